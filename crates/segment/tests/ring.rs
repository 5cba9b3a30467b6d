//! Cable redundancy: the master's secondary port wired to the last coupler's free port closes
//! the line into a ring. Frames take the processing order (esc-spec §1.5) whichever port they
//! enter by; a frame passes a processing unit only when it is received on port 0 or looped back
//! there (§1.5), and one that passes an automatically closed port 0 carries the circulating bit
//! (§1.6).
use ferrocat_segment::{MasterPort, SegmentConfig};
use ferrocat_wire::ethernet::{EthernetRepr, BROADCAST};
use ferrocat_wire::{Address, Command, DatagramHeader, Frame, FrameWriter};

/// EK1100 + EL2004 | EK1100 + EL2004, the second coupler on the first one's X2 OUT (port 2)
/// and its own X2 OUT back to the master's secondary port.
const RING: &str = r#"
seed = 3
[[device]]
builtin = "EK1100"
[[device]]
builtin = "EL2004"
[[device]]
builtin = "EK1100"
parent = 0
[[device]]
builtin = "EL2004"
[secondary]
device = 2
link_ns = 700
"#;

fn ring(extra: &str) -> ferrocat_segment::Segment {
    let cfg: SegmentConfig = toml::from_str(&format!("{RING}{extra}")).unwrap();
    cfg.build().unwrap()
}

/// A frame of one datagram from `src` MAC; returns the frame as it came back, on which port and
/// when.
fn send(
    seg: &mut ferrocat_segment::Segment,
    from: MasterPort,
    t_ns: u64,
    cmd: Command,
    ado: u16,
    data: &[u8],
) -> Option<(Vec<u8>, MasterPort, u64)> {
    let eth = EthernetRepr { dst: BROADCAST, src: [0x10; 6], vlan_tci: None, ethertype: 0 };
    let mut buf = [0u8; 1514];
    let mut w = FrameWriter::new(&mut buf, &eth).unwrap();
    w.push_chained(&DatagramHeader::new(cmd, 1, Address::Device { adp: 0, ado }, data.len() as u16), data, 0).unwrap();
    let n = w.finish().unwrap();
    let (port, back) = seg.exchange_on(from, &mut buf[..n], t_ns)?;
    Some((buf[..n].to_vec(), port, back))
}

fn wkc_and_circulating(frame: &[u8]) -> (u16, bool) {
    let f = Frame::parse(frame).unwrap().unwrap();
    let d = f.pdu.datagrams().next().unwrap();
    (d.wkc(), d.header().circulating)
}

#[test]
fn an_intact_ring_takes_the_primary_frame_through_every_slave_to_the_secondary_port() {
    let mut seg = ring("");
    let (f, port, _) = send(&mut seg, MasterPort::Primary, 1_000_000, Command::BRD, 0x0000, &[0; 2]).unwrap();
    assert_eq!((port, wkc_and_circulating(&f)), (MasterPort::Secondary, (4, false)));
    assert_eq!(f[6] & 0x02, 0x02, "processed: the source MAC's locally administered bit");
    // The secondary's frame runs the other way through forwarding paths only: nobody processes it.
    let (f, port, _) = send(&mut seg, MasterPort::Secondary, 2_000_000, Command::BRD, 0x0000, &[0; 2]).unwrap();
    assert_eq!((port, wkc_and_circulating(&f)), (MasterPort::Primary, (0, false)));
    assert_eq!(f[6] & 0x02, 0, "not processed, the source MAC untouched");
}

#[test]
fn an_intact_ring_returns_at_the_time_its_hops_add_up_to() {
    let mut seg = ring("");
    let t = 1_000_000;
    let (f, _, back) = send(&mut seg, MasterPort::Primary, t, Command::BRD, 0x0000, &[0; 2]).unwrap();
    // Head: master link 500, EK1100 processing 65, E-Bus to the EL2004 80, its turnaround
    // 65 + 20 (port 1 closed), back 80, EK1100 forwarding 65 to port 2, 100BASE-TX 420 to the
    // second coupler; the same again there; then port 2 → secondary link 700. Plus the whole
    // frame at 80 ns per byte (preamble 8, at least 60 bytes, FCS 4).
    let one_coupler = 65 + 80 + 65 + 20 + 80 + 65;
    let head = 500 + one_coupler + 420 + one_coupler + 700;
    let wire = (8 + f.len().max(60) as u64 + 4) * 80;
    assert_eq!(back - t, head + wire);
}

