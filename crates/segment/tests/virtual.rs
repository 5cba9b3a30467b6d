//! The virtual segment in-process, driven by a minimal master written here from the spec.
mod common;

use common::Bus;
use ferrocat_esc::DigitalIo;
use ferrocat_segment::{Segment, SegmentConfig};
use ferrocat_wire::register::{AlState, AlStatus, Fmmu, SyncManager};
use ferrocat_wire::{Address, Command};

fn ek1100_el2004_el2004() -> Segment {
    let dir = ferrocat_testdata::shared("captures/eeprom");
    let toml = format!(
        "seed = 1\n[[device]]\neeprom = '{0}/ek1100.hex'\n[[device]]\neeprom = '{0}/el2004.bin'\n[[device]]\neeprom = '{0}/el2004.bin'\n",
        dir.display()
    );
    let path = std::env::temp_dir().join(format!("ferrocat-seg-{}.toml", std::process::id()));
    std::fs::write(&path, toml).unwrap();
    let cfg = SegmentConfig::from_file(&path).unwrap();
    std::fs::remove_file(&path).ok();
    cfg.build().unwrap()
}

#[test]
fn needs_shared_bring_up_delays_and_outputs() {
    let mut bus = Bus::new(ek1100_el2004_el2004());
    // Count: BRD increments ADP at every slave and WKC at every one that answers.
    let (_, wkc, addr) = bus.tx(Command::BRD, Address::Device { adp: 0, ado: 0 }, &[0]);
    assert_eq!((wkc, addr), (3, Address::Device { adp: 3, ado: 0 }));
    // Station addresses by position, then identity from the SII through the EEPROM interface.
    for pos in 0..3u16 {
        let (_, w, _) = bus.tx(Command::APWR, Address::position(pos, 0x0010), &(0x1001 + pos).to_le_bytes());
        assert_eq!(w, 1);
    }
    let ek = bus.sii_read(0x1001, 0x0A);
    assert_eq!(u32::from_le_bytes(ek), 0x044C_2C52);
    assert_eq!(u32::from_le_bytes(bus.sii_read(0x1003, 0x0A)), 0x07D4_3052);
    // DC: latch receive times, compute delays the way SOEM does.
    assert_eq!(bus.tx(Command::BWR, Address::Device { adp: 0, ado: 0x0900 }, &[0; 4]).1, 3);
    let mut t = vec![];
    for s in 0x1001..=0x1003 {
        let (d, _) = bus.fp(Command::FPRD, s, 0x0900, &[0; 16]);
        let p: Vec<u32> = d.chunks(4).map(|c| u32::from_le_bytes([c[0], c[1], c[2], c[3]])).collect();
        t.push(p);
    }
    let loop_time = |k: usize| t[k][1].wrapping_sub(t[k][0]) as i64;
    let d1 = (loop_time(0) - loop_time(1)) / 2;
    let d2 = d1 + loop_time(1) / 2;
    println!("loop times {} {} ns; SOEM-style delays {d1} {d2} ns", loop_time(0), loop_time(1));
    assert!((d1 - 144).abs() <= 10 && (d2 - 299).abs() <= 10, "delays {d1} {d2}");
    // DL status: EK1100 ports 0 and 1 active, the last EL2004 only port 0.
    let (dl, _) = bus.fp(Command::FPRD, 0x1003, 0x0110, &[0; 2]);
    let dl = ferrocat_wire::register::DlStatus(u16::from_le_bytes([dl[0], dl[1]]));
    assert!(dl.port_active(0) && !dl.port_active(1));
    // AL: PREOP, SAFEOP (after SM + FMMU), OP.
    assert_eq!(bus.tx(Command::BWR, Address::Device { adp: 0, ado: 0x0120 }, &[2, 0]).1, 3);
    let (st, w, _) = bus.tx(Command::BRD, Address::Device { adp: 0, ado: 0x0130 }, &[0, 0]);
    assert_eq!((AlStatus(u16::from_le_bytes([st[0], st[1]])).state(), w), (Some(AlState::PreOp), 3));
    for (k, s) in [0x1002u16, 0x1003].into_iter().enumerate() {
        let sm = SyncManager { start: 0x0F00, length: 1, control: 0x44, status: 0, activate: 1, pdi_control: 0 };
        assert_eq!(bus.fp(Command::FPWR, s, 0x0800, &sm.to_bytes()).1, 1);
        // SOEM packs both 4-bit terminals into one logical byte: bits 0-3 and 4-7.
        let f = Fmmu {
            logical_start: 0,
            length: 1,
            logical_start_bit: 4 * k as u8,
            logical_stop_bit: 4 * k as u8 + 3,
            physical_start: 0x0F00,
            physical_start_bit: 0,
            fmmu_type: Fmmu::WRITE,
            active: true,
        };
        assert_eq!(bus.fp(Command::FPWR, s, 0x0600, &f.to_bytes()).1, 1);
    }
    bus.tx(Command::BWR, Address::Device { adp: 0, ado: 0x0120 }, &[4, 0]);
    bus.tx(Command::BWR, Address::Device { adp: 0, ado: 0x0120 }, &[8, 0]);
    let (st, _, _) = bus.tx(Command::BRD, Address::Device { adp: 0, ado: 0x0130 }, &[0, 0]);
    assert_eq!(AlStatus(u16::from_le_bytes([st[0], st[1]])).state(), Some(AlState::Op));
    // Process data: 0xA5 → first EL2004 gets 0x5, the second 0xA; WKC: two writers.
    let (_, wkc, _) = bus.tx(Command::LRW, Address::Logical(0), &[0xA5]);
    assert_eq!(wkc, 4);
    let outs: Vec<Vec<u8>> = bus.seg.nodes[1..]
        .iter()
        .map(|n| n.esc.app().as_any().downcast_ref::<DigitalIo>().unwrap().outputs.clone())
        .collect();
    assert_eq!(outs, [vec![0x05], vec![0x0A]]);
}

