//! The lab looks at the clocks at every phase of the cycle, at the same instants for every
//! method, and sees what a clock steered once per frame does in between.
use ferrocat_lab::sampler::{Sample, Sampler};
use ferrocat_master::sync::Coupling;
use ferrocat_segment::HostModel;

const CYCLE_NS: u64 = 1_000_000;

/// 2 000 cycles of `method` on two EK1100s, the reference's crystal 40 ppm fast, a sample armed
/// each cycle: each sample with the phase of its instant in the cycle.
fn run(method: &str) -> Vec<(u64, Sample)> {
    let mut cfg = ferrocat_lab::line(2);
    cfg.drift_spread_ppm = None;
    cfg.devices[0].drift_ppm = Some(40.0);
    cfg.devices[1].drift_ppm = Some(-10.0);
    let (mut m, mut sync, _) =
        ferrocat_lab::segment(&cfg, HostModel::pc_rt(), 1, method, CYCLE_NS, Coupling::ReferenceFollowsMaster).unwrap();
    let dc = ferrocat_lab::dc_slaves(&m).unwrap();
    let mut st = m.clock().sync_state().unwrap();
    let mut sampler = Sampler::new(&m, &dc, 1);
    let mut next = m.cyclic().now_ns();
    let mut starts = Vec::new();
    let mut out = Vec::new();
    for k in 0..2_000 {
        next += CYCLE_NS;
        m.cyclic().sleep_until(next);
        sampler.arm(&mut m, next, CYCLE_NS, k);
        starts.push(next);
        m.clock().sync_step(sync.as_mut(), &mut st).unwrap();
        out.extend(sampler.after_cycle(&mut m, sync.as_ref()));
    }
    out.extend(sampler.rest(&mut m, sync.as_ref()));
    out.into_iter().map(|s| (s.at_ns - starts[s.tag as usize], s)).collect()
}

#[test]
fn samples_fall_at_every_phase_and_show_the_sawtooth_between_frames() {
    let ferrocat = run("ferrocat");
    let conventional = run("conventional");
    assert_eq!(ferrocat.len(), 2_000, "one sample per cycle, none lost");
    assert!(ferrocat.iter().enumerate().all(|(k, (_, s))| s.tag == k as u64), "in order");
    // Paired: the same instants (relative to the cycle) for every method.
    let phases: Vec<u64> = ferrocat.iter().map(|(p, _)| *p).collect();
    assert_eq!(phases, conventional.iter().map(|(p, _)| *p).collect::<Vec<_>>());
    // Uniform over the cycle: each quarter holds about a quarter of them.
    for q in 0..4 {
        let n = phases.iter().filter(|&&p| p * 4 / CYCLE_NS == q).count();
        assert!((400..600).contains(&n), "quarter {q}: {n} of 2000");
    }
    // ferrocat steers the reference's offset once per frame, so between frames the reference
    // gains 40 ns per ms on the master: master − reference falls with the phase at that slope
    // (least squares over the second half, once settled).
    let settled = &ferrocat[1_000..];
    let n = settled.len() as f64;
    let (mx, my) = settled.iter().fold((0.0, 0.0), |(a, b), (p, s)| (a + *p as f64 / n, b + s.errors_ns[0] as f64 / n));
    let (sxy, sxx) = settled.iter().fold((0.0, 0.0), |(a, b), (p, s)| {
        let dx = *p as f64 - mx;
        (a + dx * (s.errors_ns[0] as f64 - my), b + dx * dx)
    });
    let slope_ppm = sxy / sxx * 1e6;
    eprintln!("master − reference against the phase: {slope_ppm:.1} ppm");
    assert!((-48.0..-32.0).contains(&slope_ppm), "slope {slope_ppm:.1} ppm, the reference runs 40 ppm fast");
}
