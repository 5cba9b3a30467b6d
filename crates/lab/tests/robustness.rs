//! Robustness runs: every method of the error tables under 1 % frame loss, a 50 ppm step of
//! the reference's crystal or of the first follower's, and a 3-cycle overrun of the master, on
//! one seed.
use ferrocat_lab::robustness::{run, Options, CONTROL, FOLLOWER_DRIFT_STEP, SCENARIOS};
use ferrocat_segment::HostModel;

#[test]
fn every_method_survives_every_disturbance_and_ferrocat_recovers() {
    let o = Options::new(HostModel::pc_rt());
    let rows = run(&o).unwrap();
    // Each method also undisturbed: the control, first.
    assert_eq!(rows.len(), (SCENARIOS.len() + 1) * 4);
    assert!(rows[..4].iter().all(|r| r.scenario == CONTROL) && rows[4..].iter().all(|r| r.scenario != CONTROL));
    for r in &rows {
        println!(
            "{:18} {:12} before {:8.1} ± {:6.1} ns, peak {:9.1} ns, recovery {:?} ms, relock {:?} ms (locked before: {}), \
             outside {:.2} %, after {:8.1}/{:8.1} ns, lost {}, probes {}",
            r.scenario, r.method, r.before_mean_ns, r.before_sd_ns, r.peak_ns, r.recovery_ms, r.relock_ms, r.locked_before,
            r.outside_pct, r.after_mean_ns, r.after_rms_ns, r.frames_lost, r.probes_after
        );
        assert!(r.after_rms_ns.is_finite() && r.peak_ns.is_finite(), "{r:?}");
        // Only ferrocat keeps a line.
        assert_eq!(r.line_restarts_after.is_some(), r.method.starts_with("ferrocat"), "{r:?}");
        // Paired with its control (the same realisation until the disturbance, which `run`
        // checks), except the control itself.
        assert_eq!(r.peak_vs_control_ns.is_some(), r.scenario != CONTROL, "{r:?}");
        if r.scenario == CONTROL {
            assert_eq!((r.frames_lost, r.recovery_vs_control_ms), (0, None), "{r:?}");
        }
        if r.scenario == "loss-1pct" {
            // 1 % of 6 000 cycles' frames, both ways of a round trip: tens of losses.
            assert!(r.frames_lost > 20, "{r:?}");
            // Only ferrocat steering the reference's offset makes a lost frame up, every one.
            let makes_up = r.method == "ferrocat";
            assert_eq!(r.make_ups, if makes_up { r.frames_lost } else { 0 }, "{r:?}");
        }
    }
    for r in rows.iter().filter(|r| r.method.starts_with("ferrocat")) {
        // Calibrated through the GPIO before the band window: the stamps' asymmetry (half of it
        // ≈ −290 ns on pc-rt uncalibrated) is out of the level before.
        assert!(r.calibration_ns.is_some_and(|e| e < -150) && r.before_mean_ns.abs() < 50.0, "{r:?}");
        let before_rms = (r.before_mean_ns.powi(2) + r.before_sd_ns.powi(2)).sqrt();
        // The error over the last half is back about where it was: its RMS exceeds the RMS
        // before by less than half the band (under lasting loss it leaves the band now and
        // then: `outside_pct` is reported, docs/lab.md).
        assert!(r.after_rms_ns < before_rms + r.band_ns / 2.0, "{r:?}");
        if r.scenario != "loss-1pct" {
            let rec = r.recovery_ms.unwrap_or_else(|| panic!("ferrocat did not recover: {r:?}"));
            assert!(rec < 1_000.0, "{r:?}");
        }
        // Locked before, locked again: no disturbance costs ferrocat its lock for good.
        assert!(r.locked_before && r.relock_ms.is_some(), "{r:?}");
        // Its lines restart for a crystal step and for nothing else: lost frames and missed
        // cycles leave them standing. The reference's step restarts ε's line (reference −
        // follower's crystal) once; the follower's, ε's and the crystal's.
        let restarts = match r.scenario.as_str() {
            "drift-step-50ppm" => 1,
            FOLLOWER_DRIFT_STEP => 2,
            _ => 0,
        };
        assert_eq!(r.line_restarts_after, Some(restarts), "{r:?}");
        if r.scenario == FOLLOWER_DRIFT_STEP {
            // The flywheel's crystal moved, the reference did not: the kink test hands the
            // estimate to the direct line within 100 ms of the undisturbed run.
            assert!(r.recovery_vs_control_ms.is_some_and(|ms| ms < 100.0), "{r:?}");
        }
        if r.scenario == "drift-step-50ppm" {
            // The crystal step: back within 100 ms (probing the reference while the line is
            // uncertain; docs/lab.md, robustness), having probed it.
            assert!(r.recovery_ms.is_some_and(|ms| ms < 100.0) && r.probes_after > 0, "{r:?}");
            // And no longer than that from where it would have been undisturbed; the step
            // moved it hundreds of ns from there first.
            assert!(r.recovery_vs_control_ms.is_some_and(|ms| ms < 100.0), "{r:?}");
            assert!(r.peak_vs_control_ns.is_some_and(|ns| ns > 200.0), "{r:?}");
            if r.method == "ferrocat" {
                // Followers kept on the middle of the reference's sawtooth: every slave back
                // within 100 ns of it within 100 ms too (docs/lab.md, robustness).
                assert!(r.relock_ms.is_some_and(|ms| ms < 100.0), "{r:?}");
            }
        }
    }
    // No method loses its hold for good: over the last half of the run every error is back
    // about where it was before. (Not "back in the band within a second": conventional and
    // park2020 leave their band on 1–2 % of samples with or without a disturbance, the host's
    // late sends in the reference's time control loop, so their last exit is wherever the
    // host's last outlier fell — on seed 1 at 7.2 s in every scenario; docs/lab.md.)
    for r in &rows {
        let before_rms = (r.before_mean_ns.powi(2) + r.before_sd_ns.powi(2)).sqrt();
        assert!(r.after_rms_ns < 1.1 * before_rms + 50.0, "{r:?}");
    }
}

