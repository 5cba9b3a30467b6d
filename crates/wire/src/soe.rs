//! Servo drive profile over EtherCAT (SoE, mailbox type 5; ETG.1000.6 §5.8, IEC 61800-7-204):
//! the SERCOS service channel in the mailbox. A message is a 4-byte header — opcode, the
//! "incomplete" (more fragments follow) and error flags, the drive number, which elements of
//! the IDN it carries, and the IDN (or, in a fragment, the fragments left) — then the data.
use core::fmt;

use crate::bytes::{need, put, u16_at, u8_at};
use crate::{Error, Result};

/// Opcode and flags, elements, IDN.
pub const HEADER_LEN: usize = 4;

pub mod opcode {
    pub const READ_REQUEST: u8 = 1;
    pub const READ_RESPONSE: u8 = 2;
    pub const WRITE_REQUEST: u8 = 3;
    pub const WRITE_RESPONSE: u8 = 4;
    /// The slave reports a changed IDN element by itself.
    pub const NOTIFICATION: u8 = 5;
    /// The slave's emergency (SoE's own, with its diagnosis text).
    pub const EMERGENCY: u8 = 6;
}

/// An IDN's elements (the header's second byte): which of them a request asks for or a
/// message carries, in this order in its data.
#[derive(Clone, Copy, PartialEq, Eq, Hash, Default)]
pub struct Elements(pub u8);

impl Elements {
    pub const DATA_STATE: Self = Self(0x01);
    pub const NAME: Self = Self(0x02);
    pub const ATTRIBUTE: Self = Self(0x04);
    pub const UNIT: Self = Self(0x08);
    pub const MIN: Self = Self(0x10);
    pub const MAX: Self = Self(0x20);
    pub const VALUE: Self = Self(0x40);
    pub const DEFAULT: Self = Self(0x80);

    /// Each element by name, as the command line takes it.
    pub const NAMES: [(&'static str, Elements); 8] = [
        ("data-state", Self::DATA_STATE),
        ("name", Self::NAME),
        ("attribute", Self::ATTRIBUTE),
        ("unit", Self::UNIT),
        ("min", Self::MIN),
        ("max", Self::MAX),
        ("value", Self::VALUE),
        ("default", Self::DEFAULT),
    ];

    pub fn contains(self, other: Elements) -> bool {
        self.0 & other.0 == other.0 && other.0 != 0
    }

    /// The element of this name (`name`, `value` …).
    pub fn by_name(name: &str) -> Option<Elements> {
        Self::NAMES.iter().find(|(n, _)| n.eq_ignore_ascii_case(name)).map(|(_, e)| *e)
    }
}

impl fmt::Debug for Elements {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        write!(f, "Elements({:#04x})", self.0)
    }
}

/// An identification number: S (standard) or P (product) parameter, parameter set 0–7, data
/// block 0–4095, as `S-0-0030` or `P-0-0001` (bit 15 P, bits 12–14 the set, bits 0–11 the
/// block).
#[derive(Clone, Copy, PartialEq, Eq, Hash, PartialOrd, Ord)]
pub struct Idn(pub u16);

impl Idn {
    /// S-0-0015, telegram type.
    pub const TELEGRAM_TYPE: Self = Self(15);
    /// S-0-0016, the AT's (drive → master) configuration list: the IDNs in the inputs.
    pub const AT_CONFIG: Self = Self(16);
    /// S-0-0017, every IDN the drive has.
    pub const ALL_IDNS: Self = Self(17);
    /// S-0-0024, the MDT's (master → drive) configuration list: the IDNs in the outputs.
    pub const MDT_CONFIG: Self = Self(24);
    /// S-0-0030, the firmware version (text).
    pub const FIRMWARE_VERSION: Self = Self(30);

    pub fn standard(set: u8, block: u16) -> Option<Self> {
        (set < 8 && block < 4096).then_some(Self((set as u16) << 12 | block))
    }

    pub fn product(set: u8, block: u16) -> Option<Self> {
        Self::standard(set, block).map(|i| Self(i.0 | 0x8000))
    }

