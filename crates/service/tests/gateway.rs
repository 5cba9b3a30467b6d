//! The mailbox gateway (ETG.8200) against a master cycling on the embedded virtual segment in
//! a thread of its own: the master's object dictionary (ETG.1510) at station address 0 by SDO
//! upload, complete access, segments and SDO information; requests passed to the slaves;
//! the error replies for what cannot be done; malformed datagrams counted; a sender over its
//! rate told so; and the cyclic exchange whole throughout.
#![cfg(feature = "server")]
mod common;

use std::net::UdpSocket;
use std::time::Duration;

use common::{Running, Setup};
use ferrocat_service::gateway::{frame, parse};
use ferrocat_service::{Client, GatewayOptions};
use ferrocat_wire::coe::{AbortCode, CoeHeader, CoeService, Sdo};
use ferrocat_wire::mailbox::{MailboxErrorCode, MailboxType};

/// EK1100, EL2004 and a SERVO in OP in virtual time, the gateway on an ephemeral loopback
/// port at `rate_per_s`; 40 events of the loop's own handed to the server at its tenth cycle.
fn running(name: &str, rate_per_s: u32) -> Running {
    let gateway = GatewayOptions {
        bind: "127.0.0.1:0".parse().unwrap(),
        rate_per_s,
        burst: (rate_per_s / 5).max(1),
        ..GatewayOptions::default()
    };
    let events = (0..40).map(|k| format!("terminal {k:02}")).collect();
    common::running(&format!("gateway-{name}"), Setup { events, gateway: Some(gateway), ..Setup::default() })
}

/// A tool's side: one request, every reply that comes within a short while.
struct Tool {
    s: UdpSocket,
    to: std::net::SocketAddr,
    counter: u8,
}

impl Tool {
    fn new(to: std::net::SocketAddr) -> Tool {
        let s = UdpSocket::bind("127.0.0.1:0").unwrap();
        Tool { s, to, counter: 0 }
    }

    fn ask(&mut self, station: u16, t: MailboxType, payload: &[u8]) -> Vec<(u16, MailboxType, u8, Vec<u8>)> {
        self.counter = self.counter % 7 + 1;
        self.s.send_to(&frame(station, t, self.counter, payload), self.to).unwrap();
        let mut out = Vec::new();
        let mut buf = [0u8; 4096];
        self.s.set_read_timeout(Some(Duration::from_secs(10))).unwrap();
        while let Ok(n) = self.s.recv(&mut buf) {
            let r = parse(&buf[..n]).unwrap();
            assert_eq!(r.header.counter, self.counter, "the reply carries the request's counter");
            // SDO information in fragments: more follow while the opcode's top bit is set.
            let more = r.header.mailbox_type == MailboxType::COE
                && r.payload.get(1).is_some_and(|s| s >> 4 == 8)
                && r.payload.get(2).is_some_and(|op| op & 0x80 != 0);
            out.push((r.header.address, r.header.mailbox_type, r.header.counter, r.payload));
            if !more {
                break;
            }
        }
        out
    }

    fn sdo(&mut self, station: u16, sdo: &Sdo<'_>) -> Vec<u8> {
        let mut m = vec![0u8; 64];
        CoeHeader::new(sdo.service()).emit(&mut m).unwrap();
        let n = sdo.emit(&mut m[2..]).unwrap();
        m.truncate(2 + n);
        let r = self.ask(station, MailboxType::COE, &m);
        assert_eq!(r.len(), 1, "one reply: {r:?}");
        assert_eq!(r[0].0, station);
        r[0].3.clone()
    }

