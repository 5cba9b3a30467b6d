//! The speed counter's rates for every SCD one SCS allows, computed once and shared by every DC
//! unit with that SCS: the time control loop's sample then needs no division to rank its
//! candidates or to apply the one it chose (the divisions were most of a sample's latency).
use std::sync::{Arc, Mutex};

const AS_PER_NS: i64 = 1_000_000_000;

/// Clock deviation of a speed-counter difference, as a fraction `num/den` (esc-spec §3.5);
/// `den > 0` for every SCD the bound allows.
fn scd_rate(scs: u16, scd: i64) -> (i64, i64) {
    let s = scs as i64;
    (scd, 5 * (s + scd + 2) * (s - scd + 2))
}

/// `a·scale/den` truncated, as i128 arithmetic gives it, without the i128 division: with
/// `a = q·den + r` both `q·scale` and `r·scale/den` have the sign of `a`, so truncating the sum
/// truncates the second term. Needs `|r|·scale` and `|q|·scale` within i64.
fn scaled_div(a: i64, scale: i64, den: i64) -> i64 {
    let (q, r) = (a / den, a % den);
    q * scale + r * scale / den
}

/// What one SCD does: the correction rate in attoseconds per ns × 2³², and the same in 10⁻¹⁵.
pub(crate) fn exact_rates(scs: u16, scd: i64) -> (i64, i64) {
    let (num, den) = scd_rate(scs, scd);
    // |num| < 2¹⁴ and den < 1.4·10⁹: every product below stays within i64.
    (scaled_div(AS_PER_NS * num, 1 << 32, den), scaled_div(AS_PER_NS * num, 1_000_000, den))
}

/// The rate of SCD `d` as a float, in the order of operations the loop ranks candidates by.
fn float_rate(scs: u16, d: i64) -> f64 {
    let (s, d) = (scs as f64, d as f64);
    d / (5.0 * (s + d + 2.0) * (s - d + 2.0))
}

/// One SCD's rate as the loop ranks it, and how far its neighbour's lies.
#[derive(Debug, Clone, Copy)]
pub(crate) struct Rank {
    /// The rate as a float, in the order of operations the loop ranks candidates by.
    pub rate: f64,
    /// 1 / (rate of SCD + 1 − this rate): how many SCD steps a difference of rate is, near here.
    inv_step: f64,
}

/// What one SCD applies: the correction rate in attoseconds per ns × 2³², and in 10⁻¹⁵.
#[derive(Debug, Clone, Copy)]
pub(crate) struct Applied {
    pub q32: i64,
    pub fpp: i64,
}

pub(crate) struct RateTable {
    pub scs: u16,
    /// The bound on |SCD|: SCS − 0x7F (esc-spec §3.5).
    pub max: i64,
    /// Both indexed by `SCD + max`; apart, so that the search's half stays in cache.
    ranks: Box<[Rank]>,
    applied: Box<[Applied]>,
}

impl std::fmt::Debug for RateTable {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        write!(f, "RateTable(scs {:#06x})", self.scs)
    }
}

/// Tables kept for reuse, the most recently built last; a master writing ever new SCS values
/// (masters write 0x0930 once, at start-up) makes every write build one.
const CACHED: usize = 8;
static CACHE: Mutex<Vec<Arc<RateTable>>> = Mutex::new(Vec::new());

impl RateTable {
    pub fn for_scs(scs: u16) -> Arc<RateTable> {
        let mut cache = CACHE.lock().unwrap_or_else(|poisoned| poisoned.into_inner());
        if let Some(t) = cache.iter().find(|t| t.scs == scs) {
            return t.clone();
        }
        let max = (scs as i64 - 0x7F).max(0);
        let ranks = (-max..=max)
            .map(|d| {
                // The last entry takes the step below it (none: a table of SCD 0 alone).
                let step = if d < max {
                    float_rate(scs, d + 1) - float_rate(scs, d)
                } else {
                    float_rate(scs, d) - float_rate(scs, d - 1)
                };
                let inv_step = if max == 0 { 0.0 } else { 1.0 / step };
                Rank { rate: float_rate(scs, d), inv_step }
            })
            .collect();
        let applied = (-max..=max)
            .map(|d| {
                let (q32, fpp) = exact_rates(scs, d);
                Applied { q32, fpp }
            })
            .collect();
        let table = Arc::new(RateTable { scs, max, ranks, applied });
        if cache.len() == CACHED {
            cache.remove(0);
        }
        cache.push(table.clone());
        table
    }

    /// What SCD `d` applies, if the bound allows it.
    #[inline]
    pub fn applied(&self, d: i64) -> Option<&Applied> {
        if d.abs() > self.max {
            return None;
        }
        self.applied.get((d + self.max) as usize)
    }

    /// How SCD `d` ranks, if the bound allows it.
    #[cfg(test)]
    pub fn rank(&self, d: i64) -> Option<&Rank> {
        if d.abs() > self.max {
            return None;
        }
        self.ranks.get((d + self.max) as usize)
    }

    /// How `d`, which lies within the bound, ranks.
    #[inline]
    fn at(&self, d: i64) -> &Rank {
        &self.ranks[(d + self.max) as usize]
    }

    /// The SCD whose rate is nearest `r`, searched from `from` (the SCD in use: the loop's
    /// command moves a few steps per sample), on an exact tie the lower. Newton steps on the
    /// table's local slopes, then a walk that brackets `r`: no division or square root (the
    /// closed form's were most of a sample's latency). `r` NaN gives `from`, clamped.
    pub fn nearest(&self, r: f64, from: i64) -> i64 {
        let max = self.max;
        let span = (2 * max + 1) as f64;
        let mut d = from.clamp(-max, max);
        // Rates rise with SCD and bend away from the line: a few steps land within one of r.
        for _ in 0..16 {
            let e = self.at(d);
            let steps = ((r - e.rate) * e.inv_step).clamp(-span, span);
            if steps.abs() < 1.0 || steps.is_nan() {
                break;
            }
            d = (d + steps as i64).clamp(-max, max);
        }
        while d > -max && self.at(d).rate > r {
            d -= 1;
        }
        while d < max && self.at(d + 1).rate <= r {
            d += 1;
        }
        // rate(d) ≤ r < rate(d + 1), or d at a bound.
        if d < max && (self.at(d + 1).rate - r).abs() < (self.at(d).rate - r).abs() {
            d + 1
        } else {
            d
        }
    }
}