    pub fn is_product(self) -> bool {
        self.0 & 0x8000 != 0
    }

    pub fn set(self) -> u8 {
        (self.0 >> 12 & 7) as u8
    }

    pub fn block(self) -> u16 {
        self.0 & 0x0FFF
    }

    /// `S-0-0030`, `P-0-0001`, `s-0-30` (the block in decimal), or a number (`0x801e`, `30`).
    pub fn parse(text: &str) -> Option<Self> {
        let t = text.trim();
        let mut parts = t.splitn(3, '-');
        match (parts.next(), parts.next(), parts.next()) {
            (Some(kind), Some(set), Some(block)) => {
                let set: u8 = set.parse().ok()?;
                let block: u16 = block.parse().ok()?;
                match kind {
                    "S" | "s" => Self::standard(set, block),
                    "P" | "p" => Self::product(set, block),
                    _ => None,
                }
            }
            _ => {
                let v = match t.strip_prefix("0x").or_else(|| t.strip_prefix("0X")) {
                    Some(h) => u16::from_str_radix(h, 16).ok()?,
                    None => t.parse().ok()?,
                };
                Some(Self(v))
            }
        }
    }
}

impl fmt::Display for Idn {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        write!(f, "{}-{}-{:04}", if self.is_product() { 'P' } else { 'S' }, self.set(), self.block())
    }
}

impl fmt::Debug for Idn {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        write!(f, "Idn({self})")
    }
}

/// The header of an SoE message.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct SoeHeader {
    pub opcode: u8,
    /// More fragments follow this one; `idn` then counts the fragments left.
    pub incomplete: bool,
    /// An error response: the data is a 16-bit [`SoeError`].
    pub error: bool,
    /// The drive (axis) of a multi-axis device, 0–7.
    pub drive: u8,
    pub elements: Elements,
    /// The IDN, or in a fragment with `incomplete` the fragments that follow.
    pub idn: u16,
}

impl SoeHeader {
    pub fn parse(buf: &[u8]) -> Result<Self> {
        need(buf, 0, HEADER_LEN, "SoE header")?;
        let b = u8_at(buf, 0, "SoE opcode")?;
        let opcode = b & 0x07;
        if opcode == 0 || opcode == 7 {
            return Err(Error::BadValue { what: "SoE opcode", offset: 0, value: opcode as u32 });
        }
        Ok(SoeHeader {
            opcode,
            incomplete: b & 0x08 != 0,
            error: b & 0x10 != 0,
            drive: b >> 5,
            elements: Elements(u8_at(buf, 1, "SoE elements")?),
            idn: u16_at(buf, 2, "SoE IDN")?,
        })
    }

    pub fn emit(&self, out: &mut [u8]) -> Result<usize> {
        if self.drive > 7 {
            return Err(Error::BadValue { what: "SoE drive number", offset: 0, value: self.drive as u32 });
        }
        let b = (self.opcode & 7) | (self.incomplete as u8) << 3 | (self.error as u8) << 4 | self.drive << 5;
        put(out, 0, &[b, self.elements.0], "SoE header")?;
        put(out, 2, &self.idn.to_le_bytes(), "SoE header")?;
        Ok(HEADER_LEN)
    }
}

/// An SoE error code (ETG.1000.6 and IEC 61800-7-204's service-channel errors: the high nibble
/// names the element, 1 the IDN, 2 the name, 3 the attribute, 4 the unit, 5 the minimum, 6 the
/// maximum, 7 the value, 8 the default).
#[derive(Clone, Copy, PartialEq, Eq, Hash)]
pub struct SoeError(pub u16);

