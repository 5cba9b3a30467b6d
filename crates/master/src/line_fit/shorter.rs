//! Shorter windows inside a line's: the newest `len` points, each with its own line, scored on
//! how well it foretold each scored point (`LineFit::score_gap`) before the point joined.
//!
//! Why: a long window averages the stamps' noise away (its phase error falls as 1/√n) while
//! the two crystals keep their rates. Real crystals also wander in frequency (a random walk of
//! a few ppb/√s); a line then carries the rate's wander over its span as a phase error that
//! grows as span^1.5, and below some span a shorter line is the better one. Where that span
//! lies depends on the stamps' noise and the crystals' wander, neither of which the master
//! knows; the points tell it. For a shorter line and the whole window's, the mean of
//! r_short² − r_whole² (each point's distance from either line before it joins) is the
//! difference of their mean squared errors: the point's own noise is common to both and
//! leaves the mean. So the line in use is the shorter window's whose mean stands lowest, if
//! it stands below zero by `CHOOSE_SE` standard errors (over about `SCORE_MEMORY` points);
//! else the whole window's. With crystals that keep their rates the whole window is the
//! better line, the means stay above zero and nothing changes. A line in use is kept until
//! it no longer beats the whole window by `KEEP_SE` standard errors or another beats it by as
//! many ([`choose`]): each change of line moves the line's value by the two lines'
//! difference, tens of ns on a stock kernel (a step `Ferrocat` hands to the followers with
//! the reference's offset), and choosing afresh at every point flipped between two windows
//! every few points.
use super::{Line, Sums};

/// The shortest window tried (points): at 1 ms a quarter of a second.
const SHORTEST: usize = 256;
/// The scores are exponential means over about this many points.
const SCORE_MEMORY: f64 = 8192.0;
/// A shorter window's line is used once its mean score is this many standard errors below
/// the whole window's (a false choice then costs a shorter line's noise, which is small; a
/// missed one the wander's error).
const CHOOSE_SE: f64 = 3.0;
/// A line in use is kept while it beats the whole window's by this many standard errors, and
/// until another beats it by this many of the larger of theirs.
const KEEP_SE: f64 = 1.0;

/// The lengths tried inside a window of `max_len`: halving down to `SHORTEST`.
pub(super) fn lengths(max_len: usize) -> impl Iterator<Item = usize> {
    std::iter::successors(Some(max_len / 2), |&len| Some(len / 2)).take_while(|&len| len >= SHORTEST)
}

#[derive(Debug, Clone)]
pub(super) struct Shorter {
    pub len: usize,
    pub sums: Sums,
    pub line: Option<Line>,
    pub score: Score,
}

impl Shorter {
    pub fn new(len: usize) -> Self {
        Shorter { len, sums: Sums::default(), line: None, score: Score::default() }
    }
}

/// The exponential mean of r_short² − r_whole² (ns²) over every point scored, 0 where the
/// window was no shorter than the whole one (its line then is the whole one's): so every
/// window's mean is over the same points, against the same whole window, and the means
/// compare. The spread is learned over the points where the window was shorter only (the
/// zeros would understate it), and a window is ready once a memory's worth of those came.
#[derive(Debug, Clone, Copy, Default)]
pub(super) struct Score {
    mean: f64,
    scored: u64,
    /// Mean and variance of the score where the window was shorter, and how many.
    shorter_mean: f64,
    var: f64,
    shorter: u64,
}

/// Folds `x` into an exponential mean (and variance) over `n` points so far: a plain one over
/// the first, then over about `SCORE_MEMORY`.
fn fold(mean: &mut f64, var: Option<&mut f64>, n: u64, x: f64) {
    let a = (1.0 / n as f64).max(1.0 / SCORE_MEMORY);
    let diff = x - *mean;
    *mean += a * diff;
    if let Some(var) = var {
        *var = (1.0 - a) * (*var + a * diff * diff);
    }
}

impl Score {
    /// Scores a point `r_short` from the shorter line and `r_whole` from the whole window's (ns);
    /// `shorter`: whether the window was shorter than the whole one.
    pub fn add(&mut self, r_short: f64, r_whole: f64, shorter: bool) {
        let d = if shorter { r_short * r_short - r_whole * r_whole } else { 0.0 };
        self.scored += 1;
        fold(&mut self.mean, None, self.scored, d);
        if shorter {
            self.shorter += 1;
            fold(&mut self.shorter_mean, Some(&mut self.var), self.shorter, d);
        }
    }

    #[cfg(test)]
    pub fn scored(&self) -> u64 {
        self.scored
    }

    /// Whether a memory's worth of points was scored while the window was shorter.
    fn ready(&self) -> bool {
        self.shorter as f64 >= SCORE_MEMORY
    }

