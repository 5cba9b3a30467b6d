//! The demo: a coupler, I/O terminals and N CiA402 drives brought to OP with distributed clocks,
//! every drive enabled in cyclic synchronous position, and a synchronised jerk-limited move of
//! all axes out and back — once per clock-sync method and cycle time, on the same seed.
//!
//! In the simulator the figures are its truth: the clocks, the drives' SYNC0 instants, late and
//! repeated set-points, following errors. On a real network (any `Io`) only what the master can
//! see is reported: following errors from 0x60F4 when mapped, late and repeated set-points from
//! the drives' 0x1C32:0C and 0x1C32:0B when they have them; the rest is `None`.
use crate::LabError;
use crate::World;
use ferrocat_esc::Cia402Drive;
use ferrocat_master::calibrate::GpioCalibration;
use ferrocat_master::cia402::Output;
use ferrocat_master::cia402::{map_for_csp, Axis, Goal};
use ferrocat_master::sync::{ClockSync, Coupling};
use ferrocat_master::trajectory::{Limits, Move};
use ferrocat_master::{DcConfig, Master, MasterEvent, SyncState};
use ferrocat_segment::SegmentConfig;
use ferrocat_segment::{HostModel, VirtualIo};
use ferrocat_wire::cia402::{index as ix, Mode, State};
use rayon::prelude::*;
use serde::Serialize;

use crate::stats::Moments;

#[derive(Debug, Clone)]
pub struct Options {
    pub drives: usize,
    /// `--device`-style description of the drive: "SERVO" (built in), an ESI file with
    /// `:PRODUCT`, or an EEPROM image.
    pub drive: String,
    pub cycles_us: Vec<u64>,
    pub methods: Vec<String>,
    pub host: HostModel,
    pub seed: u64,
    /// Synchronisation before the drives are enabled (s).
    pub settle_s: f64,
    /// ferrocat's methods calibrate their stamps' asymmetry through the host's GPIO into the
    /// reference's LATCH0 input during the settling, as in the lab, where the host model has
    /// a GPIO (simulator only: on a real network nothing is wired).
    pub gpio_calibration: bool,
    /// Motion limits of every axis (revolutions per s, s², s³).
    pub limits_rev: Limits,
}

impl Options {
    pub fn new(host: HostModel) -> Self {
        Options {
            drives: 2,
            drive: "SERVO".into(),
            cycles_us: vec![1000, 250],
            methods: crate::METHODS.iter().map(|s| s.to_string()).collect(),
            host,
            seed: 1,
            settle_s: 1.0,
            gpio_calibration: true,
            limits_rev: Limits { velocity: 20.0, acceleration: 200.0, jerk: 10_000.0 },
        }
    }
}

#[derive(Debug, Clone, Serialize, PartialEq)]
pub struct Row {
    pub method: String,
    pub cycle_us: u64,
    pub host: String,
    /// Master clock minus reference clock (ns) over the move, for a method whose reference
    /// follows the master (simulator only; `None` for the others).
    pub error_mean_ns: Option<f64>,
    pub error_rms_ns: Option<f64>,
    pub error_max_ns: Option<f64>,
    /// For a method where the master follows the reference: the reference's system time at
    /// the master's cycle start off the cycle grid (ns, within ± half a cycle; simulator only,
    /// `None` for the others). A phase, not a clock error: it says where in the reference's
    /// cycle the master sends.
    pub phase_mean_ns: Option<f64>,
    pub phase_rms_ns: Option<f64>,
    pub phase_max_ns: Option<f64>,
    /// The master − reference error the GPIO calibration found and took out (ns; None: not
    /// calibrated).
    pub calibration_ns: Option<i64>,
    /// Second drive's SYNC0 minus the first's for the same system time (Paprocki 2022, Table
    /// 2), and the largest spread of all drives' SYNC0 instants (simulator only).
    pub sync0_mean_ns: Option<f64>,
    pub sync0_sd_ns: Option<f64>,
    pub sync0_min_ns: Option<i64>,
    pub sync0_max_ns: Option<i64>,
    pub sync0_spread_max_ns: Option<u64>,
    pub late_setpoints: Option<u64>,
    pub repeated_setpoints: Option<u64>,
    /// SYNC0 numbers (from the start of the move) of the first late and repeated set-points,
    /// as "drive:cycle" (simulator only).
    pub late_cycles: Vec<String>,
    pub repeated_cycles: Vec<String>,
    /// Largest |position demand − actual| of each axis (increments) and over all.
    pub following_error: Vec<Option<f64>>,
    pub max_following_error: Option<f64>,
    /// Drives with every axis in operation enabled at the end of the move (as their
    /// statuswords say).
    pub drives_enabled: usize,
    /// Every axis of every drive, in segment order.
    pub axes: Vec<AxisRow>,
    /// Times a drive left OP during the run (a sync error, where a drive supervises its SM
    /// synchronisation, after three cycles without set-points), each brought back by the master.
    pub left_op: usize,
    pub drives: usize,
    /// Application-layer time (SYNC0 to set-point in the loops), all drives: mean and max µs
    /// (Paprocki 2022, Tables 3–4; simulator only).
    pub processing_mean_us: Option<f64>,
    pub processing_max_us: Option<f64>,
    pub move_s: f64,
    pub cycles: u64,
    pub frames_lost: u64,
    /// Every `trace_every`-th cycle: time (s), per axis set-point and actual (rev), error (ns).
    #[serde(skip)]
    pub trace: Vec<TracePoint>,
}

