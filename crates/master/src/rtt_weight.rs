//! How much of a round trip's deviation was spent on the way out: the weight that moves each
//! passage by its own round trip.
//!
//! A frame passes the reference `e_out` after its transmit stamp (or its build, without
//! stamps) and is stamped back `e_back` after it returned; both scatter. The stamp alone puts
//! the passage at the mean, off by `e_out`; half the round trip's deviation,
//! `d = (e_out + e_back)/2`, carries part of `e_out`. The passage estimated as
//! `stamp + w·d` scatters least for `w = Cov(e_out, d)/Var(d) = 2σ²_out/(σ²_out + σ²_back)`
//! (least squares; 0 when the way back alone scatters, 1 for a symmetric path, 2 when the
//! way out alone does). Neither σ is known, but the first covariance can be measured: the
//! reference's time against the line at the stamp alone is off by `e_out` (times the rate),
//! so `w` is the regression of those residuals on `d`. Each host learns its own weight.
//!
//! The deviation is taken from a short robust centre (the caller's trimmed mean of the last 64
//! half round trips), not a long mean: slower than that window the centre follows the round
//! trips, so there the passage takes half of each (the symmetric split), and a host whose
//! latencies drift as it warms up or changes its clock is followed within 64 cycles. The
//! weight acts on the faster scatter, which is what a short window (a restart) sees.
//!
//! Deviations beyond a few scales (a preempted send) are neither learned from nor applied in
//! full: their distribution is not the Gaussian the weight is optimal for.

/// Points before the weight is used (until then 0: the stamp alone, as without it).
const WARM_UP: u64 = 128;
/// Exponential memory of the moments, in points.
const MEMORY: f64 = 1024.0;
/// Deviations beyond this many scales are not learned from, and applied only up to it.
const CLIP_SCALES: f64 = 4.0;
/// The scale is a running mean |deviation| (×1.2533: σ of a normal); its inputs are capped at
/// this many scales so that rare long round trips do not inflate it.
const SCALE_CAP: f64 = 6.0;
const SCALE_WARM_UP: u64 = 16;

#[derive(Debug, Clone, Default)]
pub struct RttWeight {
    n: u64,
    scale_ns: f64,
    /// Exponentially weighted means and (co)variance of the inlier deviations and residuals.
    mean_d: f64,
    mean_r: f64,
    var_d: f64,
    cov_rd: f64,
    learned: u64,
}

impl RttWeight {
    pub fn new() -> Self {
        Self::default()
    }

    /// The weight in use: 0 until enough points were learned, then in [0, 2].
    pub fn weight(&self) -> f64 {
        if self.learned < WARM_UP || self.var_d <= 0.0 {
            return 0.0;
        }
        (self.cov_rd / self.var_d).clamp(0.0, 2.0)
    }

    /// How far to move a frame's passage, whose half round trip deviated by `dev_ns` from the
    /// centre the caller took its stamp's passage from (ns).
    pub fn shift_ns(&self, dev_ns: i64) -> i64 {
        let lim = CLIP_SCALES * self.scale_ns;
        (self.weight() * (dev_ns as f64).clamp(-lim, lim)).round() as i64
    }

    /// Learns from a frame whose half round trip deviated by `dev_ns` and whose reference time
    /// was `residual_ns` past the line at the stamp alone (None: no line yet, or the point was
    /// not accepted by it).
    pub fn learn(&mut self, dev_ns: i64, residual_ns: Option<i64>) {
        let d = dev_ns as f64;
        let inlier = self.n < WARM_UP || d.abs() <= CLIP_SCALES * self.scale_ns;
        self.n += 1;
        // Uncapped while the scale is learned.
        let cap = if self.n <= SCALE_WARM_UP { f64::INFINITY } else { SCALE_CAP * self.scale_ns };
        self.scale_ns += (d.abs().min(cap) * 1.2533 - self.scale_ns) / (self.n as f64).min(MEMORY);
        let (true, Some(r)) = (inlier, residual_ns) else { return };
        // West's exponentially weighted (co)variance update.
        self.learned += 1;
        let w = 1.0 / (self.learned as f64).min(MEMORY);
        let (dd, dr) = (d - self.mean_d, r as f64 - self.mean_r);
        self.mean_d += w * dd;
        self.mean_r += w * dr;
        self.var_d = (1.0 - w) * (self.var_d + w * dd * dd);
        self.cov_rd = (1.0 - w) * (self.cov_rd + w * dd * dr);
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use rand::SeedableRng;
    use rand_distr::{Distribution, Normal};

    /// Learns on `n` frames whose way out scatters by `out_sd` and way back by `back_sd`;
    /// returns the weight and the RMS of the passage error with it, and with the stamp alone.
    fn run(out_sd: f64, back_sd: f64, n: usize, seed: u64) -> (f64, f64, f64) {
        let mut rng = rand_chacha::ChaCha8Rng::seed_from_u64(seed);
        let (out, back) = (Normal::new(0.0, out_sd).unwrap(), Normal::new(0.0, back_sd).unwrap());
        let mut rw = RttWeight::new();
        let (mut with, mut without) = (0.0, 0.0);
        for k in 0..n {
            let (e_out, e_back) = (out.sample(&mut rng), back.sample(&mut rng));
            let dev = ((e_out + e_back) / 2.0) as i64;
            let err = e_out - rw.shift_ns(dev) as f64;
            if k >= n / 2 {
                with += err * err;
                without += e_out * e_out;
            }
            rw.learn(dev, Some(e_out as i64 + 500));
        }
        let m = (n - n / 2) as f64;
        (rw.weight(), (with / m).sqrt(), (without / m).sqrt())
    }

    #[test]
    fn the_weight_is_the_least_squares_one() {
        for (out, back) in [(300.0, 400.0), (1000.0, 1000.0), (1000.0, 10.0), (10.0, 1000.0)] {
            let (w, with, without) = run(out, back, 20_000, 1);
            let ideal = 2.0 * out * out / (out * out + back * back);
            assert!((w - ideal).abs() < 0.1, "σ {out}/{back}: weight {w:.3}, least squares {ideal:.3}");
            let best = out * back / (out * out + back * back).sqrt();
            assert!(with < best * 1.1 + 1.0 && with <= without * 1.01, "σ {out}/{back}: {with:.0} ns, best {best:.0}");
        }
    }

    #[test]
    fn no_weight_before_warm_up_nor_without_residuals() {
        let mut rw = RttWeight::new();
        for k in 0..WARM_UP as i64 - 1 {
            rw.learn(k % 7 * 100 - 300, Some(k % 7 * 100));
        }
        assert_eq!(rw.weight(), 0.0);
        assert_eq!(rw.shift_ns(10_000), 0);
        let mut rw = RttWeight::new();
        for k in 0..10_000 {
            rw.learn(k % 7 * 100 - 300, None);
        }
        assert_eq!(rw.weight(), 0.0);
    }

    #[test]
    fn a_preempted_send_is_clipped_and_not_learned() {
        let mut rw = RttWeight::new();
        for k in 0..5_000i64 {
            let e = (k * 7919 % 601) - 300; // deterministic scatter ±300 ns, all on the way out
            rw.learn(e / 2, Some(e));
        }
        let w = rw.weight();
        assert!((w - 2.0).abs() < 0.05, "weight {w}");
        // A 200 µs outlier moves the passage by at most the clip, and leaves the weight.
        assert!(rw.shift_ns(100_000).abs() as f64 <= w * CLIP_SCALES * rw.scale_ns + 1.0);
        rw.learn(100_000, Some(-1_000_000));
        assert_eq!(rw.weight(), w);
    }
}