    /// The mean score's standard error, as if it were a plain mean over the memory: an
    /// exponential mean's is 1/√2 of that, so this errs towards the whole window.
    fn se(&self) -> f64 {
        (self.var / SCORE_MEMORY).sqrt()
    }

    /// Whether the line foretold the points better than the whole window's by `z` standard
    /// errors.
    fn beats_whole(&self, z: f64) -> bool {
        self.ready() && self.mean < -z * self.se()
    }
}

/// The line to use after `current`: a shorter window's (an index of `windows`, of those whose
/// line differs from the whole window's: `differs`) or the whole window's (None).
pub(super) fn choose(current: Option<usize>, windows: &[Shorter], differs: impl Fn(usize) -> bool) -> Option<usize> {
    let score = |k: usize| &windows[k].score;
    let best = (0..windows.len())
        .filter(|&k| differs(k) && score(k).beats_whole(CHOOSE_SE))
        .min_by(|&a, &b| score(a).mean.total_cmp(&score(b).mean));
    match (current.filter(|&c| differs(c) && score(c).beats_whole(KEEP_SE)), best) {
        (None, best) => best,
        (Some(c), Some(b)) if score(b).mean < score(c).mean - KEEP_SE * score(b).se().max(score(c).se()) => Some(b),
        (Some(c), _) => Some(c),
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn lengths_halve_down_to_the_shortest() {
        assert_eq!(lengths(16_384).collect::<Vec<_>>(), [8192, 4096, 2048, 1024, 512, 256]);
        assert_eq!(lengths(1 << 16).count(), 8);
        assert_eq!(lengths(512).collect::<Vec<_>>(), [256]);
        assert_eq!(lengths(511).count(), 0);
    }

    /// A window whose line is `own_ns` off the truth at every point, the whole window's
    /// `whole_ns`, each point ±100 ns off the truth: its mean score is own² − whole², and the
    /// standard error 2·|own − whole|·100/√8192 ns² (z = (own + whole)·0.45).
    fn window(own_ns: f64, whole_ns: f64) -> Shorter {
        let mut w = Shorter::new(256);
        for k in 0..(SCORE_MEMORY as u64) {
            let noise = if k % 2 == 0 { 100.0 } else { -100.0 };
            w.score.add(noise + own_ns, noise + whole_ns, true);
        }
        w
    }

    #[test]
    fn a_line_is_chosen_only_when_it_foretold_the_points_better_beyond_their_spread() {
        // As good as the whole window's: never chosen.
        assert_eq!(choose(None, &[window(10.0, 10.0)], |_| true), None);
        // Better by 4.5 standard errors: chosen, by the difference of the squares…
        let w = window(0.0, 10.0);
        assert!((w.score.mean + 100.0).abs() < 1e-6, "{}", w.score.mean);
        assert_eq!(choose(None, std::slice::from_ref(&w), |_| true), Some(0));
        // …but not before a memory's worth of points.
        let mut young = Shorter::new(256);
        for _ in 1..(SCORE_MEMORY as u64) {
            young.score.add(0.0, 10.0, true);
        }
        assert_eq!(choose(None, &[young], |_| true), None);
        // Better by two standard errors: not chosen.
        assert_eq!(choose(None, &[window(1.4, 3.0)], |_| true), None);
        // The better of two; none whose line is the whole window's.
        let two = [window(5.0, 20.0), window(0.0, 20.0)];
        assert_eq!(choose(None, &two, |_| true), Some(1));
        assert_eq!(choose(None, &two, |k| k == 0), Some(0));
    }

    #[test]
    fn a_line_in_use_stays_until_another_is_clearly_better_or_it_no_longer_beats_the_whole() {
        // In use: 2 ns off (mean −396 ns², se 40); the other 0 ns off (−400, se 44): kept.
        let close = [window(2.0, 20.0), window(0.0, 20.0)];
        assert_eq!(choose(Some(0), &close, |_| true), Some(0));
        assert_eq!(choose(None, &close, |_| true), Some(1), "afresh, the lower mean");
        // In use 15 ns off (−175, se 11): the other is lower by 5 of its standard errors.
        assert_eq!(choose(Some(0), &[window(15.0, 20.0), window(0.0, 20.0)], |_| true), Some(1));
        // Beating the whole window by two standard errors it stays; by 0.9, it goes.
        assert_eq!(choose(Some(0), &[window(1.4, 3.0)], |_| true), Some(0));
        assert_eq!(choose(Some(0), &[window(0.5, 1.5)], |_| true), None);
        // A window whose line became the whole one's (a restart) is not kept.
        assert_eq!(choose(Some(0), &[window(0.0, 10.0)], |_| false), None);
    }
}
