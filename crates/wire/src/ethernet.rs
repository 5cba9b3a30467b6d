//! Ethernet II with an optional IEEE 802.1Q tag, and the IPv4 + UDP headers that carry
//! EtherCAT over UDP (destination port 0x88A4).
use crate::bytes::{need, put, slice_at, u16_at};
use crate::{Error, Result};

pub const ETHERTYPE_ETHERCAT: u16 = 0x88A4;
pub const ETHERTYPE_VLAN: u16 = 0x8100;
pub const ETHERTYPE_IPV4: u16 = 0x0800;
/// UDP port of EtherCAT over UDP (esc-spec §1.1).
pub const UDP_PORT_ETHERCAT: u16 = 0x88A4;
/// Minimum Ethernet frame without FCS; shorter frames are padded up to it.
pub const MIN_FRAME_LEN: usize = 60;
pub const BROADCAST: [u8; 6] = [0xFF; 6];

#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct EthernetRepr {
    pub dst: [u8; 6],
    pub src: [u8; 6],
    /// 802.1Q tag control information, when the frame carries a VLAN tag.
    pub vlan_tci: Option<u16>,
    /// The (inner) EtherType.
    pub ethertype: u16,
}

impl EthernetRepr {
    pub fn parse(buf: &[u8]) -> Result<(Self, usize)> {
        need(buf, 0, 14, "Ethernet header")?;
        let mut dst = [0; 6];
        let mut src = [0; 6];
        dst.copy_from_slice(&buf[0..6]);
        src.copy_from_slice(&buf[6..12]);
        let outer = u16::from_be_bytes([buf[12], buf[13]]);
        if outer == ETHERTYPE_VLAN {
            need(buf, 14, 4, "802.1Q VLAN tag")?;
            let tci = u16::from_be_bytes([buf[14], buf[15]]);
            let ethertype = u16::from_be_bytes([buf[16], buf[17]]);
            Ok((EthernetRepr { dst, src, vlan_tci: Some(tci), ethertype }, 18))
        } else {
            Ok((EthernetRepr { dst, src, vlan_tci: None, ethertype: outer }, 14))
        }
    }

    pub fn header_len(&self) -> usize {
        if self.vlan_tci.is_some() {
            18
        } else {
            14
        }
    }

    pub fn emit(&self, out: &mut [u8]) -> Result<usize> {
        let n = self.header_len();
        if out.len() < n {
            return Err(Error::BufferTooSmall { what: "Ethernet header", needed: n, available: out.len() });
        }
        out[0..6].copy_from_slice(&self.dst);
        out[6..12].copy_from_slice(&self.src);
        match self.vlan_tci {
            Some(tci) => {
                out[12..14].copy_from_slice(&ETHERTYPE_VLAN.to_be_bytes());
                out[14..16].copy_from_slice(&tci.to_be_bytes());
                out[16..18].copy_from_slice(&self.ethertype.to_be_bytes());
            }
            None => out[12..14].copy_from_slice(&self.ethertype.to_be_bytes()),
        }
        Ok(n)
    }
}

/// IPv4 header, kept whole (options too) so that a parsed frame re-emits byte for byte.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct Ipv4Repr {
    pub dscp_ecn: u8,
    pub total_len: u16,
    pub ident: u16,
    pub flags_fragment: u16,
    pub ttl: u8,
    pub protocol: u8,
    pub checksum: u16,
    pub src: [u8; 4],
    pub dst: [u8; 4],
    options: [u8; 40],
    options_len: u8,
}

pub const IP_PROTO_UDP: u8 = 17;

impl Ipv4Repr {
    /// A header for a UDP datagram with `udp_payload_len` bytes after the UDP header; the
    /// checksum is computed.
    pub fn for_udp(src: [u8; 4], dst: [u8; 4], udp_payload_len: usize) -> Self {
        Self::new(src, dst, IP_PROTO_UDP, 8 + udp_payload_len)
    }

    /// A header without options for `payload_len` bytes of `protocol`, don't-fragment set,
    /// TTL 64; the checksum is computed.
    pub fn new(src: [u8; 4], dst: [u8; 4], protocol: u8, payload_len: usize) -> Self {
        let mut ip = Ipv4Repr {
            dscp_ecn: 0,
            total_len: (20 + payload_len) as u16,
            ident: 0,
            flags_fragment: 0x4000,
            ttl: 64,
            protocol,
            checksum: 0,
            src,
            dst,
            options: [0; 40],
            options_len: 0,
        };
        ip.checksum = ip.compute_checksum();
        ip
    }

    pub fn options(&self) -> &[u8] {
        &self.options[..self.options_len as usize]
    }

    pub fn header_len(&self) -> usize {
        20 + self.options_len as usize
    }

