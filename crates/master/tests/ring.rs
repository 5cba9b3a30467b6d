//! Cable redundancy: the master on both ends of a ring (two couplers with a terminal each, the
//! second coupler's X2 OUT back to the master's secondary port). It finds the port the ring
//! closes through and measures a line's delays; the process data keeps its whole working
//! counter when a cable in the ring is pulled; and the split ring's far half keeps its clocks
//! by holding over instead of taking a reference time a master round trip old, together behind
//! its own first clock.
use ferrocat_master::{DcConfig, Master};
use ferrocat_master::{RingState, SplitRingClocks};
use ferrocat_segment::{Event, SegmentConfig};
use ferrocat_segment::{HostModel, Tamper, VirtualIo};

const DEVICES: &str = "seed = 5\n[[device]]\nbuiltin = 'EK1100'\n[[device]]\nbuiltin = 'EL2004'\n\
    [[device]]\nbuiltin = 'EK1100'\nparent = 0\nsync_unit = true\n[[device]]\nbuiltin = 'EL2004'\n";
const RING: &str = "[secondary]\ndevice = 2\n";

fn master(toml: &str, host: HostModel) -> Master<VirtualIo> {
    let cfg: SegmentConfig = toml::from_str(toml).unwrap();
    Master::new(VirtualIo::new(cfg.build().unwrap(), host, 5))
}

#[test]
fn the_ring_port_is_found_and_the_delays_are_a_lines() {
    let mut line = master(DEVICES, HostModel::ideal());
    line.states().scan().unwrap();
    let mut ring = master(&format!("{DEVICES}{RING}"), HostModel::ideal());
    ring.states().scan().unwrap();
    assert_eq!(ring.diagnosis().ring_state(), RingState::Intact);
    assert_eq!(ring.dc().ring_port(), Some((2, 2)), "the second coupler's X2 OUT");
    assert_eq!(line.dc().ring_port(), None);
    let delays = |m: &Master<VirtualIo>| {
        m.slaves().iter().map(|s| (s.ports().parent, s.ports().parent_port, s.dc().delay_ns)).collect::<Vec<_>>()
    };
    println!("ring {:?}\nline {:?}", delays(&ring), delays(&line));
    assert_eq!(delays(&ring), delays(&line));
    // And they are the true ones: the second coupler's processing unit 805 ns after the first's
    // (E-Bus out and back through the EL2004 and the coupler, then 100BASE-TX).
    assert_eq!(ring.slaves()[2].dc().delay_ns, 805);
    // On the line the frame loops at the closed port (20 ns), goes back to the first coupler
    // (420 ns of 100BASE-TX), through it (65 ns) and to the master (500 ns); on the ring it
    // leaves by that port for the secondary (500 ns): back 505 ns sooner.
    assert_eq!(ring.dc().ring_shortening_ns(), 505);
}

/// Brings the ring to OP with DC and runs `cycles` 1 ms cycles; the cable between the couplers
/// is pulled after the first `break_after`. Returns the master and, per cycle after the break,
/// the second coupler's true system time less the first's.
fn run_split(clocks: SplitRingClocks, cycles: u64, break_after: u64) -> (Master<VirtualIo>, Vec<i64>) {
    let mut m = master(&format!("{DEVICES}{RING}"), HostModel::pc_rt());
    m.dc().set_split_ring_clocks(clocks);
    m.states().bring_up().unwrap();
    let r = m.dc().init_dc(&DcConfig::default()).unwrap();
    assert!(r.converged, "{r:?}");
    let t0 = m.cyclic().now_ns();
    m.cyclic().io_mut().seg.schedule(t0 + break_after * 1_000_000, Event::LinkDown { node: 2, port: 0 });
    let mut after = Vec::new();
    let mut next = t0;
    for k in 0..cycles {
        assert_eq!(
            m.cyclic().cycle().unwrap(),
            m.image().expected_wkc(),
            "cycle {k}: the whole ring's working counter"
        );
        next += 1_000_000;
        m.cyclic().sleep_until(next);
        if k > break_after {
            let now = m.cyclic().now_ns();
            let t = m.io().seg.system_times_at(now);
            after.push(t[1].wrapping_sub(t[0]) as i64);
        }
    }
    (m, after)
}

#[test]
fn process_data_goes_on_across_a_pulled_ring_cable() {
    let (mut m, _) = run_split(SplitRingClocks::HoldOver, 400, 200);
    assert_eq!(m.diagnosis().ring_state(), RingState::Broken);
    assert!(m.cyclic().frame_stats().resent >= 198, "{:?}", m.cyclic().frame_stats());
    // The far half's terminal still takes its outputs: its SyncManager saw every cycle.
    let stats = m.diagnosis().cycle_stats();
    assert_eq!(stats.wkc_errors, 0, "{stats:?}");
    // Said once.
    let said: Vec<String> = m.diagnosis().events().iter().map(|e| e.to_string()).collect();
    assert_eq!(said, ["ring broken: the slaves behind the break are served from the secondary port"]);
}

