//! Ethernet over EtherCAT (EoE, mailbox type 2; ETG.1000.6 §5.5): the service data after the
//! mailbox header. An Ethernet frame travels as numbered fragments, each in one mailbox
//! message; the other frame types set and read a device's IP parameters and address filter.
//!
//! The header is two little-endian words. Word 0: frame type (bits 0–3), port (4–7), last
//! fragment (8), time appended (9), time requested (10). Word 1 of a fragment: fragment
//! number (bits 0–5), then (bits 6–11) the frame's buffer size in 32-byte units in fragment 0
//! and the fragment's offset in 32-byte units in the others, then the frame number (12–15); in
//! a response, word 1 is the result.
use core::fmt;

use crate::bytes::{need, put, slice_at, u16_at, u32_at};
use crate::{Error, Result};

pub const HEADER_LEN: usize = 4;
/// Fragments other than the last carry a multiple of this many bytes (offsets count in it).
pub const FRAGMENT_UNIT: usize = 32;
/// The longest frame a 6-bit count of 32-byte units describes.
pub const MAX_FRAME_LEN: usize = 63 * FRAGMENT_UNIT;
/// A DNS name field's fixed length (ETG.1000.6).
pub const DNS_NAME_LEN: usize = 32;
/// The IP parameter block: flags, MAC, IP, subnet mask, gateway, DNS server, DNS name — each
/// at a fixed place whether its flag is set or not (TwinCAT's request to the AKD in
/// twincat-akd-nc-mode carries all six in these 58 bytes).
pub const IP_PARAMETERS_LEN: usize = 4 + 6 + 4 * 4 + DNS_NAME_LEN;

pub mod frame_type {
    pub const FRAGMENT: u8 = 0;
    pub const TIMESTAMP: u8 = 1;
    pub const SET_IP_REQUEST: u8 = 2;
    pub const SET_IP_RESPONSE: u8 = 3;
    pub const SET_FILTER_REQUEST: u8 = 4;
    pub const SET_FILTER_RESPONSE: u8 = 5;
    pub const GET_IP_REQUEST: u8 = 6;
    pub const GET_IP_RESPONSE: u8 = 7;
    pub const GET_FILTER_REQUEST: u8 = 8;
    pub const GET_FILTER_RESPONSE: u8 = 9;
}

/// The result word of an EoE response (ETG.1000.6).
#[derive(Clone, Copy, PartialEq, Eq, Hash)]
pub struct EoeResult(pub u16);

impl EoeResult {
    pub const SUCCESS: Self = Self(0x0000);
    pub const UNSPECIFIED_ERROR: Self = Self(0x0001);
    pub const UNSUPPORTED_FRAME_TYPE: Self = Self(0x0002);
    pub const NO_IP_SUPPORT: Self = Self(0x0201);
    pub const NO_DHCP_SUPPORT: Self = Self(0x0202);
    pub const NO_FILTER_SUPPORT: Self = Self(0x0401);

    pub fn name(self) -> Option<&'static str> {
        Some(match self.0 {
            0x0000 => "success",
            0x0001 => "unspecified error",
            0x0002 => "unsupported frame type",
            0x0201 => "no IP support",
            0x0202 => "DHCP not supported",
            0x0401 => "no filter support",
            _ => return None,
        })
    }
}

impl fmt::Debug for EoeResult {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        write!(f, "EoeResult({:#06x})", self.0)
    }
}

impl fmt::Display for EoeResult {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        match self.name() {
            Some(n) => write!(f, "{:#06x} ({n})", self.0),
            None => write!(f, "{:#06x}", self.0),
        }
    }
}

#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct EoeHeader {
    pub frame_type: u8,
    pub port: u8,
    pub last_fragment: bool,
    pub time_appended: bool,
    pub time_requested: bool,
    /// Word 1: the fragment fields, or a response's result.
    pub info: u16,
}

impl EoeHeader {
    /// A header of `frame_type` whose word 1 is `info` (0 for requests).
    pub fn new(frame_type: u8, info: u16) -> Self {
        EoeHeader { frame_type, port: 0, last_fragment: false, time_appended: false, time_requested: false, info }
    }

