//! FoE between the master's client and the simulated drive's file server, in virtual time.
use ferrocat_esc::{Cia402Drive, FoeServer};
use ferrocat_master::Master;
use ferrocat_segment::SegmentConfig;
use ferrocat_segment::{HostModel, VirtualIo};
use ferrocat_wire::foe::max_data_len;

const DRIVE: u16 = 1;

/// EK1100 and the built-in servo (whose SII names FoE), in PREOP.
fn master(drive_keys: &str) -> Master<VirtualIo> {
    let toml = format!("seed = 5\n[[device]]\nbuiltin = 'EK1100'\n[[device]]\nbuiltin = 'SERVO'\n{drive_keys}\n");
    let cfg: SegmentConfig = toml::from_str(&toml).unwrap();
    let mut m = Master::new(VirtualIo::new(cfg.build().unwrap(), HostModel::pc_rt(), 5));
    m.states().scan().unwrap();
    m.states().configure().unwrap();
    m
}

fn server(m: &Master<VirtualIo>) -> &FoeServer {
    let app = m.io().seg.nodes[DRIVE as usize].esc.app();
    app.as_any().downcast_ref::<Cia402Drive>().unwrap().coe.foe.as_ref().expect("the drive serves FoE")
}

/// A file of `n` bytes that no shift of itself matches (a lost or repeated packet shows).
fn file(n: usize) -> Vec<u8> {
    (0..n).map(|k| (k * 7 + k / 251) as u8).collect()
}

#[test]
fn files_of_every_length_go_there_and_back() {
    let mut m = master("");
    let packet = max_data_len(m.slaves().at(DRIVE).unwrap().mailbox().unwrap().out.1 as usize);
    assert!(packet > 0);
    // Empty, shorter than a packet, exactly one and three packets (an empty packet ends those),
    // and a few packets and a bit.
    for n in [0, 1, packet - 1, packet, 3 * packet, 5 * packet + 17] {
        let name = format!("file-{n}.bin");
        let data = file(n);
        m.acyclic().foe().write(DRIVE, &name, 0, &data).unwrap();
        assert_eq!(server(&m).files.get(name.as_bytes()), Some(&data), "{n} bytes stored");
        assert_eq!(m.acyclic().foe().read(DRIVE, &name, 0, 1 << 20).unwrap(), data, "{n} bytes read back");
    }
    let s = server(&m);
    assert_eq!((s.writes, s.reads), (6, 6));
    // A file read into too small a bound is an error, not a shorter file.
    let e = m.acyclic().foe().read(DRIVE, &format!("file-{}.bin", 3 * packet), 0, packet + 1).unwrap_err().to_string();
    assert!(e.contains("longer than"), "{e}");
    // The aborted transfer left the server ready for the next.
    assert_eq!(m.acyclic().foe().read(DRIVE, "file-1.bin", 0, 10).unwrap(), file(1));
}

#[test]
fn the_slaves_errors_reach_the_caller_by_name() {
    let mut m = master("foe_password = 0x0012_3456");
    let e = m.acyclic().foe().write(DRIVE, "fw.bin", 1, b"x").unwrap_err().to_string();
    assert!(e.contains("access denied") && e.contains("fw.bin"), "{e}");
    m.acyclic().foe().write(DRIVE, "fw.bin", 0x0012_3456, b"firmware").unwrap();
    let e = m.acyclic().foe().read(DRIVE, "none.bin", 0x0012_3456, 100).unwrap_err().to_string();
    assert!(e.contains("file not found") && e.contains("0x8001"), "{e}");
    assert_eq!(m.acyclic().foe().read(DRIVE, "fw.bin", 0x0012_3456, 100).unwrap(), b"firmware");
    // The coupler has no mailbox at all.
    let e = m.acyclic().foe().write(0, "fw.bin", 0, b"x").unwrap_err().to_string();
    assert!(e.contains("no mailbox"), "{e}");
}

