//! The distributed-clock unit (esc-spec §3).
//!
//! Time model, all in exact integer arithmetic so that a simulation gives the same numbers on
//! any machine:
//! - the oscillator advances a phase in attoseconds at `1 + drift_ppb·10⁻⁹` of true time;
//! - the local time counts whole 10 ns ticks of that phase, plus the time control loop's
//!   corrections, which are whole nanoseconds (the datasheet's 9 ns / 11 ns ticks);
//! - the correction rate is the datasheet's `SCD / (5·(SCS+SCD+2)·(SCS−SCD+2))` (esc-spec §3.5).
//!
//! The loop that turns samples (writes of 0x0910) into SCD is not documented; ours is described
//! in docs/esc-model.md.
use std::sync::Arc;

use crate::config::DcWidth;
use crate::rate_table::{exact_rates, RateTable};

const AS_PER_NS: i128 = 1_000_000_000;
const TICK_AS: i128 = 10 * AS_PER_NS;
/// Phase time constant of the loop: an offset is slewed out over about this long.
pub const TCL_PHASE_TAU_NS: i128 = 50_000_000;
/// The shortest span between two samples that updates the loop's frequency estimate.
pub const TCL_MIN_SPAN_NS: i64 = 200_000;

/// The rate (10⁻¹⁵) that slews a mean difference of `diff_q8` (1/256 ns) out over TAU:
/// `diff·(10¹⁵/256)/TAU`. Below 2⁵³/5¹⁵ both of its roundings are exact and it is `diff·78 125`
/// exactly, one multiplication instead of a division.
fn phase_fpp(diff_q8: i64) -> f64 {
    const EXACT_BELOW: u64 = (1u64 << 53) / 5u64.pow(15);
    const _: () = assert!(1e15 / 256.0 / TCL_PHASE_TAU_NS as f64 == 78_125.0);
    if diff_q8.unsigned_abs() < EXACT_BELOW {
        diff_q8 as f64 * 78_125.0
    } else {
        diff_q8 as f64 * (1e15 / 256.0) / TCL_PHASE_TAU_NS as f64
    }
}

#[derive(Debug, Clone)]
pub struct DcUnit {
    pub width: DcWidth,
    /// True time up to which the accumulators are folded.
    t_ns: u64,
    /// Whole 10 ns ticks of the oscillator, and the phase past the last tick (attoseconds).
    ticks: i64,
    phase_rem_as: i64,
    /// Whole nanoseconds of TCL correction, and the remainder (attoseconds, 0..10⁹).
    corr_ns: i64,
    corr_rem_as: i64,
    /// Correction rate, attoseconds per ns × 2³², from SCS and SCD.
    corr_rate_q32: i64,
    pub drift_ppb: i64,
    pub offset: u64,
    pub delay: u32,
    pub scs: u16,
    pub scd: i16,
    pub depth_diff: u8,
    pub depth_speed: u8,
    /// Filtered `local − received` (0x092C), in 1/256 ns: the filter's shift floors, and on
    /// whole nanoseconds that floor alone held every follower ≈ 7.5 ns ahead of the reference.
    diff_mean_q8: i64,
    /// Estimated free-running frequency error, in units of 10⁻¹⁵ (f64: exact IEEE operations
    /// in a fixed order, so every machine computes the same value).
    freq_est_fpp: f64,
    /// The rate the current SCD applies, in units of 10⁻¹⁵.
    applied_fpp: i64,
    last_sample: Option<(u64, i64)>,
    /// The mean span between the samples that update the frequency (ns of local time, 0: none
    /// yet), over as many as the frequency filter.
    mean_span_ns: f64,
    pub sync: SyncUnit,
    /// The rates of every SCD the current SCS allows (looked up again when SCS changes).
    rates: Arc<RateTable>,
}

/// SYNC0 pulses that fell due together (see [`DcUnit::take_sync0_until`]).
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct Sync0Due {
    /// How many pulses (at least one).
    pub pulses: u64,
    /// System time of the last of them, as the registers show it (32-bit DC: masked).
    pub last_sys_ns: u64,
}

impl SyncUnit {
    /// SYNC0 generation on (0x0981 bit 1); with only SYNC1 on, SYNC0's pulses still time SYNC1
    /// but raise no SYNC0 signal.
    pub fn output_enabled(&self) -> bool {
        self.activation & ferrocat_wire::register::dc_activation::SYNC0 != 0
    }

    /// A pulse length greater than the cycle time keeps the output active (ESC datasheet
    /// section I, 9.2.3.1): after its first edge the PDI sees no further ones.
    pub fn output_held(&self) -> bool {
        self.cycle0_ns > 0 && self.pulse_len_10ns as u64 * 10 > self.cycle0_ns as u64
    }
}

