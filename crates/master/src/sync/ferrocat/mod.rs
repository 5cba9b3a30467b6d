//! ferrocat's own method (design and measurements: docs/clock-sync.md), composed of an
//! estimate of the reference's clock (`estimator`), a steering law that acts on it (the
//! reference's offset, `offset`; its time control loop; or the master's period, `schedule`),
//! and options.
mod estimator;
mod offset;
mod schedule;

use super::{ClockSync, Correction, Coupling, CyclePlan, LineEvents, ReferenceSteering, Sample, MAX_CYCLE_NS};
use crate::trimmed::TrimmedWindow;
use estimator::Estimator;
pub use estimator::{DENSE_FIT_WINDOW, FIT_WINDOW};
use offset::OffsetSteer;
use schedule::Schedule;

/// ferrocat's method. Every cycle's round trip gives a fresh estimate of how long a frame
/// takes from being built to passing the reference (transmit and receive stamps where the
/// link has them); a trimmed mean over a short window rejects the outliers of a busy host
/// without the settling time of a long average.
/// - Master follows reference: a least-squares line through (master time at passage,
///   reference time) gives offset and rate (`LineFit`: its window grows to 16 384 points
///   while the points agree with it, leaves single outliers out, and restarts when a CUSUM
///   of its innovations sees the rate or phase change); the master's clock is that line
///   (its estimate of the reference's time), and the next period puts the frame at
///   the start of the reference's cycle, removing 1/16 of the phase error per cycle (the
///   phase of the cycle's planned start plus the mean lateness: the host's jitter is not
///   chased). The passage is the transmit stamp plus half the round trip where the link
///   stamps sends, so that the send jitter, known after the fact, stays out of the line.
/// - Reference follows master ([`Steering::Offset`], the default): the same line, through
///   the reference's local time (its time read less the offset the same frame read), and
///   each frame gives the reference the offset that puts its system time on the master's
///   half a cycle after the frame's expected passage. A late send moves that passage, but
///   the offset wanted changes only at the crystals' rate difference (50 ppm: 10 ns for
///   200 µs late). The price: between frames the reference runs at its crystal's rate, a
///   sawtooth of |rate − 1|·cycle (50 ns at 50 ppm and 1 ms). The followers' loops lock to
///   the reference's time as the frame reads it, the sawtooth's top; every follower's delay
///   register gets −(rate − 1)·cycle/2 on top of its measured delay, which moves it to the
///   middle (see [`ReferenceSteering::follower_delay_bias_ns`]).
/// - Reference follows master ([`Steering::TimeControlLoop`]): the master writes its time plus
///   that lead into 0x0910, so the reference's time control loop steers to the master's time
///   at the instant the frame passes; a late send is a sample off by its lateness.
#[derive(Debug)]
pub struct Ferrocat {
    law: Law,
    options: Options,
    /// The cycle, ns.
    cycle_ns: u64,
    /// The estimate of the reference's clock.
    line: Estimator,
    leads: TrimmedWindow,
    lead_ns: Option<i64>,
    /// How much later than it was the stamps put the frame's passage of the reference, as a
    /// calibration found it (half the stamps' receive/transmit asymmetry; with the reference
    /// following, also the bias its time control loop adds to a jittery master): taken out of
    /// every passage, as linuxptp's `delayAsymmetry` is.
    calibration_ns: i64,
}

/// How the method acts on its estimate: who follows whom, and through what.
#[derive(Debug)]
enum Law {
    /// The reference follows the master through its System_Time_Offset.
    Offset(OffsetSteer),
    /// The reference follows the master through its time control loop (0x0910): no line.
    TimeControlLoop,
    /// The master follows the reference, through its own period.
    Period(Schedule),
}

/// How a method makes the reference follow the master.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Steering {
    /// Replace the reference's System_Time_Offset (0x0920) each cycle.
    Offset,
    /// Write the master's time into the reference's 0x0910, a sample of its time control loop.
    TimeControlLoop,
}