    /// Fragment `fragment` of frame `frame_number` (mod 16); `units` is the buffer size
    /// (fragment 0) or the offset (the others) in 32-byte units.
    pub fn fragment(fragment: u8, units: u8, frame_number: u8, last: bool) -> Self {
        let info = (fragment as u16 & 0x3F) | ((units as u16 & 0x3F) << 6) | ((frame_number as u16 & 0xF) << 12);
        EoeHeader { last_fragment: last, ..EoeHeader::new(frame_type::FRAGMENT, info) }
    }

    pub fn fragment_number(&self) -> u8 {
        (self.info & 0x3F) as u8
    }

    /// Buffer size (fragment 0) or offset (the others), in 32-byte units.
    pub fn units(&self) -> u8 {
        ((self.info >> 6) & 0x3F) as u8
    }

    pub fn frame_number(&self) -> u8 {
        (self.info >> 12) as u8
    }

    pub fn result(&self) -> EoeResult {
        EoeResult(self.info)
    }

    pub fn parse(buf: &[u8]) -> Result<Self> {
        let w0 = u16_at(buf, 0, "EoE header")?;
        let info = u16_at(buf, 2, "EoE header")?;
        Ok(EoeHeader {
            frame_type: (w0 & 0xF) as u8,
            port: ((w0 >> 4) & 0xF) as u8,
            last_fragment: w0 & 0x100 != 0,
            time_appended: w0 & 0x200 != 0,
            time_requested: w0 & 0x400 != 0,
            info,
        })
    }

    pub fn to_bytes(&self) -> [u8; HEADER_LEN] {
        let w0 = (self.frame_type as u16 & 0xF)
            | ((self.port as u16 & 0xF) << 4)
            | ((self.last_fragment as u16) << 8)
            | ((self.time_appended as u16) << 9)
            | ((self.time_requested as u16) << 10);
        let [a, b] = w0.to_le_bytes();
        let [c, d] = self.info.to_le_bytes();
        [a, b, c, d]
    }

    pub fn emit(&self, out: &mut [u8]) -> Result<()> {
        put(out, 0, &self.to_bytes(), "EoE header")
    }
}

/// A device's IP parameters as Set IP Parameter carries them (and Get IP Parameter returns
/// them): each present where its flag is. Addresses in network order (192.168.0.1 is
/// `[192, 168, 0, 1]`); on the wire they are little-endian 32-bit words, the bytes reversed.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
pub struct IpParameters {
    pub mac: Option<[u8; 6]>,
    pub ip: Option<[u8; 4]>,
    pub subnet_mask: Option<[u8; 4]>,
    pub gateway: Option<[u8; 4]>,
    pub dns_server: Option<[u8; 4]>,
    /// Up to 32 bytes; shorter names end at the first zero.
    pub dns_name: Option<[u8; DNS_NAME_LEN]>,
}

mod flag {
    pub const MAC: u32 = 1 << 0;
    pub const IP: u32 = 1 << 1;
    pub const SUBNET: u32 = 1 << 2;
    pub const GATEWAY: u32 = 1 << 3;
    pub const DNS_SERVER: u32 = 1 << 4;
    pub const DNS_NAME: u32 = 1 << 5;
}

fn ip_at(buf: &[u8], offset: usize) -> Result<[u8; 4]> {
    let [a, b, c, d] = u32_at(buf, offset, "EoE IP parameter")?.to_le_bytes();
    Ok([d, c, b, a])
}

impl IpParameters {
    /// The DNS name up to its first zero.
    pub fn dns_name_bytes(&self) -> Option<&[u8]> {
        self.dns_name.as_ref().map(|n| &n[..n.iter().position(|&b| b == 0).unwrap_or(DNS_NAME_LEN)])
    }

    /// `name` as the fixed field, or an error if it is longer than 32 bytes.
    pub fn dns_name_field(name: &[u8]) -> Result<[u8; DNS_NAME_LEN]> {
        let mut f = [0u8; DNS_NAME_LEN];
        put(&mut f, 0, name, "EoE DNS name (32 bytes at most)")?;
        Ok(f)
    }