#[derive(Debug, Clone, Default)]
pub struct SyncUnit {
    pub activation: u8,
    pub pulse_len_10ns: u16,
    pub start_time: u64,
    pub cycle0_ns: u32,
    pub cycle1_ns: u32,
    /// System time of the next SYNC0 pulse, when armed.
    pub next_sync0: Option<u64>,
    /// Bits 0 and 2 of 0x0984 (bit 1, SYNC1 pending, follows from the time: see
    /// [`DcUnit::activation_status_at`]).
    pub activation_status: u8,
    pub sync0_count: u64,
    /// System time of the first SYNC0 pulse since activation: SYNC1's grid starts there.
    pub first_sync0: Option<u64>,
}

impl DcUnit {
    /// A DC unit at true time `t_ns` whose local time starts at `local0_ns` (power-on).
    pub fn new(width: DcWidth, t_ns: u64, local0_ns: u64, drift_ppb: i64) -> Self {
        DcUnit {
            width,
            t_ns,
            ticks: (local0_ns / 10) as i64,
            phase_rem_as: (local0_ns % 10) as i64 * AS_PER_NS as i64,
            corr_ns: 0,
            corr_rem_as: 0,
            corr_rate_q32: 0,
            drift_ppb,
            offset: 0,
            delay: 0,
            scs: 0x1000,
            scd: 0,
            depth_diff: 4,
            depth_speed: 12,
            diff_mean_q8: 0,
            freq_est_fpp: 0.0,
            applied_fpp: 0,
            last_sample: None,
            mean_span_ns: 0.0,
            sync: SyncUnit::default(),
            rates: RateTable::for_scs(0x1000),
        }
    }

    fn mask(&self, v: u64) -> u64 {
        match self.width {
            DcWidth::Bits32 => v & 0xFFFF_FFFF,
            _ => v,
        }
    }

    /// Local time (ns) at true time `t_ns` (which may lie slightly before the folded time).
    #[inline]
    pub fn local_at(&self, t_ns: u64) -> u64 {
        self.mask(self.local_ext_at(t_ns))
    }

    /// System time without the 32-bit wrap of a 32-bit DC: what the SYNC unit schedules on.
    fn system_ext_at(&self, t_ns: u64) -> u64 {
        self.local_ext_at(t_ns).wrapping_add(self.offset)
    }

    #[inline]
    fn local_ext_at(&self, t_ns: u64) -> u64 {
        // At the folded time (every frame folds first) the accumulators are the answer.
        let (ticks, corr_ns) = if t_ns == self.t_ns {
            (self.ticks, self.corr_ns)
        } else {
            let (ticks, _, corr_ns, _) = self.project(t_ns as i128 - self.t_ns as i128);
            (ticks, corr_ns)
        };
        // The counter is 64 bits wide and wraps (a unit powered on near 2^64 does).
        (10 * ticks as i128 + corr_ns as i128).max(0) as u64
    }

    /// The accumulators `dt` ns after the folded time: (ticks, phase remainder, correction ns,
    /// correction remainder). Exact integer arithmetic; i64 on the hot path (|dt| < 2³² ns).
    fn project(&self, dt: i128) -> (i64, i64, i64, i64) {
        const TICK: i64 = TICK_AS as i64;
        const NS: i64 = AS_PER_NS as i64;
        let per_ns = AS_PER_NS as i64 + self.drift_ppb;
        let corr_delta = (dt * self.corr_rate_q32 as i128) >> 32;
        if (0..1 << 32).contains(&dt) {
            let dt = dt as i64;
            let ph = self.phase_rem_as + dt * per_ns;
            let c = self.corr_rem_as - corr_delta as i64;
            (self.ticks + ph.div_euclid(TICK), ph.rem_euclid(TICK), self.corr_ns + c.div_euclid(NS), c.rem_euclid(NS))
        } else {
            let ph = self.phase_rem_as as i128 + dt * per_ns as i128;
            let c = self.corr_rem_as as i128 - corr_delta;
            (
                self.ticks + ph.div_euclid(TICK_AS) as i64,
                ph.rem_euclid(TICK_AS) as i64,
                self.corr_ns + c.div_euclid(AS_PER_NS) as i64,
                c.rem_euclid(AS_PER_NS) as i64,
            )
        }
    }

    /// The rate table of the current SCS (`scs` is public: tests and 0x0930 writes set it).
    fn rates(&mut self) -> &RateTable {
        if self.rates.scs != self.scs {
            self.rates = RateTable::for_scs(self.scs);
        }
        &self.rates
    }

