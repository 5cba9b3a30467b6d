//! Virtual-time speed of the segment: one LRW + FRMW frame per cycle.
use criterion::{criterion_group, criterion_main, Criterion, Throughput};
use ferrocat_sim::bench::{CyclicBench, TclBench};

fn cyclic(c: &mut Criterion) {
    let mut g = c.benchmark_group("virtual_time");
    for (slaves, cycle_us) in [(6usize, 1000u64), (64, 1000), (256, 100)] {
        let mut b = CyclicBench::new(slaves, cycle_us * 1000, 1).expect("the benchmark segment builds");
        g.throughput(Throughput::Elements(1000));
        g.bench_function(format!("{slaves} slaves, {cycle_us} us cycle, 1000 cycles"), |bench| {
            bench.iter(|| b.run(1000))
        });
    }
    g.finish();
    let mut g = c.benchmark_group("tcl_sample");
    let mut b = TclBench::new(256, 100_000);
    g.throughput(Throughput::Elements(256 * 100));
    g.bench_function("256 units, 100 cycles", |bench| bench.iter(|| b.run(100)));
    g.finish();
}

criterion_group!(benches, cyclic);
criterion_main!(benches);
