//! A split ring's far reference kept on the reference's time (cable redundancy).
//!
//! Behind a break the far half follows its own first clock ([`crate::SplitRingClocks`]), which
//! no longer hears the reference and holds the rate its time control loop last had: good for
//! seconds, not for the hours a machine may run on a broken ring. The two halves share nothing
//! but the master, which sees both clocks in every cyclic frame: the FRMW reads the reference
//! on the first pass and the far reference on the second. Less the master's own time between
//! the passes (each pass's mid-point, from its transmit and receive stamps), what is left is
//! the far reference's time less the reference's, up to a constant: the passes' geometry, the
//! stamps' latencies and the far reference's delay register, which its reading subtracts.
//!
//! That constant is learned from the break itself: until then the far reference followed the
//! reference, so their difference was its time control loop's residual, nanoseconds. The
//! measured difference's level at the break (a line through the first [`ANCHOR_NS`] of samples,
//! taken back to the break) is the constant; from then on the far reference's error is the
//! line's level now less that one, and the master adds what cancels it to the far reference's
//! System_Time_Offset. The far half follows it, as it follows the far reference anyway.
//!
//! [`FarClock`] is sans-IO: samples in, an offset change out; the master does the I/O after
//! each cyclic frame, and leaves out samples whose passes took far longer than the path needs
//! (`pass_filter.rs`).
use crate::engine::SplitPasses;
use crate::line_fit::{Fate, LineFit};

/// The level at the break is taken from a line through this much of the samples after it
/// (the far reference drifts meanwhile, which the line's slope takes up), or through those
/// before the line restarts, if sooner.
pub const ANCHOR_NS: u64 = 2_000_000_000;
/// Held over, the far reference runs at the reference's rate as its loop last set it, to
/// within a few ppm of drift since: the slope's prior (rate less 1) and its spread, so that
/// the first few noisy samples do not give a steep line.
const RATE_PRIOR_SD: f64 = 10e-6;
/// A line whose level is known this well (ns, one standard deviation) is settled.
pub(crate) const SETTLED_SD_NS: f64 = 25.0;
/// The largest move beyond the drift since the last (ns).
pub(crate) const STEP_NS: f64 = 5.0;
/// Points in the line (16 s at 1 ms).
const WINDOW: usize = 16_384;
/// Samples before the error is trusted (the line's noise scale is learned over about as
/// many; a window restarted later keeps it).
const MIN_POINTS: u64 = 128;
/// How well the latched receive times give the level of a ring split from the start (ns, one
/// standard deviation): four latches of 10 ns ticks, halved or not.
pub(crate) const ANCHOR_SD_NS: f64 = 10.0;
/// An error beyond this, clear of the line's noise, on a far half set up from the latch's
/// geometry, moves all its clocks at once (ns).
pub(crate) const WHOLE_HALF_NS: f64 = 1_000.0;
/// A far reference drifting from the reference by more than this (rate less 1) is moved with
/// every frame rather than every `STEER_EVERY_NS`.
pub(crate) const FAST_DRIFT: f64 = 1e-6;
/// The far reference's offset is moved at most this often (a step each time, which its
/// followers take up through their own loops).
pub const STEER_EVERY_NS: u64 = 10_000_000;

/// The estimator: samples of the measured difference, the offset added since the break.
#[derive(Debug, Clone)]
pub struct FarClock {
    break_x: Option<u64>,
    /// The measured difference's level at the break, once [`ANCHOR_NS`] of samples fixed it,
    /// and its standard deviation.
    anchor_ns: Option<(i64, f64)>,
    fit: LineFit,
    samples: u64,
    last_x: Option<u64>,
    /// The level was known beforehand ([`FarClock::anchored`]), not learned at a break.
    known_level: bool,
    /// What has been added to the far reference's offset since the break.
    applied_ns: i64,
}

impl Default for FarClock {
    fn default() -> Self {
        Self::new()
    }
}

impl FarClock {
    pub fn new() -> Self {
        FarClock {
            break_x: None,
            anchor_ns: None,
            fit: LineFit::with_prior(WINDOW, 0.0, RATE_PRIOR_SD).whole_only(),
            samples: 0,
            last_x: None,
            known_level: false,
            applied_ns: 0,
        }
    }

    /// The level is known beforehand (`anchor_ns`, standard deviation `sd_ns`): a ring split
    /// from the start, whose geometry the latched receive times gave
    /// ([`crate::SplitLatch::anchor_ns`]).
    pub fn anchored(anchor_ns: i64, sd_ns: f64) -> Self {
        FarClock { anchor_ns: Some((anchor_ns, sd_ns)), known_level: true, ..Self::new() }
    }