#[test]
fn a_password_or_busy_on_a_device_without_foe_is_refused() {
    for key in ["foe_password", "foe_busy"] {
        let toml = format!("[[device]]\nbuiltin = 'EL2004'\n{key} = 1\n");
        let e = toml::from_str::<SegmentConfig>(&toml).unwrap().build().unwrap_err().to_string();
        assert!(e.contains("device 0") && e.contains(key), "{e}");
    }
}

#[test]
fn a_slave_busy_erasing_its_flash_gets_the_first_packet_again() {
    // The drive answers busy five times to the first data packet of every write.
    let mut m = master("foe_busy = 5");
    let packet = max_data_len(m.slaves().at(DRIVE).unwrap().mailbox().unwrap().out.1 as usize);
    for n in [1, 3 * packet + 5] {
        let name = format!("fw-{n}.bin");
        m.acyclic().foe().write(DRIVE, &name, 0, &file(n)).unwrap();
        assert_eq!(server(&m).files.get(name.as_bytes()), Some(&file(n)), "{n} bytes stored whole");
        assert_eq!(m.acyclic().foe().read(DRIVE, &name, 0, 1 << 20).unwrap(), file(n));
    }
    assert_eq!((server(&m).writes, server(&m).busy_sent), (2, 10));
}

/// Firmware the way it is loaded: the AKD (as its EEPROM dump describes it) into BOOT with the
/// SII's bootstrap mailbox (0x1800/0x1C00, 1 024 bytes each), a file by FoE — where CoE is not
/// served — then INIT with the standard mailbox and PREOP, where CoE answers again. The
/// built-in servo's SII has no bootstrap mailbox: the master says so, and the ESC refuses BOOT
/// with 0x0013.
#[test]
fn needs_shared_akd_eeprom_takes_firmware_in_boot() {
    use ferrocat_wire::register::AlState;
    let akd = ferrocat_testdata::shared("captures/eeprom/akd.hex");
    let mut m = master(&format!("[[device]]\neeprom = '{}'\n", akd.display()));
    let akd_at = 2;
    let standard = m.slaves().at(akd_at).unwrap().mailbox().cloned().unwrap();
    m.states().enter_bootstrap(akd_at).unwrap();
    let boot = m.slaves().at(akd_at).unwrap().mailbox().cloned().unwrap();
    assert_eq!((boot.out, boot.inp), ((0x1800, 1024), (0x1C00, 1024)));
    let e = m.acyclic().coe().sdo_read(akd_at, 0x1018, 1).unwrap_err().to_string();
    assert!(e.contains("protocol not supported"), "CoE in BOOT: {e}");
    let firmware = file(10_000);
    m.acyclic().foe().write(akd_at, "akd.i00", 0, &firmware).unwrap();
    let s = m.io().seg.nodes[akd_at as usize].esc.app();
    let files = &s.as_any().downcast_ref::<Cia402Drive>().unwrap().coe.foe.as_ref().unwrap().files;
    assert_eq!(files.get(&b"akd.i00"[..]), Some(&firmware));
    m.states().leave_bootstrap(akd_at).unwrap();
    assert_eq!(m.slaves().at(akd_at).unwrap().mailbox(), Some(&standard));
    m.states().request_state(akd_at, AlState::PreOp).unwrap();
    assert_eq!(m.acyclic().coe().sdo_read(akd_at, 0x1018, 1).unwrap(), 0x6Au32.to_le_bytes(), "CoE in PREOP again");
    // No bootstrap mailbox in the servo's SII.
    let e = m.states().enter_bootstrap(DRIVE).unwrap_err().to_string();
    assert!(e.contains("no bootstrap mailbox"), "{e}");
    m.states().request_state(DRIVE, AlState::Init).unwrap();
    let e = m.states().request_state(DRIVE, AlState::Bootstrap).unwrap_err().to_string();
    assert!(e.contains("0x0013"), "{e}");
}