/// One axis's figures.
#[derive(Debug, Clone, Serialize, PartialEq)]
pub struct AxisRow {
    /// The drive's position on the segment.
    pub slave: u16,
    /// The axis on that drive (0 the first; its objects n × 0x800 above the first's).
    pub axis: u8,
    /// "csp", or "csv" for an axis whose image has a target velocity but no target position.
    pub mode: String,
    /// Operation enabled at the end of the move.
    pub enabled: bool,
    /// Largest |position demand − actual| (increments): the drive's own in CSP; in CSV the
    /// move's set-point minus the shaft's travel (simulator), or minus the position actual value
    /// the image returned (a real drive: it includes the cycle or two the value takes to come
    /// back; none where the image has no position actual value).
    pub following_error: Option<f64>,
}

#[derive(Debug, Clone, PartialEq)]
pub struct TracePoint {
    pub t_s: f64,
    pub setpoint_rev: Vec<f64>,
    pub actual_rev: Vec<f64>,
    /// NaN where neither the simulator nor the image gives it.
    pub following_error: Vec<f64>,
    pub error_ns: f64,
}

struct Rig<I: World> {
    m: Master<I>,
    sync: Box<dyn ClockSync>,
    st: SyncState,
    cycle_ns: u64,
    next: u64,
}

impl<I: World> Rig<I> {
    fn step(&mut self) -> crate::Result<()> {
        self.exchange()?;
        self.wait();
        Ok(())
    }

    /// The cycle's frames and the clock sync's correction.
    fn exchange(&mut self) -> crate::Result<()> {
        self.m.cyclic().cycle()?;
        let c = self.m.clock().sync_step(self.sync.as_mut(), &mut self.st)?;
        self.next += c.next_period_ns.unwrap_or(self.cycle_ns);
        Ok(())
    }

    /// Until the next cycle is due.
    fn wait(&mut self) {
        self.m.cyclic().sleep_until(self.next);
    }

    /// The simulated drive at `k`, when the world is the in-process simulator.
    fn drive(&self, k: u16) -> Option<&Cia402Drive> {
        self.m.io().segment()?.nodes.get(k as usize)?.esc.app().as_any().downcast_ref::<Cia402Drive>()
    }
}

