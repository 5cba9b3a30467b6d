//! ferrocat's own method (design and measurements: docs/clock-sync.md).
use super::flywheel::Flywheel;
use super::{ClockSync, Correction, Coupling, CyclePlan, LineEvents, Sample, MAX_CYCLE_NS};
use crate::line_fit::{Fate, FrozenLine, LineFit};
use crate::rtt_weight::RttWeight;
use crate::trimmed::TrimmedWindow;

/// ferrocat's method. Every cycle's round trip gives a fresh estimate of how long a frame
/// takes from being built to passing the reference (transmit and receive stamps where the
/// link has them); a trimmed mean over a short window rejects the outliers of a busy host
/// without the settling time of a long average.
/// - Master follows reference: a least-squares line through (master time at passage,
///   reference time) gives offset and rate (`LineFit`: its window grows to 16 384 points
///   while the points agree with it, leaves single outliers out, and restarts when a CUSUM
///   of its innovations sees the rate or phase change); the master's clock is that line
///   (its estimate of the reference's time), and the next period puts the frame at
///   `phase_ns` of the reference's cycle, removing 1/16 of the phase error per cycle (the
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
///   middle (see [`ClockSync::follower_delay_bias_ns`]).
/// - Reference follows master ([`Steering::TimeControlLoop`]): the master writes its time plus
///   that lead into 0x0910, so the reference's time control loop steers to the master's time
///   at the instant the frame passes; a late send is a sample off by its lateness.
#[derive(Debug)]
pub struct Ferrocat {
    /// Who follows whom.
    pub coupling: Coupling,
    /// How the reference is made to follow (reference-follows-master only).
    pub steering: Steering,
    /// The cycle, ns.
    pub cycle_ns: u64,
    /// Where in the cycle the frame should pass the reference, ns.
    pub phase_ns: u64,
    /// Reference follows master: the master's time goes to the reference every this many
    /// cycles (default 1). Fewer, further-apart samples should carry less of the host's send
    /// jitter into the loop's frequency estimate, but in the modelled loop every 8th cycle
    /// measured worse (docs/clock-sync.md).
    pub write_every: u64,
    leads: TrimmedWindow,
    lead_ns: Option<i64>,
    /// (master time at passage, reference time): the line through them is the method's
    /// estimate of the reference's clock.
    pub fit: LineFit,
    /// Half round trips from the transmit stamp (or the build time), for the fit's abscissa.
    halves: TrimmedWindow,
    rtt: RttWeight,
    /// Send delays seen by transmit stamps, and how far the last frame's was from their mean:
    /// the next time written takes it back out (error feedback), so that the reference's
    /// loop, which averages its samples, sees the host's send jitter cancel pairwise.
    sends: TrimmedWindow,
    last_send_error_ns: i64,
    /// Whether to feed the last send error back (off by default: measured in docs/clock-sync.md).
    pub error_feedback: bool,
    /// How much later than it was the stamps put the frame's passage of the reference, as a
    /// calibration found it (half the stamps' receive/transmit asymmetry; with the reference
    /// following, also the bias its time control loop adds to a jittery master): taken out of
    /// every passage, as linuxptp's `delayAsymmetry` is.
    pub calibration_ns: i64,
    /// Master follows reference: the reference-time phase of the SYNC0 the frames serve. A
    /// frame whose process data ended after it (a late wake-up or send) is consumed a SYNC0 late; the
    /// next frame is held back one cycle so that it does not overwrite it before then: the
    /// slaves repeat one cycle instead of repeating one and losing the next.
    pub sync0_phase_ns: Option<u64>,
    /// Frames held back so.
    pub held_back: u64,
    /// The reference time the next frame is aimed at (its slot on the grid of `phase_ns`).
    aimed_ns: Option<u64>,
    /// Frames in a row held back.
    late_run: u32,
    /// Master follows reference: when this cycle was planned to start on the master's clock
    /// (the last one plus the period returned), and how late cycles start on average against
    /// it. A wake-up's lateness is known after the fact and says nothing of the next one's,
    /// so the period is chosen for the planned start plus the mean lateness, not for the
    /// actual start: feeding a part of each cycle's lateness back makes the loop chase the
    /// host's jitter and a coarse timer's rounding, and widens both.
    plan_ns: Option<u64>,
    /// Cycles in a row more than half a cycle off the plan.
    off_plan_run: u32,
    lateness: RunningMean,
    /// Reference following by offset: a calibration moves the reference at once by what it
    /// found, and so does the first offset it is given (from wherever the DC initialisation
    /// left it); every other slave's offset moves with it (the next correction), so that the
    /// followers' loops need not chase a step.
    pending_shift_ns: i64,
    /// The reference's offset the last frame read, and whether the method has replaced it yet.
    reference_offset_read: Option<u64>,
    offset_given: bool,
    /// The offset last given to the reference (steering by offset).
    offset_given_ns: Option<u64>,
    /// Whether to probe the reference with extra frames while the line is uncertain.
    pub probing: bool,
    /// Whether to probe every cycle, in half of it, however certain the line: many times the
    /// frames, for a line of many more points that shows a change sooner and holds the
    /// reference closer (`Ferrocat::dense`, which also widens the window for those points;
    /// `ferrocat-dense` in the lab; docs/clock-sync.md, "Probing").
    pub probe_every_cycle: bool,
    /// Offset steering: whether to bias the followers' delay registers so that they sit in the
    /// middle of the reference's sawtooth instead of on its top.
    pub centre_followers: bool,
    /// Offset steering: whether a lost frame is made up at once (its offset given by another).
    pub make_up: bool,
    /// Offset steering: whether probes give the reference its offset from the line they
    /// update, so that a change the line sees is in force at once, not a cycle later.
    pub probes_steer: bool,
    /// The bias last given to the followers' delay registers.
    delay_bias_ns: i64,
    /// A follower's crystal as the flywheel the line runs on (`Ferrocat::with_flywheel`).
    flywheel: Option<Flywheel>,
    contest: Option<Contest>,
    /// Which way the speed counter moves the clock, while it is being found out.
    trial: Option<Trial>,
}

/// The datasheet gives the speed counter's deviation but not its direction, so the flywheel
/// starts with both readings: `Ferrocat::flywheel` and `fit` take a positive SCD to slow the
/// clock (our model's reading), these the other way. The reading whose ε line stays clean
/// while the other's restarts again and again (the loop's work taken out the wrong way,
/// doubled) is kept. Until then the direct line is the estimate: the follower's loop may be too
/// calm to tell for a long while (the master following the reference, crystals alike), and a
/// guess would take the loop's first real work, a step's, the wrong way. Where neither reading
/// stays clean the flywheel is refused after a while (an ESC that does not implement 0x0932
/// would look so).
#[derive(Debug)]
struct Trial {
    other: Flywheel,
    other_fit: LineFit,
    /// Frames that read the follower so far.
    frames: u64,
}