#[test]
fn ferrocat_relocks_every_slave_within_100_ms_of_a_crystal_step() {
    // Seeds on which the step leaves the reference's crystal 60–100 ppm from the master's:
    // with the followers on the top of the reference's sawtooth (no delay bias) neither
    // relocked within the run.
    for seed in [4, 9] {
        let o = Options {
            methods: vec!["ferrocat".into()],
            scenarios: vec!["drift-step-50ppm".into()],
            seed,
            control: false,
            ..Options::new(HostModel::pc_rt())
        };
        let r = &run(&o).unwrap()[0];
        println!("seed {seed}: relock {:?} ms, recovery {:?} ms", r.relock_ms, r.recovery_ms);
        assert!(r.relock_ms.is_some_and(|ms| ms < 100.0), "{r:?}");
    }
}

#[test]
fn ferrocat_recovers_within_100_ms_of_a_crystal_step_on_beaglebone_rt() {
    // The seeds on which the reference-following coupling, its sawtooth taking half the band,
    // stayed out: 1 and 4 for 460–493 ms with a line probed only to 1/16 of its noise scale;
    // 3, 5 and 9 for 102–185 ms with 5 probes a cycle.
    for seed in [1, 3, 4, 5, 9] {
        let o = Options {
            methods: vec!["ferrocat".into(), "ferrocat-mfr".into()],
            scenarios: vec!["drift-step-50ppm".into()],
            seed,
            control: false,
            ..Options::new(HostModel::beaglebone_rt())
        };
        for r in &run(&o).unwrap() {
            println!("seed {seed} {}: recovery {:?} ms, relock {:?} ms", r.method, r.recovery_ms, r.relock_ms);
            assert!(r.recovery_ms.is_some_and(|ms| ms < 100.0), "{r:?}");
        }
    }
}

