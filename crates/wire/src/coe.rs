//! CANopen over EtherCAT (esc-spec §6.2–6.4): the CoE header, SDO transfers (expedited, normal,
//! segmented, complete access), aborts, emergencies and SDO information.
use core::fmt;

use crate::bytes::{need, put, slice_at, u16_at, u32_at, u8_at};
use crate::{Error, Result};

pub const HEADER_LEN: usize = 2;
/// Bytes of an SDO initiate frame after the CoE header: command, index, subindex, 4 data bytes.
pub const SDO_HEADER_LEN: usize = 8;

/// Where each field lies, in bytes after the CoE header, as smoltcp's `mod field` says it once
/// (ETG.1000.6 §5.6.2).
mod field {
    pub type Field = core::ops::Range<usize>;

    /// An SDO frame: the command byte, then (initiate and abort) index, subindex and four
    /// bytes of data, size or abort code; a segment's data follow the command byte.
    pub mod sdo {
        use super::Field;
        pub const COMMAND: usize = 0;
        pub const INDEX: usize = 1;
        pub const SUBINDEX: usize = 3;
        pub const DATA: Field = 4..8;
        pub const SEGMENT: usize = 1;
        /// A segment's data bytes at least (padded).
        pub const SEGMENT_MIN_LEN: usize = 7;
    }

    /// An emergency (CiA 301 EMCY in CoE).
    pub mod emergency {
        use super::Field;
        pub const ERROR_CODE: usize = 0;
        pub const ERROR_REGISTER: usize = 2;
        pub const DATA: Field = 3..8;
    }

    /// The SDO information header, and the bodies after it.
    pub mod info {
        pub const OPCODE: usize = 0;
        pub const RESERVED: usize = 1;
        pub const FRAGMENTS_LEFT: usize = 2;
        /// Object and entry descriptions: index, then …
        pub const INDEX: usize = 0;
        /// … an object's data type, highest subindex, object code and name …
        pub const OBJECT_DATA_TYPE: usize = 2;
        pub const MAX_SUBINDEX: usize = 4;
        pub const OBJECT_CODE: usize = 5;
        pub const OBJECT_NAME: usize = 6;
        /// … or an entry's subindex, value info, data type, bit length, access and the rest.
        pub const ENTRY_SUBINDEX: usize = 2;
        pub const VALUE_INFO: usize = 3;
        pub const ENTRY_DATA_TYPE: usize = 4;
        pub const BIT_LENGTH: usize = 6;
        pub const OBJECT_ACCESS: usize = 8;
        pub const ENTRY_REST: usize = 10;
    }
}
/// Bytes before segment data: CoE header and the command byte.
pub const SEGMENT_HEADER_LEN: usize = 3;

/// CoE service (header bits 15:12).
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash)]
pub struct CoeService(pub u8);

impl CoeService {
    pub const EMERGENCY: Self = Self(1);
    pub const SDO_REQUEST: Self = Self(2);
    pub const SDO_RESPONSE: Self = Self(3);
    pub const TXPDO: Self = Self(4);
    pub const RXPDO: Self = Self(5);
    pub const TXPDO_REMOTE_REQUEST: Self = Self(6);
    pub const RXPDO_REMOTE_REQUEST: Self = Self(7);
    pub const SDO_INFORMATION: Self = Self(8);
}

#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash)]
pub struct CoeHeader {
    /// PDO number (9 bits); 0 for SDO services.
    pub number: u16,
    pub reserved: u8,
    pub service: CoeService,
}

impl CoeHeader {
    pub fn new(service: CoeService) -> Self {
        CoeHeader { number: 0, reserved: 0, service }
    }
    pub fn parse(buf: &[u8]) -> Result<Self> {
        let w = u16_at(buf, 0, "CoE header")?;
        Ok(CoeHeader { number: w & 0x1FF, reserved: ((w >> 9) & 7) as u8, service: CoeService((w >> 12) as u8) })
    }
    pub fn word(&self) -> u16 {
        (self.number & 0x1FF) | ((self.reserved as u16 & 7) << 9) | ((self.service.0 as u16 & 0xF) << 12)
    }
    pub fn emit(&self, out: &mut [u8]) -> Result<()> {
        put(out, 0, &self.word().to_le_bytes(), "CoE header")
    }
}

/// SDO abort codes (CiA 301 / ETG.1000.6), with the name of every standard code.
#[derive(Clone, Copy, PartialEq, Eq, Hash)]
pub struct AbortCode(pub u32);