    fn set_scd(&mut self, scd: i16) {
        self.scd = scd;
        let scs = self.scs;
        (self.corr_rate_q32, self.applied_fpp) = match self.rates().applied(scd as i64) {
            Some(e) => (e.q32, e.fpp),
            None => exact_rates(scs, scd as i64),
        };
    }

    /// Local copy of the system time at true time `t_ns`.
    pub fn system_at(&self, t_ns: u64) -> u64 {
        self.mask(self.local_at(t_ns).wrapping_add(self.offset))
    }

    /// What an ECAT read of 0x0910 returns for a frame that reached this ESC at `t_ns`.
    pub fn ecat_system_time(&self, t_ns: u64) -> u64 {
        self.ecat_time_of_local(self.local_at(t_ns))
    }

    /// The ECAT read's value (system time less the delay) for a local time.
    fn ecat_time_of_local(&self, local: u64) -> u64 {
        self.mask(self.mask(local.wrapping_add(self.offset)).wrapping_sub(self.delay as u64))
    }

    /// Folds the accumulators forward to `t_ns` (never backward).
    pub fn fold_to(&mut self, t_ns: u64) {
        if t_ns <= self.t_ns {
            return;
        }
        (self.ticks, self.phase_rem_as, self.corr_ns, self.corr_rem_as) = self.project((t_ns - self.t_ns) as i128);
        self.t_ns = t_ns;
    }

    /// Changes the oscillator's frequency error from `t_ns` on (wander, temperature steps).
    pub fn set_drift_ppb(&mut self, t_ns: u64, drift_ppb: i64) {
        self.fold_to(t_ns);
        self.drift_ppb = drift_ppb;
    }

    /// The TCL filters are reset by any write of 0x0930 (esc-spec §3.2).
    pub fn reset_filters(&mut self, t_ns: u64) {
        self.fold_to(t_ns);
        self.diff_mean_q8 = 0;
        self.set_scd(0);
        self.freq_est_fpp = 0.0;
        self.last_sample = None;
        self.mean_span_ns = 0.0;
    }

    /// A write of `received` to 0x0910 by a frame that reached this ESC at `t_ns`: one sample of
    /// the time control loop, on the lower 32 bits (esc-spec §3.5).
    pub fn tcl_sample(&mut self, t_ns: u64, received: u32) {
        self.fold_to(t_ns);
        let local = self.local_at(t_ns);
        let local_copy = self.ecat_time_of_local(local) as u32;
        let dt = local_copy.wrapping_sub(received) as i32 as i64;
        // Mean of the difference over 2^depth samples (0x092C).
        let n1 = (self.depth_diff & 0x0F) as u32;
        self.diff_mean_q8 += ((dt << 8) - self.diff_mean_q8) >> n1;
        // Frequency: the change of the difference since the last sample, plus what the loop
        // was already correcting, filtered over 2^depth samples.
        let applied_fpp = self.applied_fpp as f64;
        // Samples closer together than TCL_MIN_SPAN_NS do not update the frequency: the change
        // of the difference over a few µs is all quantisation and jitter, and dividing it by so
        // short a span would amplify it (two FRMW frames 10 µs apart made followers wander by
        // ±1 µs before this rule). The anchor stays until a span is long enough.
        match self.last_sample {
            Some((l0, dt0)) => {
                let span = local.wrapping_sub(l0) as i64;
                if span >= TCL_MIN_SPAN_NS {
                    let meas = applied_fpp + (dt - dt0) as f64 * 1e15 / span as f64;
                    let n2 = (self.depth_speed & 0x0F).min(6) as i32;
                    // × 2⁻ⁿ is exactly ÷ 2ⁿ, without a division's latency.
                    let gain = 1.0 / (1u32 << n2) as f64;
                    let span = span as f64;
                    self.mean_span_ns = if self.mean_span_ns > 0.0 {
                        self.mean_span_ns + (span - self.mean_span_ns) * gain
                    } else {
                        span
                    };
                    // Each measurement weighs as long as its span: a frame late by L gives one
                    // short and one long span whose changes of Δt cancel, and weighed per sample
                    // the short one's won — a stock kernel's late wake-ups biased the frequency
                    // and so held a follower tens of ns off (docs/esc-model.md).
                    let weight = (gain * span / self.mean_span_ns).min(1.0);
                    self.freq_est_fpp += (meas - self.freq_est_fpp) * weight;
                    self.last_sample = Some((local, dt));
                } else if span < 0 {
                    self.last_sample = Some((local, dt));
                }
            }
            None => self.last_sample = Some((local, dt)),
        }
        // Command: cancel the frequency error and slew the mean difference out over TAU.
        let want_fpp = self.freq_est_fpp + phase_fpp(self.diff_mean_q8);
        let scd = self.scd_for(want_fpp);
        if scd != self.scd {
            self.set_scd(scd);
        }
    }

