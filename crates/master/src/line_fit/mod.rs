//! A least-squares line through (master time, reference time) pairs whose window grows while
//! the points agree with it and restarts when they stop agreeing.
//!
//! Why adaptive: the host's timestamps scatter by hundreds of ns (a stock kernel: µs), while
//! two crystals' rates drift by far less than that over seconds, so the longer the window the
//! better the line (its phase error falls as 1/√n) — until a crystal changes its rate (a
//! temperature step), when a long window keeps the old slope for seconds. A CUSUM of the
//! standardised innovations (each point's distance from the line before it joins) tells the
//! two apart: noise keeps it near zero, a change of rate or phase drives it up within a few
//! dozen points, and the window then restarts at the estimated change point — a long window
//! only once the points after the signal confirm it, since the test's rare false alarm would
//! otherwise trade a line of thousands of points for a young one. Single points
//! far off the line (a preempted send, a stamp taken late) are left out and do not count.
//!
//! A restarted window knows its new rate only from the few points since the change, which
//! probing packs into bursts a fraction of a cycle wide: their slope alone can be hundreds of
//! ppm off and, extrapolated a cycle, put the line µs away (4.4 µs once on pc-stock). So the
//! slope carries a prior from the line before the restart (a Gaussian of `RATE_CHANGE_SD`
//! about the old rate — a crystal's rate steps by tens of ppm, not hundreds): the maximum a
//! posteriori slope, (Σ(x − x̄)(z − z̄) + λ·s₀) / (Σ(x − x̄)² + λ) with λ = σ²/τ², is the old
//! rate while the window is a burst and the data's own within milliseconds.
//!
//! The sums are kept exactly in i128 about an origin, so adding and dropping a point costs
//! O(1) however long the window and the line never drifts from rounding.
//!
//! Inside the window, shorter ones (its newest points) keep lines of their own, and one of
//! them is the line in use where it has foretold the points better: crystals that wander in
//! frequency (shorter.rs).
use std::collections::VecDeque;

mod shorter;
use shorter::Shorter;

/// Points the noise scale is learned on before any is rejected or counted as a change.
const WARM_UP: usize = 16;
/// An innovation beyond this many noise scales is an outlier.
const OUTLIER_SCALES: f64 = 6.0;
/// CUSUM allowance and threshold, in noise scales (Page's test, k = 0.5, h = 16: Gaussian
/// noise trips one side about once in 3·10⁷ points (Siegmund's approximation), a ramp of
/// 50 ns per point in 1 µs of noise within ≈ 40).
const CUSUM_K: f64 = 0.5;
const CUSUM_H: f64 = 16.0;
/// This many outliers in a row on one side are a jump of the line, not outliers.
const JUMP_RUN: usize = 8;
/// A change the CUSUM signals is confirmed by the points after it: as soon as their mean
/// innovation lies on the change's side by `CONFIRM_SCALES` standard errors. It was the test's
/// false alarm, and the line stays, if after `DISMISS_AFTER` points their mean is on the other
/// side, or none confirmed it within `CONFIRM_POINTS`.
const CONFIRM_POINTS: u32 = 32;
const DISMISS_AFTER: u32 = 4;
const CONFIRM_SCALES: f64 = 3.0;
/// Only a window this long is worth a confirmation's delay (a young one restarts at once).
const CONFIRM_MIN_WINDOW: usize = 4096;
/// Points kept at least when the window restarts.
const MIN_RESTART: usize = 4;
/// The smallest noise scale (ns): the ESC's clock ticks in 10 ns.
const MIN_SCALE_NS: f64 = 2.0;
/// The noise scale is an exponential mean of |innovation| over about this many points.
const SCALE_MEMORY: f64 = 64.0;
/// The prior's standard deviation of a change of rate across a restart (τ above). Crystals
/// are specified within ±50–100 ppm over their whole temperature range, so no step exceeds
/// that.
const RATE_CHANGE_SD: f64 = 100e-6;
/// Rates further than this from 1 are clamped (1000 ppm: far beyond any crystal).
const MAX_RATE_ERROR: f64 = 1e-3;
/// Points further apart than this (ns, 18 minutes) do not share a line: the window restarts.
/// With at most `MAX_POINTS` points of |dx|, |dz| ≤ 2·SPAN the i128 sums cannot overflow.
const SPAN: u64 = 1 << 40;
const MAX_POINTS: usize = 1 << 16;

/// What became of a point.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Fate {
    /// Joined the window.
    Added,
    /// Too far off the line: left out.
    Outlier,
    /// The points had stopped agreeing with the line: the window restarted (this point in it).
    Restarted,
}

/// Exact sums of the window's points about `origin`: `dx = x − x₀`, `dz = (y − y₀) − dx`
/// (the reference's deviation from rate 1, which stays small).
#[derive(Debug, Clone, Copy, Default)]
struct Sums {
    n: i128,
    x: i128,
    xx: i128,
    z: i128,
    xz: i128,
}

impl Sums {
    fn account(&mut self, dx: i64, dz: i64, sign: i128) {
        let (dx, dz) = (dx as i128, dz as i128);
        self.n += sign;
        self.x += sign * dx;
        self.xx += sign * dx * dx;
        self.z += sign * dz;
        self.xz += sign * dx * dz;
    }

    /// n·Σ(xᵢ − x̄)² and n·Σ(xᵢ − x̄)(zᵢ − z̄) (n² times var(x) and cov(x, z)), exact.
    fn centred(&self) -> (i128, i128) {
        (self.n * self.xx - self.x * self.x, self.n * self.xz - self.x * self.z)
    }
}

/// A line as (slope of dz on dx, mean dx, mean dz).
type Line = (f64, f64, f64);

/// The line's dz at `dx`.
fn dz_at((slope, mx, mz): Line, dx: f64) -> f64 {
    mz + slope * (dx - mx)
}

/// A line kept as it was: y = y0 + (x − x0)·(1 + slope), on the wrapping u64 circle.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct FrozenLine {
    x0: u64,
    y0: u64,
    slope: f64,
}

impl FrozenLine {
    pub fn at(&self, x: u64) -> u64 {
        let dx = x.wrapping_sub(self.x0) as i64;
        // `as` saturates: a line read seconds away stays finite.
        self.y0.wrapping_add_signed(dx).wrapping_add_signed((self.slope * dx as f64).round() as i64)
    }
}

