//! Propagation delays the master computes, against the true ones the simulator knows, on
//! topologies where existing masters go wrong: trees through a junction, non-DC slaves between
//! DC slaves, a slave entered on a port other than 0, long cables.
use ferrocat_master::Master;
use ferrocat_segment::SegmentConfig;
use ferrocat_segment::{HostModel, VirtualIo};
use ferrocat_wire::{Address, Command};

/// The closed-port loop-back of the simulated ESCs (docs/segment-model.md), which a master
/// told it compensates.
const LOOP_NS: u32 = 20;

/// Scans `toml` twice and compares each DC slave's delay with the true one (the time a frame
/// reaches its processing unit minus the time it reaches the reference's, the first DC
/// slave's): with SOEM's formula (within ±10 ns, half a loop-back per closed port on a way
/// back adding up along a line) and told the loop-back (within ±5 ns, single 10 ns latches).
/// Returns the first.
fn check(name: &str, toml: &str) -> Master<VirtualIo> {
    check_within(name, toml, 10)
}

/// As [`check`], with SOEM's formula allowed `soem_ns`.
fn check_within(name: &str, toml: &str, soem_ns: i64) -> Master<VirtualIo> {
    check_prepared(name, toml, soem_ns, |_| {})
}

/// As [`check_within`], with `prepare` run on the segment before the scan.
fn check_prepared(name: &str, toml: &str, soem_ns: i64, prepare: fn(&mut Master<VirtualIo>)) -> Master<VirtualIo> {
    let m = scan(name, toml, 0, soem_ns, prepare);
    scan(&format!("{name}, loop-backs known"), toml, LOOP_NS, 5, prepare);
    m
}

fn scan(name: &str, toml: &str, loop_ns: u32, bound_ns: i64, prepare: fn(&mut Master<VirtualIo>)) -> Master<VirtualIo> {
    let cfg: SegmentConfig = toml::from_str(toml).unwrap();
    let mut m = Master::new(VirtualIo::new(cfg.build().unwrap(), HostModel::pc_rt(), 3));
    m.config().settings_mut().closed_port_loop_ns = loop_ns;
    prepare(&mut m);
    m.states().scan().unwrap();
    // The last frame of the scan visited every slave; any frame does: delays are fixed.
    // Visits are in processing order, which is the order of positions.
    let visits = m.io().seg.last_visits().to_vec();
    assert_eq!(visits.len(), m.slaves().len());
    let epu = |k: usize| visits[k].1.epu_ns;
    // The reference is the first slave with a system time; a slave with receive times only
    // (an ET1200 terminal) has its processing unit's time taken as its port 0's, exact where it
    // is entered on port 0.
    let reference = m.slaves().iter().position(|s| s.dc().has_system_time).unwrap();
    let mut worst = 0i64;
    for (k, s) in m.slaves().iter().enumerate() {
        if !(s.dc().has_system_time || (s.dc().supported && s.ports().entry == 0)) || k < reference {
            continue;
        }
        let truth = (epu(k) - epu(reference)) as i64;
        let err = s.dc().delay_ns as i64 - truth;
        println!(
            "{name}: slave {k} ({}) entry port {} delay {} ns, true {truth} ns",
            s.name(),
            s.ports().entry,
            s.dc().delay_ns
        );
        assert!(err.abs() <= bound_ns, "{name}: slave {k}: computed {} ns, true {truth} ns", s.dc().delay_ns);
        worst = worst.max(err.abs());
    }
    println!("{name}: worst error {worst} ns");
    m
}

#[test]
fn a_line() {
    check(
        "line",
        "seed = 1\n[[device]]\nbuiltin = 'EK1100'\n[[device]]\nbuiltin = 'EL2004'\n[[device]]\nbuiltin = 'EL1004'\n\
         [[device]]\nbuiltin = 'EL2004'\ncable_m = 30.0\n[[device]]\nbuiltin = 'EL1004'\n",
    );
}

#[test]
fn a_tree_through_a_junction_with_long_cables() {
    // 0 ─p1─ 1 ─ 2 ; 0 ─p2─ 3 (10 m) ─ 4 ─ 5 (50 m)
    check(
        "tree",
        "seed = 2\n\
         [[device]]\nbuiltin = 'EK1100'\n\
         [[device]]\nbuiltin = 'EL2004'\nparent = 0\nparent_port = 1\n\
         [[device]]\nbuiltin = 'EL1004'\n\
         [[device]]\nbuiltin = 'EL2004'\nparent = 0\nparent_port = 2\ncable_m = 10.0\n\
         [[device]]\nbuiltin = 'EL1004'\n\
         [[device]]\nbuiltin = 'EL2004'\ncable_m = 50.0\n",
    );
}

