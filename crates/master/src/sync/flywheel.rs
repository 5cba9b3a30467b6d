//! A follower's crystal as a flywheel for the reference's clock.
//!
//! A follower's time control loop steers its local time onto the reference's, and the speed it
//! applies (0x0932) is readable: taken back out, what is left is the follower's own crystal,
//! which does not move when the reference's does. The difference reference − crystal is then
//! known to a few ns every cycle from hardware alone (both times latched by the same frame),
//! while the crystal against the master still needs the host's noisy stamps. A change of the
//! reference's crystal shows in the first at once and not at all in the second.
use super::{FollowerClock, LineEvents};
use crate::line_fit::{FrozenLine, LineFit};

/// Readings further apart than this (or going backwards: a power cycle, a 32-bit wrap) start
/// the crystal's count again from the reference's time.
const MAX_GAP_NS: u64 = 1_000_000_000;
/// ε's line is worth freezing at a restart only with this many points behind it: a young
/// line's slope is its last restart's guess, and a change measured from it would be that
/// guess's error.
const KINK_MIN_POINTS: usize = 256;

#[derive(Debug)]
pub struct Flywheel {
    /// The follower's local time at the last reading.
    last_local_ns: Option<u64>,
    /// The follower's local time with its loop's corrections taken back out (ns).
    crystal_ns: u64,
    /// What of the corrections is not yet a whole ns.
    carry_ns: f64,
    /// (reference time, reference time + ε), ε = reference − crystal: its line, on the
    /// reference's own time, which the stamps' noise does not reach.
    eps: LineFit,
    /// The reference's time of the last frame that read the follower, and the ε it measured.
    last_point: Option<(u64, i64)>,
    /// +1 where a positive SCD slows the local clock (our model's reading of the datasheet),
    /// −1 for the other: the datasheet does not say, so the master tries both (`Ferrocat`).
    sign: f64,
    /// ε's line as it stood before its last restart, not yet taken (`Flywheel::take_kink`).
    kink: Option<FrozenLine>,
}

/// The clock deviation one speed counter difference applies: SCD / (5·(SCS + SCD + 2)·(SCS −
/// SCD + 2)) (esc-spec §3.5, the datasheet's formula); 0 where the registers make no sense.
/// Which way it moves the clock is not documented: the master measures it (`Slave::speed_diff_slows`).
pub fn speed_deviation(speed_start: u16, speed_diff: i16) -> f64 {
    let (s, d) = ((speed_start & 0x7FFF) as f64, speed_diff as f64);
    let den = 5.0 * (s + d + 2.0) * (s - d + 2.0);
    if den > 0.0 {
        d / den
    } else {
        0.0
    }
}

impl Flywheel {
    /// A flywheel whose ε runs on `eps`, taking a positive SCD to slow the local clock where
    /// `slows` (as our ESC model does), to speed it up otherwise.
    pub fn new(eps: LineFit, slows: bool) -> Self {
        Flywheel {
            last_local_ns: None,
            crystal_ns: 0,
            carry_ns: 0.0,
            eps,
            last_point: None,
            sign: if slows { 1.0 } else { -1.0 },
            kink: None,
        }
    }

    /// What ε's line has been through. A loop's corrections taken out the wrong way (or not
    /// at all) leave ε as jagged as the loop's own work, and its line restarts again and again.
    pub fn eps_events(&self) -> LineEvents {
        LineEvents { restarts: self.eps.restarts, false_alarms: self.eps.false_alarms }
    }

    /// A frame read the reference at `reference_ns` and the follower as `f`: the follower's
    /// crystal time at that instant (the point for the crystal's line against the master).
    pub fn frame(&mut self, reference_ns: u64, f: &FollowerClock) -> u64 {
        let step = self.last_local_ns.map(|prev| f.local_ns.wrapping_sub(prev));
        match step {
            Some(d) if d > 0 && d <= MAX_GAP_NS => {
                // The speed read is the one in force since the loop's last sample, the frame
                // before: over the whole interval but the frame's own passage. An ESC corrects
                // every so many of its crystal's ticks, so local = crystal·(1 − deviation).
                let dev = self.sign * speed_deviation(f.speed_start, f.speed_diff);
                let corr = d as f64 * dev / (1.0 - dev) + self.carry_ns;
                let whole = corr.round();
                self.carry_ns = corr - whole;
                self.crystal_ns = self.crystal_ns.wrapping_add(d).wrapping_add_signed(whole as i64);
            }
            // The first reading, or a count that cannot go on: the crystal takes up where the
            // line of ε says it is, so that the crystal's own line does not see a step.
            _ => {
                let e = self.eps_at(reference_ns).unwrap_or(0);
                self.crystal_ns = reference_ns.wrapping_sub(e as u64);
                self.carry_ns = 0.0;
            }
        }
        self.last_local_ns = Some(f.local_ns);
        let e = reference_ns.wrapping_sub(self.crystal_ns) as i64;
        self.last_point = Some((reference_ns, e));
        let before = self.eps_frozen_at(reference_ns);
        let restarts = self.eps.restarts;
        self.eps.push(reference_ns, reference_ns.wrapping_add_signed(e));
        if self.eps.restarts != restarts && before.is_some() {
            self.kink = before;
        }
        self.crystal_ns
    }

    /// ε = reference − crystal at reference time `reference_ns`, from its line (the last one
    /// measured before the line has two points); `None` before the first frame.
    pub fn eps_at(&self, reference_ns: u64) -> Option<i64> {
        self.eps.at(reference_ns).map(|v| v.wrapping_sub(reference_ns) as i64).or(self.last_eps_ns())
    }