/// Frames before the trial may end; the other reading's restarts that decide it,
/// `TRIAL_RATIO` times the kept one's and `TRIAL_MARGIN_RESTARTS` more; restarts above which a
/// reading is not clean, and frames after which a trial where neither is refuses the flywheel.
const TRIAL_FRAMES: u64 = 1024;
const TRIAL_CLEAN_RESTARTS: u64 = 1;
const TRIAL_RATIO: u64 = 3;
const TRIAL_MARGIN_RESTARTS: u64 = 3;
const TRIAL_GIVE_UP_FRAMES: u64 = 8 * TRIAL_FRAMES;

/// Which of two estimates of the reference foretells the stamps' points better: the flywheel's
/// (the follower's crystal plus ε) or the line through the reference's own points. They part
/// only when one of the two crystals changes, and then the one whose crystal kept its rate
/// stays with the points.
#[derive(Debug)]
struct Contest {
    /// The line through the reference's own points (ferrocat without a flywheel).
    direct: LineFit,
    /// Leaky sum of the log-likelihood ratio, flywheel over direct, one term per cycle's frame,
    /// in units of the stamps' variance.
    llr: f64,
    use_direct: bool,
    /// The test of which crystal changed, while one runs.
    kink: Option<KinkTest>,
}

/// When ε's line restarts, one of the two crystals changed its rate, and ε's departure from
/// its old line since (measured to a few ns) is the whole of that change. If it was the
/// reference's, the reference's points leave the direct line as it stood by exactly that
/// departure; if the follower's, they stay on it. Both lines are frozen at the restart and
/// each frame scores the two predictions: a known template against the stamps' noise, whose
/// evidence grows with the cube of the time since the change (50 ppm in 1 µs of noise: ≈ 8 in
/// 25 ms). The lines themselves restart at a change and follow the points again, which left
/// the leaky contest nothing to tell them apart by (pc-stock: 70 of 100 seeds back within
/// 100 ms of a follower's step).
///
/// While the speed counter's direction is on trial, each reading has its own ε, and the test
/// scores both templates: the follower's loop takes up a reference's step within tens of ms,
/// and the reading that takes it out the wrong way shows it doubled, against the other's
/// clean change. A reference that changed by one reading's template and not the other's
/// decides the direction as well (a loop too calm before the step to tell it: rtx-10us seed
/// 14, the direction unmeasured, the step taken by the direct line in 159 ms).
#[derive(Debug)]
struct KinkTest {
    direct: FrozenLine,
    /// ε's line: reference time ↦ reference time + ε.
    eps: FrozenLine,
    /// Log-likelihood ratio, the reference changed over the follower changed.
    llr: f64,
    /// The same for the other reading's ε, while the direction is on trial.
    other: Option<(FrozenLine, f64)>,
    frames: u32,
}

/// What a kink test found.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
enum Verdict {
    /// The follower's crystal changed: the direct line.
    FollowerChanged,
    /// The reference's: the flywheel, on the reading in use.
    ReferenceChanged,
    /// The reference's, by the other reading's template: that reading, and the flywheel.
    ReferenceChangedOtherReading,
}

impl KinkTest {
    /// Scores a frame: `y` of the reference at `x`, ε measured at reference time `r_ns` by
    /// the reading in use (`eps_ns`) and by the other (`other_eps_ns`), σ of the stamps `sd`.
    fn score(&mut self, x: u64, y: u64, r_ns: u64, eps_ns: i64, other_eps_ns: Option<i64>, sd: f64) -> Option<Verdict> {
        let residual = y.wrapping_sub(self.direct.at(x)) as i64 as f64;
        // ε's departure from its frozen line: the reference's from the direct line, if it
        // was the reference that changed.
        let departure = |line: &FrozenLine, eps: i64| eps.wrapping_sub(line.at(r_ns).wrapping_sub(r_ns) as i64) as f64;
        // A host's outliers say nothing: the residual is clipped 4 σ beyond both predictions.
        let evidence = |g: f64| {
            let r = residual.clamp(g.min(0.0) - 4.0 * sd, g.max(0.0) + 4.0 * sd);
            g * (2.0 * r - g) / (2.0 * sd * sd)
        };
        self.llr += evidence(departure(&self.eps, eps_ns));
        // A trial that ended meanwhile (its restarts told it) leaves one reading to test.
        match (self.other.as_mut(), other_eps_ns) {
            (Some((line, llr)), Some(e)) => *llr += evidence(departure(line, e)),
            _ => self.other = None,
        }
        self.frames += 1;
        let Some((_, other)) = self.other else {
            return match self.llr {
                l if l <= -KINK_DECIDE => Some(Verdict::FollowerChanged),
                l if l >= KINK_DECIDE => Some(Verdict::ReferenceChanged),
                _ => None,
            };
        };
        if self.llr <= -KINK_DECIDE && other <= -KINK_DECIDE {
            Some(Verdict::FollowerChanged)
        } else if self.llr >= KINK_DECIDE && self.llr - other >= KINK_DECIDE {
            Some(Verdict::ReferenceChanged)
        } else if other >= KINK_DECIDE && other - self.llr >= KINK_DECIDE {
            Some(Verdict::ReferenceChangedOtherReading)
        } else {
            None
        }
    }
}

/// The contest's memory (frames) and the evidence that hands the estimate to the direct line.
const CONTEST_LEAK: f64 = 1.0 / 256.0;
const CONTEST_SWITCH: f64 = 8.0;
/// Evidence each frame adds for the flywheel, whose ε needs no stamps: where the two agree the
/// sum settles at `CONTEST_PRIOR / CONTEST_LEAK` (2.56), and the flywheel is used again once it
/// is above 0 and the crystal's line is as certain as the direct one — after a step of the
/// follower's crystal, once its restarted line has grown as long, so that a later step of the
/// reference finds the flywheel in use.
const CONTEST_PRIOR: f64 = 0.01;
/// The evidence that decides a kink test either way, and the frames after which one that did
/// not decide is dropped (ε's line restarted for no change of either crystal).
const KINK_DECIDE: f64 = 8.0;
const KINK_MAX_FRAMES: u32 = 1024;

/// How a method makes the reference follow the master.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Steering {
    /// Replace the reference's System_Time_Offset (0x0920) each cycle.
    Offset,
    /// Write the master's time into the reference's 0x0910, a sample of its time control loop.
    TimeControlLoop,
}