/// ferrocat's options. Each is a choice the lab measured; the defaults are what it chose
/// (docs/clock-sync.md, "Probing" and "Reference follows master").
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct Options {
    /// When to probe the reference with extra frames.
    pub probing: Probing,
    /// Offset steering: what the followers' delay registers carry.
    pub followers: FollowerDelays,
    /// Offset steering: what follows a lost cycle's frame.
    pub lost_frames: LostFrames,
    /// Offset steering: what the probe frames do besides reading the reference.
    pub probes: ProbeFrames,
}

impl Default for Options {
    fn default() -> Self {
        Options {
            probing: Probing::WhenUncertain,
            followers: FollowerDelays::Centred,
            lost_frames: LostFrames::MakeUp,
            probes: ProbeFrames::Steer,
        }
    }
}

/// When the method probes the reference with extra frames after the cycle's.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Probing {
    /// Never: one point per cycle.
    Off,
    /// While the line's value a cycle ahead is uncertain (in half of the cycle) or its change
    /// test is suspicious (in a quarter).
    WhenUncertain,
    /// In half of every cycle, however certain the line: many times the frames, for a line of
    /// many more points that shows a change sooner (`Ferrocat::dense`).
    EveryCycle,
}

/// What the followers' System_Time_Delay registers carry, steering the reference's offset.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum FollowerDelays {
    /// Their measured delays: the followers lock to the top of the reference's sawtooth.
    Measured,
    /// Their delays less (rate − 1)·cycle/2: the followers sit in the middle of it.
    Centred,
}

/// What follows a lost cycle's frame, steering the reference's offset.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum LostFrames {
    /// Nothing: the reference runs on its crystal's rate for two cycles, twice the sawtooth.
    Wait,
    /// A frame at once that gives the reference its offset.
    MakeUp,
}

/// What the probe frames do, steering the reference's offset.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum ProbeFrames {
    /// Read the reference's time and offset only.
    ReadOnly,
    /// Give the reference its offset from the line they update too, so that a change the
    /// line sees is in force at once, not a cycle later.
    Steer,
}

/// The cycle's frames' round trips are averaged over this many.
const WINDOW: usize = 64;

/// Probing: extra frames while the line's value one cycle ahead is less certain than this
/// many noise scales — what a settled window of 4096 points gives at its end (2/√4096); the
/// full window is at 1/64 and does not probe. Steering the reference's offset leaves it a
/// sawtooth of up to half the 100 ns band after a crystal step, so the line must get back to
/// a few ns, not a few dozen (1/16 left beaglebone-rt outside its band for up to 0.5 s)…
const PROBE_TARGET_SCALES: f64 = 1.0 / 32.0;
/// …or while the line's change test is this far towards restarting it (a change shows sooner
/// in more points)…
const PROBE_SUSPICION: f64 = 0.25;
/// …at most this many per cycle, in at most half of it while the line is uncertain (a quarter
/// while it is only suspicious: a few points confirm a change or dismiss it). A line restarted
/// at a crystal step knows the phase to about 2σ/√n after n points, so the points per cycle
/// set how soon it is back: with a quarter cycle (5 probes on beaglebone-rt, σ ≈ 500 ns) it
/// was still ≈ 30 ns off 100 ms after a 50 ppm step, which on top of the reference's ±42 ns
/// sawtooth then left the 100 ns band in 3 of 10 realisations (docs/clock-sync.md, "Probing").
const MAX_PROBES: u64 = 32;

impl Ferrocat {
    /// ferrocat's method with `coupling` on a cycle of `cycle_ns`, steering the reference's
    /// offset where it follows, its line through the reference's own points (see
    /// [`Ferrocat::with_flywheel`]).
    pub fn new(coupling: Coupling, cycle_ns: u64) -> Self {
        Ferrocat::with_window(coupling, cycle_ns, FIT_WINDOW)
    }

    /// ferrocat probing in half of every cycle, with a window long enough for that many points.
    pub fn dense(coupling: Coupling, cycle_ns: u64) -> Self {
        let mut f = Ferrocat::with_window(coupling, cycle_ns, DENSE_FIT_WINDOW);
        f.options.probing = Probing::EveryCycle;
        f
    }

