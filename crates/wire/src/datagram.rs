//! EtherCAT datagrams (esc-spec §1.3, §1.4): a 10-byte header, data, and a 16-bit working counter.
use core::fmt;

use crate::bytes::{need, put, u16_at};
use crate::{Error, Result};

pub const HEADER_LEN: usize = 10;
pub const WKC_LEN: usize = 2;
/// Largest data field of one datagram in a standard frame (esc-spec §1.3).
pub const MAX_DATA_LEN: usize = 1486;

const LEN_MASK: u16 = 0x07FF;
const RESERVED_SHIFT: u16 = 11;
const CIRCULATING: u16 = 1 << 14;
const MORE: u16 = 1 << 15;

/// A command code. Kept as the raw byte so that unknown codes survive a parse/emit round trip.
#[derive(Clone, Copy, PartialEq, Eq, Hash, PartialOrd, Ord)]
pub struct Command(pub u8);

impl Command {
    pub const NOP: Command = Command(0);
    pub const APRD: Command = Command(1);
    pub const APWR: Command = Command(2);
    pub const APRW: Command = Command(3);
    pub const FPRD: Command = Command(4);
    pub const FPWR: Command = Command(5);
    pub const FPRW: Command = Command(6);
    pub const BRD: Command = Command(7);
    pub const BWR: Command = Command(8);
    pub const BRW: Command = Command(9);
    pub const LRD: Command = Command(10);
    pub const LWR: Command = Command(11);
    pub const LRW: Command = Command(12);
    pub const ARMW: Command = Command(13);
    pub const FRMW: Command = Command(14);

    /// The mnemonic, or `None` for a code outside 0–14.
    pub fn name(self) -> Option<&'static str> {
        const NAMES: [&str; 15] = [
            "NOP", "APRD", "APWR", "APRW", "FPRD", "FPWR", "FPRW", "BRD", "BWR", "BRW", "LRD", "LWR", "LRW", "ARMW",
            "FRMW",
        ];
        NAMES.get(self.0 as usize).copied()
    }

    pub fn from_name(name: &str) -> Option<Command> {
        (0..=14u8).map(Command).find(|c| c.name().is_some_and(|n| n.eq_ignore_ascii_case(name)))
    }

    /// Logical commands carry one 32-bit address instead of ADP + ADO.
    pub fn is_logical(self) -> bool {
        matches!(self, Command::LRD | Command::LWR | Command::LRW)
    }

    /// Position-addressed and broadcast commands: every ESC increments ADP as the frame passes.
    pub fn increments_adp(self) -> bool {
        matches!(
            self,
            Command::APRD | Command::APWR | Command::APRW | Command::BRD | Command::BWR | Command::BRW | Command::ARMW
        )
    }

    pub fn reads(self) -> bool {
        matches!(
            self,
            Command::APRD
                | Command::APRW
                | Command::FPRD
                | Command::FPRW
                | Command::BRD
                | Command::BRW
                | Command::LRD
                | Command::LRW
                | Command::ARMW
                | Command::FRMW
        )
    }

    pub fn writes(self) -> bool {
        matches!(
            self,
            Command::APWR
                | Command::APRW
                | Command::FPWR
                | Command::FPRW
                | Command::BWR
                | Command::BRW
                | Command::LWR
                | Command::LRW
                | Command::ARMW
                | Command::FRMW
        )
    }
}

impl fmt::Debug for Command {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        fmt::Display::fmt(self, f)
    }
}

impl fmt::Display for Command {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        match self.name() {
            Some(n) => f.write_str(n),
            None => write!(f, "CMD{:#04x}", self.0),
        }
    }
}

/// The 32-bit address field, interpreted by the command.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash)]
pub enum Address {
    /// Auto-increment position or configured station address (ADP) and register offset (ADO).
    Device { adp: u16, ado: u16 },
    /// LRD/LWR/LRW logical address.
    Logical(u32),
}

impl Address {
    pub fn raw(self) -> u32 {
        match self {
            Address::Device { adp, ado } => adp as u32 | (ado as u32) << 16,
            Address::Logical(a) => a,
        }
    }

    pub fn from_raw(command: Command, raw: u32) -> Self {
        if command.is_logical() {
            Address::Logical(raw)
        } else {
            Address::Device { adp: raw as u16, ado: (raw >> 16) as u16 }
        }
    }

    /// Auto-increment address of the slave at `position` (0-based): the master sends −position.
    pub fn position(position: u16, ado: u16) -> Self {
        Address::Device { adp: 0u16.wrapping_sub(position), ado }
    }
}

/// The plain representation of a datagram header.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash)]
pub struct DatagramHeader {
    pub command: Command,
    pub index: u8,
    pub address: Address,
    /// Data length in bytes (11 bits).
    pub len: u16,
    /// Bits 11–13 of the length word; zero on a valid frame, kept so nothing is lost.
    pub reserved: u8,
    pub circulating: bool,
    pub more: bool,
    pub irq: u16,
}

impl DatagramHeader {
    pub fn new(command: Command, index: u8, address: Address, len: u16) -> Self {
        DatagramHeader { command, index, address, len, reserved: 0, circulating: false, more: false, irq: 0 }
    }

