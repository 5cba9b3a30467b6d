//! The CoE SDO server of a simulated drive described by the Nanotec ESI: every kind of SDO
//! transfer, aborts, SDO information, and a PDO remapping that changes the process image.
mod common;

use common::Bus;
use ferrocat_segment::SegmentConfig;
use ferrocat_wire::coe::{self, AbortCode, CoeHeader, CoeMessage, CoeService, InfoHeader, InfoOpcode, Sdo, SdoInfo};
use ferrocat_wire::mailbox::{Mailbox, MailboxHeader, MailboxType};
use ferrocat_wire::register::{AlStatusCode, SyncManager};
use ferrocat_wire::{Address, Command};

const OUT: (u16, u16) = (0x1000, 128);
const INP: (u16, u16) = (0x1080, 128);
const S: u16 = 0x1001;

struct Client {
    bus: Bus,
    counter: u8,
}

impl Client {
    fn new() -> Self {
        Client::with(0, "")
    }

    /// The drive, with more keys for its `[[device]]` table, on a segment of seed `seed`.
    fn with(seed: u64, device_keys: &str) -> Self {
        let esi = ferrocat_testdata::shared("esi/Nanotec_C5-E-2-21.xml");
        let toml = format!(
            "seed = {seed}\n[[device]]\nesi = {:?}\nproduct = 0x4F\n{device_keys}\n",
            esi.display().to_string()
        );
        let cfg: SegmentConfig = toml::from_str(&toml).unwrap();
        let mut bus = Bus::new(cfg.build().unwrap());
        bus.address_all();
        for (n, (start, len), ctl) in [(0u16, OUT, 0x26u8), (1, INP, 0x22)] {
            let sm = SyncManager { start, length: len, control: ctl, status: 0, activate: 1, pdi_control: 0 };
            assert_eq!(bus.fp(Command::FPWR, S, 0x0800 + 8 * n, &sm.to_bytes()).1, 1);
        }
        assert_eq!(bus.request_state(S, 2).0, 2, "PREOP");
        Client { bus, counter: 0 }
    }

    fn coe(&mut self, service: CoeService, body: &[u8]) -> Vec<u8> {
        self.counter = ferrocat_wire::mailbox::next_counter(self.counter);
        let mut msg = MailboxHeader::new(MailboxType::COE, (2 + body.len()) as u16, self.counter).to_bytes().to_vec();
        msg.extend_from_slice(&CoeHeader::new(service).word().to_le_bytes());
        msg.extend_from_slice(body);
        self.bus.mailbox(S, OUT, INP, &msg)
    }

    fn sdo(&mut self, s: Sdo<'_>) -> Vec<u8> {
        let mut b = [0u8; 128];
        let n = s.emit(&mut b).unwrap();
        self.coe(CoeService::SDO_REQUEST, &b[..n])
    }

    /// A whole upload: expedited, normal or segmented, as the server chooses.
    fn upload(&mut self, index: u16, subindex: u8, complete_access: bool) -> Result<Vec<u8>, AbortCode> {
        let reply = self.sdo(Sdo::UploadRequest { index, subindex, complete_access, reserved: [0; 4] });
        let m = Mailbox::parse(&reply).unwrap();
        let (_, msg) = coe::parse(m.payload).unwrap();
        match msg {
            CoeMessage::Sdo(Sdo::UploadExpeditedResponse { size, data, .. }) => {
                Ok(data[..size.unwrap_or(4) as usize].to_vec())
            }
            CoeMessage::Sdo(Sdo::UploadNormalResponse { complete_size, data, .. }) => {
                let mut all = data.to_vec();
                let mut toggle = false;
                while all.len() < complete_size as usize {
                    let r = self.sdo(Sdo::UploadSegmentRequest { toggle, reserved: [0; 7] });
                    let m = Mailbox::parse(&r).unwrap();
                    let (_, CoeMessage::Sdo(seg)) = coe::parse(m.payload).unwrap() else { panic!("not an SDO") };
                    let Sdo::UploadSegmentResponse { toggle: t, last, .. } = seg else { panic!("{seg:?}") };
                    assert_eq!(t, toggle);
                    all.extend_from_slice(seg.segment_data().unwrap());
                    toggle = !toggle;
                    if last {
                        break;
                    }
                }
                assert_eq!(all.len(), complete_size as usize);
                Ok(all)
            }
            CoeMessage::Sdo(Sdo::Abort { code, .. }) => Err(code),
            other => panic!("{other:?}"),
        }
    }