#[test]
fn the_far_half_of_a_split_ring_holds_its_clock() {
    let (_, hold) = run_split(SplitRingClocks::HoldOver, 1200, 200);
    let (_, stale) = run_split(SplitRingClocks::AsSent, 1200, 200);
    let worst = |v: &[i64]| v.iter().map(|d| d.abs()).max().unwrap();
    let last = |v: &[i64]| *v.last().unwrap();
    println!(
        "second coupler's true time less the reference's over 1 s after the break: hold-over worst {} ns (last {}), \
         as sent (SOEM) worst {} ns (last {})",
        worst(&hold),
        last(&hold),
        worst(&stale),
        last(&stale)
    );
    // Held over, the far half's clock runs at the rate its time control loop last set.
    assert!(worst(&hold) < 200, "{}", worst(&hold));
    // Given the reference time of the first pass, it is pulled back by the master's round
    // trip between the two passes, microseconds on this host.
    assert!(worst(&stale) > 10 * worst(&hold).max(100), "{} vs {}", worst(&stale), worst(&hold));
}

/// Reference-follows-master with ferrocat's method on the ring; the cable between the couplers
/// pulled halfway. Returns the master-minus-reference and master-minus-far-coupler true errors'
/// means (ns) before and after the break.
fn ferrocat_across_a_break(host: HostModel) -> [(f64, f64); 2] {
    use ferrocat_master::sync::{Coupling, Ferrocat};
    let mut m = master(&format!("{DEVICES}{RING}"), host);
    // A closed port's loop-back, as the lab tells the master (ferrocat_lab::loop_back_ns).
    m.config().settings_mut().closed_port_loop_ns = 20;
    m.states().bring_up().unwrap();
    m.dc().init_dc(&DcConfig { sync0_slaves: Some(vec![]), ..DcConfig::default() }).unwrap();
    let mut sync = Ferrocat::new(Coupling::ReferenceFollowsMaster, 1_000_000);
    let mut st = m.clock().sync_state().unwrap();
    let mut next = m.cyclic().now_ns();
    m.cyclic().io_mut().seg.schedule(next + 4_000_000_000, Event::LinkDown { node: 2, port: 0 });
    let mut errs = [(Vec::new(), Vec::new()), (Vec::new(), Vec::new())];
    for k in 0..8000u64 {
        next += 1_000_000;
        m.cyclic().sleep_until(next);
        m.clock().sync_step(&mut sync, &mut st).unwrap();
        if k % 4000 >= 2000 {
            let t = m.cyclic().now_ns();
            let master = m.clock().master_system_time();
            let clocks = m.io().seg.system_times_at(t);
            let half = &mut errs[(k / 4000) as usize];
            half.0.push(master.wrapping_sub(clocks[0]) as i64 as f64);
            half.1.push(master.wrapping_sub(clocks[1]) as i64 as f64);
        }
    }
    let mean = |v: &[f64]| v.iter().sum::<f64>() / v.len() as f64;
    errs.map(|(r, f)| (mean(&r), mean(&f)))
}

/// The frame of a broken ring turns where the link is gone, so the loop behind the reference
/// changes: measured again at the break, the master keeps its relation to the reference (the
/// loop of the intact ring, kept, moved it by 387 ns under nic-hwts and 411 ns under pc-rt).
#[test]
fn a_master_leading_the_reference_keeps_it_across_a_break() {
    for (host, bound_ns) in [(HostModel::nic_hwts(), 30.0), (HostModel::pc_rt(), 100.0)] {
        let [before, after] = ferrocat_across_a_break(host);
        println!(
            "{}: master − reference {:.1} ns before the break, {:.1} ns after; master − far coupler {:.1}, {:.1} ns",
            host.name, before.0, after.0, before.1, after.1
        );
        assert!((after.0 - before.0).abs() < bound_ns, "{}: {before:?} → {after:?}", host.name);
    }
}

/// The cable between the couplers pulled before the master starts.
const BROKEN_FROM_START: &str = "[[event]]\nat_ms = 0\nlink_down = { device = 2, port = 0 }\n";

/// A ring already broken when the master starts: the second passes count and address the far
/// half, so the scan finds every slave and the whole ring reaches OP and exchanges its
/// process data.
#[test]
fn a_ring_broken_at_start_up_comes_up_whole() {
    let mut m = master(&format!("{DEVICES}{RING}{BROKEN_FROM_START}"), HostModel::pc_rt());
    m.states().bring_up().unwrap();
    assert_eq!(m.slaves().len(), 4);
    assert_eq!(m.diagnosis().ring_state(), RingState::Broken);
    assert_eq!(m.dc().ring_port(), None);
    let mut next = m.cyclic().now_ns();
    for _ in 0..100 {
        assert_eq!(m.cyclic().cycle().unwrap(), m.image().expected_wkc());
        next += 1_000_000;
        m.cyclic().sleep_until(next);
    }
    assert_eq!(m.image().expected_wkc(), 4, "both EL2004s written");
}

