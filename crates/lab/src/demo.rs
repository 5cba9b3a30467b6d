//! The demo: a coupler, I/O terminals and N CiA402 drives brought to OP with distributed clocks,
//! every drive enabled in cyclic synchronous position, and a synchronised jerk-limited move of
//! all axes out and back — once per clock-sync method and cycle time, on the same seed. What the
//! drives saw is the simulator's truth: their SYNC0 instants, late and repeated set-points,
//! following errors.
use ferrocat_esc::Cia402Drive;
use ferrocat_master::cia402::{Axis, Goal};
use ferrocat_master::io::{HostModel, Io, VirtualIo};
use ferrocat_master::sync::{ClockSync, Coupling};
use ferrocat_master::trajectory::{Limits, Move};
use ferrocat_master::{DcConfig, Master, SyncState};
use ferrocat_segment::SegmentConfig;
use ferrocat_wire::cia402::{index as ix, Mode};
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
            limits_rev: Limits { velocity: 20.0, acceleration: 200.0, jerk: 10_000.0 },
        }
    }
}

#[derive(Debug, Clone, Serialize, PartialEq)]
pub struct Row {
    pub method: String,
    pub cycle_us: u64,
    pub host: String,
    /// Master–reference error (ns) over the move: master clock minus reference clock where the
    /// reference follows the master; where the master follows, the reference's time at the
    /// master's cycle start off the cycle grid.
    pub error_mean_ns: f64,
    pub error_rms_ns: f64,
    pub error_max_ns: f64,
    /// Second drive's SYNC0 minus the first's for the same system time (Paprocki 2022, Table
    /// 2), and the largest spread of all drives' SYNC0 instants.
    pub sync0_mean_ns: f64,
    pub sync0_sd_ns: f64,
    pub sync0_min_ns: i64,
    pub sync0_max_ns: i64,
    pub sync0_spread_max_ns: u64,
    pub late_setpoints: u64,
    pub repeated_setpoints: u64,
    /// SYNC0 numbers (from the start of the move) of the first late and repeated set-points,
    /// as "drive:cycle".
    pub late_cycles: Vec<String>,
    pub repeated_cycles: Vec<String>,
    /// Largest |position demand − actual| of each axis (increments) and over all.
    pub following_error: Vec<f64>,
    pub max_following_error: f64,
    /// Drives in operation enabled at the end of the move.
    pub drives_enabled: usize,
    pub drives: usize,
    /// Application-layer time (SYNC0 to set-point in the loops), all drives: mean and max µs
    /// (Paprocki 2022, Tables 3–4).
    pub processing_mean_us: f64,
    pub processing_max_us: f64,
    pub move_s: f64,
    pub cycles: u64,
    pub frames_lost: u64,
    /// Every `trace_every`-th cycle: time (s), per axis set-point and actual (rev), error (ns).
    #[serde(skip)]
    pub trace: Vec<TracePoint>,
}

#[derive(Debug, Clone, PartialEq)]
pub struct TracePoint {
    pub t_s: f64,
    pub setpoint_rev: Vec<f64>,
    pub actual_rev: Vec<f64>,
    pub following_error: Vec<f64>,
    pub error_ns: f64,
}

struct Rig {
    m: Master<VirtualIo>,
    sync: Box<dyn ClockSync>,
    st: SyncState,
    cycle_ns: u64,
    next: u64,
}

impl Rig {
    fn step(&mut self) -> anyhow::Result<()> {
        self.m.cycle()?;
        let c = self.m.sync_step(self.sync.as_mut(), &mut self.st)?;
        self.next += c.next_period_ns.unwrap_or(self.cycle_ns);
        self.m.engine.io.sleep_until(self.next);
        Ok(())
    }

    fn drive(&self, k: usize) -> &Cia402Drive {
        self.m.engine.io.seg.nodes[k].esc.app().as_any().downcast_ref::<Cia402Drive>().expect("a drive")
    }
    fn drive_mut(&mut self, k: usize) -> &mut Cia402Drive {
        self.m.engine.io.seg.nodes[k].esc.app_mut().as_any_mut().downcast_mut::<Cia402Drive>().expect("a drive")
    }
}

/// The segment of the demo: EK1100, EL2004, EL1004, then the drives (`--device` syntax).
pub fn segment_config(o: &Options) -> anyhow::Result<SegmentConfig> {
    let mut cfg: SegmentConfig = toml::from_str(&format!(
        "seed = {}\ndrift_spread_ppm = 50.0\n[[device]]\nbuiltin = 'EK1100'\n[[device]]\nbuiltin = 'EL2004'\n\
         [[device]]\nbuiltin = 'EL1004'\n",
        o.seed
    ))?;
    let mut drive = SegmentConfig::from_device_args(std::slice::from_ref(&o.drive))?.devices.remove(0);
    drive.app = Some("cia402".into());
    cfg.devices.extend(std::iter::repeat_n(drive, o.drives));
    Ok(cfg)
}

