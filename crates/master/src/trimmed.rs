//! A sliding window of values kept both in arrival order and sorted, so that its trimmed mean
//! costs a binary search, a move of at most the window and a sum per value instead of a sort.
use std::collections::VecDeque;

#[derive(Debug, Clone)]
pub struct TrimmedWindow {
    order: VecDeque<i64>,
    sorted: Vec<i64>,
    len: usize,
}

impl TrimmedWindow {
    /// A window of the last `len` values (at least 1); allocated once.
    pub fn new(len: usize) -> Self {
        let len = len.max(1);
        TrimmedWindow { order: VecDeque::with_capacity(len), sorted: Vec::with_capacity(len), len }
    }

    pub fn push(&mut self, v: i64) {
        if self.order.len() == self.len {
            if let Some(old) = self.order.pop_front() {
                if let Ok(i) = self.sorted.binary_search(&old) {
                    self.sorted.remove(i);
                }
            }
        }
        self.order.push_back(v);
        let i = self.sorted.partition_point(|&x| x < v);
        self.sorted.insert(i, v);
    }

    /// The mean of the middle three quarters (an eighth cut off each end); 0 when empty.
    pub fn trimmed_mean(&self) -> i64 {
        let n = self.sorted.len();
        let cut = n / 8;
        let kept = &self.sorted[cut..n - cut];
        (kept.iter().map(|&x| x as i128).sum::<i128>() / kept.len().max(1) as i128) as i64
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use proptest::prelude::*;

    proptest! {
        // The same as sorting the window's values and trimming, whatever they are.
        #[test]
        fn equals_the_sorted_trimmed_mean(values in proptest::collection::vec(any::<i64>(), 1..300), len in 1usize..70) {
            let mut w = TrimmedWindow::new(len);
            for (k, &v) in values.iter().enumerate() {
                w.push(v);
                let mut last: Vec<i64> = values[k.saturating_sub(len - 1)..=k].to_vec();
                last.sort_unstable();
                let cut = last.len() / 8;
                let kept = &last[cut..last.len() - cut];
                let mean = (kept.iter().map(|&x| x as i128).sum::<i128>() / kept.len() as i128) as i64;
                prop_assert_eq!(w.trimmed_mean(), mean);
            }
        }
    }

    #[test]
    fn an_eighth_is_cut_off_each_end() {
        let mut w = TrimmedWindow::new(8);
        for v in [1_000_000, 1, 2, 3, 4, 5, 6, -1_000_000] {
            w.push(v);
        }
        // Sorted: −1e6, 1 … 6, 1e6; one cut off each end: the mean of 1 … 6.
        assert_eq!(w.trimmed_mean(), 3);
        // The oldest (1e6) leaves: −1e6, 1 … 7, one cut off each end: the mean of 1 … 6.
        w.push(7);
        assert_eq!(w.trimmed_mean(), 3);
        // Then −1e6's turn comes (after 1 … 6): 7, 8 … 14, cut: 8 … 13.
        for v in 8..=14 {
            w.push(v);
        }
        assert_eq!(w.trimmed_mean(), 10);
    }
}