    /// The speed-counter difference whose rate is closest to `fpp` (10⁻¹⁵), within the bound.
    fn scd_for(&mut self, fpp: f64) -> i16 {
        let from = self.scd as i64;
        self.rates().nearest(fpp * 1e-15, from) as i16
    }

    /// Filtered `local − received` (0x092C's value), in ns, rounded to nearest.
    pub fn diff_mean_ns(&self) -> i64 {
        (self.diff_mean_q8 + 128) >> 8
    }

    /// 0x092C as sign–magnitude.
    pub fn difference_register(&self) -> u32 {
        ferrocat_wire::register::SystemTimeDifference::from_ns(self.diff_mean_ns()).0
    }

    /// Arms or disarms SYNC generation after a write of 0x0981 or 0x0990 at `t_ns`.
    pub fn sync_activation_written(&mut self, t_ns: u64) {
        use ferrocat_wire::register::dc_activation as act;
        let a = self.sync.activation;
        if a & act::CYCLIC_OPERATION == 0 || a & (act::SYNC0 | act::SYNC1) == 0 {
            self.sync.next_sync0 = None;
            self.sync.first_sync0 = None;
            self.sync.activation_status = 0;
            return;
        }
        let now = self.system_ext_at(t_ns);
        let range_mask = if self.width == DcWidth::Bits32 { 0xFFFF_FFFF } else { u64::MAX };
        let ahead = self.sync.start_time.wrapping_sub(now) & range_mask;
        let near = if a & act::NEAR_FUTURE_2S != 0 {
            2_100_000_000
        } else if self.width == DcWidth::Bits32 {
            1 << 31
        } else {
            1 << 63
        };
        let in_future = ahead > 0 && ahead < near;
        let s = &mut self.sync;
        s.activation_status = 0b01;
        s.next_sync0 = if in_future {
            Some(now.wrapping_add(ahead))
        } else if a & act::START_TIME_CHECK != 0 {
            // Plausibility check: a start time outside the near future fires at once.
            s.activation_status |= 0b100;
            Some(now)
        } else if self.width == DcWidth::Bits32 {
            // Without the check a past start time waits for the time to come round again:
            // ≈4.3 s on a 32-bit DC, never on a 64-bit one.
            Some(now.wrapping_add(ahead))
        } else {
            None
        };
        s.first_sync0 = s.next_sync0;
    }

    /// SYNC1's pulses as (system time of the first, period; 0: one pulse), when SYNC1 is
    /// enabled. ESC datasheet section I 9.2.3.5: a SYNC1 pulse follows the SYNC0 pulse that arms
    /// it by the SYNC1 cycle time (0x09A4; 0: SYNC1 reflects SYNC0), and the next SYNC0 pulse
    /// after it arms the next — so the period is the SYNC0 cycle when the SYNC1 time is shorter,
    /// else the smallest multiple of it that is not shorter (model choice for an exact
    /// multiple, which the datasheet's figure draws at that multiple: a SYNC0 pulse coinciding
    /// with a SYNC1 pulse arms the next).
    fn sync1_grid(&self) -> Option<(u64, u64)> {
        use ferrocat_wire::register::dc_activation as act;
        if self.sync.activation & act::SYNC1 == 0 {
            return None;
        }
        let first0 = self.sync.first_sync0?;
        let (c0, c1) = (self.sync.cycle0_ns as u64, self.sync.cycle1_ns as u64);
        let period = if c0 == 0 { 0 } else { c1.div_ceil(c0).max(1) * c0 };
        Some((first0.wrapping_add(c1), period))
    }

    /// SYNC1 pulses by true time `t_ns` since activation, and the system time of the next one
    /// (of the last when a single shot has passed).
    fn sync1_at(&self, t_ns: u64) -> Option<(u64, u64)> {
        let (first, period) = self.sync1_grid()?;
        let late = self.system_ext_at(t_ns).wrapping_sub(first);
        Some(if (late as i64) < 0 {
            (0, first)
        } else {
            match late.checked_div(period) {
                None => (1, first), // a single shot, passed
                Some(q) => (q + 1, first.wrapping_add((q + 1) * period)),
            }
        })
    }

    /// SYNC1 pulses by true time `t_ns` since the unit was activated.
    pub fn sync1_pulses_until(&self, t_ns: u64) -> u64 {
        self.sync1_at(t_ns).map_or(0, |(k, _)| k)
    }

    /// 0x0998, the next SYNC1 pulse's system time, at true time `t_ns` (0 without SYNC1).
    pub fn next_sync1_register(&self, t_ns: u64) -> u64 {
        self.sync1_at(t_ns).map_or(0, |(_, next)| self.mask(next))
    }