/// Brings the demo segment up with DC and the drives' SYNC0 at half a cycle after the cycle
/// grid, prepares `method`, and aligns the master's first cycle with the grid.
fn rig(o: &Options, cycle_us: u64, method: &str) -> anyhow::Result<(Rig, Vec<u16>)> {
    let cycle_ns = cycle_us * 1000;
    let cfg = segment_config(o)?;
    let mut m = Master::new(VirtualIo::new(cfg.build()?, o.host, o.seed));
    m.scan()?;
    m.configure()?;
    let drives: Vec<u16> = (3..3 + o.drives as u16).collect();
    for &d in &drives {
        // What an integrator sets up in PREOP: a torque limit and a following-error window the
        // move needs (a vendor's defaults may be far tighter), where the drive has the objects.
        let _ = m.sdo_write(d, ix::MAX_TORQUE, 0, &3000u16.to_le_bytes());
        let _ = m.sdo_write(d, ix::FOLLOWING_ERROR_WINDOW, 0, &13_107u32.to_le_bytes());
    }
    let shift = (cycle_ns / 2) as i32;
    let report = m.init_dc(&DcConfig {
        sync0_cycle_ns: cycle_ns as u32,
        sync0_shift_ns: shift,
        sync0_slaves: Some(drives.clone()),
        start_delay_ns: 20_000_000,
        ..DcConfig::default()
    })?;
    m.start()?;
    let sync = crate::method(method, &mut m, cycle_ns, Coupling::ReferenceFollowsMaster)?;
    let st = m.sync_state()?;
    // The master's cycles on the grid: SYNC0 half a cycle after each frame leaves.
    let grid = report.sync0_start.unwrap_or(0).wrapping_sub(shift as u64);
    let sys = m.master_system_time();
    let now = m.engine.io.now_ns();
    // The first SYNC0 is still in the future: the phase is taken signed.
    let phase = (sys as i128 - grid as i128).rem_euclid(cycle_ns as i128) as u64;
    let next = now + (cycle_ns - phase);
    m.engine.io.sleep_until(next);
    Ok((Rig { m, sync, st, cycle_ns, next }, drives))
}

