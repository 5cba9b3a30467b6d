//! The EoE client (ETG.1000.6 §5.5): a slave's IP parameters set and read, Ethernet frames sent
//! to it in fragments and taken from it whole, and a ping over them. Fragments a slave sends
//! unasked (an ARP announcement after Set IP Parameter, replies) are put together and kept in
//! the slave's inbox whichever exchange met them, so that no frame is lost to an SDO transfer.
use std::collections::VecDeque;

use ferrocat_wire::eoe::{self, frame_type, EoeHeader, EoeResult, IpParameters};
use ferrocat_wire::ethernet::{EthernetRepr, Ipv4Repr, ETHERTYPE_IPV4};
use ferrocat_wire::inet::{IcmpEcho, IP_PROTO_ICMP};
use ferrocat_wire::mailbox::MailboxType;

use crate::error::{EoeError, MasterError, Result, SlaveError};
use crate::io::Io;
use crate::mailbox::{Mailboxes, Polled};
use crate::master::Master;

pub use crate::eoe_link::INBOX_FRAMES;

pub use crate::eoe_link::EoeLink;

/// Who pings: the master's address on the EoE network, and the slave's.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct EoePing {
    /// The master's MAC address on the EoE network.
    pub from_mac: [u8; 6],
    /// The master's IPv4 address.
    pub from_ip: [u8; 4],
    /// The slave's MAC address.
    pub to_mac: [u8; 6],
    /// The slave's IPv4 address.
    pub to_ip: [u8; 4],
}

/// The EoE client of one master (see [`Acyclic::eoe`](crate::part::Acyclic::eoe)): it borrows the master's engine and
/// slave list for as long as it is used.
pub struct Eoe<'a, I: Io> {
    pub(crate) mbx: Mailboxes<'a, I>,
}

impl<I: Io> Master<I> {}