/// A ring broken at start-up whose first probe comes back too late: the scan's count does not
/// stop at the near half (before, it found 2 of the 4 slaves, as `ferrocat scan` once did over
/// veth while the machine was busy compiling), but counts again until a probe is back.
#[test]
fn a_late_first_probe_does_not_hide_the_far_half_of_a_broken_ring() {
    let cfg: SegmentConfig = toml::from_str(&format!("{DEVICES}{RING}{BROKEN_FROM_START}")).unwrap();
    // The first frame back on the secondary port (the first probe's answer) never arrives: a
    // probe later than the engine waits, as a slow or busy segment gives.
    let lost = std::rc::Rc::new(std::cell::Cell::new(0));
    let held_back = lost.clone();
    let hook = move |_: &mut [u8], n: usize, secondary: bool| {
        if secondary && held_back.get() == 0 {
            held_back.set(1);
            return None;
        }
        Some(n)
    };
    let mut m = Master::new(Tamper { inner: VirtualIo::new(cfg.build().unwrap(), HostModel::pc_rt(), 5), hook });
    m.states().scan().unwrap();
    assert_eq!(lost.get(), 1, "the first probe's answer was held back");
    assert_eq!(m.slaves().len(), 4);
    assert_eq!(m.diagnosis().ring_state(), RingState::Broken);
}

/// The ring `toml` under `host`, in OP with DC, `events` scheduled (ns after that), then one
/// cycle a millisecond for `cycles`, each with the whole working counter; `each(k, clocks)`
/// gets the true system times after cycle `k`.
fn cycle_ring(
    toml: &str,
    host: HostModel,
    clocks: SplitRingClocks,
    events: &[(u64, Event)],
    cycles: u64,
    each: impl FnMut(u64, &[u64]),
) -> Master<VirtualIo> {
    cycle_ring_every(toml, host, clocks, events, cycles, 1_000_000, each)
}

/// [`cycle_ring`] with cycles of `cycle_ns`.
fn cycle_ring_every(
    toml: &str,
    host: HostModel,
    clocks: SplitRingClocks,
    events: &[(u64, Event)],
    cycles: u64,
    cycle_ns: u64,
    mut each: impl FnMut(u64, &[u64]),
) -> Master<VirtualIo> {
    let mut m = master(toml, host);
    m.dc().set_split_ring_clocks(clocks);
    m.states().bring_up().unwrap();
    assert!(m.dc().init_dc(&DcConfig::default()).unwrap().converged);
    let t0 = m.cyclic().now_ns();
    for (at, event) in events {
        m.cyclic().io_mut().seg.schedule(t0 + at, event.clone());
    }
    let mut next = t0;
    for k in 0..cycles {
        assert_eq!(m.cyclic().cycle().unwrap(), m.image().expected_wkc(), "cycle {k}");
        next += cycle_ns;
        m.cyclic().sleep_until(next);
        let now = m.cyclic().now_ns();
        each(k, &m.io().seg.system_times_at(now));
    }
    m
}

/// Behind the break, two clocks (the far coupler and its terminal, both with a system time),
/// the terminal warming up by 1 ppm 2 s after the break: with the far coupler as the far
/// half's reference they keep together while the ring is split; held over each on its own
/// they drift apart. Returns the worst |terminal − coupler| over 10 s after the break, and
/// after the ring is closed again the worst over the last second of 2 s.
fn far_half_spread(clocks: SplitRingClocks) -> (i64, i64) {
    let s = 1_000_000_000;
    let events = [
        (s, Event::LinkDown { node: 2, port: 0 }),
        (3 * s, Event::DriftStep { node: 3, delta_ppb: 1_000 }),
        (11 * s, Event::LinkUp { node: 2, port: 0 }),
    ];
    let toml = format!("{DEVICES}sync_unit = true\ndrift_ppm = 30.0\n{RING}");
    let (mut split, mut closed) = (0i64, 0i64);
    let mut m = cycle_ring(&toml, HostModel::pc_rt(), clocks, &events, 13_000, |k, t| {
        // The coupler's and the terminal's (an ET1200: 32 bits) system times.
        let apart = ((t[2] as u32).wrapping_sub(t[1] as u32) as i32 as i64).abs();
        if (1_001..11_000).contains(&k) {
            split = split.max(apart);
        } else if k >= 12_000 {
            closed = closed.max(apart);
        }
    });
    assert_eq!(m.diagnosis().ring_state(), RingState::Intact);
    (split, closed)
}