    /// An upload's data, with the segments that follow a normal response; or its abort.
    fn upload(&mut self, station: u16, index: u16, subindex: u8, complete_access: bool) -> Result<Vec<u8>, AbortCode> {
        let r = self.sdo(station, &Sdo::UploadRequest { index, subindex, complete_access, reserved: [0; 4] });
        let sdo = Sdo::parse(CoeHeader::parse(&r).unwrap().service, &r[2..]).unwrap();
        let (mut data, total) = match sdo {
            Sdo::UploadExpeditedResponse { size, data, .. } => return Ok(data[..size.unwrap_or(4) as usize].to_vec()),
            Sdo::UploadNormalResponse { complete_size, data, .. } => (data.to_vec(), complete_size as usize),
            Sdo::Abort { code, .. } => return Err(code),
            other => panic!("{other:?}"),
        };
        let mut toggle = false;
        while data.len() < total {
            let r = self.sdo(station, &Sdo::UploadSegmentRequest { toggle, reserved: [0; 7] });
            let sdo = Sdo::parse(CoeService::SDO_RESPONSE, &r[2..]).unwrap();
            let Sdo::UploadSegmentResponse { toggle: t, last, .. } = sdo else { panic!("{sdo:?}") };
            assert_eq!(t, toggle);
            data.extend_from_slice(sdo.segment_data().unwrap());
            toggle = !toggle;
            assert_eq!(last, data.len() >= total);
        }
        assert_eq!(data.len(), total);
        Ok(data)
    }

    fn info(&mut self, request: &[u8]) -> Vec<Vec<u8>> {
        let mut m = vec![0x00, 0x80];
        m.extend_from_slice(request);
        self.ask(0, MailboxType::COE, &m).into_iter().map(|r| r.3).collect()
    }
}

fn mailbox_error(r: &[(u16, MailboxType, u8, Vec<u8>)]) -> MailboxErrorCode {
    assert_eq!(r.len(), 1, "{r:?}");
    assert_eq!(r[0].1, MailboxType::ERR, "{r:?}");
    MailboxErrorCode::parse(&r[0].3).unwrap()
}

