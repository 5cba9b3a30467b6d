//! The cyclic synchronisation methods in virtual time, on the same segment and seed (paired),
//! judged by the true clocks the simulator knows.
use ferrocat_master::sync::{
    Chen2016, ClockSync, Conventional, Coupling, Ferrocat, FollowerDelays, LostFrames, Park2020, ProbeFrames, Probing,
    SoemPi, Steering,
};
use ferrocat_master::{DcConfig, Master};
use ferrocat_segment::SegmentConfig;
use ferrocat_segment::{HostModel, VirtualIo};

const CYCLE_NS: u64 = 1_000_000;

/// Four slaves brought up (no DC initialisation yet).
fn brought_up(host: HostModel) -> Master<VirtualIo> {
    brought_up_seeded(host, 5)
}

/// [`brought_up`] with `seed` for the segment's and the host's random draws.
fn brought_up_seeded(host: HostModel, seed: u64) -> Master<VirtualIo> {
    let cfg: SegmentConfig = toml::from_str(
        &"seed = 5\n\
         [[device]]\nbuiltin = 'EK1100'\ndrift_ppm = 40.0\n\
         [[device]]\nbuiltin = 'EL2004'\ndrift_ppm = -45.0\nesc = 'et1100'\nsync_unit = true\n\
         [[device]]\nbuiltin = 'EL1004'\ndrift_ppm = 50.0\nesc = 'et1100'\nsync_unit = true\n\
         [[device]]\nbuiltin = 'EL2004'\ndrift_ppm = -20.0\nesc = 'et1100'\nsync_unit = true\n"
            .replace("seed = 5", &format!("seed = {seed}")),
    )
    .unwrap();
    let mut m = Master::new(VirtualIo::new(cfg.build().unwrap(), host, seed));
    m.states().bring_up().unwrap();
    m
}

fn segment(host: HostModel) -> Master<VirtualIo> {
    segment_seeded(host, 5)
}

fn segment_seeded(host: HostModel, seed: u64) -> Master<VirtualIo> {
    let mut m = brought_up_seeded(host, seed);
    m.dc().init_dc(&DcConfig { sync0_slaves: Some(vec![]), ..DcConfig::default() }).unwrap();
    m
}

/// True error of slave `k`'s system time against the master's clock now (ns, low 32 bits).
fn true_error(m: &mut Master<VirtualIo>, k: usize) -> i64 {
    let t = m.cyclic().now_ns();
    let master = m.clock().master_system_time() as u32;
    let slave = m.io().seg.nodes[k].esc.dc.as_ref().unwrap().system_at(t) as u32;
    slave.wrapping_sub(master) as i32 as i64
}

struct Figures {
    ref_mean: f64,
    ref_rms: f64,
    /// The reference's spread about its mean.
    ref_sd: f64,
    last_mean: f64,
}

/// Reference-follows-master: `cycles` cycles, the error sampled every other cycle over the
/// second half.
fn run_rfm(host: HostModel, make: impl FnOnce(&mut Master<VirtualIo>) -> Box<dyn ClockSync>, cycles: u64) -> Figures {
    let mut m = segment(host);
    let mut sync = make(&mut m);
    let mut st = m.clock().sync_state().unwrap();
    let mut next = m.cyclic().now_ns();
    let (mut r, mut l) = (Vec::new(), Vec::new());
    for k in 0..cycles {
        next += CYCLE_NS;
        m.cyclic().sleep_until(next);
        m.clock().sync_step(sync.as_mut(), &mut st).unwrap();
        if k >= cycles / 2 && k % 2 == 0 {
            r.push(true_error(&mut m, 0) as f64);
            l.push(true_error(&mut m, 3) as f64);
        }
    }
    let mean = |v: &[f64]| v.iter().sum::<f64>() / v.len() as f64;
    let rms = |v: &[f64]| (v.iter().map(|x| x * x).sum::<f64>() / v.len() as f64).sqrt();
    let (ref_mean, ref_rms) = (mean(&r), rms(&r));
    let ref_sd = (ref_rms * ref_rms - ref_mean * ref_mean).max(0.0).sqrt();
    Figures { ref_mean, ref_rms, ref_sd, last_mean: mean(&l) }
}