#[test]
fn the_far_half_keeps_together_behind_its_own_reference() {
    let (far, far_closed) = far_half_spread(SplitRingClocks::FarReference);
    let (apart, apart_closed) = far_half_spread(SplitRingClocks::HoldOver);
    println!(
        "far terminal − far coupler, worst over 10 s split: {far} ns following the far coupler, {apart} ns each held \
         over; after the ring closed again: {far_closed} and {apart_closed} ns"
    );
    // Seeds 1–12: 35–87 ns following, 7.2–9.0 µs held over (without a warm-up, held over
    // without a change after the break gives as little as 26 ns).
    assert!(far < 100, "{far}");
    assert!(apart > 20 * far, "{apart} vs {far}");
    // Closed again, the delays are the reference's once more: back together either way.
    assert!(far_closed < 50 && apart_closed < 50, "{far_closed}, {apart_closed}");
}

/// A ring split for `split_s` seconds (pulled 1 s in), the far coupler's crystal 3 ppm faster
/// from 3 s on (it warms up): per 100 ms, the worst |far coupler − reference| true error over
/// it; and the offset the master added to the far coupler.
fn far_reference_error(clocks: SplitRingClocks, host: HostModel, split_s: u64) -> (Vec<i64>, i64) {
    let s = 1_000_000_000;
    let events = [(s, Event::LinkDown { node: 2, port: 0 }), (3 * s, Event::DriftStep { node: 2, delta_ppb: 3_000 })];
    let mut worst = Vec::new();
    let mut m = cycle_ring(&format!("{DEVICES}{RING}"), host, clocks, &events, (1 + split_s) * 1000, |k, t| {
        if k > 1000 {
            let e = (t[1].wrapping_sub(t[0]) as i64).abs();
            if (k - 1001) % 100 == 0 {
                worst.push(e);
            } else if let Some(w) = worst.last_mut() {
                *w = (*w).max(e);
            }
        }
    });
    assert_eq!(m.diagnosis().ring_state(), RingState::Broken);
    (worst, m.dc().far_reference().map_or(0, |f| f.offset_ns))
}

/// Split for 30 s, the far coupler warming up by 3 ppm 2 s after the break: kept through
/// its offset, it stays on the reference's time, where held over it drifts tens of µs away.
#[test]
fn the_far_reference_of_a_split_ring_is_kept_on_the_reference() {
    let worst = |v: &[i64]| *v.iter().max().unwrap();
    for host in [HostModel::nic_hwts(), HostModel::pc_rt()] {
        let (kept, added) = far_reference_error(SplitRingClocks::FarReference, host, 30);
        let (held, _) = far_reference_error(SplitRingClocks::FarReferenceHeld, host, 30);
        // Per 100 ms: the 2 s before the warm-up, the 3 s after it, and the rest.
        let (kept_before, kept_step, kept_after) = (worst(&kept[..20]), worst(&kept[20..50]), worst(&kept[50..]));
        println!(
            "{}: far coupler − reference, worst |·| kept: {kept_before} ns over the 2 s after the break, \
             {kept_step} ns over the 3 s after the warm-up, {kept_after} ns over the 25 s after that; \
             held over: {} ns, {} ns, {} ns; offset added {added} ns",
            host.name,
            worst(&held[..20]),
            worst(&held[20..50]),
            worst(&held[50..])
        );
        assert!(kept_before <= worst(&held[..20]).max(150), "{kept_before} vs {:?}", &held[..20]);
        assert!(kept_step < 1_000, "{kept_step}");
        // Segment and host seeds 5–17: 20–23 ns under nic-hwts; 22–70 ns under pc-rt but for
        // two draws, 146 and 234 ns — a steady offset over the 25 s, the error of the level at
        // the break that 2 s of software-stamped samples fixed (a bias no later sample shows,
        // far_clock.rs).
        assert!(kept_after < if host.name == "nic-hwts" { 100 } else { 300 }, "{kept_after}");
        assert!(worst(&held[50..]) > 100 * kept_after, "{} vs {kept_after}", worst(&held[50..]));
        // What was added is what held over drifted.
        let drifted = *held.last().unwrap();
        assert!((added + drifted).abs() < 200, "added {added} ns, held over drifted {drifted} ns");
    }
}

/// Cycles longer than the far reference's moves are apart (15 ms against 10 ms): each move
/// takes up all the drift since the last, so the far coupler, 3 ppm fast from 2 s after the
/// break, stays with the reference over the last 20 s of 30 (316 ns at worst: 67 samples a
/// second leave the line unsettled, moved only by errors it shows); a move limited to one
/// interval's drift fell behind by 0.7 ppm, 19.5 µs by the end.
#[test]
fn the_far_reference_is_kept_with_cycles_longer_than_its_moves_apart() {
    let s = 1_000_000_000;
    let events = [(s, Event::LinkDown { node: 2, port: 0 }), (3 * s, Event::DriftStep { node: 2, delta_ppb: 3_000 })];
    let (mut worst, cycle_ns) = (0i64, 15_000_000);
    let mut m = cycle_ring_every(
        &format!("{DEVICES}{RING}"),
        HostModel::pc_rt(),
        SplitRingClocks::FarReference,
        &events,
        30 * s / cycle_ns,
        cycle_ns,
        |k, t| {
            if k * cycle_ns > 10 * s {
                worst = worst.max((t[1].wrapping_sub(t[0]) as i64).abs());
            }
        },
    );
    println!("15 ms cycles: far coupler − reference worst {worst} ns over the last 20 s");
    assert_eq!(m.diagnosis().ring_state(), RingState::Broken);
    assert!(worst < 500, "{worst}");
}