    /// Parses the parameter block after the EoE header. A block that ends before a field its
    /// flags name is an error; fields whose flag is clear are ignored.
    pub fn parse(buf: &[u8]) -> Result<Self> {
        let flags = u32_at(buf, 0, "EoE IP parameter flags")?;
        let has = |f: u32| flags & f != 0;
        let mut p = IpParameters::default();
        if has(flag::MAC) {
            let s = slice_at(buf, 4, 6, "EoE MAC address")?;
            p.mac = Some([s[0], s[1], s[2], s[3], s[4], s[5]]);
        }
        for (f, offset, field) in [
            (flag::IP, 10, &mut p.ip),
            (flag::SUBNET, 14, &mut p.subnet_mask),
            (flag::GATEWAY, 18, &mut p.gateway),
            (flag::DNS_SERVER, 22, &mut p.dns_server),
        ] {
            if has(f) {
                *field = Some(ip_at(buf, offset)?);
            }
        }
        if has(flag::DNS_NAME) {
            let s = slice_at(buf, 26, DNS_NAME_LEN, "EoE DNS name")?;
            let mut n = [0u8; DNS_NAME_LEN];
            n.copy_from_slice(s);
            p.dns_name = Some(n);
        }
        Ok(p)
    }

    fn flags(&self) -> u32 {
        [
            (self.mac.is_some(), flag::MAC),
            (self.ip.is_some(), flag::IP),
            (self.subnet_mask.is_some(), flag::SUBNET),
            (self.gateway.is_some(), flag::GATEWAY),
            (self.dns_server.is_some(), flag::DNS_SERVER),
            (self.dns_name.is_some(), flag::DNS_NAME),
        ]
        .iter()
        .filter(|(set, _)| *set)
        .fold(0, |acc, (_, f)| acc | f)
    }

    /// Emits the whole block (58 bytes), absent fields zero.
    pub fn emit(&self, out: &mut [u8]) -> Result<usize> {
        need(out, 0, IP_PARAMETERS_LEN, "EoE IP parameters").map_err(|_| Error::BufferTooSmall {
            what: "EoE IP parameters",
            needed: IP_PARAMETERS_LEN,
            available: out.len(),
        })?;
        out[..IP_PARAMETERS_LEN].fill(0);
        out[0..4].copy_from_slice(&self.flags().to_le_bytes());
        out[4..10].copy_from_slice(&self.mac.unwrap_or_default());
        for (offset, field) in [(10, self.ip), (14, self.subnet_mask), (18, self.gateway), (22, self.dns_server)] {
            let [a, b, c, d] = field.unwrap_or_default();
            out[offset..offset + 4].copy_from_slice(&[d, c, b, a]);
        }
        out[26..26 + DNS_NAME_LEN].copy_from_slice(&self.dns_name.unwrap_or_default());
        Ok(IP_PARAMETERS_LEN)
    }
}

/// How many frame bytes fit one fragment's service data of `max_len` bytes (the mailbox
/// less its header): a multiple of 32, as offsets count in 32-byte units.
pub fn fragment_capacity(max_len: usize) -> usize {
    max_len.saturating_sub(HEADER_LEN) / FRAGMENT_UNIT * FRAGMENT_UNIT
}

/// The fragments of `frame` for service data of at most `max_len` bytes each: their headers
/// and the frame's bytes each carries. `None` where the frame is empty or longer than 2 016
/// bytes, or where the mailbox cannot carry 32 bytes.
pub fn fragments(frame: &[u8], max_len: usize, frame_number: u8) -> Option<impl Iterator<Item = (EoeHeader, &[u8])>> {
    let cap = fragment_capacity(max_len);
    if frame.is_empty() || frame.len() > MAX_FRAME_LEN || cap == 0 {
        return None;
    }
    let n = frame.len().div_ceil(cap);
    Some((0..n).map(move |k| {
        let start = k * cap;
        let end = (start + cap).min(frame.len());
        let units = if k == 0 { frame.len().div_ceil(FRAGMENT_UNIT) } else { start / FRAGMENT_UNIT };
        (EoeHeader::fragment(k as u8, units as u8, frame_number, k + 1 == n), &frame[start..end])
    }))
}

/// [`fragments`] as the service data of one mailbox message each (EoE header, then data).
#[cfg(feature = "alloc")]
pub fn fragment_messages(
    frame: &[u8],
    max_len: usize,
    frame_number: u8,
) -> Option<alloc::vec::Vec<alloc::vec::Vec<u8>>> {
    let parts = fragments(frame, max_len, frame_number)?;
    Some(
        parts
            .map(|(h, d)| {
                let mut v = alloc::vec::Vec::with_capacity(HEADER_LEN + d.len());
                v.extend_from_slice(&h.to_bytes());
                v.extend_from_slice(d);
                v
            })
            .collect(),
    )
}

