//! Which of a split ring's two-pass samples the far reference's estimator takes: those whose
//! passes took not much longer than the path needs.
//!
//! A sample times each pass by the mid-point of its transmit and receive stamps, which is
//! where the frame met the clocks only if the pass's latency was split evenly between the way
//! out and the way back. A pass that took longer than the path needs spent the excess
//! somewhere, and up to half of it is how far its mid-point may be off: a host that wakes the
//! receiver late on one pass and not on the other gives samples off by tens of µs, and a while
//! of them moves the far half that far. The path's need is the floor: the least that both
//! passes together took over the last [`FLOOR_BLOCKS`] × [`BLOCK`] samples (NTP's clock
//! filter trusts the sample of least delay most, RFC 5905 §10). A sample whose passes took
//! more than twice the floor plus [`FLOOR_SLACK_NS`] is not taken: while the host wakes late,
//! the estimator gets no samples rather than samples off by half the lateness. The others are
//! all taken, not only the quickest: where the way out scatters more than the way back, the
//! quickest are those whose way out was quickest, and their mid-points lean one way (measured:
//! taking the best of every eight left a far coupler 105 ns off under nic-hwts, against 20 ns).
//! A host that stays slow raises the floor within [`FLOOR_BLOCKS`] blocks, and its samples
//! are taken again.
use crate::engine::SplitPasses;

/// Samples whose least is kept as one of the floor's blocks.
const BLOCK: u32 = 8;
/// Blocks whose least is the floor (about 2 s at 1 ms cycles).
const FLOOR_BLOCKS: usize = 256;
/// What a sample's passes may exceed twice the floor by (ns): the stamps' own scatter on a
/// path as short as a few µs.
const FLOOR_SLACK_NS: u64 = 10_000;

/// The filter: the least of the block so far, the last blocks' least and their least, and the
/// samples taken and left out.
#[derive(Debug, Clone)]
pub(crate) struct PassFilter {
    block_min_ns: u64,
    seen: u32,
    blocks: Vec<u64>,
    next: usize,
    blocks_min_ns: u64,
    taken: u64,
    left_out: u64,
}

impl PassFilter {
    pub(crate) fn new() -> Self {
        PassFilter {
            block_min_ns: u64::MAX,
            seen: 0,
            blocks: Vec::with_capacity(FLOOR_BLOCKS),
            next: 0,
            blocks_min_ns: u64::MAX,
            taken: 0,
            left_out: 0,
        }
    }

    /// Both passes' round trips together (ns).
    fn took_ns(p: &SplitPasses) -> u64 {
        p.near_rx_ns.saturating_sub(p.near_tx_ns).saturating_add(p.far_rx_ns.saturating_sub(p.far_tx_ns))
    }

    /// Whether the estimator takes the sample `p`.
    pub(crate) fn admits(&mut self, p: &SplitPasses) -> bool {
        let took = Self::took_ns(p);
        self.block_min_ns = self.block_min_ns.min(took);
        let floor = self.block_min_ns.min(self.blocks_min_ns);
        self.seen += 1;
        if self.seen == BLOCK {
            if self.blocks.len() < FLOOR_BLOCKS {
                self.blocks.push(self.block_min_ns);
            } else {
                self.blocks[self.next] = self.block_min_ns;
            }
            self.next = (self.next + 1) % FLOOR_BLOCKS;
            self.blocks_min_ns = self.blocks.iter().copied().min().unwrap_or(u64::MAX);
            (self.seen, self.block_min_ns) = (0, u64::MAX);
        }
        let admitted = took <= floor.saturating_mul(2).saturating_add(FLOOR_SLACK_NS);
        self.taken += admitted as u64;
        self.left_out += !admitted as u64;
        admitted
    }

    /// The samples taken and those left out so far.
    pub(crate) fn counts(&self) -> (u64, u64) {
        (self.taken, self.left_out)
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// Passes sent at `at_ns`, each taking `near_ns` and `far_ns`.
    fn passes(at_ns: u64, near_ns: u64, far_ns: u64) -> SplitPasses {
        SplitPasses {
            near_tx_ns: at_ns,
            near_rx_ns: at_ns + near_ns,
            far_tx_ns: at_ns + near_ns + 5_000,
            far_rx_ns: at_ns + near_ns + 5_000 + far_ns,
            near_time: 0,
            far_time: 0,
            len: 8,
            far_wkc: 1,
        }
    }

    #[test]
    fn samples_near_the_floor_are_all_taken_and_one_far_beyond_it_is_not() {
        let mut f = PassFilter::new();
        let trips = [40_000, 35_000, 90_000, 30_000, 31_000, 60_000, 45_000, 50_000, 80_000, 71_000];
        let taken: Vec<_> =
            trips.iter().enumerate().map(|(k, &t)| f.admits(&passes(k as u64 * 1_000_000, t, t))).collect();
        // Both passes together: 180 µs is over 2 × 70 µs + 10 µs; once the floor is 60 µs,
        // 160 and 142 µs are over 130 µs.
        assert_eq!(taken, [true, true, false, true, true, true, true, true, false, false]);
        assert_eq!(f.counts(), (7, 3));
    }

    #[test]
    fn a_while_of_late_wake_ups_gives_no_samples_and_a_host_that_stays_slow_is_followed() {
        let mut f = PassFilter::new();
        let mut k = 0u64;
        let mut run = |f: &mut PassFilter, blocks: u64, near_ns: u64| {
            let mut given = 0;
            for _ in 0..blocks * BLOCK as u64 {
                given += f.admits(&passes(k * 1_000_000, near_ns, 30_000)) as u64;
                k += 1;
            }
            given
        };
        let per_block = BLOCK as u64;
        assert_eq!(run(&mut f, 100, 30_000), 100 * per_block);
        // Every near pass 200 µs late: none taken (each would be up to 100 µs off).
        assert_eq!(run(&mut f, 100, 230_000), 0);
        assert_eq!(run(&mut f, 10, 30_000), 10 * per_block);
        // Late for good: once the quick blocks have left the floor's memory, taken again.
        let late = run(&mut f, 2 * FLOOR_BLOCKS as u64, 230_000);
        assert_eq!(late, FLOOR_BLOCKS as u64 * per_block, "{late}");
    }
}
