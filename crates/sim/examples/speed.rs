//! Wall-clock speed of the benchmark workload; `speed N CYCLE_NS CYCLES` runs one size only
//! (for callgrind, whose instruction counts do not move with the machine's load).
fn main() {
    let args: Vec<u64> = std::env::args().skip(1).filter_map(|a| a.parse().ok()).collect();
    let sizes = match args[..] {
        [n, cyc, cycles] => vec![(n as usize, cyc, cycles)],
        _ => vec![(6usize, 1_000_000u64, 20_000u64), (64, 1_000_000, 20_000), (256, 100_000, 20_000)],
    };
    for (n, cyc, cycles) in sizes {
        let mut b = ferrocat_sim::bench::CyclicBench::new(n, cyc, 1).expect("the benchmark segment builds");
        let t0 = std::time::Instant::now();
        b.run(cycles);
        let wall = t0.elapsed().as_secs_f64();
        let sim = cycles as f64 * cyc as f64 * 1e-9;
        println!(
            "{n} slaves {} us: {:.1}x real time ({:.0} ns/cycle)",
            cyc / 1000,
            sim / wall,
            wall * 1e9 / cycles as f64
        );
    }
}
