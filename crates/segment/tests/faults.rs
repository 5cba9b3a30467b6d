//! Injected faults and determinism.
mod common;

use common::Bus;
use ferrocat_segment::{Event, SegmentConfig};
use ferrocat_wire::ethernet::{EthernetRepr, BROADCAST};
use ferrocat_wire::{Address, Command, DatagramHeader, FrameWriter};

fn line(extra: &str) -> SegmentConfig {
    toml::from_str(&format!(
        "seed = 21\n{extra}\n[[device]]\nbuiltin = 'EK1100'\n[[device]]\nbuiltin = 'EL2004'\n[[device]]\nbuiltin = 'EL1004'\n"
    ))
    .unwrap()
}

fn brd_frame() -> Vec<u8> {
    let eth = EthernetRepr { dst: BROADCAST, src: [2; 6], vlan_tci: None, ethertype: 0 };
    let mut b = vec![0u8; 64];
    let mut w = FrameWriter::new(&mut b, &eth).unwrap();
    w.push(&DatagramHeader::new(Command::BRD, 0, Address::Device { adp: 0, ado: 0x0130 }, 2), &[0, 0], 0).unwrap();
    let n = w.finish().unwrap();
    b.truncate(n);
    b
}

/// Returns, per cycle, the time the frame came back (or None) and its WKC.
fn run(cfg: &SegmentConfig, cycles: u64) -> Vec<(Option<u64>, u16)> {
    let mut seg = cfg.build().unwrap();
    (0..cycles)
        .map(|k| {
            let mut f = brd_frame();
            let back = seg.exchange(&mut f, 1_000_000 + k * 100_000);
            (back, u16::from_le_bytes([f[28], f[29]]))
        })
        .collect()
}

#[test]
fn one_percent_loss_and_corruption_are_seeded() {
    for key in ["loss_probability", "corruption_probability"] {
        let cfg = line(&format!("{key} = 0.01"));
        let a = run(&cfg, 20_000);
        let lost = a.iter().filter(|(b, _)| b.is_none()).count();
        println!("{key} 0.01: {lost} of 20000 frames lost");
        assert!((120..=280).contains(&lost), "{key}: {lost} lost");
        assert_eq!(a, run(&cfg, 20_000), "same seed, same frames, same times");
        let mut other = cfg.clone();
        other.seed = 22;
        assert_ne!(a, run(&other, 20_000), "another seed, other losses");
    }
    // Corruption shows in the error counters of the ESC behind the fault; a plain loss does not.
    let mut seg = line("corruption_probability = 0.05").build().unwrap();
    for k in 0..2000 {
        seg.exchange(&mut brd_frame(), 1_000_000 + k * 100_000);
    }
    let errors: u32 = seg.nodes.iter().map(|n| n.esc.peek(0x0300, 1)[0] as u32).sum();
    assert!(errors > 0 && seg.stats.corrupted > 0, "{errors} invalid frames counted");
}

#[test]
fn link_pulled_and_restored_and_slave_power_cycled() {
    let mut bus = Bus::new(line("").build().unwrap());
    bus.address_all();
    let t = bus.t;
    // Pull the link between the EL2004 (node 1) and the EL1004 (node 2), restore it 5 ms later.
    bus.seg.schedule(t + 1_000_000, Event::LinkDown { node: 1, port: 1 });
    bus.seg.schedule(t + 6_000_000, Event::LinkUp { node: 1, port: 1 });
    bus.t = t + 2_000_000;
    assert_eq!(bus.tx(Command::BRD, Address::Device { adp: 0, ado: 0 }, &[0]).1, 2, "EL1004 unreachable");
    bus.t = t + 7_000_000;
    assert_eq!(bus.tx(Command::BRD, Address::Device { adp: 0, ado: 0 }, &[0]).1, 3, "back");
    // The EL2004 keeps its configuration across a link loss...
    assert_eq!(bus.fp(Command::FPRD, 0x1002, 0x0010, &[0; 2]).0, [0x02, 0x10]);
    // ...but loses it when powered off and on: station address 0, AL state INIT.
    let t = bus.t;
    bus.seg.schedule(t + 1_000_000, Event::PowerOff { node: 1 });
    bus.seg.schedule(t + 3_000_000, Event::PowerOn { node: 1 });
    bus.t = t + 2_000_000;
    assert_eq!(bus.tx(Command::BRD, Address::Device { adp: 0, ado: 0 }, &[0]).1, 1, "only the EK1100 answers");
    bus.t = t + 4_000_000;
    assert_eq!(bus.tx(Command::BRD, Address::Device { adp: 0, ado: 0 }, &[0]).1, 3);
    assert_eq!(bus.fp(Command::FPRD, 0x1002, 0x0010, &[0; 2]).1, 0, "address forgotten");
    let (d, _, _) = bus.tx(Command::APRD, Address::position(1, 0x0130), &[0; 2]);
    assert_eq!(d[0], 1, "INIT after power-on");
    // The cable from the master pulled: no frame gets through until it is back.
    let t = bus.t;
    bus.seg.schedule(t + 1_000_000, Event::LinkDown { node: 0, port: 0 });
    bus.seg.schedule(t + 3_000_000, Event::LinkUp { node: 0, port: 0 });
    assert!(bus.seg.exchange(&mut brd_frame(), t + 2_000_000).is_none(), "master cable pulled");
    bus.t = t + 4_000_000;
    assert_eq!(bus.tx(Command::BRD, Address::Device { adp: 0, ado: 0 }, &[0]).1, 3, "plugged in again");
}