    /// Whether the level was known beforehand ([`FarClock::anchored`]).
    pub fn knew_level(&self) -> bool {
        self.known_level
    }

    /// A sample at master time `x_ns`: the far reference's time less the reference's as
    /// measured (`diff_ns`, the offset added so far included).
    pub fn push(&mut self, x_ns: u64, diff_ns: i64) {
        let break_x = *self.break_x.get_or_insert(x_ns);
        self.last_x = Some(x_ns);
        let held_ns = diff_ns.wrapping_sub(self.applied_ns);
        self.samples += 1;
        let at_break = || self.level_at(break_x).zip(self.fit.sd_at_ns(break_x));
        // A window that restarts (the far crystal changed) no longer reaches back to the
        // break: the level there is fixed by the line it had until then.
        let before = if self.anchor_ns.is_none() { at_break() } else { None };
        let fate = self.fit.push(x_ns, x_ns.wrapping_add_signed(held_ns));
        if self.anchor_ns.is_none() {
            if fate == Fate::Restarted {
                self.anchor_ns = before;
            } else if x_ns.wrapping_sub(break_x) >= ANCHOR_NS {
                self.anchor_ns = self.level_at(break_x).zip(self.fit.sd_at_ns(break_x));
            }
        }
    }

    /// The line's level (the difference without the offset added) at `x_ns`.
    fn level_at(&self, x_ns: u64) -> Option<i64> {
        Some(self.fit.at(x_ns)?.wrapping_sub(x_ns) as i64)
    }

    /// The far reference's estimated error at `x_ns` (its time less the reference's) and that
    /// estimate's standard deviation, once enough samples have come. Until the level at the
    /// break is fixed, the error is the line's rise since the break, known as well as its
    /// slope; after, the line's level now less that one, known as well as the line now and
    /// that level (a constant of the measurement, whose own error is a bias no later sample
    /// can show; a window restarted before it was fixed knows it poorly, and says so).
    pub fn error_ns(&self, x_ns: u64) -> Option<(i64, f64)> {
        if self.samples < MIN_POINTS {
            return None;
        }
        let break_x = self.break_x?;
        let (anchor, sd) = match self.anchor_ns {
            Some((a, sd_a)) => (a, libm::hypot(self.fit.sd_at_ns(x_ns)?, sd_a)),
            None => (self.level_at(break_x)?, self.fit.rate_sd()? * x_ns.wrapping_sub(break_x) as f64),
        };
        Some((self.level_at(x_ns)?.wrapping_sub(anchor).wrapping_add(self.applied_ns), sd))
    }

    /// When the last sample was taken (master ns).
    pub fn last_sample_ns(&self) -> Option<u64> {
        self.last_x
    }

    /// [`FarClock::error_ns`] at the last sample.
    pub fn error_now(&self) -> Option<i64> {
        Some(self.error_ns(self.last_x?)?.0)
    }

    /// The far reference's rate against the master's clock, less 1, as the line has it; 0
    /// while the line cannot tell it from 0 (three standard deviations).
    pub fn drift(&self) -> f64 {
        let drift = self.fit.rate().map_or(0.0, |r| r - 1.0);
        let sd = self.fit.rate_sd().unwrap_or(f64::INFINITY);
        if drift.abs() > 3.0 * sd {
            drift
        } else {
            0.0
        }
    }

    /// The far reference's offset was moved by `delta_ns`.
    pub fn applied(&mut self, delta_ns: i64) {
        self.applied_ns = self.applied_ns.wrapping_add(delta_ns);
    }

    /// What has been added to the far reference's offset since the break.
    pub fn applied_ns(&self) -> i64 {
        self.applied_ns
    }
}

/// The far reference being kept, when its offset was last moved (master time), and what its
/// offset register holds as far as the master knows.
#[derive(Debug, Clone)]
pub(crate) struct FarSteer {
    pub(crate) station: u16,
    pub(crate) clock: FarClock,
    pub(crate) filter: crate::pass_filter::PassFilter,
    pub(crate) last_move_ns: Option<u64>,
    pub(crate) offset: Option<u64>,
}

/// The far reference's time less the reference's as the two passes measured them, less the
/// master's time between the passes (mid-point to mid-point).
pub fn measured_difference_ns(p: &SplitPasses, wide: bool) -> (u64, i64) {
    let (near, far) = p.mid_points_ns();
    let apart = if wide {
        p.far_time.wrapping_sub(p.near_time) as i64
    } else {
        (p.far_time as u32).wrapping_sub(p.near_time as u32) as i32 as i64
    };
    (far, apart.wrapping_sub(far.wrapping_sub(near) as i64))
}