/// Why a fragment did not fit the frame being put together.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum ReassemblyError {
    /// A fragment other than 0 with no frame started (or after one was dropped).
    NoFrame { fragment: u8 },
    /// A fragment out of order, of another frame, or at another offset than the bytes so far.
    OutOfSequence { expected: u8, got: u8, frame_number: u8 },
    /// More bytes than the frame's announced buffer (or than any frame may have).
    TooLong { announced: usize, got: usize },
    /// A fragment with a time stamp appended shorter than the stamp.
    ShortTimestamp,
}

impl fmt::Display for ReassemblyError {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        match self {
            ReassemblyError::NoFrame { fragment } => write!(f, "EoE fragment {fragment} with no frame begun"),
            ReassemblyError::OutOfSequence { expected, got, frame_number } => {
                write!(f, "EoE fragment {got} of frame {frame_number} where fragment {expected} was expected")
            }
            ReassemblyError::TooLong { announced, got } => {
                write!(f, "EoE frame of {got} bytes exceeds its announced {announced}")
            }
            ReassemblyError::ShortTimestamp => write!(f, "EoE fragment too short for its appended time stamp"),
        }
    }
}

/// Puts fragments back together into a frame (no allocation: one 2 016-byte buffer).
#[derive(Clone)]
pub struct Reassembler {
    buf: [u8; MAX_FRAME_LEN],
    len: usize,
    announced: usize,
    next: u8,
    frame_number: u8,
    active: bool,
}

impl fmt::Debug for Reassembler {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        f.debug_struct("Reassembler")
            .field("len", &self.len)
            .field("next", &self.next)
            .field("active", &self.active)
            .finish()
    }
}

impl Default for Reassembler {
    fn default() -> Self {
        Reassembler { buf: [0; MAX_FRAME_LEN], len: 0, announced: 0, next: 0, frame_number: 0, active: false }
    }
}

/// A frame put back together, and the DC time stamp its last fragment carried, if any.
#[derive(Debug, PartialEq, Eq)]
pub struct Reassembled<'a> {
    pub frame: &'a [u8],
    pub time_stamp: Option<u32>,
}

impl Reassembler {
    /// Takes one fragment (`data`: the service data after the EoE header). Returns the frame
    /// when this was its last fragment. A fragment that does not fit drops the frame begun
    /// and is an error; fragment 0 always begins a new frame.
    pub fn push(
        &mut self,
        h: &EoeHeader,
        data: &[u8],
    ) -> core::result::Result<Option<Reassembled<'_>>, ReassemblyError> {
        let (data, time_stamp) = if h.last_fragment && h.time_appended {
            let Some(split) = data.len().checked_sub(4) else {
                self.active = false;
                return Err(ReassemblyError::ShortTimestamp);
            };
            let t = &data[split..];
            (&data[..split], Some(u32::from_le_bytes([t[0], t[1], t[2], t[3]])))
        } else {
            (data, None)
        };
        if h.fragment_number() == 0 {
            self.active = true;
            self.len = 0;
            self.next = 0;
            self.frame_number = h.frame_number();
            self.announced = h.units() as usize * FRAGMENT_UNIT;
        } else if !self.active {
            return Err(ReassemblyError::NoFrame { fragment: h.fragment_number() });
        } else if h.fragment_number() != self.next
            || h.frame_number() != self.frame_number
            || h.units() as usize * FRAGMENT_UNIT != self.len
        {
            self.active = false;
            return Err(ReassemblyError::OutOfSequence {
                expected: self.next,
                got: h.fragment_number(),
                frame_number: h.frame_number(),
            });
        }
        let end = self.len + data.len();
        // Fragment 0 announces the buffer (at most 63 units); a frame may not outgrow it.
        if end > self.announced {
            self.active = false;
            return Err(ReassemblyError::TooLong { announced: self.announced, got: end });
        }
        self.buf[self.len..end].copy_from_slice(data);
        self.len = end;
        self.next = self.next.wrapping_add(1) & 0x3F;
        if h.last_fragment {
            self.active = false;
            return Ok(Some(Reassembled { frame: &self.buf[..self.len], time_stamp }));
        }
        Ok(None)
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn twincats_set_ip_request_to_the_akd() {
        // twincat-akd-nc-mode frame 3371, after the mailbox header.
        let mut b = [0u8; 4 + IP_PARAMETERS_LEN];
        b[..4].copy_from_slice(&[0x02, 0, 0, 0]);
        b[4..8].copy_from_slice(&[0x3f, 0, 0, 0]);
        b[8..14].copy_from_slice(&[0x02, 0x01, 0x05, 0x30, 0x03, 0xe9]);
        b[14..30].copy_from_slice(&[0, 0, 0xa8, 0xc0, 0, 0xff, 0xff, 0xff, 0x8b, 0, 0xa8, 0xc0, 0, 0, 0, 0]);
        b[30..43].copy_from_slice(b"Drive_1__AKD_");
        let h = EoeHeader::parse(&b).unwrap();
        assert_eq!(h, EoeHeader::new(frame_type::SET_IP_REQUEST, 0));
        let p = IpParameters::parse(&b[4..]).unwrap();
        assert_eq!(p.mac, Some([0x02, 0x01, 0x05, 0x30, 0x03, 0xe9]));
        assert_eq!(p.ip, Some([192, 168, 0, 0]));
        assert_eq!(p.subnet_mask, Some([255, 255, 255, 0]));
        assert_eq!(p.gateway, Some([192, 168, 0, 139]));
        assert_eq!(p.dns_server, Some([0, 0, 0, 0]));
        assert_eq!(p.dns_name_bytes(), Some(&b"Drive_1__AKD_"[..]));
        let mut out = [0u8; IP_PARAMETERS_LEN];
        p.emit(&mut out).unwrap();
        assert_eq!(out[..], b[4..]);
    }

