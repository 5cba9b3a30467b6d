//! The Paprocki 2022 experiment, shortened: two DC slaves see SYNC0 within tens of ns of each
//! other under every method, and the difference is measured, not assumed.
use ferrocat_lab::paprocki2022::{run, Options};
use ferrocat_segment::HostModel;

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

#[test]
fn park2020s_offset_corrections_move_both_drives_at_once() {
    // Park's eq. 5 moves every slave's offset by the bias estimate every 100 ms; on pc-stock
    // that is up to µs. Written a slave per frame, a SYNC0 between the two drives' writes
    // would fire one correction apart: this run's minimum −2 195 ns (sd 86) that way.
    let o = Options { cycles_us: vec![500], methods: vec!["park2020".into()], ..Options::new(HostModel::pc_stock()) };
    let r = &run(&o).unwrap()[0];
    println!("mean {:.1} ns, max {}, min {}, sd {:.1}", r.mean_ns, r.max_ns, r.min_ns, r.sd_ns);
    assert!(r.max_ns - r.min_ns < 100 && r.sd_ns < 10.0, "{r:?}");
}

/// The paper's constant ≈ 0.8 µs against one candidate: its line (two drives on 100BASE-TX, the
/// first the reference) with the second drive's propagation delay left uncompensated. The drives
/// are the model's LAN9252 boards, whose 740 ns hop comes from a SOEM printout of two real ones;
/// the AX58100's own hop is not in our evidence. Compensated, the drives are together within
/// tens of ns; uncompensated, the second fires one hop late — 731 ns in this run, the paper's
/// 805.5 less 9 %.
#[test]
fn an_uncompensated_drive_delay_puts_the_second_drive_one_hop_late() {
    let path = concat!(env!("CARGO_MANIFEST_DIR"), "/../../scenarios/segments/paprocki2022-mii.toml");
    let segment = Some(ferrocat_segment::SegmentConfig::from_file(std::path::Path::new(path)).unwrap());
    let mut o = Options {
        cycles_us: vec![1000],
        methods: vec!["none".into()],
        settle_s: 2.0,
        samples: 300,
        segment,
        ..Options::new(HostModel::pc_rt())
    };
    let together = run(&o).unwrap().remove(0);
    o.drive_delay_compensated = false;
    let apart = run(&o).unwrap().remove(0);
    println!(
        "compensated {:.1} ns (sd {:.1}), uncompensated {:.1} ns (sd {:.1})",
        together.mean_ns, together.sd_ns, apart.mean_ns, apart.sd_ns
    );
    assert!(together.mean_ns.abs() < 30.0, "{together:?}");
    // One hop of two LAN9252 boards: 740 ns as SOEM measured it, within the 10 ns ticks.
    assert!((apart.mean_ns - 740.0).abs() < 40.0 && apart.sd_ns < 10.0, "{apart:?}");
}

#[test]
fn table_2_on_the_uncompensated_model_misses_only_the_1ms_spread() {
    use ferrocat_lab::paprocki2022::{compare, compared_method};
    use ferrocat_lab::scenario::{Plan, Scenario};
    let path = concat!(env!("CARGO_MANIFEST_DIR"), "/../../scenarios/paprocki2022-uncompensated.toml");
    let Plan::Paprocki2022(o) = Scenario::from_file(std::path::Path::new(path)).unwrap().plan(None, false).unwrap()
    else {
        panic!("not a paprocki2022 scenario")
    };
    let rows = run(&o).unwrap();
    assert_eq!(compared_method(&rows), Some("none"));
    let figures = compare(&rows, "none");
    for f in &figures {
        println!("{}", f.line());
    }
    assert_eq!(figures.len(), 8);
    let misses = ferrocat_lab::fit::misses(&figures);
    // The model's SYNC0 difference is steadier than the paper's at 1 ms (3.0 against 4.6 ns).
    assert_eq!(misses, ["1000 µs, sd"]);
    let sd = figures.iter().find(|f| f.name == "1000 µs, sd").unwrap();
    assert!(sd.model < sd.paper, "{sd:?}");
}
