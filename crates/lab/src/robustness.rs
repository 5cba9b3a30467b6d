//! Robustness: each method of the master–slave error tables on the same realisation, disturbed once
//! after it has settled — 1 % of frames lost from then on, the reference's crystal stepping by
//! 50 ppm (a temperature step), or the master overrunning three cycles (no frames for 3 ms) —
//! and how far and for how long the master–reference error leaves its band, and how long until
//! the segment is locked again (as the lock time counts it).
use ferrocat_master::io::{HostModel, Io};
use ferrocat_master::sync::{Correction, Coupling};
use ferrocat_segment::Event;
use rayon::prelude::*;
use serde::Serialize;

use crate::stats::Moments;

pub const SCENARIOS: [&str; 3] = ["loss-1pct", "drift-step-50ppm", "overrun-3-cycles"];

#[derive(Debug, Clone)]
pub struct Options {
    pub methods: Vec<String>,
    pub scenarios: Vec<String>,
    pub slaves: usize,
    pub cycle_ns: u64,
    /// Settling before the disturbance, the window before it that defines the band, and the
    /// time measured after it.
    pub settle_s: f64,
    pub band_window_s: f64,
    pub after_s: f64,
    pub seed: u64,
    pub host: HostModel,
    /// A segment of one's own instead of the line of `slaves` EK1100s.
    pub segment: Option<ferrocat_segment::SegmentConfig>,
    /// ferrocat's methods calibrate their stamps' asymmetry through the host's GPIO, as in
    /// park2020, before the band window (`crate::calibration`).
    pub gpio_calibration: bool,
}

impl Options {
    pub fn new(host: HostModel) -> Self {
        Options {
            methods: crate::ERROR_METHODS.iter().map(|s| s.to_string()).collect(),
            scenarios: SCENARIOS.iter().map(|s| s.to_string()).collect(),
            slaves: 2,
            cycle_ns: 1_000_000,
            settle_s: 5.0,
            band_window_s: 2.0,
            after_s: 10.0,
            seed: 1,
            host,
            segment: None,
            gpio_calibration: true,
        }
    }
}

#[derive(Debug, Clone, Serialize, PartialEq)]
pub struct Row {
    pub scenario: String,
    pub method: String,
    pub host: String,
    /// The error (master − reference, ns) over the band window before the disturbance.
    pub before_mean_ns: f64,
    pub before_sd_ns: f64,
    /// The band: the mean ± max(4 sd, 100 ns).
    pub band_ns: f64,
    /// Largest excursion from the mean before, after the disturbance.
    pub peak_ns: f64,
    /// From the disturbance until the error stayed inside the band for good (None: it did not
    /// return within the run). Under lasting loss the band is left now and then at random:
    /// `outside_pct` says how often.
    pub recovery_ms: Option<f64>,
    /// From the disturbance until the segment was locked for good as the lock time counts it:
    /// every DC slave within 100 ns of the reference, the master within 1 µs (None: not
    /// within the run).
    pub relock_ms: Option<f64>,
    /// Whether the segment was locked throughout the band window (if not, there is no lock
    /// to regain and `relock_ms` is None).
    pub locked_before: bool,
    pub outside_pct: f64,
    /// The error over the last half of the time after.
    pub after_mean_ns: f64,
    pub after_rms_ns: f64,
    pub frames_lost: u64,
    /// Lost frames the method made up for at once (ferrocat steering the reference's offset).
    pub make_ups: u64,
    /// Probe frames (ferrocat's extra reads of the reference while its estimate is uncertain):
    /// per second over the band window, and in all after the disturbance.
    pub probes_per_s_before: f64,
    pub probes_after: u64,
    /// The master − reference error the GPIO calibration found and took out (None: none).
    pub calibration_ns: Option<i64>,
}