    fn result(&self, reply: &[u8]) -> Result<(), AbortCode> {
        let m = Mailbox::parse(reply).unwrap();
        match coe::parse(m.payload).unwrap().1 {
            CoeMessage::Sdo(Sdo::DownloadResponse { .. }) | CoeMessage::Sdo(Sdo::DownloadSegmentResponse { .. }) => {
                Ok(())
            }
            CoeMessage::Sdo(Sdo::Abort { code, .. }) => Err(code),
            other => panic!("{other:?}"),
        }
    }

    /// A download sent as `first` bytes in the initiate request and the rest in segments.
    fn download_segmented(
        &mut self,
        index: u16,
        sub: u8,
        ca: bool,
        data: &[u8],
        first: usize,
    ) -> Result<(), AbortCode> {
        let r = self.sdo(Sdo::DownloadNormalRequest {
            index,
            subindex: sub,
            complete_access: ca,
            complete_size: data.len() as u32,
            data: &data[..first],
        });
        self.result(&r)?;
        let mut toggle = false;
        for (k, chunk) in data[first..].chunks(100).enumerate() {
            let last = first + (k + 1) * 100 >= data.len();
            let mut seg = chunk.to_vec();
            let unused = if seg.len() < 7 { (7 - seg.len()) as u8 } else { 0 };
            seg.resize(seg.len().max(7), 0);
            let r = self.sdo(Sdo::DownloadSegmentRequest { toggle, last, unused, segment: &seg });
            self.result(&r)?;
            toggle = !toggle;
        }
        Ok(())
    }
}

#[test]
fn needs_shared_sdo_transfers_of_every_kind() {
    transfers_of_every_kind(Client::new());
}

#[test]
fn needs_shared_sdo_transfers_of_every_kind_with_a_slow_firmware() {
    transfers_of_every_kind(Client::with(0, "mailbox_response_us = 500\nmailbox_response_max_us = 1500"));
}

/// The virtual time from an SDO upload request's write into SM0 until SM1 first reads full,
/// polled every 50 µs.
fn response_time_ns(c: &mut Client) -> u64 {
    c.counter = ferrocat_wire::mailbox::next_counter(c.counter);
    let mut b = [0u8; 128];
    let n = Sdo::UploadRequest { index: 0x1018, subindex: 1, complete_access: false, reserved: [0; 4] }
        .emit(&mut b)
        .unwrap();
    let mut msg = MailboxHeader::new(MailboxType::COE, (2 + n) as u16, c.counter).to_bytes().to_vec();
    msg.extend_from_slice(&CoeHeader::new(CoeService::SDO_REQUEST).word().to_le_bytes());
    msg.extend_from_slice(&b[..n]);
    msg.resize(OUT.1 as usize, 0);
    let written = c.bus.t;
    assert_eq!(c.bus.fp(Command::FPWR, S, OUT.0, &msg).1, 1);
    loop {
        let polled = c.bus.t;
        let (status, _) = c.bus.fp(Command::FPRD, S, 0x080D, &[0]);
        if status[0] & 0x08 != 0 {
            assert_eq!(c.bus.fp(Command::FPRD, S, INP.0, &[0; INP.1 as usize]).1, 1, "the reply is read");
            return polled - written;
        }
        assert!(polled - written < 20_000_000, "no reply within 20 ms");
        c.bus.t += 50_000;
    }
}

#[test]
fn needs_shared_the_firmware_answers_after_its_response_time() {
    // Default: at once, the first poll finds the reply.
    let mut c = Client::new();
    let fast: Vec<u64> = (0..5).map(|_| response_time_ns(&mut c)).collect();
    assert!(fast.iter().all(|&t| t < 50_000), "{fast:?}");
    // A fixed time: the reply is there from 2 ms after the request (a poll takes ≈ 10 µs of
    // round trip and 50 µs of pause).
    let mut c = Client::with(0, "mailbox_response_us = 2000");
    for _ in 0..5 {
        let t = response_time_ns(&mut c);
        assert!((2_000_000..2_000_000 + 70_000).contains(&t), "{t} ns");
    }
    // A range: each request its own time within it, the same for the same seed, other ones
    // for another seed.
    let times = |seed: u64| {
        let mut c = Client::with(seed, "mailbox_response_us = 1000\nmailbox_response_max_us = 3000");
        (0..20).map(|_| response_time_ns(&mut c)).collect::<Vec<u64>>()
    };
    let a = times(1);
    assert!(a.iter().all(|&t| (1_000_000..3_000_000 + 70_000).contains(&t)), "{a:?}");
    let (lo, hi) = (a.iter().min().unwrap(), a.iter().max().unwrap());
    assert!(hi - lo > 1_000_000, "20 draws over 2 ms spread by only {} ns", hi - lo);
    assert_eq!(a, times(1));
    assert_ne!(a, times(2));
}

