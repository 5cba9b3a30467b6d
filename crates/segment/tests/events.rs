//! ECAT events: the event request register 0x0210, its mask 0x0200 and the IRQ field every ESC
//! ORs them into, and the SyncManager status bits behind the mailbox events — as the real
//! captures show them (SOEM sets the mask to 0x0004 and sees the DL status event in every
//! datagram until it has read each slave's DL status).
mod common;

use common::Bus;
use ferrocat_segment::SegmentConfig;
use ferrocat_wire::register::SyncManager;
use ferrocat_wire::{Address, Command};

fn line() -> Bus {
    let toml =
        "seed = 5\n[[device]]\nbuiltin = 'EK1100'\n[[device]]\nbuiltin = 'EL2004'\n[[device]]\nbuiltin = 'EL1004'\n";
    let cfg: SegmentConfig = toml::from_str(toml).unwrap();
    let mut bus = Bus::new(cfg.build().unwrap());
    bus.address_all();
    bus
}

fn brd(bus: &mut Bus, ado: u16, len: usize) -> u16 {
    bus.tx(Command::BRD, Address::Device { adp: 0, ado }, &vec![0; len]);
    bus.irqs[0]
}

fn fp_irq(bus: &mut Bus, cmd: Command, station: u16, ado: u16, data: &[u8]) -> u16 {
    bus.fp(cmd, station, ado, data);
    bus.irqs[0]
}

#[test]
fn dl_and_al_status_events_reach_the_irq_field_through_the_mask() {
    let mut bus = line();
    // Power-on brought the DL status up: the event is requested, but the mask (reset 0) hides it.
    let (req, _) = bus.fp(Command::FPRD, 0x1001, 0x0210, &[0; 2]);
    assert_eq!(u16::from_le_bytes([req[0], req[1]]), 0x0004);
    assert_eq!(brd(&mut bus, 0x0000, 2), 0);
    // The datagram that writes the mask carries the IRQ as it was before it (SOEM capture,
    // frames 12–15: 0, then 4 in every datagram).
    bus.tx(Command::BWR, Address::Device { adp: 0, ado: 0x0200 }, &[0x04, 0x00]);
    assert_eq!(bus.irqs[0], 0);
    assert_eq!(brd(&mut bus, 0x0000, 2), 0x0004);
    // Reading one slave's DL status clears its event only; the datagram that reads the last
    // one still carries it (TwinCAT capture, frames 1032–1036).
    assert_eq!(fp_irq(&mut bus, Command::FPRD, 0x1001, 0x0110, &[0; 2]), 0x0004);
    assert_eq!(fp_irq(&mut bus, Command::FPRD, 0x1002, 0x0111, &[0]), 0x0004);
    assert_eq!(brd(&mut bus, 0x0000, 2), 0x0004, "the third slave's event is still pending");
    assert_eq!(fp_irq(&mut bus, Command::FPRD, 0x1003, 0x0110, &[0; 2]), 0x0004);
    assert_eq!(brd(&mut bus, 0x0000, 2), 0, "every DL status read");
    // A change of the DL status raises it again: loop control closes the second slave's port 1
    // (the third is cut off), then opens it.
    bus.fp(Command::FPWR, 0x1002, 0x0101, &[0x0C]);
    assert_eq!(brd(&mut bus, 0x0000, 2), 0x0004);
    let (dl, _) = bus.fp(Command::FPRD, 0x1002, 0x0110, &[0; 2]);
    assert_eq!(dl[1] & 0x04, 0x04, "DL status: port 1 loop closed");
    assert_eq!(bus.irqs[0], 0x0004, "the reading datagram carries the event");
    let (_, wkc, _) = bus.tx(Command::BRD, Address::Device { adp: 0, ado: 0x0110 }, &[0; 2]);
    assert_eq!((bus.irqs[0], wkc), (0, 2), "two slaves reached, the first one's DL status unchanged");
    bus.fp(Command::FPWR, 0x1002, 0x0101, &[0x00]);
    assert_eq!(brd(&mut bus, 0x0000, 2), 0x0004);
    let (_, wkc, _) = bus.tx(Command::BRD, Address::Device { adp: 0, ado: 0x0110 }, &[0; 2]);
    assert_eq!((bus.irqs[0], wkc), (0x0004, 3));
    assert_eq!(brd(&mut bus, 0x0000, 2), 0, "a broadcast read of 0x0110 cleared it; the third slave's had not changed");

    // AL status events, once the mask lets them through.
    bus.tx(Command::BWR, Address::Device { adp: 0, ado: 0x0200 }, &[0x0C, 0x00]);
    assert_eq!(brd(&mut bus, 0x0000, 2), 0, "nothing changed since");
    bus.fp(Command::FPWR, 0x1002, 0x0120, &[0x02, 0x00]);
    bus.t += 2_000_000; // the firmware answers after ≈ 1 ms
    assert_eq!(brd(&mut bus, 0x0000, 2), 0x0008, "the second slave went to PREOP");
    let (req, _) = bus.fp(Command::FPRD, 0x1002, 0x0210, &[0; 2]);
    assert_eq!(u16::from_le_bytes([req[0], req[1]]), 0x0008);
    assert_eq!(fp_irq(&mut bus, Command::FPRD, 0x1002, 0x0130, &[0; 2]), 0x0008);
    assert_eq!(brd(&mut bus, 0x0000, 2), 0);
    // Masked off again: the request stays, the IRQ field does not show it.
    bus.fp(Command::FPWR, 0x1002, 0x0120, &[0x01, 0x00]);
    bus.t += 2_000_000;
    bus.tx(Command::BWR, Address::Device { adp: 0, ado: 0x0200 }, &[0x00, 0x00]);
    assert_eq!(brd(&mut bus, 0x0000, 2), 0);
    let (req, _) = bus.fp(Command::FPRD, 0x1002, 0x0210, &[0; 2]);
    assert_eq!(u16::from_le_bytes([req[0], req[1]]), 0x0008);
    // 0x0210 is read-only for the master: the write neither takes nor counts.
    assert_eq!(bus.fp(Command::FPWR, 0x1002, 0x0210, &[0; 2]).1, 0);
    let (req, _) = bus.fp(Command::FPRD, 0x1002, 0x0210, &[0; 2]);
    assert_eq!(u16::from_le_bytes([req[0], req[1]]), 0x0008);
}

