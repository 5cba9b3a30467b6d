//! Whole EtherCAT frames: Ethernet (optionally VLAN-tagged, or IPv4/UDP), the 2-byte EtherCAT
//! header, a chain of datagrams, and padding (esc-spec §1.1–1.3).
use crate::bytes::{need, put, u16_at};
use crate::datagram::{emit_datagram, Datagram, DatagramHeader, HEADER_LEN};
use crate::ethernet::{
    EthernetRepr, Ipv4Repr, UdpRepr, ETHERTYPE_ETHERCAT, ETHERTYPE_IPV4, IP_PROTO_UDP, MIN_FRAME_LEN, UDP_PORT_ETHERCAT,
};
use crate::{Error, Result};

pub const ECAT_HEADER_LEN: usize = 2;
/// EtherCAT header type of a frame carrying datagrams (DLPDU).
pub const TYPE_DLPDU: u8 = 1;
/// Largest EtherCAT PDU (header length field is 11 bits; a standard frame holds 1498 bytes).
pub const MAX_PDU_LEN: usize = 1498;

/// The EtherCAT header: 11-bit length of what follows (without padding), a reserved bit, 4-bit type.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash)]
pub struct EcatHeader {
    pub length: u16,
    pub reserved: bool,
    pub frame_type: u8,
}

impl EcatHeader {
    pub fn dlpdu(length: u16) -> Self {
        EcatHeader { length, reserved: false, frame_type: TYPE_DLPDU }
    }

    pub fn parse(buf: &[u8]) -> Result<Self> {
        let w = u16_at(buf, 0, "EtherCAT header")?;
        Ok(EcatHeader { length: w & 0x07FF, reserved: w & 0x0800 != 0, frame_type: (w >> 12) as u8 })
    }

    pub fn word(&self) -> u16 {
        (self.length & 0x07FF) | if self.reserved { 0x0800 } else { 0 } | ((self.frame_type as u16 & 0xF) << 12)
    }

    pub fn emit(&self, out: &mut [u8]) -> Result<()> {
        put(out, 0, &self.word().to_le_bytes(), "EtherCAT header")
    }
}

/// The EtherCAT header and the bytes its length covers, with the datagram chain validated.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct EcatPdu<'a> {
    pub header: EcatHeader,
    body: &'a [u8],
    datagram_count: usize,
}

impl<'a> EcatPdu<'a> {
    /// Parses the EtherCAT header at the start of `buf`. For DLPDU frames the datagram chain must
    /// fit within the header's length; a "more follows" bit with no room after it is an error.
    /// Real masters (ethercrab) send header lengths larger than the chain, and ESCs and
    /// Wireshark accept that, so bytes after the last datagram are not an error: they belong to
    /// the frame's trailer.
    pub fn parse(buf: &'a [u8]) -> Result<Self> {
        let header = EcatHeader::parse(buf)?;
        let len = header.length as usize;
        if ECAT_HEADER_LEN + len > buf.len() {
            return Err(Error::BadLength {
                what: "EtherCAT header length",
                offset: 0,
                claimed: len,
                limit: buf.len() - ECAT_HEADER_LEN,
            });
        }
        let declared = &buf[ECAT_HEADER_LEN..ECAT_HEADER_LEN + len];
        if header.frame_type != TYPE_DLPDU {
            return Ok(EcatPdu { header, body: declared, datagram_count: 0 });
        }
        let mut datagram_count = 0;
        let mut off = 0;
        loop {
            let d = Datagram::parse(&declared[off..]).map_err(|e| e.shifted(ECAT_HEADER_LEN + off))?;
            datagram_count += 1;
            off += d.as_bytes().len();
            if !d.header().more {
                break;
            }
            if off >= declared.len() {
                return Err(Error::Truncated {
                    what: "datagram announced by the more-follows bit",
                    offset: ECAT_HEADER_LEN + off,
                    needed: HEADER_LEN,
                    available: 0,
                });
            }
        }
        Ok(EcatPdu { header, body: &declared[..off], datagram_count })
    }