#[test]
fn reference_follows_master_methods_side_by_side() {
    for host in [HostModel::pc_rt(), HostModel::nic_hwts(), HostModel::pc_stock()] {
        let conv = run_rfm(host, |_| Box::new(Conventional), 4000);
        let park = run_rfm(
            host,
            |m| {
                let d = m.clock().park_delay(1000).unwrap();
                Box::new(Park2020::new(d))
            },
            4000,
        );
        let ours = run_rfm(host, |_| Box::new(Ferrocat::new(Coupling::ReferenceFollowsMaster, CYCLE_NS)), 4000);
        let tcl = run_rfm(
            host,
            |_| {
                let f =
                    Ferrocat::new(Coupling::ReferenceFollowsMaster, CYCLE_NS).with_steering(Steering::TimeControlLoop);
                Box::new(f)
            },
            4000,
        );
        for (name, f) in [("conventional", &conv), ("park2020", &park), ("ferrocat", &ours), ("ferrocat-tcl", &tcl)] {
            println!(
                "{:9} {name:12}: reference mean {:8.1} ns rms {:8.1} ns sd {:7.1} ns; last slave mean {:8.1} ns",
                host.name, f.ref_mean, f.ref_rms, f.ref_sd, f.last_mean
            );
        }
        if host.name == "pc-stock" {
            // 1 % of sends up to 200 µs late: every time written into the reference's time
            // control loop carries its frame's lateness (conventional, park2020, ferrocat-tcl);
            // the offset ferrocat gives the reference does not depend on when the frame passes.
            // The spread, not the RMS: without the GPIO calibration ours keeps the software
            // stamps' asymmetry (≈ 0.55 µs) as its mean.
            for (name, other) in [("conventional", &conv), ("park2020", &park), ("ferrocat-tcl", &tcl)] {
                assert!(ours.ref_sd * 5.0 <= other.ref_sd, "{name}: sd {} against ours {}", other.ref_sd, ours.ref_sd);
            }
            assert!(ours.ref_mean.abs() < 1_000.0, "{}", ours.ref_mean);
        } else {
            // The conventional bias is the time from building the frame to its passing the
            // reference (host send latency + wire): microseconds.
            assert!(conv.ref_mean < -2_000.0, "{}", conv.ref_mean);
            assert!(park.ref_mean.abs() < conv.ref_mean.abs() && park.ref_rms < conv.ref_rms);
            assert!(ours.ref_mean.abs() <= park.ref_mean.abs() + 1.0 && ours.ref_rms <= park.ref_rms);
            assert!(ours.ref_rms <= tcl.ref_rms, "offset {} against time control loop {}", ours.ref_rms, tcl.ref_rms);
        }
        // The other slaves follow the reference.
        assert!((ours.last_mean - ours.ref_mean).abs() < 100.0, "{} {}", ours.last_mean, ours.ref_mean);
        if host.stamps == ferrocat_segment::Stamps::Hardware {
            // What is left is the reference's sawtooth between two offsets (its 40 ppm over
            // half a cycle: 20 ns), sampled at one phase of the cycle.
            assert!(ours.ref_mean.abs() <= 50.0, "with hardware timestamps: {}", ours.ref_mean);
        }
    }
}

/// Master-follows-reference: the phase at which each frame passes the reference, in its own
/// cycle, over the second half of the run.
fn run_mfr(make: impl FnOnce() -> Box<dyn ClockSync>, cycles: u64, seed: u64) -> (f64, f64) {
    let mut m = segment_seeded(HostModel::pc_rt(), seed);
    let mut sync = make();
    let mut st = m.clock().sync_state().unwrap();
    let mut next = m.cyclic().now_ns();
    let mut phases = Vec::new();
    for k in 0..cycles {
        let c = m.clock().sync_step(sync.as_mut(), &mut st).unwrap();
        next += c.next_period_ns.unwrap();
        m.cyclic().sleep_until(next);
        if k >= cycles / 2 {
            let t = m.cyclic().now_ns();
            let reft = m.io().seg.nodes[0].esc.dc.as_ref().unwrap().system_at(t);
            let mut p = (reft % CYCLE_NS) as f64;
            if p > CYCLE_NS as f64 / 2.0 {
                p -= CYCLE_NS as f64;
            }
            phases.push(p);
        }
    }
    // Phases on a circle: sd around the first one (Chen's method holds whatever phase it
    // started with), mean as an absolute phase.
    let c = CYCLE_NS as f64;
    let wrap = |x: f64| {
        let y = x.rem_euclid(c);
        if y > c / 2.0 {
            y - c
        } else {
            y
        }
    };
    let rel: Vec<f64> = phases.iter().map(|p| wrap(p - phases[0])).collect();
    let rel_mean = rel.iter().sum::<f64>() / rel.len() as f64;
    let sd = (rel.iter().map(|p| (p - rel_mean).powi(2)).sum::<f64>() / rel.len() as f64).sqrt();
    let mean = wrap(phases[0] + rel_mean);
    println!("{}: phase mean {mean:9.1} ns, sd {sd:8.1} ns", sync.name());
    (mean, sd)
}

#[test]
fn master_follows_reference_methods_hold_the_phase() {
    // Without following, the reference (+40 ppm) would move 40 µs per second against the
    // master. Four realisations of the host's noise (seeds 5–8): the wake-up jitter dominates
    // what is left, for every method alike, and one 3 s run's sd moves by ±15 % with it
    // (ferrocat / PI was 0.96–1.15 over seeds 5–12).
    let mut pooled = [0.0f64; 3];
    for seed in 5..=8 {
        let (_, chen) = run_mfr(|| Box::new(Chen2016::new(CYCLE_NS, 100, 10_000)), 6000, seed);
        let (_, pi) = run_mfr(|| Box::new(SoemPi::new(CYCLE_NS, 0)), 6000, seed);
        let (ours_mean, ours) =
            run_mfr(|| Box::new(Ferrocat::new(Coupling::MasterFollowsReference, CYCLE_NS)), 6000, seed);
        println!("seed {seed}: phase sd over 3 s: chen2016 {chen:.0} ns, pi {pi:.0} ns, ferrocat {ours:.0} ns");
        assert!(chen < 20_000.0 && pi < 20_000.0, "both follow the reference: {chen} {pi}");
        assert!(ours < chen, "better than Chen's averaging in every run: {ours} {chen}");
        assert!(ours_mean.abs() < 20_000.0, "ferrocat holds the wake-up near the target phase: {ours_mean}");
        for (p, sd) in pooled.iter_mut().zip([chen, pi, ours]) {
            *p += sd * sd / 4.0;
        }
    }
    let [chen, pi, ours] = pooled.map(f64::sqrt);
    println!("pooled phase sd: chen2016 {chen:.0} ns, pi {pi:.0} ns, ferrocat {ours:.0} ns");
    // Over the four: no worse than SOEM's PI within 5 %.
    assert!(ours <= pi * 1.05, "{ours} {pi}");
}

