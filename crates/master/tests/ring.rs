//! Cable redundancy: the master on both ends of a ring (two couplers with a terminal each, the
//! second coupler's X2 OUT back to the master's secondary port). It finds the port the ring
//! closes through and measures a line's delays; the process data keeps its whole working
//! counter when a cable in the ring is pulled; and the split ring's far half keeps its clocks
//! by holding over instead of taking a reference time a master round trip old.
use ferrocat_master::io::{HostModel, Io, VirtualIo};
use ferrocat_master::{DcConfig, Master};
use ferrocat_master::{RingState, SplitRingClocks};
use ferrocat_segment::{Event, SegmentConfig};

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
    line.scan().unwrap();
    let mut ring = master(&format!("{DEVICES}{RING}"), HostModel::ideal());
    ring.scan().unwrap();
    assert_eq!(ring.engine.ring, RingState::Intact);
    assert_eq!(ring.ring_port, Some((2, 2)), "the second coupler's X2 OUT");
    assert_eq!(line.ring_port, None);
    let delays =
        |m: &Master<VirtualIo>| m.slaves.iter().map(|s| (s.parent, s.parent_port, s.delay_ns)).collect::<Vec<_>>();
    println!("ring {:?}\nline {:?}", delays(&ring), delays(&line));
    assert_eq!(delays(&ring), delays(&line));
    // And they are the true ones: the second coupler's processing unit 805 ns after the first's
    // (E-Bus out and back through the EL2004 and the coupler, then 100BASE-TX).
    assert_eq!(ring.slaves[2].delay_ns, 805);
    // On the line the frame loops at the closed port (20 ns), goes back to the first coupler
    // (420 ns of 100BASE-TX), through it (65 ns) and to the master (500 ns); on the ring it
    // leaves by that port for the secondary (500 ns): back 505 ns sooner.
    assert_eq!(ring.ring_shortening_ns, 505);
}

/// Brings the ring to OP with DC and runs `cycles` 1 ms cycles; the cable between the couplers
/// is pulled after the first `break_after`. Returns the master and, per cycle after the break,
/// the second coupler's true system time less the first's.
fn run_split(clocks: SplitRingClocks, cycles: u64, break_after: u64) -> (Master<VirtualIo>, Vec<i64>) {
    let mut m = master(&format!("{DEVICES}{RING}"), HostModel::pc_rt());
    m.engine.split_ring_clocks = clocks;
    m.bring_up().unwrap();
    let r = m.init_dc(&DcConfig::default()).unwrap();
    assert!(r.converged, "{r:?}");
    let t0 = m.engine.io.now_ns();
    m.engine.io.seg.schedule(t0 + break_after * 1_000_000, Event::LinkDown { node: 2, port: 0 });
    let mut after = Vec::new();
    let mut next = t0;
    for k in 0..cycles {
        assert_eq!(m.cycle().unwrap(), m.expected_wkc, "cycle {k}: the whole ring's working counter");
        next += 1_000_000;
        m.engine.io.sleep_until(next);
        if k > break_after {
            let now = m.engine.io.now_ns();
            let t = m.engine.io.seg.system_times_at(now);
            after.push(t[1].wrapping_sub(t[0]) as i64);
        }
    }
    (m, after)
}

#[test]
fn process_data_goes_on_across_a_pulled_ring_cable() {
    let (m, _) = run_split(SplitRingClocks::HoldOver, 400, 200);
    assert_eq!(m.engine.ring, RingState::Broken);
    assert!(m.engine.stats.resent >= 198, "{:?}", m.engine.stats);
    // The far half's terminal still takes its outputs: its SyncManager saw every cycle.
    let stats = m.cycle_stats();
    assert_eq!(stats.wkc_errors, 0, "{stats:?}");
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