const WINDOW: usize = 64;
/// Late frames in a row after which the count of slots starts again (`Ferrocat::slots_to_hold`):
/// more than a late wake-up and a late send in a row.
const SLOT_SLIP_RUN: u32 = 4;
/// Cycles in a row more than half a cycle off the plan before it starts again from them
/// (`Ferrocat::lateness_deviation`). A loop that fell behind by a long wake-up catches up
/// over several cycles, each giving back what is left of its cycle after its frames: on a
/// stock kernel at 250 µs (two frames a cycle) that took four cycles often enough that four
/// in a row moved the plan back and forth (the demo's ferrocat-mfr: 1 217 late set-points
/// with one seed, 50–80 with sixteen over seeds 1–6).
const PLAN_MOVED_RUN: u32 = 16;
/// The half round trips' centre is a trimmed mean over this many. A cycle's probes come in a
/// burst and share the centre; over 64 (two cycles of bursts) its error was a burst's own and
/// counted in the change test once per point, which took it for a change of the line (a false
/// restart 4.2 s after a crystal step, pc-rt seed 2).
const CENTRE_WINDOW: usize = 1024;

/// The mean of every value so far, and once there are `2^LONG_SHIFT` of them an exponential
/// average over as many: a coarse timer's rounding is a sawtooth that sweeps its step only as
/// the reference slides past the timer's grid (thousands of cycles), and a mean that followed
/// it would have the loop chase it.
#[derive(Debug, Default, Clone, Copy)]
struct RunningMean {
    sum: i128,
    n: u64,
}

const LONG_SHIFT: u32 = 16;

impl RunningMean {
    fn push(&mut self, v: i64) {
        if self.n < 1 << LONG_SHIFT {
            self.n += 1;
        } else {
            self.sum -= self.sum >> LONG_SHIFT;
        }
        self.sum += v as i128;
    }
    fn mean(&self) -> i64 {
        (self.sum / self.n.max(1) as i128) as i64
    }
}

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
/// The smallest change of the followers' delay bias worth a write (ns), and the shortest
/// line (in cycles of master time) whose rate it is taken from.
const DELAY_BIAS_STEP_NS: f64 = 4.0;
const DELAY_BIAS_MIN_SPAN_CYCLES: u64 = 32;
/// The longest the line's window grows (16 s at 1 ms without probes) while its points agree
/// with it; probing stops at a quarter of it, so that a settled line does not probe.
pub const FIT_WINDOW: usize = 16_384;
/// The window of a line probed every cycle (the fit's largest): at 14–32 points per 1 ms cycle
/// it spans 2–5 s, where 16 384 points spanned one and let a stock kernel's stamps move the
/// level by tens of ns over seconds (docs/clock-sync.md, "Probing").
pub const DENSE_FIT_WINDOW: usize = 65_536;
/// The line's shorter windows are scored on points this fraction of a cycle or more after the
/// one before: the cycle's frames, not the probes of a burst, whose stamps share the host's
/// state (`LineFit::score_gap`).
const SCORE_GAP_DIVISOR: u64 = 4;

impl Ferrocat {
    /// ferrocat's method with `coupling` on a cycle of `cycle_ns`, its line through the reference's own points (see [`Ferrocat::with_flywheel`]).
    pub fn new(coupling: Coupling, cycle_ns: u64) -> Self {
        let cycle_ns = cycle_ns.clamp(1, MAX_CYCLE_NS);
        Ferrocat {
            coupling,
            steering: Steering::Offset,
            cycle_ns,
            phase_ns: 0,
            write_every: 1,
            leads: TrimmedWindow::new(WINDOW),
            lead_ns: None,
            fit: Ferrocat::line(FIT_WINDOW, cycle_ns),
            halves: TrimmedWindow::new(CENTRE_WINDOW),
            rtt: RttWeight::new(),
            sends: TrimmedWindow::new(WINDOW),
            last_send_error_ns: 0,
            error_feedback: false,
            calibration_ns: 0,
            sync0_phase_ns: None,
            held_back: 0,
            aimed_ns: None,
            late_run: 0,
            plan_ns: None,
            lateness: RunningMean::default(),
            off_plan_run: 0,
            pending_shift_ns: 0,
            reference_offset_read: None,
            offset_given: false,
            offset_given_ns: None,
            probing: true,
            probe_every_cycle: false,
            centre_followers: true,
            make_up: true,
            probes_steer: true,
            delay_bias_ns: 0,
            flywheel: None,
            contest: None,
            trial: None,
        }
    }

    /// ferrocat whose line runs on a follower's crystal, the reference's difference from it
    /// read from the hardware every cycle (flywheel.rs).
    pub fn with_flywheel(self) -> Self {
        let line = || Ferrocat::line(FIT_WINDOW, self.cycle_ns);
        let trial = Trial { other: Flywheel::new(line(), false), other_fit: line(), frames: 0 };
        Ferrocat {
            flywheel: Some(Flywheel::new(line(), true)),
            contest: Some(Contest { direct: line(), llr: 0.0, use_direct: true, kink: None }),
            trial: Some(trial),
            ..self
        }
    }

    /// Ends the trial of the speed counter's direction where the frames have answered it
    /// (`measured`: the direction the master measured at the DC initialisation, which ends it
    /// at once). The direct line is the estimate throughout, so nothing in use moves.
    fn judge_trial(&mut self, measured: Option<bool>) {
        let Some(t) = self.trial.as_mut().filter(|t| t.frames >= TRIAL_FRAMES || measured.is_some()) else { return };
        let mine = self.flywheel.as_ref().map_or(u64::MAX, |f| f.eps_events().restarts);
        let other = t.other.eps_events().restarts;
        // The loop's start-up (the compensation's first frames, the first offsets) can restart
        // the right reading's line once or twice too: what tells is the other's many more.
        let clean = |a: u64, b: u64| b >= TRIAL_RATIO * a + TRIAL_MARGIN_RESTARTS;
        if measured == Some(true) || (measured.is_none() && clean(mine, other)) {
            self.trial = None;
        } else if measured == Some(false) || clean(other, mine) {
            self.keep_other_reading();
            // The contest's evidence so far was the first reading's.
            if let Some(c) = self.contest.as_mut() {
                c.llr = 0.0;
            }
        } else if t.frames >= TRIAL_GIVE_UP_FRAMES && mine > TRIAL_CLEAN_RESTARTS && other > TRIAL_CLEAN_RESTARTS {
            // Neither reading is clean: no flywheel, the direct line for good.
            self.trial = None;
            self.flywheel = None;
        }
    }

