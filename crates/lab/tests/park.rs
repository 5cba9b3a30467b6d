//! The Park 2020 experiment, shortened, under the host models: the comparison the issue asks
//! for, on one seed for every method (paired).
use ferrocat_lab::park2020::{run, Options, Row};
use ferrocat_segment::HostModel;

fn table(host: HostModel) -> Vec<Row> {
    let o = Options { rounds: 2, settle_s: 2.0, samples: 2_000, ..Options::quick(host) };
    let rows = run(&o, &|_, _| {}).unwrap();
    for r in &rows {
        println!(
            "{:13} {} slaves {:13}: ref GMEAN {:7.3} MRMS {:7.3}  last GMEAN {:7.3} MRMS {:7.3} µs  lock {:?}",
            r.host, r.slaves, r.method, r.ref_gmean_us, r.ref_mrms_us, r.last_gmean_us, r.last_mrms_us, r.lock_ms
        );
    }
    rows
}

fn row<'a>(rows: &'a [Row], slaves: usize, method: &str) -> &'a Row {
    rows.iter().find(|r| r.slaves == slaves && r.method == method).unwrap()
}

#[test]
fn beaglebone_reproduces_the_conventional_bias_and_ferrocat_beats_park() {
    let rows = table(HostModel::beaglebone_rt());
    for n in [2, 6] {
        let (c, p, f) = (row(&rows, n, "conventional"), row(&rows, n, "park2020"), row(&rows, n, "ferrocat"));
        // Park's conventional GMEAN: 10.58 µs (2 slaves), 11.67 µs (6); within ±20 %.
        let paper = if n == 2 { 10.58 } else { 11.67 };
        assert!((c.ref_gmean_us - paper).abs() <= 0.2 * paper, "{n}: {}", c.ref_gmean_us);
        assert!(p.ref_gmean_us.abs() < c.ref_gmean_us.abs() && p.ref_mrms_us < c.ref_mrms_us);
        assert!(f.ref_gmean_us.abs() < p.ref_gmean_us.abs() && f.ref_mrms_us < p.ref_mrms_us);
        assert!(f.last_gmean_us.abs() < p.last_gmean_us.abs() && f.last_mrms_us < p.last_mrms_us);
        // Calibrated through the GPIO into the reference's latch: on the reference in the mean,
        // in both couplings (following the master, the reference's loop wanders more).
        let fm = row(&rows, n, "ferrocat-mfr");
        assert!(fm.ref_gmean_us.abs() <= 0.1 && fm.ref_mrms_us < p.ref_mrms_us / 5.0, "{fm:?}");
        assert!(f.ref_gmean_us.abs() <= 0.2 && f.ref_mrms_us < p.ref_mrms_us / 5.0, "{f:?}");
        assert!(fm.calibration_us.is_some() && f.calibration_us.is_some() && c.calibration_us.is_none());
        // Park's GPI measurement keeps the mean (its latencies' means are subtracted) and adds
        // the latencies' spread to every method alike.
        for r in [c, p, f] {
            assert!((r.gpi_ref_gmean_us - r.ref_gmean_us).abs() < 0.5, "{r:?}");
            assert!(r.gpi_ref_mrms_us > r.ref_mrms_us && r.gpi_last_mrms_us > r.last_mrms_us, "{r:?}");
        }
    }
}

#[test]
fn without_the_calibration_half_the_stamps_asymmetry_stays() {
    // beaglebone-rt's software stamps: transmit 2.0 µs early, receive 3.0 µs late on average;
    // no round trip shows the difference, so every passage is put 0.5 µs late.
    let o = Options {
        rounds: 2,
        settle_s: 2.0,
        samples: 2_000,
        slaves: vec![2],
        methods: vec!["ferrocat-mfr".into()],
        gpio_calibration: false,
        ..Options::quick(HostModel::beaglebone_rt())
    };
    let r = &run(&o, &|_, _| {}).unwrap()[0];
    assert!((r.ref_gmean_us + 0.5).abs() < 0.1 && r.calibration_us.is_none(), "{r:?}");
}

#[test]
fn hardware_timestamps_bring_ferrocat_within_a_tenth_of_a_microsecond_at_once() {
    let rows = table(HostModel::nic_hwts());
    for n in [2, 6] {
        let park = row(&rows, n, "park2020");
        let f = row(&rows, n, "ferrocat");
        assert!(f.ref_gmean_us.abs() <= 0.1 && f.ref_mrms_us <= 0.3, "{f:?}");
        assert!(f.ref_mrms_us < park.ref_mrms_us / 5.0);
        // The master following the reference: no loop at the reference carries host noise
        // into the slaves, and the master's clock is its fitted line through the stamps.
        let fm = row(&rows, n, "ferrocat-mfr");
        assert!(fm.ref_gmean_us.abs() <= 0.1 && fm.ref_mrms_us < park.ref_mrms_us / 5.0, "{fm:?}");
        // Every slave within 100 ns of the reference and the master within 1 µs, for good, in
        // both couplings (the reference following from the static drift compensation on).
        assert!(fm.lock_ms.is_some_and(|ms| ms < 100.0), "{fm:?}");
        assert!(f.lock_ms.is_some_and(|ms| ms < 100.0), "{f:?}");
    }
}