impl AbortCode {
    pub const TOGGLE_BIT: Self = Self(0x0503_0000);
    pub const TIMEOUT: Self = Self(0x0504_0000);
    pub const INVALID_COMMAND: Self = Self(0x0504_0001);
    pub const OUT_OF_MEMORY: Self = Self(0x0504_0005);
    pub const UNSUPPORTED_ACCESS: Self = Self(0x0601_0000);
    pub const WRITE_ONLY: Self = Self(0x0601_0001);
    pub const READ_ONLY: Self = Self(0x0601_0002);
    pub const SUBINDEX_CANNOT_BE_WRITTEN: Self = Self(0x0601_0003);
    pub const COMPLETE_ACCESS_UNSUPPORTED: Self = Self(0x0601_0004);
    pub const OBJECT_TOO_LONG: Self = Self(0x0601_0005);
    pub const OBJECT_MAPPED: Self = Self(0x0601_0006);
    pub const NO_OBJECT: Self = Self(0x0602_0000);
    pub const CANNOT_BE_MAPPED: Self = Self(0x0604_0041);
    pub const MAPPING_TOO_LONG: Self = Self(0x0604_0042);
    pub const PARAMETER_INCOMPATIBLE: Self = Self(0x0604_0043);
    pub const INTERNAL_INCOMPATIBLE: Self = Self(0x0604_0047);
    pub const HARDWARE_ERROR: Self = Self(0x0606_0000);
    pub const LENGTH_MISMATCH: Self = Self(0x0607_0010);
    pub const LENGTH_TOO_HIGH: Self = Self(0x0607_0012);
    pub const LENGTH_TOO_LOW: Self = Self(0x0607_0013);
    pub const NO_SUBINDEX: Self = Self(0x0609_0011);
    pub const VALUE_RANGE: Self = Self(0x0609_0030);
    pub const VALUE_TOO_HIGH: Self = Self(0x0609_0031);
    pub const VALUE_TOO_LOW: Self = Self(0x0609_0032);
    pub const MAX_BELOW_MIN: Self = Self(0x0609_0036);
    pub const GENERAL: Self = Self(0x0800_0000);
    pub const CANNOT_TRANSFER: Self = Self(0x0800_0020);
    pub const LOCAL_CONTROL: Self = Self(0x0800_0021);
    pub const DEVICE_STATE: Self = Self(0x0800_0022);
    pub const NO_DICTIONARY: Self = Self(0x0800_0023);

    pub fn name(self) -> Option<&'static str> {
        Some(match self.0 {
            0x0503_0000 => "Toggle bit not changed",
            0x0504_0000 => "SDO protocol timeout",
            0x0504_0001 => "Client/server command specifier not valid or unknown",
            0x0504_0002 => "Invalid block size",
            0x0504_0003 => "Invalid sequence number",
            0x0504_0004 => "CRC error",
            0x0504_0005 => "Out of memory",
            0x0601_0000 => "Unsupported access to an object",
            0x0601_0001 => "Attempt to read a write-only object",
            0x0601_0002 => "Attempt to write a read-only object",
            0x0601_0003 => "Subindex cannot be written, SI0 must be 0 for write access",
            0x0601_0004 => "SDO complete access not supported for objects of variable length",
            0x0601_0005 => "Object length exceeds mailbox size",
            0x0601_0006 => "Object mapped to RxPDO, SDO download blocked",
            0x0602_0000 => "The object does not exist in the object dictionary",
            0x0604_0041 => "The object cannot be mapped into the PDO",
            0x0604_0042 => "The number and length of the objects to be mapped would exceed the PDO length",
            0x0604_0043 => "General parameter incompatibility reason",
            0x0604_0047 => "General internal incompatibility in the device",
            0x0606_0000 => "Access failed due to a hardware error",
            0x0607_0010 => "Data type does not match, length of service parameter does not match",
            0x0607_0012 => "Data type does not match, length of service parameter too high",
            0x0607_0013 => "Data type does not match, length of service parameter too low",
            0x0609_0011 => "Subindex does not exist",
            0x0609_0030 => "Value range of parameter exceeded",
            0x0609_0031 => "Value of parameter written too high",
            0x0609_0032 => "Value of parameter written too low",
            0x0609_0036 => "Maximum value is less than minimum value",
            0x0800_0000 => "General error",
            0x0800_0020 => "Data cannot be transferred or stored to the application",
            0x0800_0021 => "Data cannot be transferred or stored to the application because of local control",
            0x0800_0022 => {
                "Data cannot be transferred or stored to the application because of the present device state"
            }
            0x0800_0023 => "Object dictionary dynamic generation fails or no object dictionary is present",
            _ => return None,
        })
    }
}

impl fmt::Debug for AbortCode {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        write!(f, "AbortCode({:#010x})", self.0)
    }
}

impl fmt::Display for AbortCode {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        match self.name() {
            Some(n) => write!(f, "{:#010x} ({n})", self.0),
            None => write!(f, "{:#010x} (unknown abort code)", self.0),
        }
    }
}

