//! A CiA402 servo drive: a CoE device (its dictionary from an ESI file, an SII or built in)
//! whose application runs the profile's state machine, the PP/PV/HM/IP/CSP/CSV/CST modes and
//! a motor.
//!
//! Timing follows a drive's firmware: in DC mode the SYNC0 interrupt takes the newest output
//! buffer and latches the feedback; the application then needs a processing time drawn from a
//! configurable distribution (by default Paprocki & Erwiński 2022, Tables 3–4) before the new
//! set-point reaches the control loops and the inputs are published. A cycle whose SYNC0 found no
//! new buffer used a *repeated* set-point; a buffer overwritten before any SYNC0 took it was a
//! *late* set-point (it arrived after the SYNC0 it was meant for).
mod homing;
mod motor;
pub mod objects;

use std::any::Any;

use ferrocat_wire::cia402::{control, error_code, index as ix, status, Command, Mode, State};
use ferrocat_wire::coe::Emergency;
use ferrocat_wire::register::{AlState, AlStatusCode};
use rand::SeedableRng;
use rand_chacha::ChaCha8Rng;
use rand_distr::{Distribution, Gamma};

pub use homing::Switches;
pub use motor::{Demand, Mechanics, MotorParams};

use crate::app::{Application, Pdi};
use crate::coe_server::CoeDevice;
use crate::od::ObjectDictionary;
use crate::sync_monitor::SmSyncMonitor;
use objects::{get, get_unsigned, set};

/// How long the application takes from SYNC0 until the set-point reaches the control loops:
/// a gamma distribution above `min_ns` with the given mean and deviation, redrawn above
/// `max_ns`.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct ProcessingTime {
    pub mean_ns: f64,
    pub sd_ns: f64,
    pub min_ns: u64,
    pub max_ns: u64,
}

impl ProcessingTime {
    /// Paprocki & Erwiński 2022, Tables 3–4, the two drives averaged: the 1000 µs row for cycles
    /// of 750 µs and more, the 500 µs row below.
    pub fn paprocki2022(cycle_ns: u64) -> Self {
        if cycle_ns >= 750_000 {
            ProcessingTime { mean_ns: 51_465.0, sd_ns: 31_350.0, min_ns: 2_868, max_ns: 148_800 }
        } else {
            ProcessingTime { mean_ns: 76_250.0, sd_ns: 34_900.0, min_ns: 9_245, max_ns: 146_850 }
        }
    }

    /// Always the same time.
    pub fn fixed(ns: u64) -> Self {
        ProcessingTime { mean_ns: ns as f64, sd_ns: 0.0, min_ns: ns, max_ns: ns }
    }

    fn draw(&self, rng: &mut ChaCha8Rng) -> u64 {
        let above = self.mean_ns - self.min_ns as f64;
        if self.sd_ns <= 0.0 || above <= 0.0 {
            return self.min_ns.max(self.mean_ns as u64).min(self.max_ns.max(self.min_ns));
        }
        let shape = (above / self.sd_ns).powi(2);
        let Ok(g) = Gamma::new(shape, self.sd_ns * self.sd_ns / above) else { return self.mean_ns as u64 };
        for _ in 0..64 {
            let t = self.min_ns + g.sample(rng) as u64;
            if t <= self.max_ns {
                return t;
            }
        }
        self.max_ns
    }
}

/// What the drive saw, for the lab and the demo (the simulator's truth).
#[derive(Debug, Clone, Default, PartialEq)]
pub struct DriveStats {
    pub sync0_events: u64,
    /// Set-points overwritten before a SYNC0 took them.
    pub late_setpoints: u64,
    /// SYNC0 events that found no new set-point.
    pub repeated_setpoints: u64,
    /// The SYNC0 event numbers (counted from the last reset) of the first late and repeated
    /// set-points.
    pub late_cycles: Vec<u64>,
    pub repeated_cycles: Vec<u64>,
    /// Processing still running when the next SYNC0 came.
    pub overruns: u64,
    /// Largest |position demand − actual| (increments) in a position mode, operation enabled.
    pub max_following_error: f64,
    pub processing_count: u64,
    pub processing_sum_ns: f64,
    pub processing_sum_sq_ns: f64,
    pub processing_min_ns: u64,
    pub processing_max_ns: u64,
}

/// Cycle numbers kept per kind.
const KEEP_CYCLES: usize = 32;

impl DriveStats {
    pub fn processing_mean_ns(&self) -> f64 {
        self.processing_sum_ns / self.processing_count.max(1) as f64
    }
    pub fn processing_sd_ns(&self) -> f64 {
        let n = self.processing_count.max(1) as f64;
        (self.processing_sum_sq_ns / n - self.processing_mean_ns().powi(2)).max(0.0).sqrt()
    }
}

#[derive(Debug, Clone, Copy, Default)]
struct Feedback {
    pos: i32,
    vel: i32,
    torque: i16,
    following_error: i32,
}

#[derive(Debug, Clone)]
struct Pending {
    at_ns: u64,
    /// When the outputs were taken (SYNC0 or the SM event).
    taken_ns: u64,
    /// Per axis.
    feedback: Vec<Feedback>,
}

/// One straight piece of the CSP demand: from `from` at `t0_ns` to `to` one period later.
#[derive(Debug, Clone, Copy, Default)]
struct Segment {
    from: f64,
    to: f64,
    t0_ns: u64,
    period_ns: u64,
    acc: f64,
}

impl Segment {
    fn slope(&self) -> f64 {
        if self.period_ns == 0 {
            0.0
        } else {
            (self.to - self.from) / (self.period_ns as f64 * 1e-9)
        }
    }
    /// Position, velocity, acceleration at `t`; after the end it holds `to`.
    fn at(&self, t_ns: u64) -> (f64, f64, f64) {
        if self.period_ns == 0 || t_ns >= self.t0_ns + self.period_ns {
            return (self.to, 0.0, 0.0);
        }
        let f = t_ns.saturating_sub(self.t0_ns) as f64 / self.period_ns as f64;
        (self.from + (self.to - self.from) * f, self.slope(), self.acc)
    }
}

/// The position demand. CSP: the target taken at SYNC0 k is reached along a straight line
/// from the previous target over [SYNC0 k + T, SYNC0 k + 2T] (T the cycle): one cycle of
/// delay covers the processing time, and the demand stays continuous. PP: a trapezoidal
/// profile stepped with the control loop.
#[derive(Debug, Clone, Copy, Default)]
struct PositionDemand {
    now: Segment,
    next: Option<Segment>,
    /// Profile position: the target and the profile's velocity, acceleration, deceleration.
    pp_target: Option<f64>,
    pp_vel: f64,
    pp_limits: (f64, f64, f64),
}