impl SoeError {
    pub const NO_IDN: Self = Self(0x1001);
    pub const INVALID_ACCESS_TO_ELEMENT_1: Self = Self(0x1009);
    pub const NO_NAME: Self = Self(0x2001);
    pub const NAME_READ_ONLY: Self = Self(0x2004);
    pub const ATTRIBUTE_READ_ONLY: Self = Self(0x3004);
    pub const NO_UNIT: Self = Self(0x4001);
    pub const NO_MIN: Self = Self(0x5001);
    pub const NO_MAX: Self = Self(0x6001);
    pub const VALUE_TOO_SHORT: Self = Self(0x7002);
    pub const VALUE_TOO_LONG: Self = Self(0x7003);
    pub const VALUE_READ_ONLY: Self = Self(0x7004);
    pub const VALUE_WRITE_PROTECTED_NOW: Self = Self(0x7005);
    pub const VALUE_BELOW_MIN: Self = Self(0x7006);
    pub const VALUE_ABOVE_MAX: Self = Self(0x7007);
    pub const VALUE_INVALID: Self = Self(0x7008);
    pub const NO_DEFAULT: Self = Self(0x8001);
    pub const INVALID_DRIVE: Self = Self(0x800A);
    pub const GENERAL: Self = Self(0x800B);
    pub const NO_ELEMENT: Self = Self(0x800C);

    pub fn name(self) -> Option<&'static str> {
        Some(match self.0 {
            0x1001 => "no IDN",
            0x1009 => "invalid access to element 1",
            0x2001 => "no name",
            0x2002 => "name too short",
            0x2003 => "name too long",
            0x2004 => "name cannot be changed, read only",
            0x2005 => "name is write protected at this time",
            0x3002 => "attribute too short",
            0x3003 => "attribute too long",
            0x3004 => "attribute cannot be changed, read only",
            0x3005 => "attribute is write protected at this time",
            0x4001 => "no unit",
            0x4002 => "unit too short",
            0x4003 => "unit too long",
            0x4004 => "unit cannot be changed, read only",
            0x4005 => "unit is write protected at this time",
            0x5001 => "no minimum",
            0x5002 => "minimum too short",
            0x5003 => "minimum too long",
            0x5004 => "minimum cannot be changed, read only",
            0x5005 => "minimum is write protected at this time",
            0x6001 => "no maximum",
            0x6002 => "maximum too short",
            0x6003 => "maximum too long",
            0x6004 => "maximum cannot be changed, read only",
            0x6005 => "maximum is write protected at this time",
            0x7002 => "operation data too short",
            0x7003 => "operation data too long",
            0x7004 => "operation data value cannot be changed, read only",
            0x7005 => "operation data is write protected at this time",
            0x7006 => "operation data is smaller than the minimum",
            0x7007 => "operation data is greater than the maximum",
            0x7008 => "invalid operation data",
            0x7009 => "operation data is write protected by a password",
            0x700A => "operation data is write protected, configured cyclically",
            0x7010 => "procedure command already active",
            0x7011 => "procedure command not interruptible",
            0x7012 => "procedure command not executable at this time",
            0x7013 => "procedure command not executable (invalid or false parameters)",
            0x8001 => "no default value",
            0x8002 => "default value too long",
            0x8004 => "default value cannot be changed, read only",
            0x800A => "invalid drive number",
            0x800B => "general error",
            0x800C => "no element addressed",
            _ => return None,
        })
    }
}

impl fmt::Debug for SoeError {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        write!(f, "SoeError({:#06x})", self.0)
    }
}

impl fmt::Display for SoeError {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        match self.name() {
            Some(n) => write!(f, "SoE error {:#06x} ({n})", self.0),
            None => write!(f, "SoE error {:#06x}", self.0),
        }
    }
}

/// An IDN's attribute (element 3), as the drive describes its value: the conversion factor
/// (bits 0–15), the value's length (16–18), whether it is a procedure command (19), its data
/// type and display format (20–22), decimal places (24–27), and in which communication phases
/// 2, 3, 4 it is write protected (28–30).
#[derive(Clone, Copy, PartialEq, Eq, Hash, Default)]
pub struct Attribute(pub u32);

/// How long an IDN's value is: a fixed width, or a list of items of that width.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum ValueLength {
    Fixed(u8),
    /// A list: a 16-bit current length and a 16-bit maximum length, both in bytes, then the
    /// items of this many bytes each.
    List(u8),
}

/// An IDN value's data type and display format.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum DataType {
    Binary,
    Unsigned,
    Signed,
    Hex,
    Text,
    Idn,
    Float,
    Parameter,
}

