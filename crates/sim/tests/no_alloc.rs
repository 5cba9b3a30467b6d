//! The cyclic frame's path through the virtual segment allocates nothing: the benchmark
//! workload (a line of terminals in OP, one LRW + FRMW frame per cycle) runs its cycles with
//! a counting allocator in place, after a warm-up that lets buffers reach their size.
use ferrocat_testdata::{allocations, CountingAllocator};

#[global_allocator]
static GLOBAL: CountingAllocator = CountingAllocator;

#[test]
fn the_cyclic_frame_allocates_nothing() {
    for (slaves, cycle_ns) in [(6, 1_000_000), (64, 1_000_000), (256, 100_000)] {
        let mut b = ferrocat_sim::bench::CyclicBench::new(slaves, cycle_ns, 1).expect("the benchmark segment builds");
        b.run(2_000);
        let before = allocations();
        b.run(5_000);
        let during = allocations() - before;
        assert_eq!(b.lost, 0);
        assert_eq!(during, 0, "{slaves} slaves: {during} allocations in 5 000 cycles");
    }
}