#[test]
fn the_master_s_dictionary_answers_at_station_0_by_upload_segments_and_sdo_information() {
    let run = running("od", 100_000);
    let mut tool = Tool::new(run.gateway.unwrap());
    let name = tool.upload(0, 0x1008, 0, false).unwrap();
    assert_eq!(String::from_utf8_lossy(&name).trim_end_matches('\0'), "ferrocat EtherCAT master");
    // The identity by complete access: subindex 0 as 16 bits, then four u32.
    let id = tool.upload(0, 0x1018, 0, true).unwrap();
    assert_eq!(id.len(), 2 + 16);
    assert_eq!(id[0], 4);
    let mut client = Client::connect(&run.path).unwrap();
    let slaves = client.slaves().unwrap();
    for s in &slaves {
        let station = tool.upload(0, 0x8000 + s.position, 1, false).unwrap();
        assert_eq!(u16::from_le_bytes([station[0], station[1]]), s.station);
        let vendor = tool.upload(0, 0x8000 + s.position, 5, false).unwrap();
        assert_eq!(u32::from_le_bytes(vendor.try_into().unwrap()), s.vendor_id);
        let product = tool.upload(0, 0x9000 + s.position, 6, false).unwrap();
        assert_eq!(u32::from_le_bytes(product.try_into().unwrap()), s.product_code);
        // Diagnosis, live: every slave in OP, without an error code.
        let al = tool.upload(0, 0xA000 + s.position, 1, false).unwrap();
        assert_eq!(al, [0x08, 0x00], "slave {}", s.position);
        assert_eq!(tool.upload(0, 0xA000 + s.position, 3, false).unwrap(), [0, 0]);
    }
    let addresses = tool.upload(0, 0xF020, 0, true).unwrap();
    assert_eq!(addresses[0] as usize, slaves.len());
    let listed: Vec<u16> = addresses[2..].chunks(2).map(|c| u16::from_le_bytes([c[0], c[1]])).collect();
    assert_eq!(listed, slaves.iter().map(|s| s.station).collect::<Vec<_>>());
    // The 40 events and the master's own in the history: longer than the mailbox, in segments,
    // and the same as the control socket's dictionary gives (the gateway reuses the loop's
    // facts for 100 ms: wait that long past the events).
    std::thread::sleep(Duration::from_millis(200));
    let history = tool.upload(0, 0x10F3, 0, true).unwrap();
    assert!(history.len() > ferrocat_service::gateway::MASTER_MAILBOX, "{} bytes", history.len());
    let text = String::from_utf8_lossy(&history);
    assert!(text.contains("terminal 00") && text.contains("terminal 39"), "{text}");
    let od = client.master_od().unwrap();
    let by_socket = od.iter().find(|o| o["index"] == 0x10F3).unwrap();
    let sixth = by_socket["entries"].as_array().unwrap().iter().find(|e| e["subindex"] == 6).unwrap();
    let first = tool.upload(0, 0x10F3, 6, false).unwrap();
    assert_eq!(sixth["value"].as_str().unwrap(), ferrocat_service::protocol::hex(&first));
    // SDO information: every object listed is described, each of its entries too.
    let list = tool.info(&[0x01, 0x00, 0x00, 0x00, 0x01, 0x00]);
    assert_eq!(list.len(), 1);
    let indices: Vec<u16> = list[0][8..].chunks(2).map(|c| u16::from_le_bytes([c[0], c[1]])).collect();
    assert_eq!(indices, od.iter().map(|o| o["index"].as_u64().unwrap() as u16).collect::<Vec<_>>());
    for &index in &[0x1018u16, 0x8002, 0xA001, 0xF120] {
        let [i0, i1] = index.to_le_bytes();
        let d = tool.info(&[0x03, 0x00, 0x00, 0x00, i0, i1]);
        assert_eq!(d[0][2], 0x04, "object description of {index:#06x}: {:?}", d[0]);
        let max = d[0][8 + 4];
        for sub in 0..=max {
            let e = tool.info(&[0x05, 0x00, 0x00, 0x00, i0, i1, sub, 0x7F]);
            let found = od.iter().find(|o| o["index"] == index).unwrap()["entries"]
                .as_array()
                .unwrap()
                .iter()
                .any(|x| x["subindex"] == sub);
            // An entry the object has is described; a gap in its subindices is an SDO info error.
            assert_eq!(e[0][2] & 0x7F, if found { 0x06 } else { 0x07 }, "{index:#06x}:{sub}");
        }
    }
    // What cannot be done is aborted, with the code that says why.
    assert_eq!(tool.upload(0, 0x7777, 0, false), Err(AbortCode::NO_OBJECT));
    assert_eq!(tool.upload(0, 0x1018, 9, false), Err(AbortCode::NO_SUBINDEX));
    assert_eq!(tool.upload(0, 0x1008, 0, true), Err(AbortCode::COMPLETE_ACCESS_UNSUPPORTED));
    let w = Sdo::DownloadExpeditedRequest {
        index: 0x1018,
        subindex: 1,
        complete_access: false,
        size: Some(4),
        data: [1; 4],
    };
    let r = tool.sdo(0, &w);
    assert!(matches!(Sdo::parse(CoeService::SDO_REQUEST, &r[2..]), Ok(Sdo::Abort { code: AbortCode::READ_ONLY, .. })));
    assert_eq!(
        mailbox_error(&tool.ask(0, MailboxType::FOE, &[1, 0, 0, 0, 0, 0])),
        MailboxErrorCode::UNSUPPORTED_PROTOCOL
    );
    let (cycles, short) = run.stop();
    assert!(cycles > 0);
    assert_eq!(short, 0, "every cycle whole while the gateway served");
}