/// (parent, parent port, delay) of every slave.
type Wiring = Vec<(Option<u16>, u8, u32)>;

fn wiring(m: &Master<VirtualIo>) -> Wiring {
    m.slaves().iter().map(|s| (s.ports().parent, s.ports().parent_port, s.dc().delay_ns)).collect()
}

/// The true delays behind a split ring's break, from one more cycle: each far slave's
/// processing unit's time on the far half's pass (the secondary's, a cycle's last frame) less
/// the far reference's — for a terminal with receive times only, its port 0's time, which the
/// master takes for its processing unit's (as `delays.rs` does).
fn far_pass_truth(m: &mut Master<VirtualIo>, far_ref: usize) -> Vec<Option<i64>> {
    m.cyclic().cycle().unwrap();
    let visits = m.io().seg.last_visits();
    let first_far = m.dc().split_latch().expect("a split ring").first_far;
    assert!(visits.iter().all(|(n, _)| *n >= first_far), "the far half's pass: {visits:?}");
    let at = |n: usize| {
        let (_, t) = visits.iter().find(|(k, _)| *k == n)?;
        let clock = m.slaves()[n].dc().has_system_time;
        Some(if clock { t.epu_ns } else { t.port_ns[0]? } as i64)
    };
    let r = at(far_ref).expect("the far reference on the far pass");
    (0..m.slaves().len()).map(|n| at(n).map(|e| e - r)).collect()
}

/// The intact ring's tree (parents and ports) and delays to within the receive times' 10 ns
/// ticks: a latch taken at another instant may halve a loop one tick the other way (5 ns).
fn assert_wiring_as_intact(got: &Wiring, intact: &Wiring) {
    let tree = |w: &Wiring| w.iter().map(|&(p, port, _)| (p, port)).collect::<Vec<_>>();
    assert_eq!(tree(got), tree(intact), "tree: {got:?} vs {intact:?}");
    for (g, i) in got.iter().zip(intact) {
        assert!((g.2 as i64 - i.2 as i64).abs() <= 10, "delays: {got:?} vs {intact:?}");
    }
}

/// A ring split before the master starts: the far half is latched from the secondary, its
/// delays from its own reference, and its offsets written for when the second pass passed
/// it; the far coupler, 3 ppm faster from 2 s on, is kept on the reference's time from the
/// latch's geometry (there was no break to learn it from). Per 100 ms over 10 s, the worst
/// |far coupler − reference| true error; the far terminal's delay less the far coupler's.
/// `seed` draws the crystals (the far coupler's 0.7 ppm off the reference with seed 5, 6–30
/// ppm with 6–10).
fn split_from_the_start(clocks: SplitRingClocks, host: HostModel, seed: u64) -> (Vec<i64>, i64) {
    let s = 1_000_000_000;
    let events = [(2 * s, Event::DriftStep { node: 2, delta_ppb: 3_000 })];
    let toml = format!("{DEVICES}sync_unit = true\ndrift_ppm = 30.0\n{RING}{BROKEN_FROM_START}")
        .replace("seed = 5", &format!("seed = {seed}"));
    let mut worst = Vec::new();
    let mut m = cycle_ring(&toml, host, clocks, &events, 10_000, |k, t| {
        let e = (t[1].wrapping_sub(t[0]) as i64).abs();
        if k % 100 == 0 {
            worst.push(e);
        } else if let Some(w) = worst.last_mut() {
            *w = (*w).max(e);
        }
    });
    assert_eq!(m.diagnosis().ring_state(), RingState::Broken);
    let latch = m.dc().split_latch().expect("the latch saw the split");
    assert_eq!((latch.first_far, latch.root, latch.root_port, latch.far_reference), (2, 2, 2, Some(2)));
    let far = wiring(&m);
    assert_eq!(far[2].0, None, "the far coupler is the far tree's root");
    (worst, far[3].2 as i64 - far[2].2 as i64)
}