    /// Ends the trial with the other reading of the speed counter's direction.
    fn keep_other_reading(&mut self) {
        let Some(mut t) = self.trial.take() else { return };
        // Its line's restarts during the trial were not changes of a crystal.
        t.other.take_kink();
        self.flywheel = Some(t.other);
        self.fit = t.other_fit;
    }

    /// With a flywheel: the reference's time of the last frame that read the follower, and
    /// the ε = reference − follower's crystal it measured (ns).
    pub fn flywheel_eps(&self) -> Option<(u64, i64)> {
        self.flywheel.as_ref()?.last_point()
    }

    /// The flywheel's estimate of the reference at master time `x` (the crystal's line plus ε).
    fn flywheel_at(&self, x: u64) -> Option<u64> {
        let c = self.fit.at(x)?;
        let Some(fw) = &self.flywheel else { return Some(c) };
        let e0 = fw.last_eps_ns().unwrap_or(0);
        let e = fw.eps_at(c.wrapping_add_signed(e0)).unwrap_or(e0);
        Some(c.wrapping_add_signed(e))
    }

    /// A restart of ε after a long run, with its line as it stood, to test which crystal
    /// changed: on trial, either reading's, with the other's line (frozen as it stands where
    /// only one restarted), once the trial has run as long as it must before it may end.
    /// Before, the loops' start-up (the reference's first offsets, the followers' first
    /// corrections) is no single crystal's change: tested then, pc-rt seed 7 took the wrong
    /// reading 39 ms in, and 7 / 100 seeds lost the flywheel.
    fn take_kink(&mut self) -> Option<(FrozenLine, Option<FrozenLine>)> {
        let mine = self.flywheel.as_mut()?.take_kink();
        let Some(t) = self.trial.as_mut() else { return mine.map(|eps| (eps, None)) };
        let other = t.other.take_kink();
        let fw = self.flywheel.as_ref()?;
        let (r_ns, _) = fw.last_point()?;
        if t.frames < TRIAL_FRAMES || (mine.is_none() && other.is_none()) {
            return None;
        }
        Some((mine.or(fw.eps_frozen_at(r_ns))?, Some(other.or(t.other.eps_frozen_at(r_ns))?)))
    }

    /// Keeps the direct line, scores the point (x, y of the reference) on both estimates where
    /// it is a cycle's frame (`frame`), and returns how far the estimate in use moved at `x` if
    /// it changed, and whether the other reading of the speed counter's direction is now the
    /// flywheel's (its point is the one for the crystal's line). A cycle's probes come in a burst whose stamps share the host's state: scored
    /// as independent points they made the evidence many times what it was (on this machine's
    /// kernel, robust noise scale ≈ 30 ns: a hand-over every second or so, by 8–207 ns each;
    /// docs/clock-sync.md, "What we tried and why not").
    fn contest_point(&mut self, x: u64, y: u64, frame: bool) -> (i64, bool) {
        let fly = self.flywheel_at(x);
        let fly_sd = self.fit.sd_ahead_ns(self.cycle_ns);
        // Not while the flywheel's direction is unknown and matters, nor once it was refused.
        let fly_present = self.flywheel.is_some();
        let fly_ok = fly_present && self.trial.is_none();
        let eps_point = self.flywheel.as_ref().and_then(|fw| fw.last_point());
        let other_eps_ns = self.trial.as_ref().and_then(|t| t.other.last_eps_ns());
        let kink = self.take_kink();
        let Some(c) = self.contest.as_mut() else { return (0, false) };
        // Back to the flywheel only once the crystal's line is as certain as the direct one: a
        // line restarted by the follower's step is young, and the stamps cannot tell its tens
        // of ns from the direct line's for a long while (back as soon as it was settled enough
        // to stop probing, the estimate jumped by that much seconds after the step: 95 of 100
        // seeds within 100 ms of the control on pc-stock, against 100).
        let settled = fly_ok && fly_sd.zip(c.direct.sd_ahead_ns(self.cycle_ns)).is_some_and(|(f, d)| f <= d);
        let direct = c.direct.at(x);
        let sd = c.direct.scale_ns().max(1.0);
        // A test already running keeps the lines it froze: a second restart of ε is the same
        // change, measured again.
        if let (Some((eps, other)), None) = (kink, &c.kink) {
            if let Some(direct) = c.direct.frozen_at(x) {
                c.kink = Some(KinkTest { direct, eps, llr: 0.0, other: other.map(|o| (o, 0.0)), frames: 0 });
            }
        }
        c.direct.push(x, y);
        if !frame {
            return (0, false);
        }
        // Refused, the flywheel is not in the contest.
        let (Some(a), Some(b), true) = (fly, direct, fly_present) else { return (0, false) };
        // A host's outliers (a stamp hundreds of µs late) say nothing of which is right: the
        // residuals are clipped at 4 σ.
        let clip = |r: f64| r.clamp(-4.0 * sd, 4.0 * sd);
        let (ra, rb) = (clip(y.wrapping_sub(a) as i64 as f64), clip(y.wrapping_sub(b) as i64 as f64));
        let limit = 2.0 * CONTEST_SWITCH;
        let evidence = (rb * rb - ra * ra) / (2.0 * sd * sd) + CONTEST_PRIOR;
        c.llr = (c.llr * (1.0 - CONTEST_LEAK) + evidence).clamp(-limit, limit);
        let mut switch = if c.use_direct { c.llr > 0.0 && settled } else { c.llr < -CONTEST_SWITCH };
        let mut verdict = None;
        if let (Some(k), Some((reference_ns, eps_ns))) = (c.kink.as_mut(), eps_point) {
            verdict = k.score(x, y, reference_ns, eps_ns, other_eps_ns, sd);
            if verdict.is_some() || k.frames >= KINK_MAX_FRAMES {
                c.kink = None;
            }
        }
        if let Some(v) = verdict {
            let to_direct = v == Verdict::FollowerChanged;
            // The leaky contest starts from the verdict, as sure of it as it can be.
            c.llr = if to_direct { -limit } else { limit };
            switch = c.use_direct != to_direct;
        }
        // A reference's change told the direction too; a follower's leaves the trial on.
        let swapped = verdict == Some(Verdict::ReferenceChangedOtherReading);
        let a = match verdict {
            Some(Verdict::ReferenceChanged) => {
                self.trial = None;
                a
            }
            Some(Verdict::ReferenceChangedOtherReading) => {
                self.keep_other_reading();
                self.flywheel_at(x).unwrap_or(a)
            }
            _ => a,
        };
        if !switch {
            return (0, swapped);
        }
        let Some(c) = self.contest.as_mut() else { return (0, swapped) };
        c.use_direct = !c.use_direct;
        let (from, to) = if c.use_direct { (a, b) } else { (b, a) };
        (to.wrapping_sub(from) as i64, swapped)
    }