#[test]
fn requests_pass_to_the_slaves_and_what_cannot_be_done_gets_a_mailbox_error() {
    let run = running("slaves", 100_000);
    let mut tool = Tool::new(run.gateway.unwrap());
    let mut client = Client::connect(&run.path).unwrap();
    let slaves = client.slaves().unwrap();
    let (el2004, servo) = (slaves[1].station, slaves[2].station);
    // The servo's device name, by its own SDO server through the gateway, as the socket reads it.
    let name = tool.upload(servo, 0x1008, 0, false).unwrap();
    assert_eq!(name, client.sdo_read(2, 0x1008, 0).unwrap());
    assert_eq!(tool.upload(servo, 0x7777, 0, false), Err(AbortCode::NO_OBJECT), "the slave's own abort");
    // Its OD list by SDO information: the servo's reply, however many fragments.
    let (list, _) = tool.info_to(servo);
    assert!(list.contains(&0x6041), "{list:x?}");
    assert_eq!(list, client.od_list(2).unwrap());
    assert_eq!(
        mailbox_error(&tool.ask(el2004, MailboxType::COE, &[0, 0x20, 0x40, 0, 0x10, 0, 0, 0, 0, 0])),
        MailboxErrorCode::UNSUPPORTED_PROTOCOL
    );
    assert_eq!(
        mailbox_error(&tool.ask(0x7777, MailboxType::COE, &[0, 0x20, 0x40, 0, 0x10, 0, 0, 0, 0, 0])),
        MailboxErrorCode::SYNTAX
    );
    let (_, short) = run.stop();
    assert_eq!(short, 0);
}

impl Tool {
    /// A slave's OD list through the gateway, its fragments joined.
    fn info_to(&mut self, station: u16) -> (Vec<u16>, usize) {
        let r = self.ask(station, MailboxType::COE, &[0x00, 0x80, 0x01, 0x00, 0x00, 0x00, 0x01, 0x00]);
        let mut data = Vec::new();
        for (k, (_, t, _, m)) in r.iter().enumerate() {
            assert_eq!(*t, MailboxType::COE);
            let left = u16::from_le_bytes([m[4], m[5]]) as usize;
            assert_eq!(left, r.len() - 1 - k, "fragments left");
            data.extend_from_slice(&m[6..]);
        }
        (data[2..].chunks(2).map(|c| u16::from_le_bytes([c[0], c[1]])).collect(), r.len())
    }
}

#[test]
fn malformed_datagrams_are_counted_and_a_sender_over_its_rate_is_told_so() {
    let run = running("flood", 200);
    let s = UdpSocket::bind("127.0.0.1:0").unwrap();
    for k in 0..50u8 {
        s.send_to(&[0x10, 0x50, k], run.gateway.unwrap()).unwrap();
        s.send_to(&[0xFF; 40], run.gateway.unwrap()).unwrap();
    }
    // 400 requests at once: a burst of 40 and 200 a second are taken; the rest told "no
    // resources" (0x07) at once, without the master.
    let request = frame(0, MailboxType::COE, 1, &[0x00, 0x20, 0x40, 0x08, 0x10, 0x00, 0, 0, 0, 0]);
    for _ in 0..400 {
        s.send_to(&request, run.gateway.unwrap()).unwrap();
    }
    s.set_read_timeout(Some(Duration::from_secs(3))).unwrap();
    let (mut answered, mut limited) = (0, 0);
    let mut buf = [0u8; 2048];
    while answered + limited < 400 {
        let Ok(n) = s.recv(&mut buf) else { break };
        let r = parse(&buf[..n]).unwrap();
        if r.header.mailbox_type == MailboxType::ERR {
            assert_eq!(MailboxErrorCode::parse(&r.payload).unwrap(), MailboxErrorCode::NO_MORE_MEMORY);
            limited += 1;
        } else {
            answered += 1;
        }
    }
    assert!(limited > 0 && answered >= 40, "{answered} answered, {limited} over the rate");
    let mut client = Client::connect(&run.path).unwrap();
    let g = client.stats().unwrap().extra["gateway"].clone();
    assert_eq!(g["malformed"], 100, "{g}");
    // What the kernel's receive buffer took got a reply each, none in silence (a flood beyond
    // the buffer is dropped by the kernel, uncounted).
    let received = g["received"].as_u64().unwrap();
    assert_eq!(g["replies"].as_u64().unwrap(), received - 100, "{g}");
    assert!(g["rate_limited"].as_u64().unwrap() >= limited, "{g}");
    let (_, short) = run.stop();
    assert_eq!(short, 0, "the flood did not cost the loop a cycle");
}