#[test]
fn a_stock_kernel_throws_off_the_reference_loop_but_not_ferrocat() {
    // 1 % of sends late by up to 200 µs: every method that writes the master's time into the
    // reference's loop is thrown off; following the reference with transmit stamps is not,
    // nor is giving the reference an offset (which does not depend on when the frame passes).
    let rows = table(HostModel::pc_stock());
    for n in [2, 6] {
        let (p, f, fm) = (row(&rows, n, "park2020"), row(&rows, n, "ferrocat"), row(&rows, n, "ferrocat-mfr"));
        // The master's error wanders here (its one-second means spread by ≈ 90 ns), and this
        // short run calibrates over one second: a looser bound than the full run's 0.1 µs.
        assert!(fm.ref_gmean_us.abs() <= 0.15 && fm.ref_mrms_us < p.ref_mrms_us / 5.0, "{fm:?}");
        assert!(f.ref_gmean_us.abs() <= 0.15 && f.ref_mrms_us < p.ref_mrms_us / 5.0, "{f:?}");
    }
}

#[test]
fn the_same_seed_gives_the_same_table() {
    let o = Options { rounds: 1, settle_s: 0.5, samples: 300, slaves: vec![2], ..Options::quick(HostModel::pc_rt()) };
    let a = run(&o, &|_, _| {}).unwrap();
    let b = run(&o, &|_, _| {}).unwrap();
    assert_eq!(a, b);
    let c = run(&Options { seed: 2, ..o }, &|_, _| {}).unwrap();
    assert_ne!(a, c, "another seed, another realisation");
}

/// The ring of scenarios/segments/ring.toml with the cable between its couplers pulled before
/// the master starts: the far coupler (the "last" clock) is set up behind the break from the
/// latch's two passes and kept on the reference's time, for every method (set up from the
/// first pass alone it would stay a master round trip off: 25.7 µs under nic-hwts, 18.1 µs
/// under pc-rt).
#[test]
fn a_ring_split_from_the_start_keeps_its_far_clock_with_the_master() {
    let toml = format!(
        "{}[[event]]\nat_ms = 0\nlink_down = {{ device = 2, port = 0 }}\n",
        std::fs::read_to_string(concat!(env!("CARGO_MANIFEST_DIR"), "/../../scenarios/segments/ring.toml")).unwrap()
    );
    for host in [HostModel::nic_hwts(), HostModel::pc_rt()] {
        let o = Options {
            rounds: 1,
            settle_s: 2.0,
            samples: 2_000,
            methods: vec!["conventional".into(), "ferrocat".into(), "ferrocat-mfr".into()],
            slaves: vec![4],
            segment: Some(toml::from_str(&toml).unwrap()),
            ..Options::quick(host)
        };
        let rows = run(&o, &|_, _| {}).unwrap();
        for r in &rows {
            println!(
                "{} {:13}: ref GMEAN {:7.3} MRMS {:7.3}  far coupler GMEAN {:7.3} MRMS {:7.3} µs  lock {:?}",
                r.host, r.method, r.ref_gmean_us, r.ref_mrms_us, r.last_gmean_us, r.last_mrms_us, r.lock_ms
            );
            // The far coupler follows the reference, whatever the master does with it: within
            // a hundredth of the master round trip it was off before (71 ns measured at worst,
            // `conventional` under pc-rt, whose reference wanders with the master's noisy
            // writes and the far coupler's 5 ns moves trail it).
            assert!((r.last_gmean_us - r.ref_gmean_us).abs() < 0.2, "{r:?}");
        }
        // Seeds 1–10: ferrocat's far coupler within 28 ns (GMEAN) and 30 ns (MRMS) but for
        // one draw under pc-rt, 57 and 58 ns (seed 9: the far reference, kept from software
        // stamps of two passes, wandered); ferrocat-mfr's within 15 and 16 ns.
        for f in rows.iter().filter(|r| r.method.starts_with("ferrocat")) {
            assert!(f.last_gmean_us.abs() <= 0.075 && f.last_mrms_us <= 0.075, "{f:?}");
        }
    }
}

/// The quick run on a line of three couplers whose crystals random-walk by 50 ppb/√s.
fn wandering_couplers(host: HostModel) -> Options {
    let device = "[[device]]\nbuiltin = \"EK1100\"\nwander_ppb_per_sqrt_s = 50.0\n";
    let segment = toml::from_str(&format!("seed = 1\n{}", device.repeat(3))).unwrap();
    Options { slaves: vec![3], segment: Some(segment), ..Options::quick(host) }
}