#[test]
fn a_ring_split_from_the_start_has_its_far_half_on_the_references_time() {
    let mut intact = master(&format!("{DEVICES}{RING}"), HostModel::ideal());
    intact.states().scan().unwrap();
    let intact_apart = intact.slaves()[3].dc().delay_ns as i64 - intact.slaves()[2].dc().delay_ns as i64;
    let worst = |v: &[i64]| *v.iter().max().unwrap();
    for (host, seed) in
        [HostModel::nic_hwts(), HostModel::pc_rt()].into_iter().flat_map(|h| (5..=8).map(move |s| (h, s)))
    {
        let (kept, apart) = split_from_the_start(SplitRingClocks::FarReference, host, seed);
        let (held, _) = split_from_the_start(SplitRingClocks::FarReferenceHeld, host, seed);
        println!(
            "{} seed {seed}: split from the start, far coupler − reference worst |·| kept: {} ns over the first \
             100 ms, {} ns over the first 2 s, {} ns over \
             the 3 s after a 3 ppm warm-up, {} ns over the 5 s after; held over: {} ns, {} ns, {} ns; far terminal \
             {apart} ns behind the far coupler ({intact_apart} ns on the intact ring)",
            host.name,
            kept[0],
            worst(&kept[..20]),
            worst(&kept[20..50]),
            worst(&kept[50..]),
            worst(&held[..20]),
            worst(&held[20..50]),
            worst(&held[50..])
        );
        // The far half's delays are those of the intact ring, less the far coupler's.
        assert_eq!(apart, intact_apart);
        // Written for the second pass's instant (a master round trip off before: 19 µs under
        // nic-hwts, 24 µs under pc-rt). Held over, the far coupler runs at its own crystal's
        // rate, never having followed the reference; kept, from the line the static drift
        // compensation's frames began, which knows that rate (a new line for the cycles would
        // let the far coupler drift for its first 128 samples: up to 3.8 µs at 30 ppm, seed 8;
        // seed 5's 0.7 ppm hides it).
        assert!(kept[0] < 150, "{kept:?}");
        assert!(worst(&kept[..20]) < 250, "{kept:?}");
        assert!(worst(&kept[20..50]) < 1_000, "{kept:?}");
        assert!(worst(&kept[50..]) < 100, "{kept:?}");
        assert!(worst(&held[50..]) > 10 * worst(&kept[50..]).max(100), "{held:?}");
    }
}

/// Split from the start and the cable back 3 s in: the ports at the break wait closed
/// (auto-close) until the master sees their link and opens them, then the far half is latched
/// again from the reference (the port the secondary's cable comes in by closed as a line's
/// end) before any clock is distributed round the closed ring. The ring's port, its shortening
/// and every delay are what a scan of the intact ring finds, and the far coupler never takes
/// the reference's time with its old delay (805 ns off: 263 ns away when the ring closed by
/// itself).
#[test]
fn a_ring_split_from_the_start_takes_the_references_delays_when_it_closes() {
    let mut intact = master(&format!("{DEVICES}{RING}"), HostModel::nic_hwts());
    intact.states().scan().unwrap();
    let s = 1_000_000_000;
    let events = [(3 * s, Event::LinkUp { node: 2, port: 0 })];
    // Four crystal draws: the far coupler 0.7 ppm off the reference with seed 5, 15–30 ppm
    // with 6–8.
    for seed in 5..=8 {
        let toml = format!("{DEVICES}{RING}{BROKEN_FROM_START}").replace("seed = 5", &format!("seed = {seed}"));
        let (mut transient, mut after) = (0i64, 0i64);
        let mut m = cycle_ring(&toml, HostModel::nic_hwts(), SplitRingClocks::FarReference, &events, 6_000, |k, t| {
            let e = (t[1].wrapping_sub(t[0]) as i64).abs();
            if k >= 5_000 {
                after = after.max(e);
            } else if k >= 3_000 {
                transient = transient.max(e);
            }
        });
        println!(
            "seed {seed}: closed after a split from the start: far coupler − reference worst {transient} ns over \
             the 2 s after, {after} ns over the next second"
        );
        assert_eq!(m.diagnosis().ring_state(), RingState::Intact);
        assert_eq!(m.dc().split_latch(), None);
        assert_eq!(
            (m.dc().ring_port(), m.dc().ring_shortening_ns()),
            (intact.dc().ring_port(), intact.dc().ring_shortening_ns())
        );
        assert_wiring_as_intact(&wiring(&m), &wiring(&intact));
        // Split from the start, the far coupler never followed the reference: the master kept
        // it by its offset, and its own loop takes up its crystal's whole offset once the
        // reference's time reaches it (about 16 ns per ppm, gone within half a second; 22,
        // 125, 364 and 489 ns measured).
        assert!(transient < 600 && after < 50, "{transient}, {after}");
    }
}