impl Attribute {
    pub fn new(length: ValueLength, data_type: DataType, decimals: u8) -> Self {
        let len = match length {
            ValueLength::Fixed(1) => 0,
            ValueLength::Fixed(2) => 1,
            ValueLength::Fixed(4) => 2,
            ValueLength::Fixed(_) => 3,
            ValueLength::List(1) => 4,
            ValueLength::List(2) => 5,
            ValueLength::List(4) => 6,
            ValueLength::List(_) => 7,
        };
        let ty = data_type as u32;
        Attribute(1 | len << 16 | ty << 20 | ((decimals & 15) as u32) << 24)
    }

    pub fn conversion_factor(self) -> u16 {
        self.0 as u16
    }

    pub fn length(self) -> ValueLength {
        match self.0 >> 16 & 7 {
            0 => ValueLength::Fixed(1),
            1 => ValueLength::Fixed(2),
            2 => ValueLength::Fixed(4),
            3 => ValueLength::Fixed(8),
            4 => ValueLength::List(1),
            5 => ValueLength::List(2),
            6 => ValueLength::List(4),
            _ => ValueLength::List(8),
        }
    }

    pub fn is_command(self) -> bool {
        self.0 & 1 << 19 != 0
    }

    pub fn data_type(self) -> DataType {
        match self.0 >> 20 & 7 {
            0 => DataType::Binary,
            1 => DataType::Unsigned,
            2 => DataType::Signed,
            3 => DataType::Hex,
            4 => DataType::Text,
            5 => DataType::Idn,
            6 => DataType::Float,
            _ => DataType::Parameter,
        }
    }

    pub fn decimals(self) -> u8 {
        (self.0 >> 24 & 15) as u8
    }

    /// Write protected in communication phase 2, 3 or 4 (PREOP, SAFEOP, OP).
    pub fn write_protected_in(self, phase: u8) -> bool {
        matches!(phase, 2..=4) && self.0 & 1 << (26 + phase) != 0
    }

    pub fn with_write_protection(self, phases: &[u8]) -> Self {
        let mut a = self.0 & !(7 << 28);
        for &p in phases.iter().filter(|p| (2..=4).contains(*p)) {
            a |= 1 << (26 + p);
        }
        Attribute(a)
    }
}

impl fmt::Debug for Attribute {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        write!(f, "Attribute({:#010x}: {:?}, {:?})", self.0, self.length(), self.data_type())
    }
}

/// A list element's current length and the items after it: a name, a unit, a text value, or
/// a list value (`List` lengths). Errors where the stated length runs past the data.
pub fn list_items(data: &[u8]) -> Result<(&[u8], u16)> {
    let current = u16_at(data, 0, "SoE list's current length")?;
    let max = u16_at(data, 2, "SoE list's maximum length")?;
    need(data, 4, current as usize, "SoE list items")?;
    Ok((&data[4..4 + current as usize], max))
}

/// A list element: current length, maximum length, then `items` (the maximum at least the
/// current).
pub fn emit_list(items: &[u8], max: u16, out: &mut [u8]) -> Result<usize> {
    let current = u16::try_from(items.len()).map_err(|_| Error::BadValue {
        what: "SoE list length",
        offset: 0,
        value: items.len() as u32,
    })?;
    put(out, 0, &current.to_le_bytes(), "SoE list")?;
    put(out, 2, &max.max(current).to_le_bytes(), "SoE list")?;
    put(out, 4, items, "SoE list")?;
    Ok(4 + items.len())
}

