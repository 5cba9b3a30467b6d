//! ferrocat's estimate of the reference's clock: a line through the frames' passages, and
//! with a flywheel, a follower's crystal plus the reference's difference from it, the two
//! estimates contested frame by frame (docs/clock-sync.md, "The line" and "Flywheel").
use super::super::flywheel::Flywheel;
use super::super::{LineEvents, Sample};
use crate::line_fit::{Fate, FrozenLine, LineFit};
use crate::rtt_weight::RttWeight;
use crate::trimmed::TrimmedWindow;

/// The estimate of the reference's clock against the master's: the line through the frames'
/// passages (master time, reference time), with a flywheel where the method has one.
#[derive(Debug)]
pub(super) struct Estimator {
    cycle_ns: u64,
    /// (master time at passage, reference time): the line through them; with a flywheel, the
    /// follower's crystal's line.
    fit: LineFit,
    /// Half round trips from the transmit stamp (or the build time), for the fit's abscissa.
    halves: TrimmedWindow,
    rtt: RttWeight,
    /// A follower's crystal as the flywheel the line runs on (`Estimator::with_flywheel`).
    flywheel: Option<Flywheel>,
    contest: Option<Contest>,
    /// Which way the speed counter moves the clock, while it is being found out.
    trial: Option<Trial>,
}

/// Where a frame passed the reference on the master's clock, and how far the estimate in use
/// moved as it took the frame (a change of the line's window, or of the estimate the contest
/// uses), in ns.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub(super) struct Passage {
    pub(super) x_ns: u64,
    pub(super) jump_ns: i64,
}

/// The datasheet gives the speed counter's deviation but not its direction, so the flywheel
/// starts with both readings: `Estimator::flywheel` and `fit` take a positive SCD to slow the
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
/// The half round trips' centre is a trimmed mean over this many. A cycle's probes come in a
/// burst and share the centre; over 64 (two cycles of bursts) its error was a burst's own and
/// counted in the change test once per point, which took it for a change of the line (a false
/// restart 4.2 s after a crystal step, pc-rt seed 2).
const CENTRE_WINDOW: usize = 1024;
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

impl Estimator {
    /// The line through the reference's own points, over up to `window` points, on a cycle of
    /// `cycle_ns`.
    pub(super) fn new(window: usize, cycle_ns: u64) -> Self {
        Estimator {
            cycle_ns,
            fit: Estimator::line(window, cycle_ns),
            halves: TrimmedWindow::new(CENTRE_WINDOW),
            rtt: RttWeight::new(),
            flywheel: None,
            contest: None,
            trial: None,
        }
    }

    /// The line run on a follower's crystal, the reference's difference from it read from the
    /// hardware every cycle (flywheel.rs).
    pub(super) fn with_flywheel(self) -> Self {
        let line = || Estimator::line(FIT_WINDOW, self.cycle_ns);
        let trial = Trial { other: Flywheel::new(line(), false), other_fit: line(), frames: 0 };
        Estimator {
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
    pub(super) fn flywheel_eps(&self) -> Option<(u64, i64)> {
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
    pub(super) fn at(&self, x: u64) -> Option<u64> {
        match &self.contest {
            Some(c) if c.use_direct || self.flywheel.is_none() => c.direct.at(x),
            _ => self.flywheel_at(x),
        }
    }

    /// The line's rate (reference per master time).
    pub(super) fn rate(&self) -> Option<f64> {
        if let Some(c) = self.contest.as_ref().filter(|c| c.use_direct || self.flywheel.is_none()) {
            return c.direct.rate();
        }
        let r = self.fit.rate()?;
        // dR/dx = dC/dx + dε/dR·dR/dx.
        Some(self.flywheel.as_ref().map_or(r, |fw| r / (1.0 - fw.eps_slope())))
    }

    /// The method's line over up to `window` points, its shorter windows scored on the frames.
    pub(super) fn line(window: usize, cycle_ns: u64) -> LineFit {
        LineFit::new(window).score_gap(cycle_ns / SCORE_GAP_DIVISOR)
    }

    /// Offers (passage of `s` on the master's clock, `y`) to the fit. The passage is the
    /// transmit stamp (or the build time) plus the trimmed mean of the half round trips, moved
    /// by the part of this frame's own deviation from it learned to be the way out
    /// (rtt_weight.rs).
    pub(super) fn push(&mut self, s: &Sample, y: u64, calibration_ns: i64) -> Passage {
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
        let stamp = sent.wrapping_add_signed(centre.wrapping_sub(calibration_ns));
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
        Passage { x_ns: x, jump_ns: jump }
    }

    /// The line in use: the crystal's where there is a flywheel, for how certain it is.
    pub(super) fn fit(&self) -> &LineFit {
        &self.fit
    }

    /// Whether the estimate reads a follower's crystal.
    pub(super) fn has_flywheel(&self) -> bool {
        self.flywheel.is_some()
    }

    /// What the estimate's lines have been through. With a flywheel the estimate is two
    /// lines, the crystal's and ε's: a step of either crystal restarts one of them.
    pub(super) fn events(&self) -> LineEvents {
        let eps = self.flywheel.as_ref().map(|fw| fw.eps_events()).unwrap_or_default();
        LineEvents {
            restarts: self.fit.restarts + eps.restarts,
            false_alarms: self.fit.false_alarms + eps.false_alarms,
        }
    }

    /// Moves every passage taken so far by `error_ns` of master time (a calibration found the
    /// passages that much earlier than the stamps said).
    pub(super) fn shift_x(&mut self, error_ns: i64) {
        self.fit.shift_x(error_ns);
        if let Some(c) = self.contest.as_mut() {
            c.direct.shift_x(error_ns);
        }
        if let Some(t) = self.trial.as_mut() {
            t.other_fit.shift_x(error_ns);
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;
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
}
