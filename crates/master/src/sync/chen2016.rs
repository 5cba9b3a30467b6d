//! Chen et al. 2016 as published.
use super::{ClockSync, Correction, Coupling, Sample, MAX_CYCLE_NS};

/// Chen et al. 2016: the master's period rescaled by the reference's speed (eqs. 3–5, the
/// average of `n` timestamp differences), rounded to the timer's resolution with the
/// truncation error carried over (Algorithm 1).
#[derive(Debug)]
pub struct Chen2016 {
    /// The nominal cycle, ns.
    pub nominal_ns: u64,
    /// Timestamp differences per speed update.
    pub n: u32,
    /// The host timer's resolution, ns.
    pub resolution_ns: u64,
    ideal_ns: f64,
    prev: Option<(u64, u64)>,
    sum_ns: f64,
    count: u32,
    truncation_ns: f64,
}

impl Chen2016 {
    /// Chen 2016 on a cycle of `nominal_ns`, `n` differences per update, a timer of `resolution_ns`.
    pub fn new(nominal_ns: u64, n: u32, resolution_ns: u64) -> Self {
        let nominal_ns = nominal_ns.clamp(1, MAX_CYCLE_NS);
        Chen2016 {
            nominal_ns,
            n: n.max(1),
            resolution_ns: resolution_ns.clamp(1, MAX_CYCLE_NS),
            ideal_ns: nominal_ns as f64,
            prev: None,
            sum_ns: 0.0,
            count: 0,
            truncation_ns: 0.0,
        }
    }

    /// Algorithm 1: round the ideal period down to the resolution, accumulate what was cut
    /// off, and add one resolution step whenever the accumulated error exceeds it.
    pub fn truncate(&mut self, ideal_ns: f64) -> u64 {
        let res = self.resolution_ns as f64;
        let mut rounded = (ideal_ns / res).floor() * res;
        self.truncation_ns += ideal_ns - rounded;
        if self.truncation_ns > res {
            rounded += res;
            self.truncation_ns -= res;
        }
        rounded.max(res) as u64
    }
}

impl ClockSync for Chen2016 {
    fn name(&self) -> &'static str {
        "chen2016"
    }
    fn coupling(&self) -> Coupling {
        Coupling::MasterFollowsReference
    }
    fn update(&mut self, s: Option<&Sample>) -> Correction {
        if let Some(s) = s {
            if let Some((c0, t0)) = self.prev {
                let cycles = s.cycle.saturating_sub(c0).max(1);
                // ΔT_k, per master cycle even across a lost frame.
                self.sum_ns += s.reference_ns.wrapping_sub(t0) as i64 as f64 / cycles as f64;
                self.count += 1;
            }
            self.prev = Some((s.cycle, s.reference_ns));
            if self.count >= self.n {
                let t_ref_test = self.sum_ns / self.count as f64;
                if t_ref_test > 0.0 {
                    // Eq. 5: T_cycle_m(k+1) = T_cycle_ref / T_ref_test · T_cycle_m(k).
                    self.ideal_ns *= self.nominal_ns as f64 / t_ref_test;
                }
                self.sum_ns = 0.0;
                self.count = 0;
            }
        }
        let ideal = self.ideal_ns;
        Correction { shift_offsets_ns: 0, next_period_ns: Some(self.truncate(ideal)) }
    }
}