#[test]
fn a_mailbox_response_range_must_be_ordered() {
    let toml = "[[device]]\nbuiltin = 'EK1100'\nmailbox_response_us = 300\nmailbox_response_max_us = 200\n";
    let err = toml::from_str::<SegmentConfig>(toml).unwrap().build().unwrap_err().to_string();
    assert!(err.contains("device 0: mailbox_response_max_us 200.0 out of range (300.0 to"), "{err}");
}

fn transfers_of_every_kind(mut c: Client) {
    // Expedited upload.
    assert_eq!(c.upload(0x1018, 1, false).unwrap(), 0x26Cu32.to_le_bytes());
    assert_eq!(c.upload(0x1018, 2, false).unwrap(), 0x4Fu32.to_le_bytes());
    // Expedited download and read-back.
    let r = c.sdo(Sdo::DownloadExpeditedRequest {
        index: 0x6060,
        subindex: 0,
        complete_access: false,
        size: Some(1),
        data: [8, 0, 0, 0],
    });
    c.result(&r).unwrap();
    assert_eq!(c.upload(0x6060, 0, false).unwrap(), [8]);
    // Complete access of the RxPDO assignment: SI0 as one byte padded to 16 bits, then UINTs
    // (the drive's default, from its ESI: 0x1600 only, out of four places).
    assert_eq!(c.upload(0x1C12, 0, true).unwrap(), [1, 0, 0x00, 0x16, 0, 0, 0, 0, 0, 0]);
    // A ≈1 KiB object through a 128-byte mailbox: normal response, then segments.
    let big = c.upload(0x2701, 0, true).unwrap();
    assert!(big.len() > 1000, "{} bytes", big.len());
    // Segmented download of the same object, read back.
    let mut pattern = big.clone();
    for (i, b) in pattern.iter_mut().enumerate().skip(2) {
        *b = (i * 7) as u8;
    }
    c.download_segmented(0x2701, 0, true, &pattern, 50).unwrap();
    assert_eq!(c.upload(0x2701, 0, true).unwrap(), pattern);
    // Aborts, by name.
    assert_eq!(c.upload(0x1234, 0, false), Err(AbortCode::NO_OBJECT));
    assert_eq!(c.upload(0x1018, 9, false), Err(AbortCode::NO_SUBINDEX));
    let r = c.sdo(Sdo::DownloadExpeditedRequest {
        index: 0x1018,
        subindex: 1,
        complete_access: false,
        size: Some(4),
        data: [0; 4],
    });
    assert_eq!(c.result(&r), Err(AbortCode::READ_ONLY));
    assert_eq!(AbortCode::READ_ONLY.name(), Some("Attempt to write a read-only object"));
}

#[test]
fn needs_shared_sdo_information() {
    let mut c = Client::new();
    let h = |op| InfoHeader { opcode: op, incomplete: false, reserved: 0, fragments_left: 0 };
    let mut b = [0u8; 64];
    let n = SdoInfo::OdListRequest { header: h(InfoOpcode::GET_OD_LIST_REQUEST), list_type: 1 }.emit(&mut b).unwrap();
    let first = c.coe(CoeService::SDO_INFORMATION, &b[..n]);
    let mut indices = Vec::new();
    let mut reply = first;
    loop {
        let m = Mailbox::parse(&reply).unwrap();
        let (_, CoeMessage::Information(SdoInfo::OdListResponse { header, data })) = coe::parse(m.payload).unwrap()
        else {
            panic!()
        };
        indices.extend(data.chunks(2).map(|x| u16::from_le_bytes([x[0], x[1]])));
        if header.fragments_left == 0 {
            break;
        }
        reply = c.bus.read_mailbox(S, INP).expect("next fragment");
    }
    assert_eq!(indices[0], 1, "list type first");
    assert!(indices.len() > 150, "{} objects", indices.len() - 1);
    assert!(indices.contains(&0x6040) && indices.contains(&0x1C12));
    let n = SdoInfo::ObjectDescriptionRequest { header: h(InfoOpcode::GET_OBJECT_DESCRIPTION_REQUEST), index: 0x1018 }
        .emit(&mut b)
        .unwrap();
    let r = c.coe(CoeService::SDO_INFORMATION, &b[..n]);
    let m = Mailbox::parse(&r).unwrap();
    let (_, CoeMessage::Information(SdoInfo::ObjectDescriptionResponse { max_subindex, object_code, name, .. })) =
        coe::parse(m.payload).unwrap()
    else {
        panic!()
    };
    assert_eq!((max_subindex, object_code), (4, 9));
    assert!(!name.is_empty());
    let n = SdoInfo::EntryDescriptionRequest {
        header: h(InfoOpcode::GET_ENTRY_DESCRIPTION_REQUEST),
        index: 0x6040,
        subindex: 0,
        value_info: 0,
    }
    .emit(&mut b)
    .unwrap();
    let r = c.coe(CoeService::SDO_INFORMATION, &b[..n]);
    let m = Mailbox::parse(&r).unwrap();
    let (_, CoeMessage::Information(SdoInfo::EntryDescriptionResponse { data_type, bit_length, .. })) =
        coe::parse(m.payload).unwrap()
    else {
        panic!()
    };
    assert_eq!((data_type, bit_length), (6, 16));
}