#[derive(Debug, Clone)]
pub struct LineFit {
    max_len: usize,
    points: VecDeque<(u64, u64)>,
    origin: (u64, u64),
    sums: Sums,
    /// The whole window's line, refreshed on every change.
    line: Option<Line>,
    /// Shorter windows of the newest points, and which of them, if any, is the line in use.
    shorter: Vec<Shorter>,
    chosen: Option<usize>,
    /// Only points at least this long after the one before are scored (`LineFit::score_gap`).
    score_gap_ns: i64,
    /// How far changes of the line in use moved its value, not yet taken (ns).
    switch_jump_ns: f64,
    /// The slope of the line before the last restart: the prior of the new window's.
    prior_slope: Option<f64>,
    /// The prior's standard deviation (`RATE_CHANGE_SD`; tests compare others).
    rate_change_sd: f64,
    scale_ns: f64,
    innovations: u64,
    /// Points added so far (the window's and those since dropped).
    added: u64,
    /// Page's CUSUM upwards and downwards, and `added` when each last stood at zero.
    up: (f64, u64),
    down: (f64, u64),
    /// The outliers in a row so far, and on which side of the line.
    far_run: Vec<(u64, u64, bool)>,
    /// A change signalled and not yet confirmed.
    pending: Option<Signal>,
    pub outliers: u64,
    pub restarts: u64,
    pub false_alarms: u64,
}

/// A change the CUSUM signalled: its side, where it began (`added` then), and the points since
/// with the sum of their standardised innovations (signed so that the change's side counts up).
#[derive(Debug, Clone, Copy)]
struct Signal {
    up: bool,
    since: u64,
    points: u32,
    sum_z: f64,
}

impl LineFit {
    /// A fit over at most `max_len` points (at least 2).
    pub fn new(max_len: usize) -> Self {
        let max_len = max_len.clamp(2, MAX_POINTS);
        LineFit {
            max_len,
            points: VecDeque::with_capacity(max_len),
            origin: (0, 0),
            sums: Sums::default(),
            line: None,
            shorter: shorter::lengths(max_len).map(Shorter::new).collect(),
            chosen: None,
            score_gap_ns: 0,
            switch_jump_ns: 0.0,
            prior_slope: None,
            rate_change_sd: RATE_CHANGE_SD,
            scale_ns: 0.0,
            innovations: 0,
            added: 0,
            up: (0.0, 0),
            down: (0.0, 0),
            far_run: Vec::with_capacity(JUMP_RUN),
            pending: None,
            outliers: 0,
            restarts: 0,
            false_alarms: 0,
        }
    }

    /// A fit whose slope starts from `slope` (the rate less 1), known to a standard deviation
    /// `sd`, until its points say more; a restarted window's prior is the old line's, with the
    /// same `sd`.
    pub fn with_prior(max_len: usize, slope: f64, sd: f64) -> Self {
        let mut f = LineFit::new(max_len);
        f.prior_slope = Some(slope.clamp(-MAX_RATE_ERROR, MAX_RATE_ERROR));
        f.rate_change_sd = if sd > 0.0 { sd } else { RATE_CHANGE_SD };
        f
    }

    /// Scores the shorter lines only on points at least `gap_ns` after the one before: where
    /// points come in bursts whose stamps share the host's state (probes, a few µs apart), a
    /// line of the burst's own points foretells the next one of it better than the truth does,
    /// and would be chosen for that (on a live kernel: 256 points, 20 ms of probes, and the
    /// reference's error grew; docs/clock-sync.md). A cycle's frame, well after its last
    /// probe, is scored.
    pub fn score_gap(mut self, gap_ns: u64) -> Self {
        self.score_gap_ns = gap_ns.min(i64::MAX as u64) as i64;
        self
    }

    /// Keeps no shorter windows: the whole window's line is always the line in use (where
    /// the line is read back far into the past, which a shorter one does not reach).
    pub fn whole_only(mut self) -> Self {
        self.shorter.clear();
        self.chosen = None;
        self
    }

    /// Points in the window.
    pub fn len(&self) -> usize {
        self.points.len()
    }

    /// The noise scale learned (ns; 0 before the second point).
    pub fn scale_ns(&self) -> f64 {
        self.scale_ns
    }

    /// Offers the point (x, y).
    pub fn push(&mut self, x: u64, y: u64) -> Fate {
        let Some(predicted) = self.at(x) else {
            self.add(x, y);
            return Fate::Added;
        };
        let innovation = y.wrapping_sub(predicted) as i64 as f64;
        self.innovations += 1;
        // A restarted window too short for the change test still knows where its line is to
        // within its own spread (the prior holds its slope): its points are measured against
        // the spread of the innovation, σ·√(1 + 1/n + d²/P), so that a stamp µs off does not
        // join the few points the new line stands on.
        let young = self.points.len() < WARM_UP;
        let spread = if young { self.line_var_at(x).map(|v| (1.0 + v).sqrt()) } else { Some(1.0) };
        // Neither outliers nor changes before the scale is learned, nor outliers where a young
        // window knows nothing of its slope, nor changes while it is young.
        if let Some(spread) = spread.filter(|_| self.innovations > WARM_UP as u64) {
            let z = innovation / (self.scale() * spread);
            if z.abs() > OUTLIER_SCALES {
                // One far point is an outlier; a run of them on one side is a jump.
                if self.far_run.last().is_some_and(|&(_, _, side)| side != (z > 0.0)) {
                    self.far_run.clear();
                }
                self.far_run.push((x, y, z > 0.0));
                if self.far_run.len() < JUMP_RUN {
                    self.outliers += 1;
                    return Fate::Outlier;
                }
                // The run becomes the new window (its buffer kept: the cyclic path does not
                // allocate).
                let mut run = std::mem::take(&mut self.far_run);
                self.restart(0);
                for &(x, y, _) in &run {
                    self.add(x, y);
                }
                run.clear();
                self.far_run = run;
                return Fate::Restarted;
            }
            self.far_run.clear();
        }
        if let (Some(mut signal), false) = (self.pending, young) {
            let z = innovation / self.scale();
            signal.points += 1;
            signal.sum_z += if signal.up { z } else { -z };
            if signal.sum_z / (signal.points as f64).sqrt() > CONFIRM_SCALES {
                return self.restart_at_change(signal.since, x, y);
            } else if signal.points < CONFIRM_POINTS && (signal.points < DISMISS_AFTER || signal.sum_z > 0.0) {
                self.pending = Some(signal);
            } else {
                self.pending = None;
                self.false_alarms += 1;
                self.up = (0.0, self.added);
                self.down = (0.0, self.added);
            }
        } else if self.innovations > WARM_UP as u64 && !young {
            let z = innovation / self.scale();
            // Page's CUSUM both ways; the count of points added when each last stood at zero
            // marks where a change began.
            self.up.0 = (self.up.0 + z - CUSUM_K).max(0.0);
            self.down.0 = (self.down.0 - z - CUSUM_K).max(0.0);
            if self.up.0 == 0.0 {
                self.up.1 = self.added;
            }
            if self.down.0 == 0.0 {
                self.down.1 = self.added;
            }
            if self.up.0 > CUSUM_H || self.down.0 > CUSUM_H {
                let up = self.up.0 > CUSUM_H;
                let since = if up { self.up.1 } else { self.down.1 };
                if self.points.len() < CONFIRM_MIN_WINDOW {
                    return self.restart_at_change(since, x, y);
                }
                self.pending = Some(Signal { up, since, points: 0, sum_z: 0.0 });
            }
        }
        // The scale follows the accepted innovations (mean |·| of a normal is 0.8 σ).
        let a = innovation.abs().min(SPAN as f64) * 1.2533;
        self.scale_ns = if self.innovations == 1 { a } else { self.scale_ns + (a - self.scale_ns) / SCALE_MEMORY };
        self.score_shorter(x, y);
        if self.add(x, y) {
            self.restarts += 1;
            return Fate::Restarted;
        }
        Fate::Added
    }