#[test]
fn non_dc_slaves_between_dc_slaves() {
    check(
        "nodc",
        "seed = 3\n[[device]]\nbuiltin = 'EK1100'\n[[device]]\nbuiltin = 'EL2004'\nesc = 'nodc'\n\
         [[device]]\nbuiltin = 'EL1004'\n[[device]]\nbuiltin = 'EL2004'\nesc = 'nodc'\n[[device]]\nbuiltin = 'EL1004'\n",
    );
}

#[test]
fn a_slave_entered_on_port_1() {
    // Reversed cabling: the third device's cable from upstream is on its port 1, so the slave
    // behind its port 0 is processed before it.
    let toml = "seed = 4\n[[device]]\nbuiltin = 'EK1100'\n[[device]]\nbuiltin = 'EL2004'\n\
         [[device]]\nbuiltin = 'EL1004'\nport = 1\n[[device]]\nbuiltin = 'EL2004'\n";
    let m = check("reversed", toml);
    let names: Vec<&str> = m.slaves().iter().map(|s| s.name()).collect();
    assert_eq!(names, ["EK1100", "EL2004", "EL2004", "EL1004"], "the slave behind is processed first");
    assert_eq!(m.slaves().iter().map(|s| s.ports().entry).collect::<Vec<_>>(), [0, 0, 0, 1]);
    assert_eq!(links(&m), [None, Some((0, 1)), Some((3, 0)), Some((1, 1))]);
    synchronises(m);
}

#[test]
fn the_first_slave_reversed_and_couplers_cabled_in_to_in() {
    // The master's cable on the first coupler's X2 (port 2); its X1 to a second coupler's X1,
    // which has a terminal on its E-Bus and a third coupler at the end of 40 m on X2, reversed
    // too; a 32-bit-DC terminal on the first coupler's E-Bus. Processing order: coupler 2, its
    // terminal, coupler 3, coupler 1, the 32-bit terminal.
    let toml = "seed = 5\n\
         [[device]]\nname = 'c1'\nbuiltin = 'EK1100'\nport = 2\n\
         [[device]]\nname = 'c2'\nbuiltin = 'EK1100'\nparent = 'c1'\nparent_port = 0\n\
         [[device]]\nbuiltin = 'EL2004'\nparent = 'c2'\nparent_port = 1\n\
         [[device]]\nbuiltin = 'EL2004'\nparent = 'c1'\nparent_port = 1\nesc = 'esc20'\n\
         [[device]]\nname = 'c3'\nbuiltin = 'EK1100'\nparent = 'c2'\nparent_port = 2\nport = 2\ncable_m = 40.0\n";
    // SOEM's formula makes the third coupler's hop half a loop-back (10 ns) too long, and its
    // 10 ns latches add ±5: over seeds 1–200 its worst error on this tree is 10 ns in 130 and
    // 15 ns in 70 (told the loop-back: 0 in 58, 5 in 142). This seed's is 10.
    let m = check_within("reversed tree", toml, 15);
    assert_eq!(m.slaves().iter().map(|s| s.ports().entry).collect::<Vec<_>>(), [0, 0, 2, 2, 0]);
    assert_eq!(links(&m), [Some((3, 0)), Some((0, 1)), Some((0, 2)), None, Some((3, 1))]);
    synchronises(m);
}

/// Controllers whose ports 1–3 take the frame after the write to 0x0900 (ET1200, ESC20, the
/// IP core), entered on port 1 with a slave behind their port 0: the first latch gives their
/// entry port a later frame's time; the master latches them again.
const NEXT_FRAME_REVERSED: &str = "seed = 6\n\
     [[device]]\nname = 'c'\nbuiltin = 'EK1100'\n\
     [[device]]\nname = 'in'\nbuiltin = 'EL1004'\nparent = 'c'\nparent_port = 1\nport = 1\napp = 'dc'\n\
     [[device]]\nbuiltin = 'EL2004'\nparent = 'in'\nparent_port = 0\napp = 'dc'\n\
     [[device]]\nname = 'ip'\nbuiltin = 'SERVO'\nesc = 'ipcore'\nparent = 'c'\nparent_port = 2\nport = 1\ncable_m = 20.0\n\
     [[device]]\nname = 'e20'\nbuiltin = 'SERVO'\nesc = 'esc20'\nparent = 'ip'\nparent_port = 0\nport = 1\n\
     [[device]]\nbuiltin = 'SERVO'\nparent = 'e20'\nparent_port = 0\ncable_m = 5.0\n";

#[test]
fn next_frame_controllers_entered_on_port_1() {
    let m = check("next-frame reversed", NEXT_FRAME_REVERSED);
    let entries: Vec<(&str, u8)> = m.slaves().iter().map(|s| (s.name(), s.ports().entry)).collect();
    println!("{entries:?}");
    assert_eq!(m.slaves().iter().map(|s| s.ports().entry).collect::<Vec<_>>(), [0, 0, 1, 0, 1, 1]);
    synchronises(m);
}