/// Brings the segment up with DC and the drives' SYNC0 half a cycle after the cycle grid,
/// prepares `method`, and aligns the master's first cycle with the grid. The drives are the
/// slaves with a controlword and a statusword in their image (after `map_for_csp`).
fn rig<I: World>(mut m: Master<I>, cycle_us: u64, method: &str) -> crate::Result<(Rig<I>, Vec<u16>)> {
    let cycle_ns = cycle_us * 1000;
    m.states().scan()?;
    m.states().configure()?;
    let mut drives = Vec::new();
    for k in 0..m.slaves().len() as u16 {
        if Axis::on_axis(&m, k, 0).is_err() {
            continue;
        }
        map_for_csp(&mut m, k)?;
        // What an integrator sets up in PREOP: a torque limit and a following-error window the
        // move needs (a vendor's defaults may be far tighter), where the drive has the objects.
        for a in Axis::all(&m, k)? {
            let _ = m.acyclic().coe().sdo_write(k, a.index(ix::MAX_TORQUE), 0, &3000u16.to_le_bytes());
            let _ = m.acyclic().coe().sdo_write(k, a.index(ix::FOLLOWING_ERROR_WINDOW), 0, &13_107u32.to_le_bytes());
        }
        drives.push(k);
    }
    if drives.is_empty() {
        return Err(LabError::NoDrive);
    }
    let shift = (cycle_ns / 2) as i32;
    let report = m.dc().init_dc(&DcConfig {
        sync0_cycle_ns: cycle_ns as u32,
        sync0_shift_ns: shift,
        sync0_slaves: Some(drives.clone()),
        start_delay_ns: 20_000_000,
        ..DcConfig::default()
    })?;
    if let Some(&(position, pulse_ns)) = report.sync0_held.first() {
        return Err(LabError::Sync0Held { position, pulse_ns, cycle_ns });
    }
    // Before OP: Park's 1000 delay round trips carry no process data, and in OP the drives'
    // SM-synchronisation supervision would take them out of OP (sync error 0x001A).
    let sync = crate::method(method, &mut m, cycle_ns, Coupling::ReferenceFollowsMaster)?;
    m.states().start()?;
    let st = m.clock().sync_state()?;
    // The master's cycles on the grid: SYNC0 half a cycle after each frame leaves.
    let grid = report.sync0_start.unwrap_or(0).wrapping_sub(shift as u64);
    let next = m.clock().next_on_grid_ns(grid, cycle_ns);
    m.cyclic().sleep_until(next);
    Ok((Rig { m, sync, st, cycle_ns, next }, drives))
}

/// The segment of the demo: EK1100, EL2004, EL1004, then the drives (`--device` syntax).
pub fn segment_config(o: &Options) -> crate::Result<SegmentConfig> {
    let mut cfg: SegmentConfig = toml::from_str(&format!(
        "seed = {}\ndrift_spread_ppm = 50.0\n[[device]]\nbuiltin = 'EK1100'\n[[device]]\nbuiltin = 'EL2004'\n\
         [[device]]\nbuiltin = 'EL1004'\n",
        o.seed
    ))?;
    let mut drive = SegmentConfig::from_device_args(std::slice::from_ref(&o.drive))?.devices.remove(0);
    // A device without a CoE mailbox (a terminal's EEPROM, say) cannot be a CiA402 drive: say so
    // in the terms of --drive, before the segment is built with the drive application.
    let alone = SegmentConfig { devices: vec![drive.clone()], ..SegmentConfig::default() }.build()?;
    let node = &alone.nodes[0];
    if node.esc.app().as_any().is::<ferrocat_esc::DigitalIo>()
        || node.esc.app().as_any().is::<ferrocat_esc::NoApplication>()
    {
        return Err(LabError::NotADrive { drive: o.drive.clone(), name: node.name.clone() });
    }
    // A drive of the SoE profile (SERCOS over EtherCAT) has its own control and status words:
    // the demo drives CiA402 only, and says so rather than finding no 0x6040 later.
    if let Some(dev) = node.esc.app().as_any().downcast_ref::<ferrocat_esc::CoeDevice>() {
        if dev.soe.is_some() {
            let coe = dev.serves_coe;
            return Err(LabError::SoeProfile { drive: o.drive.clone(), name: node.name.clone(), coe });
        }
    }
    drive.app = Some("cia402".into());
    cfg.devices.extend(std::iter::repeat_n(drive, o.drives));
    Ok(cfg)
}

/// Makes the GPIO calibration of a method, where the world has a GPIO to calibrate with.
type Calibrate<'a, I> = &'a dyn Fn(&mut Master<I>, &str, usize) -> Option<GpioCalibration>;

