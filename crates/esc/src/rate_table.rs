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

pub(crate) struct RateTable {
    pub scs: u16,
    /// The bound on |SCD|: SCS − 0x7F (esc-spec §3.5).
    pub max: i64,
    /// Indexed by `SCD + max`: (float rate, correction rate × 2³², rate in 10⁻¹⁵).
    entries: Box<[(f64, i64, i64)]>,
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
        let entries = (-max..=max)
            .map(|d| {
                let (q32, fpp) = exact_rates(scs, d);
                (float_rate(scs, d), q32, fpp)
            })
            .collect();
        let table = Arc::new(RateTable { scs, max, entries });
        if cache.len() == CACHED {
            cache.remove(0);
        }
        cache.push(table.clone());
        table
    }

    /// The entry of SCD `d`, if the bound allows it.
    #[inline]
    pub fn get(&self, d: i64) -> Option<&(f64, i64, i64)> {
        if d.abs() > self.max {
            return None;
        }
        self.entries.get((d + self.max) as usize)
    }
}