    /// A change began when `since` points had been added: the window keeps the points from
    /// there on (at least `MIN_RESTART`) and takes (x, y).
    fn restart_at_change(&mut self, since: u64, x: u64, y: u64) -> Fate {
        self.restart(((self.added - since) as usize).max(MIN_RESTART));
        self.add(x, y);
        Fate::Restarted
    }

    /// Scores the shorter windows' lines on the accepted point (x, y) before it joins, and
    /// chooses the line in use (shorter.rs).
    fn score_shorter(&mut self, x: u64, y: u64) {
        let Some(whole) = self.line else { return };
        if self.points.back().is_some_and(|&(newest, _)| (x.wrapping_sub(newest) as i64) < self.score_gap_ns) {
            return;
        }
        let (dx, dz) = self.rel((x, y));
        let (dx, dz) = (dx as f64, dz as f64);
        let r_whole = dz - dz_at(whole, dx);
        // Every window is scored on every point, so that their means are over the same points
        // against the same whole window (scored only once shorter, a window's mean was over
        // other points than another's, and the whole window's growth in between favoured the
        // one scored later: a rate walk's line moved to 8 192 points from 2 048 and stayed).
        let n = self.sums.n;
        for w in &mut self.shorter {
            if let Some(line) = w.line {
                w.score.add(dz - dz_at(line, dx), r_whole, w.sums.n < n);
            }
        }
        let chosen = shorter::choose(self.chosen, &self.shorter, |k| self.shorter[k].sums.n < n);
        if chosen != self.chosen {
            let at =
                |c: Option<usize>| c.and_then(|k| self.shorter[k].line).or(self.line).map_or(0.0, |l| dz_at(l, dx));
            self.switch_jump_ns += at(chosen) - at(self.chosen);
            self.chosen = chosen;
        }
    }

    /// The shorter windows' scores start again (points too far from the window's to share a
    /// line: whatever the scores said was of another run).
    fn forget_scores(&mut self) {
        for w in &mut self.shorter {
            w.score = Default::default();
        }
    }

    /// Drops all but the newest `keep` points.
    fn restart(&mut self, keep: usize) {
        self.keep_prior();
        self.chosen = None;
        let n = self.points.len();
        let keep = keep.min(n);
        self.points.drain(..n - keep);
        self.rebuild();
        self.up = (0.0, self.added);
        self.down = (0.0, self.added);
        self.far_run.clear();
        self.pending = None;
        self.restarts += 1;
    }

    /// The line at `x` (None before the first point).
    pub fn at(&self, x: u64) -> Option<u64> {
        Some(self.value_at(self.in_use().1?, x))
    }

    fn value_at(&self, line: Line, x: u64) -> u64 {
        let dx = x.wrapping_sub(self.origin.0) as i64;
        let dz = dz_at(line, dx as f64);
        self.origin.1.wrapping_add_signed(dx).wrapping_add_signed(dz.round() as i64)
    }

    /// The sums and the line in use: the whole window's or a shorter one's that foretold the
    /// points better.
    fn in_use(&self) -> (&Sums, Option<Line>) {
        match self.chosen.and_then(|k| self.shorter.get(k)) {
            Some(w) => (&w.sums, w.line),
            None => (&self.sums, self.line),
        }
    }

    /// The line in use at `x`, frozen: what it foretells from here on however the window
    /// changes (None before the first point).
    pub fn frozen_at(&self, x: u64) -> Option<FrozenLine> {
        Some(FrozenLine { x0: x, y0: self.at(x)?, slope: self.rate()? - 1.0 })
    }

    /// How far the line's value moved (ns) when the line in use changed from one window's to
    /// another's since the last call: a reference steered by its offset takes that as a step,
    /// which its followers should take with it rather than chase (`Ferrocat`).
    pub fn take_switch_jump_ns(&mut self) -> i64 {
        // `as` saturates, and a jump is at most the window's spread anyway.
        std::mem::take(&mut self.switch_jump_ns).round() as i64
    }

    /// Points in the line in use (the window's, or the shorter window's chosen).
    #[cfg(test)]
    pub fn len_in_use(&self) -> usize {
        self.in_use().0.n as usize
    }

    /// The standard deviation (ns) of the whole window's line `ahead_ns` past its newest point,
    /// from the noise scale and the window's spread: σ·√(1/n + (x − x̄)²/(Σ(xᵢ − x̄)² + λ)), λ
    /// the prior's weight (0 without one). `None` before two distinct x where there is no
    /// prior. The whole window's even where a shorter line is in use: this is what waiting for
    /// points makes certain, which is what probing asks (with wandering crystals, probing by
    /// the shorter line's spread bought nothing measurable: docs/clock-sync.md).
    pub fn sd_ahead_ns(&self, ahead_ns: u64) -> Option<f64> {
        let &(newest, _) = self.points.back()?;
        Some(self.scale() * self.var_at(&self.sums, newest.wrapping_add(ahead_ns))?.sqrt())
    }

    /// The standard deviation (ns) of the line's value at `x`.
    pub fn sd_at_ns(&self, x: u64) -> Option<f64> {
        Some(self.scale() * self.line_var_at(x)?.sqrt())
    }

    /// The variance of the line in use's value at `x` in units of σ²: 1/n + (x − x̄)²/P.
    fn line_var_at(&self, x: u64) -> Option<f64> {
        self.var_at(self.in_use().0, x)
    }

    /// The same for the line through `s`.
    fn var_at(&self, s: &Sums, x: u64) -> Option<f64> {
        let precision = self.slope_precision(s)?;
        let n = s.n as f64;
        let d = x.wrapping_sub(self.origin.0) as i64 as f64 - s.x as f64 / n;
        Some(1.0 / n + d * d / precision)
    }

    /// How far the change test is towards restarting the window: its larger CUSUM over the
    /// threshold (0 while the points agree with the line, 1 restarts).
    pub fn suspicion(&self) -> f64 {
        self.up.0.max(self.down.0) / CUSUM_H
    }

    /// The reference's rate against the master's (1 before there are two distinct x).
    pub fn rate(&self) -> Option<f64> {
        self.in_use().1.map(|(slope, _, _)| 1.0 + slope)
    }

