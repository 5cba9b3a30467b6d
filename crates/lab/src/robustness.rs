//! Robustness: each method of the master–slave error tables on the same realisation, disturbed once
//! after it has settled — 1 % of frames lost from then on, the reference's crystal stepping by
//! 50 ppm (a temperature step), the master overrunning three cycles (no frames for 3 ms), or on
//! a ring a cable pulled —
//! and how far and for how long the master–reference error leaves its band, and how long until
//! the segment is locked again (as the lock time counts it).
//!
//! Each method also runs undisturbed on the same seed (the control, scenario `control`): the two
//! runs are the same realisation up to the disturbance (checked), so the disturbed error minus
//! the control's is the disturbance's own effect, free of the level's slow wander that a band
//! drawn over the window before cannot foresee (a stock kernel's software stamps leave the line
//! tens of ns of phase error that moves over seconds).
use crate::LabError;
use ferrocat_master::sync::{Correction, Coupling};
use ferrocat_segment::Event;
use ferrocat_segment::HostModel;
use rayon::prelude::*;
use serde::Serialize;

use crate::stats::Moments;

/// The disturbances a run takes by default.
pub const SCENARIOS: [&str; 4] = ["loss-1pct", "drift-step-50ppm", "overrun-3-cycles", FOLLOWER_DRIFT_STEP];
/// On a ring segment (one with `[secondary]`): the cable into the device the secondary port is
/// wired to pulled, splitting the ring there (cable redundancy, docs/master.md).
pub const RING_CABLE_PULLED: &str = "ring-cable-pulled";
/// The first follower's crystal stepping by +50 ppm instead of the reference's: what ferrocat,
/// which takes a follower's crystal for its flywheel, must tell from the other.
pub const FOLLOWER_DRIFT_STEP: &str = "follower-drift-step-50ppm";
/// Every disturbance a run can name: [`SCENARIOS`] and, on a ring, [`RING_CABLE_PULLED`].
pub const KNOWN: [&str; 5] = crate::concat_names(SCENARIOS, [RING_CABLE_PULLED]);
/// The undisturbed run every disturbed one is paired with.
pub const CONTROL: &str = "control";

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
    /// Run each method undisturbed too and compare every disturbed run with it.
    pub control: bool,
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
            control: true,
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
    /// `outside_pct` says how often. For the control, which has no disturbance, the same
    /// instant counts from the time the others' disturbance comes: the band's last departure.
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
    /// After the disturbance: how often ferrocat's line restarted, and how often its change
    /// test signalled a change the next points did not confirm (None: the method keeps no line).
    pub line_restarts_after: Option<u64>,
    pub false_alarms_after: Option<u64>,
    /// The master − reference error the GPIO calibration found and took out (None: none).
    pub calibration_ns: Option<i64>,
    /// Paired with the control: from the disturbance until the error stayed within the band's
    /// half-width of the control's error at the same sample for good (None: not within the
    /// run, or no control), and the largest distance from it.
    pub recovery_vs_control_ms: Option<f64>,
    pub peak_vs_control_ns: Option<f64>,
    /// The error (ns) against the time from the disturbance (ms, negative before it), from the
    /// band window on, at most 2 000 points: for the figures, not the tables.
    #[serde(skip)]
    pub trace: crate::stats::Trace,
}

/// A run's row and its errors from the start of the band window on.
struct Run {
    row: Row,
    errors: Vec<f64>,
    window: usize,
    cycle_ns: u64,
}

/// Cycles of `cycle_ns` as milliseconds.
fn ms(cycles: usize, cycle_ns: u64) -> f64 {
    cycles as f64 * cycle_ns as f64 / 1e6
}

/// From the disturbance (sample 0 of `errors`) until no sample was out any more, if that was
/// before the last 10 % of the run: back for good only if the last 10 % stayed so.
fn back_for_good(last_out: Option<usize>, len: usize, cycle_ns: u64) -> Option<f64> {
    match last_out {
        None => Some(0.0),
        Some(i) if i < len * 9 / 10 => Some(ms(i + 1, cycle_ns)),
        Some(_) => None,
    }
}

