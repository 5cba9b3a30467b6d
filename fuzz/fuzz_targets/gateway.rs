//! The mailbox gateway's side of untrusted datagrams: any bytes through its parser, and any
//! request to station 0 through the master's dictionary (facts of three slaves, live registers
//! from the input), never a panic; every reply fits an ETG.8200 datagram.
#![no_main]
use libfuzzer_sys::fuzz_target;

use ferrocat_service::gateway::{frame, parse, MasterCoe};
use ferrocat_service::master_od::{Facts, Live, SlaveFacts};

fuzz_target!(|data: &[u8]| {
    let Ok(r) = parse(data) else { return };
    let facts = Facts {
        slaves: (0..3u16)
            .map(|k| SlaveFacts { position: k, station: 0x1001 + k, name: format!("slave {k}"), ..Default::default() })
            .collect(),
        events: vec![(1, 2, String::from_utf8_lossy(&r.payload).into_owned())],
        ..Default::default()
    };
    let mut coe = MasterCoe::default();
    let from = "127.0.0.1:1".parse().unwrap();
    let mut live = |_| Live { registers: Some(r.payload.clone()) };
    for _ in 0..3 {
        for (t, payload) in coe.answer(&facts, &r.payload, from, &mut live) {
            let d = frame(r.header.address, t, r.header.counter, &payload);
            assert!(d.len() <= 2 + 2047, "a reply of {} bytes", d.len());
            assert!(parse(&d).is_ok());
        }
    }
});
