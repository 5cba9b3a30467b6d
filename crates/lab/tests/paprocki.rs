//! The Paprocki 2022 experiment, shortened: two DC slaves see SYNC0 within tens of ns of each
//! other under every method, and the difference is measured, not assumed.
use ferrocat_lab::paprocki2022::{run, Options};
use ferrocat_master::io::HostModel;

#[test]
fn two_slaves_see_sync0_together() {
    let o = Options { settle_s: 1.0, samples: 300, ..Options::new(HostModel::pc_rt()) };
    let rows = run(&o).unwrap();
    assert_eq!(rows.len(), 8);
    for r in &rows {
        println!(
            "{:>4} µs {:12}: mean {:6.1} ns, max {:4}, min {:4}, sd {:4.1} ({} pulses)",
            r.cycle_us, r.method, r.mean_ns, r.max_ns, r.min_ns, r.sd_ns, r.samples
        );
        assert_eq!(r.samples, 300);
        assert!(r.mean_ns.abs() < 50.0 && r.max_ns - r.min_ns < 100 && r.sd_ns > 0.0, "{r:?}");
    }
}
