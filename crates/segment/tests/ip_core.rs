//! The `ipcore` ESC kind, which the segment gives the Kollmorgen AKD's EEPROM dump, against
//! what the real drive answered in its captures (soem-sdinfo-akd, twincat-akd-nc-mode).
mod common;

use common::Bus;
use ferrocat_wire::register::SiiControl;
use ferrocat_wire::{Address, Command};

const S: u16 = 0x1001;

/// The AKD's dump on the ESC the segment picks for it, or on `esc`.
fn akd(esc: Option<&str>) -> Bus {
    let dump = ferrocat_testdata::shared("captures/eeprom/akd.hex");
    let esc = esc.map(|e| format!("esc = '{e}'\n")).unwrap_or_default();
    Bus::addressed(&format!("[[device]]\neeprom = '{}'\n{esc}", dump.display()))
}

#[test]
fn needs_shared_the_ip_core_answers_as_the_akd_did() {
    // Its identity (vendor 0x6A, product 0x414B44) picks the IP core.
    let mut bus = akd(None);
    // TwinCAT's APRD of 0x0000–0x0009 on the real drive.
    let (id, _) = bus.fp(Command::FPRD, S, 0x0000, &[0; 10]);
    assert_eq!(id, [0x04, 0x02, 0x43, 0x00, 0x03, 0x04, 0x04, 0x0F, 0x84, 0x01]);
    // SOEM's APRD of PDI control: fixed in the core, whatever the dump's word 0 (0x0009) says.
    assert_eq!(bus.fp(Command::FPRD, S, 0x0140, &[0; 2]).0, [0x08, 0x0C]);
    // SOEM's reads of the SII interface: 0x0020, an emulated EEPROM with 4-byte reads.
    let (ctl, _) = bus.fp(Command::FPRD, S, 0x0502, &[0; 2]);
    assert_eq!(u16::from_le_bytes([ctl[0], ctl[1]]) & 0x00E0, SiiControl::EMULATION);
    // A 32-bit DC: the upper halves of the system time and of 0x0918 read 0 (SOEM's 8-byte
    // read of 0x0918: fa1f8a59 00000000), and a 4-byte ARMW distributes the time (TwinCAT).
    bus.tx(Command::BWR, Address::Device { adp: 0, ado: 0x0900 }, &[0; 4]);
    assert_eq!(bus.fprd_u64(S, 0x0918) >> 32, 0);
    assert_eq!(bus.fprd_u64(S, 0x0910) >> 32, 0);
    assert_eq!(bus.tx(Command::ARMW, Address::position(0, 0x0910), &[0; 4]).1, 1);
    // Asked for, the same dump sits on an ET1100, which the drive is not.
    let mut et = akd(Some("et1100"));
    assert_eq!(et.fp(Command::FPRD, S, 0x0000, &[0; 1]).0, [0x11]);
}
