//! The control socket against a master cycling on the embedded virtual segment in a thread of
//! its own: every request of the protocol answered through the socket, bad lines and
//! vanished clients answered or ignored, and the cyclic exchange whole throughout.
#![cfg(feature = "server")]
mod common;

use std::io::{BufRead, BufReader, Write};
use std::os::unix::net::UnixStream;

use common::{Running, Setup};
use ferrocat_service::protocol::ErrorKind;
use ferrocat_service::Client;

/// EK1100, EL2004 and a SERVO in OP on the virtual segment, the socket served once a cycle.
fn running(name: &str, register_writes: bool) -> Running {
    running_with(name, register_writes, 0)
}

/// As [`running`], the loop also handing the server `events` events of its own at its tenth
/// cycle (slave 1 back in OP, numbered in their `name`s), besides the master's.
fn running_with(name: &str, register_writes: bool, events: usize) -> Running {
    common::running(
        name,
        Setup { register_writes, events: (0..events).map(|k| format!("e{k}")).collect(), gateway: None },
    )
}

#[test]
fn every_request_is_answered_through_the_socket_and_the_cycle_stays_whole() {
    let r = running("all", false);
    let mut c = Client::connect(&r.path).unwrap();
    assert_eq!((c.hello().slaves, c.hello().target.as_str()), (3, "virtual"));
    let slaves = c.slaves().unwrap();
    assert_eq!(slaves.iter().map(|s| s.name.as_str()).collect::<Vec<_>>()[0], "EK1100");
    assert!(slaves.iter().all(|s| s.state == "OP" && s.health == "operational"), "{slaves:?}");
    assert_eq!((slaves[0].coe, slaves[2].coe), (false, true));

    let vendor = c.sdo_read(2, 0x1018, 1).unwrap();
    assert_eq!(vendor, slaves[2].vendor_id.to_le_bytes());
    c.sdo_download(2, 0x10F1, 2, false, &[7, 0]).unwrap();
    assert_eq!(c.sdo_read(2, 0x10F1, 2).unwrap(), [7, 0]);
    assert_eq!(c.entry_info(2, 0x10F1, 2).unwrap().bit_length, 16);
    assert!(c.od_list(2).unwrap().contains(&0x1018));
    assert_eq!(c.object_info(2, 0x1018).unwrap().max_subindex, 4);
    assert_eq!(c.register_read(1, 0x0130, 2).unwrap(), [8, 0]);
    // The SII as the master read it: its header's vendor ID (word 8) is the slave's.
    let sii = c.sii_read(2).unwrap();
    assert!(sii.len() >= 128, "{} bytes", sii.len());
    assert_eq!(u32::from_le_bytes(sii[16..20].try_into().unwrap()), slaves[2].vendor_id);
    assert_eq!(u32::from_le_bytes(sii[20..24].try_into().unwrap()), slaves[2].product_code);
    // FoE through the socket: files written and read back, one of several parts each way.
    let file: Vec<u8> = (0..3000u32).map(|k| (k * 7) as u8).collect();
    c.foe_write(2, "params.bin", 0, &file).unwrap();
    assert_eq!(c.foe_read(2, "params.bin", 0, 1 << 20).unwrap(), file);
    let big: Vec<u8> =
        (0..2 * ferrocat_service::protocol::MAX_DATA as u32 + 77).map(|k| (k * 13 + k / 256) as u8).collect();
    c.foe_write(2, "big.bin", 0, &big).unwrap();
    assert_eq!(c.foe_read(2, "big.bin", 0, 1 << 20).unwrap(), big);
    let short = c.foe_read(2, "big.bin", 0, 1000).unwrap_err().to_string();
    assert!(short.contains("longer than 1000"), "{short}");
    let pdos = c.pdos(1).unwrap();
    assert_eq!((pdos.outputs.len(), pdos.inputs.len()), (4, 0), "{pdos:?}");
    assert!(pdos.outputs.iter().all(|e| e.bits == 1 && e.name == "Output"), "{pdos:?}");
    assert_eq!(c.pdos(9).unwrap_err().remote().unwrap().kind, ErrorKind::NoSuchSlave);

    // Errors as the master words them, by kind.
    let e = c.sdo_read(2, 0x5FFF, 0).unwrap_err();
    let remote = e.remote().unwrap();
    assert_eq!((remote.kind, remote.abort_code.is_some()), (ErrorKind::Abort, true));
    assert!(remote.message.contains("slave 2") && remote.message.contains("0x5fff"), "{}", remote.message);
    assert_eq!(c.sdo_read(7, 0x1018, 1).unwrap_err().remote().unwrap().kind, ErrorKind::NoSuchSlave);
    assert_eq!(c.sdo_read(0, 0x1018, 1).unwrap_err().remote().unwrap().kind, ErrorKind::Slave);
    let refused = c.register_write(1, 0x0120, &[2, 0]).unwrap_err();
    assert_eq!(refused.remote().unwrap().kind, ErrorKind::Refused);
    assert_eq!(c.request_state(1, "BOOT").unwrap_err().remote().unwrap().kind, ErrorKind::BadRequest);

    let stats = c.stats().unwrap();
    assert!(stats.cycles > 0 && stats.requests_answered >= 8, "{stats:?}");
    assert_eq!(stats.extra["lock"], "none");
    drop(c);
    let (cycles, short) = r.stop();
    assert!(cycles > 0);
    assert_eq!(short, 0, "a cycle came back short while the socket was served");
}