/// Under device emulation (the EL2004's ESC has no firmware) an expired process data watchdog
/// resets the outputs and nothing else: AL status is only ever a copy of AL control, so the
/// terminal stays in OP with status code 0, and the next output buffer sets the outputs again.
#[test]
fn expired_process_data_watchdog_resets_a_device_emulation_terminals_outputs() {
    use ferrocat_esc::DigitalIo;
    use ferrocat_wire::register::{Fmmu, SyncManager};
    let mut bus = Bus::new(line("").build().unwrap());
    bus.address_all();
    // EL2004 outputs SM with the watchdog trigger (control 0x44), default 100 ms watchdog.
    let sm = SyncManager { start: 0x0F00, length: 1, control: 0x44, status: 0, activate: 1, pdi_control: 0 };
    bus.fp(Command::FPWR, 0x1002, 0x0800, &sm.to_bytes());
    let f = Fmmu {
        logical_start: 0,
        length: 1,
        logical_start_bit: 0,
        logical_stop_bit: 7,
        physical_start: 0x0F00,
        physical_start_bit: 0,
        fmmu_type: Fmmu::WRITE,
        active: true,
    };
    bus.fp(Command::FPWR, 0x1002, 0x0600, &f.to_bytes());
    for s in [2u8, 4, 8] {
        bus.fp(Command::FPWR, 0x1002, 0x0120, &[s, 0]);
    }
    let outputs = |bus: &Bus| bus.seg.nodes[1].esc.app().as_any().downcast_ref::<DigitalIo>().unwrap().outputs.clone();
    // Process data every millisecond keeps the watchdog from expiring...
    for _ in 0..300 {
        bus.tx(Command::LWR, Address::Logical(0), &[0x0F]);
        bus.t += 1_000_000;
    }
    assert_eq!(bus.fp(Command::FPRD, 0x1002, 0x0440, &[0; 2]).0[0] & 1, 1, "0x0440: active");
    assert_eq!(outputs(&bus), [0x0F]);
    // ...150 ms without it expire it once: outputs off, OP kept.
    bus.t += 150_000_000;
    let (st, _) = bus.fp(Command::FPRD, 0x1002, 0x0130, &[0; 6]);
    assert_eq!((st[0], u16::from_le_bytes([st[4], st[5]])), (0x08, 0), "still OP, no status code");
    assert_eq!(bus.fp(Command::FPRD, 0x1002, 0x0440, &[0; 2]).0[0] & 1, 0, "0x0440: expired");
    assert_eq!(outputs(&bus), [0x00], "outputs in their safe state");
    bus.t += 150_000_000;
    assert_eq!(bus.fp(Command::FPRD, 0x1002, 0x0442, &[0]).0, [1], "0x0442 counts the expiry once");
    bus.tx(Command::LWR, Address::Logical(0), &[0x05]);
    assert_eq!(outputs(&bus), [0x05], "the next buffer drives the outputs again");
    // A write of either watchdog counter clears both (datasheet II, 0x0442–0x0443).
    bus.fp(Command::FPWR, 0x1002, 0x0443, &[0x55]);
    assert_eq!(bus.fp(Command::FPRD, 0x1002, 0x0442, &[0; 2]).0, [0, 0], "cleared");
}