impl PositionDemand {
    fn hold(at: f64) -> Self {
        PositionDemand { now: Segment { from: at, to: at, ..Default::default() }, ..Default::default() }
    }
    fn segment(&self, t_ns: u64) -> &Segment {
        match &self.next {
            Some(n) if t_ns >= n.t0_ns => n,
            _ => &self.now,
        }
    }
    fn at(&self, t_ns: u64) -> (f64, f64) {
        let (p, v, _) = self.segment(t_ns).at(t_ns);
        (p, v)
    }
    /// Makes the queued segment current once it has started.
    fn promote(&mut self, t_ns: u64) {
        if self.next.is_some_and(|n| t_ns >= n.t0_ns) {
            self.now = self.next.take().unwrap_or_default();
        }
    }
    /// Queues the line to `to` over [`t0_ns`, `t0_ns` + `period_ns`], from the last target, or
    /// (`from_demand`) from where the demand will stand at `t0_ns` — the same but where the
    /// line before has not ended by then (an interpolation period longer than the cycle).
    fn queue(&mut self, to: f64, t0_ns: u64, period_ns: u64, from_demand: bool) {
        if let Some(n) = self.next.take() {
            self.now = n;
        }
        let from = if from_demand { self.now.at(t0_ns).0 } else { self.now.to };
        let mut seg = Segment { from, to, t0_ns, period_ns, acc: 0.0 };
        seg.acc = (seg.slope() - self.now.slope()) / (period_ns.max(1) as f64 * 1e-9);
        self.next = Some(seg);
    }
    /// The last target (where the demand ends up).
    fn last_target(&self) -> f64 {
        self.next.map_or(self.now.to, |n| n.to)
    }
}

/// A CiA402 drive: one CoE device, one firmware cycle (SYNC0 or the SM event takes the outputs
/// of every axis, one processing time later the inputs of every axis are published), and one
/// or more axes.
#[derive(Debug)]
pub struct Cia402Drive {
    pub coe: CoeDevice,
    /// `None`: Paprocki 2022's figures for the SYNC0 cycle the drive runs at.
    pub processing: Option<ProcessingTime>,
    pub stats: DriveStats,
    rng: ChaCha8Rng,
    axes: Vec<DriveAxis>,
    op: bool,
    dc: bool,
    written: u64,
    taken: u64,
    pending: Option<Pending>,
    last_sync0_ns: Option<u64>,
    cycle_ns: u64,
    active_processing: ProcessingTime,
    /// The SM-synchronisation supervision in DC mode, where the dictionary has the SSC's 0x10F1
    /// (its limit 0x10F1:02).
    monitor: SmSyncMonitor,
}

/// One axis of a drive. Axis n's profile objects sit n × 0x800 above the first axis's (axis B's
/// controlword at 0x6840: CiA 402-2's multi-axis offset, as e.g. the STOBER SC6 manual lists
/// it), so that each axis runs its own state machine, mode and motor.
#[derive(Debug)]
pub struct DriveAxis {
    pub motor: MotorParams,
    /// Added to every profile index: n × 0x800 for axis n.
    base: u16,
    state: State,
    mode: Option<Mode>,
    mech: Mechanics,
    model_ns: Option<u64>,
    demand: PositionDemand,
    /// Quick-stop, fault-reaction or stopping ramp: velocity demand (increments/s) and
    /// deceleration.
    ramp: Option<(f64, f64)>,
    /// The state a shutdown or disable operation (option code 1) enters once its ramp ends.
    after_ramp: Option<State>,
    /// Interpolated position: bit 4 set and no halt, so the drive follows the set-points.
    ip_active: bool,
    /// Interpolated position halted: the demand ramps down from where halt found it.
    ip_halting: bool,
    prev_cw: u16,
    fault_code: u16,
    following_since_ns: Option<u64>,
    /// Controlword bit 4 as last seen (profile position takes a set-point on its rising edge,
    /// homing starts on it).
    pp_bit: bool,
    /// Profile velocity: the velocity demand ramping to the target (increments/s), and since
    /// when the actual velocity has been within the window of the target and below the
    /// threshold (ns).
    pv: f64,
    pv_in_window_since: Option<u64>,
    pv_still_since: Option<u64>,
    /// Target reached and speed zero, as last judged.
    pv_flags: (bool, bool),
    /// The user's position scale on the shaft: position actual = shaft position + offset
    /// (increments; homing sets it).
    offset: f64,
    homing: homing::Homing,
    /// Limit and home switches on the shaft (none unless set).
    switches: Switches,
    /// A limit switch stopping motion toward it, outside homing.
    limit_stop: Option<LimitStop>,
    /// Largest |position demand − actual| (increments) since the last reset.
    max_following_error: f64,
}

/// What one axis's part of a firmware cycle needs.
#[derive(Debug, Clone, Copy)]
struct Cycle {
    feedback: Feedback,
    /// When the outputs were taken (SYNC0 or the SM event).
    taken_ns: u64,
    now: u64,
    cycle_ns: u64,
}

/// A limit switch the shaft stands on stops motion toward it: a ramp at the quick-stop
/// deceleration (0x6085), then the shaft held where it stopped for as long as the demand points
/// that way; motion away is free, and statusword bit 11 (internal limit active) shows it. The
/// profile leaves the reaction to the manufacturer; this is the common "stop and block that
/// direction" (model choice). Homing reads the switches itself.
#[derive(Debug, Clone, Copy)]
struct LimitStop {
    /// The ramp's velocity demand (increments/s).
    vel: f64,
    /// Where the shaft is held once stopped (increments).
    hold: Option<f64>,
}

impl Cia402Drive {
    /// A drive over `od` with one axis per profile found in it (the objects each axis lacks
    /// are added); `seed` draws the shafts' starting positions and the processing times.
    pub fn new(mut od: ObjectDictionary, sm_count: u8, seed: u64) -> Self {
        let pt = ProcessingTime::paprocki2022(1_000_000);
        let bases = objects::axis_bases(&od);
        objects::complete_profile(&mut od, &bases, pt.max_ns as u32);
        let mut rng = ChaCha8Rng::seed_from_u64(seed ^ 0xC1A4_0200);
        let axes = bases
            .iter()
            .map(|&base| {
                // The first axis draws from the drive's stream (its figures stay as they were
                // with one axis); each other axis from a stream of its own.
                let start_rev = if base == 0 {
                    rand::Rng::gen_range(&mut rng, -4.0..4.0)
                } else {
                    let mut own = ChaCha8Rng::seed_from_u64(seed ^ 0xC1A4_0200 ^ ((base as u64) << 32));
                    rand::Rng::gen_range(&mut own, -4.0..4.0)
                };
                DriveAxis::new(&od, base, start_rev)
            })
            .collect();
        let mut d = Cia402Drive {
            coe: CoeDevice::new(od, sm_count, Box::new(crate::PassiveLogic)),
            processing: None,
            stats: DriveStats::default(),
            rng,
            axes,
            op: false,
            dc: false,
            written: 0,
            taken: 0,
            pending: None,
            last_sync0_ns: None,
            cycle_ns: 1_000_000,
            active_processing: pt,
            monitor: SmSyncMonitor::default(),
        };
        d.write_feedback();
        d
    }