    fn with_window(coupling: Coupling, cycle_ns: u64, window: usize) -> Self {
        let cycle_ns = cycle_ns.clamp(1, MAX_CYCLE_NS);
        let law = match coupling {
            Coupling::ReferenceFollowsMaster => Law::Offset(OffsetSteer::default()),
            Coupling::MasterFollowsReference => Law::Period(Schedule::new(cycle_ns)),
        };
        Ferrocat {
            law,
            options: Options::default(),
            cycle_ns,
            line: Estimator::new(window, cycle_ns),
            leads: TrimmedWindow::new(WINDOW),
            lead_ns: None,
            calibration_ns: 0,
        }
    }

    /// ferrocat whose line runs on a follower's crystal, the reference's difference from it
    /// read from the hardware every cycle (flywheel.rs).
    pub fn with_flywheel(self) -> Self {
        Ferrocat { line: self.line.with_flywheel(), ..self }
    }

    /// The reference following through `steering` (the master following the reference
    /// steers its own period whatever this says).
    pub fn with_steering(self, steering: Steering) -> Self {
        let law = match (self.law, steering) {
            (Law::Period(s), _) => Law::Period(s),
            (Law::Offset(o), Steering::Offset) => Law::Offset(o),
            (Law::TimeControlLoop, Steering::Offset) => Law::Offset(OffsetSteer::default()),
            (_, Steering::TimeControlLoop) => Law::TimeControlLoop,
        };
        Ferrocat { law, ..self }
    }

    /// Its options.
    pub fn options(&self) -> Options {
        self.options
    }

    /// Its options, to change.
    pub fn options_mut(&mut self) -> &mut Options {
        &mut self.options
    }

    /// Master follows reference: the reference-time phase (ns into its cycle) of the SYNC0
    /// the frames serve, `None` for unknown. A frame whose process data ended after it (a
    /// late wake-up or send) is consumed a SYNC0 late; the next frame is then held back one
    /// cycle so that it does not overwrite it before then: the slaves repeat one cycle
    /// instead of repeating one and losing the next. No effect where the reference follows.
    pub fn set_sync0_phase_ns(&mut self, phase_ns: Option<u64>) {
        if let Law::Period(s) = &mut self.law {
            s.sync0_phase_ns = phase_ns;
        }
    }

    /// Master follows reference: frames held back after a late one so far.
    pub fn held_back(&self) -> u64 {
        match &self.law {
            Law::Period(s) => s.held_back,
            _ => 0,
        }
    }

    /// What calibrations have taken out of every passage, ns.
    pub fn calibration_ns(&self) -> i64 {
        self.calibration_ns
    }

    /// The lead in use (None before the first sample).
    pub fn lead_ns(&self) -> Option<i64> {
        self.lead_ns
    }

    /// With a flywheel: the reference's time of the last frame that read the follower, and
    /// the ε = reference − follower's crystal it measured (ns).
    pub fn flywheel_eps(&self) -> Option<(u64, i64)> {
        self.line.flywheel_eps()
    }

    /// Whether the method keeps its line (not when it steers the reference's time control loop).
    fn keeps_line(&self) -> bool {
        !matches!(self.law, Law::TimeControlLoop)
    }

    /// Reference-follows-master, steering the reference's System_Time_Offset.
    fn steers_reference_offset(&self) -> bool {
        matches!(self.law, Law::Offset(_))
    }

    /// The reference's time the line takes from `s`: its system time where the master follows
    /// it; steering its offset, its local time (what it would read with the offset it had at
    /// the start), where the frame read the offset.
    fn line_point(&self, s: &Sample) -> Option<u64> {
        match self.law {
            Law::Period(_) => Some(s.reference_ns),
            Law::Offset(_) => s.reference_offset_ns.map(|o| s.reference_ns.wrapping_sub(o)),
            Law::TimeControlLoop => None,
        }
    }

    /// Offers the point (passage of `s`, `y`) to the line; steering by offset, a move of the
    /// estimate in use moves the reference at its next offset.
    fn take_point(&mut self, s: &Sample, y: u64) -> u64 {
        let passage = self.line.push(s, y, self.calibration_ns);
        if let Law::Offset(o) = &mut self.law {
            o.estimate_moved(passage.jump_ns);
        }
        passage.x_ns
    }

