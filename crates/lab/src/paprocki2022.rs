//! Paprocki & Erwiński 2022, Table 2: how simultaneously two drives see SYNC0 — the difference
//! of their SYNC0 instants (true time, which the simulator knows) for the same system time, over
//! 1000 cycles at 1000 and 500 µs, for each clock-sync method.
use crate::LabError;
use ferrocat_master::sync::Coupling;
use ferrocat_master::DcConfig;
use ferrocat_segment::HostModel;
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
    /// A segment of one's own instead of a coupler and two DC slaves: the first two DC slaves
    /// after the reference stand for the drives, or the only two, the reference first.
    pub segment: Option<SegmentConfig>,
    /// Whether the second drive keeps the propagation delay the DC initialisation wrote. Off,
    /// its System_Time_Delay is 0 from the cycles on, as under a master that does not
    /// compensate the delay to it: one candidate for the paper's constant ≈ 0.8 µs.
    pub drive_delay_compensated: bool,
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
            segment: None,
            drive_delay_compensated: true,
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
    /// Every difference (ns), for the figures, not the tables.
    #[serde(skip)]
    pub diffs_ns: crate::stats::Trace,
}

/// Table 2 as published: cycle µs, mean, max, min, standard deviation (ns; the paper's headings
/// say µs, its text ns).
pub const PAPER: [(u64, f64, f64, f64, f64); 2] =
    [(1000, 805.5, 831.5, 730.0, 4.621), (500, 807.2, 831.5, 760.0, 3.725)];

fn run_one(o: &Options, cycle_us: u64, name: &str) -> crate::Result<Row> {
    let cycle_ns = cycle_us * 1000;
    // A coupler and two DC slaves standing in for the drives (their SYNC0 unit is what counts;
    // a DC-synchronous application enables it, without which an ET1200 has no system time).
    let toml = format!(
        "seed = {}\ndrift_spread_ppm = 50.0\n[[device]]\nbuiltin = 'EK1100'\n\
         [[device]]\nbuiltin = 'EL2004'\napp = 'dc'\n[[device]]\nbuiltin = 'EL2004'\napp = 'dc'\n",
        o.seed
    );
    let cfg: SegmentConfig = match &o.segment {
        Some(c) => SegmentConfig { seed: o.seed, ..c.clone() },
        None => toml::from_str(&toml)?,
    };
    let mut m = crate::master(cfg, o.host, o.seed, name)?;
    m.states().bring_up()?;
    let dc = crate::dc_slaves(&m)?;
    // The paper's line is the master and two drives, the first the reference; the default
    // segment puts a coupler before them, whose clock is then the reference.
    let drives = match dc.len() {
        2 => [dc[0], dc[1]],
        n if n >= 3 => [dc[1], dc[2]],
        n => return Err(LabError::TooFewDcSlaves { what: "two drives", needed: 2, found: n }),
    };
    let nodes = drives.map(|k| crate::node_of(&m, k).unwrap_or(k) as u16);
    let dc_cfg = DcConfig {
        sync0_cycle_ns: cycle_ns as u32,
        sync0_slaves: Some(drives.iter().map(|&k| k as u16).collect()),
        start_delay_ns: 10_000_000,
        ..DcConfig::default()
    };
    let (mut sync, _) = crate::init_with_method(&mut m, &dc_cfg, name, cycle_ns, Coupling::ReferenceFollowsMaster)?;
    if !o.drive_delay_compensated {
        // The delay register as a master that never wrote it leaves it: the drive's loop then
        // steers its time onto the reference's as it arrives, one hop late.
        if let Some(d) = m.cyclic().io_mut().seg.nodes[nodes[1] as usize].esc.dc.as_mut() {
            d.delay = 0;
        }
    }
    let mut st = m.clock().sync_state()?;
    let settle = (o.settle_s * 1e9 / cycle_ns as f64) as u64;
    let mut next = m.cyclic().now_ns();
    let mut sync0 = crate::stats::Sync0Stats::default();
    let mut k = 0u64;
    // Every method's cyclic phase meets the same host, whatever its bring-up did.
    m.cyclic().io_mut().start_cycles(cycle_ns);
    while (sync0.diffs.n as usize) < o.samples {
        m.cyclic().cycle()?;
        let c = m.clock().sync_step(sync.as_mut(), &mut st)?;
        next += c.next_period_ns.unwrap_or(cycle_ns);
        m.cyclic().sleep_until(next);
        k += 1;
        if k >= settle + 100 * o.samples as u64 {
            return Err(LabError::Sync0Stopped);
        }
        if k >= settle {
            // The two drives' pulses for the same system time.
            sync0.sample(&m.io().seg, &nodes);
        }
    }
    let (mean, sd, min, max, _) = sync0.figures();
    Ok(Row {
        cycle_us,
        method: name.to_string(),
        host: o.host.name.to_string(),
        mean_ns: mean.unwrap_or(f64::NAN),
        max_ns: max.unwrap_or(0),
        min_ns: min.unwrap_or(0),
        sd_ns: sd.unwrap_or(f64::NAN),
        samples: sync0.diffs.n as usize,
        diffs_ns: crate::stats::Trace(sync0.values.iter().enumerate().map(|(k, &d)| (k as f64, d as f64)).collect()),
    })
}

pub fn run(o: &Options) -> crate::Result<Vec<Row>> {
    let jobs: Vec<(u64, String)> =
        o.cycles_us.iter().flat_map(|&c| o.methods.iter().map(move |m| (c, m.clone()))).collect();
    jobs.par_iter().map(|(c, name)| run_one(o, *c, name).map_err(|e| e.in_run(format!("{c} µs, {name}")))).collect()
}

/// The row Table 2 is compared on: `none`, which leaves the slaves' clocks to their DC after the
/// initialisation, as any master does for the drives among themselves; else the first method.
pub fn compared_method(rows: &[Row]) -> Option<&str> {
    rows.iter().find(|r| r.method == "none").or(rows.first()).map(|r| r.method.as_str())
}

/// Every published figure of Table 2 beside `method`'s row. Nothing of the set-up model is
/// fitted (docs/lab.md): every figure is a prediction, and its band is ±30 % alone (the ±0.5 µs
/// floor of µs-sized figures would hold any of these ns).
pub fn compare(rows: &[Row], method: &str) -> Vec<crate::fit::Figure> {
    use crate::fit::{Band, Figure, Part};
    let band = Band { share: Band::PREDICTION_US.share, floor: None };
    let mut out = Vec::new();
    for &(cycle, mean, max, min, sd) in &PAPER {
        let Some(r) = rows.iter().find(|r| r.cycle_us == cycle && r.method == method) else { continue };
        for (what, paper, model) in [
            ("mean", mean, r.mean_ns),
            ("max", max, r.max_ns as f64),
            ("min", min, r.min_ns as f64),
            ("sd", sd, r.sd_ns),
        ] {
            out.push(Figure::new(format!("{cycle} µs, {what}"), "ns", Part::Prediction, band, paper, model));
        }
    }
    out
}