/// The largest |follower − reference| and |master − reference| over the first `cycles` cycles
/// of ferrocat with the reference following the master, DC initialised with
/// (`init_dc_with`) or without its steering during the static drift compensation.
fn rfm_start(steer_from_init: bool, cycles: u64) -> (i64, i64, ferrocat_master::DcReport) {
    let mut m = brought_up(HostModel::pc_rt());
    let mut sync = Ferrocat::new(Coupling::ReferenceFollowsMaster, CYCLE_NS);
    let dc = DcConfig { sync0_slaves: Some(vec![]), ..DcConfig::default() };
    let report = if steer_from_init { m.dc().init_dc_with(&dc, Some(&mut sync)) } else { m.dc().init_dc(&dc) }.unwrap();
    let mut st = m.clock().sync_state().unwrap();
    let mut next = m.cyclic().now_ns();
    let (mut spread, mut master) = (0i64, 0i64);
    for _ in 0..cycles {
        next += CYCLE_NS;
        m.cyclic().sleep_until(next);
        m.clock().sync_step(&mut sync, &mut st).unwrap();
        let r = true_error(&mut m, 0);
        master = master.max(r.abs());
        for k in 1..4 {
            spread = spread.max((true_error(&mut m, k) - r).abs());
        }
    }
    (spread, master, report)
}

#[test]
fn steering_the_reference_from_the_static_drift_compensation_starts_cyclic_operation_locked() {
    let (spread, master, report) = rfm_start(true, 200);
    println!("steered from init: followers within {spread} ns, master within {master} ns; {report:?}");
    assert!(report.reference_steered && report.converged, "{report:?}");
    // Locked from the first cycle: every slave within 100 ns of the reference, the master
    // within 1 µs of it (uncalibrated: half the stamps' asymmetry, ≈ 0.25 µs on pc-rt).
    assert!(spread < 100 && master < 1_000, "{spread} {master}");
    // Without it the reference leaves its crystal's rate for the master's when cyclic
    // operation starts, and every follower's loop must learn that again.
    let (spread, master, report) = rfm_start(false, 200);
    println!("free-running reference in init: followers within {spread} ns, master within {master} ns; {report:?}");
    assert!(!report.reference_steered && spread > 100, "{spread}");
}

/// Master follows reference through a +50 ppm step of the reference's crystal after 12 s:
/// (ms from the step until the master's estimate of the reference stayed within 100 ns of
/// its mean before, peak excursion ns, probe frames in the settled second before the step,
/// after it).
fn mfr_crystal_step(probing: bool) -> (f64, f64, u64, u64) {
    mfr_crystal_step_on(HostModel::pc_rt(), probing, false)
}

fn mfr_crystal_step_on(host: HostModel, probing: bool, every_cycle: bool) -> (f64, f64, u64, u64) {
    let mut m = segment(host);
    let mut sync = if every_cycle {
        Ferrocat::dense(Coupling::MasterFollowsReference, CYCLE_NS)
    } else {
        Ferrocat::new(Coupling::MasterFollowsReference, CYCLE_NS)
    };
    if !probing {
        sync.options_mut().probing = Probing::Off;
    }
    let mut st = m.clock().sync_state().unwrap();
    let mut next = m.cyclic().now_ns();
    let (step_at, cycles) = (12000, 13000);
    let (mut before, mut after, mut probes_before) = (Vec::new(), Vec::new(), 0);
    let mut settled_from = 0;
    for k in 0..cycles {
        if k == step_at - 1000 {
            settled_from = st.probing.sent;
        }
        if k == step_at {
            let now = m.cyclic().now_ns();
            m.cyclic().io_mut().seg.schedule(now, ferrocat_segment::Event::DriftStep { node: 0, delta_ppb: 50_000 });
            probes_before = st.probing.sent;
        }
        let c = m.clock().sync_step(&mut sync, &mut st).unwrap();
        next += c.next_period_ns.unwrap();
        m.cyclic().sleep_until(next);
        let t = m.cyclic().now_ns();
        let own = m.clock().master_system_time();
        let reference = m.io().seg.nodes[0].esc.dc.as_ref().unwrap().system_at(t);
        let e = sync.master_time(own).unwrap().wrapping_sub(reference) as i64 as f64;
        if k >= step_at {
            after.push(e);
        } else if k >= step_at - 1000 {
            before.push(e);
        }
    }
    let mean = before.iter().sum::<f64>() / before.len() as f64;
    let last_out = after.iter().rposition(|e| (e - mean).abs() > 100.0).map_or(0, |i| i + 1);
    let peak = after.iter().map(|e| (e - mean).abs()).fold(0.0, f64::max);
    (last_out as f64 * CYCLE_NS as f64 / 1e6, peak, probes_before - settled_from, st.probing.sent - probes_before)
}