/// Three couplers whose crystals random-walk by 50 ppb/√s (a plain crystal: a few), seeds
/// 1–4 of one round each after 30 s of settling: ferrocat's line takes the shorter window that
/// foretells the cycles' points best. Reference MRMS, mean of the four seeds, `ferrocat` /
/// `ferrocat-mfr`: 16 / 19 ns; with the whole window only 58 / 56 ns (docs/lab.md,
/// park2020, wandering crystals).
#[test]
fn wandering_crystals_shorten_ferrocats_line() {
    let o = Options {
        rounds: 1,
        methods: vec!["ferrocat".into(), "ferrocat-mfr".into()],
        // The shorter lines are scored on the cycles' frames and one counts after 8 192 of
        // them; the GPIO calibration, in the middle half of the settling, must come after that
        // (else it takes the whole line's wander error there for the stamps' asymmetry).
        settle_s: 30.0,
        ..wandering_couplers(HostModel::pc_rt())
    };
    let mut mrms_us = [0.0; 2];
    for seed in 1..=4 {
        for (k, r) in run(&Options { seed, ..o.clone() }, &|_, _| {}).unwrap().iter().enumerate() {
            println!("seed {seed} {:13}: ref GMEAN {:7.4} MRMS {:7.4} µs", r.method, r.ref_gmean_us, r.ref_mrms_us);
            mrms_us[k] += r.ref_mrms_us / 4.0;
        }
    }
    assert!(mrms_us.iter().all(|&m| m < 0.03), "{mrms_us:?}");
}

/// The same couplers on a stock kernel: a change of ferrocat's line moves the reference by the
/// two lines' difference (≈ 100 ns there), and the followers are shifted with it rather than
/// left to chase it (before, they sat 100 ns from the reference for 10 ms after a change, and
/// this run's lock time was 8.3 s).
#[test]
fn a_change_of_line_moves_the_followers_with_the_reference() {
    let o = Options { methods: vec!["ferrocat".into()], ..wandering_couplers(HostModel::pc_stock()) };
    let r = &run(&o, &|_, _| {}).unwrap()[0];
    println!("ref GMEAN {:7.4} MRMS {:7.4} µs, lock {:?}", r.ref_gmean_us, r.ref_mrms_us, r.lock_ms);
    assert_eq!(r.lock_ms, Some(0.0), "{r:?}");
}

#[test]
fn the_beaglebone_model_is_the_fit_of_table_1s_two_slave_rows() {
    use ferrocat_lab::park2020::{fit, SetupModel};
    let base = Options::quick(HostModel::beaglebone_rt());
    // The presets are the fit's fixed point: from them every error is under 20 ns at once.
    let steps = fit(&base, SetupModel::current(), 4).unwrap();
    assert_eq!(steps.len(), 1, "{steps:?}");
    // From elsewhere (send path 2 µs longer, receive path 4 µs shorter, spread 1 µs less) the
    // fit comes back to them.
    let far = SetupModel { send_mean_ns: 12_000.0, recv_mean_ns: 8_000.0, gpi_master_detect_sd_ns: 2_800.0 };
    let steps = fit(&base, far, 8).unwrap();
    let (m, now) = (steps.last().unwrap().model, SetupModel::current());
    assert!(steps.len() < 8, "{steps:?}");
    assert!((m.send_mean_ns - now.send_mean_ns).abs() < 50.0, "{m:?}");
    assert!((m.recv_mean_ns - now.recv_mean_ns).abs() < 100.0, "{m:?}");
    assert!((m.gpi_master_detect_sd_ns - now.gpi_master_detect_sd_ns).abs() < 50.0, "{m:?}");
}

#[test]
fn table_1_fitted_on_two_slaves_predicts_six_but_for_park2020s_gmean() {
    use ferrocat_lab::park2020::{compare, paper_setup};
    let o = Options {
        methods: vec!["conventional".into(), "park2020".into()],
        ..Options::quick(HostModel::beaglebone_rt())
    };
    assert!(paper_setup(&o).is_ok());
    let figures = compare(&run(&o, &|_, _| {}).unwrap());
    assert_eq!(figures.len(), 16);
    for f in &figures {
        println!("{}", f.line());
    }
    let misses = ferrocat_lab::fit::misses(&figures);
    assert_eq!(misses, ["6 slaves, park2020, ref GMEAN", "6 slaves, park2020, last GMEAN"]);
    // The model keeps the 2-slave bias where the paper's went below zero (docs/lab.md).
    for f in figures.iter().filter(|f| !f.within) {
        assert!(f.model > 0.5 && f.paper < -1.5, "{f:?}");
    }
    // Another host is not the paper's set-up: no comparison.
    assert!(paper_setup(&Options::quick(HostModel::pc_rt())).is_err());
}