    /// The drive's axes, the first at the profile's own indices.
    pub fn axes(&self) -> &[DriveAxis] {
        &self.axes
    }
    pub fn axes_mut(&mut self) -> &mut [DriveAxis] {
        &mut self.axes
    }
    /// The first axis's state (every drive has one).
    pub fn state(&self) -> State {
        self.axes[0].state
    }
    /// Gives the drive the ETG.1020 error settings (0x10F1) with this sync error counter
    /// limit, as the Slave Stack Code does: the SM-synchronisation supervision in DC mode.
    pub fn supervise_sync(&mut self, limit: u16) {
        objects::add_error_settings(&mut self.coe.od, limit);
    }
    /// The supervision's counter and flag, as the last OP left them.
    pub fn sync_monitor(&self) -> SmSyncMonitor {
        self.monitor
    }
    /// The first axis's mode.
    pub fn mode(&self) -> Option<Mode> {
        self.axes[0].mode
    }
    /// The first axis's motor.
    pub fn motor(&self) -> &MotorParams {
        &self.axes[0].motor
    }
    /// The first axis's shaft position (increments).
    pub fn position_increments(&self) -> f64 {
        self.axes[0].position_increments()
    }
    /// The first axis's shaft velocity (increments/s).
    pub fn velocity_increments(&self) -> f64 {
        self.axes[0].velocity_increments()
    }
    /// The first axis's position demand minus actual (increments).
    pub fn following_error_increments(&self) -> f64 {
        self.axes[0].following_error_increments()
    }
    /// The first axis's torque (N·m).
    pub fn torque_nm(&self) -> f64 {
        self.axes[0].torque_nm()
    }
    /// Whether the drive takes its set-points on SYNC0 (decided on entering OP).
    pub fn dc_synchronous(&self) -> bool {
        self.dc
    }

    /// Starts the statistics afresh.
    pub fn reset_stats(&mut self) {
        self.stats = DriveStats::default();
        for a in &mut self.axes {
            a.max_following_error = 0.0;
        }
    }

    /// Puts limit and home switches on the first axis's shaft.
    pub fn set_switches(&mut self, switches: Switches) {
        self.axes[0].switches = switches;
    }

    /// A fault raised by the device itself (over-current, under-voltage …) on the first axis:
    /// fault reaction, then FAULT, with an emergency message.
    pub fn inject_fault(&mut self, code: u16) {
        self.inject_axis_fault(0, code);
    }

    /// As [`Cia402Drive::inject_fault`], on axis `axis` (ignored where the drive has no such
    /// axis).
    pub fn inject_axis_fault(&mut self, axis: usize, code: u16) {
        if let Some(a) = self.axes.get_mut(axis) {
            a.enter_fault(&mut self.coe, code);
        }
    }

    fn feedback(&self) -> Vec<Feedback> {
        self.axes.iter().map(DriveAxis::feedback).collect()
    }

    fn write_feedback(&mut self) {
        for a in &self.axes {
            a.write_feedback(&mut self.coe.od, a.feedback());
        }
        self.write_counters();
    }

    fn write_counters(&mut self) {
        let od = &mut self.coe.od;
        set(od, 0x1C32, 0x0B, self.stats.repeated_setpoints.min(u16::MAX as u64) as i64);
        set(od, 0x1C32, 0x0C, self.stats.late_setpoints.min(u16::MAX as u64) as i64);
    }

    fn advance(&mut self, now: u64) {
        for a in &mut self.axes {
            a.advance(&mut self.coe, &mut self.stats, now);
        }
    }

    /// The application's work for one cycle, every axis, then the inputs published.
    fn complete(&mut self, pdi: &mut Pdi<'_>, feedback: Vec<Feedback>, taken_ns: u64) {
        let now = pdi.now_ns();
        for (a, feedback) in self.axes.iter_mut().zip(feedback) {
            let cycle = Cycle { feedback, taken_ns, now, cycle_ns: self.cycle_ns };
            a.complete(&mut self.coe, &mut self.stats, cycle);
        }
        self.write_counters();
        self.coe.publish_inputs(pdi);
    }

    /// SYNC0 or an SM event: take the newest outputs, latch the feedback, start processing.
    fn take(&mut self, pdi: &mut Pdi<'_>) {
        let now = pdi.now_ns();
        if let Some(p) = self.pending.take() {
            self.stats.overruns += 1;
            self.complete(pdi, p.feedback, p.taken_ns);
        }
        self.advance(now);
        if let Some((_, sm)) = pdi.process_data_sm(true, self.coe.sm_count) {
            let buf = pdi.read(sm.start, sm.length as usize).to_vec();
            self.coe.copy_outputs(&buf);
        }
        let t = self.active_processing.draw(&mut self.rng);
        let s = &mut self.stats;
        s.processing_count += 1;
        s.processing_sum_ns += t as f64;
        s.processing_sum_sq_ns += (t as f64).powi(2);
        s.processing_min_ns = if s.processing_count == 1 { t } else { s.processing_min_ns.min(t) };
        s.processing_max_ns = s.processing_max_ns.max(t);
        self.pending = Some(Pending { at_ns: now + t, taken_ns: now, feedback: self.feedback() });
    }
}

impl DriveAxis {
    fn new(od: &ObjectDictionary, base: u16, start_rev: f64) -> Self {
        let mut motor = MotorParams::default();
        let (inc, revs) = (get_unsigned(od, base + 0x608F, 1), get_unsigned(od, base + 0x608F, 2));
        if inc > 0 && revs > 0 {
            motor.increments_per_rev = inc as f64 / revs as f64;
        }
        // Wherever the shaft happens to stand at power-on: a CSP start must not jump to 0.
        let mut mech = Mechanics::default();
        mech.pos_rad = start_rev * std::f64::consts::TAU;
        let demand = PositionDemand::hold(mech.position_increments(&motor));
        DriveAxis {
            motor,
            base,
            state: State::SwitchOnDisabled,
            mode: None,
            mech,
            model_ns: None,
            demand,
            ramp: None,
            after_ramp: None,
            ip_active: false,
            ip_halting: false,
            prev_cw: 0,
            fault_code: 0,
            following_since_ns: None,
            pp_bit: false,
            pv: 0.0,
            pv_in_window_since: None,
            pv_still_since: None,
            pv_flags: (false, false),
            offset: 0.0,
            homing: homing::Homing::default(),
            switches: Switches::default(),
            limit_stop: None,
            max_following_error: 0.0,
        }
    }

    /// The offset of this axis's objects above the profile's (0 for the first axis).
    pub fn object_offset(&self) -> u16 {
        self.base
    }
    pub fn state(&self) -> State {
        self.state
    }
    pub fn mode(&self) -> Option<Mode> {
        self.mode
    }
    pub fn position_increments(&self) -> f64 {
        self.mech.position_increments(&self.motor)
    }
    pub fn velocity_increments(&self) -> f64 {
        self.mech.velocity_increments(&self.motor)
    }
    /// Position demand minus actual (increments) in a position mode with operation enabled.
    pub fn following_error_increments(&self) -> f64 {
        if !self.position_controlled() {
            return 0.0;
        }
        self.demand.at(self.model_ns.unwrap_or(0)).0 - self.mech.position_increments(&self.motor)
    }
    pub fn torque_nm(&self) -> f64 {
        self.mech.torque_nm
    }
    /// Largest |position demand − actual| (increments) in a position mode, operation enabled,
    /// since the drive's statistics were last reset.
    pub fn max_following_error(&self) -> f64 {
        self.max_following_error
    }
    /// Puts limit and home switches on the shaft (homing methods 1–14 and 17–30 use them, a
    /// limit switch stops motion toward it in the other modes; 0x60FD reports them).
    pub fn set_switches(&mut self, switches: Switches) {
        self.switches = switches;
    }

