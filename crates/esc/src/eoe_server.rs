//! The EoE endpoint of a device whose SII names EoE (ETG.1000.6 §5.5): it takes its IP
//! parameters from the master (Set/Get IP Parameter) and Ethernet frames in fragments, and
//! runs what a device's IP stack shows a master: ARP replies for its address, ICMP echo
//! replies, and an ARP announcement when it is given an address — as the AKD in
//! twincat-akd-nc-mode answers TwinCAT's Set IP Parameter (response, then the announcement).
use ferrocat_wire::eoe::{self, frame_type, EoeHeader, EoeResult, IpParameters, Reassembler};
use ferrocat_wire::ethernet::{EthernetRepr, Ipv4Repr, BROADCAST, ETHERTYPE_IPV4};
use ferrocat_wire::inet::{self, ArpRepr, IcmpEcho, ARP_LEN, ETHERTYPE_ARP, IP_PROTO_ICMP};

/// Frames kept for the host of a bridged endpoint until it takes them.
pub const HOST_FRAMES: usize = 64;

#[derive(Debug, Clone, Default)]
pub struct EoeServer {
    /// What the master set; a device without a MAC address answers no frame.
    pub params: IpParameters,
    /// Bridged to a host (`ferrocat sim --eoe-tap`): the frames it receives go to the host
    /// (`to_host`), not to its own small stack, and the host's frames come in by
    /// [`Esc::eoe_from_host`](crate::Esc::eoe_from_host).
    pub bridged: bool,
    pub to_host: std::collections::VecDeque<Vec<u8>>,
    reassembler: Reassembler,
    /// The next frame number it sends (4 bits; not reset by INIT: the AKD's announcements in
    /// the capture count 0, 1, 2, 3 across TwinCAT's four sessions).
    frame_number: u8,
    /// Frames received whole, frames sent, frames received and not answered (not for this
    /// device, or nothing it serves), fragments that did not fit the frame begun.
    pub frames_in: u64,
    pub frames_out: u64,
    pub ignored: u64,
    pub fragment_errors: u64,
}

fn response(frame_type: u8, result: EoeResult) -> Vec<u8> {
    EoeHeader::new(frame_type, result.0).to_bytes().to_vec()
}

impl EoeServer {
    /// Answers one EoE message: the service data of each mailbox message to send, in order.
    /// `max_len` is what one message may carry (the send mailbox less the mailbox header).
    pub fn handle(&mut self, request: &[u8], max_len: usize) -> Vec<Vec<u8>> {
        let Ok(h) = EoeHeader::parse(request) else { return Vec::new() };
        let body = &request[eoe::HEADER_LEN..];
        match h.frame_type {
            frame_type::SET_IP_REQUEST => match IpParameters::parse(body) {
                Ok(p) => {
                    let announce = p.ip.is_some();
                    // Fields whose flag is clear keep what the device had.
                    let old = self.params;
                    self.params = IpParameters {
                        mac: p.mac.or(old.mac),
                        ip: p.ip.or(old.ip),
                        subnet_mask: p.subnet_mask.or(old.subnet_mask),
                        gateway: p.gateway.or(old.gateway),
                        dns_server: p.dns_server.or(old.dns_server),
                        dns_name: p.dns_name.or(old.dns_name),
                    };
                    let mut out = vec![response(frame_type::SET_IP_RESPONSE, EoeResult::SUCCESS)];
                    // Bridged, the host's own stack announces what it is told (or not).
                    if announce && !self.bridged {
                        if let Some(frame) = self.announcement() {
                            out.extend(self.send(&frame, max_len));
                        }
                    }
                    out
                }
                Err(_) => vec![response(frame_type::SET_IP_RESPONSE, EoeResult::UNSPECIFIED_ERROR)],
            },
            frame_type::GET_IP_REQUEST => {
                let mut v = response(frame_type::GET_IP_RESPONSE, EoeResult::SUCCESS);
                let mut b = [0u8; eoe::IP_PARAMETERS_LEN];
                self.params.emit(&mut b).ok();
                v.extend_from_slice(&b);
                vec![v]
            }
            // It receives what is addressed to it and broadcasts, and keeps no other filter.
            frame_type::SET_FILTER_REQUEST => {
                vec![response(frame_type::SET_FILTER_RESPONSE, EoeResult::NO_FILTER_SUPPORT)]
            }
            frame_type::GET_FILTER_REQUEST => {
                vec![response(frame_type::GET_FILTER_RESPONSE, EoeResult::NO_FILTER_SUPPORT)]
            }
            frame_type::FRAGMENT => {
                let reply = match self.reassembler.push(&h, body) {
                    Ok(Some(r)) if self.bridged => {
                        self.frames_in += 1;
                        if self.to_host.len() == HOST_FRAMES {
                            self.to_host.pop_front();
                            self.ignored += 1;
                        }
                        self.to_host.push_back(r.frame.to_vec());
                        return Vec::new();
                    }
                    Ok(Some(r)) => {
                        self.frames_in += 1;
                        answer(&self.params, r.frame)
                    }
                    Ok(None) => return Vec::new(),
                    Err(_) => {
                        self.fragment_errors += 1;
                        return Vec::new();
                    }
                };
                match reply {
                    Some(frame) => self.send(&frame, max_len),
                    None => {
                        self.ignored += 1;
                        Vec::new()
                    }
                }
            }
            // A response or time stamp from the master, or a type ETG.1000.6 does not name.
            _ => Vec::new(),
        }
    }