    /// The line's estimate of the reference's time at master time `x`: with a flywheel, the
    /// crystal's line there plus ε.
    fn line_at(&self, x: u64) -> Option<u64> {
        match &self.contest {
            Some(c) if c.use_direct || self.flywheel.is_none() => c.direct.at(x),
            _ => self.flywheel_at(x),
        }
    }

    /// The line's rate (reference per master time).
    fn line_rate(&self) -> Option<f64> {
        if let Some(c) = self.contest.as_ref().filter(|c| c.use_direct || self.flywheel.is_none()) {
            return c.direct.rate();
        }
        let r = self.fit.rate()?;
        // dR/dx = dC/dx + dε/dR·dR/dx.
        Some(self.flywheel.as_ref().map_or(r, |fw| r / (1.0 - fw.eps_slope())))
    }

    /// ferrocat probing in half of every cycle, with a window long enough for that many points.
    pub fn dense(coupling: Coupling, cycle_ns: u64) -> Self {
        let f = Ferrocat::new(coupling, cycle_ns);
        Ferrocat { probe_every_cycle: true, fit: Ferrocat::line(DENSE_FIT_WINDOW, f.cycle_ns), ..f }
    }

    /// The method's line over up to `window` points, its shorter windows scored on the frames.
    fn line(window: usize, cycle_ns: u64) -> LineFit {
        LineFit::new(window).score_gap(cycle_ns / SCORE_GAP_DIVISOR)
    }

    /// The lead in use (None before the first sample).
    pub fn lead_ns(&self) -> Option<i64> {
        self.lead_ns
    }

    /// How many cycles to hold the next frame back: as many SYNC0s as the process data of
    /// `s` ended after the one it was aimed before. The frame's slot is counted on from the
    /// last one, not read off its phase, which could not tell a frame late by most of a cycle
    /// from an early one.
    fn slots_to_hold(&mut self, s: &Sample) -> u64 {
        let Some(sync0) = self.sync0_phase_ns else { return 0 };
        let c = self.cycle_ns;
        let late_of = |aimed: u64| s.reference_ns.wrapping_add(s.data_ns).wrapping_sub(aimed) as i64;
        let mut aimed = self.aimed_ns.unwrap_or_else(|| self.nearest_slot(s.reference_ns));
        // Far off the count (a stall, a jump of the reference): start counting again here.
        if !(-(c as i64) / 2..=8 * c as i64).contains(&late_of(aimed)) {
            aimed = self.nearest_slot(s.reference_ns);
        }
        let room = (sync0.wrapping_sub(self.phase_ns) % c) as i64;
        // At most the 8 cycles a frame may be late before the count starts again.
        let hold_for = |late: i64| if late >= room { ((late - room) / c as i64 + 1).min(8) as u64 } else { 0 };
        // A late frame is held back, and the next one, on time, is not. Late frames in a row
        // are a schedule that moved past the SYNC0: the loop, which steers to the nearest slot,
        // takes it on to the next one, while the count stays behind — and counting on held
        // every frame back from then on, each a repeated cycle (85 % of the cycles at 250 µs on
        // pc-stock with seed 1 without this rule; at 100 µs, with the plan's restart in
        // `lateness_deviation` alone, more than every other one with each seed tried). So the
        // `SLOT_SLIP_RUN`-th late frame in a row starts the count again at its own slot.
        let mut hold = hold_for(late_of(aimed));
        self.late_run = if hold > 0 { self.late_run + 1 } else { 0 };
        if self.late_run >= SLOT_SLIP_RUN {
            aimed = self.nearest_slot(s.reference_ns);
            hold = hold_for(late_of(aimed));
            self.late_run = 0;
        }
        self.aimed_ns = Some(aimed.wrapping_add((1 + hold) * c));
        hold
    }

    /// The slot (reference time on the grid of `phase_ns`) nearest to reference time `t_ns`.
    fn nearest_slot(&self, t_ns: u64) -> u64 {
        let c = self.cycle_ns;
        let off = t_ns.wrapping_sub(self.phase_ns).wrapping_add(c / 2) % c;
        t_ns.wrapping_sub(off).wrapping_add(c / 2)
    }

    /// Offers (passage of `s` on the master's clock, `y`) to the fit. The passage is the
    /// transmit stamp (or the build time) plus the trimmed mean of the half round trips, moved
    /// by the part of this frame's own deviation from it learned to be the way out
    /// (rtt_weight.rs).
    fn fit_passage(&mut self, s: &Sample, y: u64) -> u64 {
        // With a flywheel the line runs on the follower's crystal: a frame that read the
        // follower gives its crystal time; any other point the reference's less ε.
        let y_reference = y;
        let y_other = self.trial.as_mut().map(|t| match &s.follower {
            Some(f) => t.other.frame(y, f),
            None => y.wrapping_sub(t.other.eps_at(y).unwrap_or(0) as u64),
        });
        let y = match (&mut self.flywheel, &s.follower) {
            (None, _) => y,
            (Some(fw), Some(f)) => fw.frame(y, f),
            // Before the first reading (or with no follower to read) ε is 0: the crystal's
            // count starts where the reference is, so the line goes on through it unbroken.
            (Some(fw), None) => y.wrapping_sub(fw.eps_at(y).unwrap_or(0) as u64),
        };
        let sent = s.tx_ns.unwrap_or(s.built_ns);
        let half = s.lead_ns().wrapping_sub(sent.wrapping_sub(s.built_ns) as i64);
        self.halves.push(half);
        let centre = self.halves.trimmed_mean();
        let stamp = sent.wrapping_add_signed(centre.wrapping_sub(self.calibration_ns));
        let dev = half.wrapping_sub(centre);
        let x = stamp.wrapping_add_signed(self.rtt.shift_ns(dev));
        // The weight is learned from the reference's time against the line at the stamp alone.
        let residual = self.fit.at(stamp).map(|p| y.wrapping_sub(p) as i64);
        let (contest_jump, swapped) = self.contest_point(x, y_reference, s.follower.is_some());
        // The other reading, now the flywheel's: its crystal's point.
        let y = if swapped { y_other.unwrap_or(y) } else { y };
        let fate = self.fit.push(x, y);
        if let (Some(t), Some(y_other)) = (self.trial.as_mut(), y_other) {
            t.other_fit.push(x, y_other);
            // Neither reading is the estimate in use yet: their changes of line move nothing.
            t.other_fit.take_switch_jump_ns();
            t.other.take_switch_jump_ns();
            t.frames += s.follower.is_some() as u64;
        }
        self.rtt.learn(dev, residual.filter(|_| fate == Fate::Added));
        // The line in use changed windows: steering by offset, the reference steps by the
        // change at its next offset, and every follower with it (their loops would take
        // milliseconds to chase a step of tens of ns, 100 ns on a stock kernel).
        // With a flywheel, only the jumps of the estimate in use move the reference.
        let fly_jump = self.fit.take_switch_jump_ns() + self.flywheel.as_mut().map_or(0, |fw| fw.take_switch_jump_ns());
        let jump = match self.contest.as_mut() {
            Some(c) if c.use_direct || self.flywheel.is_none() => c.direct.take_switch_jump_ns(),
            Some(c) => {
                c.direct.take_switch_jump_ns();
                fly_jump
            }
            None => fly_jump,
        } + contest_jump;
        self.judge_trial(s.follower.and_then(|f| f.speed_diff_slows));
        if self.steers_reference_offset() {
            self.pending_shift_ns = self.pending_shift_ns.saturating_sub(jump);
        }
        x
    }