    /// The master time from the window's oldest point to its newest (ns).
    pub fn span_ns(&self) -> u64 {
        match (self.points.front(), self.points.back()) {
            (Some(a), Some(b)) => b.0.wrapping_sub(a.0),
            _ => 0,
        }
    }

    /// The standard deviation of [`LineFit::rate`], from the noise scale and the window's
    /// spread: σ/√(Σ(xᵢ − x̄)² + λ). `None` before two distinct x where there is no prior.
    pub fn rate_sd(&self) -> Option<f64> {
        Some(self.scale() / self.slope_precision(self.in_use().0)?.sqrt())
    }

    /// Σ(xᵢ − x̄)² plus the prior's λ (ns²) of the points summed in `s`: the slope's
    /// precision times σ². `None` while they say nothing of the slope and there is no prior.
    fn slope_precision(&self, s: &Sums) -> Option<f64> {
        let (sxx, _) = s.centred();
        let spread = if sxx > 0 { sxx as f64 / s.n as f64 } else { 0.0 };
        let precision = spread + self.prior_weight();
        (s.n >= 1 && precision > 0.0).then_some(precision)
    }

    /// λ = σ²/τ² of the prior on the slope (0 without one).
    fn prior_weight(&self) -> f64 {
        match self.prior_slope {
            Some(_) => (self.scale() / self.rate_change_sd).powi(2),
            None => 0.0,
        }
    }

    fn scale(&self) -> f64 {
        self.scale_ns.max(MIN_SCALE_NS)
    }

    /// The line's slope becomes the prior of the window about to restart.
    fn keep_prior(&mut self) {
        if let Some((slope, _, _)) = self.line {
            self.prior_slope = Some(slope);
        }
    }

    /// Moves every point's x by `dx_ns` (a calibration found the abscissa off by that much).
    pub fn shift_x(&mut self, dx_ns: i64) {
        for (x, _) in self.points.iter_mut() {
            *x = x.wrapping_add_signed(dx_ns);
        }
        self.rebuild();
    }

    /// Adds the point; true if it was too far from the window's to share their line, which
    /// then starts again from it alone.
    fn add(&mut self, x: u64, y: u64) -> bool {
        self.added += 1;
        let far = |a: i64| a.unsigned_abs() > SPAN;
        if let Some(&oldest) = self.points.front() {
            let (dx_oldest, _) = self.rel_to(oldest, (x, y));
            let (_, dz) = self.rel((x, y));
            if far(dx_oldest) || far(dz) {
                self.keep_prior();
                self.forget_scores();
                self.chosen = None;
                self.pending = None;
                self.points.clear();
                self.points.push_back((x, y));
                self.rebuild();
                return true;
            }
        }
        if self.points.is_empty() {
            self.origin = (x, y);
        }
        if self.points.len() >= self.max_len {
            if let Some(old) = self.points.pop_front() {
                let (dx, dz) = self.rel(old);
                self.sums.account(dx, dz, -1);
            }
        }
        self.points.push_back((x, y));
        let (dx, dz) = self.rel((x, y));
        // Far from the origin: start the sums again about this point (exactness needs dx
        // well inside i64; 2⁴⁰ ns is 18 minutes).
        if far(dx) || far(dz) {
            self.rebuild();
            return false;
        }
        self.sums.account(dx, dz, 1);
        // Each shorter window takes the point and, once full, drops the one `len` back (the
        // whole window's oldest is never in a shorter one: `len` < `max_len`).
        let n = self.points.len();
        for k in 0..self.shorter.len() {
            let len = self.shorter[k].len;
            let dropped = (n > len).then(|| self.rel(self.points[n - 1 - len]));
            let w = &mut self.shorter[k];
            w.sums.account(dx, dz, 1);
            if let Some((dx, dz)) = dropped {
                w.sums.account(dx, dz, -1);
            }
        }
        self.refresh();
        false
    }

    fn rel(&self, p: (u64, u64)) -> (i64, i64) {
        self.rel_to(self.origin, p)
    }

    /// (dx, dz) of `p` about `o`.
    fn rel_to(&self, o: (u64, u64), (x, y): (u64, u64)) -> (i64, i64) {
        let dx = x.wrapping_sub(o.0) as i64;
        let dy = y.wrapping_sub(o.1) as i64;
        (dx, dy.wrapping_sub(dx))
    }

    /// The sums again from the points, about the newest point.
    fn rebuild(&mut self) {
        self.sums = Sums::default();
        if let Some(&newest) = self.points.back() {
            self.origin = newest;
        }
        // Every point is within SPAN of the oldest when it joins; this keeps the bound the
        // sums rely on whatever the history.
        while let Some(&p) = self.points.front() {
            let (dx, dz) = self.rel(p);
            if dx.unsigned_abs() <= 2 * SPAN && dz.unsigned_abs() <= 2 * SPAN {
                break;
            }
            self.points.pop_front();
        }
        let n = self.points.len();
        for w in &mut self.shorter {
            w.sums = Sums::default();
        }
        for k in 0..n {
            let (dx, dz) = self.rel(self.points[k]);
            self.sums.account(dx, dz, 1);
            for w in self.shorter.iter_mut().filter(|w| k + w.len >= n) {
                w.sums.account(dx, dz, 1);
            }
        }
        self.refresh();
    }

    fn refresh(&mut self) {
        self.line = self.line_through(&self.sums);
        for k in 0..self.shorter.len() {
            // A window no shorter than the whole one sums the same points: the same line.
            let s = self.shorter[k].sums;
            self.shorter[k].line = if s.n == self.sums.n { self.line } else { self.line_through(&s) };
        }
    }

