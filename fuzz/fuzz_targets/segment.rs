#![no_main]
//! Any sequence of frames a master could send, as `ferrocat sim` takes them off an interface,
//! through a segment of every kind of ESC the simulator models: the coupler, I/O terminals on an
//! ET1100, a LAN9252 with an SM-synchronous application, a 32-bit DC whose local time starts
//! just before its wrap, an ESC without DC, the CiA402 drive behind a firmware that checks
//! AL transitions (CoE mailbox, SDO server, PDO mapping), the EVB-LAN9252 (a CoE device with a
//! fixed mapping behind its firmware) and the AKD's IP core (PDI control fixed, EEPROM
//! emulated, 32-bit DC), closed into a ring back to the master's second port (so that our
//! master's bring-up takes its redundancy path). The simulator must not panic, and a
//! frame it answers must still parse as the same chain of datagrams.
//!
//! Input: a first byte choosing where the fuzzed frames start (mod 5: a segment just powered
//! on; after our master's scan; configured, in PREOP with mailboxes and the process-data
//! layout; with distributed clocks initialised and SYNC0 running; in OP), so that the fuzzer
//! reaches the mailboxes, the SDO server and the drive without having to find a bring-up
//! itself. Then records, each one datagram `[gap][cmd][adp lo][adp hi][ado lo][ado hi][len]
//! [flags]` and `len + 256·(flags >> 5)` data bytes (fewer if the input ends). Flag bit 0
//! chains the next record's datagram into the same frame; otherwise the frame goes out after
//! `gap²` µs (up to ≈ 65 ms, so that watchdogs, SYNC pulses, EEPROM busy and AL responses come
//! due). Flag bit 1 makes the record raw bytes after the Ethernet header instead (EtherCAT
//! header and all, which may lie about the length); flag bit 2 sends the frame from the
//! secondary port. Built this way the fuzzer spends its time
//! in the ESCs, not in guessing the frame format, which the `frame` target covers.
use ferrocat_master::{DcConfig, Master};
use ferrocat_segment::{HostModel, VirtualIo};
use ferrocat_segment::{MasterPort, Segment, SegmentConfig};
use ferrocat_wire::Frame;
use libfuzzer_sys::fuzz_target;

const SEGMENT: &str = r#"
seed = 7
[[device]]
builtin = "EK1100"
[[device]]
builtin = "EL2004"
[[device]]
builtin = "EL2004"
esc = "lan9252"
app = "sm"
[[device]]
builtin = "EL1004"
esc = "esc20"
app = "dc"
local_time_ns = 4294000000
[[device]]
builtin = "EL1004"
esc = "nodc"
[[device]]
builtin = "SERVO"
device_emulation = false
local_time_ns = "18446744073000000000"
[[device]]
builtin = "LAN9252-EVB"
# Its firmware answers at once here: the real board's 38 ms per mailbox reply made every
# bring-up a second long, and the fuzzer is after the ESC's logic, not its timing.
mailbox_response_us = 0
al_response_us = 1000
[[device]]
builtin = "EL2004"
esc = "ipcore"
[secondary]
"#;

fuzz_target!(|data: &[u8]| {
    let Some((&stage, mut rest)) = data.split_first() else { return };
    let (mut seg, mut t_ns) = prepared(stage % 5);
    let mut body: Vec<u8> = Vec::new();
    while let [gap, cmd, adp0, adp1, ado0, ado1, len, flags, tail @ ..] = rest {
        let len = (*len as usize + 256 * (*flags >> 5) as usize).min(tail.len());
        let (bytes, next) = tail.split_at(len);
        rest = next;
        let raw = flags & 2 != 0;
        if raw {
            body.clear();
            body.extend_from_slice(bytes);
        } else {
            let more = flags & 1 != 0 && !rest.is_empty();
            body.extend_from_slice(&[*cmd, 0, *adp0, *adp1, *ado0, *ado1]);
            body.extend_from_slice(&((len as u16 & 0x07FF) | if more { 0x8000 } else { 0 }).to_le_bytes());
            body.extend_from_slice(&[0, 0]);
            body.extend_from_slice(bytes);
            body.extend_from_slice(&[0, 0]);
            if more {
                continue;
            }
        }
        t_ns += (*gap as u64).pow(2) * 1_000;
        let mut frame = Vec::with_capacity(body.len() + 16);
        frame.extend_from_slice(&[0xFF; 6]);
        frame.extend_from_slice(&[2, 0, 0, 0, 0, 1]);
        frame.extend_from_slice(&[0x88, 0xA4]);
        if !raw {
            // The EtherCAT header: the chain's length (11 bits), type 1 (DLPDU).
            frame.extend_from_slice(&((body.len() as u16 & 0x07FF) | 0x1000).to_le_bytes());
        }
        frame.extend_from_slice(&body);
        body.clear();
        let port = if flags & 4 != 0 { MasterPort::Secondary } else { MasterPort::Primary };
        send(&mut seg, port, &mut frame, &mut t_ns);
    }
});

/// The fuzz segment, brought by our master (in virtual time, deterministic) as far as `stage`
/// says; and the time then.
fn prepared(stage: u8) -> (Segment, u64) {
    let cfg: SegmentConfig = toml::from_str(SEGMENT).expect("the fuzz segment parses");
    let seg = cfg.build().expect("the fuzz segment builds");
    if stage == 0 {
        return (seg, 1_000_000);
    }
    let mut m = Master::new(VirtualIo::new(seg, HostModel::ideal(), 1));
    m.states().scan().expect("scan");
    if stage >= 2 {
        m.states().configure().expect("configure");
    }
    if stage >= 3 {
        // Every slave with a DC system time gets SYNC0 (the 32-bit one too), a short drift
        // compensation; the terminals with receive times only cannot.
        let positions = m.slaves().iter().filter(|s| s.dc().has_system_time).map(|s| s.position()).collect();
        let dc =
            DcConfig { max_frames: 300, sync0_cycle_ns: 250_000, sync0_slaves: Some(positions), ..DcConfig::default() };
        m.dc().init_dc(&dc).expect("DC initialisation");
    }
    if stage >= 4 {
        m.states().start().expect("OP");
    }
    let mut io = m.into_io();
    let t_ns = ferrocat_master::io::Io::now_ns(&mut io);
    (io.seg, t_ns)
}

/// What the live server does with a frame off the wire (sim/src/serve.rs), and what must
/// hold of the answer.
fn send(seg: &mut Segment, port: MasterPort, frame: &mut [u8], t_ns: &mut u64) {
    let before = match Frame::parse(frame) {
        Ok(Some(f)) if f.pdu.header.frame_type == ferrocat_wire::frame::TYPE_DLPDU => f.pdu.datagram_count(),
        _ => return,
    };
    if let Some((_, back_ns)) = seg.exchange_on(port, frame, *t_ns) {
        assert!(back_ns > *t_ns, "a frame came back at {back_ns} ns, sent at {t_ns} ns");
        let after = Frame::parse(frame).expect("an answered frame parses").expect("and is EtherCAT");
        assert_eq!(after.pdu.datagram_count(), before, "the ESCs changed the datagram chain");
        *t_ns = back_ns;
    }
}