    /// Whether the method keeps its line (not when it steers the reference's time control loop).
    fn keeps_line(&self) -> bool {
        self.coupling == Coupling::MasterFollowsReference || self.steering == Steering::Offset
    }

    /// The reference's time the line takes from `s`: its system time where the master follows
    /// it; steering its offset, its local time (what it would read with the offset it had at
    /// the start), where the frame read the offset.
    fn line_point(&self, s: &Sample) -> Option<u64> {
        match (self.coupling, self.steering) {
            (Coupling::MasterFollowsReference, _) => Some(s.reference_ns),
            (Coupling::ReferenceFollowsMaster, Steering::Offset) => {
                s.reference_offset_ns.map(|o| s.reference_ns.wrapping_sub(o))
            }
            (Coupling::ReferenceFollowsMaster, Steering::TimeControlLoop) => None,
        }
    }

    /// This cycle's lateness against its plan less the mean lateness. A cycle more than half
    /// a cycle off is an outlier of the host (a wake-up that late, and the cycles that catch
    /// up after it), taken back to the plan like any other but kept out of the mean;
    /// `PLAN_MOVED_RUN` of them in a row are the schedule itself moving (a master that
    /// skipped cycles without a word), and the plan starts again from there, deviation 0.
    /// (Starting again at a single outlier would put the plan where that one late wake-up
    /// was: the cycles after it, back on the master's schedule, would all look early by as
    /// much, and the loop would move the frames that much later, to the SYNC0 and past it,
    /// for thousands of cycles on pc-stock.)
    fn lateness_deviation(&mut self, built_ns: u64) -> i64 {
        let Some(plan) = self.plan_ns else {
            self.plan_ns = Some(built_ns);
            self.lateness.push(0);
            return 0;
        };
        let late = built_ns.wrapping_sub(plan) as i64;
        let mean = self.lateness.mean();
        let dev = late.wrapping_sub(mean);
        if dev.unsigned_abs() > self.cycle_ns / 2 {
            self.off_plan_run += 1;
            if self.off_plan_run < PLAN_MOVED_RUN {
                return dev;
            }
            self.plan_ns = Some(built_ns.wrapping_add_signed(mean.wrapping_neg()));
            self.off_plan_run = 0;
            return 0;
        }
        self.off_plan_run = 0;
        self.lateness.push(late);
        dev
    }

    /// The plan moved on by the period returned (master follows reference only).
    fn planned(&mut self, c: Correction) -> Correction {
        if let (Some(plan), Some(period)) = (self.plan_ns, c.next_period_ns) {
            self.plan_ns = Some(plan.wrapping_add(period));
        }
        c
    }
}

impl Ferrocat {
    /// Reference-follows-master, steering the reference's System_Time_Offset.
    fn steers_reference_offset(&self) -> bool {
        self.coupling == Coupling::ReferenceFollowsMaster && self.steering == Steering::Offset
    }

