//! The BOOT state's checks (esc-spec §5.1; ETG.1000.6's AL status codes): a device whose SII
//! gives a bootstrap mailbox enters BOOT only with SM0 and SM1 set as that mailbox (else
//! 0x0015); a device without one refuses BOOT with 0x0013; BOOT leads only back to INIT.
mod common;

use common::Bus;
use ferrocat_wire::register::{AlStatusCode, SyncManager};
use ferrocat_wire::Command;

const S: u16 = 0x1001;

fn mailbox_sms(bus: &mut Bus, out: (u16, u16), inp: (u16, u16)) {
    for (n, (start, length), control) in [(0u16, out, 0x26u8), (1, inp, 0x22)] {
        let sm = SyncManager { start, length, control, status: 0, activate: 1, pdi_control: 0 };
        assert_eq!(bus.fp(Command::FPWR, S, 0x0800 + 8 * n, &sm.to_bytes()).1, 1);
    }
}

#[test]
fn needs_shared_akd_eeprom_enters_boot_only_with_its_bootstrap_mailbox() {
    let akd = ferrocat_testdata::shared("captures/eeprom/akd.hex");
    let mut bus = Bus::addressed(&format!("[[device]]\neeprom = '{}'\n", akd.display()));
    // The SII's bootstrap mailbox is 0x1800/0x1C00, 1 024 bytes each; half the length is not it.
    mailbox_sms(&mut bus, (0x1800, 512), (0x1C00, 512));
    assert_eq!(bus.request_state(S, 3), (0x11, AlStatusCode::INVALID_BOOT_MAILBOX_CONFIG.0));
    mailbox_sms(&mut bus, (0x1800, 1024), (0x1C00, 1024));
    assert_eq!(bus.request_state(S, 0x13), (0x03, 0), "BOOT, the error acknowledged");
    // From BOOT only INIT: PREOP is an invalid state change.
    assert_eq!(bus.request_state(S, 2), (0x13, AlStatusCode::INVALID_STATE_CHANGE.0));
    assert_eq!(bus.request_state(S, 0x11), (0x01, 0));
}

#[test]
fn a_device_without_a_bootstrap_mailbox_refuses_boot() {
    let mut bus = Bus::addressed("[[device]]\nbuiltin = 'SERVO'\n");
    mailbox_sms(&mut bus, (0x1000, 128), (0x1080, 128));
    assert_eq!(bus.request_state(S, 3), (0x11, AlStatusCode::BOOTSTRAP_NOT_SUPPORTED.0));
}