    pub fn parse(buf: &[u8]) -> Result<Self> {
        need(buf, 0, HEADER_LEN, "datagram header")?;
        let command = Command(buf[0]);
        let raw = u32::from_le_bytes([buf[2], buf[3], buf[4], buf[5]]);
        let lw = u16_at(buf, 6, "datagram length")?;
        Ok(DatagramHeader {
            command,
            index: buf[1],
            address: Address::from_raw(command, raw),
            len: lw & LEN_MASK,
            reserved: ((lw >> RESERVED_SHIFT) & 0x7) as u8,
            circulating: lw & CIRCULATING != 0,
            more: lw & MORE != 0,
            irq: u16_at(buf, 8, "datagram IRQ")?,
        })
    }

    pub fn length_word(&self) -> u16 {
        (self.len & LEN_MASK)
            | ((self.reserved as u16 & 0x7) << RESERVED_SHIFT)
            | if self.circulating { CIRCULATING } else { 0 }
            | if self.more { MORE } else { 0 }
    }

    pub fn emit(&self, out: &mut [u8]) -> Result<()> {
        let mut h = [0u8; HEADER_LEN];
        h[0] = self.command.0;
        h[1] = self.index;
        h[2..6].copy_from_slice(&self.address.raw().to_le_bytes());
        h[6..8].copy_from_slice(&self.length_word().to_le_bytes());
        h[8..10].copy_from_slice(&self.irq.to_le_bytes());
        put(out, 0, &h, "datagram header")
    }

    /// Bytes this datagram occupies on the wire: header, data and working counter.
    pub fn wire_len(&self) -> usize {
        HEADER_LEN + self.len as usize + WKC_LEN
    }
}

/// A zero-copy view of one datagram (header, data, WKC), validated at construction.
#[derive(Clone, Copy, PartialEq, Eq)]
pub struct Datagram<'a> {
    bytes: &'a [u8],
    header: DatagramHeader,
}

impl<'a> Datagram<'a> {
    /// Reads the datagram at the start of `buf`; `buf` may continue with more datagrams.
    pub fn parse(buf: &'a [u8]) -> Result<Self> {
        let header = DatagramHeader::parse(buf)?;
        let total = header.wire_len();
        if total > buf.len() {
            return Err(Error::BadLength {
                what: "datagram data length",
                offset: 6,
                claimed: header.len as usize,
                limit: buf.len().saturating_sub(HEADER_LEN + WKC_LEN),
            });
        }
        Ok(Datagram { bytes: &buf[..total], header })
    }

    pub fn header(&self) -> &DatagramHeader {
        &self.header
    }

    pub fn data(&self) -> &'a [u8] {
        &self.bytes[HEADER_LEN..self.bytes.len() - WKC_LEN]
    }

    pub fn wkc(&self) -> u16 {
        let n = self.bytes.len();
        u16::from_le_bytes([self.bytes[n - 2], self.bytes[n - 1]])
    }

    /// The whole datagram as it is on the wire.
    pub fn as_bytes(&self) -> &'a [u8] {
        self.bytes
    }
}

impl fmt::Debug for Datagram<'_> {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        f.debug_struct("Datagram")
            .field("header", &self.header)
            .field("len", &self.data().len())
            .field("wkc", &self.wkc())
            .finish()
    }
}

/// Writes a whole datagram (header, data, WKC) at the start of `out`; returns its length.
pub fn emit_datagram(out: &mut [u8], header: &DatagramHeader, data: &[u8], wkc: u16) -> Result<usize> {
    if data.len() != header.len as usize {
        return Err(Error::BadLength {
            what: "datagram data",
            offset: 0,
            claimed: data.len(),
            limit: header.len as usize,
        });
    }
    let total = header.wire_len();
    if out.len() < total {
        return Err(Error::BufferTooSmall { what: "datagram", needed: total, available: out.len() });
    }
    header.emit(out)?;
    out[HEADER_LEN..HEADER_LEN + data.len()].copy_from_slice(data);
    out[total - 2..total].copy_from_slice(&wkc.to_le_bytes());
    Ok(total)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn header_bits() {
        let mut h = DatagramHeader::new(Command::FRMW, 7, Address::Device { adp: 0x1001, ado: 0x0910 }, 8);
        h.circulating = true;
        h.more = true;
        h.irq = 0x0123;
        let mut buf = [0u8; 20];
        assert_eq!(emit_datagram(&mut buf, &h, &[1, 2, 3, 4, 5, 6, 7, 8], 3).unwrap(), 20);
        assert_eq!(&buf[..10], &[14, 7, 0x01, 0x10, 0x10, 0x09, 0x08, 0xC0, 0x23, 0x01]);
        let d = Datagram::parse(&buf).unwrap();
        assert_eq!(*d.header(), h);
        assert_eq!(d.data(), &[1, 2, 3, 4, 5, 6, 7, 8]);
        assert_eq!(d.wkc(), 3);
    }

    #[test]
    fn logical_and_position_addresses() {
        assert_eq!(Address::from_raw(Command::LRW, 0x0001_0000), Address::Logical(0x10000));
        assert_eq!(Address::position(2, 0x10), Address::Device { adp: 0xFFFE, ado: 0x10 });
        assert_eq!(Command::from_name("armw"), Some(Command::ARMW));
        assert_eq!(Command(0xFF).name(), None);
        assert!(Command::ARMW.increments_adp() && !Command::FRMW.increments_adp());
    }

    #[test]
    fn lying_length_is_an_error() {
        let mut buf = [0u8; 14];
        buf[6] = 0xFF; // len 0x7FF
        buf[7] = 0x07;
        assert!(matches!(Datagram::parse(&buf), Err(Error::BadLength { what: "datagram data length", .. })));
        assert!(matches!(Datagram::parse(&buf[..5]), Err(Error::Truncated { .. })));
    }
}
