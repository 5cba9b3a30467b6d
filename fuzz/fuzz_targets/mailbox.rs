#![no_main]
//! Any bytes as an SM1 mailbox buffer: mailbox header, CoE, SDO, SDO information, emergency,
//! FoE; as a sequence of FoE requests (split at 0xFF bytes) to the simulated file server,
//! whose every reply must decode; and as a sequence of EoE messages (split at 0xFE bytes) to
//! the simulated EoE endpoint, whose every reply must decode, fit the mailbox and, in
//! fragments, put together into whole frames; and as a sequence of SoE requests (split at 0xFD
//! bytes) to the simulated drive, whose every reply must decode and fit the mailbox.
use ferrocat_esc::{EoeServer, FoeServer, SoeServer};
use ferrocat_wire::coe::{self, CoeMessage, Sdo, SdoInfo};
use ferrocat_wire::eoe::{frame_type, EoeHeader, Reassembler};
use ferrocat_wire::foe::Foe;
use ferrocat_wire::mailbox::{Mailbox, MailboxErrorCode};
use ferrocat_wire::register::AlState;
use ferrocat_wire::soe::{self, SoeHeader};
use libfuzzer_sys::fuzz_target;

fuzz_target!(|data: &[u8]| {
    let mut server = FoeServer::with_password(data.first().map_or(0, |&b| (b & 1) as u32));
    for request in data.split(|&b| b == 0xFF) {
        // Small mailboxes (8 bytes of data a packet) make many packets of short inputs.
        let reply = server.handle(request, 20, 20);
        if !reply.is_empty() {
            Foe::parse(&reply).expect("the server's reply decodes");
        }
    }
    let (mut eoe, mut frames) = (EoeServer::default(), Reassembler::default());
    for request in data.split(|&b| b == 0xFE) {
        for reply in eoe.handle(request, 70) {
            assert!(reply.len() <= 70, "an EoE reply longer than the mailbox");
            let h = EoeHeader::parse(&reply).expect("the endpoint's reply decodes");
            if h.frame_type == frame_type::FRAGMENT {
                frames.push(&h, &reply[4..]).expect("the endpoint's fragments fit together");
            }
        }
    }
    let mut drive = SoeServer::one_drive("fuzz");
    let state = [AlState::PreOp, AlState::SafeOp, AlState::Op][data.first().map_or(0, |&b| b as usize % 3)];
    for request in data.split(|&b| b == 0xFD) {
        for reply in drive.handle(request, 30, state) {
            assert!(reply.len() + 6 <= 30, "an SoE reply longer than the mailbox");
            SoeHeader::parse(&reply).expect("the drive's reply decodes");
        }
        let _ = soe::list_items(request);
    }
    let Ok(m) = Mailbox::parse(data) else { return };
    if let Ok(f) = Foe::parse(m.payload) {
        let mut out = vec![0u8; f.len()];
        let n = f.emit(&mut out).expect("re-emit");
        assert_eq!(Foe::parse(&out[..n]).expect("re-parse"), f);
    }
    let _ = MailboxErrorCode::parse(m.payload);
    if let Ok((h, msg)) = coe::parse(m.payload) {
        // Room for anything the input holds (a segment may be as long as the input).
        let mut out = vec![0u8; data.len() + 64];
        match msg {
            CoeMessage::Sdo(s) => {
                let n = s.emit(&mut out).expect("re-emit");
                assert_eq!(Sdo::parse(h.service, &out[..n]).expect("re-parse"), s);
            }
            CoeMessage::Information(i) => {
                let n = i.emit(&mut out).expect("re-emit");
                assert_eq!(SdoInfo::parse(&out[..n]).expect("re-parse"), i);
            }
            CoeMessage::Emergency(_) | CoeMessage::Other(_) => {}
        }
    }
});
