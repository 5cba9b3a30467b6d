//! The PI loop of SOEM's examples.
use super::{ClockSync, Correction, Coupling, Sample, MAX_CYCLE_NS};

/// The PI loop of SOEM's examples: the reference's time modulo the cycle, minus a shift, is
/// the phase error; the next period is the cycle minus error/100 minus the error sign's
/// running sum/20.
#[derive(Debug)]
pub struct SoemPi {
    /// The cycle, ns.
    pub cycle_ns: u64,
    /// Where in the reference's cycle the master aims, ns.
    pub shift_ns: i64,
    integral: i64,
}

impl SoemPi {
    /// SOEM's loop on a cycle of `cycle_ns`, aiming `shift_ns` into the reference's cycle.
    pub fn new(cycle_ns: u64, shift_ns: i64) -> Self {
        SoemPi { cycle_ns: cycle_ns.clamp(2, MAX_CYCLE_NS), shift_ns, integral: 0 }
    }
}

impl SoemPi {
    /// The reference's time modulo the cycle less the shift, in (−cycle/2, cycle/2].
    fn phase_error_ns(&self, s: &Sample) -> i64 {
        let c = self.cycle_ns as i64;
        let delta = (s.reference_ns.wrapping_sub(self.shift_ns as u64) % self.cycle_ns) as i64;
        if delta > c / 2 {
            delta - c
        } else {
            delta
        }
    }
}

impl ClockSync for SoemPi {
    fn name(&self) -> &'static str {
        "pi"
    }
    fn coupling(&self) -> Coupling {
        Coupling::MasterFollowsReference
    }
    /// The phase error the loop works on: where in the reference's cycle the frame passed it,
    /// less the aimed shift.
    fn offset_ns(&self, s: &Sample) -> Option<i64> {
        Some(self.phase_error_ns(s))
    }
    fn update(&mut self, s: Option<&Sample>) -> Correction {
        let c = self.cycle_ns as i64;
        let Some(s) = s else { return Correction { shift_offsets_ns: 0, next_period_ns: Some(self.cycle_ns) } };
        let delta = self.phase_error_ns(s);
        self.integral = self.integral.saturating_add(delta.signum());
        let period = c.saturating_sub(delta / 100).saturating_sub(self.integral / 20);
        Correction { shift_offsets_ns: 0, next_period_ns: Some(period.max(1) as u64) }
    }
}