    /// How many probes the line wants after this cycle's frame.
    fn probes_wanted(&self) -> u32 {
        let fit = self.line.fit();
        let (Some(sd), Some(lead)) = (fit.sd_ahead_ns(self.cycle_ns), self.lead_ns) else { return 0 };
        let uncertain = sd > fit.scale_ns() * PROBE_TARGET_SCALES;
        let half_cycle = uncertain || self.options.probing == Probing::EveryCycle;
        if self.options.probing == Probing::Off
            || !self.keeps_line()
            || !(half_cycle || fit.suspicion() >= PROBE_SUSPICION)
        {
            return 0;
        }
        // A probe costs about a round trip and the send before it: twice the lead. One probe's
        // worth of the budget is kept as slack for a late reply.
        let cost_ns = lead.saturating_mul(2).max(1) as u64;
        let budget_ns = if half_cycle { self.cycle_ns / 2 } else { self.cycle_ns / 4 };
        (budget_ns / cost_ns).saturating_sub(1).min(MAX_PROBES) as u32
    }
}

impl ClockSync for Ferrocat {
    fn name(&self) -> &'static str {
        "ferrocat"
    }
    fn coupling(&self) -> Coupling {
        match self.law {
            Law::Period(_) => Coupling::MasterFollowsReference,
            _ => Coupling::ReferenceFollowsMaster,
        }
    }
    fn reference_time(&mut self, built_ns: u64) -> u64 {
        built_ns.wrapping_add_signed(self.lead_ns.unwrap_or(0))
    }
    fn plan(&self, _cycle: u64) -> CyclePlan {
        let steer = self.steers_reference_offset();
        CyclePlan {
            write_reference_time: true,
            steer_reference_offset: steer,
            read_follower_clock: self.line.has_flywheel() && self.keeps_line(),
            probes: self.probes_wanted(),
            probe_window_ns: self.cycle_ns,
            probes_give_offset: self.options.probes == ProbeFrames::Steer && steer,
            // Steering by offset, a lost frame leaves the reference on its crystal's rate for
            // two cycles instead of one: twice the sawtooth.
            make_up_lost_frames: self.options.lost_frames == LostFrames::MakeUp && steer,
        }
    }
    fn update(&mut self, s: Option<&Sample>) -> Correction {
        let Some(s) = s else {
            return match &mut self.law {
                Law::Period(schedule) => schedule.lost(),
                _ => Correction::default(),
            };
        };
        self.leads.push(s.lead_ns());
        self.lead_ns = Some(self.leads.trimmed_mean().wrapping_sub(self.calibration_ns));
        match self.law {
            Law::Offset(_) | Law::TimeControlLoop => {
                if let Some(y) = self.line_point(s) {
                    if let Law::Offset(o) = &mut self.law {
                        o.offset_read = s.reference_offset_ns;
                    }
                    self.take_point(s, y);
                }
                let shift_offsets_ns = match &mut self.law {
                    Law::Offset(o) => o.take_shift(),
                    _ => 0,
                };
                Correction { shift_offsets_ns, next_period_ns: None }
            }
            Law::Period(_) => {
                let dev = match &mut self.law {
                    Law::Period(schedule) => schedule.lateness_deviation(s.built_ns),
                    _ => 0,
                };
                let x = self.take_point(s, s.reference_ns);
                let Law::Period(schedule) = &mut self.law else { return Correction::default() };
                schedule.period_after(s, x, dev, &self.line)
            }
        }
    }
    fn master_time(&self, host_ns: u64) -> Option<u64> {
        match self.law {
            Law::Period(_) => self.line.at(host_ns),
            _ => None,
        }
    }
    fn reference_belief_ns(&self, host_ns: u64) -> u64 {
        match &self.law {
            Law::Offset(o) => o.belief_ns(host_ns, &self.line).unwrap_or(host_ns),
            _ => self.master_time(host_ns).unwrap_or(host_ns),
        }
    }
    fn reference_steering(&mut self) -> Option<&mut dyn ReferenceSteering> {
        Some(self)
    }
}