    pub fn parse(buf: &[u8]) -> Result<(Self, usize)> {
        need(buf, 0, 20, "IPv4 header")?;
        let version = buf[0] >> 4;
        if version != 4 {
            return Err(Error::BadValue { what: "IPv4 version", offset: 0, value: version as u32 });
        }
        let ihl = (buf[0] & 0x0F) as usize * 4;
        if ihl < 20 {
            return Err(Error::BadLength { what: "IPv4 header length (IHL)", offset: 0, claimed: ihl, limit: 60 });
        }
        let opts = slice_at(buf, 20, ihl - 20, "IPv4 options")?;
        let mut options = [0; 40];
        options[..opts.len()].copy_from_slice(opts);
        let be = |o: usize| u16::from_be_bytes([buf[o], buf[o + 1]]);
        Ok((
            Ipv4Repr {
                dscp_ecn: buf[1],
                total_len: be(2),
                ident: be(4),
                flags_fragment: be(6),
                ttl: buf[8],
                protocol: buf[9],
                checksum: be(10),
                src: [buf[12], buf[13], buf[14], buf[15]],
                dst: [buf[16], buf[17], buf[18], buf[19]],
                options,
                options_len: opts.len() as u8,
            },
            ihl,
        ))
    }

    fn write_header(&self, out: &mut [u8], checksum: u16) {
        out[0] = 0x40 | (self.header_len() / 4) as u8;
        out[1] = self.dscp_ecn;
        out[2..4].copy_from_slice(&self.total_len.to_be_bytes());
        out[4..6].copy_from_slice(&self.ident.to_be_bytes());
        out[6..8].copy_from_slice(&self.flags_fragment.to_be_bytes());
        out[8] = self.ttl;
        out[9] = self.protocol;
        out[10..12].copy_from_slice(&checksum.to_be_bytes());
        out[12..16].copy_from_slice(&self.src);
        out[16..20].copy_from_slice(&self.dst);
        out[20..self.header_len()].copy_from_slice(self.options());
    }

    /// RFC 791 header checksum over this header with a zero checksum field.
    pub fn compute_checksum(&self) -> u16 {
        let mut hdr = [0u8; 60];
        self.write_header(&mut hdr, 0);
        crate::inet::checksum(&hdr[..self.header_len()])
    }

    pub fn emit(&self, out: &mut [u8]) -> Result<usize> {
        let n = self.header_len();
        if out.len() < n {
            return Err(Error::BufferTooSmall { what: "IPv4 header", needed: n, available: out.len() });
        }
        self.write_header(out, self.checksum);
        Ok(n)
    }
}

#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct UdpRepr {
    pub src_port: u16,
    pub dst_port: u16,
    pub length: u16,
    pub checksum: u16,
}

impl UdpRepr {
    pub fn parse(buf: &[u8]) -> Result<Self> {
        need(buf, 0, 8, "UDP header")?;
        let be = |o: usize| u16::from_be_bytes([buf[o], buf[o + 1]]);
        Ok(UdpRepr { src_port: be(0), dst_port: be(2), length: be(4), checksum: be(6) })
    }

    pub fn emit(&self, out: &mut [u8]) -> Result<usize> {
        let mut hdr = [0u8; 8];
        hdr[0..2].copy_from_slice(&self.src_port.to_be_bytes());
        hdr[2..4].copy_from_slice(&self.dst_port.to_be_bytes());
        hdr[4..6].copy_from_slice(&self.length.to_be_bytes());
        hdr[6..8].copy_from_slice(&self.checksum.to_be_bytes());
        put(out, 0, &hdr, "UDP header")?;
        Ok(8)
    }
}

/// Reads the EtherType after an optional VLAN tag without building a repr (fast path filter).
pub fn ethertype_of(buf: &[u8]) -> Result<u16> {
    let outer = u16_at(buf, 12, "EtherType").map(u16::swap_bytes)?;
    if outer == ETHERTYPE_VLAN {
        u16_at(buf, 16, "inner EtherType").map(u16::swap_bytes)
    } else {
        Ok(outer)
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn vlan_round_trip() {
        let e = EthernetRepr {
            dst: BROADCAST,
            src: [2, 0, 0, 0, 0, 1],
            vlan_tci: Some(0x2005),
            ethertype: ETHERTYPE_ETHERCAT,
        };
        let mut b = [0u8; 18];
        assert_eq!(e.emit(&mut b).unwrap(), 18);
        assert_eq!(EthernetRepr::parse(&b).unwrap(), (e, 18));
        assert_eq!(ethertype_of(&b).unwrap(), ETHERTYPE_ETHERCAT);
    }

    #[test]
    fn ipv4_checksum_known_vector() {
        // Classic example header from RFC 1071 discussions: checksum 0xB861.
        let hdr = [
            0x45, 0x00, 0x00, 0x73, 0x00, 0x00, 0x40, 0x00, 0x40, 0x11, 0xb8, 0x61, 0xc0, 0xa8, 0x00, 0x01, 0xc0, 0xa8,
            0x00, 0xc7,
        ];
        let (ip, n) = Ipv4Repr::parse(&hdr).unwrap();
        assert_eq!(n, 20);
        assert_eq!(ip.compute_checksum(), 0xb861);
    }

    #[test]
    fn short_and_bad_headers_are_errors() {
        assert!(matches!(EthernetRepr::parse(&[0; 13]), Err(Error::Truncated { .. })));
        let mut v = [0u8; 14];
        v[12] = 0x81;
        assert!(matches!(EthernetRepr::parse(&v), Err(Error::Truncated { what: "802.1Q VLAN tag", .. })));
        assert!(matches!(Ipv4Repr::parse(&[0x46; 20]), Err(Error::Truncated { .. })));
        assert!(matches!(Ipv4Repr::parse(&[0x60; 20]), Err(Error::BadValue { .. })));
    }
}
