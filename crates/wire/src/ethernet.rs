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

/// Where each header field lies, in bytes, as smoltcp's `mod field` says it once.
mod field {
    pub type Field = core::ops::Range<usize>;

    /// Ethernet II, with the 802.1Q tag where the outer EtherType says so.
    pub mod eth {
        use super::Field;
        pub const DESTINATION: Field = 0..6;
        pub const SOURCE: Field = 6..12;
        pub const ETHERTYPE: Field = 12..14;
        pub const HEADER_LEN: usize = 14;
        pub const VLAN_TCI: Field = 14..16;
        pub const VLAN_ETHERTYPE: Field = 16..18;
        pub const VLAN_HEADER_LEN: usize = 18;
    }

    /// IPv4 (RFC 791), without its options.
    pub mod ipv4 {
        use super::Field;
        pub const VERSION_IHL: usize = 0;
        pub const DSCP_ECN: usize = 1;
        pub const TOTAL_LEN: Field = 2..4;
        pub const IDENT: Field = 4..6;
        pub const FLAGS_FRAGMENT: Field = 6..8;
        pub const TTL: usize = 8;
        pub const PROTOCOL: usize = 9;
        pub const CHECKSUM: Field = 10..12;
        pub const SOURCE: Field = 12..16;
        pub const DESTINATION: Field = 16..20;
        pub const HEADER_LEN: usize = 20;
    }

    /// UDP (RFC 768).
    pub mod udp {
        use super::Field;
        pub const SOURCE_PORT: Field = 0..2;
        pub const DESTINATION_PORT: Field = 2..4;
        pub const LENGTH: Field = 4..6;
        pub const CHECKSUM: Field = 6..8;
        pub const HEADER_LEN: usize = 8;
    }
}