#[test]
fn dense_probing_probes_every_settled_cycle_and_recovers_from_a_step_on_a_stock_kernel() {
    let (dense, peak_dense, settled, after) = mfr_crystal_step_on(HostModel::pc_stock(), true, true);
    let (sparse, peak_sparse, settled_sparse, _) = mfr_crystal_step_on(HostModel::pc_stock(), true, false);
    println!(
        "50 ppm step, pc-stock: dense probing back within 100 ns after {dense} ms (peak {peak_dense:.0} ns; \
         probes {settled} in the settled second before, {after} after); probing while uncertain {sparse} ms \
         (peak {peak_sparse:.0} ns; {settled_sparse} settled probes)"
    );
    // Half of every 1 ms cycle at twice a stock kernel's lead fits ≈ 14 probes; the sparse
    // rule sends none once settled but for the change test's and the uncertainty's bursts.
    assert!(settled >= 10 * 1_000, "{settled} probes in 1 000 settled cycles");
    assert!(settled > 10 * settled_sparse, "{settled} vs {settled_sparse}");
    assert!(dense < 100.0, "{dense} ms");
}

#[test]
fn probing_while_the_estimate_is_uncertain_recovers_from_a_crystal_step_sooner() {
    let (with, peak_with, quiet, burst) = mfr_crystal_step(true);
    let (without, peak_without, none_before, none_after) = mfr_crystal_step(false);
    println!(
        "50 ppm step, pc-rt: probing back within 100 ns after {with} ms (peak {peak_with:.0} ns; probes {quiet} \
         in the settled second before, {burst} after); without {without} ms (peak {peak_without:.0} ns)"
    );
    assert_eq!((none_before, none_after), (0, 0), "probing off sends none");
    assert!(burst > 100, "the step is probed: {burst}");
    // Settled, the line needs few probes (the change test now and then, the uncertainty rule
    // at times, which sends up to 32 at once): under one per 5 cycles.
    assert!(quiet < 200, "{quiet} probes in 1 000 settled cycles");
    assert!(with < without && with < 100.0, "{with} ms vs {without} ms");
    assert!(peak_with < peak_without, "{peak_with} vs {peak_without}");
}

/// Reference follows master by its offset, the master waiting a quarter cycle for each frame;
/// every 50th cycle the master's link is down while that cycle's frame would pass: (mean
/// |change| of master − reference, taken just before each frame, across the lost frames;
/// frames lost, frames made up).
fn offset_steering_across_lost_frames(make_up: bool) -> (f64, u64, u64) {
    let mut m = segment(HostModel::pc_rt());
    let mut sync = Ferrocat::new(Coupling::ReferenceFollowsMaster, CYCLE_NS);
    sync.options_mut().lost_frames = if make_up { LostFrames::MakeUp } else { LostFrames::Wait };
    m.config().settings_mut().cyclic_timeout_ns = CYCLE_NS / 4;
    let mut st = m.clock().sync_state().unwrap();
    let mut next = m.cyclic().now_ns();
    let (mut prev, mut lost_before, mut jumps): (Option<i64>, u64, Vec<f64>) = (None, 0, Vec::new());
    for k in 0..3_000 {
        next += CYCLE_NS;
        if k % 50 == 25 {
            let down = ferrocat_segment::Event::LinkDown { node: 0, port: 0 };
            m.cyclic().io_mut().seg.schedule(next, down);
            m.cyclic().io_mut().seg.schedule(next + CYCLE_NS / 8, ferrocat_segment::Event::LinkUp { node: 0, port: 0 });
        }
        m.cyclic().sleep_until(next);
        // Just before the frame the reference has run on its crystal longest since its offset.
        let e = true_error(&mut m, 0);
        if let Some(p) = prev.filter(|_| st.lost > lost_before) {
            jumps.push((e - p).abs() as f64);
        }
        (prev, lost_before) = (Some(e), st.lost);
        m.clock().sync_step(&mut sync, &mut st).unwrap();
    }
    (jumps.iter().sum::<f64>() / jumps.len().max(1) as f64, st.lost, st.make_ups)
}

#[test]
fn a_lost_frame_is_made_up_at_once_when_the_reference_follows_by_its_offset() {
    let (with, lost, made_up) = offset_steering_across_lost_frames(true);
    let (without, lost_without, none) = offset_steering_across_lost_frames(false);
    println!(
        "master − reference across a lost frame: {with:.1} ns with make-up ({lost} lost, {made_up} made up), \
         {without:.1} ns without ({lost_without} lost)"
    );
    assert!(lost == 60 && made_up == lost && none == 0, "{lost} {made_up} {none}");
    // The reference's crystal runs 40 ppm fast and the offset centres its sawtooth: a lost
    // frame leaves it a whole cycle longer on its crystal (40 ns); made up a quarter cycle
    // later, aimed half a cycle on, it is a quarter cycle off by the next frame (10 ns).
    assert!(without > 30.0 && with < without / 2.0, "{with} vs {without}");
}

