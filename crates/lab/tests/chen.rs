//! The Chen 2016 experiment, shortened: a master that does not follow the reference loses and
//! repeats process data in DC-synchronous slaves; Chen's method, SOEM's PI and ferrocat's do not
//! at 500, 250 and 100 µs on Chen's 10 µs timer (Chen's now and then at 100 µs).
use ferrocat_lab::chen2016::{run, Options};
use ferrocat_master::io::HostModel;

#[test]
fn only_a_master_that_follows_the_reference_keeps_every_cycle() {
    let o = Options { cycles_us: vec![500, 250, 100], seconds: 4.0, ..Options::quick(HostModel::rtx_10us()) };
    let rows = run(&o, &|_, _| {}).unwrap();
    for r in &rows {
        // Jitter min, max (µs), width (%), sd (µs), cycles, lost, repeated.
        println!("{:>3} µs {:9}: {}", r.cycle_us, r.method, r.figures().join("  "));
        if r.method == "none" {
            // +40 ppm over 4 s: the reference's grid slides 160 µs past the master's.
            assert!(r.jitter_max_us - r.jitter_min_us > 100.0, "{r:?}");
            if r.cycle_us == 250 {
                assert!(r.lost > 0 && r.repeated > 0, "{r:?}");
            }
        } else if r.method == "chen2016" && r.cycle_us == 100 {
            // Chen's method at 100 µs loses a cycle now and then on some host draws: 37 in
            // 600 000 over a minute (docs/clock-sync.md), 2 and 2 repeated in these 40 000
            // with seed 3, none with seed 1 (until session 41 the test asked for none).
            assert!(r.lost + r.repeated <= 8, "{r:?}");
            assert!(r.jitter_width_pct < 70.0, "{r:?}");
        } else {
            assert_eq!((r.lost, r.repeated), (0, 0), "{r:?}");
            // At 100 µs the 10 µs timer's steps and the host's wake-ups are half the cycle (the
            // paper's width there: 64 %).
            assert!(r.jitter_width_pct < if r.cycle_us == 100 { 70.0 } else { 50.0 }, "{r:?}");
        }
    }
    // The width is two extremes; the spread of every cycle is where the methods differ: on the
    // same host draws, ferrocat's is the smallest at every cycle time.
    for c in &o.cycles_us {
        let sd = |m: &str| rows.iter().find(|r| r.cycle_us == *c && r.method == m).unwrap().jitter_sd_us;
        assert!(sd("ferrocat") < sd("pi") && sd("ferrocat") < sd("chen2016"), "{c} µs: {rows:?}");
        assert!(sd("ferrocat") > 1.0, "{c} µs: a 10 µs timer cannot do better than its steps");
    }
}

#[test]
fn at_50_us_ferrocat_holds_a_frame_back_after_a_late_one_and_loses_none() {
    // The host's rare late wake-ups and sends (0.1 % each, up to 30 and 20 µs) pass the SYNC0
    // half a 50 µs cycle after the frame's target: the others lose the next frame's data,
    // ferrocat holds that frame back one cycle, so the slaves repeat one cycle and lose none.
    let o = Options {
        // The quick run's 10 s: the widths are extremes, and chen2016's grows over the run.
        cycles_us: vec![50],
        methods: vec!["chen2016".into(), "ferrocat".into()],
        ..Options::quick(HostModel::rtx_10us())
    };
    let rows = run(&o, &|_, _| {}).unwrap();
    let (chen, f) = (&rows[0], &rows[1]);
    let show = |r: &ferrocat_lab::chen2016::Row| {
        format!(
            "{}: width {:.1} %, sd {:.2} µs, lost {}, repeated {}",
            r.method, r.jitter_width_pct, r.jitter_sd_us, r.lost, r.repeated
        )
    };
    println!("{}\n{}", show(chen), show(f));
    assert!(chen.lost > 0, "{}", show(chen));
    assert!(f.lost == 0 && f.repeated > 0, "{}", show(f));
    assert!(f.jitter_width_pct < chen.jitter_width_pct, "{}", show(f));
    assert!(f.jitter_sd_us < chen.jitter_sd_us, "{}", show(f));
}
