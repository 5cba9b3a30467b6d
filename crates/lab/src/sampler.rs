//! When the lab looks at the clocks. Park 2020 (§IV-B) triggers its measurements from a free
//! function generator, whose edges fall at any phase of the master's cycle; so does the lab:
//! each sample is taken at an instant drawn uniformly over its cycle from a stream of the
//! lab's own (the same instants for every method of a table). A clock steered once per frame
//! runs at its crystal's rate in between, so looking right after each frame would see only
//! one point of that sawtooth. The segment fills in the slaves' true times at the instant
//! exactly, however that cycle's frames fall around it (`Segment::watch`).
use crate::World;
use std::collections::VecDeque;

use ferrocat_master::sync::ClockSync;
use ferrocat_master::Master;
use ferrocat_segment::VirtualIo;
use rand::{Rng, SeedableRng};
use rand_chacha::ChaCha8Rng;

/// Samples of the master − slave error of the DC slaves at `positions`.
#[derive(Debug)]
pub struct Sampler {
    rng: ChaCha8Rng,
    /// The segment node of each position (None: not found; its error reads 0).
    nodes: Vec<Option<usize>>,
    /// Each armed sample, oldest first: its tag, instant and the master's clock then (low 32
    /// bits), known once the cycle that armed it is over.
    armed: VecDeque<(u64, u64, Option<u32>)>,
}

/// One sample: its tag and instant, and master − slave (ns, Park's sign) for each position.
#[derive(Debug, Clone, PartialEq)]
pub struct Sample {
    pub tag: u64,
    pub at_ns: u64,
    pub errors_ns: Vec<i64>,
}

impl Sampler {
    pub fn new<I: World>(m: &Master<I>, positions: &[usize], seed: u64) -> Self {
        Sampler {
            rng: ChaCha8Rng::seed_from_u64(seed ^ 0x5A3F_1E00),
            nodes: positions.iter().map(|&k| crate::node_of(m, k)).collect(),
            armed: VecDeque::new(),
        }
    }

    /// Arms sample `tag` at an instant drawn uniformly over `[start_ns, start_ns + span_ns)`.
    pub fn arm(&mut self, m: &mut Master<VirtualIo>, start_ns: u64, span_ns: u64, tag: u64) {
        let at = start_ns + self.rng.gen_range(0..span_ns.max(1));
        m.cyclic().io_mut().seg.watch(at);
        self.armed.push_back((tag, at, None));
    }

    /// Called after each cycle: the samples whose instants every slave's clock has passed,
    /// oldest first.
    pub fn after_cycle(&mut self, m: &mut Master<VirtualIo>, sync: &dyn ClockSync) -> Vec<Sample> {
        // The master's clock at each instant armed this cycle, as the method stands after the
        // cycle: where the master follows the reference, the estimate it keeps of the
        // reference's time (a line that later points would move only in hindsight).
        for (_, at, master) in self.armed.iter_mut().filter(|a| a.2.is_none()) {
            *master = Some(master_at(m, sync, *at));
        }
        let mut out = Vec::new();
        while let Some(w) = m.cyclic().io_mut().seg.watched() {
            out.extend(self.sample(m, sync, w));
        }
        out
    }

    /// Every sample still armed, read from the clocks as they stand (the end of a run).
    pub fn rest(&mut self, m: &mut Master<VirtualIo>, sync: &dyn ClockSync) -> Vec<Sample> {
        let mut out = self.after_cycle(m, sync);
        while let Some(w) = m.cyclic().io_mut().seg.watched_now() {
            out.extend(self.sample(m, sync, w));
        }
        out
    }

    /// The sample of watch `w`, the oldest armed (None: a watch the sampler did not arm).
    fn sample(
        &mut self,
        m: &mut Master<VirtualIo>,
        sync: &dyn ClockSync,
        w: ferrocat_segment::Watch,
    ) -> Option<Sample> {
        let (tag, at, master) = self.armed.pop_front()?;
        debug_assert_eq!(at, w.at_ns);
        let master = master.unwrap_or_else(|| master_at(m, sync, at));
        let errors_ns = self
            .nodes
            .iter()
            .map(|node| {
                let slave = node.and_then(|n| w.system_ns.get(n).copied().flatten()).map_or(master, |s| s as u32);
                // On the low 32 bits, so that 32-bit DCs compare too.
                master.wrapping_sub(slave) as i32 as i64
            })
            .collect();
        Some(Sample { tag, at_ns: w.at_ns, errors_ns })
    }
}

/// The master's clock at true time `at_ns` (low 32 bits): its own, or where it follows the
/// reference, the method's estimate of the reference's time.
fn master_at(m: &mut Master<VirtualIo>, sync: &dyn ClockSync, at_ns: u64) -> u32 {
    let own = m.clock().master_system_time_at(at_ns);
    sync.master_time(own).unwrap_or(own) as u32
}

/// Whether the segment is locked as the lock time counts it: every DC slave within 100 ns of
/// the reference and the master within 1 µs of it; `errors_ns` as a [`Sample`] has them, the
/// reference first.
pub fn locked(errors_ns: &[i64]) -> bool {
    let Some((&e_ref, followers)) = errors_ns.split_first() else { return true };
    followers.iter().all(|e| (e - e_ref).abs() <= 100) && e_ref.abs() <= 1_000
}