    /// How many probes the line wants after this cycle's frame.
    fn probes_wanted(&self) -> u32 {
        let (Some(sd), Some(lead)) = (self.fit.sd_ahead_ns(self.cycle_ns), self.lead_ns) else { return 0 };
        let uncertain = sd > self.fit.scale_ns() * PROBE_TARGET_SCALES;
        let half_cycle = uncertain || self.probe_every_cycle;
        if !self.probing || !self.keeps_line() || !(half_cycle || self.fit.suspicion() >= PROBE_SUSPICION) {
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
        self.coupling
    }
    fn reference_time(&mut self, built_ns: u64) -> u64 {
        let feedback = if self.error_feedback { self.last_send_error_ns } else { 0 };
        built_ns.wrapping_add_signed(self.lead_ns.unwrap_or(0).wrapping_sub(feedback))
    }
    fn plan(&self, cycle: u64) -> CyclePlan {
        let steer = self.steers_reference_offset();
        CyclePlan {
            write_reference_time: cycle % self.write_every.max(1) == 0,
            steer_reference_offset: steer,
            read_follower_clock: self.flywheel.is_some() && self.keeps_line(),
            probes: self.probes_wanted(),
            probe_window_ns: self.cycle_ns,
            probes_give_offset: self.probes_steer && steer,
            // Steering by offset, a lost frame leaves the reference on its crystal's rate for
            // two cycles instead of one: twice the sawtooth.
            make_up_lost_frames: self.make_up && steer,
        }
    }
    fn update(&mut self, s: Option<&Sample>) -> Correction {
        let Some(s) = s else {
            self.aimed_ns = self.aimed_ns.map(|a| a.wrapping_add(self.cycle_ns));
            let next_period_ns = (self.coupling == Coupling::MasterFollowsReference).then_some(self.cycle_ns);
            return self.planned(Correction { shift_offsets_ns: 0, next_period_ns });
        };
        self.leads.push(s.lead_ns());
        self.lead_ns = Some(self.leads.trimmed_mean().wrapping_sub(self.calibration_ns));
        if let Some(tx) = s.tx_ns {
            let send = tx.wrapping_sub(s.built_ns) as i64;
            self.sends.push(send);
            self.last_send_error_ns = send.wrapping_sub(self.sends.trimmed_mean());
        }
        if self.coupling == Coupling::ReferenceFollowsMaster {
            if let Some(y) = self.line_point(s) {
                self.reference_offset_read = s.reference_offset_ns;
                self.fit_passage(s, y);
            }
            return Correction { shift_offsets_ns: std::mem::take(&mut self.pending_shift_ns), next_period_ns: None };
        }
        let dev = self.lateness_deviation(s.built_ns);
        let x = self.fit_passage(s, s.reference_ns);
        // The reference's time, from the fit, where this frame would have passed had its
        // cycle started as late as cycles do on average; its phase in the cycle against the
        // target, in integers.
        let (Some(y), Some(rate)) = (self.line_at(x.wrapping_add_signed(dev.wrapping_neg())), self.line_rate()) else {
            return self.planned(Correction { shift_offsets_ns: 0, next_period_ns: Some(self.cycle_ns) });
        };
        let c = self.cycle_ns as f64;
        let mut phase = (y.wrapping_sub(self.phase_ns) % self.cycle_ns) as f64;
        if phase > c / 2.0 {
            phase -= c;
        }
        // One cycle of reference time is cycle/rate of master time; 1/16 of the phase error is
        // taken out per cycle, so that the line's and the mean's own noise averages away.
        let mut period = (c - phase / 16.0) / rate;
        let hold = self.slots_to_hold(s);
        period += hold as f64 * c / rate;
        self.held_back += hold;
        self.planned(Correction { shift_offsets_ns: 0, next_period_ns: Some(period.max(1.0) as u64) })
    }
    fn reference_offset(&mut self, built_ns: u64, holds_ns: Option<u64>) -> Option<u64> {
        // Until the next frame gives it another offset the reference runs at its own crystal's
        // rate; aiming its time at the master's halfway through that span centres the
        // sawtooth (±|rate − 1|·span/2) on the master's time.
        let passage = built_ns.wrapping_add_signed(self.lead_ns?);
        let aim = passage.wrapping_add(holds_ns.unwrap_or(self.cycle_ns) / 2);
        let offset = aim.wrapping_sub(self.line_at(aim)?);
        self.offset_given_ns = Some(offset);
        if !self.offset_given {
            let step = offset.wrapping_sub(self.reference_offset_read?) as i64;
            self.pending_shift_ns = self.pending_shift_ns.saturating_add(step);
            self.offset_given = true;
        }
        Some(offset)
    }
    fn master_time(&self, host_ns: u64) -> Option<u64> {
        match self.coupling {
            Coupling::MasterFollowsReference => self.line_at(host_ns),
            Coupling::ReferenceFollowsMaster => None,
        }
    }
    fn reference_belief_ns(&self, host_ns: u64) -> u64 {
        // Steering the offset, the reference runs on its crystal from the instant it was aimed
        // at: its time is the line's local time plus the offset last given. Compared at the
        // master's own time instead, a calibration took the sawtooth's value where its pulses
        // fell for an error of the stamps (at 4 ms cycles up to ±75 ns; in the demo at 1 ms
        // 17 ns, its whole mean error there).
        match (self.coupling, self.steering, self.offset_given_ns) {
            (Coupling::ReferenceFollowsMaster, Steering::Offset, Some(offset)) => {
                self.line_at(host_ns).map_or(host_ns, |local| local.wrapping_add(offset))
            }
            _ => self.master_time(host_ns).unwrap_or(host_ns),
        }
    }
    fn probe(&mut self, s: &Sample) {
        if let Some(y) = self.line_point(s) {
            self.fit_passage(s, y);
        }
    }
    fn line_events(&self) -> Option<LineEvents> {
        // With a flywheel the estimate is two lines, the crystal's and ε's: a step of either
        // crystal restarts one of them.
        let eps = self.flywheel.as_ref().map(|fw| fw.eps_events()).unwrap_or_default();
        self.keeps_line().then_some(LineEvents {
            restarts: self.fit.restarts + eps.restarts,
            false_alarms: self.fit.false_alarms + eps.false_alarms,
        })
    }
    fn follower_delay_bias_ns(&mut self) -> Option<i64> {
        if !self.steers_reference_offset() || !self.centre_followers {
            return None;
        }
        // The followers' loops lock to the reference as the frame reads it, a cycle after its
        // last offset: (rate − 1)·cycle/2 above the master, the top of its sawtooth. A delay
        // register larger by b puts a follower b later (its loop compares the time received
        // with its own less the delay), so −(rate − 1)·cycle/2 centres them on the reference.
        let half_cycle = self.cycle_ns as f64 / 2.0;
        let bias = -(self.line_rate()? - 1.0) * half_cycle;
        // No crystal is 200 ppm off: a wilder rate is a young line's.
        let limit = half_cycle * 2e-4;
        let bias = bias.clamp(-limit, limit).round() as i64;
        // Each change is a step the followers' loops slew out: only one that stands out from
        // the rate's own uncertainty (3 σ) and the loops' 10 ns tick is worth it.
        // A line over a few cycles, dense with probes, can look certain of a rate it does not
        // know (on a live kernel such lines swung it by ±100 ppm): act on longer ones only.
        if self.fit.span_ns() < DELAY_BIAS_MIN_SPAN_CYCLES * self.cycle_ns {
            return None;
        }
        let sd = self.fit.rate_sd()? * half_cycle;
        if ((bias - self.delay_bias_ns).abs() as f64) < (3.0 * sd).max(DELAY_BIAS_STEP_NS) {
            return None;
        }
        self.delay_bias_ns = bias;
        Some(bias)
    }
    fn take_error(&mut self, error_ns: i64) -> bool {
        // The master (or its estimate of the reference) is ahead by `error_ns`: the passages
        // were that much earlier than the stamps said. Past passages move at once too.
        self.calibration_ns = self.calibration_ns.saturating_sub(error_ns);
        self.lead_ns = self.lead_ns.map(|l| l.wrapping_add(error_ns));
        self.fit.shift_x(error_ns);
        if let Some(c) = self.contest.as_mut() {
            c.direct.shift_x(error_ns);
        }
        if let Some(t) = self.trial.as_mut() {
            t.other_fit.shift_x(error_ns);
        }
        if self.steers_reference_offset() {
            self.pending_shift_ns = self.pending_shift_ns.saturating_add(error_ns);
        }
        true
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::sync::tests::sample;
    use rand::SeedableRng;
    use rand_distr::{Distribution, Normal};

    /// The line y = x, frozen: the direct line and ε's (ε = 0) before a change.
    fn identity_line() -> FrozenLine {
        let mut f = LineFit::new(16);
        f.push(1_000_000_000, 1_000_000_000);
        f.push(2_000_000_000, 2_000_000_000);
        f.frozen_at(2_000_000_000).unwrap()
    }

    /// A kink test fed one frame a ms after a 50 ppm change, the stamps scattered by 1 µs:
    /// ε departs by `g(k)` in the reading in use and `other(k)` in the other (on trial), the
    /// reference by `moved(k)`. The verdict and the frame it came at.
    fn kink_verdict(
        g: impl Fn(f64) -> f64,
        other: Option<&dyn Fn(f64) -> f64>,
        moved: impl Fn(f64) -> f64,
        seed: u64,
    ) -> Option<(Verdict, u32)> {
        let mut rng = rand_chacha::ChaCha8Rng::seed_from_u64(seed);
        let noise = Normal::new(0.0, 1000.0).unwrap();
        let line = identity_line();
        let mut k = KinkTest { direct: line, eps: line, llr: 0.0, other: other.map(|_| (line, 0.0)), frames: 0 };
        for n in 1..=KINK_MAX_FRAMES {
            let t = 2_000_000_000 + n as u64 * 1_000_000;
            let c = n as f64;
            let y = t.wrapping_add_signed((moved(c) + noise.sample(&mut rng)) as i64);
            if let Some(v) = k.score(t, y, t, g(c) as i64, other.map(|o| o(c) as i64), 1000.0) {
                return Some((v, n));
            }
        }
        None
    }

    /// Which crystal changed, from ε's departure (50 ns more each ms) and the stamps: the
    /// reference's when its points leave the direct line by that departure, the follower's
    /// when they stay; on trial, the reading whose departure the reference followed. Each
    /// within tens of frames, and the same verdict over ten realisations of the noise.
    #[test]
    fn the_kink_test_tells_which_crystal_changed_and_which_reading_is_right() {
        let ramp = |c: f64| 50.0 * c;
        let turned = |c: f64| -50.0 * c;
        for seed in 0..10 {
            let cases: [(Option<(Verdict, u32)>, Verdict); 5] = [
                (kink_verdict(ramp, None, ramp, seed), Verdict::ReferenceChanged),
                (kink_verdict(ramp, None, |_| 0.0, seed), Verdict::FollowerChanged),
                (kink_verdict(ramp, Some(&turned), ramp, seed), Verdict::ReferenceChanged),
                (kink_verdict(ramp, Some(&turned), turned, seed), Verdict::ReferenceChangedOtherReading),
                (kink_verdict(ramp, Some(&turned), |_| 0.0, seed), Verdict::FollowerChanged),
            ];
            println!("seed {seed}: {cases:?}");
            for (got, want) in cases {
                let (v, frames) = got.unwrap_or_else(|| panic!("seed {seed}: no verdict, {want:?} wanted"));
                assert_eq!(v, want, "seed {seed}");
                assert!(frames <= 60, "seed {seed}: {v:?} after {frames} frames");
            }
        }
    }

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
    fn error_feedback_takes_the_last_send_error_back_out() {
        let mut f = Ferrocat::new(Coupling::ReferenceFollowsMaster, 1_000_000);
        f.error_feedback = true;
        let stamped = |k: u64, send: u64| {
            let mut s = sample(k, 0, 0);
            s.tx_ns = Some(s.built_ns + send);
            s.frame_ns = 0;
            s
        };
        for k in 1..=32 {
            f.update(Some(&stamped(k, 1_000)));
        }
        let base = f.reference_time(0);
        // A frame that left 2 µs late: the next time written is 2 µs earlier than it would be.
        f.update(Some(&stamped(33, 3_000)));
        let lead_change = f.lead_ns().unwrap() - base as i64;
        assert_eq!(f.reference_time(0) as i64, base as i64 + lead_change - 2_000);
        f.error_feedback = false;
        assert_eq!(f.reference_time(0) as i64, base as i64 + lead_change);
    }

    #[test]
    fn a_frame_that_ended_past_its_sync0_holds_the_next_back_one_cycle() {
        let c = 50_000;
        let mut f = Ferrocat::new(Coupling::MasterFollowsReference, c);
        f.sync0_phase_ns = Some(c / 2);
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
        assert!(period(&mut f, 100, 19_000) < c * 3 / 2 && f.held_back == 0);
        assert!(period(&mut f, 101, 21_000) > c * 3 / 2 && f.held_back == 1);
        // Early (its end 2 µs before its target, or its head 7 µs): not taken for late.
        assert!(period(&mut f, 103, -7_000) < c * 3 / 2 && f.held_back == 1);
        // Without a SYNC0 to serve, never.
        f.sync0_phase_ns = None;
        assert!(period(&mut f, 104, 30_000) < c * 3 / 2 && f.held_back == 1);
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
        f.sync0_phase_ns = Some(c / 2);
        f.probing = false;
        let mut t = 3 * c;
        let mut holds = Vec::new();
        for k in 1..600u64 {
            let built = t + if k >= 200 { c * 6 / 10 } else { 0 };
            let s = passing(k, built, 8_000, 3_000);
            let before = f.held_back;
            t += f.update(Some(&s)).next_period_ns.unwrap();
            holds.push(f.held_back - before);
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
    fn one_wake_up_later_than_half_a_cycle_does_not_move_the_plan() {
        let c = 250_000u64;
        let mut f = Ferrocat::new(Coupling::MasterFollowsReference, c);
        let t0 = 10 * c;
        let mut plan = t0;
        let mut step = |f: &mut Ferrocat, late: u64| {
            let dev = f.lateness_deviation(plan + late);
            f.plan_ns = f.plan_ns.map(|p| p + c);
            plan += c;
            dev
        };
        for _ in 0..100 {
            assert_eq!(step(&mut f, 20_000), 0);
        }
        // One wake-up 300 µs late is that far off, and the cycles after it are on the plan
        // again (they looked 280 µs early when that one had moved the plan).
        assert_eq!(step(&mut f, 320_000), 300_000);
        for _ in 0..10 {
            assert_eq!(step(&mut f, 20_000), 0);
        }
        // A schedule that moved by 300 µs for good: the plan follows on the sixteenth cycle.
        let devs: Vec<i64> = (0..18).map(|_| step(&mut f, 320_000)).collect();
        assert!(devs[..15].iter().all(|&d| d == 300_000) && devs[15..] == [0, 0, 0], "{devs:?}");
    }

    #[test]
    fn a_late_wake_up_is_not_fed_back_into_the_period() {
        // The reference on the master's clock exactly; each cycle starts 0–40 µs late (known
        // only after the fact) and its frame passes the reference 5 µs after it is built.
        let c = 1_000_000u64;
        let mut f = Ferrocat::new(Coupling::MasterFollowsReference, c);
        f.probing = false;
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
        f.centre_followers = false;
        f.delay_bias_ns = 0;
        assert_eq!(f.follower_delay_bias_ns(), None);
        let mut tcl = Ferrocat::new(Coupling::ReferenceFollowsMaster, c);
        tcl.steering = Steering::TimeControlLoop;
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