#[test]
fn a_broken_ring_serves_each_half_from_its_own_port() {
    // The cable between the couplers pulled after 10 ms.
    let mut seg = ring("[[event]]\nat_ms = 10\nlink_down = { device = 2, port = 0 }\n");
    let (f, port, _) = send(&mut seg, MasterPort::Primary, 1_000_000, Command::BRD, 0x0000, &[0; 2]).unwrap();
    assert_eq!((port, wkc_and_circulating(&f).0), (MasterPort::Secondary, 4));
    let t = 20_000_000;
    // The primary's frame turns at the first coupler's closed port 2: the first half.
    let (f, port, _) = send(&mut seg, MasterPort::Primary, t, Command::BRD, 0x0000, &[0; 2]).unwrap();
    assert_eq!((port, wkc_and_circulating(&f)), (MasterPort::Primary, (2, false)));
    // The secondary's frame loops at the second coupler's port 0, which has lost its link: it is
    // processed from there on, and marked as having passed an automatically closed port 0.
    let (f2, port, _) = send(&mut seg, MasterPort::Secondary, t + 100_000, Command::BRD, 0x0000, &[0; 2]).unwrap();
    assert_eq!((port, wkc_and_circulating(&f2)), (MasterPort::Secondary, (2, true)));
    // What SOEM does on a broken ring: the primary's answer sent again from the secondary port
    // collects the second half; the working counter adds up to the whole ring's.
    let mut again = f.clone();
    let (_, back) = seg.exchange_on(MasterPort::Secondary, &mut again, t + 200_000).unwrap();
    assert!(back > t + 200_000);
    assert_eq!(wkc_and_circulating(&again), (4, true));
    // A frame that has passed one auto-closed port 0 is destroyed at the next: sent again from
    // the secondary it passes the second coupler's once more.
    let before = seg.stats.destroyed_circulating;
    assert!(seg.exchange_on(MasterPort::Secondary, &mut again, t + 300_000).is_none());
    assert_eq!(seg.stats.destroyed_circulating, before + 1);
}

#[test]
fn a_pulled_secondary_cable_leaves_a_plain_line() {
    let mut seg = ring("[[event]]\nat_ms = 10\nlink_down = { device = 2, port = 2 }\n");
    let t = 20_000_000;
    let (f, port, _) = send(&mut seg, MasterPort::Primary, t, Command::BRD, 0x0000, &[0; 2]).unwrap();
    assert_eq!((port, wkc_and_circulating(&f)), (MasterPort::Primary, (4, false)));
    assert!(send(&mut seg, MasterPort::Secondary, t + 100_000, Command::BRD, 0x0000, &[0; 2]).is_none());
}

#[test]
fn a_segment_without_a_secondary_port_loses_what_is_sent_there() {
    let cfg: SegmentConfig = toml::from_str("[[device]]\nbuiltin = \"EK1100\"\n").unwrap();
    let mut seg = cfg.build().unwrap();
    assert!(send(&mut seg, MasterPort::Secondary, 1_000_000, Command::BRD, 0x0000, &[0; 2]).is_none());
}

#[test]
fn bad_rings_and_events_are_named() {
    let err = |toml: &str| {
        let cfg: SegmentConfig = toml::from_str(toml).unwrap();
        cfg.build().unwrap_err().to_string()
    };
    assert_eq!(err("[secondary]\n"), "[secondary]: no device to wire it to");
    let two = "[[device]]\nbuiltin = \"EK1100\"\n[[device]]\nbuiltin = \"EL2004\"\n";
    assert_eq!(
        err(&format!("{two}[secondary]\ndevice = 0\nport = 1\n")),
        "[secondary]: port 1 of device 0 ('EK1100') is already in use"
    );
    assert_eq!(err(&format!("{two}[secondary]\ndevice = 5\n")), "[secondary]: no device 5 (there are 2)");
    assert_eq!(
        err(&format!("{two}[secondary]\ndevice = 1\nport = 3\n")),
        "[secondary]: device 1 ('EL2004') has no port 3"
    );
    assert_eq!(
        err(&format!("{two}[[event]]\nat_ms = 1\npower_off = 1\npower_on = 1\n")),
        "event 0: give exactly one of link_down, link_up, power_off, power_on, drift_step, drive_fault, al_error, soe_message"
    );
    assert_eq!(
        err(&format!("{two}[[event]]\nat_ms = 1\ndrift_step = {{ device = 0, ppm = 2000.0 }}\n")),
        "event 0: drift_step.ppm 2000.0 out of range (-1000.0 to 1000.0)"
    );
    assert_eq!(
        err(&format!("{two}[[event]]\nat_ms = 1\ndrift_step = {{ device = 7, ppm = 1.0 }}\n")),
        "event 0: no device 7 (there are 2)"
    );
    assert_eq!(
        err(&format!("{two}[[event]]\nat_ms = -1\npower_off = 1\n")),
        "event 0: at_ms -1.0 out of range (0.0 to 10000000000.0)"
    );
    assert_eq!(
        err(&format!("{two}[[event]]\nat_ms = 1\nlink_down = {{ device = \"EL2004\", port = 2 }}\n")),
        "event 0: device 1 ('EL2004') has no port 2"
    );
}

/// `drift_step` in a segment file: the device's crystal that much faster from the event on.
#[test]
fn a_drift_step_in_the_file_speeds_the_crystal_up() {
    let cfg: SegmentConfig = toml::from_str(
        "seed = 1\n[[device]]\nbuiltin = \"EK1100\"\n[[event]]\nat_ms = 500\ndrift_step = { device = 0, ppm = 50.0 }\n",
    )
    .unwrap();
    let mut seg = cfg.build().unwrap();
    let mut clock_at = |t_ns: u64| {
        seg.advance_to(t_ns);
        seg.system_times_at(t_ns)[0] as i64
    };
    let ms = 1_000_000;
    let before = clock_at(400 * ms) - clock_at(100 * ms);
    let after = clock_at(900 * ms) - clock_at(600 * ms);
    // 50 ppm of 300 ms, to the clock's 10 ns tick.
    assert!((after - before - 15_000).abs() <= 20, "{before} → {after}");
}