/// A big-endian u16 at `f` of a buffer already checked to hold it.
fn be16(buf: &[u8], f: field::Field) -> u16 {
    u16::from_be_bytes([buf[f.start], buf[f.start + 1]])
}

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
        use field::eth;
        need(buf, 0, eth::HEADER_LEN, "Ethernet header")?;
        let mut dst = [0; 6];
        let mut src = [0; 6];
        dst.copy_from_slice(&buf[eth::DESTINATION]);
        src.copy_from_slice(&buf[eth::SOURCE]);
        let outer = be16(buf, eth::ETHERTYPE);
        if outer == ETHERTYPE_VLAN {
            need(buf, eth::HEADER_LEN, eth::VLAN_HEADER_LEN - eth::HEADER_LEN, "802.1Q VLAN tag")?;
            let tci = be16(buf, eth::VLAN_TCI);
            let ethertype = be16(buf, eth::VLAN_ETHERTYPE);
            Ok((EthernetRepr { dst, src, vlan_tci: Some(tci), ethertype }, eth::VLAN_HEADER_LEN))
        } else {
            Ok((EthernetRepr { dst, src, vlan_tci: None, ethertype: outer }, eth::HEADER_LEN))
        }
    }

    pub fn header_len(&self) -> usize {
        if self.vlan_tci.is_some() {
            field::eth::VLAN_HEADER_LEN
        } else {
            field::eth::HEADER_LEN
        }
    }

    pub fn emit(&self, out: &mut [u8]) -> Result<usize> {
        let n = self.header_len();
        if out.len() < n {
            return Err(Error::BufferTooSmall { what: "Ethernet header", needed: n, available: out.len() });
        }
        use field::eth;
        out[eth::DESTINATION].copy_from_slice(&self.dst);
        out[eth::SOURCE].copy_from_slice(&self.src);
        match self.vlan_tci {
            Some(tci) => {
                out[eth::ETHERTYPE].copy_from_slice(&ETHERTYPE_VLAN.to_be_bytes());
                out[eth::VLAN_TCI].copy_from_slice(&tci.to_be_bytes());
                out[eth::VLAN_ETHERTYPE].copy_from_slice(&self.ethertype.to_be_bytes());
            }
            None => out[eth::ETHERTYPE].copy_from_slice(&self.ethertype.to_be_bytes()),
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
        field::ipv4::HEADER_LEN + self.options_len as usize
    }

    pub fn parse(buf: &[u8]) -> Result<(Self, usize)> {
        use field::ipv4;
        need(buf, 0, ipv4::HEADER_LEN, "IPv4 header")?;
        let version = buf[ipv4::VERSION_IHL] >> 4;
        if version != 4 {
            return Err(Error::BadValue { what: "IPv4 version", offset: ipv4::VERSION_IHL, value: version as u32 });
        }
        let ihl = (buf[ipv4::VERSION_IHL] & 0x0F) as usize * 4;
        if ihl < ipv4::HEADER_LEN {
            return Err(Error::BadLength {
                what: "IPv4 header length (IHL)",
                offset: ipv4::VERSION_IHL,
                claimed: ihl,
                limit: 60,
            });
        }
        let opts = slice_at(buf, ipv4::HEADER_LEN, ihl - ipv4::HEADER_LEN, "IPv4 options")?;
        let mut options = [0; 40];
        options[..opts.len()].copy_from_slice(opts);
        let mut src = [0; 4];
        let mut dst = [0; 4];
        src.copy_from_slice(&buf[ipv4::SOURCE]);
        dst.copy_from_slice(&buf[ipv4::DESTINATION]);
        Ok((
            Ipv4Repr {
                dscp_ecn: buf[ipv4::DSCP_ECN],
                total_len: be16(buf, ipv4::TOTAL_LEN),
                ident: be16(buf, ipv4::IDENT),
                flags_fragment: be16(buf, ipv4::FLAGS_FRAGMENT),
                ttl: buf[ipv4::TTL],
                protocol: buf[ipv4::PROTOCOL],
                checksum: be16(buf, ipv4::CHECKSUM),
                src,
                dst,
                options,
                options_len: opts.len() as u8,
            },
            ihl,
        ))
    }

    fn write_header(&self, out: &mut [u8], checksum: u16) {
        use field::ipv4;
        out[ipv4::VERSION_IHL] = 0x40 | (self.header_len() / 4) as u8;
        out[ipv4::DSCP_ECN] = self.dscp_ecn;
        out[ipv4::TOTAL_LEN].copy_from_slice(&self.total_len.to_be_bytes());
        out[ipv4::IDENT].copy_from_slice(&self.ident.to_be_bytes());
        out[ipv4::FLAGS_FRAGMENT].copy_from_slice(&self.flags_fragment.to_be_bytes());
        out[ipv4::TTL] = self.ttl;
        out[ipv4::PROTOCOL] = self.protocol;
        out[ipv4::CHECKSUM].copy_from_slice(&checksum.to_be_bytes());
        out[ipv4::SOURCE].copy_from_slice(&self.src);
        out[ipv4::DESTINATION].copy_from_slice(&self.dst);
        out[ipv4::HEADER_LEN..self.header_len()].copy_from_slice(self.options());
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
        use field::udp;
        need(buf, 0, udp::HEADER_LEN, "UDP header")?;
        Ok(UdpRepr {
            src_port: be16(buf, udp::SOURCE_PORT),
            dst_port: be16(buf, udp::DESTINATION_PORT),
            length: be16(buf, udp::LENGTH),
            checksum: be16(buf, udp::CHECKSUM),
        })
    }

    pub fn emit(&self, out: &mut [u8]) -> Result<usize> {
        use field::udp;
        let mut hdr = [0u8; udp::HEADER_LEN];
        hdr[udp::SOURCE_PORT].copy_from_slice(&self.src_port.to_be_bytes());
        hdr[udp::DESTINATION_PORT].copy_from_slice(&self.dst_port.to_be_bytes());
        hdr[udp::LENGTH].copy_from_slice(&self.length.to_be_bytes());
        hdr[udp::CHECKSUM].copy_from_slice(&self.checksum.to_be_bytes());
        put(out, 0, &hdr, "UDP header")?;
        Ok(udp::HEADER_LEN)
    }
}

/// Reads the EtherType after an optional VLAN tag without building a repr (fast path filter).
pub fn ethertype_of(buf: &[u8]) -> Result<u16> {
    let outer = u16_at(buf, field::eth::ETHERTYPE.start, "EtherType").map(u16::swap_bytes)?;
    if outer == ETHERTYPE_VLAN {
        u16_at(buf, field::eth::VLAN_ETHERTYPE.start, "inner EtherType").map(u16::swap_bytes)
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