    /// Leaving OP takes the power away (the set-points stopped): switch on disabled.
    fn power_lost(&mut self) {
        if !matches!(self.state, State::Fault | State::FaultReactionActive) {
            self.state = State::SwitchOnDisabled;
        }
        (self.ramp, self.after_ramp) = (None, None);
    }

    fn enter_fault(&mut self, coe: &mut CoeDevice, code: u16) {
        if matches!(self.state, State::Fault | State::FaultReactionActive) {
            return;
        }
        self.fault_code = code;
        coe.emergency(Emergency { error_code: code, error_register: 0x01, data: [0; 5] });
        self.after_ramp = None;
        let powered = matches!(self.state, State::OperationEnabled | State::QuickStopActive);
        // 0x605E: 0 coasts (the power stage off at once), the others brake first.
        match self.stop_deceleration(&coe.od, get(&coe.od, self.base + ix::FAULT_REACTION_OPTION, 0)) {
            Some(dec) if powered => {
                self.state = State::FaultReactionActive;
                self.brake(dec);
            }
            _ => {
                self.ramp = None;
                self.state = State::Fault;
            }
        }
    }

    /// Starts a stopping ramp from the shaft's velocity at `dec` (increments/s²; infinite: at
    /// the current limit).
    fn brake(&mut self, dec: f64) {
        self.ramp = Some((self.mech.velocity_increments(&self.motor), dec));
    }

    /// How an option code (0x605A, 0x605E) stops the shaft: `None` coasts (0: disable the drive
    /// function), 1 and 5 at the profile deceleration (0x6084), 3, 4, 7 and 8 at the current
    /// (or voltage) limit — infinite: the most torque against the motion until the shaft stands
    /// — 2, 6 and manufacturer codes at the quick-stop deceleration (0x6085).
    fn stop_deceleration(&self, od: &ObjectDictionary, option: i64) -> Option<f64> {
        let dec = |index| get_unsigned(od, self.base + index, 0).max(1) as f64;
        match option {
            0 => None,
            1 | 5 => Some(dec(ix::PROFILE_DECELERATION)),
            3 | 4 | 7 | 8 => Some(f64::INFINITY),
            _ => Some(dec(ix::QUICK_STOP_DECELERATION)),
        }
    }

    /// How halt stops the shaft (0x605D), in increments/s²: 2 at the quick-stop
    /// deceleration, 3 and 4 at the current (voltage) limit — the most torque the drive may
    /// give (0x6072) over the inertia, a ramp the loops follow, so the drive stays enabled and
    /// holds where it stops — 1 and any other code at the profile deceleration.
    fn halt_deceleration(&self, od: &ObjectDictionary) -> f64 {
        match get(od, self.base + ix::HALT_OPTION, 0) {
            2 => get_unsigned(od, self.base + ix::QUICK_STOP_DECELERATION, 0).max(1) as f64,
            3 | 4 => {
                let per_rad = self.motor.increments_per_rev / std::f64::consts::TAU;
                (self.max_torque_nm(od) / self.motor.inertia_kg_m2 * per_rad).max(1.0)
            }
            _ => get_unsigned(od, self.base + ix::PROFILE_DECELERATION, 0).max(1) as f64,
        }
    }

    fn feedback(&self) -> Feedback {
        let pos = self.mech.position_increments(&self.motor);
        let (demand, _) = self.demand.at(self.model_ns.unwrap_or(0));
        let fe = if self.position_controlled() { demand - pos } else { 0.0 };
        let torque_pm = self.mech.torque_nm / self.motor.rated_torque_nm * 1000.0;
        Feedback {
            pos: (pos + self.offset).round() as i64 as i32,
            vel: self.mech.velocity_increments(&self.motor).round() as i32,
            torque: torque_pm.round().clamp(i16::MIN as f64, i16::MAX as f64) as i16,
            following_error: fe.round().clamp(i32::MIN as f64, i32::MAX as f64) as i32,
        }
    }

    fn position_controlled(&self) -> bool {
        // A stopping ramp (shutdown or disable operation, option 1) drives the velocity.
        self.state == State::OperationEnabled
            && self.ramp.is_none()
            && match self.mode {
                Some(Mode::CyclicSyncPosition | Mode::InterpolatedPosition | Mode::ProfilePosition) => true,
                // Homing holds the shaft while it is not moving it.
                Some(Mode::Homing) => !self.homing.moving(),
                _ => false,
            }
    }

    fn max_torque_nm(&self, od: &ObjectDictionary) -> f64 {
        let pm = get_unsigned(od, self.base + ix::MAX_TORQUE, 0);
        let pm = if pm == 0 { 3000 } else { pm };
        pm as f64 / 1000.0 * self.motor.rated_torque_nm
    }

    /// Runs the control loops up to `t_ns`.
    fn advance(&mut self, coe: &mut CoeDevice, stats: &mut DriveStats, t_ns: u64) {
        let Some(mut at) = self.model_ns else {
            self.model_ns = Some(t_ns);
            return;
        };
        let loop_ns = self.motor.loop_ns.max(1_000);
        let dt = loop_ns as f64 * 1e-9;
        let od = &coe.od;
        let max_torque = self.max_torque_nm(od);
        let window = get_unsigned(od, self.base + ix::FOLLOWING_ERROR_WINDOW, 0);
        let timeout_ns = get_unsigned(od, self.base + ix::FOLLOWING_ERROR_TIMEOUT, 0) * 1_000_000;
        while at + loop_ns <= t_ns {
            at += loop_ns;
            self.demand.promote(at);
            let demand = self.step_demand(&coe.od, at, dt);
            let demand = self.limit_guard(&coe.od, demand, dt);
            let before_rad = self.mech.pos_rad;
            self.mech.step(&self.motor, demand, max_torque, dt);
            if let Some(home_rad) = self.homing.track(before_rad, self.mech.pos_rad, &self.switches) {
                // The home position (an index pulse or a switch's edge) reads the home offset.
                let home = home_rad * self.motor.increments_per_rev / std::f64::consts::TAU;
                self.offset = get(&coe.od, self.base + ix::HOME_OFFSET, 0) as f64 - home;
            }
            if let Some((v, _)) = self.ramp {
                if v == 0.0 && self.mech.vel_rad_s.abs() < 0.05 {
                    self.ramp = None;
                    self.ramp_finished(&coe.od);
                }
            }
            if self.position_controlled() {
                let (d, _) = self.demand.at(at);
                let fe = (d - self.mech.position_increments(&self.motor)).abs();
                self.max_following_error = self.max_following_error.max(fe);
                stats.max_following_error = stats.max_following_error.max(fe);
                // Window 0xFFFFFFFF switches the check off (the profile's convention).
                if window != 0xFFFF_FFFF && fe > window as f64 {
                    let since = *self.following_since_ns.get_or_insert(at);
                    if at - since >= timeout_ns {
                        self.following_since_ns = None;
                        self.enter_fault(coe, error_code::FOLLOWING_ERROR);
                    }
                } else {
                    self.following_since_ns = None;
                }
            } else {
                let p = self.mech.position_increments(&self.motor);
                self.demand = PositionDemand::hold(p);
                self.following_since_ns = None;
            }
        }
        self.model_ns = Some(at);
    }

