//! The demo's measurements are real: with ferrocat's clock sync on a real-time host the drives'
//! SYNC0 instants agree within 100 ns and no set-point is late or repeated at 1 ms and 250 µs;
//! on a stock kernel's host model at 250 µs the same counters are not zero.
use ferrocat_lab::demo::{run, Options};
use ferrocat_master::io::HostModel;

#[test]
fn ferrocat_keeps_the_drives_together_and_a_stock_host_shows_late_setpoints() {
    let o = Options { methods: vec!["ferrocat".into(), "conventional".into()], ..Options::new(HostModel::pc_rt()) };
    let rows = run(&o).unwrap();
    assert_eq!(rows.len(), 4);
    for r in &rows {
        println!(
            "{} µs {:12}: SYNC0 spread max {:?} ns, late {:?}, repeated {:?}, max FE {:?}, enabled {}/{}",
            r.cycle_us,
            r.method,
            r.sync0_spread_max_ns,
            r.late_setpoints,
            r.repeated_setpoints,
            r.max_following_error,
            r.drives_enabled,
            r.drives
        );
        assert_eq!(r.drives_enabled, 2, "{r:?}");
        assert!(r.cycles > 0 && r.trace.len() > 100);
        let (mean, max) = (r.processing_mean_us.unwrap(), r.processing_max_us.unwrap());
        assert!(mean > 20.0 && max < 150.0, "{r:?}");
    }
    for r in rows.iter().filter(|r| r.method == "ferrocat") {
        assert!(r.sync0_spread_max_ns.unwrap() <= 100, "{r:?}");
        assert_eq!((r.late_setpoints, r.repeated_setpoints), (Some(0), Some(0)), "{r:?}");
        // A tenth of a revolution would be a poor servo; the model follows within ~0.2 %.
        assert!(r.max_following_error.unwrap() < 1000.0, "{r:?}");
    }
    let stock = Options {
        methods: vec!["ferrocat".into()],
        cycles_us: vec![250],
        ..Options::new(HostModel::preset("pc-stock").unwrap())
    };
    let r = &run(&stock).unwrap()[0];
    println!("pc-stock 250 µs ferrocat: late {:?}, repeated {:?}", r.late_setpoints, r.repeated_setpoints);
    assert!(r.late_setpoints.unwrap() > 0 && r.repeated_setpoints.unwrap() > 0, "{r:?}");
    assert!(!r.late_cycles.is_empty() && !r.repeated_cycles.is_empty());
}
