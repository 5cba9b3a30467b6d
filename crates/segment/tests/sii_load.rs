//! The ESC configuration area (SII words 0–7) and its checksum: what an ESC takes from it at
//! power-on and at a reload, and what it does when the checksum is wrong (Beckhoff, EtherCAT
//! Slave Controller Technology, Section I, "SII EEPROM content" and "SII EEPROM errors").
mod common;

use common::Bus;
use ferrocat_segment::{Event, BUILTIN_NAMES};
use ferrocat_wire::register::SiiControl;
use ferrocat_wire::{Address, Command};

const S: u16 = 0x1002;

fn u16_at(bus: &mut Bus, ado: u16) -> u16 {
    let (d, w) = bus.fp(Command::FPRD, S, ado, &[0; 2]);
    assert_eq!(w, 1, "read of {ado:#06x}");
    u16::from_le_bytes([d[0], d[1]])
}

/// Writes one EEPROM word through the SII interface and waits until it is programmed.
fn sii_write(bus: &mut Bus, word: u32, value: u16) {
    assert_eq!(bus.fp(Command::FPWR, S, 0x0508, &value.to_le_bytes()).1, 1);
    let mut cmd = 0x0201u16.to_le_bytes().to_vec();
    cmd.extend_from_slice(&word.to_le_bytes());
    assert_eq!(bus.fp(Command::FPWR, S, 0x0502, &cmd).1, 1);
    wait_idle(bus);
}

/// Polls the SII interface until it is no longer busy; its status then.
fn wait_idle(bus: &mut Bus) -> u16 {
    for _ in 0..1000 {
        let c = u16_at(bus, 0x0502);
        if c & SiiControl::BUSY == 0 {
            return c;
        }
        bus.t += 500_000;
    }
    panic!("the SII interface stays busy");
}

fn reload(bus: &mut Bus) -> u16 {
    assert_eq!(bus.fp(Command::FPWR, S, 0x0502, &0x0400u16.to_le_bytes()).1, 1);
    wait_idle(bus);
    // The configuration is taken when the reload is over, with the next frame.
    u16_at(bus, 0x0502)
}

/// The device at position 1 powered off and on; station address 0x1002 again.
fn power_cycle(bus: &mut Bus) {
    let t = bus.t;
    bus.seg.schedule(t + 1_000_000, Event::PowerOff { node: 1 });
    bus.seg.schedule(t + 2_000_000, Event::PowerOn { node: 1 });
    bus.t = t + 3_000_000;
    let (_, w, _) = bus.tx(Command::APWR, Address::position(1, 0x0010), &S.to_le_bytes());
    assert_eq!(w, 1);
}

fn crc_of(bus: &mut Bus) -> u16 {
    let mut header = Vec::new();
    for w in (0..8).step_by(2) {
        header.extend_from_slice(&bus.sii_read(S, w));
    }
    ferrocat_wire::sii::header_crc(&header) as u16
}

#[test]
fn every_builtin_device_loads_its_configuration_area() {
    for name in BUILTIN_NAMES {
        let mut bus = Bus::addressed(&format!("[[device]]\nbuiltin = '{name}'\n"));
        let (d, w) = bus.fp(Command::FPRD, 0x1001, 0x0110, &[0; 2]);
        assert_eq!(w, 1);
        assert_eq!(d[0] & 1, 1, "{name}: DL status bit 0, EEPROM loaded");
        let (d, _) = bus.fp(Command::FPRD, 0x1001, 0x0502, &[0; 2]);
        let ctl = u16::from_le_bytes([d[0], d[1]]);
        assert_eq!(ctl & (SiiControl::CHECKSUM_ERROR | SiiControl::NOT_LOADED), 0, "{name}: {ctl:#06x}");
    }
}

