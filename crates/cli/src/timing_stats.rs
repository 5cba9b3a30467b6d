//! The real-time loop's quality as cyclictest reports it: how late each wake-up came and how
//! far each period strayed from the nominal, as a histogram with percentiles.
use serde_json::{json, Value};

/// 1 µs buckets up to 1 ms, 10 µs buckets up to 10 ms, then one for everything beyond.
const FINE: usize = 1_000;
const COARSE: usize = 900;

/// A histogram of durations in ns, with the exact minimum and maximum.
#[derive(Debug, Clone)]
pub struct Histogram {
    counts: Vec<u64>,
    n: u64,
    min_ns: u64,
    max_ns: u64,
}

impl Default for Histogram {
    fn default() -> Self {
        Histogram { counts: vec![0; FINE + COARSE + 1], n: 0, min_ns: u64::MAX, max_ns: 0 }
    }
}

impl Histogram {
    /// Counts one duration.
    pub fn add(&mut self, ns: u64) {
        let us = (ns / 1_000) as usize;
        let k = if us < FINE { us } else { (FINE + (us - FINE) / 10).min(FINE + COARSE) };
        self.counts[k] += 1;
        self.n += 1;
        self.min_ns = self.min_ns.min(ns);
        self.max_ns = self.max_ns.max(ns);
    }

    /// The smallest duration counted, µs.
    pub fn min_us(&self) -> Option<f64> {
        (self.n > 0).then(|| self.min_ns as f64 / 1e3)
    }

    /// The largest duration counted, µs.
    pub fn max_us(&self) -> Option<f64> {
        (self.n > 0).then(|| self.max_ns as f64 / 1e3)
    }

    /// The lower edge of bucket `k`, µs.
    fn lower_us(k: usize) -> u64 {
        if k < FINE {
            k as u64
        } else {
            (FINE + (k - FINE) * 10) as u64
        }
    }

    /// The `q` quantile (0–1), µs: the upper edge of the bucket it falls in (the maximum for
    /// the last); `None` with nothing counted.
    pub fn quantile_us(&self, q: f64) -> Option<f64> {
        if self.n == 0 {
            return None;
        }
        let rank = ((q * self.n as f64).ceil() as u64).clamp(1, self.n);
        let mut seen = 0;
        for (k, &c) in self.counts.iter().enumerate() {
            seen += c;
            if seen >= rank {
                let upper = if k + 1 < self.counts.len() { Self::lower_us(k + 1) as f64 } else { f64::INFINITY };
                return Some(upper.min(self.max_ns as f64 / 1e3));
            }
        }
        Some(self.max_ns as f64 / 1e3)
    }

    /// "p50 a, p99 b, max c µs".
    pub fn summary(&self) -> String {
        match (self.quantile_us(0.5), self.quantile_us(0.99)) {
            (Some(p50), Some(p99)) => {
                format!("p50 {p50:.0} µs, p99 {p99:.0} µs, max {:.1} µs", self.max_ns as f64 / 1e3)
            }
            _ => "none measured".into(),
        }
    }

    /// Percentiles and the non-empty buckets (`[lower_us, count]`) for `--json`.
    pub fn to_json(&self) -> Value {
        let buckets: Vec<Value> = self
            .counts
            .iter()
            .enumerate()
            .filter(|(_, &c)| c > 0)
            .map(|(k, &c)| json!([Self::lower_us(k), c]))
            .collect();
        json!({
            "count": self.n,
            "p50_us": self.quantile_us(0.5),
            "p99_us": self.quantile_us(0.99),
            "min_us": (self.n > 0).then(|| self.min_ns as f64 / 1e3),
            "max_us": (self.n > 0).then(|| self.max_ns as f64 / 1e3),
            "histogram": buckets,
        })
    }
}

#[cfg(test)]
mod tests {
    use super::Histogram;

    #[test]
    fn percentiles_come_from_the_buckets_and_the_maximum_is_exact() {
        let mut h = Histogram::default();
        assert_eq!(h.quantile_us(0.5), None);
        for k in 0..100u64 {
            h.add(k * 1_000 + 500); // 0.5, 1.5, … 99.5 µs
        }
        h.add(4_321_000); // one wake-up 4.3 ms late
        assert_eq!(h.quantile_us(0.5), Some(51.0));
        assert_eq!(h.quantile_us(0.99), Some(100.0));
        assert_eq!(h.quantile_us(1.0), Some(4_321.0));
        assert_eq!(h.to_json()["count"], 101);
        assert_eq!(h.min_us(), Some(0.5));
        assert_eq!(h.to_json()["histogram"][100], serde_json::json!([4_320, 1]));
        // Beyond 10 ms: the last bucket, the maximum exact.
        h.add(60_000_000_000);
        assert_eq!(h.quantile_us(1.0), Some(60_000_000.0));
    }
}