impl ReferenceSteering for Ferrocat {
    fn reference_offset(&mut self, built_ns: u64, holds_ns: Option<u64>) -> Option<u64> {
        let lead_ns = self.lead_ns?;
        let Law::Offset(o) = &mut self.law else { return None };
        o.give(built_ns, holds_ns, lead_ns, self.cycle_ns, &self.line)
    }
    fn probe(&mut self, s: &Sample) {
        if let Some(y) = self.line_point(s) {
            self.take_point(s, y);
        }
    }
    fn take_error(&mut self, error_ns: i64) -> bool {
        // The master (or its estimate of the reference) is ahead by `error_ns`: the passages
        // were that much earlier than the stamps said. Past passages move at once too.
        self.calibration_ns = self.calibration_ns.saturating_sub(error_ns);
        self.lead_ns = self.lead_ns.map(|l| l.wrapping_add(error_ns));
        self.line.shift_x(error_ns);
        if let Law::Offset(o) = &mut self.law {
            o.master_moved(error_ns);
        }
        true
    }
    fn line_events(&self) -> Option<LineEvents> {
        self.keeps_line().then(|| self.line.events())
    }
    fn follower_delay_bias_ns(&mut self) -> Option<i64> {
        if self.options.followers != FollowerDelays::Centred {
            return None;
        }
        let Law::Offset(o) = &mut self.law else { return None };
        o.follower_delay_bias_ns(&self.line, self.cycle_ns)
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::sync::tests::sample;
    use schedule::SLOT_SLIP_RUN;

    /// Cycle `k`'s frame, built at `built_ns` on a master whose clock the reference keeps
    /// exactly: it passes the reference 5 µs after it is built and is back 5 µs later.
    fn passing(k: u64, built_ns: u64, frame_ns: u64, data_ns: u64) -> Sample {
        Sample {
            cycle: k,
            built_ns,
            tx_ns: None,
            rx_ns: built_ns + 10_000,
            reference_ns: built_ns + 5_000,
            reference_offset_ns: None,
            difference_ns: 0,
            loop_ns: 0,
            frame_ns,
            data_ns,
            follower: None,
        }
    }

    #[test]
    fn a_frame_that_ended_past_its_sync0_holds_the_next_back_one_cycle() {
        let c = 50_000;
        let mut f = Ferrocat::new(Coupling::MasterFollowsReference, c);
        f.set_sync0_phase_ns(Some(c / 2));
        // Process data ending 5 µs after the frame's head, aimed at phase 0 of the reference's cycle, SYNC0 at 25 µs.
        let frame = |k: u64, late: i64| Sample {
            cycle: k,
            built_ns: k * c,
            tx_ns: None,
            rx_ns: (k * c).wrapping_add_signed(late) + 10_000,
            reference_ns: (k * c).wrapping_add_signed(late),
            reference_offset_ns: None,
            difference_ns: 0,
            loop_ns: 0,
            frame_ns: 8_000,
            data_ns: 5_000,
            follower: None,
        };
        let period = |f: &mut Ferrocat, k, late| f.update(Some(&frame(k, late))).next_period_ns.unwrap();
        for k in 1..100 {
            let p = period(&mut f, k, 1_000);
            assert!(p.abs_diff(c) < 2_000, "{k}: {p}");
        }
        // Ends 1 µs before SYNC0: nothing; 1 µs after: the next frame one cycle later.
        assert!(period(&mut f, 100, 19_000) < c * 3 / 2 && f.held_back() == 0);
        assert!(period(&mut f, 101, 21_000) > c * 3 / 2 && f.held_back() == 1);
        // Early (its end 2 µs before its target, or its head 7 µs): not taken for late.
        assert!(period(&mut f, 103, -7_000) < c * 3 / 2 && f.held_back() == 1);
        // Without a SYNC0 to serve, never.
        f.set_sync0_phase_ns(None);
        assert!(period(&mut f, 104, 30_000) < c * 3 / 2 && f.held_back() == 1);
    }

    #[test]
    fn a_schedule_that_moved_past_the_sync0_is_not_held_back_for_good() {
        // The reference on the master's clock; the master wakes on its own absolute schedule
        // (each wake-up at the last plus the period returned, as the lab's loop does), its
        // frame passing 5 µs after it is built. From frame 200 on every wake-up is 60 % of a
        // cycle late (a busy CPU): the frames pass after the SYNC0 half a cycle on. The first
        // is a late frame and held back; then the loop moves the schedule to the next slot,
        // and the count must follow it rather than hold every frame back from then on (every
        // frame of the run's rest, each a repeated cycle).
        let c = 250_000u64;
        let mut f = Ferrocat::new(Coupling::MasterFollowsReference, c);
        f.set_sync0_phase_ns(Some(c / 2));
        f.options_mut().probing = Probing::Off;
        let mut t = 3 * c;
        let mut holds = Vec::new();
        for k in 1..600u64 {
            let built = t + if k >= 200 { c * 6 / 10 } else { 0 };
            let s = passing(k, built, 8_000, 3_000);
            let before = f.held_back();
            t += f.update(Some(&s)).next_period_ns.unwrap();
            holds.push(f.held_back() - before);
        }
        let late_holds: u64 = holds[198..].iter().sum();
        assert_eq!(holds[..198].iter().sum::<u64>(), 0, "{holds:?}");
        assert!(
            (1..=SLOT_SLIP_RUN as u64 + 1).contains(&late_holds),
            "{late_holds} held back after the move: {holds:?}"
        );
        assert!(holds[300..].iter().all(|&h| h == 0), "{holds:?}");
    }

    #[test]
    fn a_late_wake_up_is_not_fed_back_into_the_period() {
        // The reference on the master's clock exactly; each cycle starts 0–40 µs late (known
        // only after the fact) and its frame passes the reference 5 µs after it is built.
        let c = 1_000_000u64;
        let mut f = Ferrocat::new(Coupling::MasterFollowsReference, c);
        f.options_mut().probing = Probing::Off;
        let (mut plan, mut lcg) = (7 * c + 123_456, 1u64);
        let mut periods = Vec::new();
        let mut phases = Vec::new();
        for k in 1..4_000u64 {
            lcg = lcg.wrapping_mul(6_364_136_223_846_793_005).wrapping_add(1_442_695_040_888_963_407);
            let built = plan + (lcg >> 33) % 40_000;
            let s = passing(k, built, 0, 0);
            let p = f.update(Some(&s)).next_period_ns.unwrap();
            if k == 3_000 {
                // A master that skipped three cycles without a word: the plan starts again.
                plan += 3 * c;
            }
            if (2_000..3_000).contains(&k) {
                periods.push(p as i64);
                let ph = ((built + 5_000) % c) as i64;
                phases.push(if ph > c as i64 / 2 { ph - c as i64 } else { ph });
            }
            if k > 3_100 {
                // Back on the cycle (the restart takes that one cycle's lateness, 1/16 of it
                // per cycle out again), not chasing a 3 ms lateness.
                assert!(p.abs_diff(c) < 300, "{k}: {p}");
            }
            plan += p;
        }
        // Feeding back 1/16 of each cycle's lateness, the period spread over 2.5 µs.
        let spread = periods.iter().max().unwrap() - periods.iter().min().unwrap();
        assert!(spread < 300, "period spread {spread} ns");
        // The passages centred on the target phase: the mean lateness is aimed for.
        let mean = phases.iter().sum::<i64>() / phases.len() as i64;
        assert!(mean.abs() < 1_000, "mean phase {mean} ns");
    }

    #[test]
    fn ferrocat_lead_is_half_the_round_trip_without_loop_and_frame() {
        let s = sample(1, 0, 0);
        assert_eq!(s.lead_ns(), (20_000 - 4_000 - 6_000) / 2);
        let mut f = Ferrocat::new(Coupling::ReferenceFollowsMaster, 1_000_000);
        assert_eq!(f.reference_time(100), 100, "no lead before the first sample");
        f.update(Some(&s));
        assert_eq!(f.reference_time(100), 100 + 5_000);
        // One wild sample out of many does not move it.
        for k in 2..60 {
            f.update(Some(&sample(k, 0, 0)));
        }
        let mut wild = sample(61, 0, 0);
        wild.rx_ns += 500_000;
        f.update(Some(&wild));
        assert_eq!(f.lead_ns(), Some(5_000));
    }

    #[test]
    fn offset_steering_puts_the_reference_on_the_master_half_a_cycle_after_passage() {
        // The reference's local time runs 50 ppm fast from 7 ms; the offsets it read differ
        // from frame to frame (as the master's writes change them): the line goes through
        // the local time all the same.
        let c = 1_000_000u64;
        let local = |x: u64| 7_000_000 + x + x / 20_000;
        let mut f = Ferrocat::new(Coupling::ReferenceFollowsMaster, c);
        assert!(f.steers_reference_offset());
        assert_eq!(f.reference_offset(0, None), None, "nothing to aim with before a sample");
        for k in 1..=40u64 {
            let mut s = sample(k, 0, 0);
            // Passage: build + lead = k ms + 5 µs (no transmit stamp: half the round trip).
            let passage = s.built_ns + 5_000;
            let offset = 123_456_789 + k * 977;
            s.reference_ns = local(passage) + offset;
            s.reference_offset_ns = Some(offset);
            f.update(Some(&s));
        }
        let built = 41 * c;
        let aim = built + 5_000 + c / 2;
        let got = f.reference_offset(built, None).unwrap();
        let want = aim.wrapping_sub(local(aim));
        assert!((got.wrapping_sub(want) as i64).abs() <= 2, "offset {got}, want {want}");
        // A probe's offset, standing 200 µs until the next probe, is aimed 100 µs on.
        let aim = built + 5_000 + 100_000;
        let got = f.reference_offset(built, Some(200_000)).unwrap();
        let want = aim.wrapping_sub(local(aim));
        assert!((got.wrapping_sub(want) as i64).abs() <= 2, "probe's offset {got}, want {want}");
        assert_eq!(f.master_time(built), None, "the master keeps its own clock");
        // 50 ppm fast, 1 ms: the followers would sit 25 ns above the reference's mean.
        assert_eq!(f.follower_delay_bias_ns(), Some(-25));
        assert_eq!(f.follower_delay_bias_ns(), None, "given once: nothing new to write");
        f.options_mut().followers = FollowerDelays::Measured;
        assert_eq!(f.follower_delay_bias_ns(), None);
        let tcl = Ferrocat::new(Coupling::ReferenceFollowsMaster, c).with_steering(Steering::TimeControlLoop);
        assert!(!tcl.steers_reference_offset());
    }

    #[test]
    fn the_first_offset_given_to_the_reference_moves_every_other_slave_with_it() {
        let mut f = Ferrocat::new(Coupling::ReferenceFollowsMaster, 1_000_000);
        // The reference's local time runs 1:1 with the master's but 5 µs behind, and its
        // offset (read by each frame) is 2 000 ns: the offset that puts it on the master's
        // time is 5 000 ns, a step of 3 000 ns from what the DC initialisation left.
        let read = |k: u64| {
            let mut s = sample(k, 0, 0);
            let passage = s.built_ns.wrapping_add_signed(s.lead_ns());
            s.reference_offset_ns = Some(2_000);
            s.reference_ns = passage - 5_000 + 2_000;
            s
        };
        for k in 1..=8 {
            assert_eq!(f.update(Some(&read(k))).shift_offsets_ns, 0, "no shift before an offset is given");
        }
        let offset = f.reference_offset(9 * 1_000_000, None).unwrap();
        assert!((offset as i64 - 5_000).abs() <= 1, "{offset}");
        assert_eq!(f.update(Some(&read(9))).shift_offsets_ns, offset as i64 - 2_000, "the step, once");
        f.reference_offset(10 * 1_000_000, None).unwrap();
        assert_eq!(f.update(Some(&read(10))).shift_offsets_ns, 0, "later offsets move the reference alone");
    }
}