    /// The datagram chain (DLPDU), or everything the header length covers (other types).
    pub fn body(&self) -> &'a [u8] {
        self.body
    }

    /// Bytes of header plus body (a DLPDU header may declare more; those bytes are trailer).
    pub fn wire_len(&self) -> usize {
        ECAT_HEADER_LEN + self.body.len()
    }

    pub fn datagram_count(&self) -> usize {
        self.datagram_count
    }

    /// The datagrams, in order (empty for frame types other than DLPDU).
    pub fn datagrams(&self) -> Datagrams<'a> {
        let body = if self.header.frame_type == TYPE_DLPDU { self.body } else { &[] };
        Datagrams { rest: body }
    }
}

/// Iterator over an already validated datagram chain.
#[derive(Debug, Clone)]
pub struct Datagrams<'a> {
    rest: &'a [u8],
}

impl<'a> Iterator for Datagrams<'a> {
    type Item = Datagram<'a>;
    fn next(&mut self) -> Option<Datagram<'a>> {
        if self.rest.is_empty() {
            return None;
        }
        // The chain was validated by EcatPdu::parse; a failure here cannot happen, but stop
        // rather than panic if it ever did.
        let d = Datagram::parse(self.rest).ok()?;
        self.rest = &self.rest[d.as_bytes().len()..];
        Some(d)
    }
}

/// How the EtherCAT PDU is carried.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Encapsulation {
    /// Directly in Ethernet with EtherType 0x88A4.
    Ethernet,
    /// In a UDP datagram to port 0x88A4 over IPv4.
    Udp { ip: Ipv4Repr, udp: UdpRepr },
}

/// A parsed frame: nothing is lost, so [`Frame::emit`] reproduces the input byte for byte.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct Frame<'a> {
    pub ethernet: EthernetRepr,
    pub encapsulation: Encapsulation,
    pub pdu: EcatPdu<'a>,
    /// Bytes after the datagram chain: Ethernet padding, any slack the EtherCAT header length
    /// declares beyond the chain, and over UDP anything past the PDU.
    pub trailer: &'a [u8],
}

impl<'a> Frame<'a> {
    /// Parses an Ethernet frame (without FCS). `Ok(None)` when it is not EtherCAT at all.
    pub fn parse(buf: &'a [u8]) -> Result<Option<Self>> {
        let (ethernet, mut off) = EthernetRepr::parse(buf)?;
        let encapsulation = match ethernet.ethertype {
            ETHERTYPE_ETHERCAT => Encapsulation::Ethernet,
            ETHERTYPE_IPV4 => {
                let (ip, ihl) = Ipv4Repr::parse(&buf[off..]).map_err(|e| e.shifted(off))?;
                // Only an unfragmented (or first-fragment) UDP datagram to port 0x88A4 is
                // EtherCAT; anything else, even malformed, is simply not ours.
                if ip.protocol != IP_PROTO_UDP || ip.flags_fragment & 0x1FFF != 0 {
                    return Ok(None);
                }
                let udp = match UdpRepr::parse(&buf[off + ihl..]) {
                    Ok(u) if u.dst_port == UDP_PORT_ETHERCAT => u,
                    _ => return Ok(None),
                };
                off += ihl + 8;
                Encapsulation::Udp { ip, udp }
            }
            _ => return Ok(None),
        };
        let pdu = EcatPdu::parse(&buf[off..]).map_err(|e| e.shifted(off))?;
        let trailer = &buf[off + pdu.wire_len()..];
        Ok(Some(Frame { ethernet, encapsulation, pdu, trailer }))
    }

    /// Emits the frame exactly as parsed, copying the PDU body.
    pub fn emit(&self, out: &mut [u8]) -> Result<usize> {
        let mut w = FrameWriter::with_encapsulation(out, &self.ethernet, &self.encapsulation)?;
        for d in self.pdu.datagrams() {
            w.push(d.header(), d.data(), d.wkc())?;
        }
        if self.pdu.header.frame_type != TYPE_DLPDU {
            w.push_body(self.pdu.body())?;
        }
        w.finish_exact(self.pdu.header, self.trailer)
    }
}

/// Builds a frame in a caller-supplied buffer without allocating.
#[derive(Debug)]
pub struct FrameWriter<'b> {
    buf: &'b mut [u8],
    /// Offset of the EtherCAT header.
    ecat_at: usize,
    pos: usize,
    last_datagram: Option<usize>,
    udp: Option<(Ipv4Repr, UdpRepr, usize)>,
}