/// An SDO frame (the bytes after the CoE header), for both directions.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Sdo<'a> {
    /// ccs 1, expedited: up to 4 bytes in the frame. `size` is `None` when not indicated.
    DownloadExpeditedRequest { index: u16, subindex: u8, complete_access: bool, size: Option<u8>, data: [u8; 4] },
    /// ccs 1, normal: total size and the first part of the data.
    DownloadNormalRequest { index: u16, subindex: u8, complete_access: bool, complete_size: u32, data: &'a [u8] },
    /// ccs 0: one segment; `segment` holds at least 7 bytes of which `unused` at the end are padding.
    DownloadSegmentRequest { toggle: bool, last: bool, unused: u8, segment: &'a [u8] },
    /// scs 3.
    DownloadResponse { index: u16, subindex: u8, complete_access: bool, reserved: [u8; 4] },
    /// scs 1.
    DownloadSegmentResponse { toggle: bool, reserved: [u8; 7] },
    /// ccs 2.
    UploadRequest { index: u16, subindex: u8, complete_access: bool, reserved: [u8; 4] },
    /// scs 2, expedited.
    UploadExpeditedResponse { index: u16, subindex: u8, complete_access: bool, size: Option<u8>, data: [u8; 4] },
    /// scs 2, normal; if `data` is shorter than `complete_size`, segments follow.
    UploadNormalResponse { index: u16, subindex: u8, complete_access: bool, complete_size: u32, data: &'a [u8] },
    /// ccs 3.
    UploadSegmentRequest { toggle: bool, reserved: [u8; 7] },
    /// scs 0.
    UploadSegmentResponse { toggle: bool, last: bool, unused: u8, segment: &'a [u8] },
    /// cs 4, either direction.
    Abort { index: u16, subindex: u8, code: AbortCode },
}

const CS_SHIFT: u8 = 5;
const COMPLETE_ACCESS: u8 = 0x10;
const TOGGLE: u8 = 0x10;
const EXPEDITED: u8 = 0x02;
const SIZE_INDICATED: u8 = 0x01;

/// Unused bytes of a segment's 7-byte minimum (bits 3:1).
fn unused_of(command: u8) -> u8 {
    (command >> 1) & 0x07
}

impl<'a> Sdo<'a> {
    /// Parses `body` (everything after the CoE header up to the mailbox length). Whether it is a
    /// request or a response follows from the CoE service.
    pub fn parse(service: CoeService, body: &'a [u8]) -> Result<Self> {
        use field::sdo;
        let cmd = u8_at(body, sdo::COMMAND, "SDO command")?;
        let cs = cmd >> CS_SHIFT;
        let toggle = cmd & TOGGLE != 0;
        if cs == 4 {
            need(body, 0, SDO_HEADER_LEN, "SDO abort")?;
            return Ok(Sdo::Abort {
                index: u16_at(body, sdo::INDEX, "")?,
                subindex: body[sdo::SUBINDEX],
                code: AbortCode(u32_at(body, sdo::DATA.start, "")?),
            });
        }
        let request = match service {
            CoeService::SDO_REQUEST => true,
            CoeService::SDO_RESPONSE => false,
            other => return Err(Error::BadValue { what: "CoE service for SDO", offset: 0, value: other.0 as u32 }),
        };
        let seven = |b: &[u8]| -> Result<[u8; 7]> {
            let s = slice_at(b, sdo::SEGMENT, sdo::SEGMENT_MIN_LEN, "SDO segment reserved bytes")?;
            let mut r = [0; 7];
            r.copy_from_slice(s);
            Ok(r)
        };
        match (request, cs) {
            (true, 0) | (false, 0) => {
                let segment = slice_at(body, sdo::SEGMENT, body.len().saturating_sub(sdo::SEGMENT), "SDO segment")?;
                if segment.len() < sdo::SEGMENT_MIN_LEN {
                    return Err(Error::Truncated {
                        what: "SDO segment (7 bytes minimum)",
                        offset: sdo::SEGMENT,
                        needed: sdo::SEGMENT_MIN_LEN,
                        available: segment.len(),
                    });
                }
                let unused = unused_of(cmd);
                if segment.len() > sdo::SEGMENT_MIN_LEN && unused != 0 {
                    return Err(Error::BadValue {
                        what: "SDO segment unused-byte count",
                        offset: sdo::COMMAND,
                        value: unused as u32,
                    });
                }
                let last = cmd & 1 != 0;
                Ok(if request {
                    Sdo::DownloadSegmentRequest { toggle, last, unused, segment }
                } else {
                    Sdo::UploadSegmentResponse { toggle, last, unused, segment }
                })
            }
            (false, 1) => Ok(Sdo::DownloadSegmentResponse { toggle, reserved: seven(body)? }),
            (true, 3) => Ok(Sdo::UploadSegmentRequest { toggle, reserved: seven(body)? }),
            (true, 1) | (false, 2) => {
                need(body, 0, SDO_HEADER_LEN, "SDO initiate")?;
                let index = u16_at(body, sdo::INDEX, "")?;
                let subindex = body[sdo::SUBINDEX];
                let complete_access = cmd & COMPLETE_ACCESS != 0;
                let mut four = [0; 4];
                four.copy_from_slice(&body[sdo::DATA]);
                if cmd & EXPEDITED != 0 {
                    // Initiate frames count unused bytes in bits 3:2 (segments use 3:1).
                    let size = (cmd & SIZE_INDICATED != 0).then(|| 4 - ((cmd >> 2) & 3));
                    Ok(if request {
                        Sdo::DownloadExpeditedRequest { index, subindex, complete_access, size, data: four }
                    } else {
                        Sdo::UploadExpeditedResponse { index, subindex, complete_access, size, data: four }
                    })
                } else {
                    let complete_size = u32::from_le_bytes(four);
                    let data = &body[SDO_HEADER_LEN..];
                    Ok(if request {
                        Sdo::DownloadNormalRequest { index, subindex, complete_access, complete_size, data }
                    } else {
                        Sdo::UploadNormalResponse { index, subindex, complete_access, complete_size, data }
                    })
                }
            }
            (true, 2) | (false, 3) => {
                need(body, 0, SDO_HEADER_LEN, "SDO initiate")?;
                let index = u16_at(body, sdo::INDEX, "")?;
                let subindex = body[sdo::SUBINDEX];
                let complete_access = cmd & COMPLETE_ACCESS != 0;
                let mut reserved = [0; 4];
                reserved.copy_from_slice(&body[sdo::DATA]);
                Ok(if request {
                    Sdo::UploadRequest { index, subindex, complete_access, reserved }
                } else {
                    Sdo::DownloadResponse { index, subindex, complete_access, reserved }
                })
            }
            _ => Err(Error::BadValue { what: "SDO command specifier", offset: sdo::COMMAND, value: cmd as u32 }),
        }
    }

    /// The CoE service this frame travels in.
    pub fn service(&self) -> CoeService {
        match self {
            Sdo::DownloadExpeditedRequest { .. }
            | Sdo::DownloadNormalRequest { .. }
            | Sdo::DownloadSegmentRequest { .. }
            | Sdo::UploadRequest { .. }
            | Sdo::UploadSegmentRequest { .. }
            | Sdo::Abort { .. } => CoeService::SDO_REQUEST,
            _ => CoeService::SDO_RESPONSE,
        }
    }

    /// Segment payload without padding (segments only).
    pub fn segment_data(&self) -> Option<&'a [u8]> {
        match *self {
            Sdo::DownloadSegmentRequest { unused, segment, .. }
            | Sdo::UploadSegmentResponse { unused, segment, .. } => Some(&segment[..segment.len() - unused as usize]),
            _ => None,
        }
    }

    /// Writes the frame (after the CoE header) into `out`; returns its length.
    pub fn emit(&self, out: &mut [u8]) -> Result<usize> {
        let initiate = |out: &mut [u8], cmd: u8, index: u16, sub: u8, four: [u8; 4], rest: &[u8]| -> Result<usize> {
            use field::sdo;
            let mut head = [0u8; SDO_HEADER_LEN];
            head[sdo::COMMAND] = cmd;
            head[sdo::INDEX..sdo::SUBINDEX].copy_from_slice(&index.to_le_bytes());
            head[sdo::SUBINDEX] = sub;
            head[sdo::DATA].copy_from_slice(&four);
            put(out, 0, &head, "SDO frame")?;
            put(out, SDO_HEADER_LEN, rest, "SDO data")?;
            Ok(SDO_HEADER_LEN + rest.len())
        };
        let ca = |b: bool| if b { COMPLETE_ACCESS } else { 0 };
        let tg = |b: bool| if b { TOGGLE } else { 0 };
        let exp = |size: Option<u8>| match size {
            Some(s) => EXPEDITED | SIZE_INDICATED | ((4 - s.clamp(1, 4)) << 2),
            None => EXPEDITED,
        };
        match *self {
            Sdo::DownloadExpeditedRequest { index, subindex, complete_access, size, data } => {
                initiate(out, 0x20 | ca(complete_access) | exp(size), index, subindex, data, &[])
            }
            Sdo::UploadExpeditedResponse { index, subindex, complete_access, size, data } => {
                initiate(out, 0x40 | ca(complete_access) | exp(size), index, subindex, data, &[])
            }
            Sdo::DownloadNormalRequest { index, subindex, complete_access, complete_size, data } => initiate(
                out,
                0x20 | ca(complete_access) | SIZE_INDICATED,
                index,
                subindex,
                complete_size.to_le_bytes(),
                data,
            ),
            Sdo::UploadNormalResponse { index, subindex, complete_access, complete_size, data } => initiate(
                out,
                0x40 | ca(complete_access) | SIZE_INDICATED,
                index,
                subindex,
                complete_size.to_le_bytes(),
                data,
            ),
            Sdo::UploadRequest { index, subindex, complete_access, reserved } => {
                initiate(out, 0x40 | ca(complete_access), index, subindex, reserved, &[])
            }
            Sdo::DownloadResponse { index, subindex, complete_access, reserved } => {
                initiate(out, 0x60 | ca(complete_access), index, subindex, reserved, &[])
            }
            Sdo::Abort { index, subindex, code } => initiate(out, 0x80, index, subindex, code.0.to_le_bytes(), &[]),
            Sdo::DownloadSegmentRequest { toggle, last, unused, segment }
            | Sdo::UploadSegmentResponse { toggle, last, unused, segment } => {
                let cmd = tg(toggle) | ((unused & 7) << 1) | last as u8;
                put(out, 0, &[cmd], "SDO segment")?;
                put(out, 1, segment, "SDO segment")?;
                Ok(1 + segment.len())
            }
            Sdo::DownloadSegmentResponse { toggle, reserved } => {
                put(out, 0, &[0x20 | tg(toggle)], "SDO segment response")?;
                put(out, 1, &reserved, "SDO segment response")?;
                Ok(8)
            }
            Sdo::UploadSegmentRequest { toggle, reserved } => {
                put(out, 0, &[0x60 | tg(toggle)], "SDO segment request")?;
                put(out, 1, &reserved, "SDO segment request")?;
                Ok(8)
            }
        }
    }
}

/// CoE data type codes (CiA 301's data type table, ETG.1000.6 Table 63) that ferrocat's
/// dictionaries use; [`data_type_name`] names every standard one.
pub mod data_type {
    pub const BOOLEAN: u16 = 0x0001;
    pub const INTEGER8: u16 = 0x0002;
    pub const INTEGER16: u16 = 0x0003;
    pub const INTEGER32: u16 = 0x0004;
    pub const UNSIGNED8: u16 = 0x0005;
    pub const UNSIGNED16: u16 = 0x0006;
    pub const UNSIGNED32: u16 = 0x0007;
    pub const REAL32: u16 = 0x0008;
    pub const VISIBLE_STRING: u16 = 0x0009;
    pub const OCTET_STRING: u16 = 0x000A;
    pub const INTEGER64: u16 = 0x0015;
    pub const UNSIGNED64: u16 = 0x001B;
    pub const PDO_MAPPING: u16 = 0x0021;
    pub const IDENTITY: u16 = 0x0023;
}

/// Object codes of SDO information (CiA 301's object code table, ETG.1000.6 Table 62).
pub mod object_code {
    /// A single value.
    pub const VAR: u8 = 0x07;
    /// Entries of one type.
    pub const ARRAY: u8 = 0x08;
    /// Entries of several types.
    pub const RECORD: u8 = 0x09;
}

/// A CoE data type code's name (CiA 301's data type table, ETG.1000.6 Table 63), for the
/// standard types; `None` for a code it does not name (a device's own, or a complex type of a
/// profile).
pub fn data_type_name(code: u16) -> Option<&'static str> {
    Some(match code {
        data_type::BOOLEAN => "BOOLEAN",
        data_type::INTEGER8 => "INTEGER8",
        data_type::INTEGER16 => "INTEGER16",
        data_type::INTEGER32 => "INTEGER32",
        data_type::UNSIGNED8 => "UNSIGNED8",
        data_type::UNSIGNED16 => "UNSIGNED16",
        data_type::UNSIGNED32 => "UNSIGNED32",
        data_type::REAL32 => "REAL32",
        data_type::VISIBLE_STRING => "VISIBLE_STRING",
        data_type::OCTET_STRING => "OCTET_STRING",
        0x000B => "UNICODE_STRING",
        0x000C => "TIME_OF_DAY",
        0x000D => "TIME_DIFFERENCE",
        0x000F => "DOMAIN",
        0x0010 => "INTEGER24",
        0x0011 => "REAL64",
        0x0012 => "INTEGER40",
        0x0013 => "INTEGER48",
        0x0014 => "INTEGER56",
        data_type::INTEGER64 => "INTEGER64",
        0x0016 => "UNSIGNED24",
        0x0018 => "UNSIGNED40",
        0x0019 => "UNSIGNED48",
        0x001A => "UNSIGNED56",
        data_type::UNSIGNED64 => "UNSIGNED64",
        0x0020 => "PDO_COMMUNICATION_PARAMETER",
        data_type::PDO_MAPPING => "PDO_MAPPING",
        0x0022 => "SDO_PARAMETER",
        data_type::IDENTITY => "IDENTITY",
        _ => return None,
    })
}

/// An object code's name (CiA 301's object code table): VAR, ARRAY or RECORD.
pub fn object_code_name(code: u8) -> Option<&'static str> {
    Some(match code {
        0x02 => "DOMAIN",
        0x05 => "DEFTYPE",
        0x06 => "DEFSTRUCT",
        object_code::VAR => "VAR",
        object_code::ARRAY => "ARRAY",
        object_code::RECORD => "RECORD",
        _ => return None,
    })
}