fn run_one(o: &Options, cycle_us: u64, method: &str) -> anyhow::Result<Row> {
    let (mut r, drives) = rig(o, cycle_us, method)?;
    let cycle_ns = r.cycle_ns;
    let mfr = r.sync.coupling() == Coupling::MasterFollowsReference;
    for _ in 0..(o.settle_s * 1e9 / cycle_ns as f64) as u64 {
        r.step()?;
    }
    let mut axes: Vec<Axis> = drives.iter().map(|&d| Axis::new(&r.m, d)).collect::<Result<_, _>>()?;
    for a in &mut axes {
        a.set_mode(&mut r.m, Mode::CyclicSyncPosition)?;
        a.set_goal(Goal::OperationEnabled);
    }
    // Enabling, with the clock sync running meanwhile.
    for k in 0.. {
        r.step()?;
        let mut ready = true;
        for a in &mut axes {
            a.update(&mut r.m);
            ready &= a.ready(&r.m);
        }
        if ready {
            break;
        }
        anyhow::ensure!(k < 5_000, "drives not enabled: {:?}", axes.iter().map(|a| a.state()).collect::<Vec<_>>());
    }
    let per_rev: Vec<f64> = drives.iter().map(|&d| r.drive(d as usize).motor.increments_per_rev).collect();
    let start: Vec<f64> = axes.iter().map(|a| a.position_actual(&r.m).unwrap_or(0) as f64).collect();
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
    for &d in &drives {
        r.drive_mut(d as usize).reset_stats();
    }
    let lost0 = r.st.lost;
    let mut err = Moments::default();
    let mut err_max = 0.0f64;
    let mut diffs = Moments::default();
    let (mut dmin, mut dmax, mut spread_max) = (i64::MAX, i64::MIN, 0u64);
    let mut last_sys = None;
    let mut sp = vec![0.0; axes.len()];
    let mut trace = Vec::new();
    let trace_every = (1_000_000 / cycle_ns).max(1);
    for k in 0..cycles {
        // One set-point per SYNC0: cycle k's is the profile at k cycles on the SYNC0 grid.
        let t = k as f64 * cycle_ns as f64 * 1e-9;
        let t_back = t - there.duration_s() - dwell_s;
        if t_back < 0.0 {
            there.positions(t, &mut sp);
        } else {
            back.positions(t_back, &mut sp);
        }
        for (a, p) in axes.iter().zip(&sp) {
            a.set_target_position(&mut r.m, p.round() as i64 as i32);
        }
        let e = if mfr {
            // The reference's time at the master's cycle start, off the grid.
            let c = cycle_ns as i64;
            let now = r.m.engine.io.now_ns();
            let rsys = r.m.engine.io.seg.nodes[0].esc.dc.as_ref().map(|d| d.system_at(now)).unwrap_or(0);
            let ph = (rsys % cycle_ns) as i64;
            (if ph > c / 2 { ph - c } else { ph }) as f64
        } else {
            crate::clock_error_ns(&mut r.m, 0) as f64
        };
        err.push(e);
        err_max = err_max.max(e.abs());
        r.step()?;
        for a in &mut axes {
            a.update(&mut r.m);
        }
        // SYNC0 simultaneity: the drives' pulses for the same system time.
        let nodes = &r.m.engine.io.seg.nodes;
        if let Some(&(s1, t1)) = nodes[drives[0] as usize].esc.sync0_log.pulses.back() {
            if last_sys != Some(s1) {
                let ts: Vec<u64> = drives
                    .iter()
                    .filter_map(|&d| {
                        nodes[d as usize].esc.sync0_log.pulses.iter().rev().find(|(s, _)| *s as u32 == s1 as u32)
                    })
                    .map(|&(_, t)| t)
                    .collect();
                if ts.len() == drives.len() {
                    last_sys = Some(s1);
                    if let Some(&t2) = ts.get(1) {
                        let d = t2 as i64 - t1 as i64;
                        diffs.push(d as f64);
                        dmin = dmin.min(d);
                        dmax = dmax.max(d);
                    }
                    let (lo, hi) = (ts.iter().min().copied().unwrap_or(0), ts.iter().max().copied().unwrap_or(0));
                    spread_max = spread_max.max(hi - lo);
                }
            }
        }
        if k % trace_every == 0 {
            let mut p = TracePoint {
                t_s: t,
                setpoint_rev: sp.iter().zip(&per_rev).map(|(s, p)| s / p).collect(),
                actual_rev: Vec::new(),
                following_error: Vec::new(),
                error_ns: e,
            };
            for (i, &d) in drives.iter().enumerate() {
                let dr = r.drive(d as usize);
                p.actual_rev.push(dr.position_increments() / per_rev[i]);
                p.following_error.push(dr.following_error_increments());
            }
            trace.push(p);
        }
    }
    let stats: Vec<_> = drives.iter().map(|&d| r.drive(d as usize).stats.clone()).collect();
    let tagged = |f: &dyn Fn(&ferrocat_esc::DriveStats) -> &Vec<u64>| -> Vec<String> {
        let mut v: Vec<String> = stats
            .iter()
            .enumerate()
            .flat_map(|(i, s)| f(s).iter().map(move |c| format!("{}:{c}", i + 1)).collect::<Vec<_>>())
            .collect();
        v.truncate(8);
        v
    };
    let n_proc: u64 = stats.iter().map(|s| s.processing_count).sum();
    let following_error: Vec<f64> = stats.iter().map(|s| s.max_following_error).collect();
    let enabled = drives
        .iter()
        .filter(|&&d| r.drive(d as usize).state() == ferrocat_wire::cia402::State::OperationEnabled)
        .count();
    Ok(Row {
        method: method.to_string(),
        cycle_us,
        host: o.host.name.to_string(),
        error_mean_ns: err.mean(),
        error_rms_ns: err.rms(),
        error_max_ns: err_max,
        sync0_mean_ns: diffs.mean(),
        sync0_sd_ns: (diffs.rms().powi(2) - diffs.mean().powi(2)).max(0.0).sqrt(),
        sync0_min_ns: if diffs.n > 0 { dmin } else { 0 },
        sync0_max_ns: if diffs.n > 0 { dmax } else { 0 },
        sync0_spread_max_ns: spread_max,
        late_setpoints: stats.iter().map(|s| s.late_setpoints).sum(),
        repeated_setpoints: stats.iter().map(|s| s.repeated_setpoints).sum(),
        late_cycles: tagged(&|s| &s.late_cycles),
        repeated_cycles: tagged(&|s| &s.repeated_cycles),
        max_following_error: following_error.iter().copied().fold(0.0, f64::max),
        following_error,
        drives_enabled: enabled,
        drives: drives.len(),
        processing_mean_us: stats.iter().map(|s| s.processing_sum_ns).sum::<f64>() / n_proc.max(1) as f64 / 1e3,
        processing_max_us: stats.iter().map(|s| s.processing_max_ns).max().unwrap_or(0) as f64 / 1e3,
        move_s,
        cycles,
        frames_lost: r.st.lost - lost0,
        trace,
    })
}

/// Every (cycle, method) run, in parallel; the same seed for all.
pub fn run(o: &Options) -> anyhow::Result<Vec<Row>> {
    anyhow::ensure!(o.drives >= 1, "at least one drive");
    let jobs: Vec<(u64, String)> =
        o.cycles_us.iter().flat_map(|&c| o.methods.iter().map(move |m| (c, m.clone()))).collect();
    jobs.par_iter()
        .map(|(c, name)| run_one(o, *c, name).map_err(|e| anyhow::anyhow!("{c} µs, {name}: {e:#}")))
        .collect()
}