#[test]
fn needs_shared_pdo_remapping_changes_the_process_image() {
    let mut c = Client::new();
    let sm2 = |len| SyncManager { start: 0x1100, length: len, control: 0x24, status: 0, activate: 1, pdi_control: 0 };
    // Inputs: the default TxPDO assignment (0x1A00: statusword + mode display, 3 bytes).
    assert_eq!(c.upload(0x1C13, 0, true).unwrap()[..4], [1, 0, 0x00, 0x1A]);
    let sm3 = SyncManager { start: 0x1180, length: 3, control: 0x20, status: 0, activate: 1, pdi_control: 0 };
    c.bus.fp(Command::FPWR, S, 0x0818, &sm3.to_bytes());
    // Default assignment 0x1600: controlword + mode, 16 + 8 bits = 3 bytes.
    c.bus.fp(Command::FPWR, S, 0x0810, &sm2(8).to_bytes());
    assert_eq!(c.bus.request_state(S, 4), (0x12, AlStatusCode::INVALID_OUTPUT_CONFIG.0), "8-byte SM2 refused");
    assert_eq!(c.bus.request_state(S, 0x12).0, 2, "error acknowledged");
    // Remap: only 0x1601 (target position + profile velocity): 8 bytes.
    let r = c.sdo(Sdo::DownloadNormalRequest {
        index: 0x1C12,
        subindex: 0,
        complete_access: true,
        complete_size: 4,
        data: &[1, 0, 0x01, 0x16],
    });
    c.result(&r).unwrap();
    assert_eq!(c.upload(0x1C12, 0, true).unwrap()[..4], [1, 0, 0x01, 0x16]);
    let (st, code) = c.bus.request_state(S, 4);
    assert_eq!(st, 4, "SAFEOP with the remapped image; status code {code:#06x}");
    // PDO assignment is PREOP-only.
    let r = c.sdo(Sdo::DownloadNormalRequest {
        index: 0x1C12,
        subindex: 0,
        complete_access: true,
        complete_size: 4,
        data: &[1, 0, 0x00, 0x16],
    });
    assert_eq!(c.result(&r), Err(AbortCode::DEVICE_STATE));
    // The outputs land in the mapped objects: target position = first 4 bytes.
    let f = ferrocat_wire::register::Fmmu {
        logical_start: 0,
        length: 8,
        logical_start_bit: 0,
        logical_stop_bit: 7,
        physical_start: 0x1100,
        physical_start_bit: 0,
        fmmu_type: 2,
        active: true,
    };
    c.bus.fp(Command::FPWR, S, 0x0600, &f.to_bytes());
    assert_eq!(c.bus.request_state(S, 8).0, 8, "OP");
    let target = 123_456i32.to_le_bytes();
    let (_, wkc, _) =
        c.bus.tx(Command::LWR, Address::Logical(0), &[target[0], target[1], target[2], target[3], 0xE8, 3, 0, 0]);
    assert_eq!(wkc, 1);
    assert_eq!(c.upload(0x607A, 0, false).unwrap(), target);
    assert_eq!(c.upload(0x6081, 0, false).unwrap(), 1000u32.to_le_bytes());
}
