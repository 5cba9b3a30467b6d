//! A minimal master for the segment's tests: one datagram per frame, written from the spec.
#![allow(dead_code)]
use ferrocat_segment::{Segment, SegmentConfig};
use ferrocat_wire::ethernet::{EthernetRepr, BROADCAST};
use ferrocat_wire::sii::SiiHeader;
use ferrocat_wire::{Address, Command, DatagramHeader, Frame, FrameWriter};

pub struct Bus {
    pub seg: Segment,
    pub t: u64,
    /// The IRQ field of each datagram of the last frame, as it came back.
    pub irqs: Vec<u16>,
}

impl Bus {
    pub fn new(seg: Segment) -> Self {
        Bus { seg, t: 1_000_000, irqs: Vec::new() }
    }

    /// The segment a TOML description builds, its slaves at station addresses 0x1001, ….
    pub fn addressed(toml: &str) -> Self {
        let cfg: SegmentConfig = toml::from_str(toml).unwrap();
        let mut bus = Bus::new(cfg.build().unwrap());
        bus.address_all();
        bus
    }

    /// Several datagrams in one frame, sent at `self.t`; returns each one's (data, wkc,
    /// address as returned).
    pub fn tx_all(&mut self, datagrams: &[(Command, Address, &[u8])]) -> Vec<(Vec<u8>, u16, Address)> {
        let eth = EthernetRepr { dst: BROADCAST, src: [0x10; 6], vlan_tci: None, ethertype: 0 };
        let mut buf = [0u8; 1514];
        let mut w = FrameWriter::new(&mut buf, &eth).unwrap();
        for (i, (cmd, address, data)) in datagrams.iter().enumerate() {
            let header = DatagramHeader::new(*cmd, i as u8 + 1, *address, data.len() as u16);
            w.push_chained(&header, data, 0).unwrap();
        }
        let n = w.finish().unwrap();
        let back = self.seg.exchange(&mut buf[..n], self.t).expect("frame returns");
        assert!(back > self.t);
        self.t = back + 10_000;
        let f = Frame::parse(&buf[..n]).unwrap().unwrap();
        self.irqs = f.pdu.datagrams().map(|d| d.header().irq).collect();
        let answers = f.pdu.datagrams().map(|d| (d.data().to_vec(), d.wkc(), d.header().address)).collect();
        answers
    }

    /// One datagram in one frame, sent at `self.t`; returns (data, wkc, address as returned).
    pub fn tx(&mut self, cmd: Command, address: Address, data: &[u8]) -> (Vec<u8>, u16, Address) {
        self.tx_all(&[(cmd, address, data)]).remove(0)
    }

    pub fn fp(&mut self, cmd: Command, station: u16, ado: u16, data: &[u8]) -> (Vec<u8>, u16) {
        let (d, w, _) = self.tx(cmd, Address::Device { adp: station, ado }, data);
        (d, w)
    }

    pub fn fprd_u64(&mut self, station: u16, ado: u16) -> u64 {
        let (d, w) = self.fp(Command::FPRD, station, ado, &[0; 8]);
        assert_eq!(w, 1);
        u64::from_le_bytes(d.try_into().unwrap())
    }

    pub fn fprd_u32(&mut self, station: u16, ado: u16) -> u32 {
        let (d, w) = self.fp(Command::FPRD, station, ado, &[0; 4]);
        assert_eq!(w, 1);
        u32::from_le_bytes(d.try_into().unwrap())
    }

    /// Reads 4 bytes of the SII at `word` through the EEPROM interface, polling busy.
    pub fn sii_read(&mut self, station: u16, word: u32) -> [u8; 4] {
        let mut req = vec![0x00, 0x01];
        req.extend_from_slice(&word.to_le_bytes());
        assert_eq!(self.fp(Command::FPWR, station, 0x0502, &req).1, 1);
        loop {
            let (d, _) = self.fp(Command::FPRD, station, 0x0502, &[0; 2]);
            if u16::from_le_bytes([d[0], d[1]]) & 0x8000 == 0 {
                break;
            }
        }
        let (d, _) = self.fp(Command::FPRD, station, 0x0508, &[0; 4]);
        [d[0], d[1], d[2], d[3]]
    }