#[test]
fn a_latch_event_is_requested_until_its_time_is_read() {
    // The EK1100 (ET1100, latch unit on): the terminals' ET1200s answer their receive times only.
    let mut bus = line();
    bus.fp(Command::FPWR, 0x1001, 0x0200, &[0x01, 0x00]);
    bus.fp(Command::FPWR, 0x1001, 0x09A8, &[0x01]); // rising edge: single event
    let t = bus.t;
    bus.seg.nodes[0].esc.latch_input(0, true, t + 1_000);
    bus.t = t + 10_000;
    assert_eq!(brd(&mut bus, 0x0000, 2), 0x0001);
    assert_eq!(fp_irq(&mut bus, Command::FPRD, 0x1001, 0x09B0, &[0; 8]), 0x0001);
    assert_eq!(brd(&mut bus, 0x0000, 2), 0, "reading the edge's time cleared it");
    // Continuous mode keeps no event.
    let t = bus.t;
    bus.seg.nodes[0].esc.latch_input(0, false, t + 1_000);
    bus.t = t + 10_000;
    assert_eq!(brd(&mut bus, 0x0000, 2), 0);
}

#[test]
fn needs_shared_mailbox_status_bits_and_syncmanager_events() {
    const S: u16 = 0x1001;
    const OUT: (u16, u16) = (0x1000, 128);
    const INP: (u16, u16) = (0x1080, 128);
    let esi = ferrocat_testdata::shared("esi/Nanotec_C5-E-2-21.xml");
    let cfg = SegmentConfig::from_device_args(&[format!("{}:0x4F", esi.display())]).unwrap();
    let mut bus = Bus::new(cfg.build().unwrap());
    bus.address_all();
    // SM1 with its ECAT event enabled (control bit 4); the mask lets SM1's event (bit 5) through.
    for (n, (start, length), control) in [(0u16, OUT, 0x26u8), (1, INP, 0x32)] {
        let sm = SyncManager { start, length, control, status: 0, activate: 1, pdi_control: 0 };
        assert_eq!(bus.fp(Command::FPWR, S, 0x0800 + 8 * n, &sm.to_bytes()).1, 1);
    }
    bus.fp(Command::FPWR, S, 0x0200, &[0x20, 0x00]);
    assert_eq!(bus.request_state(S, 2).0, 2, "PREOP");
    let status = |bus: &mut Bus, n: u16| bus.fp(Command::FPRD, S, 0x0805 + 8 * n, &[0]).0[0];
    assert_eq!((status(&mut bus, 0), status(&mut bus, 1)), (0x00, 0x00));
    assert_eq!(bus.irqs[0], 0);
    // An SDO upload request of 0x1000:00 (device type).
    let mut req = vec![0u8; OUT.1 as usize];
    req[..16].copy_from_slice(&[10, 0, 0, 0, 0, 0x13, 0x00, 0x20, 0x40, 0x00, 0x10, 0x00, 0, 0, 0, 0]);
    assert_eq!(bus.fp(Command::FPWR, S, OUT.0, &req).1, 1);
    // The firmware read the request (SM0: buffer read) and wrote the reply (SM1: written, full)
    // — the values real slaves show in the captures once their firmware has answered.
    assert_eq!(status(&mut bus, 0), SyncManager::STATUS_INT_READ);
    assert_eq!(status(&mut bus, 1), SyncManager::STATUS_INT_WRITE | SyncManager::STATUS_MAILBOX_FULL);
    assert_eq!(bus.irqs[0], 0x0020, "SM1's event");
    let (reply, wkc) = bus.fp(Command::FPRD, S, INP.0, &vec![0; INP.1 as usize]);
    assert_eq!(wkc, 1);
    assert_eq!(bus.irqs[0], 0x0020, "the reading datagram still carries it");
    assert_eq!(reply[5] & 0x0F, 3, "a CoE reply");
    assert_eq!(status(&mut bus, 1), SyncManager::STATUS_INT_READ, "read completely, empty");
    assert_eq!(bus.irqs[0], 0);
    // The master's next write opens SM0 again: the firmware's read event goes.
    let mut part = req.clone();
    part.truncate(8);
    bus.fp(Command::FPWR, S, OUT.0, &part);
    assert_eq!(status(&mut bus, 0), 0x00, "opened, not yet complete");
}