/// An emergency error code in words: the code itself where it is a well-known one, else its
/// class. Codes and classes from CiA 301 (the emergency error codes table), the drive codes
/// from CiA 402 (IEC 61800-7-201's error codes), 0xA000/0xA001 from ETG.1000.6 (the EtherCAT
/// state machine's transitions).
pub fn emergency_text(code: u16) -> &'static str {
    let exact = match code {
        0x0000 => Some("no error (error reset)"),
        0x2310 => Some("continuous over-current"),
        0x2320 => Some("short circuit or earth leakage"),
        0x3210 => Some("DC link over-voltage"),
        0x3220 => Some("DC link under-voltage"),
        0x4310 => Some("drive over-temperature"),
        0x5530 => Some("EEPROM or flash error"),
        0x7121 => Some("motor blocked"),
        0x7305 => Some("incremental sensor 1 fault"),
        0x8110 => Some("communication: overrun, objects lost"),
        0x8130 => Some("life guard or heartbeat error"),
        0x8210 => Some("PDO not processed: length error"),
        0x8220 => Some("PDO length exceeded"),
        0x8611 => Some("following error"),
        0x8612 => Some("reference limit"),
        0xA000 => Some("transition PREOP to SAFEOP failed"),
        0xA001 => Some("transition SAFEOP to OP failed"),
        _ => None,
    };
    if let Some(t) = exact {
        return t;
    }
    match code >> 8 {
        0x10 => "generic error",
        0x21 => "current, input side",
        0x22 => "current inside the device",
        0x23 => "current, output side",
        0x31 => "mains voltage",
        0x32 => "voltage inside the device",
        0x33 => "output voltage",
        0x41 => "ambient temperature",
        0x42 => "device temperature",
        0x61 => "internal software",
        0x62 => "user software",
        0x63 => "data set",
        0x81 => "communication",
        0x82 => "protocol error",
        0x83 => "torque control",
        0x84 => "velocity speed controller",
        0x85 => "position controller",
        0x86 => "positioning controller",
        0x87 => "sync controller",
        0xFF => "device specific",
        _ => match code >> 12 {
            0x1 => "generic error",
            0x2 => "current",
            0x3 => "voltage",
            0x4 => "temperature",
            0x5 => "device hardware",
            0x6 => "device software",
            0x7 => "additional modules",
            0x8 => "monitoring",
            0x9 => "external error",
            0xA => "EtherCAT state machine",
            0xF => "additional functions",
            _ => "unknown class",
        },
    }
}

