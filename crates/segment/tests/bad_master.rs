//! What a faulty master may write must not stop the simulator: each case here is one the
//! `segment` fuzz target found (fuzz/fuzz_targets/segment.rs), kept as a regression test.
mod common;
use common::Bus;
use ferrocat_segment::SegmentConfig;
use ferrocat_wire::register::SyncManager;
use ferrocat_wire::Command;

const STATION: u16 = 0x1001;

/// An ET1100-like ESC (4 KiB of registers and 8 KiB of process RAM: memory ends at 0x3000).
fn et1100_bus() -> Bus {
    let cfg: SegmentConfig = toml::from_str("[[device]]\nbuiltin = 'EL2004'\nesc = 'et1100'\n").unwrap();
    let mut bus = Bus::new(cfg.build().unwrap());
    bus.address_all();
    bus
}

fn configure_sm(bus: &mut Bus, n: u16, start: u16, length: u16, control: u8) {
    let sm = SyncManager { start, length, control, status: 0, activate: 1, pdi_control: 0 };
    assert_eq!(bus.fp(Command::FPWR, STATION, 0x0800 + 8 * n, &sm.to_bytes()).1, 1, "SM{n} configured");
}

/// A buffered SyncManager whose area runs past the end of the memory: its bytes inside are
/// written (into the buffer), its last byte does not exist, so the buffer never completes and
/// the memory keeps what it held. Until 2026-11-24 the first write panicked copying the area.
#[test]
fn a_buffered_sync_manager_past_the_end_of_memory_never_completes() {
    let mut bus = et1100_bus();
    configure_sm(&mut bus, 2, 0x2FF8, 0x10, 0x44);
    let (_, wkc) = bus.fp(Command::FPWR, STATION, 0x2FF8, &[0xA5; 8]);
    assert_eq!(wkc, 1, "the bytes inside the memory are written");
    let (_, wkc) = bus.fp(Command::FPWR, STATION, 0x3000, &[0xA5; 8]);
    assert_eq!(wkc, 0, "nothing beyond the memory");
    let (data, wkc) = bus.fp(Command::FPRD, STATION, 0x2FF8, &[0; 8]);
    assert_eq!((data, wkc), (vec![0; 8], 1), "the buffer never completed");
    assert_eq!(bus.fprd_u32(STATION, 0x0010) & 0xFFFF, STATION as u32, "the ESC still answers");
}

/// A send mailbox whose area runs past the end: a reply is put into it as far as the memory
/// goes, and as its last byte cannot be read, it stays full. Until 2026-11-24 putting the reply
/// there panicked.
#[test]
fn a_send_mailbox_past_the_end_of_memory_holds_what_fits() {
    let mut bus = et1100_bus();
    configure_sm(&mut bus, 0, 0x1000, 0x20, 0x26);
    configure_sm(&mut bus, 1, 0x2FF0, 0x40, 0x22);
    // A request of a protocol the terminal does not speak (type 0x0F): the ESC answers with a
    // mailbox error.
    let mut request = vec![10, 0, 0, 0, 0, 0x1F];
    request.resize(0x20, 0);
    assert_eq!(bus.fp(Command::FPWR, STATION, 0x1000, &request).1, 1, "the request");
    for _ in 0..2 {
        let (reply, wkc) = bus.fp(Command::FPRD, STATION, 0x2FF0, &[0; 16]);
        assert_eq!(wkc, 1, "the reply's bytes inside the memory are readable");
        assert_eq!(reply[5] & 0x0F, 0, "a mailbox error reply: {reply:02x?}");
    }
    assert_eq!(bus.fprd_u32(STATION, 0x0010) & 0xFFFF, STATION as u32, "the ESC still answers");
}