fn run_one<I: World>(
    m: Master<I>,
    o: &Options,
    cycle_us: u64,
    method: &str,
    calibrate: Calibrate<'_, I>,
) -> crate::Result<Row> {
    let (mut r, drives) = rig(m, cycle_us, method)?;
    let events0 = r.m.diagnosis().events().len();
    let cycle_ns = r.cycle_ns;
    let mfr = r.sync.coupling() == Coupling::MasterFollowsReference;
    let settle_cycles = (o.settle_s * 1e9 / cycle_ns as f64) as u64;
    // The pulses spread over the settling's middle half, at most one per cycle.
    let pulses = crate::calibration_pulses(settle_cycles);
    let mut calibration = if o.gpio_calibration && pulses > 0 { calibrate(&mut r.m, method, pulses) } else { None };
    let mut calibration_ns = None;
    for k in 0..settle_cycles {
        r.exchange()?;
        // After the cycle's frames, as in the lab: a pulse before the wait does not delay the
        // next cycle.
        if let Some(cal) = calibration.as_mut().filter(|_| crate::calibration_cycle(k, settle_cycles)) {
            calibration_ns = calibration_ns.or(cal.pulse(&mut r.m, r.sync.as_mut())?);
        }
        r.wait();
    }
    let mut axes: Vec<Axis> = Vec::new();
    for &d in &drives {
        axes.extend(Axis::all(&r.m, d)?);
    }
    // Position where the image carries a target position, else velocity.
    let mut csv = Vec::with_capacity(axes.len());
    for a in &mut axes {
        let velocity = !a.can_run(ferrocat_master::cia402::Mode::CyclicSyncPosition);
        if !(a.can_run(ferrocat_master::cia402::Mode::CyclicSyncPosition)
            || a.can_run(ferrocat_master::cia402::Mode::CyclicSyncVelocity))
        {
            let mapped = r.m.slaves().get(a.position as usize).map(|s| s.mapping().outputs.clone()).unwrap_or_default();
            let outputs = mapped
                .iter()
                .filter(|e| e.index != 0)
                .map(|e| format!("{:#06X} {}", e.index, e.name))
                .collect::<Vec<_>>()
                .join(", ");
            return Err(LabError::NoTarget { position: a.position, axis: a.axis, outputs });
        }
        a.set_mode(&mut r.m, if velocity { Mode::CyclicSyncVelocity } else { Mode::CyclicSyncPosition })?;
        a.set_goal(Goal::OperationEnabled);
        csv.push(velocity);
    }
    // Enabling, with the clock sync running meanwhile.
    for k in 0.. {
        r.step()?;
        let mut ready = true;
        for a in &mut axes {
            a.update(&mut r.m);
            ready &= a.feedback(&r.m).ready;
        }
        if ready {
            break;
        }
        if k >= 5_000 {
            return Err(LabError::DrivesNotEnabled(axes.iter().map(|a| a.state()).collect()));
        }
    }
    let mut per_rev = Vec::new();
    for a in &axes {
        per_rev.push(match r.drive(a.position) {
            Some(dr) => sim_axis(dr, a).map_or(131_072.0, |x| x.motor.increments_per_rev),
            None => increments_per_rev(&mut r.m, a.position, a.index(0x608F)),
        });
    }
    let start: Vec<f64> = axes.iter().map(|a| a.feedback(&r.m).position.unwrap_or(0) as f64).collect();
    // Axis i moves (i + 1) · 2 revolutions, alternating direction, then back.
    let out: Vec<f64> = start
        .iter()
        .enumerate()
        .map(|(i, s)| s + per_rev[i] * 2.0 * (i as f64 + 1.0) * if i % 2 == 0 { 1.0 } else { -1.0 })
        .collect();
    let lim: Vec<Limits> = per_rev
        .iter()
        .map(|p| Limits {
            velocity: o.limits_rev.velocity * p,
            acceleration: o.limits_rev.acceleration * p,
            jerk: o.limits_rev.jerk * p,
        })
        .collect();
    let there = Move::new(&start, &out, &lim);
    let back = Move::new(&out, &start, &lim);
    let dwell_s = 0.1;
    let move_s = there.duration_s() + back.duration_s() + 2.0 * dwell_s;
    let cycles = (move_s * 1e9 / cycle_ns as f64).ceil() as u64;
    let simulated = r.m.io().segment().is_some();
    if let Some(seg) = r.m.cyclic().io_mut().segment_mut() {
        for &d in &drives {
            if let Some(dr) = seg.nodes[d as usize].esc.app_mut().as_any_mut().downcast_mut::<Cia402Drive>() {
                dr.reset_stats();
            }
        }
    }
    let counters0 = if simulated { None } else { sync_counters(&mut r.m, &drives) };
    let lost0 = r.st.lost;
    let mut err = Moments::default();
    let mut err_max = 0.0f64;
    let mut sync0 = crate::stats::Sync0Stats::default();
    let mut fe_image: Vec<Option<f64>> = vec![None; axes.len()];
    // A CSV axis in the simulator: the move measured from where each shaft stood at its start
    // (the image may carry no position actual value at all).
    let shaft =
        |r: &Rig<I>, a: &Axis| r.drive(a.position).and_then(|dr| sim_axis(dr, a)).map(|x| x.position_increments());
    let shaft0: Vec<Option<f64>> = axes.iter().map(|a| shaft(&r, a)).collect();
    let mut fe_csv: Vec<Option<f64>> = vec![None; axes.len()];
    let mut sp = vec![0.0; axes.len()];
    let mut sp_next = vec![0.0; axes.len()];
    let cycle_s = cycle_ns as f64 * 1e-9;
    let at = |t: f64, out: &mut [f64]| {
        let t_back = t - there.duration_s() - dwell_s;
        if t_back < 0.0 {
            there.positions(t, out);
        } else {
            back.positions(t_back, out);
        }
    };
    let mut trace = Vec::new();
    let trace_every = (1_000_000 / cycle_ns).max(1);
    for k in 0..cycles {
        // One set-point per SYNC0: cycle k's is the profile at k cycles on the SYNC0 grid.
        let t = k as f64 * cycle_s;
        at(t, &mut sp);
        at(t + cycle_s, &mut sp_next);
        for (i, a) in axes.iter().enumerate() {
            if csv[i] {
                // CSV: the slope to the next cycle's set-point (increments/s).
                a.write(&mut r.m, Output::Velocity(((sp_next[i] - sp[i]) / cycle_s).round() as i32));
            } else {
                a.write(&mut r.m, Output::Position(sp[i].round() as i64 as i32));
            }
        }
        let e = true_error_ns(&mut r.m, mfr, cycle_ns);
        if let Some(e) = e {
            err.push(e);
            err_max = err_max.max(e.abs());
        }
        r.step()?;
        for (i, (a, fe)) in axes.iter_mut().zip(&mut fe_image).enumerate() {
            a.update(&mut r.m);
            let f = if csv[i] {
                a.feedback(&r.m).position.map(|p| (sp[i] - p as f64).abs())
            } else {
                a.feedback(&r.m).following_error.map(|f| f.unsigned_abs() as f64)
            };
            if let Some(f) = f {
                *fe = Some(fe.unwrap_or(0.0).max(f));
            }
        }
        for (i, a) in axes.iter().enumerate().filter(|(i, _)| csv[*i]) {
            if let (Some(now), Some(s0)) = (shaft(&r, a), shaft0[i]) {
                let e = ((sp[i] - start[i]) - (now - s0)).abs();
                fe_csv[i] = Some(fe_csv[i].unwrap_or(0.0).max(e));
            }
        }
        if let Some(seg) = r.m.io().segment() {
            sync0.sample(seg, &drives);
        }
        if k % trace_every == 0 {
            let mut p = TracePoint {
                t_s: t,
                setpoint_rev: sp.iter().zip(&per_rev).map(|(s, p)| s / p).collect(),
                actual_rev: Vec::new(),
                following_error: Vec::new(),
                error_ns: e.unwrap_or(f64::NAN),
            };
            for (i, a) in axes.iter().enumerate() {
                let (pos, fe) = match r.drive(a.position).and_then(|dr| sim_axis(dr, a)) {
                    Some(ax) if csv[i] => {
                        let moved = ax.position_increments() - shaft0[i].unwrap_or(0.0);
                        (start[i] + moved, sp[i] - start[i] - moved)
                    }
                    Some(ax) => (ax.position_increments(), ax.following_error_increments()),
                    None => (
                        a.feedback(&r.m).position.unwrap_or(0) as f64,
                        a.feedback(&r.m).following_error.map_or(f64::NAN, |f| f as f64),
                    ),
                };
                p.actual_rev.push(pos / per_rev[i]);
                p.following_error.push(fe);
            }
            trace.push(p);
        }
    }
    let stats: Option<Vec<ferrocat_esc::DriveStats>> =
        drives.iter().map(|&d| r.drive(d).map(|dr| dr.stats.clone())).collect();
    let tagged = |f: &dyn Fn(&ferrocat_esc::DriveStats) -> &Vec<u64>| -> Vec<String> {
        let mut v: Vec<String> = stats
            .iter()
            .flatten()
            .enumerate()
            .flat_map(|(i, s)| f(s).iter().map(move |c| format!("{}:{c}", i + 1)).collect::<Vec<_>>())
            .collect();
        v.truncate(8);
        v
    };
    let (late, repeated) = match &stats {
        Some(st) => {
            (Some(st.iter().map(|s| s.late_setpoints).sum()), Some(st.iter().map(|s| s.repeated_setpoints).sum()))
        }
        None => match (counters0, sync_counters(&mut r.m, &drives)) {
            (Some((l0, r0)), Some((l1, r1))) => (Some(l1.wrapping_sub(l0)), Some(r1.wrapping_sub(r0))),
            _ => (None, None),
        },
    };
    let following_error: Vec<Option<f64>> = axes
        .iter()
        .enumerate()
        .map(|(i, a)| match r.drive(a.position) {
            Some(dr) if !csv[i] => sim_axis(dr, a).map(|x| x.max_following_error()),
            Some(_) => fe_csv[i],
            None => fe_image[i],
        })
        .collect();
    let n_proc: u64 = stats.iter().flatten().map(|s| s.processing_count).sum();
    let axis_rows: Vec<AxisRow> = axes
        .iter()
        .enumerate()
        .map(|(i, a)| AxisRow {
            slave: a.position,
            axis: a.axis,
            mode: if csv[i] { "csv" } else { "csp" }.into(),
            enabled: a.state() == Some(State::OperationEnabled),
            following_error: following_error[i],
        })
        .collect();
    let enabled = drives.iter().filter(|&&d| axis_rows.iter().filter(|a| a.slave == d).all(|a| a.enabled)).count();
    let left_op = r.m.diagnosis().events()[events0..]
        .iter()
        .filter(|e| matches!(e, MasterEvent::LeftOp { position, .. } if drives.contains(position)))
        .count();
    let (sync0_mean_ns, sync0_sd_ns, sync0_min_ns, sync0_max_ns, sync0_spread_max_ns) = sync0.figures();
    Ok(Row {
        method: method.to_string(),
        cycle_us,
        host: if simulated { o.host.name.to_string() } else { "real".to_string() },
        error_mean_ns: (err.n > 0 && !mfr).then(|| err.mean()),
        error_rms_ns: (err.n > 0 && !mfr).then(|| err.rms()),
        error_max_ns: (err.n > 0 && !mfr).then_some(err_max),
        phase_mean_ns: (err.n > 0 && mfr).then(|| err.mean()),
        phase_rms_ns: (err.n > 0 && mfr).then(|| err.rms()),
        phase_max_ns: (err.n > 0 && mfr).then_some(err_max),
        calibration_ns,
        sync0_mean_ns,
        sync0_sd_ns,
        sync0_min_ns,
        sync0_max_ns,
        sync0_spread_max_ns,
        late_setpoints: late,
        repeated_setpoints: repeated,
        late_cycles: tagged(&|s| &s.late_cycles),
        repeated_cycles: tagged(&|s| &s.repeated_cycles),
        max_following_error: following_error.iter().flatten().copied().reduce(f64::max),
        following_error,
        drives_enabled: enabled,
        axes: axis_rows,
        left_op,
        drives: drives.len(),
        processing_mean_us: (n_proc > 0)
            .then(|| stats.iter().flatten().map(|s| s.processing_sum_ns).sum::<f64>() / n_proc as f64 / 1e3),
        processing_max_us: (n_proc > 0)
            .then(|| stats.iter().flatten().map(|s| s.processing_max_ns).max().unwrap_or(0) as f64 / 1e3),
        move_s,
        cycles,
        frames_lost: r.st.lost - lost0,
        trace,
    })
}