    /// Whether a SYNC1 pulse fell within the `window_ns` of system time before true time `t_ns`.
    pub fn sync1_within(&self, t_ns: u64, window_ns: u64) -> bool {
        let Some((first, period)) = self.sync1_grid() else { return false };
        let late = self.system_ext_at(t_ns).wrapping_sub(first);
        // A single shot (period 0) counts from its one pulse.
        (late as i64) >= 0 && late.checked_rem(period).unwrap_or(late) < window_ns
    }

    /// 0x0984 at true time `t_ns`: bit 1 while the first SYNC1 pulse is pending.
    pub fn activation_status_at(&self, t_ns: u64) -> u8 {
        let pending1 = self.sync1_at(t_ns).is_some_and(|(k, _)| k == 0);
        (self.sync.activation_status & !0b10) | if pending1 { 0b10 } else { 0 }
    }

    /// The SYNC0 pulses due by true time `t_ns`, taken together and the schedule advanced past
    /// them: constant time however short the cycle or long the gap, so a master that programs
    /// a cycle of a few ns cannot make the simulator count pulses one by one.
    pub fn take_sync0_until(&mut self, t_ns: u64) -> Option<Sync0Due> {
        let next = self.sync.next_sync0?;
        // Wrapping, half-range comparisons: the schedule never overflows, whatever the offset.
        let late = self.system_ext_at(t_ns).wrapping_sub(next);
        if (late as i64) < 0 {
            return None;
        }
        let (pulses, last) = match self.sync.cycle0_ns {
            0 => {
                self.sync.next_sync0 = None; // single shot
                (1, next)
            }
            c => {
                let c = c as u64;
                let k = late / c + 1;
                let last = next.wrapping_add((k - 1) * c);
                self.sync.next_sync0 = Some(last.wrapping_add(c));
                (k, last)
            }
        };
        self.sync.sync0_count += pulses;
        self.sync.activation_status &= !0b01;
        Some(Sync0Due { pulses, last_sys_ns: self.mask(last) })
    }

    /// The next SYNC0 as the register 0x0990 shows it.
    pub fn next_sync0_register(&self) -> u64 {
        self.sync.next_sync0.map(|n| self.mask(n)).unwrap_or(self.sync.start_time)
    }

    /// True time of the next SYNC0 pulse, searching from `from_ns`.
    #[inline]
    pub fn next_sync0_true(&self, from_ns: u64) -> Option<u64> {
        let next = self.sync.next_sync0?;
        self.search_sync0(from_ns, next)
    }

    /// True time of the first SYNC0 pulse later than true time `after_ns`: the pulses due by
    /// then are skipped (they fall while the PDI still services an earlier one).
    pub fn next_sync0_true_after(&self, after_ns: u64) -> Option<u64> {
        let next = self.sync.next_sync0?;
        let late = self.system_ext_at(after_ns).wrapping_sub(next);
        let first = if (late as i64) < 0 {
            next
        } else {
            match self.sync.cycle0_ns as u64 {
                0 => return None,
                c => next.wrapping_add((late / c + 1) * c),
            }
        };
        self.search_sync0(after_ns.saturating_add(1), first)
    }