/// Three couplers with a terminal each, the third's X2 OUT back to the secondary port, split
/// from the start between the first and the second: the far tree's root is the third coupler
/// (entered by its X2 port), the far reference the second coupler hanging on the root's X1
/// port — processed first, on the frame's way back. Returns (parent, port, delay) of every
/// slave after `init_dc`, the worst |far coupler − reference| of both far couplers over the
/// first 3 s, the 2 s after the cable is put back and the second after, and the master at the end.
#[allow(clippy::type_complexity)]
fn three_couplers_split_from_the_start(
    host: HostModel,
    seed: u64,
) -> (Wiring, Vec<Option<i64>>, [i64; 3], Master<VirtualIo>) {
    let toml = format!("{THREE_COUPLERS}[[event]]\nat_ms = 0\nlink_down = {{ device = 2, port = 0 }}\n")
        .replace("seed = 5", &format!("seed = {seed}"));
    let s = 1_000_000_000;
    let mut worst = [0i64; 3];
    let m = cycle_ring(
        &toml,
        host,
        SplitRingClocks::FarReference,
        &[(3 * s, Event::LinkUp { node: 2, port: 0 })],
        6_000,
        |k, t| {
            let e = [1, 2].map(|c| (t[c].wrapping_sub(t[0]) as i64).abs()).into_iter().max().unwrap();
            let w = &mut worst[usize::from(k >= 3_000) + usize::from(k >= 5_000)];
            *w = (*w).max(e);
        },
    );
    // (The wiring as init_dc left it is gone once the ring closed: cycle_ring's callback sees
    // only clocks, so the split latch's view is checked by a second bring-up.)
    let mut again = master(&toml, host);
    again.states().bring_up().unwrap();
    again.dc().init_dc(&DcConfig::default()).unwrap();
    let l = again.dc().split_latch().unwrap();
    assert_eq!((l.first_far, l.root, l.root_port, l.far_reference), (2, 4, 2, Some(2)));
    let split = wiring(&again);
    let truth = far_pass_truth(&mut again, 2);
    (split, truth, worst, m)
}

const THREE_COUPLERS: &str = "seed = 5\n[[device]]\nbuiltin = 'EK1100'\n[[device]]\nbuiltin = 'EL2004'\n\
    [[device]]\nbuiltin = 'EK1100'\nparent = 0\n[[device]]\nbuiltin = 'EL2004'\n\
    [[device]]\nbuiltin = 'EK1100'\nparent = 2\n[[device]]\nbuiltin = 'EL2004'\n[secondary]\ndevice = 4\n";

#[test]
fn a_longer_ring_split_from_the_start_roots_its_far_tree_where_the_secondary_comes_in() {
    for (host, seed) in
        [HostModel::nic_hwts(), HostModel::pc_rt()].into_iter().flat_map(|h| (5..=8).map(move |s| (h, s)))
    {
        let mut intact = master(THREE_COUPLERS, host);
        intact.states().scan().unwrap();
        let whole = wiring(&intact);
        let (split, truth, worst, mut m) = three_couplers_split_from_the_start(host, seed);
        println!(
            "{} seed {seed}: intact {whole:?}\n  split {split:?}\n  true on the far pass {truth:?}\n  worst |far couplers − \
             reference| {} ns over the first 3 s, {} ns over the 2 s after the cable is back, {} ns over the third",
            host.name, worst[0], worst[1], worst[2]
        );
        // The far half's delays from the second coupler: its terminal, the third coupler (on
        // the root's X1 port, seen the other way round) and its terminal, within 15 ns of the
        // true ones — the far tree is entered by X2, a reversed tree, where SOEM's formula is
        // half a loop-back long and the latches add ±5 ns (`delays.rs`; 10 ns off with seed 5,
        // 15 with 6). Against the true delays, not the intact ring's measured differences,
        // which seed 6 puts 15 ns apart themselves.
        assert_eq!((split[2].0, split[4].0), (Some(4), None), "the third coupler is the root: {split:?}");
        for k in [3, 4, 5] {
            let t = truth[k].expect("on the far pass");
            assert!((split[k].2 as i64 - t).abs() <= 15, "slave {k}: {} vs true {t}", split[k].2);
        }
        // Split, the far couplers within 100 ns (`nic-hwts`) and 400 ns (`pc-rt`, software
        // stamps) of the reference: 14–49 and 64–274 ns over 40 realisations (segment seeds
        // 5–12, host seeds 5–9).
        // Back together, both far couplers' loops take up their crystals' whole offsets (the
        // master kept them by their offsets while split): 24–797 ns, which seed 5 alone (25
        // ns) had hidden; settled a second later (19–25 ns).
        let split_bound = if host.name == "nic-hwts" { 100 } else { 400 };
        assert!(worst[0] < split_bound && worst[1] < 1_000 && worst[2] < 50, "{worst:?}");
        // Closed again: the intact ring's tree and delays.
        assert_eq!(m.diagnosis().ring_state(), RingState::Intact);
        assert_wiring_as_intact(&wiring(&m), &whole);
    }
}

/// A ring of drives whose controllers are IP cores (ports 1–3 take the frame after the write
/// to 0x0900), split before the master starts between the first and second drive: the far
/// half is entered on the last drive's port 1, so the first latch gives its port 1 the next
/// frame through it — a probe from the secondary. The master latches the far half again with
/// the probes off (master/next_frame_latch.rs).
const IP_CORE_RING: &str = "seed = 8\n[[device]]\nname = 'c'\nbuiltin = 'EK1100'\n[[device]]\nbuiltin = 'EL2004'\n\
    [[device]]\nbuiltin = 'SERVO'\nesc = 'ipcore'\nparent = 'c'\nparent_port = 2\n\
    [[device]]\nbuiltin = 'SERVO'\nesc = 'ipcore'\ncable_m = 10.0\n\
    [[device]]\nbuiltin = 'SERVO'\nesc = 'ipcore'\n[secondary]\ndevice = 4\n";