impl<'b> FrameWriter<'b> {
    /// A frame carried directly in Ethernet (the `ethertype` of `eth` is replaced by 0x88A4).
    pub fn new(buf: &'b mut [u8], eth: &EthernetRepr) -> Result<Self> {
        let eth = EthernetRepr { ethertype: ETHERTYPE_ETHERCAT, ..*eth };
        Self::with_encapsulation(buf, &eth, &Encapsulation::Ethernet)
    }

    pub fn with_encapsulation(buf: &'b mut [u8], eth: &EthernetRepr, enc: &Encapsulation) -> Result<Self> {
        let mut pos = eth.emit(buf)?;
        let mut udp = None;
        if let Encapsulation::Udp { ip, udp: u } = enc {
            let ip_at = pos;
            pos += ip.emit(&mut buf[pos..])?;
            pos += u.emit(&mut buf[pos..])?;
            udp = Some((*ip, *u, ip_at));
        }
        need(buf, pos, ECAT_HEADER_LEN, "EtherCAT header").map_err(|_| Error::BufferTooSmall {
            what: "EtherCAT header",
            needed: pos + ECAT_HEADER_LEN,
            available: buf.len(),
        })?;
        Ok(FrameWriter { buf, ecat_at: pos, pos: pos + ECAT_HEADER_LEN, last_datagram: None, udp })
    }

    /// Appends a datagram with its header exactly as given. Returns the offset of its data in
    /// the frame buffer.
    pub fn push(&mut self, header: &DatagramHeader, data: &[u8], wkc: u16) -> Result<usize> {
        let at = self.pos;
        self.pos += emit_datagram(&mut self.buf[at..], header, data, wkc)?;
        self.last_datagram = Some(at);
        Ok(at + HEADER_LEN)
    }

    /// Appends a datagram and sets the more-follows bit of the one before it.
    pub fn push_chained(&mut self, header: &DatagramHeader, data: &[u8], wkc: u16) -> Result<usize> {
        if let Some(prev) = self.last_datagram {
            self.buf[prev + 7] |= 0x80;
        }
        let h = DatagramHeader { more: false, ..*header };
        self.push(&h, data, wkc)
    }

    /// Appends opaque PDU bytes (the body of EtherCAT types other than DLPDU).
    pub fn push_body(&mut self, bytes: &[u8]) -> Result<()> {
        put(self.buf, self.pos, bytes, "EtherCAT PDU")?;
        self.pos += bytes.len();
        Ok(())
    }

    /// Mutable access to bytes already written (e.g. to fill a datagram's data in place).
    pub fn bytes_mut(&mut self) -> &mut [u8] {
        &mut self.buf[..self.pos]
    }

    /// Writes the EtherCAT header (type 1, length of the datagrams), fixes IPv4/UDP lengths and
    /// checksum, pads to the 60-byte Ethernet minimum with zeros; returns the frame length.
    pub fn finish(self) -> Result<usize> {
        let len = self.pos - self.ecat_at - ECAT_HEADER_LEN;
        if len > MAX_PDU_LEN {
            return Err(Error::BadLength {
                what: "EtherCAT PDU",
                offset: self.ecat_at,
                claimed: len,
                limit: MAX_PDU_LEN,
            });
        }
        EcatHeader::dlpdu(len as u16).emit(&mut self.buf[self.ecat_at..])?;
        if let Some((ip, udp, ip_at)) = self.udp {
            let udp_len = 8 + ECAT_HEADER_LEN + len;
            let mut ip = ip;
            ip.total_len = (ip.header_len() + udp_len) as u16;
            ip.checksum = ip.compute_checksum();
            let n = ip.emit(&mut self.buf[ip_at..])?;
            UdpRepr { length: udp_len as u16, checksum: 0, ..udp }.emit(&mut self.buf[ip_at + n..])?;
        }
        let end = self.pos.max(MIN_FRAME_LEN);
        if end > self.buf.len() {
            return Err(Error::BufferTooSmall { what: "frame padding", needed: end, available: self.buf.len() });
        }
        self.buf[self.pos..end].fill(0);
        Ok(end)
    }