    fn step_demand(&mut self, od: &ObjectDictionary, at: u64, dt: f64) -> Demand {
        let max_torque = self.max_torque_nm(od);
        if let Some((v, dec)) = self.ramp.as_mut() {
            if dec.is_infinite() {
                // At the current limit: the most torque against the motion, no velocity loop
                // (whose integral would wind up and reverse the shaft), until it stands.
                if *v * self.mech.vel_rad_s > 0.0 {
                    return Demand::Torque(-v.signum() * max_torque);
                }
                *v = 0.0;
            }
            *v = if *v > 0.0 { (*v - *dec * dt).max(0.0) } else { (*v + *dec * dt).min(0.0) };
            return Demand::Velocity(*v);
        }
        if self.state != State::OperationEnabled {
            return Demand::Off;
        }
        let halt = get_unsigned(od, self.base + ix::CONTROLWORD, 0) as u16 & control::HALT != 0;
        match self.mode {
            // Halt in interpolated position: from the demand's position and velocity as halt
            // found them, down at 0x605D's deceleration, then held; released, the set-points
            // are approached from there (`queue_set_point` from the demand).
            Some(Mode::InterpolatedPosition) if halt => {
                let dec = self.halt_deceleration(od);
                let d = &mut self.demand;
                if !self.ip_halting {
                    self.ip_halting = true;
                    let (pos, vel, _) = d.segment(at).at(at);
                    *d = PositionDemand { pp_vel: vel, ..PositionDemand::hold(pos) };
                }
                d.pp_vel -= d.pp_vel.clamp(-dec * dt, dec * dt);
                d.now.to += d.pp_vel * dt;
                d.now.from = d.now.to;
                Demand::Position { pos: d.now.to, vel: d.pp_vel, acc: 0.0 }
            }
            Some(Mode::CyclicSyncPosition | Mode::InterpolatedPosition) => {
                self.ip_halting = false;
                let (pos, vel, acc) = self.demand.segment(at).at(at);
                Demand::Position { pos, vel, acc }
            }
            Some(Mode::ProfilePosition) => {
                // Halt stops the move as 0x605D says and keeps its target: released, the
                // move goes on to it.
                let halt_dec = if halt { self.halt_deceleration(od) } else { 0.0 };
                let d = &mut self.demand;
                if let Some(target) = d.pp_target {
                    let (vmax, acc, dec) = d.pp_limits;
                    let rest = target - d.now.to;
                    // Decelerate when the stopping distance reaches what is left.
                    let stopping = d.pp_vel * d.pp_vel / (2.0 * dec);
                    let want = if halt || rest.abs() <= stopping { 0.0 } else { vmax * rest.signum() };
                    let step = if halt {
                        halt_dec
                    } else if want.abs() < d.pp_vel.abs() {
                        dec
                    } else {
                        acc
                    } * dt;
                    d.pp_vel += (want - d.pp_vel).clamp(-step, step);
                    d.now.to += d.pp_vel * dt;
                    if !halt
                        && (target - d.now.to).abs() <= (d.pp_vel * dt).abs().max(0.5)
                        && d.pp_vel.abs() <= dec * dt * 2.0
                    {
                        d.now.to = target;
                        d.pp_vel = 0.0;
                        d.pp_target = None;
                    }
                    d.now.from = d.now.to;
                    d.now.period_ns = 0;
                }
                Demand::Position { pos: d.now.to, vel: d.pp_vel, acc: 0.0 }
            }
            Some(Mode::ProfileVelocity) => {
                // The target (or zero while halted), reached along the profile's ramps.
                let target = if halt { 0.0 } else { get(od, self.base + ix::TARGET_VELOCITY, 0) as f64 };
                let rising = target.abs() > self.pv.abs() && target * self.pv >= 0.0;
                let rate = if halt {
                    self.halt_deceleration(od)
                } else {
                    get_unsigned(
                        od,
                        self.base + if rising { ix::PROFILE_ACCELERATION } else { ix::PROFILE_DECELERATION },
                        0,
                    )
                    .max(1) as f64
                };
                self.pv += (target - self.pv).clamp(-rate * dt, rate * dt);
                Demand::Velocity(self.pv)
            }
            Some(Mode::Homing) if self.homing.moving() => Demand::Velocity(self.homing.step(dt)),
            Some(Mode::Homing) => {
                let (pos, vel, acc) = self.demand.segment(at).at(at);
                Demand::Position { pos, vel, acc }
            }
            Some(Mode::CyclicSyncVelocity) => Demand::Velocity(get(od, self.base + ix::TARGET_VELOCITY, 0) as f64),
            Some(Mode::CyclicSyncTorque) => {
                Demand::Torque(get(od, self.base + ix::TARGET_TORQUE, 0) as f64 / 1000.0 * self.motor.rated_torque_nm)
            }
            _ => Demand::Off,
        }
    }

    /// The demand, unless a limit switch blocks it (see [`LimitStop`]).
    fn limit_guard(&mut self, od: &ObjectDictionary, demand: Demand, dt: f64) -> Demand {
        let rad = self.mech.pos_rad;
        let neg = self.switches.active(homing::Switch::NegativeLimit, rad);
        let pos = self.switches.active(homing::Switch::PositiveLimit, rad);
        let free = self.state != State::OperationEnabled || self.mode == Some(Mode::Homing) || self.ramp.is_some();
        if free || !(neg || pos) {
            self.limit_stop = None;
            return demand;
        }
        let here = self.mech.position_increments(&self.motor);
        let from = self.limit_stop.and_then(|s| s.hold).unwrap_or(here);
        let toward = match demand {
            // A position demand is judged by where it lies, not by its feed-forward.
            Demand::Position { pos: p, .. } => p - from,
            Demand::Velocity(v) => v,
            Demand::Torque(t) => t,
            Demand::Off => 0.0,
        };
        if !((neg && toward < 0.0) || (pos && toward > 0.0)) {
            self.limit_stop = None;
            return demand;
        }
        let dec = get_unsigned(od, self.base + ix::QUICK_STOP_DECELERATION, 0).max(1) as f64;
        let vel = self.mech.velocity_increments(&self.motor);
        let s = self.limit_stop.get_or_insert(LimitStop { vel, hold: None });
        if s.hold.is_none() {
            if (neg && s.vel < 0.0) || (pos && s.vel > 0.0) {
                s.vel = if s.vel > 0.0 { (s.vel - dec * dt).max(0.0) } else { (s.vel + dec * dt).min(0.0) };
            } else {
                s.vel = 0.0;
            }
            if s.vel != 0.0 {
                self.pv = s.vel;
                return Demand::Velocity(s.vel);
            }
            s.hold = Some(here);
        }
        // Profile velocity's own ramp starts again from standstill once released.
        self.pv = 0.0;
        Demand::Position { pos: s.hold.unwrap_or(here), vel: 0.0, acc: 0.0 }
    }

