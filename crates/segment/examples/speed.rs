fn main() {
    for (n, cyc) in [(6usize, 1_000_000u64), (64, 1_000_000), (256, 100_000)] {
        let mut b = ferrocat_segment::bench::CyclicBench::new(n, cyc, 1);
        let t0 = std::time::Instant::now();
        let cycles = 20_000;
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
