//! The reference following the master through its System_Time_Offset (0x0920): each frame
//! gives the reference the offset that puts its time on the master's half a cycle after the
//! frame's passage, the other slaves' offsets move with every step of it, and the followers'
//! delay registers carry a bias that centres them in the reference's sawtooth
//! (docs/clock-sync.md, "Reference follows master").
use super::estimator::Estimator;

/// The smallest change of the followers' delay bias worth a write (ns), and the shortest
/// line (in cycles of master time) whose rate it is taken from.
const DELAY_BIAS_STEP_NS: f64 = 4.0;
const DELAY_BIAS_MIN_SPAN_CYCLES: u64 = 32;

/// What steering the reference's offset keeps between frames.
#[derive(Debug, Default)]
pub(super) struct OffsetSteer {
    /// A calibration moves the reference at once by what it found, and so does the first
    /// offset it is given (from wherever the DC initialisation left it); every other slave's
    /// offset moves with it (the next correction), so that the followers' loops need not
    /// chase a step.
    pending_shift_ns: i64,
    /// The reference's offset the last frame read, and whether the method has replaced it yet.
    pub(super) offset_read: Option<u64>,
    offset_given: bool,
    /// The offset last given to the reference.
    offset_given_ns: Option<u64>,
    /// The bias last given to the followers' delay registers.
    delay_bias_ns: i64,
}

impl OffsetSteer {
    /// The estimate in use moved by `jump_ns` (a change of the line's window): the reference
    /// steps by as much at its next offset, and every follower with it (their loops would
    /// take milliseconds to chase a step of tens of ns, 100 ns on a stock kernel).
    pub(super) fn estimate_moved(&mut self, jump_ns: i64) {
        self.pending_shift_ns = self.pending_shift_ns.saturating_sub(jump_ns);
    }

    /// The master was found ahead by `error_ns`: the reference moves by as much, and the
    /// others with it.
    pub(super) fn master_moved(&mut self, error_ns: i64) {
        self.pending_shift_ns = self.pending_shift_ns.saturating_add(error_ns);
    }

    /// What the other slaves' offsets must move by now, leaving nothing pending.
    pub(super) fn take_shift(&mut self) -> i64 {
        std::mem::take(&mut self.pending_shift_ns)
    }

    /// The offset for the frame built at `built_ns`, which passes the reference `lead_ns`
    /// later and stands for `holds_ns` after (a cycle, `cycle_ns`, where `None`).
    pub(super) fn give(
        &mut self,
        built_ns: u64,
        holds_ns: Option<u64>,
        lead_ns: i64,
        cycle_ns: u64,
        line: &Estimator,
    ) -> Option<u64> {
        // Until the next frame gives it another offset the reference runs at its own crystal's
        // rate; aiming its time at the master's halfway through that span centres the
        // sawtooth (±|rate − 1|·span/2) on the master's time.
        let passage = built_ns.wrapping_add_signed(lead_ns);
        let aim = passage.wrapping_add(holds_ns.unwrap_or(cycle_ns) / 2);
        let offset = aim.wrapping_sub(line.at(aim)?);
        self.offset_given_ns = Some(offset);
        if !self.offset_given {
            let step = offset.wrapping_sub(self.offset_read?) as i64;
            self.pending_shift_ns = self.pending_shift_ns.saturating_add(step);
            self.offset_given = true;
        }
        Some(offset)
    }

    /// The reference's time at the master's `host_ns`, where an offset was given: it runs on
    /// its crystal from the instant it was aimed at, so its time is the line's local time plus
    /// the offset last given. Compared at the master's own time instead, a calibration took
    /// the sawtooth's value where its pulses fell for an error of the stamps (at 4 ms cycles
    /// up to ±75 ns; in the demo at 1 ms 17 ns, its whole mean error there).
    pub(super) fn belief_ns(&self, host_ns: u64, line: &Estimator) -> Option<u64> {
        let offset = self.offset_given_ns?;
        Some(line.at(host_ns).map_or(host_ns, |local| local.wrapping_add(offset)))
    }

    /// The bias every follower's delay register should carry from now on, where it changed
    /// enough to be worth a write.
    pub(super) fn follower_delay_bias_ns(&mut self, line: &Estimator, cycle_ns: u64) -> Option<i64> {
        // The followers' loops lock to the reference as the frame reads it, a cycle after its
        // last offset: (rate − 1)·cycle/2 above the master, the top of its sawtooth. A delay
        // register larger by b puts a follower b later (its loop compares the time received
        // with its own less the delay), so −(rate − 1)·cycle/2 centres them on the reference.
        let half_cycle = cycle_ns as f64 / 2.0;
        let bias = -(line.rate()? - 1.0) * half_cycle;
        // No crystal is 200 ppm off: a wilder rate is a young line's.
        let limit = half_cycle * 2e-4;
        let bias = bias.clamp(-limit, limit).round() as i64;
        // Each change is a step the followers' loops slew out: only one that stands out from
        // the rate's own uncertainty (3 σ) and the loops' 10 ns tick is worth it.
        // A line over a few cycles, dense with probes, can look certain of a rate it does not
        // know (on a live kernel such lines swung it by ±100 ppm): act on longer ones only.
        let fit = line.fit();
        if fit.span_ns() < DELAY_BIAS_MIN_SPAN_CYCLES * cycle_ns {
            return None;
        }
        let sd = fit.rate_sd()? * half_cycle;
        if ((bias - self.delay_bias_ns).abs() as f64) < (3.0 * sd).max(DELAY_BIAS_STEP_NS) {
            return None;
        }
        self.delay_bias_ns = bias;
        Some(bias)
    }
}