impl<I: Io> Eoe<'_, I> {
    /// The frames, fragments lost and frames dropped of the slave's EoE inbox.
    pub fn link(&self, position: u16) -> Result<&EoeLink> {
        Ok(&crate::slave::slave_at(self.mbx.slaves, position)?.eoe)
    }

    /// Sends an EoE request and returns the service data after the header of the first EoE
    /// message of `response` type (fragments met meanwhile go to the inbox).
    fn request(&mut self, position: u16, request: u8, body: &[u8], response: u8) -> Result<(EoeHeader, Vec<u8>)> {
        let mut msg = EoeHeader::new(request, 0).to_bytes().to_vec();
        msg.extend_from_slice(body);
        self.mbx.write(position, MailboxType::EOE, &msg)?;
        loop {
            let reply = self.mbx.read(position, MailboxType::EOE)?;
            let h = EoeHeader::parse(&reply)?;
            if h.frame_type == response {
                return Ok((h, reply[eoe::HEADER_LEN..].to_vec()));
            }
        }
    }

    fn result(&self, position: u16, request: &'static str, result: EoeResult) -> Result<()> {
        if result == EoeResult::SUCCESS {
            return Ok(());
        }
        Err(self.error(position, EoeError::Result { request, result }))
    }

    fn error(&self, position: u16, error: EoeError) -> MasterError {
        MasterError::of(position, &self.mbx.name_of(position), SlaveError::Eoe(error))
    }

    /// Sets the slave's IP parameters (those given; the others it keeps).
    pub fn set_ip(&mut self, position: u16, params: &IpParameters) -> Result<()> {
        let mut body = [0u8; eoe::IP_PARAMETERS_LEN];
        params.emit(&mut body)?;
        let (h, _) = self.request(position, frame_type::SET_IP_REQUEST, &body, frame_type::SET_IP_RESPONSE)?;
        self.result(position, "Set IP Parameter", h.result())
    }

    /// The slave's IP parameters as it reports them.
    pub fn get_ip(&mut self, position: u16) -> Result<IpParameters> {
        let (h, body) = self.request(position, frame_type::GET_IP_REQUEST, &[], frame_type::GET_IP_RESPONSE)?;
        self.result(position, "Get IP Parameter", h.result())?;
        IpParameters::parse(&body).map_err(|e| self.error(position, EoeError::IpParameters(e)))
    }

    /// The frame cut into fragments for the slave's receive mailbox, under the next frame
    /// number.
    fn cut(&mut self, position: u16, frame: &[u8]) -> Result<Vec<Vec<u8>>> {
        let (_, name, m) = self.mbx.mailbox_of(position, MailboxType::EOE)?;
        let max_len = (m.out.1 as usize).saturating_sub(ferrocat_wire::mailbox::HEADER_LEN);
        let link = &mut self.mbx.slaves[position as usize].eoe;
        let msgs = eoe::fragment_messages(frame, max_len, link.frame_number).ok_or_else(|| {
            MasterError::of(
                position,
                &name,
                SlaveError::Eoe(EoeError::FrameTooLong { len: frame.len(), mailbox: m.out.1, max: eoe::MAX_FRAME_LEN }),
            )
        })?;
        link.frame_number = (link.frame_number + 1) & 0xF;
        Ok(msgs)
    }

    /// Sends one Ethernet frame to the slave, in as many fragments as its mailbox needs.
    /// Refused while frames queued for [`pump`](Self::pump) are still going out (the
    /// fragments of two frames would interleave).
    pub fn send(&mut self, position: u16, frame: &[u8]) -> Result<()> {
        if self.mbx.slave(position)?.eoe.sending() {
            return Err(self.error(position, EoeError::Busy));
        }
        for msg in self.cut(position, frame)? {
            self.mbx.write(position, MailboxType::EOE, &msg)?;
        }
        Ok(())
    }

    /// The next Ethernet frame from the slave, waiting up to `timeout_ns` for one; `None` if
    /// none came.
    pub fn receive(&mut self, position: u16, timeout_ns: u64) -> Result<Option<Vec<u8>>> {
        self.mbx.mailbox_of(position, MailboxType::EOE)?;
        let deadline = self.mbx.engine.io.now_ns().saturating_add(timeout_ns);
        loop {
            if let Some(f) = self.mbx.slaves[position as usize].eoe.inbox.pop_front() {
                return Ok(Some(f));
            }
            // Anything but a fragment here is an answer nobody waits for: dropped.
            let polled = self.mbx.poll(position)?;
            let now = self.mbx.engine.io.now_ns();
            if now > deadline {
                return Ok(self.mbx.slaves[position as usize].eoe.inbox.pop_front());
            }
            if let Polled::Empty = polled {
                self.mbx.engine.io.sleep_until((now + 50_000).min(deadline.saturating_add(1)));
            }
        }
    }

    /// Queues one Ethernet frame for the slave, cut into fragments, for [`pump`](Self::pump)
    /// to send between cycles. `false` (and counted as dropped) where 64 frames are already
    /// waiting; an error where the frame has no EoE form.
    pub fn queue(&mut self, position: u16, frame: &[u8]) -> Result<bool> {
        self.mbx.mailbox_of(position, MailboxType::EOE)?;
        if self.mbx.slaves[position as usize].eoe.outbox.len() >= INBOX_FRAMES {
            self.mbx.slaves[position as usize].eoe.dropped += 1;
            return Ok(false);
        }
        let msgs = self.cut(position, frame)?;
        self.mbx.slaves[position as usize].eoe.outbox.push_back(msgs.into());
        Ok(true)
    }

    /// One step of EoE traffic that never waits, for a cyclic loop: at most one fragment
    /// written (where the slave's receive mailbox is free) and one read of its send mailbox.
    /// Returns a frame from the slave if one is complete.
    pub fn pump(&mut self, position: u16) -> Result<Option<Vec<u8>>> {
        self.mbx.mailbox_of(position, MailboxType::EOE)?;
        let link = &mut self.mbx.slaves[position as usize].eoe;
        if link.trying.is_none() {
            if let Some(msg) = link.outbox.front_mut().and_then(VecDeque::pop_front) {
                let buf = self.mbx.message(position, MailboxType::EOE, &msg)?;
                self.mbx.slaves[position as usize].eoe.trying = Some(buf);
            }
        }
        if let Some(mut buf) = self.mbx.slaves[position as usize].eoe.trying.take() {
            let written = match self.mbx.try_write(position, &mut buf) {
                Ok(w) => w,
                Err(e) => {
                    // Not taken (its frame went unanswered): the same fragment at the next call.
                    self.mbx.slaves[position as usize].eoe.trying = Some(buf);
                    return Err(e);
                }
            };
            let link = &mut self.mbx.slaves[position as usize].eoe;
            if !written {
                link.trying = Some(buf);
            } else if link.outbox.front().is_some_and(VecDeque::is_empty) {
                // The frame's last fragment went: one frame fewer waiting.
                link.outbox.pop_front();
            }
        }
        if let Some(f) = self.mbx.slaves[position as usize].eoe.inbox.pop_front() {
            return Ok(Some(f));
        }
        self.mbx.poll(position)?;
        Ok(self.mbx.slaves[position as usize].eoe.inbox.pop_front())
    }

    /// Sends an ICMP echo request with `data_len` bytes of data to the slave and waits up to
    /// `timeout_ns` for its reply: the round trip in ns, or `None`. Other frames that arrive
    /// meanwhile are dropped.
    pub fn ping(
        &mut self,
        position: u16,
        p: &EoePing,
        seq: u16,
        data_len: usize,
        timeout_ns: u64,
    ) -> Result<Option<u64>> {
        let data: Vec<u8> = (0..data_len).map(|i| i as u8).collect();
        let frame = p.echo_request(seq, &data)?;
        let t0 = self.mbx.engine.io.now_ns();
        self.send(position, &frame)?;
        let deadline = t0.saturating_add(timeout_ns);
        loop {
            let now = self.mbx.engine.io.now_ns();
            let Some(f) = self.receive(position, deadline.saturating_sub(now))? else { return Ok(None) };
            if p.is_echo_reply(&f, seq, &data) {
                return Ok(Some(self.mbx.engine.io.now_ns() - t0));
            }
        }
    }
}

