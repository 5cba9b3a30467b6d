//! The cyclic frame's path through the virtual segment allocates nothing: the benchmark
//! workload (a line of terminals in OP, one LRW + FRMW frame per cycle) runs its cycles with
//! a counting allocator in place, after a warm-up that lets buffers reach their size.
use std::alloc::{GlobalAlloc, Layout, System};
use std::sync::atomic::{AtomicU64, Ordering};

struct Counting;

static ALLOCATIONS: AtomicU64 = AtomicU64::new(0);

// SAFETY: every call is forwarded to the system allocator unchanged; only counted.
unsafe impl GlobalAlloc for Counting {
    unsafe fn alloc(&self, layout: Layout) -> *mut u8 {
        ALLOCATIONS.fetch_add(1, Ordering::Relaxed);
        // SAFETY: the caller's contract is the system allocator's.
        unsafe { System.alloc(layout) }
    }
    unsafe fn dealloc(&self, ptr: *mut u8, layout: Layout) {
        // SAFETY: as above.
        unsafe { System.dealloc(ptr, layout) }
    }
    unsafe fn realloc(&self, ptr: *mut u8, layout: Layout, new_size: usize) -> *mut u8 {
        ALLOCATIONS.fetch_add(1, Ordering::Relaxed);
        // SAFETY: as above.
        unsafe { System.realloc(ptr, layout, new_size) }
    }
}

#[global_allocator]
static GLOBAL: Counting = Counting;

#[test]
fn the_cyclic_frame_allocates_nothing() {
    for (slaves, cycle_ns) in [(6, 1_000_000), (64, 1_000_000), (256, 100_000)] {
        let mut b = ferrocat_sim::bench::CyclicBench::new(slaves, cycle_ns, 1).expect("the benchmark segment builds");
        b.run(2_000);
        let before = ALLOCATIONS.load(Ordering::Relaxed);
        b.run(5_000);
        let during = ALLOCATIONS.load(Ordering::Relaxed) - before;
        assert_eq!(b.lost, 0);
        assert_eq!(during, 0, "{slaves} slaves: {during} allocations in 5 000 cycles");
    }
}