    fn ramp_finished(&mut self, od: &ObjectDictionary) {
        if let Some(next) = self.after_ramp.take() {
            self.state = next;
            return;
        }
        match self.state {
            State::FaultReactionActive => self.state = State::Fault,
            // Option codes 0–4: then switch on disabled; 5–8: stay in quick stop active.
            State::QuickStopActive if !(5..=8).contains(&get(od, self.base + ix::QUICK_STOP_OPTION, 0)) => {
                self.state = State::SwitchOnDisabled;
            }
            _ => {}
        }
    }

    /// The device-control state machine, on a controlword the application took.
    fn control(&mut self, od: &ObjectDictionary, cw: u16) {
        use State::*;
        let reset_edge = cw & control::FAULT_RESET != 0 && self.prev_cw & control::FAULT_RESET == 0;
        self.prev_cw = cw;
        let cmd = Command::from_controlword(cw);
        let before = self.state;
        if self.after_ramp.is_some() && self.state == OperationEnabled {
            // Braking before a shutdown or disable operation: only a stronger command counts.
            match cmd {
                Command::DisableVoltage => {
                    (self.ramp, self.after_ramp) = (None, None);
                    self.state = SwitchOnDisabled;
                }
                Command::QuickStop => {
                    (self.ramp, self.after_ramp) = (None, None);
                    self.state = self.quick_stop(od);
                }
                _ => {}
            }
            return;
        }
        self.state = match (self.state, cmd) {
            (Fault, _) if reset_edge => {
                self.fault_code = 0;
                SwitchOnDisabled
            }
            (Fault | FaultReactionActive | NotReadyToSwitchOn, _) => self.state,
            (_, _) if cw & control::FAULT_RESET != 0 => self.state,
            (SwitchOnDisabled, Command::Shutdown) => ReadyToSwitchOn,
            (ReadyToSwitchOn, Command::SwitchOn) => SwitchedOn,
            // Transitions 3 and 4 in one step, as most drives allow.
            (ReadyToSwitchOn | SwitchedOn, Command::EnableOperation) => OperationEnabled,
            (OperationEnabled, Command::Shutdown) => self.stop_then(od, ix::SHUTDOWN_OPTION, ReadyToSwitchOn),
            (SwitchedOn, Command::Shutdown) => ReadyToSwitchOn,
            (OperationEnabled, Command::SwitchOn) => self.stop_then(od, ix::DISABLE_OPERATION_OPTION, SwitchedOn),
            (OperationEnabled, Command::QuickStop) => self.quick_stop(od),
            (QuickStopActive, Command::EnableOperation)
                if (5..=8).contains(&get(od, self.base + ix::QUICK_STOP_OPTION, 0)) && self.ramp.is_none() =>
            {
                OperationEnabled
            }
            (QuickStopActive, Command::DisableVoltage) => {
                self.ramp = None;
                SwitchOnDisabled
            }
            (ReadyToSwitchOn | SwitchedOn | OperationEnabled, Command::DisableVoltage | Command::QuickStop) => {
                SwitchOnDisabled
            }
            (s, _) => s,
        };
        if self.state == OperationEnabled && before != OperationEnabled {
            // Enabling starts from where the shaft stands: no jump.
            self.mech.reset_loops();
            self.demand = PositionDemand::hold(self.mech.position_increments(&self.motor));
        }
    }

    /// Transitions 5 and 8 (disable operation, shutdown) by their option code (0x605C, 0x605B):
    /// 1 brakes at the profile deceleration first, operation staying enabled until the shaft
    /// stands; 0 (and any other) takes the power away at once and the shaft coasts.
    fn stop_then(&mut self, od: &ObjectDictionary, option: u16, next: State) -> State {
        if get(od, self.base + option, 0) != 1 {
            return next;
        }
        let dec = get_unsigned(od, self.base + ix::PROFILE_DECELERATION, 0).max(1) as f64;
        self.brake(dec);
        self.after_ramp = Some(next);
        State::OperationEnabled
    }

    /// Transition 11 by 0x605A: a ramp then quick stop active, or (option 0) switch on disabled
    /// at once, the shaft coasting.
    fn quick_stop(&mut self, od: &ObjectDictionary) -> State {
        match self.stop_deceleration(od, get(od, self.base + ix::QUICK_STOP_OPTION, 0)) {
            Some(dec) => {
                self.brake(dec);
                State::QuickStopActive
            }
            None => State::SwitchOnDisabled,
        }
    }

    /// The interpolation period 0x60C2 gives (value × 10^index s), else the SYNC0 cycle.
    fn interpolation_period_ns(&self, od: &ObjectDictionary, cycle_ns: u64) -> u64 {
        let value = get_unsigned(od, self.base + ix::INTERPOLATION_TIME_PERIOD, 1);
        let index = get(od, self.base + ix::INTERPOLATION_TIME_PERIOD, 2);
        if value == 0 || !(-9..=0).contains(&index) {
            return cycle_ns.max(1);
        }
        value * 10u64.pow((9 + index) as u32)
    }

    /// The axis's part of the application's cycle: state machine, mode, new targets, inputs.
    fn complete(&mut self, coe: &mut CoeDevice, stats: &mut DriveStats, cycle: Cycle) {
        let Cycle { feedback, taken_ns, now, cycle_ns } = cycle;
        self.advance(coe, stats, now);
        let od = &coe.od;
        let cw = get_unsigned(od, self.base + ix::CONTROLWORD, 0) as u16;
        let mode_req = Mode::from_code(get(od, self.base + ix::MODES_OF_OPERATION, 0) as i8)
            .filter(|m| objects::MODES.contains(m));
        self.control(od, cw);
        if mode_req.is_some() && mode_req != self.mode {
            self.mode = mode_req;
            self.demand = PositionDemand::hold(self.mech.position_increments(&self.motor));
            self.ip_halting = false;
            // Profile velocity starts from the speed the shaft has; homing from the start.
            self.pv = self.mech.velocity_increments(&self.motor);
            self.homing = homing::Homing::default();
        }
        let bit4_rising = self.bit4_rising(cw);
        let braking = self.ramp.is_some();
        self.ip_active = self.state == State::OperationEnabled
            && !braking
            && self.mode == Some(Mode::InterpolatedPosition)
            && cw & control::ENABLE_IP_MODE != 0
            && cw & control::HALT == 0;
        if self.state == State::OperationEnabled && !braking {
            match self.mode {
                Some(Mode::CyclicSyncPosition) => {
                    let target = get(od, self.base + ix::TARGET_POSITION, 0) as i32;
                    let period = cycle_ns.max(1);
                    self.queue_set_point(target, taken_ns + period, period, false);
                }
                // Linear interpolation (0x60C0 = 0) over the period 0x60C2 gives, starting one
                // cycle after SYNC0 as CSP does, from where the demand stands then (a period
                // longer than the cycle: each set-point is approached, never jumped to); with
                // bit 4 clear (or halt) the set-points are ignored and the demand stops at the
                // last one.
                Some(Mode::InterpolatedPosition) if self.ip_active => {
                    let target = get(od, self.base + ix::INTERPOLATION_DATA, 1) as i32;
                    self.queue_set_point(
                        target,
                        taken_ns + cycle_ns.max(1),
                        self.interpolation_period_ns(od, cycle_ns),
                        true,
                    );
                }
                Some(Mode::ProfilePosition) if bit4_rising => {
                    let target = get(od, self.base + ix::TARGET_POSITION, 0) as f64;
                    let base = if cw & control::RELATIVE != 0 { self.demand.now.to } else { -self.offset };
                    let lim = |i| get_unsigned(od, self.base + i, 0).max(1) as f64;
                    self.demand.pp_target = Some(base + target);
                    self.demand.pp_limits =
                        (lim(ix::PROFILE_VELOCITY), lim(ix::PROFILE_ACCELERATION), lim(ix::PROFILE_DECELERATION));
                }
                Some(Mode::Homing) => self.homing_control(od, cw, bit4_rising),
                _ => {}
            }
        }
        self.watch_velocity(od, feedback.vel, now);
        self.write_feedback(&mut coe.od, feedback);
    }