/// A CoE emergency (service 1): error code, error register, 5 manufacturer bytes.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct Emergency {
    pub error_code: u16,
    pub error_register: u8,
    pub data: [u8; 5],
}

impl Emergency {
    pub const LEN: usize = 8;
    pub fn parse(body: &[u8]) -> Result<Self> {
        need(body, 0, Self::LEN, "CoE emergency")?;
        use field::emergency as f;
        let mut data = [0; 5];
        data.copy_from_slice(&body[f::DATA]);
        Ok(Emergency { error_code: u16_at(body, f::ERROR_CODE, "")?, error_register: body[f::ERROR_REGISTER], data })
    }
    pub fn to_bytes(&self) -> [u8; 8] {
        use field::emergency as f;
        let mut b = [0u8; Self::LEN];
        b[f::ERROR_CODE..f::ERROR_REGISTER].copy_from_slice(&self.error_code.to_le_bytes());
        b[f::ERROR_REGISTER] = self.error_register;
        b[f::DATA].copy_from_slice(&self.data);
        b
    }
}

/// SDO information opcodes (header byte 0, bits 6:0).
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash)]
pub struct InfoOpcode(pub u8);

impl InfoOpcode {
    pub const GET_OD_LIST_REQUEST: Self = Self(1);
    pub const GET_OD_LIST_RESPONSE: Self = Self(2);
    pub const GET_OBJECT_DESCRIPTION_REQUEST: Self = Self(3);
    pub const GET_OBJECT_DESCRIPTION_RESPONSE: Self = Self(4);
    pub const GET_ENTRY_DESCRIPTION_REQUEST: Self = Self(5);
    pub const GET_ENTRY_DESCRIPTION_RESPONSE: Self = Self(6);
    pub const ERROR_REQUEST: Self = Self(7);
}

