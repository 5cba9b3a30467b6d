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
    let cfg: SegmentConfig =
        toml::from_str("[[device]]\nbuiltin = 'EL2004'\nesc = 'et1100'\nsync_unit = true\n").unwrap();
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
/// the memory keeps what it held (no panic copying the area).
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
/// goes, and as its last byte cannot be read, it stays full (no panic putting it there).
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

/// Programs SYNC0 on the ET1100 terminal: `cycle_ns`, the first pulse 1 ms ahead; returns that
/// start time.
fn start_sync0(bus: &mut Bus, cycle_ns: u32) -> u64 {
    use ferrocat_wire::register::dc_activation as act;
    let start = bus.fprd_u64(STATION, 0x0910) + 1_000_000;
    bus.fp(Command::FPWR, STATION, 0x0981, &[0]);
    bus.fp(Command::FPWR, STATION, 0x09A0, &cycle_ns.to_le_bytes());
    bus.fp(Command::FPWR, STATION, 0x0990, &start.to_le_bytes());
    bus.fp(Command::FPWR, STATION, 0x0981, &[act::CYCLIC_OPERATION | act::SYNC0]);
    start
}

/// A SYNC0 cycle of 10 ns in acknowledge mode, then 65 ms without a frame: 6.4 million pulses.
/// The application sees one edge per PDI service time (1 µs); the others fall while the signal
/// is still asserted, are counted, and 0x0990 still shows the next pulse on the grid. Listing
/// every pulse before handing them over would take 2 GiB for this gap (the `segment` fuzz
/// target found it as an out-of-memory).
#[test]
fn a_sync0_cycle_of_a_few_ns_neither_stalls_nor_exhausts_memory() {
    let mut bus = et1100_bus();
    let start = start_sync0(&mut bus, 10);
    let t0 = bus.t;
    bus.seg.advance_to(t0 + 65_000_000);
    let esc = &bus.seg.nodes[0].esc;
    let log = esc.sync0_log.clone();
    let sys_now = esc.dc.as_ref().unwrap().system_at(t0 + 65_000_000);
    assert_eq!(log.count, (sys_now - start) / 10 + 1, "every pulse on the grid up to now counted");
    let seen = log.count - log.merged;
    assert!((50_000..=65_001).contains(&seen), "{seen} edges seen in 65 ms");
    for w in log.pulses.iter().collect::<Vec<_>>().windows(2) {
        assert!(w[1].1 - w[0].1 > 1_000, "edges {w:?} closer than the service time");
    }
    bus.t = bus.t.max(t0 + 65_000_000);
    let next = bus.fprd_u64(STATION, 0x0990);
    assert_eq!((next - start) % 10, 0, "0x0990 {next} on the grid");
    assert!(next > sys_now, "0x0990 {next} shows a pulse to come (now {sys_now})");
}

/// A pulse length (SII word 2, 10 µs here) greater than the cycle time keeps the output active
/// (ESC datasheet section I, 9.2.3.1): one edge for the application however many pulses follow;
/// with a cycle longer than the pulse every pulse is an edge again. The pulse length is the
/// EEPROM's: a master cannot write 0x0982.
#[test]
fn a_pulse_length_longer_than_the_cycle_holds_the_output() {
    // The terminal's EEPROM as a master would dump it, with word 2 set to 1000 × 10 ns.
    let mut bus = common::patched_device(&mut et1100_bus(), STATION, |h| h.sync_impulse_len = 1_000);
    assert_eq!(bus.fp(Command::FPRD, STATION, 0x0982, &[0; 2]).0, 1_000u16.to_le_bytes(), "from the EEPROM");
    bus.fp(Command::FPWR, STATION, 0x0982, &0u16.to_le_bytes());
    assert_eq!(bus.fp(Command::FPRD, STATION, 0x0982, &[0; 2]).0, 1_000u16.to_le_bytes(), "ECAT read-only");

    let start = start_sync0(&mut bus, 5_000);
    let t0 = bus.t;
    bus.seg.advance_to(t0 + 10_000_000);
    let esc = &bus.seg.nodes[0].esc;
    let sys_now = esc.dc.as_ref().unwrap().system_at(t0 + 10_000_000);
    let log = &esc.sync0_log;
    assert_eq!(log.count, (sys_now - start) / 5_000 + 1, "every pulse counted");
    assert_eq!(log.count - log.merged, 1, "one edge while held");
    bus.t = bus.t.max(t0 + 10_000_000);
    let start = start_sync0(&mut bus, 50_000);
    let merged = bus.seg.nodes[0].esc.sync0_log.merged;
    let t1 = bus.t;
    bus.seg.advance_to(t1 + 2_000_000);
    let esc = &bus.seg.nodes[0].esc;
    let sys_now = esc.dc.as_ref().unwrap().system_at(t1 + 2_000_000);
    let log = &esc.sync0_log;
    assert_eq!(log.merged, merged, "50 µs cycle with 10 µs pulses: every pulse an edge");
    assert_eq!(log.pulses.back().unwrap().0, start + (sys_now - start) / 50_000 * 50_000, "the last edge");
}
