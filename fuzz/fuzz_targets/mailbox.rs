#![no_main]
//! Any bytes as an SM1 mailbox buffer: mailbox header, CoE, SDO, SDO information, emergency,
//! FoE; and as a sequence of FoE requests (split at 0xFF bytes) to the simulated file server,
//! whose every reply must decode.
use ferrocat_esc::FoeServer;
use ferrocat_wire::coe::{self, CoeMessage, Sdo, SdoInfo};
use ferrocat_wire::foe::Foe;
use ferrocat_wire::mailbox::{Mailbox, MailboxErrorCode};
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
    let Ok(m) = Mailbox::parse(data) else { return };
    if let Ok(f) = Foe::parse(m.payload) {
        let mut out = vec![0u8; f.len()];
        let n = f.emit(&mut out).expect("re-emit");
        assert_eq!(Foe::parse(&out[..n]).expect("re-parse"), f);
    }
    let _ = MailboxErrorCode::parse(m.payload);
    if let Ok((h, msg)) = coe::parse(m.payload) {
        let mut out = [0u8; 2048];
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