#[test]
fn a_tree_through_a_junction() {
    // EK1100 with an EL2004 on its E-Bus port 1 and an EL1004 line on its port 2 (MII, 10 m).
    let cfg: SegmentConfig = toml::from_str(
        "seed = 1\n[[device]]\nbuiltin = 'EK1100'\n[[device]]\nbuiltin = 'EL2004'\nparent = 0\nparent_port = 1\n\
         [[device]]\nbuiltin = 'EL1004'\nparent = 0\nparent_port = 2\ncable_m = 10.0\n[[device]]\nbuiltin = 'EL1004'\n",
    )
    .unwrap();
    let mut bus = Bus::new(cfg.build().unwrap());
    assert_eq!(bus.tx(Command::BRD, Address::Device { adp: 0, ado: 0 }, &[0]).1, 4);
    bus.address_all();
    assert_eq!(bus.tx(Command::BWR, Address::Device { adp: 0, ado: 0x0900 }, &[0; 4]).1, 4);
    let ports: Vec<u32> = (0..4).map(|p| bus.fprd_u32(0x1001, 0x0900 + 4 * p)).collect();
    // The frame goes 0 → 1 (EL2004 branch) → 2 (EL1004 branch, 100BASE-TX) → back to 0.
    let branch1 = ports[1].wrapping_sub(ports[0]);
    let branch2 = ports[2].wrapping_sub(ports[1]);
    println!("EK1100 port times: {ports:?}; branch loops {branch1} ns and {branch2} ns");
    // E-Bus branch with one terminal: 65 + 2·80 + 85 = 310 ns; the MII branch: two terminals,
    // 2·(420 + 40) cable + their loops.
    assert!((300..=320).contains(&branch1), "{branch1}");
    assert!(branch2 > 2 * (420 + 40), "{branch2}");
    let (dl, _) = bus.fp(Command::FPRD, 0x1001, 0x0110, &[0; 2]);
    let dl = ferrocat_wire::register::DlStatus(u16::from_le_bytes([dl[0], dl[1]]));
    assert!(dl.port_active(0) && dl.port_active(1) && dl.port_active(2) && !dl.port_active(3));
    // The EL1004 on port 2 sees the frame only after the whole port-1 branch came back.
    let t_el2004 = bus.seg.last_visits().iter().find(|(n, _)| *n == 1).unwrap().1.epu_ns;
    let t_el1004 = bus.seg.last_visits().iter().find(|(n, _)| *n == 2).unwrap().1.epu_ns;
    assert!(t_el1004 > t_el2004 + 200);
}

/// `esc_identity` sets the ESC's identity registers to a particular unit's, keeping the kind's
/// bytes where it says `..`; malformed or impossible values are refused with the device named.
#[test]
fn esc_identity_sets_the_identity_registers() {
    let cfg: SegmentConfig =
        toml::from_str("seed = 1\n[[device]]\nbuiltin = 'EL1004'\nesc_identity = '12 01 01 00 03 04 01 .. fc 01'\n")
            .unwrap();
    let seg = cfg.build().unwrap();
    let ports = seg.nodes[0].esc.peek(0x0007, 1)[0];
    assert_eq!(seg.nodes[0].esc.peek(0, 10), [0x12, 0x01, 0x01, 0x00, 0x03, 0x04, 0x01, ports, 0xFC, 0x01]);
    for (bad, says) in [
        ("12 01", "20 are needed"),
        ("12 01 01 00 03 04 01 4a fc zz", "byte 9 is 'zz'"),
        ("12 01 01 00 11 04 01 4a fc 01", "at most 16"),
    ] {
        let cfg: SegmentConfig =
            toml::from_str(&format!("seed = 1\n[[device]]\nbuiltin = 'EL1004'\nesc_identity = '{bad}'\n")).unwrap();
        let err = cfg.build().err().unwrap().to_string();
        assert!(err.contains("device 0") && err.contains(says), "{bad}: {err}");
    }
}
