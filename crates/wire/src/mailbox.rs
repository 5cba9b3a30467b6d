//! The 6-byte mailbox header (esc-spec §6.1) and mailbox error replies.
use core::fmt;

use crate::bytes::{need, put, u16_at};
use crate::{Error, Result};

pub const HEADER_LEN: usize = 6;

/// Mailbox protocol type (header byte 5, bits 3:0).
#[derive(Clone, Copy, PartialEq, Eq, Hash)]
pub struct MailboxType(pub u8);

impl MailboxType {
    pub const ERR: Self = Self(0);
    pub const AOE: Self = Self(1);
    pub const EOE: Self = Self(2);
    pub const COE: Self = Self(3);
    pub const FOE: Self = Self(4);
    pub const SOE: Self = Self(5);
    pub const VOE: Self = Self(0xF);

    pub fn name(self) -> &'static str {
        match self.0 {
            0 => "ERR",
            1 => "AoE",
            2 => "EoE",
            3 => "CoE",
            4 => "FoE",
            5 => "SoE",
            0xF => "VoE",
            _ => "reserved",
        }
    }

    /// The SII's mailbox-protocol bit for this type (`sii::mailbox_protocol`; 0 for a type the
    /// SII does not list).
    pub fn sii_protocol(self) -> u16 {
        use crate::sii::mailbox_protocol as p;
        match self {
            Self::AOE => p::AOE,
            Self::EOE => p::EOE,
            Self::COE => p::COE,
            Self::FOE => p::FOE,
            Self::SOE => p::SOE,
            Self::VOE => p::VOE,
            _ => 0,
        }
    }
}

impl fmt::Debug for MailboxType {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        write!(f, "{}({})", self.name(), self.0)
    }
}

#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash)]
pub struct MailboxHeader {
    /// Bytes of service data after this header.
    pub length: u16,
    pub address: u16,
    pub channel: u8,
    pub priority: u8,
    pub mailbox_type: MailboxType,
    /// Session counter 1–7 (0 = unused).
    pub counter: u8,
    pub reserved: bool,
}

impl MailboxHeader {
    pub fn new(mailbox_type: MailboxType, length: u16, counter: u8) -> Self {
        MailboxHeader { length, address: 0, channel: 0, priority: 0, mailbox_type, counter, reserved: false }
    }

    pub fn parse(buf: &[u8]) -> Result<Self> {
        need(buf, 0, HEADER_LEN, "mailbox header")?;
        Ok(MailboxHeader {
            length: u16_at(buf, 0, "mailbox length")?,
            address: u16_at(buf, 2, "mailbox address")?,
            channel: buf[4] & 0x3F,
            priority: buf[4] >> 6,
            mailbox_type: MailboxType(buf[5] & 0x0F),
            counter: (buf[5] >> 4) & 0x07,
            reserved: buf[5] & 0x80 != 0,
        })
    }

    pub fn to_bytes(&self) -> [u8; HEADER_LEN] {
        let l = self.length.to_le_bytes();
        let a = self.address.to_le_bytes();
        [
            l[0],
            l[1],
            a[0],
            a[1],
            (self.channel & 0x3F) | (self.priority << 6),
            (self.mailbox_type.0 & 0x0F) | ((self.counter & 7) << 4) | if self.reserved { 0x80 } else { 0 },
        ]
    }

    pub fn emit(&self, out: &mut [u8]) -> Result<()> {
        put(out, 0, &self.to_bytes(), "mailbox header")
    }
}

/// The next session counter after `c`: 1, 2, …, 7, 1, … (0 is "not used").
pub fn next_counter(c: u8) -> u8 {
    if c >= 7 {
        1
    } else {
        c + 1
    }
}

/// A mailbox (header and service data) read from an SM buffer that may be longer.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct Mailbox<'a> {
    pub header: MailboxHeader,
    pub payload: &'a [u8],
}

impl<'a> Mailbox<'a> {
    pub fn parse(buf: &'a [u8]) -> Result<Self> {
        let header = MailboxHeader::parse(buf)?;
        let len = header.length as usize;
        if HEADER_LEN + len > buf.len() {
            return Err(Error::BadLength {
                what: "mailbox length",
                offset: 0,
                claimed: len,
                limit: buf.len() - HEADER_LEN,
            });
        }
        Ok(Mailbox { header, payload: &buf[HEADER_LEN..HEADER_LEN + len] })
    }
}

/// Detail code of a mailbox error reply (mailbox type 0, service type 0x0001).
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash)]
pub struct MailboxErrorCode(pub u16);

impl MailboxErrorCode {
    pub const SYNTAX: Self = Self(1);
    pub const UNSUPPORTED_PROTOCOL: Self = Self(2);
    pub const INVALID_CHANNEL: Self = Self(3);
    pub const SERVICE_NOT_SUPPORTED: Self = Self(4);
    pub const INVALID_HEADER: Self = Self(5);
    pub const SIZE_TOO_SHORT: Self = Self(6);
    pub const NO_MORE_MEMORY: Self = Self(7);
    pub const INVALID_SIZE: Self = Self(8);
    pub const SERVICE_IN_WORK: Self = Self(9);

    pub fn name(self) -> Option<&'static str> {
        Some(match self.0 {
            1 => "Syntax of 6-octet mailbox header is wrong",
            2 => "Mailbox protocol not supported",
            3 => "Channel field contains wrong value",
            4 => "Service in the mailbox protocol is not supported",
            5 => "Mailbox protocol header is wrong",
            6 => "Length of received mailbox data is too short",
            7 => "Mailbox protocol cannot be processed: not enough resources",
            8 => "Length of data is inconsistent",
            9 => "Mailbox service already in use",
            _ => return None,
        })
    }

    /// Reads the 4-byte body of an error reply (type 0x0001, detail).
    pub fn parse(payload: &[u8]) -> Result<Self> {
        let service = u16_at(payload, 0, "mailbox error type")?;
        if service != 1 {
            return Err(Error::BadValue { what: "mailbox error type", offset: 0, value: service as u32 });
        }
        Ok(MailboxErrorCode(u16_at(payload, 2, "mailbox error detail")?))
    }

    pub fn to_bytes(self) -> [u8; 4] {
        let d = self.0.to_le_bytes();
        [1, 0, d[0], d[1]]
    }
}

impl fmt::Display for MailboxErrorCode {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        match self.name() {
            Some(n) => write!(f, "mailbox error {:#06x} ({n})", self.0),
            None => write!(f, "mailbox error {:#06x}", self.0),
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn header_round_trip_and_counter() {
        let h = MailboxHeader {
            length: 10,
            address: 0x1001,
            channel: 0,
            priority: 3,
            mailbox_type: MailboxType::COE,
            counter: 5,
            reserved: false,
        };
        assert_eq!(MailboxHeader::parse(&h.to_bytes()).unwrap(), h);
        assert_eq!(next_counter(7), 1);
        assert_eq!(next_counter(0), 1);
        let mut buf = [0u8; 16];
        h.emit(&mut buf).unwrap();
        assert_eq!(Mailbox::parse(&buf).unwrap().payload.len(), 10);
        assert!(Mailbox::parse(&buf[..12]).is_err());
        assert_eq!(MailboxErrorCode::parse(&[1, 0, 2, 0]).unwrap(), MailboxErrorCode::UNSUPPORTED_PROTOCOL);
    }
}