    /// Queues a 32-bit position set-point (on the user's scale, unwrapped around the last one)
    /// as the line reached over [`t0_ns`, `t0_ns` + `period_ns`].
    fn queue_set_point(&mut self, target: i32, t0_ns: u64, period_ns: u64, from_demand: bool) {
        let last = self.demand.last_target() + self.offset;
        let to = last + target.wrapping_sub(last.round() as i64 as i32) as f64 - self.offset;
        self.demand.queue(to, t0_ns, period_ns, from_demand);
    }

    /// Profile velocity's two conditions, each of which must hold for its time (0x606E,
    /// 0x6070): the velocity within the window of the target, and below the threshold.
    fn watch_velocity(&mut self, od: &ObjectDictionary, vel: i32, now: u64) {
        let halt = get_unsigned(od, self.base + ix::CONTROLWORD, 0) as u16 & control::HALT != 0;
        let target = if halt { 0 } else { get(od, self.base + ix::TARGET_VELOCITY, 0) };
        let within = (vel as i64 - target).unsigned_abs() <= get_unsigned(od, self.base + ix::VELOCITY_WINDOW, 0);
        let still = (vel as i64).unsigned_abs() <= get_unsigned(od, self.base + ix::VELOCITY_THRESHOLD, 0);
        self.pv_in_window_since = within.then(|| self.pv_in_window_since.unwrap_or(now));
        self.pv_still_since = still.then(|| self.pv_still_since.unwrap_or(now));
        self.pv_flags = (
            self.pv_in_window_since
                .is_some_and(|t| now - t >= get_unsigned(od, self.base + ix::VELOCITY_WINDOW_TIME, 0) * 1_000_000),
            self.pv_still_since
                .is_some_and(|t| now - t >= get_unsigned(od, self.base + ix::VELOCITY_THRESHOLD_TIME, 0) * 1_000_000),
        );
    }

    /// Whether controlword bit 4 rose since the last cycle the application took (it is
    /// recorded every cycle, so that each new set-point or homing start is one edge).
    fn bit4_rising(&mut self, cw: u16) -> bool {
        let was = self.pp_bit;
        self.pp_bit = cw & control::NEW_SETPOINT != 0;
        self.pp_bit && !was
    }

    /// Homing mode's controlword: bit 4 rising starts the method, falling interrupts it, halt
    /// (bit 8) stops it.
    fn homing_control(&mut self, od: &ObjectDictionary, cw: u16, rising: bool) {
        use homing::Phase;
        let running = matches!(self.homing.phase, Phase::Searching { .. } | Phase::Stopping);
        if running && (cw & control::HOMING_START == 0 || cw & control::HALT != 0) {
            self.homing.phase = Phase::Interrupted;
            return;
        }
        if !rising || cw & control::HALT != 0 {
            return;
        }
        self.homing.acc = get_unsigned(od, self.base + ix::HOMING_ACCELERATION, 0).max(1) as f64;
        self.homing.switch_speed = get_unsigned(od, self.base + ix::HOMING_SPEEDS, 1).max(1) as f64;
        self.homing.zero_speed = get_unsigned(od, self.base + ix::HOMING_SPEEDS, 2).max(1) as f64;
        self.homing.phase = match homing::start(get(od, self.base + ix::HOMING_METHOD, 0)) {
            homing::Start::Here => {
                let here = self.mech.position_increments(&self.motor);
                self.offset = get(od, self.base + ix::HOME_OFFSET, 0) as f64 - here;
                Phase::Attained
            }
            homing::Start::Index(dir) => Phase::Searching { dir },
            homing::Start::Edge(edge) => homing::begin(edge, &self.switches, self.mech.pos_rad),
            homing::Start::Cam(first, edge) => homing::begin_cam(first, edge, &self.switches, self.mech.pos_rad),
            homing::Start::Unsupported => Phase::Error,
        };
    }

