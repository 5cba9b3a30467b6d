//! Paprocki & Erwiński 2022, Table 2: how simultaneously two drives see SYNC0 — the difference
//! of their SYNC0 instants (true time, which the simulator knows) for the same system time, over
//! 1000 cycles at 1000 and 500 µs, for each clock-sync method.
use ferrocat_master::io::{HostModel, Io};
use ferrocat_master::sync::Coupling;
use ferrocat_master::{DcConfig, Master};
use ferrocat_segment::SegmentConfig;
use rayon::prelude::*;
use serde::Serialize;

pub const METHODS: [&str; 4] = ["none", "conventional", "park2020", "ferrocat"];

#[derive(Debug, Clone)]
pub struct Options {
    pub cycles_us: Vec<u64>,
    pub methods: Vec<String>,
    pub settle_s: f64,
    pub samples: usize,
    pub seed: u64,
    pub host: HostModel,
}

impl Options {
    pub fn new(host: HostModel) -> Self {
        Options {
            cycles_us: vec![1000, 500],
            methods: METHODS.iter().map(|s| s.to_string()).collect(),
            settle_s: 5.0,
            samples: 1000,
            seed: 1,
            host,
        }
    }
}

#[derive(Debug, Clone, Serialize, PartialEq)]
pub struct Row {
    pub cycle_us: u64,
    pub method: String,
    pub host: String,
    /// Second drive's SYNC0 minus the first's, for the same system time (ns).
    pub mean_ns: f64,
    pub max_ns: i64,
    pub min_ns: i64,
    pub sd_ns: f64,
    pub samples: usize,
}

/// Table 2 as published: cycle µs, mean, max, min, standard deviation (ns; the paper's headings
/// say µs, its text ns).
pub const PAPER: [(u64, f64, f64, f64, f64); 2] =
    [(1000, 805.5, 831.5, 730.0, 4.621), (500, 807.2, 831.5, 760.0, 3.725)];

fn run_one(o: &Options, cycle_us: u64, name: &str) -> anyhow::Result<Row> {
    let cycle_ns = cycle_us * 1000;
    // A coupler and two DC slaves standing in for the drives (their SYNC0 unit is what counts).
    let toml = format!(
        "seed = {}\ndrift_spread_ppm = 50.0\n[[device]]\nbuiltin = 'EK1100'\n\
         [[device]]\nbuiltin = 'EL2004'\n[[device]]\nbuiltin = 'EL2004'\n",
        o.seed
    );
    let cfg: SegmentConfig = toml::from_str(&toml)?;
    let mut m = Master::new(ferrocat_master::io::VirtualIo::new(cfg.build()?, o.host, o.seed));
    m.bring_up()?;
    m.init_dc(&DcConfig {
        sync0_cycle_ns: cycle_ns as u32,
        sync0_slaves: Some(vec![1, 2]),
        start_delay_ns: 10_000_000,
        ..DcConfig::default()
    })?;
    let mut sync = crate::method(name, &mut m, cycle_ns, Coupling::ReferenceFollowsMaster)?;
    let mut st = m.sync_state()?;
    let settle = (o.settle_s * 1e9 / cycle_ns as f64) as u64;
    let mut next = m.engine.io.now_ns();
    let mut diffs: Vec<i64> = Vec::with_capacity(o.samples);
    let mut last_sys = None;
    let mut k = 0u64;
    while diffs.len() < o.samples {
        m.cycle()?;
        let c = m.sync_step(sync.as_mut(), &mut st)?;
        next += c.next_period_ns.unwrap_or(cycle_ns);
        m.engine.io.sleep_until(next);
        k += 1;
        anyhow::ensure!(k < settle + 100 * o.samples as u64, "SYNC0 pulses stopped");
        if k < settle {
            continue;
        }
        let nodes = &m.engine.io.seg.nodes;
        let (Some(&(s1, t1)), Some(p2)) = (nodes[1].esc.sync0_log.pulses.back(), Some(&nodes[2].esc.sync0_log.pulses))
        else {
            continue;
        };
        // The second drive's pulse for the same system time (32-bit DCs compared on 32 bits).
        if last_sys == Some(s1) {
            continue;
        }
        if let Some(&(_, t2)) = p2.iter().rev().find(|(s2, _)| *s2 as u32 == s1 as u32) {
            diffs.push(t2 as i64 - t1 as i64);
            last_sys = Some(s1);
        }
    }
    let n = diffs.len() as f64;
    let mean = diffs.iter().sum::<i64>() as f64 / n;
    let sd = (diffs.iter().map(|&d| (d as f64 - mean).powi(2)).sum::<f64>() / n).sqrt();
    Ok(Row {
        cycle_us,
        method: name.to_string(),
        host: o.host.name.to_string(),
        mean_ns: mean,
        max_ns: *diffs.iter().max().unwrap_or(&0),
        min_ns: *diffs.iter().min().unwrap_or(&0),
        sd_ns: sd,
        samples: diffs.len(),
    })
}

pub fn run(o: &Options) -> anyhow::Result<Vec<Row>> {
    let jobs: Vec<(u64, String)> =
        o.cycles_us.iter().flat_map(|&c| o.methods.iter().map(move |m| (c, m.clone()))).collect();
    jobs.par_iter()
        .map(|(c, name)| run_one(o, *c, name).map_err(|e| anyhow::anyhow!("{c} µs, {name}: {e:#}")))
        .collect()
}
