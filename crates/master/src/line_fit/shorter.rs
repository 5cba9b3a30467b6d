//! Shorter windows inside a line's: the newest `len` points, each with its own line, scored on
//! how well it foretold every point before the point joined.
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
//! better line, the means stay above zero and nothing changes.
use super::{Line, Sums};

/// The shortest window tried (points): at 1 ms a quarter of a second.
const SHORTEST: usize = 256;
/// The scores are exponential means over about this many points.
const SCORE_MEMORY: f64 = 8192.0;
/// A shorter window's line is used once its mean score is this many standard errors below
/// the whole window's (a false choice then costs a shorter line's noise, which is small; a
/// missed one the wander's error).
const CHOOSE_SE: f64 = 3.0;

/// The lengths tried inside a window of `max_len`: halving down to `SHORTEST`.
pub(super) fn lengths(max_len: usize) -> impl Iterator<Item = usize> {
    std::iter::successors(Some(max_len / 2), |&len| Some(len / 2)).take_while(|&len| len >= SHORTEST)
}

/// At most this many shorter windows (a window of 2¹⁶ points, the fit's largest, has 8).
pub(super) const MAX_SHORTER: usize = 8;

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

/// Exponential mean and variance of r_short² − r_whole² (ns²), and the points scored.
#[derive(Debug, Clone, Copy, Default)]
pub(super) struct Score {
    mean: f64,
    var: f64,
    scored: u64,
}

impl Score {
    /// Scores a point `r_short` from the shorter line and `r_whole` from the whole window's (ns).
    pub fn add(&mut self, r_short: f64, r_whole: f64) {
        let d = r_short * r_short - r_whole * r_whole;
        self.scored += 1;
        // A plain mean and variance over the first points, then exponential ones.
        let a = (1.0 / self.scored as f64).max(1.0 / SCORE_MEMORY);
        let diff = d - self.mean;
        self.mean += a * diff;
        self.var = (1.0 - a) * (self.var + a * diff * diff);
    }

    #[cfg(test)]
    pub fn scored(&self) -> u64 {
        self.scored
    }

    /// How much better than the whole window's the line foretold the points (its mean score,
    /// ns², negative), if it did by `CHOOSE_SE` standard errors after a memory's worth of them.
    pub fn better_by(&self) -> Option<f64> {
        // The standard error of a plain mean over the memory: an exponential mean's is
        // 1/√2 of it, so this errs towards the whole window.
        let se = (self.var / SCORE_MEMORY).sqrt();
        (self.scored as f64 >= SCORE_MEMORY && self.mean < -CHOOSE_SE * se).then_some(self.mean)
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn lengths_halve_down_to_the_shortest() {
        assert_eq!(lengths(16_384).collect::<Vec<_>>(), [8192, 4096, 2048, 1024, 512, 256]);
        assert_eq!(lengths(1 << 16).count(), MAX_SHORTER);
        assert_eq!(lengths(512).collect::<Vec<_>>(), [256]);
        assert_eq!(lengths(511).count(), 0);
    }

    #[test]
    fn a_line_is_chosen_only_when_it_foretold_the_points_better_beyond_their_spread() {
        let mut s = Score::default();
        // Equal errors but for noise: never chosen.
        for k in 0..20_000u64 {
            let noise = if k % 2 == 0 { 30.0 } else { -30.0 };
            s.add(100.0 + noise, 100.0 - noise);
        }
        assert_eq!(s.better_by(), None);
        // 20 ns closer on every point: chosen, by the difference of the squares.
        let mut s = Score::default();
        for _ in 0..(SCORE_MEMORY as u64 - 1) {
            s.add(80.0, 100.0);
        }
        assert_eq!(s.better_by(), None, "not before a memory's worth of points");
        s.add(80.0, 100.0);
        let by = s.better_by().expect("chosen");
        assert!((by + 3600.0).abs() < 1e-6, "{by}");
    }
}