    fn write_feedback(&self, od: &mut ObjectDictionary, f: Feedback) {
        let mut sw = self.state.statusword_bits() | status::REMOTE;
        if matches!(
            self.state,
            State::ReadyToSwitchOn
                | State::SwitchedOn
                | State::OperationEnabled
                | State::QuickStopActive
                | State::FaultReactionActive
        ) {
            sw |= status::VOLTAGE_ENABLED;
        }
        if (self.mech.limited || self.limit_stop.is_some()) && self.state == State::OperationEnabled {
            sw |= status::INTERNAL_LIMIT;
        }
        let window = get_unsigned(od, self.base + ix::FOLLOWING_ERROR_WINDOW, 0);
        match (self.state, self.mode) {
            (State::OperationEnabled, Some(Mode::CyclicSyncPosition)) => {
                sw |= status::OP_SPECIFIC_12;
                if window != 0xFFFF_FFFF && f.following_error.unsigned_abs() as u64 > window {
                    sw |= status::OP_SPECIFIC_13;
                }
            }
            (State::OperationEnabled, Some(Mode::CyclicSyncVelocity | Mode::CyclicSyncTorque)) => {
                sw |= status::OP_SPECIFIC_12;
            }
            (State::OperationEnabled, Some(Mode::InterpolatedPosition)) => {
                if self.ip_active {
                    sw |= status::OP_SPECIFIC_12;
                }
                if window != 0xFFFF_FFFF && f.following_error.unsigned_abs() as u64 > window {
                    sw |= status::OP_SPECIFIC_13;
                }
                // Target reached: the demand stands at the last set-point (or where halt
                // stopped it), the shaft with it.
                let (at, vel) = self.demand.at(self.model_ns.unwrap_or(0));
                let stopping = self.ip_halting && self.demand.pp_vel != 0.0;
                if !stopping && vel == 0.0 && at == self.demand.last_target() && f.following_error.unsigned_abs() < 100
                {
                    sw |= status::TARGET_REACHED;
                }
            }
            (State::OperationEnabled, Some(Mode::ProfilePosition)) => {
                if self.pp_bit {
                    sw |= status::OP_SPECIFIC_12;
                }
                // Target reached, or halted and standing.
                let halted = get_unsigned(od, self.base + ix::CONTROLWORD, 0) as u16 & control::HALT != 0
                    && self.demand.pp_vel == 0.0;
                if (self.demand.pp_target.is_none() || halted) && f.following_error.unsigned_abs() < 100 {
                    sw |= status::TARGET_REACHED;
                }
            }
            (State::OperationEnabled, Some(Mode::ProfileVelocity)) => {
                // Target reached, and speed zero (the shaft stands).
                if self.pv_flags.0 {
                    sw |= status::TARGET_REACHED;
                }
                if self.pv_flags.1 {
                    sw |= status::OP_SPECIFIC_12;
                }
            }
            (State::OperationEnabled, Some(Mode::Homing)) => {
                let (error, attained, reached) = self.homing.status_bits();
                for (on, bit) in [
                    (error, status::OP_SPECIFIC_13),
                    (attained, status::OP_SPECIFIC_12),
                    (reached, status::TARGET_REACHED),
                ] {
                    if on {
                        sw |= bit;
                    }
                }
            }
            _ => {}
        }
        set(od, self.base + ix::STATUSWORD, 0, sw as i64);
        set(od, self.base + ix::MODES_OF_OPERATION_DISPLAY, 0, self.mode.map_or(0, |m| m.code()) as i64);
        set(od, self.base + ix::POSITION_ACTUAL, 0, f.pos as i64);
        set(od, self.base + ix::POSITION_ACTUAL_INTERNAL, 0, f.pos as i64);
        set(od, self.base + ix::VELOCITY_ACTUAL, 0, f.vel as i64);
        set(od, self.base + ix::TORQUE_ACTUAL, 0, f.torque as i64);
        set(od, self.base + ix::FOLLOWING_ERROR_ACTUAL, 0, f.following_error as i64);
        set(od, self.base + ix::ERROR_CODE, 0, self.fault_code as i64);
        set(od, self.base + ix::DIGITAL_INPUTS, 0, self.switches.inputs(self.mech.pos_rad) as i64);
    }
}

impl Application for Cia402Drive {
    fn check_transition(&mut self, pdi: &mut Pdi<'_>, from: AlState, to: AlState) -> Result<(), AlStatusCode> {
        self.coe.check_transition(pdi, from, to)?;
        if to == AlState::Op {
            let sync0 = pdi.read(0x0981, 1).first().is_some_and(|a| a & 0x03 == 0x03);
            let asked = get_unsigned(&self.coe.od, 0x1C32, 1) as u16;
            if asked == objects::SYNC_DC_SYNC0 && !sync0 {
                return Err(AlStatusCode::INVALID_DC_SYNC_CONFIG);
            }
            self.dc = sync0;
            let cycle = u32::from_le_bytes(pdi.read(0x09A0, 4).try_into().unwrap_or([0; 4])) as u64;
            if self.dc && cycle > 0 {
                self.cycle_ns = cycle;
            }
            self.active_processing = self.processing.unwrap_or(ProcessingTime::paprocki2022(self.cycle_ns));
            let od = &mut self.coe.od;
            set(od, 0x1C32, 1, if sync0 { objects::SYNC_DC_SYNC0 } else { objects::SYNC_SM } as i64);
            set(od, 0x1C32, 0x0A, if sync0 { cycle as i64 } else { 0 });
        }
        Ok(())
    }
    fn process_data_bytes(&self, sm: u8, outputs: bool) -> Option<u16> {
        self.coe.process_data_bytes(sm, outputs)
    }
    fn state_changed(&mut self, pdi: &mut Pdi<'_>, state: AlState) {
        let was_op = self.op;
        self.op = state == AlState::Op;
        if self.op && !was_op {
            // The limit as 0x10F1:02 holds it now (0 without the object: no supervision).
            self.monitor.on = self.coe.od.get(0x10F1).is_some();
            self.monitor.limit = get_unsigned(&self.coe.od, 0x10F1, 2).min(u16::MAX as u64) as u16;
            self.monitor.restart();
            for a in &mut self.axes {
                a.model_ns = Some(pdi.now_ns());
            }
            self.last_sync0_ns = None;
            self.taken = self.written;
        }
        if was_op && !self.op {
            // Leaving OP takes the power away (the set-points stopped): switch on disabled.
            self.pending = None;
            for a in &mut self.axes {
                a.power_lost();
            }
        }
        self.coe.state_changed(pdi, state);
        self.write_feedback();
        self.coe.publish_inputs(pdi);
    }
    fn outputs_written(&mut self, pdi: &mut Pdi<'_>, sm: u8) {
        self.written += 1;
        if self.op {
            self.monitor.outputs(pdi.now_ns(), self.dc.then_some(self.cycle_ns));
        }
        if self.op && !self.dc {
            self.take(pdi);
        } else if !self.op {
            let s = pdi.sm(sm);
            let buf = pdi.read(s.start, s.length as usize).to_vec();
            self.coe.copy_outputs(&buf);
        }
    }
    fn sync0(&mut self, pdi: &mut Pdi<'_>, _sys_ns: u64) {
        if !(self.op && self.dc) {
            return;
        }
        let now = pdi.now_ns();
        let s = &mut self.stats;
        if let Some(last) = self.last_sync0_ns {
            self.cycle_ns = now - last;
            let new = self.written - self.taken;
            if new == 0 {
                s.repeated_setpoints += 1;
                if s.repeated_cycles.len() < KEEP_CYCLES {
                    s.repeated_cycles.push(s.sync0_events);
                }
            } else if new > 1 {
                s.late_setpoints += new - 1;
                if s.late_cycles.len() < KEEP_CYCLES {
                    s.late_cycles.push(s.sync0_events);
                }
            }
        }
        s.sync0_events += 1;
        self.taken = self.written;
        self.last_sync0_ns = Some(now);
        self.monitor.pulse(now);
        set(&mut self.coe.od, 0x1C32, 0x20, self.monitor.sync_error as i64);
        self.take(pdi);
    }
    fn take_fault(&mut self) -> Option<AlStatusCode> {
        self.monitor.take_fault()
    }
    fn mailbox(&mut self, pdi: &mut Pdi<'_>, request: &[u8]) -> Option<Vec<u8>> {
        self.coe.mailbox(pdi, request)
    }
    fn pending_mailbox(&mut self) -> Option<Vec<u8>> {
        self.coe.pending_mailbox()
    }
    fn next_event_ns(&self) -> Option<u64> {
        self.pending.as_ref().map(|p| p.at_ns)
    }
    fn tick(&mut self, pdi: &mut Pdi<'_>) {
        if let Some(p) = self.pending.take() {
            self.complete(pdi, p.feedback, p.taken_ns);
        }
    }
    fn as_any(&self) -> &dyn Any {
        self
    }
    fn as_any_mut(&mut self) -> &mut dyn Any {
        self
    }
}