    fn search_sync0(&self, from_ns: u64, next: u64) -> Option<u64> {
        let now = self.system_ext_at(from_ns);
        let ahead = next.wrapping_sub(now) as i64;
        if ahead <= 0 {
            return Some(from_ns);
        }
        let ahead = ahead as u64;
        let reached = |t: u64| (self.system_ext_at(t).wrapping_sub(next) as i64) >= 0;
        // Bracket the pulse between `lo` (not reached) and `hi` (reached), starting from the
        // estimate for a clock 0.1 % fast and galloping forward with doubling steps, then
        // bisect: at most ~130 evaluations however far the start time or fast the clock.
        let mut lo = from_ns;
        let mut hi = from_ns.saturating_add(ahead.saturating_sub(ahead / 1000 + 10));
        let mut step = 1u64 << 16;
        while !reached(hi) && hi < u64::MAX {
            lo = hi;
            hi = hi.saturating_add(step);
            step = step.saturating_mul(2);
        }
        while hi - lo > 1 {
            let mid = lo + (hi - lo) / 2;
            if reached(mid) {
                hi = mid;
            } else {
                lo = mid;
            }
        }
        let t = hi;
        Some(t)
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use proptest::prelude::*;

    /// The i64 rate arithmetic equals the i128 formula for every SCS the register takes and
    /// every SCD the bound allows.
    #[test]
    fn rates_match_the_wide_formula() {
        for scs in (0x0080u16..=0x3FFF).step_by(97).chain([0x0080, 0x1000, 0x3FFF]) {
            let max = scs as i64 - 0x7F;
            let mut dc = DcUnit::new(DcWidth::Bits64, 0, 0, 0);
            dc.scs = scs;
            for scd in (-max..=max).step_by(13).chain([-max, -1, 0, 1, max]) {
                let (num, den) = (scd as i128, 5 * (scs as i128 + scd as i128 + 2) * (scs as i128 - scd as i128 + 2));
                dc.set_scd(scd as i16);
                assert_eq!(dc.corr_rate_q32 as i128, ((AS_PER_NS * num) << 32) / den, "scs {scs} scd {scd}");
                assert_eq!(dc.applied_fpp as i128, 1_000_000_000_000_000 * num / den, "scs {scs} scd {scd}");
            }
        }
    }

    proptest! {
        /// Whatever the power-on time, offset, delay, crystal (±1000 ppm), samples written to
        /// 0x0910 and SYNC0 set-up, on either width: no overflow or panic, and the local
        /// time advances by the elapsed true time (within the crystal and loop's 0.2 %) across
        /// every wrap.
        #[test]
        fn the_dc_unit_never_overflows(
            wide in any::<bool>(),
            local0 in any::<u64>(),
            offset in any::<u64>(),
            delay in any::<u32>(),
            drift_ppb in -1_000_000i64..1_000_000,
            samples in proptest::collection::vec((0u64..20_000_000, any::<u32>()), 1..40),
            start in any::<u64>(),
            cycle in any::<u32>(),
            cycle1 in any::<u32>(),
            activation in any::<u8>(),
        ) {
            let width = if wide { DcWidth::Bits64 } else { DcWidth::Bits32 };
            let mut dc = DcUnit::new(width, 1_000, local0, drift_ppb);
            (dc.offset, dc.delay) = (offset, delay);
            dc.sync.start_time = start;
            dc.sync.cycle0_ns = cycle.max(1_000);
            dc.sync.cycle1_ns = cycle1;
            dc.sync.activation = activation;
            dc.sync_activation_written(1_000);
            let mut t = 1_000u64;
            for (dt, received) in samples {
                let before = dc.local_at(t);
                t += dt;
                let elapsed = dc.local_at(t).wrapping_sub(before) & dc.mask(u64::MAX);
                prop_assert!((elapsed as f64 - dt as f64).abs() <= dt as f64 * 2e-3 + 20.0, "{elapsed} after {dt}");
                dc.tcl_sample(t, received);
                let _ = (dc.system_at(t), dc.ecat_system_time(t), dc.difference_register());
                if let Some(due) = dc.take_sync0_until(t) {
                    prop_assert!(due.pulses >= 1 && due.pulses <= dt / 1_000 + 2, "{due:?} after {dt}");
                }
                let _ = dc.next_sync0_true(t);
                let _ = (dc.next_sync1_register(t), dc.sync1_pulses_until(t), dc.activation_status_at(t));
            }
        }
    }

    /// `x.round() as i64` without the library call `round` is on baseline x86-64 (no SSE4.1): the
    /// cast truncates, and `x − trunc(x)` is exact.
    fn round_half_away(x: f64) -> i64 {
        let t = x as i64;
        let frac = x - t as f64;
        if frac >= 0.5 {
            t.saturating_add(1)
        } else if frac <= -0.5 {
            t.saturating_sub(1)
        } else {
            t
        }
    }

    /// The SCD nearest a rate by the closed form the table's search replaced: `d = 5r((S+2)² −
    /// d²)` is a quadratic in d; its root, rounded, and the two neighbours ranked.
    fn closed_form_scd(table: &RateTable, scs: u16, fpp: f64) -> i64 {
        let max = table.max;
        let s = scs as f64;
        let rate = |d: i64| table.rank(d).map_or(f64::INFINITY, |e| e.rate);
        let r = fpp * 1e-15;
        let guess =
            if r == 0.0 { 0.0 } else { (-1.0 + (1.0 + 100.0 * r * r * (s + 2.0) * (s + 2.0)).sqrt()) / (10.0 * r) };
        let g = round_half_away(guess).clamp(-max, max);
        let (mut best, mut best_err) = (g, (rate(g) - r).abs());
        for d in [g - 1, g + 1] {
            if d.abs() <= max {
                let err = (rate(d) - r).abs();
                if err < best_err {
                    (best, best_err) = (d, err);
                }
            }
        }
        best
    }

    proptest! {
        /// The table's search from any SCD in use finds the SCD the closed form finds, for any
        /// SCS and any commanded rate up to beyond the bound's (outside exact ties, where the
        /// search takes the lower and the closed form its rounded root).
        #[test]
        fn the_searched_scd_is_the_closed_forms(
            scs in 0x0080u16..=0x3FFF,
            from in any::<i16>(),
            fpp in prop_oneof![-1e13f64..1e13, -1e11f64..1e11, -1e9f64..1e9, Just(0.0)],
        ) {
            let table = RateTable::for_scs(scs);
            let searched = table.nearest(fpp * 1e-15, from as i64);
            let closed = closed_form_scd(&table, scs, fpp);
            let (r, rate) = (fpp * 1e-15, |d: i64| table.rank(d).unwrap().rate);
            let tie = (rate(searched) - r).abs() == (rate(closed) - r).abs();
            prop_assert!(searched == closed || tie, "scs {scs} from {from} fpp {fpp}: {searched} vs {closed}");
        }

        /// The phase term's multiplication is the division it replaced, to the bit.
        #[test]
        fn the_phase_rate_is_the_divisions(diff_q8 in prop_oneof![-400_000i64..400_000, -(1i64 << 50)..(1i64 << 50), any::<i64>()]) {
            let divided = diff_q8 as f64 * (1e15 / 256.0) / TCL_PHASE_TAU_NS as f64;
            prop_assert_eq!(phase_fpp(diff_q8).to_bits(), divided.to_bits());
        }
    }

    #[test]
    fn rounding_matches_the_library() {
        let mut xs = vec![0.0, -0.0, 0.5, -0.5, 1.5, -1.5, 2.5, 0.49999999999999994, -0.49999999999999994];
        xs.extend([4503599627370495.5, -4503599627370495.5, 1e300, -1e300, f64::INFINITY, f64::NEG_INFINITY, f64::NAN]);
        xs.extend((-20_000..20_000).map(|k| k as f64 * 0.25 + 1e-9 * k as f64));
        for x in xs {
            assert_eq!(round_half_away(x), x.round() as i64, "{x}");
        }
    }

    #[test]
    fn ticks_and_drift() {
        let dc = DcUnit::new(DcWidth::Bits64, 0, 0, 50_000);
        assert_eq!(dc.local_at(9), 0);
        assert_eq!(dc.local_at(10), 10);
        // 50 ppm fast: after 1 s the local clock is 50 µs ahead.
        assert_eq!(dc.local_at(1_000_000_000), 1_000_050_000);
        let slow = DcUnit::new(DcWidth::Bits64, 0, 0, -100_000);
        assert_eq!(slow.local_at(1_000_000_000), 999_900_000);
    }

    #[test]
    fn speed_counter_deviation_formula() {
        // esc-spec §3.2, 0x0932: Deviation = SCD / (5·(SCS+SCD+2)·(SCS−SCD+2)).
        for (scs, scd) in [(0x1000u16, 100i16), (0x1000, -2565), (0x0080, 1), (0x3FFF, 3000)] {
            let mut dc = DcUnit::new(DcWidth::Bits64, 0, 0, 0);
            dc.scs = scs;
            dc.set_scd(scd);
            let span = 10_000_000_000u64;
            let measured = dc.local_at(span) as f64 - span as f64;
            let (s, d) = (scs as f64, scd as f64);
            let expected = -(d / (5.0 * (s + d + 2.0) * (s - d + 2.0))) * span as f64;
            assert!(
                (measured - expected).abs() <= 11.0,
                "SCS {scs} SCD {scd}: {measured} ns vs {expected} ns over 10 s"
            );
        }
    }

    #[test]
    fn wrap_on_32_bit() {
        let mut dc = DcUnit::new(DcWidth::Bits32, 0, 0, 0);
        dc.offset = 0xFFFF_FFF0;
        assert_eq!(dc.system_at(100), 84);
    }

    #[test]
    fn the_64_bit_local_time_wraps_too() {
        // Powered on 5 µs before the 64-bit wrap: 10 µs later the counter reads 5 µs, to
        // within its 10 ns tick.
        let dc = DcUnit::new(DcWidth::Bits64, 0, u64::MAX - 4_999, 0);
        assert!((4_990..=5_000).contains(&dc.local_at(10_000)), "{}", dc.local_at(10_000));
        let dc32 = DcUnit::new(DcWidth::Bits32, 0, 0xFFFF_FFFF - 4_999, 0);
        assert!((4_990..=5_000).contains(&dc32.local_at(10_000)), "{}", dc32.local_at(10_000));
    }

    #[test]
    fn loop_locks_a_50ppm_clock_to_a_reference() {
        // Reference = true time; the slave runs 50 ppm fast, starts 3 µs ahead; samples every 1 ms.
        let mut dc = DcUnit::new(DcWidth::Bits64, 0, 3_000, 50_000);
        let mut worst_late = 0i64;
        for k in 1..=20_000u64 {
            let t = k * 1_000_000;
            dc.tcl_sample(t, t as u32);
            if k > 10_000 {
                worst_late = worst_late.max((dc.system_at(t) as i64 - t as i64).abs());
            }
        }
        assert!(worst_late <= 20, "error after lock {worst_late} ns, scd {}", dc.scd);
        assert!(dc.scd > 2000, "50 ppm needs a large SCD, got {}", dc.scd);
    }

    /// A slave 37 ppm fast, 3 µs ahead, fed 30 000 samples: sample k is taken at true time
    /// `at(k).0` and carries the reference's time `at(k).1`. Its mean error against true time
    /// at the samples after the first 10 000.
    fn mean_error_after_lock(at: impl Fn(u64) -> (u64, u64)) -> f64 {
        let mut dc = DcUnit::new(DcWidth::Bits64, 0, 3_000, 37_000);
        let (mut sum, mut n) = (0i64, 0i64);
        for k in 1..=30_000u64 {
            let (t, read) = at(k);
            dc.tcl_sample(t, read as u32);
            if k > 10_000 {
                sum += dc.system_at(t) as i64 - t as i64;
                n += 1;
            }
        }
        sum as f64 / n as f64
    }

    #[test]
    fn a_locked_loop_is_centred_on_the_reference() {
        // The mean error after lock, not only its bound: the 0x092C filter must not round its
        // way to a bias (on whole ns its shift's floor held the slave 7.5 ns ahead).
        let mean = mean_error_after_lock(|k| {
            let t = k * 1_000_000 + k % 7;
            (t, t)
        });
        assert!(mean.abs() < 1.5, "mean error after lock {mean:.2} ns");
    }

    #[test]
    fn late_frames_do_not_bias_the_loop() {
        // Every 50th sample 400 µs late, carrying what an offset-steered reference 90 ppm off
        // reads then: 36 ns more, and the next sample, on time, 36 ns less. The changes cancel
        // over the two spans; weighed per sample instead of per span, the short span's won and
        // held the clock 57 ns off (docs/esc-model.md).
        let mean = mean_error_after_lock(|k| {
            let late = k % 50 == 0;
            let t = k * 1_000_000 + if late { 400_000 } else { 0 };
            let read = match k % 50 {
                0 => t + 36,
                1 => t - 36,
                _ => t,
            };
            (t, read)
        });
        assert!(mean.abs() < 3.0, "mean error after lock {mean:.2} ns");
    }

    /// A 64-bit unit with a perfect crystal, SYNC0 activated at 0 to start at 1 µs.
    fn sync0_from_1us(cycle0_ns: u32) -> DcUnit {
        use ferrocat_wire::register::dc_activation as act;
        let mut dc = DcUnit::new(DcWidth::Bits64, 0, 0, 0);
        dc.sync.start_time = 1_000;
        dc.sync.cycle0_ns = cycle0_ns;
        dc.sync.activation = act::CYCLIC_OPERATION | act::SYNC0;
        dc.sync_activation_written(0);
        dc
    }

    #[test]
    fn sync0_single_shot_and_past_start() {
        use ferrocat_wire::register::dc_activation as act;
        let mut dc = sync0_from_1us(0);
        assert_eq!(dc.take_sync0_until(5_000), Some(Sync0Due { pulses: 1, last_sys_ns: 1_000 }));
        assert_eq!(dc.take_sync0_until(50_000), None);
        // A start time in the past never fires on 64 bit without the check, at once with it.
        dc.sync.start_time = 10;
        dc.sync_activation_written(60_000);
        assert_eq!(dc.take_sync0_until(70_000), None);
        dc.sync.activation |= act::START_TIME_CHECK;
        dc.sync_activation_written(80_000);
        assert_eq!(dc.take_sync0_until(80_000), Some(Sync0Due { pulses: 1, last_sys_ns: 80_000 }));
        assert_eq!(dc.sync.sync0_count, 2);
    }

    #[test]
    fn sync0_pulses_due_together_are_counted_not_listed() {
        let mut dc = sync0_from_1us(10);
        // An hour of 10 ns pulses in one step: 1_000, 1_010, … up to 3.6e12.
        let t = 3_600_000_000_000;
        let due = dc.take_sync0_until(t).expect("due");
        assert_eq!(due, Sync0Due { pulses: (t - 1_000) / 10 + 1, last_sys_ns: t });
        assert_eq!(dc.next_sync0_register(), t + 10);
        assert_eq!(dc.take_sync0_until(t + 9), None);
        assert_eq!(dc.take_sync0_until(t + 10).map(|d| d.pulses), Some(1));
    }
}