/// Reference follows master by its offset on an RT kernel, 30 s: after each cycle, the
/// reference's true error just before the next frame (where it has run on its +40 ppm crystal
/// longest since its last offset), apart for cycles with and without probes: (mean with
/// probes − mean without, its standard error, ns; probed cycles).
fn sawtooth_top_after_probes(probes_steer: bool) -> (f64, f64, usize) {
    let mut m = segment(HostModel::pc_rt());
    let mut sync = Ferrocat::new(Coupling::ReferenceFollowsMaster, CYCLE_NS);
    sync.options_mut().probes = if probes_steer { ProbeFrames::Steer } else { ProbeFrames::ReadOnly };
    sync.options_mut().followers = FollowerDelays::Measured;
    let mut st = m.clock().sync_state().unwrap();
    let mut next = m.cyclic().now_ns();
    let (mut probed, mut quiet) = (Vec::new(), Vec::new());
    for k in 0..30_000 {
        let probes_before = st.probing.sent;
        next += CYCLE_NS;
        m.cyclic().sleep_until(next);
        m.clock().sync_step(&mut sync, &mut st).unwrap();
        // Just before the next cycle's frame is built.
        m.cyclic().sleep_until(next + CYCLE_NS - 1_000);
        let e = true_error(&mut m, 0) as f64;
        if k >= 2_000 {
            if st.probing.sent > probes_before {
                probed.push(e)
            } else {
                quiet.push(e)
            }
        }
    }
    let mean = |v: &[f64]| v.iter().sum::<f64>() / v.len().max(1) as f64;
    let var_of_mean = |v: &[f64]| {
        let m = mean(v);
        v.iter().map(|x| (x - m) * (x - m)).sum::<f64>() / (v.len().max(2) - 1) as f64 / v.len().max(1) as f64
    };
    let se = (var_of_mean(&probed) + var_of_mean(&quiet)).sqrt();
    (mean(&probed) - mean(&quiet), se, probed.len())
}

#[test]
fn probes_give_the_reference_an_offset_that_holds_until_the_next_frame() {
    let (steering, se, probed) = sawtooth_top_after_probes(true);
    let (reading, se_reading, probed_reading) = sawtooth_top_after_probes(false);
    println!(
        "reference 40 ppm fast, error before the next frame, probed − unprobed cycles: {steering:.1} ± {se:.1} ns \
         with probes giving offsets ({probed} probed cycles), {reading:.1} ± {se_reading:.1} ns with probes \
         reading them ({probed_reading})"
    );
    assert!(probed > 100 && probed_reading > 100, "{probed} {probed_reading}");
    // A probe's offset is aimed halfway to the next frame, not half a cycle past its own
    // passage: the reference ends the cycle nearer the master by 40 ppm · (how much less
    // than a cycle the last probe's offset stood)/2, several ns. Probes that only read leave
    // the cycle frame's offset: probed cycles end where the others do.
    assert!(steering < -3.0 && steering < -4.0 * se, "{steering} ± {se}");
    assert!(reading.abs() < 3.0 * se_reading.max(0.5), "{reading} ± {se_reading}");
}

/// Probing counts its window from the cycle's planned start: on a host that wakes every cycle
/// 600 µs late, the probes still end before the next cycle is due (counted from the late
/// wake-up, the half cycle they may fill would run into it).
#[test]
fn probes_of_a_cycle_that_woke_late_end_before_the_next_is_due() {
    use ferrocat_segment::Latency;
    let host = HostModel { name: "late-wake", wake: Latency::fixed(600_000.0), ..HostModel::pc_rt() };
    let mut m = segment(host);
    let mut sync = Ferrocat::new(Coupling::ReferenceFollowsMaster, CYCLE_NS);
    sync.options_mut().followers = FollowerDelays::Measured;
    let mut st = m.clock().sync_state().unwrap();
    let mut next = m.cyclic().now_ns();
    let (mut latest_ns, mut probed) = (i64::MIN, 0);
    for _ in 0..300 {
        next += CYCLE_NS;
        m.cyclic().sleep_until(next);
        let probes_before = st.probing.sent;
        m.clock().sync_step(&mut sync, &mut st).unwrap();
        if st.probing.sent > probes_before {
            probed += 1;
            // How far past the next cycle's due time this one ended (negative: before it).
            latest_ns = latest_ns.max(m.cyclic().now_ns() as i64 - (next + CYCLE_NS) as i64);
        }
    }
    println!(
        "{probed} cycles probed ({} probes), the latest ended {latest_ns} ns after the next was due",
        st.probing.sent
    );
    assert!(probed > 10, "the young line probes: {probed}");
    assert!(latest_ns <= 0, "a cycle that probed ended {latest_ns} ns after the next was due");
}

/// Probing never makes the next cycle late: on a host whose stamps are quick but whose replies
/// reach the program 200 µs late, a probe costs ten times what the lead suggests, and the
/// probes wanted would fill several cycles; they stop where one more could overrun the cycle.
#[test]
fn probes_end_within_the_cycle_on_a_slow_receive_path() {
    use ferrocat_segment::{Latency, Stamps};
    let host = HostModel {
        name: "slow-receive",
        send: Latency::fixed(10_000.0),
        recv: Latency::fixed(200_000.0),
        wake: Latency::fixed(5_000.0),
        stamps: Stamps::Software { tx_early: Latency::fixed(1_000.0), rx_late: Latency::fixed(1_000.0) },
        timer_resolution_ns: 0,
        gpio: None,
    };
    let mut m = segment(host);
    let mut sync = Ferrocat::new(Coupling::ReferenceFollowsMaster, CYCLE_NS);
    // Only the cycle's frame and its probes: no writes of the followers' delays between them.
    sync.options_mut().followers = FollowerDelays::Measured;
    let mut st = m.clock().sync_state().unwrap();
    let mut next = m.cyclic().now_ns();
    let mut longest_ns = 0;
    for _ in 0..200 {
        next += CYCLE_NS;
        m.cyclic().sleep_until(next);
        // When the cycle really began: late if the one before overran.
        let began = m.cyclic().now_ns();
        let probes_before = st.probing.sent;
        m.clock().sync_step(&mut sync, &mut st).unwrap();
        // A cycle whose own writes (an offset shift to every slave) took it past its end has
        // no room for probes; those that probed must have ended within a period.
        if st.probing.sent > probes_before {
            longest_ns = longest_ns.max(m.cyclic().now_ns() - began);
        }
    }
    assert!(st.probing.sent > 0, "the young line probes");
    assert!(longest_ns <= CYCLE_NS, "a cycle that probed ended {longest_ns} ns after it began");
    assert!(st.probing.cut > 0, "the window cut probing short");
    println!(
        "probes {}, cut in {} cycles, mean {} ns, longest cycle {longest_ns} ns",
        st.probing.sent, st.probing.cut, st.probing.mean_ns
    );
}