    /// Sends one mailbox message (written whole into SM0 at `out`) and polls SM1 at `inp`
    /// until the reply arrives.
    pub fn mailbox(&mut self, station: u16, out: (u16, u16), inp: (u16, u16), msg: &[u8]) -> Vec<u8> {
        let mut buf = msg.to_vec();
        buf.resize(out.1 as usize, 0);
        assert_eq!(self.fp(Command::FPWR, station, out.0, &buf).1, 1, "SM0 write");
        self.read_mailbox(station, inp).expect("a reply")
    }

    /// Reads SM1 once it is full (polls 0.1 ms apart for up to 100 ms: a firmware may take
    /// tens of ms, as the EVB-LAN9252's does).
    pub fn read_mailbox(&mut self, station: u16, inp: (u16, u16)) -> Option<Vec<u8>> {
        for _ in 0..1000 {
            let (d, w) = self.fp(Command::FPRD, station, inp.0, &vec![0; inp.1 as usize]);
            if w == 1 {
                return Some(d);
            }
            self.t += 100_000;
        }
        None
    }

    /// Requests an AL state and polls AL status until it is reached or refused (firmware
    /// takes its time, as real slaves do). Returns (AL status, AL status code).
    pub fn request_state(&mut self, station: u16, state: u8) -> (u8, u16) {
        let (before, _) = self.fp(Command::FPRD, station, 0x0130, &[0; 2]);
        assert_eq!(self.fp(Command::FPWR, station, 0x0120, &[state, 0]).1, 1, "AL control write");
        let mut last = (before[0], 0);
        // Up to 100 ms (the EVB-LAN9252's firmware takes 17).
        for _ in 0..500 {
            let (d, _) = self.fp(Command::FPRD, station, 0x0130, &[0; 6]);
            last = (d[0], u16::from_le_bytes([d[4], d[5]]));
            if d[0] != before[0] {
                break;
            }
            self.t += 200_000;
        }
        last
    }

    /// Station addresses 0x1001, 0x1002, … by position.
    pub fn address_all(&mut self) {
        for pos in 0..self.seg.nodes.len() as u16 {
            let (_, w, _) = self.tx(Command::APWR, Address::position(pos, 0x0010), &(0x1001 + pos).to_le_bytes());
            assert_eq!(w, 1);
        }
    }
}

/// One device (ET1100-like ESC) whose EEPROM is station `station`'s of `bus`, read as a
/// master would dump it, with its header changed by `patch` — written to a file, as a user's
/// dump would be, and loaded from it. Station address 0x1001.
pub fn patched_device(bus: &mut Bus, station: u16, patch: impl FnOnce(&mut SiiHeader)) -> Bus {
    let mut image: Vec<u8> = (0..512).flat_map(|w| bus.sii_read(station, 2 * w)[..4].to_vec()).collect();
    let mut header = SiiHeader::parse(&image).unwrap();
    patch(&mut header);
    image[..ferrocat_wire::sii::HEADER_LEN].copy_from_slice(&header.with_checksum().to_bytes());
    static NEXT: std::sync::atomic::AtomicU32 = std::sync::atomic::AtomicU32::new(0);
    let n = NEXT.fetch_add(1, std::sync::atomic::Ordering::Relaxed);
    let path = std::env::temp_dir().join(format!("ferrocat-patched-{}-{n}.bin", std::process::id()));
    std::fs::write(&path, &image).unwrap();
    let cfg: SegmentConfig =
        toml::from_str(&format!("[[device]]\neeprom = '{}'\nesc = 'et1100'\nsync_unit = true\n", path.display()))
            .unwrap();
    let seg = cfg.build();
    std::fs::remove_file(&path).unwrap();
    let mut bus = Bus::new(seg.unwrap());
    bus.address_all();
    bus
}
