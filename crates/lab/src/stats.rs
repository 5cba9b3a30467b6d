//! Running statistics of error samples.

/// Mean and RMS of a stream of samples, without keeping them.
#[derive(Debug, Clone, Copy, Default, PartialEq)]
pub struct Moments {
    pub n: u64,
    sum: f64,
    sum_sq: f64,
}

impl Moments {
    pub fn push(&mut self, x: f64) {
        self.n += 1;
        self.sum += x;
        self.sum_sq += x * x;
    }
    pub fn mean(&self) -> f64 {
        if self.n == 0 {
            f64::NAN
        } else {
            self.sum / self.n as f64
        }
    }
    pub fn rms(&self) -> f64 {
        if self.n == 0 {
            f64::NAN
        } else {
            (self.sum_sq / self.n as f64).sqrt()
        }
    }
}

/// The median of `v` (NaN when empty).
pub fn median(v: &[f64]) -> f64 {
    let mut s: Vec<f64> = v.iter().copied().filter(|x| !x.is_nan()).collect();
    if s.is_empty() {
        return f64::NAN;
    }
    s.sort_by(f64::total_cmp);
    let k = s.len() / 2;
    if s.len() % 2 == 1 {
        s[k]
    } else {
        (s[k - 1] + s[k]) / 2.0
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn moments_and_median() {
        let mut m = Moments::default();
        for x in [3.0, -4.0] {
            m.push(x);
        }
        assert_eq!(m.mean(), -0.5);
        assert_eq!(m.rms(), (12.5f64).sqrt());
        assert_eq!(median(&[5.0, 1.0, 3.0]), 3.0);
        assert_eq!(median(&[4.0, 1.0, 3.0, 2.0]), 2.5);
        assert!(median(&[]).is_nan());
    }
}

/// Points of a figure: (x, y). Debug output gives their number, not every point.
#[derive(Clone, Default, PartialEq)]
pub struct Trace(pub Vec<(f64, f64)>);

impl std::fmt::Debug for Trace {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        write!(f, "[{} points]", self.0.len())
    }
}

/// SYNC0 simultaneity from the slaves' pulse logs (Paprocki 2022, Table 2): the second slave
/// minus the first for the same system time, and the spread of all.
#[derive(Debug, Default)]
pub struct Sync0Stats {
    pub diffs: Moments,
    /// Every difference (ns), in order.
    pub values: Vec<i64>,
    min: i64,
    max: i64,
    spread_max: u64,
    last_sys: Option<u64>,
}

impl Sync0Stats {
    pub fn sample(&mut self, seg: &ferrocat_segment::Segment, drives: &[u16]) {
        let log = |d: u16| &seg.nodes[d as usize].esc.sync0_log.pulses;
        let Some(&(s1, t1)) = log(drives[0]).back() else { return };
        if self.last_sys == Some(s1) {
            return;
        }
        // 32-bit DCs compare on 32 bits.
        let ts: Vec<u64> = drives
            .iter()
            .filter_map(|&d| log(d).iter().rev().find(|(s, _)| *s as u32 == s1 as u32).map(|&(_, t)| t))
            .collect();
        if ts.len() != drives.len() {
            return;
        }
        self.last_sys = Some(s1);
        if let Some(&t2) = ts.get(1) {
            let d = t2 as i64 - t1 as i64;
            if self.diffs.n == 0 {
                (self.min, self.max) = (d, d);
            }
            self.diffs.push(d as f64);
            self.values.push(d);
            self.min = self.min.min(d);
            self.max = self.max.max(d);
        }
        let (lo, hi) = (ts.iter().min().copied().unwrap_or(0), ts.iter().max().copied().unwrap_or(0));
        self.spread_max = self.spread_max.max(hi - lo);
    }

    #[allow(clippy::type_complexity)]
    pub fn figures(&self) -> (Option<f64>, Option<f64>, Option<i64>, Option<i64>, Option<u64>) {
        if self.last_sys.is_none() {
            return (None, None, None, None, None);
        }
        let two = self.diffs.n > 0;
        let sd = (self.diffs.rms().powi(2) - self.diffs.mean().powi(2)).max(0.0).sqrt();
        (
            two.then(|| self.diffs.mean()),
            two.then_some(sd),
            two.then_some(self.min),
            two.then_some(self.max),
            Some(self.spread_max),
        )
    }
}