fn run_one(o: &Options, scenario: &str, method: &str) -> anyhow::Result<Row> {
    let cfg = o.segment.clone().unwrap_or_else(|| crate::line(o.slaves));
    let (mut m, mut sync, _) =
        crate::segment(&cfg, o.host, o.seed, method, o.cycle_ns, Coupling::ReferenceFollowsMaster)?;
    // The master waits a quarter of the cycle for its frame (SOEM's examples wait 2 ms, IgH
    // until the next cycle): what is not back by then is lost, and a method may still make up
    // for it before the next cycle.
    m.cyclic_timeout_ns = o.cycle_ns / 4;
    let dc = crate::dc_slaves(&m)?;
    let reference = dc[0];
    let reference_node = crate::node_of(&m, reference).unwrap_or(0);
    let mut st = m.sync_state()?;
    let per_s = 1e9 / o.cycle_ns as f64;
    let settle = (o.settle_s * per_s) as u64;
    let window = (o.band_window_s * per_s) as u64;
    let after = (o.after_s * per_s) as u64;
    let mut next = m.engine.io.now_ns();
    let (mut before, mut late) = (Moments::default(), Moments::default());
    let mut errors_after = Vec::with_capacity(after as usize);
    let (mut lost0, mut make_ups0) = (0, 0);
    let mut c = Correction::default();
    let (mut probes_window, mut probes0) = (0, 0);
    let mut last_unlocked: Option<u64> = None;
    let mut locked_before = true;
    let mut sampler = crate::sampler::Sampler::new(&m, &dc, o.seed);
    // The calibration's pulses are over before the band window, so that the step it takes out
    // is not part of the level the band is drawn around.
    let mut calibration = if o.gpio_calibration { crate::calibration(&mut m, method, reference) } else { None };
    let calibrated_by = settle.saturating_sub(window);
    let mut calibration_ns = None;
    // Each cycle's sample, once every clock has passed its instant.
    let mut take = |samples: Vec<crate::sampler::Sample>| {
        for s in samples {
            let k = s.tag;
            let e = s.errors_ns[0] as f64;
            if k + window >= settle {
                let locked = crate::sampler::locked(&s.errors_ns);
                match k.checked_sub(settle) {
                    Some(after) if !locked => last_unlocked = Some(after),
                    None => locked_before &= locked,
                    _ => {}
                }
            }
            if k >= settle {
                errors_after.push(e);
                if k >= settle + after / 2 {
                    late.push(e);
                }
            } else if k + window >= settle {
                before.push(e);
            }
        }
    };
    // Every method's cyclic phase meets the same host, whatever its bring-up did.
    m.engine.io.start_cycles(o.cycle_ns);
    for k in 0..settle + after {
        if k + window == settle {
            probes_window = st.probes;
        }
        if k == settle {
            probes0 = st.probes;
            lost0 = st.lost;
            make_ups0 = st.make_ups;
            let now = m.engine.io.now_ns();
            match scenario {
                "loss-1pct" => m.engine.io.seg.loss_probability = 0.01,
                "drift-step-50ppm" => {
                    m.engine.io.seg.schedule(now, Event::DriftStep { node: reference_node, delta_ppb: 50_000 })
                }
                // The master's task misses three periods: no frame, no correction.
                "overrun-3-cycles" => next += 3 * o.cycle_ns,
                other => anyhow::bail!("unknown scenario {other:?} (known: {})", SCENARIOS.join(", ")),
            }
        }
        // A master that follows the reference times its next cycle by it.
        next = crate::next_wake(next, o.cycle_ns, &c);
        m.engine.io.sleep_until(next);
        sampler.arm(&mut m, next, o.cycle_ns, k);
        c = m.sync_step(sync.as_mut(), &mut st)?;
        if let Some(cal) =
            calibration.as_mut().filter(|_| k < calibrated_by && crate::calibration_cycle(k, calibrated_by))
        {
            calibration_ns = calibration_ns.or(cal.pulse(&mut m, sync.as_mut())?);
        }
        take(sampler.after_cycle(&mut m, sync.as_ref()));
    }
    take(sampler.rest(&mut m, sync.as_ref()));
    let mean = before.mean();
    let sd = (before.rms().powi(2) - mean * mean).max(0.0).sqrt();
    let band = (4.0 * sd).max(100.0);
    let peak = errors_after.iter().map(|e| (e - mean).abs()).fold(0.0, f64::max);
    let last_out = errors_after.iter().rposition(|e| (e - mean).abs() > band);
    let ms = |cycles: usize| cycles as f64 * o.cycle_ns as f64 / 1e6;
    // Back for good only if the last 10 % of the run stayed so.
    let for_good = |last: Option<usize>| match last {
        None => Some(0.0),
        Some(i) if i < errors_after.len() * 9 / 10 => Some(ms(i + 1)),
        Some(_) => None,
    };
    let recovery_ms = for_good(last_out);
    let relock_ms = if locked_before { for_good(last_unlocked.map(|k| k as usize)) } else { None };
    Ok(Row {
        scenario: scenario.to_string(),
        method: method.to_string(),
        host: o.host.name.to_string(),
        before_mean_ns: mean,
        before_sd_ns: sd,
        band_ns: band,
        peak_ns: peak,
        recovery_ms,
        relock_ms,
        locked_before,
        outside_pct: errors_after.iter().filter(|e| (*e - mean).abs() > band).count() as f64
            / errors_after.len().max(1) as f64
            * 100.0,
        after_mean_ns: late.mean(),
        after_rms_ns: late.rms(),
        frames_lost: st.lost - lost0,
        make_ups: st.make_ups - make_ups0,
        probes_per_s_before: (probes0 - probes_window) as f64 / o.band_window_s,
        probes_after: st.probes - probes0,
        calibration_ns,
    })
}

/// Every (scenario, method), on the same seed.
pub fn run(o: &Options) -> anyhow::Result<Vec<Row>> {
    let jobs: Vec<(String, String)> =
        o.scenarios.iter().flat_map(|s| o.methods.iter().map(move |m| (s.clone(), m.clone()))).collect();
    jobs.par_iter().map(|(s, name)| run_one(o, s, name).map_err(|e| anyhow::anyhow!("{s}, {name}: {e:#}"))).collect()
}