impl FarSteer {
    /// The far reference's offset register was changed by others (the whole far half moved).
    pub(crate) fn forget_offset(&mut self) {
        self.offset = None;
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use rand::SeedableRng;
    use rand_distr::{Distribution, Normal};

    /// A far reference drifting `ppm` from the break, measured through a constant bias and
    /// stamps scattered by `sd_ns`, one sample per ms; every move the estimator asks for
    /// applied. Returns its true error after `ms`.
    fn steer(ppm: f64, bias_ns: f64, sd_ns: f64, ms: u64) -> (f64, FarClock) {
        let mut rng = rand_chacha::ChaCha8Rng::seed_from_u64(7);
        let noise = Normal::new(0.0, sd_ns).unwrap();
        let mut f = FarClock::new();
        let x0 = 5_000_000_000_000u64;
        let mut added = 0i64;
        let mut true_error = 0.0;
        for k in 0..ms {
            let dx = k * 1_000_000;
            true_error = ppm * 1e-6 * dx as f64 + added as f64;
            let measured = true_error + bias_ns + noise.sample(&mut rng);
            f.push(x0 + dx, measured.round() as i64);
            if k % 10 == 0 {
                if let Some((e, _)) = f.error_ns(x0 + dx) {
                    added -= e;
                    f.applied(-e);
                }
            }
        }
        (true_error, f)
    }

    #[test]
    fn the_measurements_bias_is_learned_at_the_break_and_the_drift_taken_out() {
        // Exact stamps: the error stays within the drift of one move's interval.
        let (e, f) = steer(0.5, -1_234.0, 0.0, 20_000);
        assert!(e.abs() < 6.0, "{e}");
        assert!((f.drift() - 0.5e-6).abs() < 1e-9, "{}", f.drift());
        assert!((f.applied_ns() as f64 + 0.5e-6 * 19_999e6).abs() < 10.0, "{}", f.applied_ns());
        // Stamps scattered by 300 ns: within tens of ns after 20 s (10 µs held over).
        let (e, _) = steer(0.5, 2_000.0, 300.0, 20_000);
        assert!(e.abs() < 30.0, "{e}");
    }

    #[test]
    fn a_level_known_beforehand_is_not_learned() {
        // The measurement's constant is 300 ns and the far reference 200 ns off from the start:
        // learned from its first samples the error would read 0; known, it reads 200.
        let mut f = FarClock::anchored(300, 10.0);
        assert!(f.knew_level() && !FarClock::new().knew_level());
        for k in 0..MIN_POINTS {
            f.push(k * 1_000_000, 500);
        }
        let (e, sd) = f.error_ns(MIN_POINTS * 1_000_000).unwrap();
        assert_eq!(e, 200);
        assert!(sd >= 10.0, "{sd}");
        assert_eq!(f.error_now(), Some(200));
        // Moved by −200, the next samples measure the constant: no error left.
        f.applied(-200);
        for k in MIN_POINTS..2 * MIN_POINTS {
            f.push(k * 1_000_000, 300);
        }
        assert!(f.error_now().unwrap().abs() <= 1, "{:?}", f.error_now());
    }

    #[test]
    fn nothing_is_said_before_enough_samples() {
        let mut f = FarClock::new();
        for k in 0..MIN_POINTS - 1 {
            f.push(k * 1_000_000, 100);
        }
        assert_eq!(f.error_ns(MIN_POINTS * 1_000_000), None);
        f.push(MIN_POINTS * 1_000_000, 100);
        let (e, _) = f.error_ns(MIN_POINTS * 1_000_000).unwrap();
        assert_eq!(e, 0, "a constant difference is the bias, not an error");
    }

    #[test]
    fn the_difference_is_taken_across_a_32_bit_wrap_and_less_the_masters_time() {
        let p = SplitPasses {
            near_tx_ns: 1_000,
            near_rx_ns: 41_000,
            far_tx_ns: 100_000,
            far_rx_ns: 140_000,
            near_time: 0xFFFF_FF00,
            far_time: 0x1_0001_0000 + 0x100,
            len: 4,
            far_wkc: 1,
        };
        // The far reference's reading is 0x10200 ns on, the master's mid-points 99 000 apart.
        assert_eq!(measured_difference_ns(&p, false), (120_000, 0x10200 - 99_000));
        let wide = SplitPasses { near_time: 5_000_000, far_time: 4_990_000, len: 8, ..p };
        assert_eq!(measured_difference_ns(&wide, true), (120_000, -10_000 - 99_000));
        // Stamps out of order (a receive stamp before its send) do not overflow.
        let odd = SplitPasses { near_tx_ns: u64::MAX, near_rx_ns: 0, far_tx_ns: 0, far_rx_ns: u64::MAX, ..wide };
        let _ = measured_difference_ns(&odd, true);
    }
}
