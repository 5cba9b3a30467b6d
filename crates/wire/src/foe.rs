//! File access over EtherCAT (FoE, mailbox type 4; ETG.1000.6 §5.7): the service data after the
//! mailbox header. A file moves as numbered DATA packets, each acknowledged; a packet shorter
//! than the mailbox allows ends the file (an empty one where the file fills the last packet).
use core::fmt;

use crate::bytes::{need, put, u16_at, u32_at, u8_at};
use crate::{Error, Result};

/// Opcode and reserved byte, then a 32-bit field (password, packet number, error code, or busy
/// progress), then the name, data or error text.
pub const HEADER_LEN: usize = 6;

pub mod opcode {
    pub const READ_REQUEST: u8 = 1;
    pub const WRITE_REQUEST: u8 = 2;
    pub const DATA: u8 = 3;
    pub const ACK: u8 = 4;
    pub const ERROR: u8 = 5;
    pub const BUSY: u8 = 6;
}

/// An FoE error code (ETG.1000.6 Table 92).
#[derive(Clone, Copy, PartialEq, Eq, Hash)]
pub struct FoeErrorCode(pub u32);

impl FoeErrorCode {
    pub const NOT_DEFINED: Self = Self(0x8000);
    pub const NOT_FOUND: Self = Self(0x8001);
    pub const ACCESS_DENIED: Self = Self(0x8002);
    pub const DISK_FULL: Self = Self(0x8003);
    pub const ILLEGAL: Self = Self(0x8004);
    pub const PACKET_NUMBER_WRONG: Self = Self(0x8005);
    pub const ALREADY_EXISTS: Self = Self(0x8006);
    pub const NO_USER: Self = Self(0x8007);
    pub const BOOTSTRAP_ONLY: Self = Self(0x8008);
    pub const NOT_BOOTSTRAP: Self = Self(0x8009);
    pub const NO_RIGHTS: Self = Self(0x800A);
    pub const PROGRAM_ERROR: Self = Self(0x800B);

    pub fn name(self) -> Option<&'static str> {
        Some(match self.0 {
            0x8000 => "not defined",
            0x8001 => "file not found",
            0x8002 => "access denied",
            0x8003 => "disk full",
            0x8004 => "illegal",
            0x8005 => "packet number wrong",
            0x8006 => "file already exists",
            0x8007 => "no user",
            0x8008 => "bootstrap only",
            0x8009 => "not in bootstrap",
            0x800A => "no rights",
            0x800B => "program error",
            _ => return None,
        })
    }
}

impl fmt::Debug for FoeErrorCode {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        write!(f, "FoeErrorCode({:#06x})", self.0)
    }
}

impl fmt::Display for FoeErrorCode {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        match self.name() {
            Some(n) => write!(f, "FoE error {:#06x} ({n})", self.0),
            None => write!(f, "FoE error {:#06x}", self.0),
        }
    }
}

/// One FoE message, borrowing its name, data or text from the buffer it was parsed from.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Foe<'a> {
    ReadRequest {
        password: u32,
        file_name: &'a [u8],
    },
    WriteRequest {
        password: u32,
        file_name: &'a [u8],
    },
    /// Packets count from 1.
    Data {
        packet: u32,
        data: &'a [u8],
    },
    Ack {
        packet: u32,
    },
    Error {
        code: FoeErrorCode,
        text: &'a [u8],
    },
    /// The slave is not ready for the next packet yet: `done` of `entire` (units its own).
    Busy {
        done: u16,
        entire: u16,
    },
}

impl<'a> Foe<'a> {
    /// Parses the service data of a type-4 mailbox (its header's length already applied).
    pub fn parse(buf: &'a [u8]) -> Result<Self> {
        need(buf, 0, HEADER_LEN, "FoE header")?;
        let op = u8_at(buf, 0, "FoE opcode")?;
        let field = u32_at(buf, 2, "FoE header field")?;
        let rest = &buf[HEADER_LEN..];
        Ok(match op {
            opcode::READ_REQUEST => Foe::ReadRequest { password: field, file_name: rest },
            opcode::WRITE_REQUEST => Foe::WriteRequest { password: field, file_name: rest },
            opcode::DATA => Foe::Data { packet: field, data: rest },
            opcode::ACK => Foe::Ack { packet: field },
            opcode::ERROR => Foe::Error { code: FoeErrorCode(field), text: rest },
            opcode::BUSY => {
                Foe::Busy { done: u16_at(buf, 2, "FoE busy done")?, entire: u16_at(buf, 4, "FoE busy entire")? }
            }
            other => return Err(Error::BadValue { what: "FoE opcode", offset: 0, value: other as u32 }),
        })
    }