    #[test]
    fn the_akds_arp_fragment_header() {
        // twincat-akd-nc-mode frames 3386 and 9271: a 42-byte frame in one fragment.
        assert_eq!(EoeHeader::fragment(0, 2, 0, true).to_bytes(), [0x00, 0x01, 0x80, 0x00]);
        assert_eq!(EoeHeader::fragment(0, 2, 1, true).to_bytes(), [0x00, 0x01, 0x80, 0x10]);
    }

    #[test]
    fn fields_past_the_end_are_errors_and_clear_flags_are_ignored() {
        let only_ip = IpParameters { ip: Some([10, 0, 0, 2]), ..Default::default() };
        let mut out = [0u8; IP_PARAMETERS_LEN];
        only_ip.emit(&mut out).unwrap();
        assert_eq!(IpParameters::parse(&out).unwrap(), only_ip);
        assert!(matches!(IpParameters::parse(&out[..13]), Err(Error::Truncated { .. })));
        assert!(IpParameters::parse(&out[..14]).is_ok());
        assert!(IpParameters::dns_name_field(&[b'x'; 33]).is_err());
    }

    #[test]
    fn fragments_reassemble_and_disorder_is_an_error() {
        let frame: [u8; 100] = core::array::from_fn(|i| i as u8);
        // A 64-byte mailbox less its 6-byte header: 58 bytes of service data, 32 frame bytes each.
        let parts: [_; 4] = {
            let mut it = fragments(&frame, 58, 3).unwrap();
            core::array::from_fn(|_| it.next().unwrap())
        };
        assert_eq!(parts[0].0.units(), 4);
        assert_eq!(parts[3].1.len(), 4);
        assert!(parts[3].0.last_fragment);
        let mut r = Reassembler::default();
        for (h, d) in &parts[..3] {
            assert_eq!(r.push(h, d), Ok(None));
        }
        assert_eq!(r.push(&parts[3].0, parts[3].1).unwrap().unwrap().frame, &frame[..]);
        // Fragment 2 before 1.
        r.push(&parts[0].0, parts[0].1).unwrap();
        assert!(matches!(r.push(&parts[2].0, parts[2].1), Err(ReassemblyError::OutOfSequence { .. })));
        assert_eq!(r.push(&parts[1].0, parts[1].1), Err(ReassemblyError::NoFrame { fragment: 1 }));
        assert!(fragments(&frame, 35, 0).is_none());
        assert!(fragments(&[0; MAX_FRAME_LEN + 1], 1000, 0).is_none());
    }
}