/// The simulated axis the driver's `a` drives: the one whose objects sit where `a`'s do.
fn sim_axis<'d>(dr: &'d Cia402Drive, a: &Axis) -> Option<&'d ferrocat_esc::DriveAxis> {
    dr.axes().iter().find(|x| x.object_offset() == ferrocat_master::cia402::axis_offset(a.axis))
}

/// The true master–reference error now (simulator only): master − reference clock, or, where
/// the master follows, the reference's time off the cycle grid.
fn true_error_ns<I: World>(m: &mut Master<I>, mfr: bool, cycle_ns: u64) -> Option<f64> {
    if !mfr {
        return crate::clock_error_ns(m, 0).map(|e| e as f64);
    }
    let now = m.cyclic().now_ns();
    let rsys = m.io().segment()?.nodes.first()?.esc.dc.as_ref()?.system_at(now);
    let c = cycle_ns as i64;
    let ph = (rsys % cycle_ns) as i64;
    Some((if ph > c / 2 { ph - c } else { ph }) as f64)
}

/// Increments per revolution from 0x608F (encoder increments / motor revolutions), or the
/// model's 131 072 when the drive does not say.
fn increments_per_rev<I: World>(m: &mut Master<I>, d: u16, index: u16) -> f64 {
    let u32_of = |v: Vec<u8>| v.get(..4).map(|b| u32::from_le_bytes([b[0], b[1], b[2], b[3]]));
    let inc = m.acyclic().coe().sdo_read(d, index, 1).ok().and_then(u32_of).unwrap_or(0);
    let revs = m.acyclic().coe().sdo_read(d, index, 2).ok().and_then(u32_of).unwrap_or(0);
    if inc > 0 && revs > 0 {
        inc as f64 / revs as f64
    } else {
        131_072.0
    }
}

