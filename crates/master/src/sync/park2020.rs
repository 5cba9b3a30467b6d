//! Park et al. 2020 as published.
use super::{ClockSync, Correction, Coupling, Sample};

/// Park et al. 2020: compensated time sent (delay from eq. 3, averaged over many round trips
/// before cyclic operation), then every `period_ns` an EMA of the reference's 0x092C (eq. 4)
/// subtracted from every slave's offset (eq. 5).
#[derive(Debug)]
pub struct Park2020 {
    /// The master–reference delay of eq. 3, ns.
    pub delay_ns: i64,
    /// The EMA weight of eq. 4.
    pub alpha: f64,
    /// How often the bias is corrected, ns.
    pub period_ns: u64,
    ema_ns: Option<f64>,
    last_ns: Option<u64>,
}

impl Park2020 {
    /// Park 2020 with the delay `delay_ns` ([`Park2020::delay_from`]), α = 0.25, every 100 ms.
    pub fn new(delay_ns: i64) -> Self {
        Park2020 { delay_ns, alpha: 0.25, period_ns: 100_000_000, ema_ns: None, last_ns: None }
    }

    /// Eq. 3 over many round trips: (master round trip − reference's port 1 − port 0) / 2, averaged.
    pub fn delay_from(round_trips: &[(u64, u64)]) -> i64 {
        if round_trips.is_empty() {
            return 0;
        }
        let sum: i128 = round_trips.iter().map(|&(m, r)| (m as i128 - r as i128) / 2).sum();
        (sum / round_trips.len() as i128) as i64
    }
}

impl ClockSync for Park2020 {
    fn name(&self) -> &'static str {
        "park2020"
    }
    fn coupling(&self) -> Coupling {
        Coupling::ReferenceFollowsMaster
    }
    fn reference_time(&mut self, built_ns: u64) -> u64 {
        built_ns.wrapping_add_signed(self.delay_ns)
    }
    fn update(&mut self, s: Option<&Sample>) -> Correction {
        let Some(s) = s else { return Correction::default() };
        if self.last_ns.is_some_and(|l| s.built_ns.wrapping_sub(l) < self.period_ns) {
            return Correction::default();
        }
        self.last_ns = Some(s.built_ns);
        let d = s.difference_ns as f64;
        // Eq. 4, with ΔT⁰ = Δt⁰.
        let ema = match self.ema_ns {
            None => d,
            Some(e) => self.alpha * d + (1.0 - self.alpha) * e,
        };
        self.ema_ns = Some(ema);
        // Eq. 5: t_new_offset = t_offset − ΔT.
        Correction { shift_offsets_ns: -(ema.round() as i64), next_period_ns: None }
    }
}
