#![no_main]
//! Any bytes: parse as a frame; whatever parses must re-emit to the same bytes. An odd first
//! byte puts a broadcast Ethernet header with EtherType 0x88A4 in front, so that the fuzzer
//! spends its time inside the EtherCAT PDU rather than guessing the EtherType.
use ferrocat_wire::Frame;
use libfuzzer_sys::fuzz_target;

fuzz_target!(|data: &[u8]| {
    let Some((&sel, rest)) = data.split_first() else { return };
    let mut buf = Vec::with_capacity(data.len() + 14);
    if sel & 1 == 1 {
        buf.extend_from_slice(&[0xFF; 6]);
        buf.extend_from_slice(&[2, 0, 0, 0, 0, 1]);
        buf.extend_from_slice(&[0x88, 0xA4]);
    }
    buf.extend_from_slice(rest);
    if let Ok(Some(f)) = Frame::parse(&buf) {
        assert_eq!(f.pdu.datagrams().count(), f.pdu.datagram_count());
        let mut out = vec![0u8; buf.len()];
        let n = f.emit(&mut out).expect("a parsed frame re-emits");
        assert_eq!(&out[..n], &buf[..]);
    }
});