#[test]
fn a_wrong_checksum_keeps_the_esc_unconfigured_until_a_good_reload() {
    let mut bus = Bus::addressed("[[device]]\nbuiltin = 'EK1100'\n[[device]]\nbuiltin = 'EL2004'\n");
    let pdi_control = u16_at(&mut bus, 0x0140);
    assert_ne!(pdi_control, 0, "the EL2004's SII names a PDI");
    // A station alias written into word 4 without the checksum (word 7) made right.
    sii_write(&mut bus, 4, 0x0BAD);
    power_cycle(&mut bus);
    let ctl = u16_at(&mut bus, 0x0502);
    assert_eq!(ctl & 0x1800, 0x1800, "checksum error and configuration not loaded: {ctl:#06x}");
    assert_eq!(u16_at(&mut bus, 0x0110) & 1, 0, "DL status: PDI not operational");
    assert_eq!(u16_at(&mut bus, 0x0140), 0, "PDI control at its reset value");
    assert_eq!(u16_at(&mut bus, 0x0012), 0, "no alias");
    // Nothing acts on AL control, and process memory does not answer.
    assert_eq!(bus.fp(Command::FPWR, S, 0x0120, &[0x02, 0]).1, 1);
    bus.t += 50_000_000;
    assert_eq!(u16_at(&mut bus, 0x0130), 0x0001, "AL status stays INIT");
    assert_eq!(bus.fp(Command::FPWR, S, 0x1000, &[0xAA]).1, 0, "process memory write");
    assert_eq!(bus.fp(Command::FPRD, S, 0x1000, &[0]).1, 0, "process memory read");
    // A reload of the same bad area: the error stays, nothing else moves.
    let ctl = reload(&mut bus);
    assert_eq!(ctl & 0x1800, 0x1800, "{ctl:#06x}");
    assert_eq!(u16_at(&mut bus, 0x0110) & 1, 0);
    // The checksum made right and the EEPROM reloaded: the configuration is taken, the
    // alias not (only the first load after power-on takes it).
    let crc = crc_of(&mut bus);
    sii_write(&mut bus, 7, crc);
    let ctl = reload(&mut bus);
    assert_eq!(ctl & 0x1800, 0, "{ctl:#06x}");
    assert_eq!(u16_at(&mut bus, 0x0110) & 1, 1, "PDI operational");
    assert_eq!(u16_at(&mut bus, 0x0140), pdi_control);
    assert_eq!(u16_at(&mut bus, 0x0012), 0, "a reload does not take the alias");
    assert_eq!(bus.fp(Command::FPWR, S, 0x0120, &[0x02, 0]).1, 1);
    bus.t += 50_000_000;
    assert_eq!(u16_at(&mut bus, 0x0130), 0x0002, "PREOP once the PDI runs");
    // After a power cycle the alias is there.
    power_cycle(&mut bus);
    assert_eq!(u16_at(&mut bus, 0x0012), 0x0BAD);
    assert_eq!(u16_at(&mut bus, 0x0502) & 0x1800, 0);
}

#[test]
fn a_bad_reload_keeps_what_the_first_load_set() {
    // An EK1100 at position 1: its ET1100's SYNC unit is on (the EL2004's ET1200 has none).
    let mut bus = Bus::addressed("[[device]]\nbuiltin = 'EK1100'\n[[device]]\nbuiltin = 'EK1100'\n");
    let pulse = u16_at(&mut bus, 0x0982);
    // A new SYNC pulse length with its checksum: a reload takes it.
    sii_write(&mut bus, 2, pulse + 7);
    let crc = crc_of(&mut bus);
    sii_write(&mut bus, 7, crc);
    assert_eq!(reload(&mut bus) & 0x1800, 0);
    assert_eq!(u16_at(&mut bus, 0x0982), pulse + 7);
    // Another without: bit 11 only; the registers and DL status bit 0 as they were.
    sii_write(&mut bus, 2, pulse + 9);
    let ctl = reload(&mut bus);
    assert_eq!(ctl & 0x1800, SiiControl::CHECKSUM_ERROR, "{ctl:#06x}");
    assert_eq!(u16_at(&mut bus, 0x0982), pulse + 7);
    assert_eq!(u16_at(&mut bus, 0x0110) & 1, 1);
    // Word 7 = 0x88A4 switches the test off (for debugging, Section I).
    sii_write(&mut bus, 7, 0x88A4);
    assert_eq!(reload(&mut bus) & 0x1800, 0);
    assert_eq!(u16_at(&mut bus, 0x0982), pulse + 9);
}