    pub fn opcode(&self) -> u8 {
        match self {
            Foe::ReadRequest { .. } => opcode::READ_REQUEST,
            Foe::WriteRequest { .. } => opcode::WRITE_REQUEST,
            Foe::Data { .. } => opcode::DATA,
            Foe::Ack { .. } => opcode::ACK,
            Foe::Error { .. } => opcode::ERROR,
            Foe::Busy { .. } => opcode::BUSY,
        }
    }

    fn field_and_tail(&self) -> (u32, &'a [u8]) {
        match *self {
            Foe::ReadRequest { password, file_name } | Foe::WriteRequest { password, file_name } => {
                (password, file_name)
            }
            Foe::Data { packet, data } => (packet, data),
            Foe::Ack { packet } => (packet, &[]),
            Foe::Error { code, text } => (code.0, text),
            Foe::Busy { done, entire } => (done as u32 | (entire as u32) << 16, &[]),
        }
    }

    /// Bytes [`emit`](Self::emit) writes.
    pub fn len(&self) -> usize {
        HEADER_LEN + self.field_and_tail().1.len()
    }

    pub fn is_empty(&self) -> bool {
        false
    }

    /// Writes the message into `out`; returns its length.
    pub fn emit(&self, out: &mut [u8]) -> Result<usize> {
        let (field, tail) = self.field_and_tail();
        put(out, 0, &[self.opcode(), 0], "FoE header")?;
        put(out, 2, &field.to_le_bytes(), "FoE header")?;
        put(out, HEADER_LEN, tail, "FoE data")?;
        Ok(self.len())
    }
}

/// The most file data one DATA packet carries through a mailbox of `mailbox_len` bytes.
pub fn max_data_len(mailbox_len: usize) -> usize {
    mailbox_len.saturating_sub(crate::mailbox::HEADER_LEN + HEADER_LEN)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn every_message_round_trips() {
        let msgs = [
            Foe::ReadRequest { password: 0x1234_5678, file_name: b"app.bin" },
            Foe::WriteRequest { password: 0, file_name: b"" },
            Foe::Data { packet: 7, data: &[1, 2, 3] },
            Foe::Data { packet: u32::MAX, data: &[] },
            Foe::Ack { packet: 3 },
            Foe::Error { code: FoeErrorCode::NOT_FOUND, text: b"no such file" },
            Foe::Busy { done: 30, entire: 100 },
        ];
        for m in msgs {
            let mut b = [0u8; 64];
            let n = m.emit(&mut b).unwrap();
            assert_eq!(n, m.len());
            assert_eq!(Foe::parse(&b[..n]).unwrap(), m);
        }
    }

    #[test]
    fn the_bytes_match_the_specification() {
        // Opcode, reserved, the 32-bit field little-endian, then the name.
        let mut b = [0u8; 16];
        let n = Foe::WriteRequest { password: 0x0102_0304, file_name: b"fw" }.emit(&mut b).unwrap();
        assert_eq!(&b[..n], &[2, 0, 4, 3, 2, 1, b'f', b'w']);
        let n = Foe::Busy { done: 1, entire: 2 }.emit(&mut b).unwrap();
        assert_eq!(&b[..n], &[6, 0, 1, 0, 2, 0]);
    }

    #[test]
    fn bad_input_is_an_error_not_a_panic() {
        assert!(matches!(Foe::parse(&[3, 0, 1]), Err(Error::Truncated { what: "FoE header", .. })));
        assert_eq!(Foe::parse(&[9, 0, 0, 0, 0, 0]), Err(Error::BadValue { what: "FoE opcode", offset: 0, value: 9 }));
        let mut small = [0u8; 7];
        assert!(Foe::Data { packet: 1, data: &[0; 4] }.emit(&mut small).is_err());
        assert_eq!(max_data_len(128), 116);
        assert_eq!(max_data_len(4), 0);
    }

    #[test]
    fn error_codes_name_themselves() {
        assert_eq!(FoeErrorCode::PACKET_NUMBER_WRONG.to_string(), "FoE error 0x8005 (packet number wrong)");
        assert_eq!(FoeErrorCode(0x8123).to_string(), "FoE error 0x8123");
    }
}