    /// dε/d(reference time).
    pub fn eps_slope(&self) -> f64 {
        self.eps.rate().map_or(0.0, |r| r - 1.0)
    }

    /// The last ε measured.
    pub fn last_eps_ns(&self) -> Option<i64> {
        self.last_point.map(|(_, e)| e)
    }

    /// The last ε measured and the reference's time it was measured at.
    pub fn last_point(&self) -> Option<(u64, i64)> {
        self.last_point
    }

    /// ε's line (reference time ↦ reference time + ε) as it stood before it last restarted
    /// after a long run, if not taken yet: one of the two crystals changed then, and how far
    /// ε has left that line since is how far the one that changed has left its old rate.
    pub fn take_kink(&mut self) -> Option<FrozenLine> {
        self.kink.take()
    }

    /// ε's line at `reference_ns` as it stands, frozen, if it has run long enough to be worth
    /// it (the other reading's, when this one's restarted: see `Ferrocat`'s kink test).
    pub fn eps_frozen_at(&self, reference_ns: u64) -> Option<FrozenLine> {
        self.eps.frozen_at(reference_ns).filter(|_| self.eps.len() >= KINK_MIN_POINTS)
    }

    /// How far ε's line moved when it changed windows (see `LineFit::take_switch_jump_ns`).
    pub fn take_switch_jump_ns(&mut self) -> i64 {
        self.eps.take_switch_jump_ns()
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use proptest::prelude::*;

    proptest! {
        /// Whatever the wire brings (any SCS, SCD and local time, wraps and jumps included), the
        /// deviation stays a small finite fraction and the flywheel neither panics nor
        /// overflows.
        #[test]
        fn any_reading_is_taken_without_panic(
            readings in proptest::collection::vec((any::<u64>(), any::<u64>(), any::<u16>(), any::<i16>()), 1..64)
        ) {
            let mut fw = Flywheel::new(LineFit::new(64), true);
            for (reference_ns, local_ns, speed_start, speed_diff) in readings {
                let dev = speed_deviation(speed_start, speed_diff);
                prop_assert!(dev.is_finite() && dev.abs() < 0.5, "{dev}");
                fw.frame(reference_ns, &FollowerClock { local_ns, speed_start, speed_diff, speed_diff_slows: None });
                let _ = (fw.eps_at(reference_ns), fw.eps_slope());
            }
        }
    }

    #[test]
    fn speed_deviation_is_the_datasheets_formula() {
        // esc-spec §3.5 at SCS = 0x1000: SCD 1 → 0.012 ppm, 100 → 1.19 ppm, 2565 → 50 ppm,
        // 3969 (the bound) → 763 ppm.
        for (scd, ppm) in [(1, 0.0119), (100, 1.19), (2565, 50.0), (3969, 763.0)] {
            let got = speed_deviation(0x1000, scd) * 1e6;
            assert!((got - ppm).abs() < ppm * 0.01, "SCD {scd}: {got} ppm");
            assert_eq!(speed_deviation(0x1000, -scd), -speed_deviation(0x1000, scd));
        }
        // Registers no ESC would hold give no correction rather than a wild one.
        assert_eq!(speed_deviation(0, 100), 0.0);
    }

    /// A follower whose loop changes its speed every cycle: the crystal the flywheel takes back
    /// out of its local time keeps the crystal's own rate to the ns, and a step of the
    /// reference's crystal is in ε's line within a few cycles.
    #[test]
    fn the_crystal_comes_back_out_of_a_steered_local_time() {
        let (ref_ppm, fol_ppm) = (23.0, -31.0);
        let mut fw = Flywheel::new(LineFit::new(4096), true);
        let (mut t, mut local, mut crystal, mut reference) = (0.0f64, 5e8f64, 5e8f64, 7e9f64);
        let mut ref_rate = 1.0 + ref_ppm * 1e-6;
        let mut scd: i16 = 0;
        let mut first_offset = None;
        let mut worst_ns = 0.0f64;
        let mut late_eps_error_ns = 0.0f64;
        for k in 0..20_000u64 {
            // The loop's speed jumps about, as a loop chasing a jittery reference's would.
            scd = (scd as i32 + ((k * 7919 % 601) as i32 - 300)).clamp(-3000, 3000) as i16;
            let dt = 1_000_000.0 + (k * 104_729 % 20_000) as f64;
            if k == 10_000 {
                ref_rate += 50e-6;
            }
            t += dt;
            let crystal_dt = dt * (1.0 + fol_ppm * 1e-6);
            crystal += crystal_dt;
            local += crystal_dt * (1.0 - speed_deviation(0x1000, scd));
            reference += dt * ref_rate;
            // Read on the 10 ns grid of the local clock.
            let f = FollowerClock {
                local_ns: (local / 10.0).floor() as u64 * 10,
                speed_start: 0x1000,
                speed_diff: scd,
                speed_diff_slows: None,
            };
            let got = fw.frame(reference as u64, &f) as f64;
            let offset = got - crystal;
            let first = *first_offset.get_or_insert(offset);
            worst_ns = worst_ns.max((offset - first).abs());
            if (10_010..10_020).contains(&k) {
                let eps = fw.eps_at(reference as u64).unwrap() as f64;
                late_eps_error_ns = late_eps_error_ns.max((eps - (reference - got)).abs());
            }
        }
        println!("crystal off by at most {worst_ns:.1} ns; ε's line off by {late_eps_error_ns:.1} ns after the step");
        assert!(worst_ns <= 10.0, "{worst_ns}");
        assert!(late_eps_error_ns <= 15.0, "{late_eps_error_ns}");
        let _ = t;
    }
}