/// The 4-byte SDO information header.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct InfoHeader {
    pub opcode: InfoOpcode,
    pub incomplete: bool,
    pub reserved: u8,
    pub fragments_left: u16,
}

impl InfoHeader {
    pub const LEN: usize = 4;
    pub fn parse(b: &[u8]) -> Result<Self> {
        need(b, 0, Self::LEN, "SDO information header")?;
        use field::info;
        Ok(InfoHeader {
            opcode: InfoOpcode(b[info::OPCODE] & 0x7F),
            incomplete: b[info::OPCODE] & 0x80 != 0,
            reserved: b[info::RESERVED],
            fragments_left: u16_at(b, info::FRAGMENTS_LEFT, "")?,
        })
    }
    pub fn to_bytes(&self) -> [u8; 4] {
        use field::info;
        let mut b = [0u8; Self::LEN];
        b[info::OPCODE] = self.opcode.0 | if self.incomplete { 0x80 } else { 0 };
        b[info::RESERVED] = self.reserved;
        b[info::FRAGMENTS_LEFT..].copy_from_slice(&self.fragments_left.to_le_bytes());
        b
    }
}

/// An SDO information service frame (after the CoE header).
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum SdoInfo<'a> {
    /// List type: 0 counts per type, 1 all objects, 2 RxPDO-mappable, 3 TxPDO-mappable, 4 backup, 5 settings.
    OdListRequest {
        header: InfoHeader,
        list_type: u16,
    },
    /// A fragment of the list: the first fragment starts with the list type, then u16 indices.
    OdListResponse {
        header: InfoHeader,
        data: &'a [u8],
    },
    ObjectDescriptionRequest {
        header: InfoHeader,
        index: u16,
    },
    ObjectDescriptionResponse {
        header: InfoHeader,
        index: u16,
        data_type: u16,
        max_subindex: u8,
        object_code: u8,
        name: &'a [u8],
    },
    EntryDescriptionRequest {
        header: InfoHeader,
        index: u16,
        subindex: u8,
        value_info: u8,
    },
    /// `rest` holds the optional value fields selected by `value_info`, then the name.
    EntryDescriptionResponse {
        header: InfoHeader,
        index: u16,
        subindex: u8,
        value_info: u8,
        data_type: u16,
        bit_length: u16,
        object_access: u16,
        rest: &'a [u8],
    },
    Error {
        header: InfoHeader,
        code: AbortCode,
    },
}