    /// The frame's fragments as service data, under the next frame number.
    pub fn send(&mut self, frame: &[u8], max_len: usize) -> Vec<Vec<u8>> {
        let Some(out) = eoe::fragment_messages(frame, max_len, self.frame_number) else { return Vec::new() };
        self.frame_number = (self.frame_number + 1) & 0xF;
        self.frames_out += 1;
        out
    }

    /// An ARP announcement of its address (request, sender and target its own IP, target MAC
    /// zero), broadcast, 42 bytes with no padding — the AKD's, byte for byte.
    fn announcement(&self) -> Option<Vec<u8>> {
        let (mac, ip) = (self.params.mac?, self.params.ip?);
        let arp =
            ArpRepr { operation: inet::ARP_REQUEST, sender_mac: mac, sender_ip: ip, target_mac: [0; 6], target_ip: ip };
        Some(ethernet_frame(BROADCAST, mac, ETHERTYPE_ARP, |b| arp.emit(b).unwrap_or(0), ARP_LEN))
    }
}

fn ethernet_frame(
    dst: [u8; 6],
    src: [u8; 6],
    ethertype: u16,
    body: impl FnOnce(&mut [u8]) -> usize,
    len: usize,
) -> Vec<u8> {
    let eth = EthernetRepr { dst, src, vlan_tci: None, ethertype };
    let mut v = vec![0u8; 14 + len];
    eth.emit(&mut v).ok();
    let n = body(&mut v[14..]);
    v.truncate(14 + n);
    v
}