#[test]
fn ip_cores_left_in_reverse_latch_mode() {
    // 0x0936 = 1: the ports after the processing unit give the frame before the write (the
    // first IP core's port 1, entered on port 0). The master sets forwarding mode.
    let toml = "seed = 7\n\
         [[device]]\nname = 'c'\nbuiltin = 'EK1100'\n\
         [[device]]\nbuiltin = 'EL2004'\n\
         [[device]]\nname = 'a'\nbuiltin = 'SERVO'\nesc = 'ipcore'\nparent = 'c'\nparent_port = 2\n\
         [[device]]\nname = 'b'\nbuiltin = 'SERVO'\nparent = 'a'\nparent_port = 1\ncable_m = 10.0\n\
         [[device]]\nname = 'r'\nbuiltin = 'SERVO'\nesc = 'ipcore'\nparent = 'b'\nparent_port = 1\nport = 1\n\
         [[device]]\nbuiltin = 'SERVO'\nparent = 'r'\nparent_port = 0\n";
    let m = check_prepared("reverse mode", toml, 10, |m| {
        m.cyclic().datagram(Command::BWR, Address::Device { adp: 0, ado: 0x0936 }, &mut [1]).unwrap();
    });
    assert_eq!(m.slaves().iter().map(|s| s.ports().entry).collect::<Vec<_>>(), [0, 0, 0, 0, 0, 1]);
}

/// Brings `m` up with DC and runs a second of 1 ms cycles: every DC slave's true system time
/// within 100 ns of the reference's (32-bit DCs on their low 32 bits).
fn synchronises(mut m: Master<VirtualIo>) {
    m.states().bring_up().unwrap();
    let r = m.dc().init_dc(&ferrocat_master::DcConfig::default()).unwrap();
    assert!(r.converged, "{r:?}");
    let mut next = m.cyclic().now_ns();
    let mut worst = 0i64;
    for k in 0..1000 {
        m.cyclic().cycle().unwrap();
        next += 1_000_000;
        m.cyclic().sleep_until(next);
        if k > 200 {
            let t = m.cyclic().now_ns();
            // Slaves with receive times only (ET1200 terminals) have no system time to compare.
            let times: Vec<u32> = m.io().seg.system_times_at(t).iter().map(|&x| x as u32).collect();
            let d: Vec<i64> = times.iter().map(|&x| x.wrapping_sub(times[0]) as i32 as i64).collect();
            worst = worst.max(d.iter().max().unwrap() - d.iter().min().unwrap());
        }
    }
    println!("worst true spread of the DC slaves over the last 800 cycles: {worst} ns");
    assert!(worst <= 100, "{worst} ns");
}

/// Every slave's (parent, port) as the master inferred it.
fn links(m: &Master<VirtualIo>) -> Vec<Option<(u16, u8)>> {
    m.slaves().iter().map(|s| s.ports().parent.map(|p| (p, s.ports().parent_port))).collect()
}

#[test]
fn a_reversed_terminal_at_the_end() {
    // A terminal entered on port 1 with nothing on its port 0 (closed), which therefore
    // latches nothing: no receive time gives its processing unit's, and with a single port in
    // use it is still placed (its parent's round trip holds it). A second coupler on the
    // first one's X2: SOEM's formula makes its hop 25 ns long here (the closed-port bias, 20 ns
    // with the terminal cabled normally); told the loop-back, 5 ns.
    let toml = "seed = 9\n[[device]]\nbuiltin = 'EK1100'\n[[device]]\nbuiltin = 'EL2004'\n\
         [[device]]\nbuiltin = 'EL1004'\nport = 1\n[[device]]\nbuiltin = 'EK1100'\nparent = 0\napp = 'dc'\n";
    let m = check_within("reversed at the end", toml, 30);
    assert_eq!(m.slaves().iter().map(|s| s.ports().entry).collect::<Vec<_>>(), [0, 0, 1, 0]);
    assert_eq!(links(&m), [None, Some((0, 1)), Some((1, 1)), Some((0, 2))]);
}

#[test]
fn a_reversed_clock_at_the_end() {
    // The same terminal with a system time (the SYNC unit on), entered on port 1 with port 0
    // closed: the only tree fits the first latch's times, whose port 1 holds a later frame's;
    // its delay came out 0 ns for 230 (the config fuzz target found it). Latched again now.
    let toml = "seed = 6\n[[device]]\nname = 'c'\nbuiltin = 'EK1100'\n\
         [[device]]\nbuiltin = 'EL1004'\nparent = 'c'\nparent_port = 1\nport = 1\napp = 'dc'\n";
    let m = check("reversed clock at the end", toml);
    assert_eq!(m.slaves().iter().map(|s| s.ports().entry).collect::<Vec<_>>(), [0, 1]);
    assert!(m.slaves()[1].dc().has_system_time);
    synchronises(m);
}