impl<'a> SdoInfo<'a> {
    pub fn parse(body: &'a [u8]) -> Result<Self> {
        let header = InfoHeader::parse(body)?;
        let b = &body[InfoHeader::LEN..];
        let sh = |e: Error| e.shifted(InfoHeader::LEN);
        use field::info as f;
        Ok(match header.opcode {
            InfoOpcode::GET_OD_LIST_REQUEST => {
                SdoInfo::OdListRequest { header, list_type: u16_at(b, 0, "OD list type").map_err(sh)? }
            }
            InfoOpcode::GET_OD_LIST_RESPONSE => SdoInfo::OdListResponse { header, data: b },
            InfoOpcode::GET_OBJECT_DESCRIPTION_REQUEST => {
                SdoInfo::ObjectDescriptionRequest { header, index: u16_at(b, 0, "object index").map_err(sh)? }
            }
            InfoOpcode::GET_OBJECT_DESCRIPTION_RESPONSE => {
                need(b, 0, f::OBJECT_NAME, "object description").map_err(sh)?;
                SdoInfo::ObjectDescriptionResponse {
                    header,
                    index: u16_at(b, f::INDEX, "")?,
                    data_type: u16_at(b, f::OBJECT_DATA_TYPE, "")?,
                    max_subindex: b[f::MAX_SUBINDEX],
                    object_code: b[f::OBJECT_CODE],
                    name: &b[f::OBJECT_NAME..],
                }
            }
            InfoOpcode::GET_ENTRY_DESCRIPTION_REQUEST => {
                need(b, 0, f::VALUE_INFO + 1, "entry description request").map_err(sh)?;
                SdoInfo::EntryDescriptionRequest {
                    header,
                    index: u16_at(b, f::INDEX, "")?,
                    subindex: b[f::ENTRY_SUBINDEX],
                    value_info: b[f::VALUE_INFO],
                }
            }
            InfoOpcode::GET_ENTRY_DESCRIPTION_RESPONSE => {
                need(b, 0, f::ENTRY_REST, "entry description").map_err(sh)?;
                SdoInfo::EntryDescriptionResponse {
                    header,
                    index: u16_at(b, f::INDEX, "")?,
                    subindex: b[f::ENTRY_SUBINDEX],
                    value_info: b[f::VALUE_INFO],
                    data_type: u16_at(b, f::ENTRY_DATA_TYPE, "")?,
                    bit_length: u16_at(b, f::BIT_LENGTH, "")?,
                    object_access: u16_at(b, f::OBJECT_ACCESS, "")?,
                    rest: &b[f::ENTRY_REST..],
                }
            }
            InfoOpcode::ERROR_REQUEST => {
                SdoInfo::Error { header, code: AbortCode(u32_at(b, 0, "SDO info abort code").map_err(sh)?) }
            }
            other => return Err(Error::BadValue { what: "SDO information opcode", offset: 0, value: other.0 as u32 }),
        })
    }

    pub fn header(&self) -> &InfoHeader {
        match self {
            SdoInfo::OdListRequest { header, .. }
            | SdoInfo::OdListResponse { header, .. }
            | SdoInfo::ObjectDescriptionRequest { header, .. }
            | SdoInfo::ObjectDescriptionResponse { header, .. }
            | SdoInfo::EntryDescriptionRequest { header, .. }
            | SdoInfo::EntryDescriptionResponse { header, .. }
            | SdoInfo::Error { header, .. } => header,
        }
    }

    pub fn emit(&self, out: &mut [u8]) -> Result<usize> {
        put(out, 0, &self.header().to_bytes(), "SDO information header")?;
        let o = InfoHeader::LEN;
        let mut n = o;
        let mut w = |bytes: &[u8]| -> Result<()> {
            put(out, n, bytes, "SDO information")?;
            n += bytes.len();
            Ok(())
        };
        match *self {
            SdoInfo::OdListRequest { list_type, .. } => w(&list_type.to_le_bytes())?,
            SdoInfo::OdListResponse { data, .. } => w(data)?,
            SdoInfo::ObjectDescriptionRequest { index, .. } => w(&index.to_le_bytes())?,
            SdoInfo::ObjectDescriptionResponse { index, data_type, max_subindex, object_code, name, .. } => {
                w(&index.to_le_bytes())?;
                w(&data_type.to_le_bytes())?;
                w(&[max_subindex, object_code])?;
                w(name)?;
            }
            SdoInfo::EntryDescriptionRequest { index, subindex, value_info, .. } => {
                w(&index.to_le_bytes())?;
                w(&[subindex, value_info])?;
            }
            SdoInfo::EntryDescriptionResponse {
                index,
                subindex,
                value_info,
                data_type,
                bit_length,
                object_access,
                rest,
                ..
            } => {
                w(&index.to_le_bytes())?;
                w(&[subindex, value_info])?;
                w(&data_type.to_le_bytes())?;
                w(&bit_length.to_le_bytes())?;
                w(&object_access.to_le_bytes())?;
                w(rest)?;
            }
            SdoInfo::Error { code, .. } => w(&code.0.to_le_bytes())?,
        }
        Ok(n)
    }
}