    /// The line through the points summed in `s`: least squares, or with the prior the maximum
    /// a posteriori slope (module comment). `None` for no points.
    fn line_through(&self, s: &Sums) -> Option<Line> {
        if s.n == 0 {
            return None;
        }
        let (sxx, sxz) = s.centred();
        let n = s.n as f64;
        let slope = match self.prior_slope {
            Some(prior) => {
                let covariance = if sxx > 0 { sxz as f64 / n } else { 0.0 };
                // Σ(x − x̄)² + λ: never 0 with a prior.
                self.slope_precision(s).map_or(prior, |p| (covariance + self.prior_weight() * prior) / p)
            }
            None if sxx > 0 => sxz as f64 / sxx as f64,
            None => 0.0,
        }
        .clamp(-MAX_RATE_ERROR, MAX_RATE_ERROR);
        Some((slope, s.x as f64 / n, s.z as f64 / n))
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use proptest::prelude::*;
    use rand::{Rng, SeedableRng};
    use rand_distr::{Distribution, Normal};

    /// Points of a reference running `ppm` fast from `y0`, the master's stamps scattered by
    /// `sd_ns`, one per `cycle_ns`.
    fn points(n: usize, ppm: f64, sd_ns: f64, seed: u64) -> Vec<(u64, u64)> {
        let mut rng = rand_chacha::ChaCha8Rng::seed_from_u64(seed);
        let noise = Normal::new(0.0, sd_ns).unwrap();
        (0..n as u64)
            .map(|k| {
                let t = 5_000_000_000 + k * 1_000_000;
                let y = 700_000_000_000 + t + (t as f64 * ppm * 1e-6) as u64;
                (t.wrapping_add_signed(noise.sample(&mut rng) as i64), y)
            })
            .collect()
    }

    fn phase_error(f: &LineFit, ppm: f64, x: u64) -> i64 {
        let truth = 700_000_000_000 + x + (x as f64 * ppm * 1e-6) as u64;
        f.at(x).unwrap().wrapping_sub(truth) as i64
    }

    #[test]
    fn a_longer_window_halves_the_error_per_fourfold_points() {
        // RMS phase error at the newest point, over many independent fits.
        let rms = |len: usize| {
            let mut s = 0.0;
            for seed in 0..40 {
                let mut f = LineFit::new(len);
                let pts = points(len, 30.0, 1000.0, seed);
                for &(x, y) in &pts {
                    f.push(x, y);
                }
                let x = 5_000_000_000 + (len as u64 - 1) * 1_000_000;
                s += (phase_error(&f, 30.0, x) as f64).powi(2);
            }
            (s / 40.0).sqrt()
        };
        let (short, long) = (rms(64), rms(1024));
        // Theory: 2σ/√n at the end of the window — 250 ns and 62 ns.
        assert!(long < short / 2.5, "64 points: {short:.0} ns, 1024 points: {long:.0} ns");
        assert!(long < 100.0, "1024 points: {long:.0} ns");
    }

    #[test]
    fn the_rate_sd_is_the_spread_of_fitted_rates() {
        // Over independent fits of 256 points 1 ms apart with 300 ns of noise, the rates'
        // spread matches what each fit says of itself (within the 40 fits' sampling error).
        let (mut rates, mut sds) = (Vec::new(), Vec::new());
        for seed in 0..40 {
            let mut f = LineFit::new(4096);
            for (x, y) in points(256, 40.0, 300.0, seed) {
                f.push(x, y);
            }
            // The window may have restarted early on; it spans what it kept.
            assert!((100_000_000..255_003_000).contains(&f.span_ns()), "span {} ns", f.span_ns());
            rates.push(f.rate().unwrap());
            sds.push(f.rate_sd().unwrap());
        }
        let mean = rates.iter().sum::<f64>() / 40.0;
        let spread = (rates.iter().map(|r| (r - mean).powi(2)).sum::<f64>() / 39.0).sqrt();
        let said = sds.iter().sum::<f64>() / 40.0;
        assert!((mean - (1.0 + 40e-6)).abs() < 3.0 * said, "mean rate {mean}");
        assert!(spread > 0.6 * said && spread < 1.6 * said, "spread {spread:e}, said {said:e}");
    }

    #[test]
    fn a_rate_step_restarts_the_window_within_tens_of_points() {
        let mut f = LineFit::new(4096);
        let mut rng = rand_chacha::ChaCha8Rng::seed_from_u64(7);
        let noise = Normal::new(0.0, 1000.0).unwrap();
        let mut y: u64 = 1 << 50;
        let mut restarted_at = None;
        for k in 0..3000u64 {
            // 20 ppm fast, then 70 ppm fast from point 2000: a 50 ns per cycle ramp.
            // (1 ms at 1 + ppm·10⁻⁶ is 10⁶ + ppm ns.)
            let ppm: u64 = if k < 2000 { 20 } else { 70 };
            y += 1_000_000 + ppm;
            let x = (k * 1_000_000).wrapping_add_signed(noise.sample(&mut rng) as i64);
            let fate = f.push(x, y);
            if fate == Fate::Restarted && k >= 2000 && restarted_at.is_none() {
                restarted_at = Some(k - 2000);
            }
        }
        let after = restarted_at.expect("the step was never detected");
        assert!(after < 80, "detected {after} points after the step");
        assert_eq!(f.restarts, 1, "no restart but the step's");
        let rate = f.rate().unwrap();
        assert!((rate - 1.000070).abs() < 2e-6, "rate after the step {rate}");
    }

    /// A line frozen before a rate step goes on foretelling the old rate after the window
    /// restarted at the step, to within the fit's own error, seconds away and across the u64
    /// wrap; the window's own line follows the new rate.
    #[test]
    fn a_frozen_line_keeps_the_old_rate_after_the_window_restarted() {
        let mut f = LineFit::new(4096);
        let mut rng = rand_chacha::ChaCha8Rng::seed_from_u64(5);
        let noise = Normal::new(0.0, 1000.0).unwrap();
        // Starts 2 s before the u64 wrap, 20 ppm fast, then 70 ppm fast from point 2000.
        let (mut y, x0) = (u64::MAX - 2_000_000_000, u64::MAX - 1_500_000_000);
        let mut frozen = None;
        for k in 0..3000u64 {
            let ppm: u64 = if k < 2000 { 20 } else { 70 };
            y = y.wrapping_add(1_000_000 + ppm);
            let x = x0.wrapping_add(k * 1_000_000);
            if k == 2000 {
                frozen = f.frozen_at(x);
            }
            f.push(x.wrapping_add_signed(noise.sample(&mut rng) as i64), y);
        }
        assert!(f.restarts >= 1, "the step restarted the window");
        let frozen = frozen.unwrap();
        // 1 s after the step: the old line is 50 ppm·1 s = 50 µs behind the reference.
        let x = x0.wrapping_add(2999 * 1_000_000);
        let old_rate_there = y.wrapping_sub(1000 * 50);
        let off = frozen.at(x).wrapping_sub(old_rate_there) as i64;
        println!("frozen line off the old rate by {off} ns");
        assert!(off.abs() < 300, "frozen line off the old rate by {off} ns");
        let now = f.at(x).unwrap().wrapping_sub(y) as i64;
        assert!(now.abs() < 300, "the window's own line off by {now} ns");
    }

    /// A window of `mature` points of a 20 ppm fast reference in 1 µs of noise, then `extra`
    /// points from `make`(k, truth) (k counted from the end of the mature part): the fit, and
    /// the first point that restarted the window (counted like k).
    fn mature_then(mature: u64, extra: u64, make: impl Fn(u64, u64) -> u64) -> (LineFit, Option<u64>) {
        let mut f = LineFit::new(8192);
        let mut rng = rand_chacha::ChaCha8Rng::seed_from_u64(11);
        let noise = Normal::new(0.0, 1000.0).unwrap();
        let mut restarted_at = None;
        for k in 0..mature + extra {
            let x = k * 1_000_000;
            let truth = (1u64 << 50) + x + x / 50_000;
            let y = if k < mature { truth } else { make(k - mature, truth) };
            let y = y.wrapping_add_signed(noise.sample(&mut rng) as i64);
            if f.push(x, y) == Fate::Restarted && k >= mature && restarted_at.is_none() {
                restarted_at = Some(k - mature);
            }
        }
        (f, restarted_at)
    }

    #[test]
    fn a_change_signal_the_next_points_do_not_confirm_leaves_a_long_line_alone() {
        // 10 points 2.5 σ high (a host's brief disturbance) trip the CUSUM of a 6 000-point
        // line; the points after them are on the line again.
        let (f, restarted) = mature_then(6_000, 500, |k, truth| if k < 10 { truth + 2_500 } else { truth });
        assert_eq!((f.restarts, restarted), (0, None), "the line was restarted (false alarms {})", f.false_alarms);
        assert_eq!(f.false_alarms, 1, "the CUSUM should have signalled once");
        // The line still has its 6 000 points' phase: within a few σ/√n of the truth.
        let x = 6_500 * 1_000_000;
        let truth = (1u64 << 50) + x + x / 50_000;
        let err = f.at(x).unwrap().wrapping_sub(truth) as i64;
        assert!(err.abs() < 100, "phase error {err} ns");
        // Without the confirmation (a young window restarts at once) the same signal restarts it.
        let (young, restarted) = mature_then(3_000, 500, |k, truth| if k < 10 { truth + 2_500 } else { truth });
        assert!(restarted.is_some() && young.false_alarms == 0, "{restarted:?}");
    }

    #[test]
    fn a_rate_step_of_a_long_line_is_confirmed_within_a_few_points_of_its_signal() {
        // +50 ppm from point 6 000: a 50 ns per point ramp in 1 µs of noise.
        let (f, restarted) = mature_then(6_000, 1_000, |k, truth| truth + 50 * k);
        let after = restarted.expect("the step was never detected");
        assert!(after < 80, "detected {after} points after the step");
        assert_eq!((f.restarts, f.false_alarms), (1, 0));
        let rate = f.rate().unwrap();
        assert!((rate - 1.000070).abs() < 3e-6, "rate after the step {rate}");
    }

    /// The squared errors (ns²) of the line one cycle ahead over the `cycles` cycles after the
    /// first restart: points in bursts of 16 within 0.3 ms (a cycle's probes) with `sd_ns`
    /// of noise, the reference 20 ppm fast, its time jumping 30 µs after 3 s.
    fn errors_after_jump(seed: u64, sd_ns: f64, cycles: u64, rate_change_sd: f64) -> Vec<f64> {
        let mut rng = rand_chacha::ChaCha8Rng::seed_from_u64(seed);
        let noise = Normal::new(0.0, sd_ns).unwrap();
        let truth = |x: u64| x as i64 + (x as f64 * 20e-6) as i64 + if x < 3_000_000_000 { 0 } else { 30_000 };
        let mut f = LineFit { rate_change_sd, ..LineFit::new(16_384) };
        let (mut restarted, mut errors) = (None, Vec::new());
        for k in 1..4_000u64 {
            for j in 0..16 {
                let x = k * 1_000_000 + j * 20_000;
                f.push(x, (truth(x) + noise.sample(&mut rng) as i64) as u64);
            }
            if restarted.is_none() && f.restarts > 0 {
                restarted = Some(k);
            }
            if restarted.is_some_and(|r| k < r + cycles) {
                let ahead = (k + 1) * 1_000_000;
                errors.push(((f.at(ahead).unwrap() as i64 - truth(ahead)) as f64).powi(2));
            }
        }
        assert_eq!(restarted, Some(3_000), "seed {seed}: the jump restarts the window in its cycle");
        errors
    }

    #[test]
    fn a_restarted_window_keeps_the_old_rate_until_its_points_say_otherwise() {
        // The jump restarts the window from the 8 points of one burst a sixth of a cycle
        // wide: alone, their slope is known to σ/(50 µs·√8), thousands of ppm in 1 µs of
        // noise (the clamp's 1 000 ppm is 1 µs a cycle ahead). With the old rate as its prior
        // the line is off by its intercept's noise, σ/√n. Measured: 194 ns against 550.
        let rms = |cycles, rate_change_sd| {
            let e: Vec<f64> =
                (0..20).flat_map(|seed| errors_after_jump(seed, 1_000.0, cycles, rate_change_sd)).collect();
            (e.iter().sum::<f64>() / e.len() as f64).sqrt()
        };
        // The first three cycles after the restart, 20 realisations; no prior (a negligible
        // one: λ = σ²) against the prior.
        let (with, without) = (rms(3, RATE_CHANGE_SD), rms(3, 1.0));
        assert!(with < without / 2.0, "RMS one cycle ahead: {with:.0} ns with the prior, {without:.0} ns without");
        // No worse than the mean of the burst that restarted it: σ/√8.
        assert!(with < 1_000.0 / 8f64.sqrt(), "RMS one cycle ahead with the prior: {with:.0} ns");
    }

    #[test]
    fn single_outliers_are_left_out_and_do_not_restart() {
        let mut f = LineFit::new(4096);
        let pts = points(3000, -40.0, 300.0, 3);
        let mut rng = rand_chacha::ChaCha8Rng::seed_from_u64(9);
        for (k, &(x, y)) in pts.iter().enumerate() {
            // 1 % of the stamps 20–200 µs late (a preempted sender).
            let late = if k > 100 && rng.gen_bool(0.01) { rng.gen_range(20_000..200_000) } else { 0 };
            f.push(x + late, y);
        }
        assert_eq!(f.restarts, 0);
        assert!(f.outliers >= 15, "outliers {}", f.outliers);
        let x = 5_000_000_000 + 2999 * 1_000_000;
        assert!(phase_error(&f, -40.0, x).abs() < 60, "phase error {}", phase_error(&f, -40.0, x));
    }

    /// 1 200 points of a reference 25 ppm fast in 200 ns of noise whose time jumps 30 µs ahead
    /// at point 1000 (someone wrote its offset), point `k` also `extra(k)` ns off: each
    /// point's fate, and the fit.
    fn jump_fates(extra: impl Fn(usize) -> u64) -> (Vec<Fate>, LineFit) {
        let mut f = LineFit::new(4096);
        let pts = points(1200, 25.0, 200.0, 5);
        let fates = pts
            .iter()
            .enumerate()
            .map(|(k, &(x, y))| f.push(x, y + if k >= 1000 { 30_000 } else { 0 } + extra(k)))
            .collect();
        (fates, f)
    }

    #[test]
    fn a_jump_restarts_after_a_run_of_outliers_and_the_line_follows_it() {
        let (fates, f) = jump_fates(|_| 0);
        assert!(fates[1000..1000 + JUMP_RUN - 1].iter().all(|&f| f == Fate::Outlier), "{:?}", &fates[1000..1010]);
        assert_eq!(fates[1000 + JUMP_RUN - 1], Fate::Restarted);
        assert_eq!(f.restarts, 1);
        let x = 5_000_000_000 + 1199 * 1_000_000;
        let e = phase_error(&f, 25.0, x) - 30_000;
        assert!(e.abs() < 100, "phase error after the jump {e} ns");
    }

    #[test]
    fn a_young_window_leaves_out_a_stamp_far_off_its_line() {
        // A jump restarts the window from its run of 8 points; a stamp 10 µs off (a software
        // stamp's rare outlier) right after would otherwise be a ninth of the new line.
        let (fates, f) = jump_fates(|k| if k == 1000 + JUMP_RUN { 10_000 } else { 0 });
        assert_eq!(fates[1000 + JUMP_RUN - 1], Fate::Restarted);
        assert_eq!(fates[1000 + JUMP_RUN], Fate::Outlier);
        assert!(fates[1000 + JUMP_RUN + 1..].iter().all(|&f| f == Fate::Added));
        assert_eq!(f.restarts, 1);
    }

    /// (master time, reference time) of a reference whose rate starts 30 ppm fast and
    /// random-walks by `wander_ppb` per √s (a step every 100 ms, as the simulator's crystals
    /// do), one a millisecond for `n` ms, each with the master's stamp of it scattered by
    /// `sd_ns`: (true x, stamped x, y).
    fn wandering(n: usize, wander_ppb: f64, sd_ns: f64, seed: u64) -> Vec<(u64, u64, u64)> {
        let mut rng = rand_chacha::ChaCha8Rng::seed_from_u64(seed);
        let noise = Normal::new(0.0, sd_ns).unwrap();
        let step = Normal::new(0.0, wander_ppb * 1e-9 * 0.1f64.sqrt()).unwrap();
        let (mut rate, mut phase) = (30e-6, 0.0);
        (0..n as u64)
            .map(|k| {
                if k % 100 == 0 {
                    rate += step.sample(&mut rng);
                }
                phase += rate * 1e6;
                let t = 5_000_000_000 + k * 1_000_000;
                (t, t.wrapping_add_signed(noise.sample(&mut rng) as i64), 700_000_000_000 + t + phase as u64)
            })
            .collect()
    }

    /// RMS (ns) of the line in use against each point's true reference time, before the point
    /// joins, over the points after the first 20 000 of 40 000; whether a shorter line was ever
    /// in use; with shorter lines or without.
    fn wandering_error(wander_ppb: f64, seed: u64, choose: bool) -> (f64, bool) {
        let f = LineFit::new(16_384);
        let mut f = if choose { f } else { f.whole_only() };
        let (mut sq, mut n, mut shorter) = (0.0, 0.0, false);
        for (k, &(t, x, y)) in wandering(40_000, wander_ppb, 300.0, seed).iter().enumerate() {
            if k >= 20_000 {
                sq += (f.at(t).unwrap().wrapping_sub(y) as i64 as f64).powi(2);
                n += 1.0;
            }
            f.push(x, y);
            shorter |= f.len_in_use() < f.len();
        }
        ((sq / n).sqrt(), shorter)
    }

    #[test]
    fn a_wandering_rate_puts_a_shorter_line_in_use_nearer_the_truth() {
        // 50 ppb/√s with 300 ns stamps (pc-rt's scale): 16 s of points carry the wander, and
        // the change test restarts such a window now and then.
        for seed in 7..10 {
            let (with, shorter) = wandering_error(50.0, seed, true);
            let (without, _) = wandering_error(50.0, seed, false);
            assert!(shorter, "seed {seed}");
            assert!(with < 0.6 * without, "seed {seed}: {with:.1} ns with shorter lines, {without:.1} without");
        }
    }

    #[test]
    fn without_wander_the_whole_window_stays_in_use() {
        for seed in 10..13 {
            let (with, shorter) = wandering_error(0.0, seed, true);
            assert!(!shorter, "seed {seed}");
            assert_eq!(with, wandering_error(0.0, seed, false).0);
        }
    }

    #[test]
    fn probes_in_a_burst_are_not_scored() {
        // Each 1 ms cycle a frame and 15 probes 20 µs apart: with a quarter cycle's gap only
        // the frames are scored (the probes' stamps share the host's state with the burst's
        // other points, which a short line of them follows).
        let mut rng = rand_chacha::ChaCha8Rng::seed_from_u64(3);
        let noise = Normal::new(0.0, 300.0).unwrap();
        let (mut gapped, mut every) = (LineFit::new(4096).score_gap(250_000), LineFit::new(4096));
        for cycle in 0..1_000u64 {
            for k in 0..16 {
                let t = 5_000_000_000 + cycle * 1_000_000 + k * 20_000;
                let x = t.wrapping_add_signed(noise.sample(&mut rng) as i64);
                gapped.push(x, 700_000_000_000 + t);
                every.push(x, 700_000_000_000 + t);
            }
        }
        let scored = |f: &LineFit| f.shorter.iter().map(|w| w.score.scored()).max().unwrap();
        // Scoring starts once the window is longer than the shortest one (256 points).
        assert!((980..=1_000).contains(&scored(&gapped)), "{}", scored(&gapped));
        assert!(scored(&every) > 15_000, "{}", scored(&every));
    }

    #[test]
    fn a_rate_step_is_no_evidence_of_wander() {
        // Before the change test restarts the window, every shorter line foretells the step's
        // points better than the whole one; kept as evidence, that would keep a shorter,
        // noisier line in use for seconds after a step of steady crystals. A 1 ppm step in
        // 300 ns of noise: its ramp takes hundreds of points to show. After the restart every
        // shorter window is the whole one's line again and scores 0, which outweighs the
        // ramp's points within a second (scored only while shorter, as first built, the
        // evidence stayed: an 8 192-point line in use 8 s after the step).
        for seed in 0..3 {
            let mut rng = rand_chacha::ChaCha8Rng::seed_from_u64(40 + seed);
            let noise = Normal::new(0.0, 300.0).unwrap();
            let mut f = LineFit::new(16_384);
            let mut phase = 0.0;
            for k in 0..40_000u64 {
                phase += if k < 20_000 { 10.0 } else { 11.0 } * 1e-6 * 1e6;
                let t = 5_000_000_000 + k * 1_000_000;
                f.push(t.wrapping_add_signed(noise.sample(&mut rng) as i64), 700_000_000_000 + t + phase as u64);
                // A shorter line may be in use while the ramp builds (it is nearer the truth
                // then), not once the window restarted at the change.
                if k >= 22_000 {
                    assert_eq!(f.len_in_use(), f.len(), "seed {seed}, point {k}");
                }
            }
            assert_eq!(f.restarts, 1, "seed {seed}");
        }
    }

    #[test]
    fn noise_alone_never_restarts_the_window() {
        // Four 20 s runs of 1 µs noise: a false change would cost seconds of accuracy.
        for seed in 0..4 {
            let mut f = LineFit::new(4096);
            for &(x, y) in &points(20_000, -35.0, 1000.0, 100 + seed) {
                f.push(x, y);
            }
            assert_eq!(f.restarts, 0, "seed {seed}");
        }
    }

    #[test]
    fn the_predicted_spread_matches_the_scatter_of_independent_fits() {
        // 256 points of 300 ns noise; the line one cycle past the newest point, over many
        // independent fits: its RMS error against the truth and the fit's own estimate of it.
        let (n, sd) = (256, 300.0);
        let x_next = 5_000_000_000 + n as u64 * 1_000_000;
        let (mut sq, mut predicted) = (0.0, 0.0);
        for seed in 0..200 {
            let mut f = LineFit::new(4096);
            for &(x, y) in &points(n, 20.0, sd, 1000 + seed) {
                f.push(x, y);
            }
            sq += (phase_error(&f, 20.0, x_next) as f64).powi(2);
            predicted += f.sd_ahead_ns(1_000_000).unwrap();
        }
        let (actual, predicted) = ((sq / 200.0).sqrt(), predicted / 200.0);
        // Theory: σ·√(1/n + 3(n+1)²/(n(n²−1))) ≈ 2σ/√n = 37.5 ns; the scale learned from
        // innovations is σ's estimate.
        assert!((actual / predicted - 1.0).abs() < 0.2, "actual {actual:.1} ns, predicted {predicted:.1} ns");
        assert!((predicted - 2.0 * sd / (n as f64).sqrt()).abs() < 8.0, "predicted {predicted:.1} ns");
    }

    #[test]
    fn the_spread_falls_with_more_points_and_grows_with_the_distance_ahead() {
        let mut f = LineFit::new(4096);
        assert_eq!(f.sd_ahead_ns(0), None);
        let pts = points(1024, -10.0, 500.0, 2);
        for &(x, y) in &pts[..64] {
            f.push(x, y);
        }
        let short = f.sd_ahead_ns(1_000_000).unwrap();
        assert!(f.sd_ahead_ns(100_000_000).unwrap() > 2.0 * short, "a longer lever, a larger spread");
        for &(x, y) in &pts[64..] {
            f.push(x, y);
        }
        let long = f.sd_ahead_ns(1_000_000).unwrap();
        assert!(long < short / 3.0, "64 points {short:.1} ns, 1024 points {long:.1} ns");
    }

    #[test]
    fn suspicion_rises_on_a_ramp_before_the_restart() {
        let mut f = LineFit::new(4096);
        let mut fates = Vec::new();
        let mut suspicion = Vec::new();
        for (k, &(x, y)) in points(1200, 0.0, 300.0, 4).iter().enumerate() {
            // 50 ns more per point from point 1000 (a 50 ppm step at 1 ms).
            let ramp = k.saturating_sub(1000) as u64 * 50;
            fates.push(f.push(x, y + ramp));
            suspicion.push(f.suspicion());
        }
        let restart = fates[1000..].iter().position(|&f| f == Fate::Restarted).expect("the ramp restarts") + 1000;
        let first_suspect = suspicion[1000..].iter().position(|&s| s >= 0.25).expect("suspected") + 1000;
        assert!(first_suspect < restart, "suspected at {first_suspect}, restarted at {restart}");
        // Before the ramp the test sits well below a quarter of its threshold most of the time.
        let quiet = suspicion[100..1000].iter().filter(|&&s| s < 0.25).count();
        assert!(quiet > 800, "{quiet} of 900 points below a quarter");
    }

    #[test]
    fn shifting_x_moves_the_line_by_the_shift() {
        let mut f = LineFit::new(256);
        for &(x, y) in &points(200, 10.0, 0.0, 1) {
            f.push(x, y);
        }
        let x = 5_150_000_000;
        let before = f.at(x).unwrap();
        f.shift_x(-1000);
        // The points' x are 1 µs earlier: at the same x the line now reads 1 µs later.
        let after = f.at(x).unwrap();
        assert!((after.wrapping_sub(before) as i64 - 1000).abs() <= 1, "{before} → {after}");
    }

    proptest! {
        #[test]
        fn never_panics_and_stays_exact_across_wraps(
            base_x in any::<u64>(), base_y in any::<u64>(),
            steps in proptest::collection::vec((0u64..10_000_000_000, -1_000_000i64..1_000_000), 1..300),
            len in 2usize..64,
        ) {
            let mut f = LineFit::new(len);
            let (mut x, mut y) = (base_x, base_y);
            for (dt, jitter) in steps {
                x = x.wrapping_add(dt);
                y = y.wrapping_add(dt);
                f.push(x.wrapping_add_signed(jitter), y);
                let _ = f.at(x);
                prop_assert!(f.len() <= len);
            }
            let r = f.rate().unwrap();
            prop_assert!((r - 1.0).abs() <= MAX_RATE_ERROR + 1e-12);
        }

        #[test]
        fn the_shorter_windows_sum_exactly_their_newest_points(
            base_x in any::<u64>(), base_y in any::<u64>(),
            steps in proptest::collection::vec((0u64..3_000_000, -3_000i64..3_000, 0u8..100), 1..2_000),
            len in 512usize..1_100,
        ) {
            // Jumps (a run of far points), steps of the rate, gaps that restart the window and
            // shifts of x, across any wrap: each shorter window sums exactly the newest `len`
            // points of the window (or all of them, fewer).
            let mut f = LineFit::new(len);
            let (mut x, mut y, mut drift) = (base_x, base_y, 0i64);
            for (k, (dt, jitter, event)) in steps.into_iter().enumerate() {
                match event {
                    0 => drift = jitter,
                    1 => y = y.wrapping_add(50_000),
                    2 => x = x.wrapping_add(SPAN + 1),
                    3 if k % 7 == 0 => f.shift_x(jitter),
                    _ => {}
                }
                x = x.wrapping_add(dt);
                y = y.wrapping_add(dt).wrapping_add_signed(drift * dt as i64 / 1_000_000);
                f.push(x.wrapping_add_signed(jitter), y);
                let n = f.points.len();
                for w in &f.shorter {
                    let mut sums = Sums::default();
                    for &p in f.points.iter().skip(n.saturating_sub(w.len)) {
                        let (dx, dz) = f.rel(p);
                        sums.account(dx, dz, 1);
                    }
                    prop_assert_eq!((w.sums.n, w.sums.x, w.sums.xx, w.sums.z, w.sums.xz), (sums.n, sums.x, sums.xx, sums.z, sums.xz));
                }
                prop_assert!(f.len_in_use() <= f.len());
                let _ = (f.at(x), f.rate(), f.sd_ahead_ns(1_000_000), f.rate_sd());
            }
        }
    }
}