/// The most service data one fragment carries through a mailbox of `mailbox_len` bytes.
pub fn max_fragment_len(mailbox_len: usize) -> usize {
    mailbox_len.saturating_sub(crate::mailbox::HEADER_LEN + HEADER_LEN)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn idns_are_written_as_sercos_writes_them() {
        assert_eq!(Idn::parse("S-0-0030"), Some(Idn(30)));
        assert_eq!(Idn::parse("P-0-0001"), Some(Idn(0x8001)));
        assert_eq!(Idn::parse("S-7-4095"), Some(Idn(0x7FFF)));
        assert_eq!(Idn::parse("s-0-16"), Some(Idn::AT_CONFIG));
        assert_eq!(Idn::parse("0x8001"), Some(Idn(0x8001)));
        assert_eq!(Idn::parse("S-8-0001"), None, "parameter sets 0 to 7");
        assert_eq!(Idn::parse("S-0-4096"), None, "blocks 0 to 4095");
        assert_eq!(Idn::parse("X-0-0001"), None);
        assert_eq!(Idn(0x8001).to_string(), "P-0-0001");
        assert_eq!(Idn(0x7FFF).to_string(), "S-7-4095");
        for v in [0u16, 30, 0x8001, 0x7FFF, 0xFFFF] {
            assert_eq!(Idn::parse(&Idn(v).to_string()), Some(Idn(v)));
        }
    }

    #[test]
    fn the_header_s_bits_are_where_etg_1000_6_puts_them() {
        // A read response, fragment with 3 left, drive 2, value: opcode 2 | incomplete 0x08
        // | drive 2 << 5.
        let h = SoeHeader { opcode: 2, incomplete: true, error: false, drive: 2, elements: Elements::VALUE, idn: 3 };
        let mut b = [0u8; 4];
        h.emit(&mut b).unwrap();
        assert_eq!(b, [0x4A, 0x40, 3, 0]);
        assert_eq!(SoeHeader::parse(&b).unwrap(), h);
        let e = SoeHeader::parse(&[0x14, 0x40, 0x1E, 0x00]).unwrap();
        assert!(e.error && e.opcode == opcode::WRITE_RESPONSE && e.idn == 30);
        assert!(SoeHeader::parse(&[0x00, 0, 0, 0]).is_err(), "opcode 0");
        assert!(SoeHeader::parse(&[0x01, 0x40, 0]).is_err(), "3 bytes");
        let bad = SoeHeader { drive: 8, ..h };
        assert!(bad.emit(&mut b).is_err());
    }

    #[test]
    fn attributes_decode_length_type_decimals_and_protection() {
        // A 4-byte signed value with 3 decimals, written only in PREOP (protected in 3, 4).
        let a = Attribute::new(ValueLength::Fixed(4), DataType::Signed, 3).with_write_protection(&[3, 4]);
        assert_eq!(a.length(), ValueLength::Fixed(4));
        assert_eq!(a.data_type(), DataType::Signed);
        assert_eq!(a.decimals(), 3);
        assert_eq!(a.conversion_factor(), 1);
        assert!(!a.write_protected_in(2) && a.write_protected_in(3) && a.write_protected_in(4));
        assert_eq!(a.0, 0x6322_0001);
        // A text: a list of 1-byte items.
        let t = Attribute::new(ValueLength::List(1), DataType::Text, 0);
        assert_eq!((t.length(), t.data_type()), (ValueLength::List(1), DataType::Text));
        assert_eq!(t.0 >> 16 & 7, 4);
    }

    #[test]
    fn lists_carry_their_lengths_and_a_short_one_is_an_error() {
        let mut b = [0u8; 16];
        let n = emit_list(b"V1.02", 8, &mut b).unwrap();
        assert_eq!(&b[..n], &[5, 0, 8, 0, b'V', b'1', b'.', b'0', b'2']);
        assert_eq!(list_items(&b[..n]).unwrap(), (&b"V1.02"[..], 8));
        assert!(list_items(&[9, 0, 9, 0, 1, 2]).is_err(), "9 bytes stated, 2 there");
        assert!(list_items(&[1, 0]).is_err());
    }

    #[test]
    fn error_codes_are_named() {
        assert_eq!(SoeError(0x1001).to_string(), "SoE error 0x1001 (no IDN)");
        assert_eq!(
            SoeError::VALUE_READ_ONLY.to_string(),
            "SoE error 0x7004 (operation data value cannot be changed, read only)"
        );
        assert_eq!(SoeError(0x7FFF).to_string(), "SoE error 0x7fff");
    }
}