#[test]
fn builtin_devices_and_bad_descriptions() {
    let cfg = SegmentConfig::from_device_args(&["EK1100".into(), "EL1004".into(), "EL2004".into()]).unwrap();
    let mut bus = Bus::new(cfg.build().unwrap());
    assert_eq!(bus.tx(Command::BRD, Address::Device { adp: 0, ado: 0 }, &[0]).1, 3);
    assert!(SegmentConfig::from_device_args(&["EL9999".into()])
        .unwrap()
        .build()
        .unwrap_err()
        .to_string()
        .contains("unknown built-in"));
    let p = std::env::temp_dir().join(format!("ferrocat-bad-{}.toml", std::process::id()));
    std::fs::write(&p, "seed = 1\n[[device]]\nbuiltin = 'EK1100'\ncolour = 'red'\n").unwrap();
    let e = SegmentConfig::from_file(&p).unwrap_err().to_string();
    std::fs::remove_file(&p).ok();
    assert!(e.contains("line 4") && e.contains("colour"), "{e}");
    let e = SegmentConfig::from_device_args(&["/nonexistent/x.bin".into()]).unwrap().build().unwrap_err().to_string();
    assert!(e.contains("/nonexistent/x.bin"), "{e}");
    // Wiring: a port the device lacks, a parent for the first device, a port taken twice.
    for (toml, want) in [
        ("[[device]]\nbuiltin = 'EK1100'\nport = 3\n", "device 0 (EK1100): port 3 does not exist"),
        (
            "[[device]]\nbuiltin = 'EK1100'\nparent_port = 1\n",
            "device 0 (EK1100): the first device hangs on the master",
        ),
        (
            "[[device]]\nbuiltin = 'EK1100'\nport = 2\n[[device]]\nbuiltin = 'EL2004'\nparent_port = 2\n",
            "device 1 (EL2004): port 2 of 'EK1100' is already in use",
        ),
        (
            "[[device]]\nbuiltin = 'EK1100'\ncable_m = 5.0\n",
            "device 0 (EK1100): the first device's link is the master's",
        ),
        // Numbers out of their range, NaN and infinity among them: an error naming the key,
        // never a panic (NaN spread), a hang (a free-running period that rounds to 0 ns) or a
        // frequency error taken as given (1e300 ppm).
        ("drift_spread_ppm = nan\n[[device]]\nbuiltin = 'EK1100'\n", "segment: drift_spread_ppm NaN out of range"),
        ("[[device]]\nbuiltin = 'EK1100'\ndrift_ppm = 1e300\n", "device 0: drift_ppm 1e300 out of range"),
        (
            "[[device]]\nbuiltin = 'EL1004'\napp = 'free-run'\napp_period_us = 1e-9\n",
            "device 0: app_period_us 1e-9 out of range",
        ),
        (
            "[[device]]\nbuiltin = 'EK1100'\nwander_ppb_per_sqrt_s = inf\n",
            "device 0: wander_ppb_per_sqrt_s inf out of range",
        ),
        ("[[device]]\nbuiltin = 'EK1100'\nal_response_us = -1\n", "device 0: al_response_us -1.0 out of range"),
        (
            "[[device]]\nbuiltin = 'EK1100'\n[[device]]\nbuiltin = 'EL2004'\napp = 'dc'\nsync_unit = false\n",
            "device 1: app = \"dc\" needs sync_unit = true",
        ),
        (
            "[[device]]\nbuiltin = 'EK1100'\n[[device]]\nbuiltin = 'EL2004'\ncable_m = -5\n",
            "device 1 (EL2004): cable_m -5.0 out of range",
        ),
        (
            "[[device]]\nbuiltin = 'EL2004'\nhome_switch_rev = 1.0\n",
            "device 0: limit and home switches need a CiA402 drive",
        ),
        (
            "[[device]]\nbuiltin = 'LAN9252-EVB'\napp = 'dc'\n",
            "device 0: app = \"dc\" has no CoE server, and this device's SII names CoE",
        ),
        (
            "[[device]]\nbuiltin = 'EL2004'\nsync_error_limit = 4\n",
            "device 0: sync_error_limit needs app = \"dc\" or a CiA402 drive",
        ),
        (
            "[[device]]\nbuiltin = 'EL2004'\napp = 'dc'\nsync_error_limit = 4\n",
            "device 0: sync_error_limit needs a firmware behind AL control (device_emulation = false)",
        ),
        (
            "[[device]]\nbuiltin = 'SERVO'\nnegative_limit_rev = 2.0\npositive_limit_rev = -2.0\n",
            "device 0: negative_limit_rev (2) must lie below positive_limit_rev (-2)",
        ),
        ("[[device]]\nbuiltin = 'SERVO'\nhome_switch_rev = nan\n", "device 0: home_switch_rev NaN out of range"),
        (
            "[[device]]\nbuiltin = 'SERVO'\nhome_switch_rev = 2.0\nhome_switch_to_rev = 1.0\n",
            "device 0: home_switch_to_rev (1) must lie above home_switch_rev (2)",
        ),
        (
            "[[device]]\nbuiltin = 'SERVO'\nhome_switch_to_rev = 1.0\n",
            "device 0: home_switch_to_rev needs home_switch_rev",
        ),
        ("loss_probability = 1.5\n[[device]]\nbuiltin = 'EK1100'\n", "segment: loss_probability 1.5 out of range"),
        (
            "[[device]]\nbuiltin = 'EK1100'\n[[device]]\nbuiltin = 'EL2004'\ncable_m = 5\nlink_ns = 500\n",
            "device 1 (EL2004): give cable_m or link_ns, not both",
        ),
    ] {
        let cfg: SegmentConfig = toml::from_str(toml).unwrap();
        let e = cfg.build().unwrap_err().to_string();
        assert!(e.contains(want), "{toml}: {e}");
    }
}

