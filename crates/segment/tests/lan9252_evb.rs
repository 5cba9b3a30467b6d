//! The built-in EVB-LAN9252 against the real board SOEM talked to
//! (../shared/captures/soem-single-lan9252.pcapng): the ESC's identity registers, and every
//! complete-access SDO upload the capture made answered byte for byte as the real firmware
//! answered it (its mailbox counter aside).
mod common;

use common::Bus;
use ferrocat_wire::{Address, Command, Frame};

const S: u16 = 0x1001;

/// Answered datagrams of the capture (WKC > 0): command, address, offset and data.
fn answered() -> Vec<(Command, u16, u16, Vec<u8>)> {
    let bytes = std::fs::read(ferrocat_testdata::shared("captures/soem-single-lan9252.pcapng")).unwrap();
    let mut v = Vec::new();
    ferrocat_capture::for_each_packet(&bytes, |p| {
        if let Ok(Some(f)) = Frame::parse(&p.data) {
            for d in f.pdu.datagrams() {
                if let (Address::Device { adp, ado }, true) = (d.header().address, d.wkc() > 0) {
                    v.push((d.header().command, adp, ado, d.data().to_vec()));
                }
            }
        }
        Ok(())
    })
    .unwrap();
    v
}

fn board() -> Bus {
    Bus::addressed("[[device]]\nbuiltin = 'LAN9252-EVB'\n")
}

#[test]
fn needs_shared_the_esc_reads_as_the_real_lan9252() {
    let real = answered();
    let mut bus = board();
    let mut compared = 0;
    // Type/revision, port descriptor/features, PDI control/ESC configuration, DL status.
    for (ado, len) in [(0x0000u16, 2usize), (0x0007, 2), (0x0140, 2), (0x0110, 2)] {
        let Some((_, _, _, want)) =
            real.iter().find(|(c, _, a, d)| c.reads() && *a == ado && d.len() == len && !c.is_logical())
        else {
            continue;
        };
        let (ours, wkc) = bus.fp(Command::FPRD, S, ado, &vec![0; len]);
        assert_eq!(wkc, 1);
        assert_eq!(&ours, want, "register {ado:#06x}");
        compared += 1;
    }
    assert_eq!(compared, 4, "the capture reads all four");
}

#[test]
fn needs_shared_sdo_uploads_are_answered_as_the_real_firmware_did() {
    let real = answered();
    let mut bus = board();
    // The mailbox SyncManagers as SOEM wrote them, then PREOP.
    let sms = real
        .iter()
        .find(|(c, _, a, d)| *c == Command::FPWR && *a == 0x0800 && d.len() == 16)
        .expect("SOEM configures SM0/SM1")
        .3
        .clone();
    assert_eq!(bus.fp(Command::FPWR, S, 0x0800, &sms).1, 1);
    assert_eq!(bus.request_state(S, 2).0, 2, "PREOP");
    let mut pairs = 0;
    let mut pending: Option<Vec<u8>> = None;
    for (c, _, ado, data) in &real {
        match (*c, *ado) {
            (Command::FPWR, 0x1000) => pending = Some(data.clone()),
            (Command::FPRD, 0x1080) => {
                let Some(req) = pending.take() else { continue };
                let ours = bus.mailbox(S, (0x1000, 128), (0x1080, 128), &req);
                let len = 6 + u16::from_le_bytes([data[0], data[1]]) as usize;
                let mask = |m: &[u8]| {
                    let mut m = m[..len].to_vec();
                    m[5] &= 0x0F; // the mailbox counter is each side's own
                    m
                };
                assert_eq!(mask(&ours), mask(data), "reply to {:02x?}", &req[..16]);
                pairs += 1;
            }
            _ => {}
        }
    }
    assert_eq!(pairs, 6, "0x1C00, 0x1C12, 0x1601, 0x1C13, 0x1A00, 0x1A02");
}