#[test]
fn a_state_request_holds_and_the_slave_comes_back_when_asked() {
    let r = running("state", true);
    let mut c = Client::connect(&r.path).unwrap();
    assert_eq!(c.request_state(1, "safeop").unwrap(), "SAFEOP");
    assert_eq!(c.slaves().unwrap()[1].state, "SAFEOP");
    assert_eq!(c.register_read(1, 0x0130, 2).unwrap(), [4, 0]);
    assert_eq!(c.request_state(1, "OP").unwrap(), "OP");
    // Register writes where the master takes them: the ESC's user RAM, read back.
    c.register_write(1, 0x0F80, &[0x34, 0x12]).unwrap();
    assert_eq!(c.register_read(1, 0x0F80, 2).unwrap(), [0x34, 0x12]);
    drop(c);
    r.stop();
}

#[test]
fn bad_lines_and_clients_that_vanish_change_nothing() {
    let r = running("bad", false);
    let s = UnixStream::connect(&r.path).unwrap();
    let mut reader = BufReader::new(s.try_clone().unwrap());
    let mut line = String::new();
    reader.read_line(&mut line).unwrap();
    assert!(line.contains("\"hello\""), "{line}");
    for (bad, says) in [
        ("{\"id\":9,\"op\":\"reboot\"}\n", "unknown variant"),
        ("not json\n", "not a request"),
        ("{\"id\":10,\"op\":\"sdo_write\",\"position\":2,\"index\":1,\"subindex\":0,\"data\":\"xyz\"}\n", "hex"),
        ("{\"id\":11,\"op\":\"state\",\"position\":1,\"state\":\"RUN\"}\n", "give INIT"),
        ("{\"id\":12,\"op\":\"foe_read\",\"position\":2,\"file\":\"x\",\"offset\":5}\n", "from offset 0 first"),
    ] {
        (&s).write_all(bad.as_bytes()).unwrap();
        line.clear();
        reader.read_line(&mut line).unwrap();
        assert!(line.contains("bad_request") && line.contains(says), "{bad} → {line}");
    }
    // A line too long is answered and the connection closed.
    (&s).write_all(&vec![b'x'; ferrocat_service::protocol::MAX_LINE + 10]).unwrap();
    line.clear();
    reader.read_line(&mut line).unwrap();
    assert!(line.contains("longer than"), "{line}");
    line.clear();
    assert_eq!(reader.read_line(&mut line).unwrap(), 0);
    // Clients that send a request and go before its reply (each holds a place until the
    // reply, which nobody reads, is written).
    for _ in 0..10 {
        let s = UnixStream::connect(&r.path).unwrap();
        (&s).write_all(b"{\"id\":1,\"op\":\"od_list\",\"position\":2}\n").unwrap();
    }
    let mut c = Client::connect(&r.path).unwrap();
    assert_eq!(c.sdo_read(2, 0x1018, 1).unwrap().len(), 4);
    drop(c);
    let (_, short) = r.stop();
    assert_eq!(short, 0);
}

#[test]
fn events_come_in_order_from_a_number_on_and_the_oldest_go_past_1024() {
    let r = running_with("events", false, 1030);
    let mut c = Client::connect(&r.path).unwrap();
    let t0 = std::time::Instant::now();
    let first = loop {
        let e = c.events(0).unwrap();
        if e.next > 0 || t0.elapsed() > std::time::Duration::from_secs(20) {
            break e;
        }
        std::thread::sleep(std::time::Duration::from_millis(5));
    };
    // 1 030 given, the last 1 024 kept: 6 missed from 0; more than a line holds, so in parts.
    assert_eq!(first.missed, 6);
    assert!(first.events.len() < 1024 && first.next == first.events.last().unwrap().seq + 1);
    let mut all = first.clone();
    loop {
        let more = c.events(all.next).unwrap();
        assert_eq!(more.missed, 0);
        if more.events.is_empty() {
            assert_eq!(more.next, 1030);
            break;
        }
        all.next = more.next;
        all.events.extend(more.events);
    }
    assert_eq!(all.events.len(), 1024);
    assert_eq!(all.events[0].seq, 6);
    assert!(all.events[0].text.contains("slave 1 (e6) is back in OP"), "{:?}", all.events[0]);
    assert_eq!((all.events[0].kind.as_str(), all.events[0].position, all.events[0].at_s), ("recovered", Some(1), 0.5));
    assert!(all.events.windows(2).all(|w| w[1].seq == w[0].seq + 1));
    let tail = c.events(1028).unwrap();
    assert_eq!((tail.missed, tail.events.iter().map(|e| e.seq).collect::<Vec<_>>()), (0, vec![1028, 1029]));
    let none = c.events(1030).unwrap();
    assert!(none.events.is_empty() && none.next == 1030);
    drop(c);
    r.stop();
}