/// What the device's stack sends back for `frame`: an ARP reply to a request for its
/// address, an echo reply to an echo request to it; nothing for the rest.
fn answer(p: &IpParameters, frame: &[u8]) -> Option<Vec<u8>> {
    let (mac, ip) = (p.mac?, p.ip?);
    let (eth, n) = EthernetRepr::parse(frame).ok()?;
    if eth.dst != mac && eth.dst != BROADCAST {
        return None;
    }
    let payload = &frame[n..];
    match eth.ethertype {
        ETHERTYPE_ARP => {
            let a = ArpRepr::parse(payload).ok()?;
            (a.operation == inet::ARP_REQUEST && a.target_ip == ip).then(|| {
                let r = ArpRepr {
                    operation: inet::ARP_REPLY,
                    sender_mac: mac,
                    sender_ip: ip,
                    target_mac: a.sender_mac,
                    target_ip: a.sender_ip,
                };
                ethernet_frame(a.sender_mac, mac, ETHERTYPE_ARP, |b| r.emit(b).unwrap_or(0), ARP_LEN)
            })
        }
        ETHERTYPE_IPV4 => {
            let (h, hl) = Ipv4Repr::parse(payload).ok()?;
            let end = (h.total_len as usize).min(payload.len());
            if h.dst != ip || h.protocol != IP_PROTO_ICMP || h.compute_checksum() != h.checksum || end < hl {
                return None;
            }
            let echo = IcmpEcho::parse(&payload[hl..end]).ok().filter(|e| !e.reply)?;
            let reply = IcmpEcho { reply: true, ..echo };
            let r = Ipv4Repr::new(ip, h.src, IP_PROTO_ICMP, reply.len());
            Some(ethernet_frame(
                eth.src,
                mac,
                ETHERTYPE_IPV4,
                |b| {
                    let n = r.emit(b).unwrap_or(0);
                    n + reply.emit(&mut b[n..]).unwrap_or(0)
                },
                20 + reply.len(),
            ))
        }
        _ => None,
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    const MAC: [u8; 6] = [0x02, 0x01, 0x05, 0x30, 0x03, 0xe9];

    fn set_ip(ip: [u8; 4]) -> Vec<u8> {
        let mut v = EoeHeader::new(frame_type::SET_IP_REQUEST, 0).to_bytes().to_vec();
        let mut b = [0u8; eoe::IP_PARAMETERS_LEN];
        IpParameters { mac: Some(MAC), ip: Some(ip), ..Default::default() }.emit(&mut b).unwrap();
        v.extend_from_slice(&b);
        v
    }

    fn reassemble(msgs: &[Vec<u8>]) -> Vec<u8> {
        let mut r = Reassembler::default();
        let mut out = None;
        for m in msgs {
            let h = EoeHeader::parse(m).unwrap();
            if let Some(f) = r.push(&h, &m[4..]).unwrap() {
                out = Some(f.frame.to_vec());
            }
        }
        out.unwrap()
    }

    #[test]
    fn set_ip_answers_then_announces_and_frame_numbers_count_on() {
        let mut s = EoeServer::default();
        let out = s.handle(&set_ip([192, 168, 0, 0]), 1018);
        assert_eq!(out.len(), 2);
        assert_eq!(out[0], [0x03, 0, 0, 0]);
        assert_eq!(out[1][..4], [0x00, 0x01, 0x80, 0x00]);
        assert_eq!(out[1].len(), 4 + 42);
        let again = s.handle(&set_ip([192, 168, 0, 0]), 1018);
        assert_eq!(again[1][..4], [0x00, 0x01, 0x80, 0x10]);
        let get = s.handle(&EoeHeader::new(frame_type::GET_IP_REQUEST, 0).to_bytes(), 1018);
        let p = IpParameters::parse(&get[0][4..]).unwrap();
        assert_eq!((p.mac, p.ip, p.gateway), (Some(MAC), Some([192, 168, 0, 0]), None));
    }

    #[test]
    fn a_ping_larger_than_the_mailbox_comes_back_in_fragments() {
        let mut s = EoeServer::default();
        s.handle(&set_ip([10, 0, 0, 2]), 122);
        let data: Vec<u8> = (0..300).map(|i| i as u8).collect();
        let echo = IcmpEcho { reply: false, ident: 9, seq: 4, data: &data };
        let ip = Ipv4Repr::new([10, 0, 0, 1], [10, 0, 0, 2], IP_PROTO_ICMP, echo.len());
        let master = [0x02, 0, 0, 0, 0, 1];
        let frame = ethernet_frame(
            MAC,
            master,
            ETHERTYPE_IPV4,
            |b| {
                let n = ip.emit(b).unwrap();
                n + echo.emit(&mut b[n..]).unwrap()
            },
            20 + echo.len(),
        );
        let mut replies = Vec::new();
        for (h, d) in eoe::fragments(&frame, 122, 5).unwrap() {
            let mut m = h.to_bytes().to_vec();
            m.extend_from_slice(d);
            replies.extend(s.handle(&m, 122));
        }
        assert!(replies.len() > 1);
        let back = reassemble(&replies);
        let (eth, n) = EthernetRepr::parse(&back).unwrap();
        assert_eq!((eth.dst, eth.src), (master, MAC));
        let (h, hl) = Ipv4Repr::parse(&back[n..]).unwrap();
        assert_eq!((h.src, h.dst, h.compute_checksum()), ([10, 0, 0, 2], [10, 0, 0, 1], h.checksum));
        let e = IcmpEcho::parse(&back[n + hl..]).unwrap();
        assert_eq!((e.reply, e.ident, e.seq, e.data), (true, 9, 4, &data[..]));
        // An echo to another address is not answered.
        let other = ethernet_frame(
            BROADCAST,
            master,
            ETHERTYPE_ARP,
            |b| {
                ArpRepr {
                    operation: 1,
                    sender_mac: master,
                    sender_ip: [10, 0, 0, 1],
                    target_mac: [0; 6],
                    target_ip: [10, 0, 0, 3],
                }
                .emit(b)
                .unwrap()
            },
            ARP_LEN,
        );
        let (h, d) = eoe::fragments(&other, 122, 6).unwrap().next().unwrap();
        let mut m = h.to_bytes().to_vec();
        m.extend_from_slice(d);
        assert!(s.handle(&m, 122).is_empty());
        assert_eq!((s.frames_in, s.ignored), (2, 1));
    }
}