/// ferrocat with a follower's crystal as flywheel, the master following, on a stock kernel:
/// the follower's crystal steps by +50 ppm, and 20 s later the reference's. The first is a step
/// the flywheel's crystal takes and the reference does not (the line through the reference's
/// own points takes over once the kink test tells); by the second the flywheel is in use again (its crystal's restarted line as long as the
/// direct one), and ε sees the step at
/// once. (ms until the master's estimate stayed within 100 ns of its level before each step,
/// for good before the next, and the peak distance from it.)
fn flywheel_two_steps(seed: u64) -> [(f64, f64); 2] {
    let mut m = brought_up_seeded(HostModel::pc_stock(), seed);
    let mut sync = Ferrocat::new(Coupling::MasterFollowsReference, CYCLE_NS).with_flywheel();
    // Initialised for the method: the speed counter's direction measured, the flywheel in use
    // from the start (without, its trial would still be on at the follower's step, which the
    // direct line in use then never sees).
    m.dc().init_dc_with(&DcConfig { sync0_slaves: Some(vec![]), ..DcConfig::default() }, Some(&mut sync)).unwrap();
    let mut st = m.clock().sync_state().unwrap();
    let mut next = m.cyclic().now_ns();
    let steps = [(12_000, 1), (32_000, 0)];
    let mut before = [Vec::new(), Vec::new()];
    let mut after = [Vec::new(), Vec::new()];
    for k in 0..33_000 {
        for (i, &(at, node)) in steps.iter().enumerate() {
            if k == at {
                let now = m.cyclic().now_ns();
                m.cyclic().io_mut().seg.schedule(now, ferrocat_segment::Event::DriftStep { node, delta_ppb: 50_000 });
            }
            let e_slot = if k >= at && k < at + 1_000 {
                Some(&mut after[i])
            } else if k + 1_000 >= at && k < at {
                Some(&mut before[i])
            } else {
                None
            };
            if let Some(v) = e_slot {
                let t = m.cyclic().now_ns();
                let own = m.clock().master_system_time();
                let reference = m.io().seg.nodes[0].esc.dc.as_ref().unwrap().system_at(t);
                v.push(sync.master_time(own).map_or(0.0, |e| e.wrapping_sub(reference) as i64 as f64));
            }
        }
        let c = m.clock().sync_step(&mut sync, &mut st).unwrap();
        next += c.next_period_ns.unwrap();
        m.cyclic().sleep_until(next);
    }
    [0, 1].map(|i| {
        let mean = before[i].iter().sum::<f64>() / before[i].len() as f64;
        let last_out = after[i].iter().rposition(|e| (e - mean).abs() > 100.0).map_or(0, |j| j + 1);
        let peak = after[i].iter().map(|e| (e - mean).abs()).fold(0.0, f64::max);
        (last_out as f64 * CYCLE_NS as f64 / 1e6, peak)
    })
}

#[test]
fn a_flywheel_hands_over_at_a_followers_step_and_is_back_for_the_references() {
    for seed in 1..=4 {
        let [(follower_ms, follower_peak), (reference_ms, reference_peak)] = flywheel_two_steps(seed);
        println!(
            "seed {seed}: the follower's step back within 100 ns after {follower_ms} ms (peak {follower_peak:.0} \
             ns), the reference's 20 s later after {reference_ms} ms (peak {reference_peak:.0} ns)"
        );
        // The kink test hands over once the stamps tell which crystal moved: on a stock
        // kernel, tens of ms into the follower's step (seeds 1–4: 24–25 ms; 39–162 ms with
        // the leaky contest alone).
        assert!(follower_ms < 100.0, "{follower_ms} ms");
        assert!(reference_ms < 100.0, "{reference_ms} ms");
        // In use, the flywheel takes the reference's step at ≈ 400 ns of peak; the direct line
        // (in use for good without the pull back to the flywheel: seed 1 1 354 ns) at a microsecond and more.
        assert!(reference_peak < 700.0, "{reference_peak} ns");
    }
}