    /// Writes `header` as given and `trailer` verbatim after the PDU (exact re-emission).
    pub fn finish_exact(self, header: EcatHeader, trailer: &[u8]) -> Result<usize> {
        header.emit(&mut self.buf[self.ecat_at..])?;
        put(self.buf, self.pos, trailer, "frame trailer")?;
        Ok(self.pos + trailer.len())
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::datagram::{Address, Command};
    use crate::ethernet::BROADCAST;

    fn eth() -> EthernetRepr {
        EthernetRepr { dst: BROADCAST, src: [2, 0, 0, 0, 0, 0], vlan_tci: None, ethertype: ETHERTYPE_ETHERCAT }
    }

    #[test]
    fn build_and_parse_two_datagrams() {
        let mut buf = [0u8; 128];
        let mut w = FrameWriter::new(&mut buf, &eth()).unwrap();
        w.push_chained(&DatagramHeader::new(Command::BRD, 1, Address::Device { adp: 0, ado: 0x130 }, 2), &[0, 0], 0)
            .unwrap();
        w.push_chained(&DatagramHeader::new(Command::LRW, 2, Address::Logical(0x10000), 4), &[1, 2, 3, 4], 0).unwrap();
        let n = w.finish().unwrap();
        assert_eq!(n, 60);
        let f = Frame::parse(&buf[..n]).unwrap().unwrap();
        assert_eq!(f.pdu.header, EcatHeader::dlpdu(14 + 16));
        let ds: Vec<_> = f.pdu.datagrams().collect();
        assert_eq!(ds.len(), 2);
        assert!(ds[0].header().more && !ds[1].header().more);
        assert_eq!(ds[1].header().address, Address::Logical(0x10000));
        assert_eq!(f.trailer.len(), 60 - 14 - 2 - 30);
        let mut again = [0u8; 128];
        assert_eq!(f.emit(&mut again).unwrap(), n);
        assert_eq!(&again[..n], &buf[..n]);
    }

    #[test]
    fn udp_encapsulation_round_trip() {
        let mut buf = [0u8; 128];
        let e = EthernetRepr { ethertype: ETHERTYPE_IPV4, ..eth() };
        let enc = Encapsulation::Udp {
            ip: Ipv4Repr::for_udp([127, 0, 0, 1], [127, 0, 0, 1], 0),
            udp: UdpRepr { src_port: 0x88A4, dst_port: 0x88A4, length: 0, checksum: 0 },
        };
        let mut w = FrameWriter::with_encapsulation(&mut buf, &e, &enc).unwrap();
        w.push(&DatagramHeader::new(Command::APRD, 0, Address::position(0, 0), 1), &[0], 0).unwrap();
        let n = w.finish().unwrap();
        let f = Frame::parse(&buf[..n]).unwrap().unwrap();
        let Encapsulation::Udp { ip, udp } = f.pdu_encapsulation() else { panic!("not udp") };
        assert_eq!(udp.length as usize, 8 + 2 + 13);
        assert_eq!(ip.checksum, ip.compute_checksum());
        assert_eq!(f.pdu.datagram_count(), 1);
    }

    impl Frame<'_> {
        fn pdu_encapsulation(&self) -> Encapsulation {
            self.encapsulation
        }
    }

    #[test]
    fn lies_are_errors() {
        let mut buf = [0u8; 60];
        let n = {
            let mut w = FrameWriter::new(&mut buf, &eth()).unwrap();
            w.push(&DatagramHeader::new(Command::BRD, 1, Address::Device { adp: 0, ado: 0 }, 2), &[0, 0], 0).unwrap();
            w.finish().unwrap()
        };
        // More-follows bit set on the last datagram.
        let mut b = buf;
        b[16 + 7] |= 0x80;
        assert!(Frame::parse(&b[..n]).is_err());
        // Header length larger than the frame.
        let mut b = buf;
        b[14] = 0xFF;
        b[15] = 0x17;
        assert!(matches!(Frame::parse(&b[..n]), Err(Error::BadLength { offset: 14, .. })));
        // Header length shorter than the datagram chain.
        let mut b = buf;
        b[14] = 10;
        assert!(Frame::parse(&b[..n]).is_err());
        // Not EtherCAT.
        let mut b = buf;
        b[12] = 0x08;
        b[13] = 0x06;
        assert_eq!(Frame::parse(&b[..n]).unwrap(), None);
    }
}
