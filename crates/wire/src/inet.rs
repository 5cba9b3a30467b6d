//! ARP (RFC 826, Ethernet/IPv4 only) and ICMP echo (RFC 792): what a master pings an EoE
//! device with and what the device's small IP stack answers.
use crate::bytes::{need, slice_at};
use crate::{Error, Result};

pub const ETHERTYPE_ARP: u16 = 0x0806;
pub const IP_PROTO_ICMP: u8 = 1;
pub const ARP_LEN: usize = 28;
pub const ARP_REQUEST: u16 = 1;
pub const ARP_REPLY: u16 = 2;
pub const ICMP_ECHO_REPLY: u8 = 0;
pub const ICMP_ECHO_REQUEST: u8 = 8;

/// The Internet checksum (RFC 1071) of `data`: the ones' complement of the ones' complement
/// sum of its 16-bit big-endian words, an odd last byte padded with zero.
pub fn checksum(data: &[u8]) -> u16 {
    let mut sum: u32 = data.chunks(2).map(|c| u16::from_be_bytes([c[0], *c.get(1).unwrap_or(&0)]) as u32).sum();
    while sum > 0xFFFF {
        sum = (sum & 0xFFFF) + (sum >> 16);
    }
    !(sum as u16)
}

#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct ArpRepr {
    pub operation: u16,
    pub sender_mac: [u8; 6],
    pub sender_ip: [u8; 4],
    pub target_mac: [u8; 6],
    pub target_ip: [u8; 4],
}

impl ArpRepr {
    /// Parses an ARP packet for Ethernet and IPv4; other hardware or protocol types are errors.
    pub fn parse(buf: &[u8]) -> Result<Self> {
        need(buf, 0, ARP_LEN, "ARP packet")?;
        let be = |o: usize| u16::from_be_bytes([buf[o], buf[o + 1]]);
        if be(0) != 1 || be(2) != crate::ETHERTYPE_IPV4 || buf[4] != 6 || buf[5] != 4 {
            return Err(Error::BadValue { what: "ARP hardware/protocol type", offset: 0, value: be(0) as u32 });
        }
        let mac = |o: usize| -> [u8; 6] { core::array::from_fn(|i| buf[o + i]) };
        let ip = |o: usize| -> [u8; 4] { core::array::from_fn(|i| buf[o + i]) };
        Ok(ArpRepr { operation: be(6), sender_mac: mac(8), sender_ip: ip(14), target_mac: mac(18), target_ip: ip(24) })
    }

    pub fn emit(&self, out: &mut [u8]) -> Result<usize> {
        if out.len() < ARP_LEN {
            return Err(Error::BufferTooSmall { what: "ARP packet", needed: ARP_LEN, available: out.len() });
        }
        out[0..2].copy_from_slice(&1u16.to_be_bytes());
        out[2..4].copy_from_slice(&crate::ETHERTYPE_IPV4.to_be_bytes());
        out[4] = 6;
        out[5] = 4;
        out[6..8].copy_from_slice(&self.operation.to_be_bytes());
        out[8..14].copy_from_slice(&self.sender_mac);
        out[14..18].copy_from_slice(&self.sender_ip);
        out[18..24].copy_from_slice(&self.target_mac);
        out[24..28].copy_from_slice(&self.target_ip);
        Ok(ARP_LEN)
    }
}

/// An ICMP echo request or reply: identifier, sequence number and the data echoed.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct IcmpEcho<'a> {
    pub reply: bool,
    pub ident: u16,
    pub seq: u16,
    pub data: &'a [u8],
}

impl<'a> IcmpEcho<'a> {
    /// Parses an echo request or reply and checks its checksum.
    pub fn parse(buf: &'a [u8]) -> Result<Self> {
        need(buf, 0, 8, "ICMP echo header")?;
        let reply = match (buf[0], buf[1]) {
            (ICMP_ECHO_REQUEST, 0) => false,
            (ICMP_ECHO_REPLY, 0) => true,
            (t, _) => return Err(Error::BadValue { what: "ICMP type (echo only)", offset: 0, value: t as u32 }),
        };
        if checksum(buf) != 0 {
            let stated = u16::from_be_bytes([buf[2], buf[3]]);
            return Err(Error::Checksum { what: "ICMP checksum", offset: 2, expected: 0, actual: stated as u32 });
        }
        let be = |o: usize| u16::from_be_bytes([buf[o], buf[o + 1]]);
        Ok(IcmpEcho { reply, ident: be(4), seq: be(6), data: slice_at(buf, 8, buf.len() - 8, "ICMP echo data")? })
    }

    pub fn len(&self) -> usize {
        8 + self.data.len()
    }

    pub fn is_empty(&self) -> bool {
        false
    }

    /// Emits the message with its checksum.
    pub fn emit(&self, out: &mut [u8]) -> Result<usize> {
        let n = self.len();
        if out.len() < n {
            return Err(Error::BufferTooSmall { what: "ICMP echo", needed: n, available: out.len() });
        }
        out[0] = if self.reply { ICMP_ECHO_REPLY } else { ICMP_ECHO_REQUEST };
        out[1] = 0;
        out[2..4].fill(0);
        out[4..6].copy_from_slice(&self.ident.to_be_bytes());
        out[6..8].copy_from_slice(&self.seq.to_be_bytes());
        out[8..n].copy_from_slice(self.data);
        let c = checksum(&out[..n]);
        out[2..4].copy_from_slice(&c.to_be_bytes());
        Ok(n)
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn the_akds_gratuitous_arp() {
        // twincat-akd-nc-mode frame 3386: the ARP announcement after the AKD took 192.168.0.0.
        let b = [
            0x00, 0x01, 0x08, 0x00, 0x06, 0x04, 0x00, 0x01, 0x02, 0x01, 0x05, 0x30, 0x03, 0xe9, 0xc0, 0xa8, 0x00, 0x00,
            0, 0, 0, 0, 0, 0, 0xc0, 0xa8, 0x00, 0x00,
        ];
        let a = ArpRepr::parse(&b).unwrap();
        assert_eq!(a.operation, ARP_REQUEST);
        assert_eq!(a.sender_ip, [192, 168, 0, 0]);
        assert_eq!(a.target_ip, a.sender_ip);
        let mut out = [0u8; ARP_LEN];
        a.emit(&mut out).unwrap();
        assert_eq!(out, b);
        assert!(ArpRepr::parse(&b[..27]).is_err());
    }

    #[test]
    fn echo_round_trip_and_checksum() {
        let e = IcmpEcho { reply: false, ident: 0x1234, seq: 7, data: b"abc" };
        let mut out = [0u8; 11];
        e.emit(&mut out).unwrap();
        assert_eq!(IcmpEcho::parse(&out).unwrap(), e);
        out[9] ^= 1;
        assert!(matches!(IcmpEcho::parse(&out), Err(Error::Checksum { .. })));
        // RFC 1071's example words 0x0001 0xf203 0xf4f5 0xf6f7 sum to 0xddf2 (complement 0x220d).
        assert_eq!(checksum(&[0x00, 0x01, 0xf2, 0x03, 0xf4, 0xf5, 0xf6, 0xf7]), 0x220d);
    }
}