/// Steps that add up beyond ±1000 ppm leave the crystal at that bound (the DC unit's range),
/// however many a file gives.
#[test]
fn drift_steps_add_up_to_no_more_than_1000_ppm() {
    let steps: String =
        (0..40).map(|k| format!("[[event]]\nat_ms = {k}\ndrift_step = {{ device = 0, ppm = 900.0 }}\n")).collect();
    let cfg: SegmentConfig =
        toml::from_str(&format!("seed = 1\n[[device]]\nbuiltin = \"EK1100\"\ndrift_ppm = 0.0\n{steps}")).unwrap();
    let mut seg = cfg.build().unwrap();
    let ms = 1_000_000;
    let mut clock_at = |t_ns: u64| {
        seg.advance_to(t_ns);
        seg.system_times_at(t_ns)[0] as i64
    };
    let span = clock_at(1_300 * ms) - clock_at(100 * ms);
    // 1.2 s at 1000 ppm fast.
    assert!((span - 1_201_200_000).abs() <= 20, "{span}");
    assert_eq!(seg.nodes[0].drift_ppb, 1_000_000);
}

/// Loop control auto-close (0x0101 = 01 per port): a link that comes back leaves the port
/// closed until the master writes DL control again or a valid frame arrives at it (Beckhoff,
/// EtherCAT Technology Section I, "Auto close").
#[test]
fn auto_close_ports_stay_closed_when_the_link_comes_back_until_opened() {
    // (Said twice: a link that is up already does not open the port.)
    let mut seg = ring(
        "[[event]]\nat_ms = 10\nlink_down = { device = 2, port = 0 }\n[[event]]\nat_ms = 30\nlink_up = { device = 2, port = 0 }\n\
         [[event]]\nat_ms = 35\nlink_up = { device = 2, port = 0 }\n",
    );
    let ms = 1_000_000;
    // Auto-close on every port of every slave, written round each half of the broken ring.
    for (k, from) in [MasterPort::Primary, MasterPort::Secondary].into_iter().enumerate() {
        send(&mut seg, from, 20 * ms + k as u64 * 100_000, Command::BWR, 0x0101, &[0x55]).unwrap();
    }
    // The cable is back at 30 ms, but both of its ports wait closed: still two halves.
    let (f, port, _) = send(&mut seg, MasterPort::Primary, 40 * ms, Command::BRD, 0x0000, &[0; 2]).unwrap();
    assert_eq!((port, wkc_and_circulating(&f).0), (MasterPort::Primary, 2));
    // The first coupler's DL status: link on port 2, its loop closed.
    let (f, _, _) = send(&mut seg, MasterPort::Primary, 41 * ms, Command::APRD, 0x0110, &[0; 2]).unwrap();
    let d = Frame::parse(&f).unwrap().unwrap();
    let dl = u16::from_le_bytes(d.pdu.datagrams().next().unwrap().data()[..2].try_into().unwrap());
    assert_eq!((dl >> 6 & 1, dl >> 12 & 1), (1, 1), "{dl:#06x}");
    // DL control written again from the primary opens the first coupler's side only: the next
    // frame out of it arrives at the second coupler's port, still closed, and is lost there —
    // but opens it. Then the ring is whole.
    send(&mut seg, MasterPort::Primary, 42 * ms, Command::BWR, 0x0101, &[0x55]).unwrap();
    assert!(send(&mut seg, MasterPort::Primary, 43 * ms, Command::BRD, 0x0000, &[0; 2]).is_none());
    let (f, port, _) = send(&mut seg, MasterPort::Primary, 44 * ms, Command::BRD, 0x0000, &[0; 2]).unwrap();
    assert_eq!((port, wkc_and_circulating(&f)), (MasterPort::Secondary, (4, false)));
}

/// Written again round both halves at once (a frame's two passes), both ports open together
/// and no frame is lost.
#[test]
fn auto_close_ports_opened_from_both_sides_close_the_ring_at_once() {
    let mut seg = ring("[[event]]\nat_ms = 10\nlink_down = { device = 2, port = 0 }\n[[event]]\nat_ms = 30\nlink_up = { device = 2, port = 0 }\n");
    let ms = 1_000_000;
    for (at, from) in
        [(20, MasterPort::Primary), (21, MasterPort::Secondary), (40, MasterPort::Primary), (41, MasterPort::Secondary)]
    {
        send(&mut seg, from, at * ms, Command::BWR, 0x0101, &[0x55]).unwrap();
    }
    let (f, port, _) = send(&mut seg, MasterPort::Primary, 42 * ms, Command::BRD, 0x0000, &[0; 2]).unwrap();
    assert_eq!((port, wkc_and_circulating(&f)), (MasterPort::Secondary, (4, false)));
    assert_eq!(seg.stats.lost, 0);
}