/// A method that reads a follower's clock has the DC initialisation measure which way each
/// follower's speed counter moves its clock: the raw crystal rates while the loops are reset,
/// against the deviation the converged loops apply. The model slows a clock for a positive
/// SCD; crystals 85, 10 and 60 ppm from the reference's all say so. Other methods do not
/// measure it (their frames, and so every figure of theirs, stay as they were), nor does a
/// flywheel that steers the reference's offset while the loops converge.
#[test]
fn the_speed_counters_direction_is_measured_at_the_dc_initialisation() {
    let mut m = brought_up(HostModel::pc_rt());
    let mut fly = Ferrocat::new(Coupling::MasterFollowsReference, CYCLE_NS).with_flywheel();
    let report =
        m.dc().init_dc_with(&DcConfig { sync0_slaves: Some(vec![]), ..DcConfig::default() }, Some(&mut fly)).unwrap();
    assert!(report.converged);
    let measured: Vec<_> = m.slaves().iter().map(|s| s.dc().speed_diff_slows).collect();
    assert_eq!(measured, [None, Some(true), Some(true), Some(true)]);
    // Plain ferrocat reads no follower; the flywheel steering the reference's offset during
    // the compensation has its followers converge on the master's rate, and finds the
    // direction by its trial instead.
    for sync in [
        Ferrocat::new(Coupling::MasterFollowsReference, CYCLE_NS),
        Ferrocat::new(Coupling::ReferenceFollowsMaster, CYCLE_NS).with_flywheel(),
    ] {
        let mut sync = sync;
        let mut m = brought_up(HostModel::pc_rt());
        m.dc().init_dc_with(&DcConfig { sync0_slaves: Some(vec![]), ..DcConfig::default() }, Some(&mut sync)).unwrap();
        assert!(m.slaves().iter().all(|s| s.dc().speed_diff_slows.is_none()));
    }
}

/// ε = reference − follower's crystal, as the flywheel reconstructs it on the simulated ESC,
/// against the reference's time, while the follower's loop works (both crystals are fixed
/// here): (the largest residual from its least-squares line over `cycles`, its slope in ppm).
fn flywheel_eps_line(host: HostModel, coupling: Coupling, cycles: u64) -> (f64, f64) {
    let mut m = segment(host);
    let mut sync = Ferrocat::new(coupling, CYCLE_NS).with_flywheel();
    let mut st = m.clock().sync_state().unwrap();
    let mut next = m.cyclic().now_ns();
    let mut pts = Vec::new();
    let (mut last, mut first) = (None, None);
    for _ in 0..cycles {
        let c = m.clock().sync_step(&mut sync, &mut st).unwrap();
        next += c.next_period_ns.unwrap_or(CYCLE_NS);
        m.cyclic().sleep_until(next);
        let e = sync.flywheel_eps();
        if e != last {
            let (reference_ns, eps_ns) = e.unwrap();
            let from = *first.get_or_insert(reference_ns);
            pts.push((reference_ns.wrapping_sub(from) as f64, eps_ns as f64));
            last = e;
        }
    }
    let n = pts.len() as f64;
    let (mx, my) = (pts.iter().map(|p| p.0).sum::<f64>() / n, pts.iter().map(|p| p.1).sum::<f64>() / n);
    let sxy: f64 = pts.iter().map(|p| (p.0 - mx) * (p.1 - my)).sum();
    let sxx: f64 = pts.iter().map(|p| (p.0 - mx).powi(2)).sum();
    let b = sxy / sxx;
    let worst = pts.iter().map(|p| (p.1 - my - b * (p.0 - mx)).abs()).fold(0.0, f64::max);
    (worst, b * 1e6)
}

#[test]
fn the_flywheels_eps_is_a_straight_line() {
    for (host, coupling) in [
        (HostModel::pc_rt(), Coupling::MasterFollowsReference),
        (HostModel::pc_stock(), Coupling::ReferenceFollowsMaster),
        (HostModel::pc_stock(), Coupling::MasterFollowsReference),
    ] {
        let (worst, ppm) = flywheel_eps_line(host, coupling, 5_000);
        println!("{coupling:?}: ε off its line by at most {worst:.1} ns, slope {ppm:.2} ppm");
        // Two 10 ns ticks (the reference's read and the follower's); the crystals 40 and −45
        // ppm. Without the loop's corrections taken out, ε carries the follower's whole loop:
        // hundreds of ns, and the slope of the reference against the follower's steered
        // clock, 0.
        assert!(worst <= 15.0, "{worst} ns");
        assert!((ppm - 85.0).abs() < 0.05, "{ppm} ppm");
    }
}

/// ferrocat's probes over `cycles` cycles on a stock kernel, within `budget_ns` a cycle
/// (`None`: no budget); the sync state at the end.
fn probes_in_budget(budget_ns: Option<u64>, cycles: u64) -> ferrocat_master::SyncState {
    let mut m = segment(HostModel::pc_stock());
    let mut sync = Ferrocat::new(Coupling::ReferenceFollowsMaster, CYCLE_NS);
    let mut st = m.clock().sync_state().unwrap();
    st.probing.budget_ns = budget_ns;
    let mut next = m.cyclic().now_ns();
    for _ in 0..cycles {
        next += CYCLE_NS;
        m.cyclic().sleep_until(next);
        m.clock().sync_step(&mut sync, &mut st).unwrap();
    }
    st
}

#[test]
fn probing_keeps_to_its_budget_on_average() {
    const CYCLES: u64 = 3000;
    let free = probes_in_budget(None, CYCLES);
    let budget_ns = 20_000;
    let held = probes_in_budget(Some(budget_ns), CYCLES);
    println!(
        "no budget: {} probes (mean {} ns); {budget_ns} ns a cycle: {} probes, {} not funded",
        free.probing.sent, free.probing.mean_ns, held.probing.sent, held.probing.unfunded
    );
    assert_eq!(free.probing.unfunded, 0);
    assert!(held.probing.sent > 0 && held.probing.unfunded > 0, "{held:?}");
    // The time spent probing: at most the budget of every cycle, and one window saved up.
    let spent_ns = held.probing.sent * held.probing.mean_ns;
    assert!(spent_ns <= budget_ns * CYCLES + CYCLE_NS, "{spent_ns} ns probing for {} ns of budget", budget_ns * CYCLES);
    assert!(
        held.probing.sent < free.probing.sent,
        "the budget bound: {} against {}",
        held.probing.sent,
        free.probing.sent
    );
}

