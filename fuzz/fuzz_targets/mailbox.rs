#![no_main]
//! Any bytes as an SM1 mailbox buffer: mailbox header, CoE, SDO, SDO information, emergency.
use ferrocat_wire::coe::{self, CoeMessage, Sdo, SdoInfo};
use ferrocat_wire::mailbox::{Mailbox, MailboxErrorCode};
use libfuzzer_sys::fuzz_target;

fuzz_target!(|data: &[u8]| {
    let Ok(m) = Mailbox::parse(data) else { return };
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