/// A whole CoE message after the mailbox header.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum CoeMessage<'a> {
    Sdo(Sdo<'a>),
    Emergency(Emergency),
    Information(SdoInfo<'a>),
    /// PDO services and anything else: kept raw.
    Other(&'a [u8]),
}

/// Parses a CoE mailbox payload (CoE header and body).
pub fn parse(payload: &[u8]) -> Result<(CoeHeader, CoeMessage<'_>)> {
    let header = CoeHeader::parse(payload)?;
    let body = &payload[HEADER_LEN..];
    let shift = |e: Error| e.shifted(HEADER_LEN);
    let msg = match header.service {
        CoeService::SDO_REQUEST | CoeService::SDO_RESPONSE => {
            CoeMessage::Sdo(Sdo::parse(header.service, body).map_err(shift)?)
        }
        CoeService::EMERGENCY => CoeMessage::Emergency(Emergency::parse(body).map_err(shift)?),
        CoeService::SDO_INFORMATION => CoeMessage::Information(SdoInfo::parse(body).map_err(shift)?),
        _ => CoeMessage::Other(body),
    };
    Ok((header, msg))
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn emergency_codes_in_words_exact_then_by_class() {
        assert_eq!(emergency_text(0x8611), "following error");
        assert_eq!(emergency_text(0x2310), "continuous over-current");
        assert_eq!(emergency_text(0x2311), "current, output side");
        assert_eq!(emergency_text(0x4999), "temperature");
        assert_eq!(emergency_text(0xFF42), "device specific");
        assert_eq!(emergency_text(0xA001), "transition SAFEOP to OP failed");
        assert_eq!(emergency_text(0xB000), "unknown class");
    }

    fn rt(sdo: Sdo<'_>) {
        let mut buf = [0u8; 64];
        let n = sdo.emit(&mut buf).unwrap();
        assert_eq!(Sdo::parse(sdo.service(), &buf[..n]).unwrap(), sdo);
    }

    #[test]
    fn sdo_command_bytes_match_the_spec_table() {
        // esc-spec §6.3: expedited download of 1..4 bytes = 0x2F/0x2B/0x27/0x23, CA adds 0x10.
        let mut buf = [0u8; 16];
        for (size, cmd) in [(1, 0x2F), (2, 0x2B), (3, 0x27), (4, 0x23)] {
            Sdo::DownloadExpeditedRequest {
                index: 0x6040,
                subindex: 0,
                complete_access: false,
                size: Some(size),
                data: [0; 4],
            }
            .emit(&mut buf)
            .unwrap();
            assert_eq!(buf[0], cmd);
        }
        Sdo::UploadRequest { index: 0x1C12, subindex: 0, complete_access: true, reserved: [0; 4] }
            .emit(&mut buf)
            .unwrap();
        assert_eq!(buf[0], 0x50);
        Sdo::DownloadNormalRequest {
            index: 0x1C12,
            subindex: 0,
            complete_access: true,
            complete_size: 4,
            data: &[1, 2, 3, 4],
        }
        .emit(&mut buf)
        .unwrap();
        assert_eq!(buf[0], 0x31);
        Sdo::UploadSegmentRequest { toggle: true, reserved: [0; 7] }.emit(&mut buf).unwrap();
        assert_eq!(buf[0], 0x70);
        Sdo::Abort { index: 1, subindex: 2, code: AbortCode::NO_OBJECT }.emit(&mut buf).unwrap();
        assert_eq!(buf[..8], [0x80, 1, 0, 2, 0, 0, 2, 6]);
    }

    #[test]
    fn round_trips() {
        rt(Sdo::UploadExpeditedResponse {
            index: 0x1000,
            subindex: 0,
            complete_access: false,
            size: Some(4),
            data: [1, 2, 3, 4],
        });
        rt(Sdo::UploadNormalResponse {
            index: 0x1008,
            subindex: 0,
            complete_access: false,
            complete_size: 40,
            data: b"EL2004 long name",
        });
        rt(Sdo::UploadSegmentResponse { toggle: true, last: true, unused: 4, segment: &[1, 2, 3, 0, 0, 0, 0] });
        rt(Sdo::DownloadSegmentRequest { toggle: false, last: false, unused: 0, segment: &[9; 20] });
        rt(Sdo::DownloadSegmentResponse { toggle: true, reserved: [0; 7] });
        rt(Sdo::DownloadResponse { index: 0x1C12, subindex: 0, complete_access: true, reserved: [0; 4] });
        let s = Sdo::UploadSegmentResponse { toggle: false, last: true, unused: 5, segment: &[7, 8, 0, 0, 0, 0, 0] };
        assert_eq!(s.segment_data(), Some(&[7u8, 8][..]));
    }

    #[test]
    fn malformed_sdo_frames_are_errors() {
        assert!(Sdo::parse(CoeService::SDO_REQUEST, &[]).is_err());
        assert!(Sdo::parse(CoeService::SDO_RESPONSE, &[0x43, 0, 0x10]).is_err());
        assert!(Sdo::parse(CoeService::SDO_REQUEST, &[0xE0, 0, 0, 0, 0, 0, 0, 0]).is_err());
        assert!(Sdo::parse(CoeService::EMERGENCY, &[0x40, 0, 0, 0, 0, 0, 0, 0]).is_err());
        // Segment with more than 7 bytes must not claim unused bytes.
        assert!(Sdo::parse(CoeService::SDO_RESPONSE, &[0x03, 1, 2, 3, 4, 5, 6, 7, 8]).is_err());
    }

    #[test]
    fn info_and_emergency() {
        let h = InfoHeader {
            opcode: InfoOpcode::GET_OBJECT_DESCRIPTION_RESPONSE,
            incomplete: false,
            reserved: 0,
            fragments_left: 0,
        };
        let m = SdoInfo::ObjectDescriptionResponse {
            header: h,
            index: 0x1018,
            data_type: 0x23,
            max_subindex: 4,
            object_code: 9,
            name: b"Identity",
        };
        let mut buf = [0u8; 64];
        let n = m.emit(&mut buf).unwrap();
        assert_eq!(SdoInfo::parse(&buf[..n]).unwrap(), m);
        let e = Emergency { error_code: 0x8700, error_register: 0x11, data: [1, 2, 3, 4, 5] };
        assert_eq!(Emergency::parse(&e.to_bytes()).unwrap(), e);
        assert_eq!(AbortCode(0x0602_0000).name(), Some("The object does not exist in the object dictionary"));
    }
}