/// Sum over the drives of 0x1C32:0C (cycle time too small: late) and 0x1C32:0B (SM event
/// missed: repeated), when every drive has both.
fn sync_counters<I: World>(m: &mut Master<I>, drives: &[u16]) -> Option<(u64, u64)> {
    let mut sum = (0u64, 0u64);
    for &d in drives {
        let late = m.acyclic().coe().sdo_read(d, 0x1C32, 0x0C).ok()?;
        let missed = m.acyclic().coe().sdo_read(d, 0x1C32, 0x0B).ok()?;
        sum.0 += u16::from_le_bytes([*late.first()?, *late.get(1)?]) as u64;
        sum.1 += u16::from_le_bytes([*missed.first()?, *missed.get(1)?]) as u64;
    }
    Some(sum)
}

/// Every (cycle, method) run on the embedded virtual segment, in parallel; the same seed for all.
pub fn run(o: &Options) -> crate::Result<Vec<Row>> {
    if o.drives < 1 {
        return Err(LabError::NoDrives);
    }
    let cfg = segment_config(o)?;
    let jobs: Vec<(u64, String)> =
        o.cycles_us.iter().flat_map(|&c| o.methods.iter().map(move |m| (c, m.clone()))).collect();
    jobs.par_iter()
        .map(|(c, name)| {
            // ferrocat's methods know the simulated ESCs' closed-port loop-back, as in the lab.
            let m = crate::master(cfg.clone(), o.host, o.seed, name)?;
            // The host's GPIO wired to the reference's (the first DC slave's) LATCH0.
            let calibrate = |m: &mut Master<VirtualIo>, method: &str, pulses: usize| {
                let reference = *crate::dc_slaves(m).ok()?.first()?;
                crate::calibration(m, method, reference, pulses)
            };
            run_one(m, o, *c, name, &calibrate).map_err(|e| e.in_run(format!("{c} µs, {name}")))
        })
        .collect()
}

/// The same runs one after the other on masters `open` makes (a real network: the drives are
/// whatever the segment holds).
pub fn run_with<I: World>(o: &Options, open: &mut dyn FnMut() -> crate::Result<Master<I>>) -> crate::Result<Vec<Row>> {
    let mut rows = Vec::new();
    for &c in &o.cycles_us {
        for name in &o.methods {
            let m = open()?;
            rows.push(run_one(m, o, c, name, &|_, _, _| None).map_err(|e| e.in_run(format!("{c} µs, {name}")))?);
        }
    }
    Ok(rows)
}