/// Three slaves brought up behind a master link of 300 µs each way: a round trip of about
/// 620 µs, most of a 1 ms cycle.
fn slow_segment() -> Master<VirtualIo> {
    let cfg: SegmentConfig = toml::from_str(
        "seed = 5\nmaster_link_ns = 300000\n[[device]]\nbuiltin = 'EK1100'\ndrift_ppm = 40.0\n\
         [[device]]\nbuiltin = 'EL2004'\ndrift_ppm = -45.0\nesc = 'et1100'\nsync_unit = true\n\
         [[device]]\nbuiltin = 'EL1004'\ndrift_ppm = 20.0\nesc = 'et1100'\nsync_unit = true\n",
    )
    .unwrap();
    let mut m = Master::new(VirtualIo::new(cfg.build().unwrap(), HostModel::pc_rt(), 5));
    m.states().bring_up().unwrap();
    m
}

/// Park's method over 1 500 cycles of 1 ms on a segment whose master link makes the round trip
/// most of the cycle, through `cycle_sync` (the image's LRW with the sync datagrams), the
/// loop's period told to the master (`period_ns`, 0: none); the cycles whose work ran past
/// their period, and how far the corrections moved the last clock's System_Time_Offset (ns).
fn park_on_a_slow_segment(period_ns: u64) -> (u32, i64) {
    let mut m = slow_segment();
    m.dc().init_dc(&DcConfig { sync0_slaves: Some(vec![]), ..DcConfig::default() }).unwrap();
    let d = m.clock().park_delay(100).unwrap();
    let mut sync = Park2020::new(d);
    m.states().start().unwrap();
    let offset_before = u64::from_le_bytes(m.io().seg.nodes[2].esc.peek(0x0920, 8).try_into().unwrap());
    m.cyclic().set_period_ns(period_ns);
    let mut st = m.clock().sync_state().unwrap();
    let mut next = m.cyclic().now_ns();
    let mut late = 0;
    for _ in 0..1500 {
        next += CYCLE_NS;
        m.cyclic().sleep_until(next);
        m.cyclic().cycle_sync(&mut sync, &mut st).unwrap();
        late += (m.cyclic().now_ns() > next + CYCLE_NS) as u32;
    }
    // How far Park's corrections moved the last clock's offset, from the simulator's register.
    let offset =
        |m: &Master<VirtualIo>| u64::from_le_bytes(m.io().seg.nodes[2].esc.peek(0x0920, 8).try_into().unwrap());
    (late, offset(&m).wrapping_sub(offset_before) as i64)
}

#[test]
fn on_a_slow_segment_the_methods_writes_ride_on_the_cyclic_frames() {
    // Park's correction every 100 ms reads and writes every offset: two more frames of ≈ 620 µs
    // each, a late cycle each time, where the master knows no period to fit them in.
    let (late_alone, moved_alone) = park_on_a_slow_segment(0);
    // Told the period, the master sees no room for them and sends them on the next cyclic
    // frames instead: the offsets read on one, written shifted on the next.
    let (late_riding, moved_riding) = park_on_a_slow_segment(CYCLE_NS);
    println!(
        "late cycles {late_alone} in frames of their own, {late_riding} riding; the offset moved {moved_alone} and {moved_riding} ns"
    );
    assert!(late_alone >= 10, "{late_alone} late cycles with frames of their own");
    assert_eq!(late_riding, 0);
    // The corrections land either way, the same way and about as far (a frame or two later
    // riding, so not to the ns).
    assert!(moved_alone.signum() == moved_riding.signum() && moved_alone != 0, "{moved_alone} and {moved_riding} ns");
    assert!((moved_alone - moved_riding).abs() * 4 < moved_alone.abs(), "{moved_alone} and {moved_riding} ns");
}

/// ferrocat steering the reference's offset on the slow segment, the period told: the
/// followers' delay bias rides on the cyclic frames; no cycle is late and every clock ends
/// within 1 µs of the master's. (A shift and a bias on one frame: `dc_writes`' unit tests.)
#[test]
fn on_a_slow_segment_ferrocats_writes_ride_too() {
    let mut m = slow_segment();
    let method = ferrocat_master::sync::SyncMethod::default();
    let dc = DcConfig { sync0_slaves: Some(vec![]), ..DcConfig::default() };
    let (mut sync, _, mut st) = m.clock().start_clock_sync(&dc, &method, CYCLE_NS).unwrap();
    m.states().start().unwrap();
    m.cyclic().set_period_ns(CYCLE_NS);
    let mut next = m.cyclic().now_ns();
    let mut late = 0;
    for _ in 0..3000 {
        next += CYCLE_NS;
        m.cyclic().sleep_until(next);
        m.cyclic().cycle_sync(sync.as_mut(), &mut st).unwrap();
        late += (m.cyclic().now_ns() > next + CYCLE_NS) as u32;
    }
    let errors: Vec<i64> = (0..3).map(|k| true_error(&mut m, k)).collect();
    println!("late cycles {late}; clocks − master {errors:?} ns; lock {:?}", st.lock.state());
    assert_eq!(late, 0);
    assert!(errors.iter().all(|e| e.abs() < 1_000), "{errors:?}");
}