impl<I: Io> Master<I> {}

impl EoePing {
    /// The identifier its echo requests carry.
    pub const IDENT: u16 = 0xFE00;

    /// An Ethernet frame with an ICMP echo request from the master to the slave.
    pub fn echo_request(&self, seq: u16, data: &[u8]) -> Result<Vec<u8>> {
        let echo = IcmpEcho { reply: false, ident: Self::IDENT, seq, data };
        let ip = Ipv4Repr::new(self.from_ip, self.to_ip, IP_PROTO_ICMP, echo.len());
        let eth = EthernetRepr { dst: self.to_mac, src: self.from_mac, vlan_tci: None, ethertype: ETHERTYPE_IPV4 };
        let mut frame = vec![0u8; 14 + 20 + echo.len()];
        eth.emit(&mut frame)?;
        ip.emit(&mut frame[14..])?;
        echo.emit(&mut frame[34..])?;
        Ok(frame)
    }

    /// Whether `f` is the slave's reply to the request `seq` with `data`.
    pub fn is_echo_reply(&self, f: &[u8], seq: u16, data: &[u8]) -> bool {
        let Ok((eth, n)) = EthernetRepr::parse(f) else { return false };
        let Ok((ip, hl)) = Ipv4Repr::parse(&f[n..]) else { return false };
        let end = (n + ip.total_len as usize).min(f.len());
        if eth.dst != self.from_mac || ip.src != self.to_ip || ip.protocol != IP_PROTO_ICMP || n + hl > end {
            return false;
        }
        IcmpEcho::parse(&f[n + hl..end])
            .is_ok_and(|e| e.reply && e.ident == Self::IDENT && e.seq == seq && e.data == data)
    }
}

impl<'a, I: Io> crate::master::part::Acyclic<'a, I> {
    /// The EoE client: a slave's IP parameters, Ethernet frames to and from it, ping.
    pub fn eoe(self) -> Eoe<'a, I> {
        Eoe { mbx: self.m.mailboxes() }
    }
}