/// On the ring of scenarios/segments/ring.toml, the cable into its second coupler pulled once
/// settled: every method's master − reference error stays within its band around the
/// undisturbed run's, ferrocat's within a few tens of ns (the loop behind the reference
/// measured again; 200 ns off when the intact ring's shortening came from 32 round trips each
/// way), and ferrocat's segment, the far coupler kept behind the break, is locked again within
/// 2.5 s: relock 0–2 001 ms over seeds 1–10, the late ones bunched just below the 2 s after
/// which the level at the break is fixed from its samples (`far_clock::ANCHOR_NS`; seed 7:
/// 2 001 ms). On a line the disturbance is refused.
#[test]
fn a_pulled_ring_cable_leaves_every_method_where_it_was() {
    let toml = std::fs::read_to_string(concat!(env!("CARGO_MANIFEST_DIR"), "/../../scenarios/segments/ring.toml"));
    let segment = Some(toml::from_str(&toml.unwrap()).unwrap());
    let ring = ferrocat_lab::robustness::RING_CABLE_PULLED.to_string();
    let o = Options { scenarios: vec![ring.clone()], segment, ..Options::new(HostModel::pc_rt()) };
    let rows = run(&o).unwrap();
    for r in rows.iter().filter(|r| r.scenario == ring) {
        println!(
            "{:12} peak vs control {:?} ns, recovery vs control {:?} ms, relock {:?} ms, after {:.1} ns (before {:.1})",
            r.method, r.peak_vs_control_ns, r.recovery_vs_control_ms, r.relock_ms, r.after_mean_ns, r.before_mean_ns
        );
        // Never outside its band (from its own noise) around the control's error.
        assert_eq!(r.recovery_vs_control_ms, Some(0.0), "{r:?}");
        if r.method.starts_with("ferrocat") {
            assert!(r.peak_vs_control_ns.is_some_and(|p| p < 60.0), "{r:?}");
            assert!(r.locked_before && r.relock_ms.is_some_and(|ms| ms < 2_500.0), "{r:?}");
        }
    }
    let line = Options { scenarios: vec![ring], methods: vec!["ferrocat".into()], ..Options::new(HostModel::pc_rt()) };
    let e = run(&line).unwrap_err().to_string();
    assert!(e.contains("needs a ring segment"), "{e}");
}

/// ferrocat, its flywheel a follower's crystal (`sync/flywheel.rs`), on a stock kernel whose
/// stamps left the direct line alone (`ferrocat-direct`) more
/// than 100 ms from its control after the reference's crystal step on these seeds
/// (docs/clock-sync.md, "A follower's crystal as flywheel"): back within 100 ms of the control
/// after the reference's step (ε sees it at once) and after the follower's (the kink test hands
/// the estimate to the direct line).
/// Seeds on which `ferrocat-direct` was 108–1 282 ms from its control after the reference's step.
const SEEDS_DIRECT_MISSES: [u64; 3] = [2, 4, 6];

#[test]
fn a_followers_crystal_as_flywheel_recovers_from_either_crystals_step_on_a_stock_kernel() {
    let direct = |seed| {
        let o = Options {
            methods: vec!["ferrocat-direct".into()],
            scenarios: vec!["drift-step-50ppm".into()],
            seed,
            ..Options::new(HostModel::pc_stock())
        };
        run(&o).unwrap().into_iter().find(|r| r.scenario != CONTROL).unwrap().recovery_vs_control_ms
    };
    for seed in SEEDS_DIRECT_MISSES {
        let base = direct(seed);
        println!("seed {seed} ferrocat-direct: {base:?} ms");
        assert!(base.is_none_or(|ms| ms > 100.0), "seed {seed}: ferrocat-direct back in {base:?} ms");
        let o = Options {
            methods: vec!["ferrocat".into(), "ferrocat-mfr".into()],
            scenarios: vec!["drift-step-50ppm".into(), FOLLOWER_DRIFT_STEP.into()],
            seed,
            ..Options::new(HostModel::pc_stock())
        };
        for r in run(&o).unwrap().iter().filter(|r| r.scenario != CONTROL) {
            println!(
                "seed {seed} {} {}: {:?} ms, peak {:.0} ns",
                r.method, r.scenario, r.recovery_vs_control_ms, r.peak_ns
            );
            // Either crystal's step: within 100 ms (the follower's is told from the
            // reference's by the kink test, docs/clock-sync.md).
            assert!(r.recovery_vs_control_ms.is_some_and(|ms| ms <= 100.0), "{r:?}");
        }
    }
}

/// The master following on Chen's host, seed 14: the two crystals too alike for the DC
/// initialisation to measure which way the speed counter turns, and the follower's loop too
/// calm for the trial to have told it 5 s later, when the reference's crystal steps. The kink
/// test scores both readings' templates: the step tells the direction, and the flywheel takes
/// over (38 ms; 159 ms with the direct line alone and a test that scores one reading).
#[test]
fn a_step_during_the_speed_counters_trial_tells_its_direction() {
    let o = Options {
        methods: vec!["ferrocat-mfr".into()],
        scenarios: vec!["drift-step-50ppm".into()],
        seed: 14,
        ..Options::new(HostModel::rtx_10us())
    };
    let rows = run(&o).unwrap();
    let r = rows.iter().find(|r| r.scenario != CONTROL).unwrap();
    println!("recovery vs control {:?} ms, peak {:.0} ns", r.recovery_vs_control_ms, r.peak_ns);
    assert!(r.recovery_vs_control_ms.is_some_and(|ms| ms <= 100.0), "{r:?}");
}