#[test]
fn a_ring_of_ip_cores_split_from_the_start_is_latched_again_without_probes() {
    let mut intact = master(IP_CORE_RING, HostModel::pc_rt());
    intact.states().scan().unwrap();
    let whole = wiring(&intact);
    let toml = format!("{IP_CORE_RING}[[event]]\nat_ms = 0\nlink_down = {{ device = 3, port = 0 }}\n");
    let mut worst = 0i64;
    let m = cycle_ring(&toml, HostModel::pc_rt(), SplitRingClocks::FarReference, &[], 3_000, |k, t| {
        if k >= 1_000 {
            // Clocks with a system time: the coupler (the reference), then the drives.
            worst = worst
                .max([2, 3].map(|d| (t[d].wrapping_sub(t[0]) as u32 as i32 as i64).abs()).into_iter().max().unwrap());
        }
    });
    let mut m = m;
    let split = wiring(&m);
    let l = m.dc().split_latch().expect("the latch saw the split");
    assert_eq!((l.first_far, l.root, l.root_port), (3, 4, 1), "entered on the last drive's port 1");
    assert_eq!(m.slaves().iter().map(|s| s.ports().entry).collect::<Vec<_>>(), [0, 0, 0, 1, 1]);
    let truth = far_pass_truth(&mut m, 3);
    println!(
        "intact {whole:?}\nsplit {split:?}\ntrue on the far pass {truth:?}\nworst |far drives − reference| over the \
         last 2 s: {worst} ns"
    );
    // The last drive's delay from the far reference (the second drive) within 10 ns of the
    // true one (the intact ring's difference may be 15 ns off it: seen with seed 9).
    let (apart, t) = (split[4].2 as i64 - split[3].2 as i64, truth[4].expect("on the far pass"));
    assert!((apart - t).abs() <= 10, "{apart} vs true {t}");
    assert!(worst < 200, "{worst} ns");
}

#[test]
fn a_ring_with_a_device_cabled_the_wrong_way_round_is_refused_by_name() {
    // The last drive entered by its port 1 from the one before, its port 0 back to the
    // master: the primary's frames leave by its port 0 before its processing unit, so only the
    // secondary's probe counts it. A scan that went on would lose it from every count.
    let toml = "seed = 5\n[[device]]\nname = 'c'\nbuiltin = 'EK1100'\n[[device]]\nbuiltin = 'EL2004'\n\
        [[device]]\nname = 'a'\nbuiltin = 'SERVO'\nparent = 'c'\nparent_port = 2\n\
        [[device]]\nbuiltin = 'SERVO'\nparent = 'a'\nparent_port = 1\nport = 1\n[secondary]\ndevice = 3\n";
    let mut m = master(toml, HostModel::pc_rt());
    let e = m.states().scan().unwrap_err().to_string();
    assert!(e.contains("1 slave(s) on the ring answer only frames from the secondary port"), "{e}");
    // Cabled the right way round (its port 1 back to the master), it is a ring like any other.
    let mut m = master(&toml.replace("port = 1\n[secondary]", "[secondary]"), HostModel::pc_rt());
    m.states().scan().unwrap();
    assert_eq!(
        (m.slaves().len(), m.diagnosis().ring_state(), m.dc().ring_port()),
        (4, RingState::Intact, Some((3, 1)))
    );
}

#[test]
fn a_ring_of_ip_cores_split_from_the_start_closes_on_the_references_delays() {
    // The cable back 1 s in: the master opens the ring and latches the far half again from the
    // reference, as a line entered on port 0 everywhere (no second latch needed).
    let s = 1_000_000_000;
    let toml = format!("{IP_CORE_RING}[[event]]\nat_ms = 0\nlink_down = {{ device = 3, port = 0 }}\n");
    let mut worst = 0i64;
    let mut m = cycle_ring(
        &toml,
        HostModel::pc_rt(),
        SplitRingClocks::FarReference,
        &[(s, Event::LinkUp { node: 3, port: 0 })],
        3_000,
        |k, t| {
            if k >= 2_000 {
                worst = worst.max(
                    [2, 3].map(|d| (t[d].wrapping_sub(t[0]) as u32 as i32 as i64).abs()).into_iter().max().unwrap(),
                );
            }
        },
    );
    let mut intact = master(IP_CORE_RING, HostModel::pc_rt());
    intact.states().scan().unwrap();
    println!(
        "closed {:?}\nintact {:?}\nworst |far drives − reference| over the last second: {worst} ns",
        wiring(&m),
        wiring(&intact)
    );
    assert_eq!(m.diagnosis().ring_state(), RingState::Intact);
    assert_wiring_as_intact(&wiring(&m), &wiring(&intact));
    assert!(m.dc().relatched().is_empty(), "{:?}", m.dc().relatched());
    assert!(worst < 100, "{worst} ns");
}