/// One frame at a time on the master's link: a frame handed over while the one before is
/// still on the wire leaves after it and the 12-byte gap, and comes back that much later.
#[test]
fn frames_handed_over_together_leave_one_after_another() {
    let cfg = SegmentConfig::from_device_args(&["EK1100".into(), "EL2004".into()]).unwrap();
    let mut seg = cfg.build().unwrap();
    let eth = ferrocat_wire::ethernet::EthernetRepr {
        dst: ferrocat_wire::ethernet::BROADCAST,
        src: [0x10; 6],
        vlan_tci: None,
        ethertype: 0,
    };
    let frame = |len: u16| {
        let mut buf = vec![0u8; 1514];
        let mut w = ferrocat_wire::FrameWriter::new(&mut buf, &eth).unwrap();
        let h = ferrocat_wire::DatagramHeader::new(Command::BRD, 1, Address::Device { adp: 0, ado: 0 }, len);
        w.push(&h, &vec![0; len as usize], 0).unwrap();
        let n = w.finish().unwrap();
        buf.truncate(n);
        buf
    };
    let t0 = 5_000_000;
    // Alone: leaves when handed over.
    let mut a = frame(200);
    let alone = seg.exchange(&mut a, t0).unwrap() - t0;
    assert_eq!(seg.last_departure_ns(), t0);
    // Two handed over 1 µs apart: the second waits for the first's 8 + len + 4 bytes and the gap.
    let t1 = t0 + 1_000_000;
    let mut first = frame(200);
    let wire_ns = (8 + first.len() as u64 + 4 + 12) * 80;
    let back_first = seg.exchange(&mut first, t1).unwrap();
    assert_eq!(back_first - t1, alone);
    let mut second = frame(200);
    let back_second = seg.exchange(&mut second, t1 + 1_000).unwrap();
    assert_eq!(seg.last_departure_ns(), t1 + wire_ns);
    assert_eq!(back_second - back_first, wire_ns);
    // Handed over after the link is free again: no wait.
    let t2 = t1 + 2 * wire_ns + 50_000;
    let mut third = frame(200);
    seg.exchange(&mut third, t2).unwrap();
    assert_eq!(seg.last_departure_ns(), t2);
}