fn run_one(o: &Options, scenario: &str, method: &str) -> crate::Result<Run> {
    let cfg = o.segment.clone().unwrap_or_else(|| crate::line(o.slaves));
    let (mut m, mut sync, _) =
        crate::segment(&cfg, o.host, o.seed, method, o.cycle_ns, Coupling::ReferenceFollowsMaster)?;
    // The master waits a quarter of the cycle for its frame (SOEM's examples wait 2 ms, IgH
    // until the next cycle): what is not back by then is lost, and a method may still make up
    // for it before the next cycle.
    m.config().settings_mut().cyclic_timeout_ns = o.cycle_ns / 4;
    let dc = crate::dc_slaves(&m)?;
    let reference = dc[0];
    let reference_node = crate::node_of(&m, reference).unwrap_or(0);
    let mut st = m.clock().sync_state()?;
    let per_s = 1e9 / o.cycle_ns as f64;
    let settle = (o.settle_s * per_s) as u64;
    let window = (o.band_window_s * per_s) as u64;
    let after = (o.after_s * per_s) as u64;
    let mut next = m.cyclic().now_ns();
    let (mut before, mut late) = (Moments::default(), Moments::default());
    // From the band window on: the control's pairing checks the window is the same.
    let mut errors = Vec::with_capacity((window + after) as usize);
    let (mut lost0, mut make_ups0) = (0, 0);
    let mut c = Correction::default();
    let (mut probes_window, mut probes0) = (0, 0);
    let mut events0 = None;
    let mut last_unlocked: Option<u64> = None;
    let mut locked_before = true;
    let mut sampler = crate::sampler::Sampler::new(&m, &dc, o.seed);
    // The calibration's pulses are over before the band window, so that the step it takes out
    // is not part of the level the band is drawn around.
    let calibrated_by = settle.saturating_sub(window);
    let pulses = crate::calibration_pulses(calibrated_by);
    let mut calibration =
        if o.gpio_calibration && pulses > 0 { crate::calibration(&mut m, method, reference, pulses) } else { None };
    let mut calibration_ns = None;
    // Each cycle's sample, once every clock has passed its instant.
    let mut take = |samples: Vec<crate::sampler::Sample>| {
        for s in samples {
            let k = s.tag;
            // Only the band window and what follows it count.
            if k + window < settle {
                continue;
            }
            let e = s.errors_ns[0] as f64;
            let locked = crate::sampler::locked(&s.errors_ns);
            match k.checked_sub(settle) {
                Some(after) if !locked => last_unlocked = Some(after),
                None => locked_before &= locked,
                _ => {}
            }
            errors.push(e);
            if k < settle {
                before.push(e);
            } else if k >= settle + after / 2 {
                late.push(e);
            }
        }
    };
    // Every method's cyclic phase meets the same host, whatever its bring-up did.
    m.cyclic().io_mut().start_cycles(o.cycle_ns);
    for k in 0..settle + after {
        if k + window == settle {
            probes_window = st.probing.sent;
        }
        if k == settle {
            probes0 = st.probing.sent;
            events0 = sync.reference_steering().and_then(|s| s.line_events());
            lost0 = st.lost;
            make_ups0 = st.make_ups;
            let now = m.cyclic().now_ns();
            match scenario {
                "loss-1pct" => m.cyclic().io_mut().seg.loss_probability = 0.01,
                "drift-step-50ppm" => {
                    m.cyclic().io_mut().seg.schedule(now, Event::DriftStep { node: reference_node, delta_ppb: 50_000 })
                }
                FOLLOWER_DRIFT_STEP => {
                    let Some(&follower) = dc.get(1) else {
                        return Err(LabError::TooFewDcSlaves { what: FOLLOWER_DRIFT_STEP, needed: 2, found: dc.len() });
                    };
                    let node = crate::node_of(&m, follower).unwrap_or(0);
                    m.cyclic().io_mut().seg.schedule(now, Event::DriftStep { node, delta_ppb: 50_000 })
                }
                // The master's task misses three periods: no frame, no correction.
                "overrun-3-cycles" => next += 3 * o.cycle_ns,
                RING_CABLE_PULLED => {
                    let Some(ring) = m.io().seg.secondary() else {
                        return Err(LabError::NeedsRing(RING_CABLE_PULLED));
                    };
                    m.cyclic().io_mut().seg.schedule(now, Event::LinkDown { node: ring.node, port: 0 })
                }
                CONTROL => {}
                other => return Err(LabError::UnknownDisturbance { name: other.into(), known: KNOWN.join(", ") }),
            }
        }
        // A master that follows the reference times its next cycle by it.
        next = crate::next_wake(next, o.cycle_ns, &c);
        m.cyclic().sleep_until(next);
        sampler.arm(&mut m, next, o.cycle_ns, k);
        c = m.clock().sync_step(sync.as_mut(), &mut st)?;
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
    let errors_after = &errors[(window as usize).min(errors.len())..];
    let peak = errors_after.iter().map(|e| (e - mean).abs()).fold(0.0, f64::max);
    let last_out = errors_after.iter().rposition(|e| (e - mean).abs() > band);
    let for_good = |last: Option<usize>| back_for_good(last, errors_after.len(), o.cycle_ns);
    let recovery_ms = for_good(last_out);
    let relock_ms = if locked_before { for_good(last_unlocked.map(|k| k as usize)) } else { None };
    let events_after =
        sync.reference_steering().and_then(|s| s.line_events()).zip(events0).map(|(now, then)| now.since(then));
    let row = Row {
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
        probes_after: st.probing.sent - probes0,
        line_restarts_after: events_after.map(|e| e.restarts),
        false_alarms_after: events_after.map(|e| e.false_alarms),
        calibration_ns,
        recovery_vs_control_ms: None,
        peak_vs_control_ns: None,
        trace: {
            let (every, cycle_ms) = ((errors.len() / 2000).max(1), o.cycle_ns as f64 / 1e6);
            crate::stats::Trace(
                errors
                    .iter()
                    .enumerate()
                    .step_by(every)
                    .map(|(i, &e)| ((i as f64 - window as f64) * cycle_ms, e))
                    .collect(),
            )
        },
    };
    Ok(Run { row, errors, window: window as usize, cycle_ns: o.cycle_ns })
}

/// Compares a disturbed run with its method's control, sample by sample.
fn pair(run: &mut Run, control: &Run) -> crate::Result<()> {
    let w = run.window;
    let (mine_before, mine) = run.errors.split_at(w.min(run.errors.len()));
    let (theirs_before, theirs) = control.errors.split_at(w.min(control.errors.len()));
    // The same seed, method and host: identical until the disturbance, or the pairing is void.
    if mine_before != theirs_before {
        return Err(LabError::ControlDiffers(run.row.method.clone()));
    }
    let d: Vec<f64> = mine.iter().zip(theirs).map(|(a, b)| a - b).collect();
    let last_out = d.iter().rposition(|x| x.abs() > run.row.band_ns);
    run.row.recovery_vs_control_ms = back_for_good(last_out, d.len(), run.cycle_ns);
    run.row.peak_vs_control_ns = Some(d.iter().map(|x| x.abs()).fold(0.0, f64::max));
    Ok(())
}

/// Every (scenario, method), on the same seed; the controls' rows (scenario `control`) first.
pub fn run(o: &Options) -> crate::Result<Vec<Row>> {
    let control = o.control || o.scenarios.iter().any(|s| s == CONTROL);
    let scenarios: Vec<&str> = control
        .then_some(CONTROL)
        .into_iter()
        .chain(o.scenarios.iter().map(String::as_str).filter(|s| *s != CONTROL))
        .collect();
    let jobs: Vec<(&str, &str)> =
        scenarios.iter().flat_map(|s| o.methods.iter().map(move |m| (*s, m.as_str()))).collect();
    let mut runs = jobs
        .par_iter()
        .map(|(s, name)| run_one(o, s, name).map_err(|e| e.in_run(format!("{s}, {name}"))))
        .collect::<crate::Result<Vec<Run>>>()?;
    if control {
        let (controls, disturbed) = runs.split_at_mut(o.methods.len());
        for run in disturbed {
            let c = controls.iter().find(|c| c.row.method == run.row.method).expect("one control per method");
            pair(run, c)?;
        }
    }
    Ok(runs.into_iter().map(|r| r.row).collect())
}

#[cfg(test)]
mod tests {
    use super::*;

    fn run_of(errors: Vec<f64>, window: usize) -> Run {
        let row = Row {
            scenario: "drift-step-50ppm".into(),
            method: "ferrocat".into(),
            host: "pc-rt".into(),
            before_mean_ns: 0.0,
            before_sd_ns: 0.0,
            band_ns: 100.0,
            peak_ns: 0.0,
            recovery_ms: None,
            relock_ms: None,
            locked_before: true,
            outside_pct: 0.0,
            after_mean_ns: 0.0,
            after_rms_ns: 0.0,
            frames_lost: 0,
            make_ups: 0,
            probes_per_s_before: 0.0,
            probes_after: 0,
            line_restarts_after: None,
            false_alarms_after: None,
            calibration_ns: None,
            recovery_vs_control_ms: None,
            peak_vs_control_ns: None,
            trace: crate::stats::Trace::default(),
        };
        Run { row, errors, window, cycle_ns: 1_000_000 }
    }

    #[test]
    fn a_run_is_measured_against_its_control_sample_by_sample() {
        // The control wanders 90 ns away from the level before; the disturbed run follows it
        // after 3 cycles 400 ns off: out of the control's band for 3 ms, not for the wander.
        let control: Vec<f64> = (0..40).map(|k| if k < 10 { 0.0 } else { 90.0 }).collect();
        let mut disturbed = control.clone();
        for e in &mut disturbed[10..13] {
            *e += 400.0;
        }
        let mut run = run_of(disturbed, 10);
        pair(&mut run, &run_of(control, 10)).unwrap();
        assert_eq!(run.row.recovery_vs_control_ms, Some(3.0));
        assert_eq!(run.row.peak_vs_control_ns, Some(400.0));
    }

    #[test]
    fn a_control_that_differs_before_the_disturbance_is_refused() {
        let control = vec![0.0; 40];
        let mut disturbed = control.clone();
        disturbed[9] = 1.0;
        let err = pair(&mut run_of(disturbed, 10), &run_of(control, 10)).unwrap_err();
        assert!(err.to_string().contains("differs"), "{err}");
    }
}
