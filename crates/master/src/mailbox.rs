//! The mailbox layer (ETG.1000.4 §5.6): messages written to a slave's receive mailbox (SM0)
//! and read from its send mailbox (SM1), with counters, the repeat of a lost read, CoE
//! emergencies turned into events and EoE fragments kept in the slave's inbox whichever
//! exchange met them. The CoE, FoE and EoE clients are built on it; each borrows the engine
//! and the slave list from the master for as long as it is used.
use ferrocat_wire::coe::{self, CoeMessage};
use ferrocat_wire::eoe::{self, frame_type, EoeHeader};
use ferrocat_wire::mailbox::{next_counter, Mailbox, MailboxErrorCode, MailboxHeader, MailboxType};
use ferrocat_wire::{Address, Command};

use crate::engine::Engine;
use crate::eoe_link::INBOX_FRAMES;
use crate::error::{MasterError, Result, SlaveError};
use crate::event::MasterEvent;
use crate::io::Io;
use crate::slave::{slave_at, Slave};

/// SM1 (the slave's send mailbox): its activate byte, where the master toggles the repeat
/// request (bit 1), and its PDI control byte, where the slave acknowledges it (bit 1).
const SM1_ACTIVATE: u16 = ferrocat_wire::register::addr::sm(1) + 6;
const SM1_PDI_CONTROL: u16 = ferrocat_wire::register::addr::sm(1) + 7;

/// How long the master waits for a slave to acknowledge a mailbox repeat request before it
/// polls on (a firmware answers it within its mailbox response time).
const REPEAT_ACK_WAIT_NS: u64 = 50_000_000;

/// What one read of a send mailbox found.
pub(crate) enum Polled {
    /// Nothing (the mailbox was empty).
    Empty,
    /// A message handled on the way: a CoE emergency (now an event) or an EoE fragment (now
    /// in the slave's EoE inbox).
    Taken,
    /// Any other message: its type and service data.
    Message(MailboxType, Vec<u8>),
}

/// What the mailbox clients borrow from the master: the engine, the slave list (mailbox
/// configuration, counters, EoE inboxes), the event list and the mailbox timeout.
pub(crate) struct Mailboxes<'a, I: Io> {
    pub(crate) engine: &'a mut Engine<I>,
    pub(crate) slaves: &'a mut [Slave],
    pub(crate) events: &'a mut Vec<MasterEvent>,
    /// How long a message may wait for room in SM0, or a reply in SM1.
    pub(crate) timeout_ns: u64,
}

impl<I: Io> Mailboxes<'_, I> {
    /// The slave at `position`, or an error saying how many there are.
    pub(crate) fn slave(&self, position: u16) -> Result<&Slave> {
        slave_at(self.slaves, position)
    }

    /// The name of the slave at `position`, for an error (empty if there is none).
    pub(crate) fn name_of(&self, position: u16) -> String {
        self.slaves.get(position as usize).map(|s| s.name.clone()).unwrap_or_default()
    }

    fn push_event(&mut self, e: MasterEvent) {
        tracing::info!("{e}");
        self.events.push(e);
    }

    /// The slave's station address, name and mailbox, if its SII names `protocol`.
    pub(crate) fn mailbox_of(
        &self,
        position: u16,
        protocol: MailboxType,
    ) -> Result<(u16, String, crate::slave::MailboxConfig)> {
        let (st, name, m) = self.mailbox_any(position)?;
        if !self.slave(position)?.mailbox().is_some_and(|mb| mb.has_protocol(protocol.sii_protocol())) {
            return Err(MasterError::of(position, &name, SlaveError::Unsupported(protocol)));
        }
        Ok((st, name, m))
    }

    /// The slave's station address, name and mailbox, whatever protocols it speaks.
    fn mailbox_any(&self, position: u16) -> Result<(u16, String, crate::slave::MailboxConfig)> {
        let s = self.slave(position)?;
        let m = s.mailbox.clone().ok_or_else(|| MasterError::of(position, &s.name, SlaveError::NoMailbox))?;
        // In INIT the mailbox SyncManagers are off: a write would land in plain memory and the
        // read find zeros, a "mailbox error" of nothing.
        if s.state == ferrocat_wire::register::AlState::Init {
            return Err(MasterError::of(position, &s.name, SlaveError::MailboxInInit));
        }
        Ok((s.station, s.name.clone(), m))
    }

    /// Writes one message of `mailbox_type` into SM0 (waiting while it is full).
    pub(crate) fn write(&mut self, position: u16, mailbox_type: MailboxType, payload: &[u8]) -> Result<()> {
        let mut buf = self.message(position, mailbox_type, payload)?;
        let deadline = self.engine.io.now_ns() + self.timeout_ns;
        loop {
            if self.try_write(position, &mut buf)? {
                return Ok(());
            }
            if self.engine.io.now_ns() > deadline {
                return Err(MasterError::of(position, &self.name_of(position), SlaveError::MailboxFull));
            }
            let now = self.engine.io.now_ns();
            self.engine.io.sleep_until(now + 100_000);
        }
    }

    /// A message of `mailbox_type` as the whole receive mailbox, under the next counter.
    pub(crate) fn message(&mut self, position: u16, mailbox_type: MailboxType, payload: &[u8]) -> Result<Vec<u8>> {
        let (_, name, m) = self.mailbox_of(position, mailbox_type)?;
        let mut buf = vec![0u8; m.out.1 as usize];
        if 6 + payload.len() > buf.len() {
            return Err(MasterError::of(
                position,
                &name,
                SlaveError::RequestTooLong { len: payload.len(), mailbox: buf.len() },
            ));
        }
        let c = next_counter(self.slaves[position as usize].mbx_counter);
        self.slaves[position as usize].mbx_counter = c;
        MailboxHeader::new(mailbox_type, payload.len() as u16, c).emit(&mut buf)?;
        buf[6..6 + payload.len()].copy_from_slice(payload);
        Ok(buf)
    }

    /// One write of a message into SM0: whether the slave took it (not while it is full).
    pub(crate) fn try_write(&mut self, position: u16, buf: &mut [u8]) -> Result<bool> {
        let (st, _, m) = self.mailbox_any(position)?;
        Ok(self.engine.one(Command::FPWR, Address::Device { adp: st, ado: m.out.0 }, buf)? == 1)
    }

    /// The next message of `mailbox_type` from SM1 (CoE emergencies met on the way become
    /// events, EoE fragments go to the slave's EoE inbox; a mailbox error reply is an error;
    /// messages of other protocols are dropped).
    pub(crate) fn read(&mut self, position: u16, mailbox_type: MailboxType) -> Result<Vec<u8>> {
        let name = self.mailbox_of(position, mailbox_type)?.1;
        let deadline = self.engine.io.now_ns() + self.timeout_ns;
        loop {
            if let Polled::Message(t, payload) = self.poll(position)? {
                if t == mailbox_type {
                    return Ok(payload);
                }
            }
            if self.engine.io.now_ns() > deadline {
                return Err(MasterError::of(position, &name, SlaveError::NoReply));
            }
            let now = self.engine.io.now_ns();
            self.engine.io.sleep_until(now + 50_000);
        }
    }

    /// One read of the slave's send mailbox (SM1).
    pub(crate) fn poll(&mut self, position: u16) -> Result<Polled> {
        let (st, name, m) = self.mailbox_any(position)?;
        let mut buf = vec![0u8; m.inp.1 as usize];
        let retries = self.engine.stats.retries;
        let wkc = match self.engine.one(Command::FPRD, Address::Device { adp: st, ado: m.inp.0 }, &mut buf) {
            Ok(wkc) => wkc,
            Err(e) => {
                // Given up (the acyclic side sends once): the slave may have handed its
                // message over to the frame lost, which the next read that finds the
                // mailbox empty asks for again.
                if matches!(e, MasterError::Timeout { .. }) {
                    self.slaves[position as usize].mbx_read_lost = true;
                }
                return Err(e);
            }
        };
        if wkc != 1 {
            // The read's frame was sent again and found the mailbox empty: the first may
            // have been lost after the slave handed its message over. Ask for it again.
            if self.engine.stats.retries > retries {
                self.repeat(position)?;
            } else if std::mem::take(&mut self.slaves[position as usize].mbx_read_lost) {
                // In the cycle's spare time: the request only, its acknowledge not awaited
                // (the message comes back to a later read).
                self.request_repeat(position)?;
            }
            return Ok(Polled::Empty);
        }
        self.slaves[position as usize].mbx_read_lost = false;
        let mbx = Mailbox::parse(&buf).map_err(|e| MasterError::of(position, &name, SlaveError::MalformedReply(e)))?;
        // After a repeat request the slave may put back a message that had reached us (the
        // lost frame had not got there): the same counter as the last one taken is that one.
        let counter = mbx.header.counter;
        let slave = &mut self.slaves[position as usize];
        if slave.mbx_repeated.take().is_some_and(|c| c != 0 && c == counter) {
            return Ok(Polled::Taken);
        }
        slave.mbx_in_counter = counter;
        if mbx.header.mailbox_type == MailboxType::ERR {
            let code = MailboxErrorCode::parse(mbx.payload)
                .map_err(|e| MasterError::of(position, &name, SlaveError::MalformedErrorReply(e)))?;
            return Err(MasterError::of(position, &name, SlaveError::MailboxError(code)));
        }
        if mbx.header.mailbox_type == MailboxType::COE {
            if let Ok((_, CoeMessage::Emergency(e))) = coe::parse(mbx.payload) {
                self.push_event(MasterEvent::Emergency {
                    position,
                    name,
                    error_code: e.error_code,
                    error_register: e.error_register,
                    data: e.data,
                });
                return Ok(Polled::Taken);
            }
        }
        if mbx.header.mailbox_type == MailboxType::SOE {
            if let Ok(h) = ferrocat_wire::soe::SoeHeader::parse(mbx.payload) {
                use ferrocat_wire::soe::opcode;
                if matches!(h.opcode, opcode::NOTIFICATION | opcode::EMERGENCY) {
                    self.push_event(MasterEvent::Soe {
                        position,
                        name,
                        drive: h.drive,
                        emergency: h.opcode == opcode::EMERGENCY,
                        idn: ferrocat_wire::soe::Idn(h.idn),
                        data: mbx.payload[ferrocat_wire::soe::HEADER_LEN..].to_vec(),
                    });
                    return Ok(Polled::Taken);
                }
            }
        }
        if mbx.header.mailbox_type == MailboxType::EOE && self.take_eoe_fragment(position, mbx.payload) {
            return Ok(Polled::Taken);
        }
        Ok(Polled::Message(mbx.header.mailbox_type, mbx.payload.to_vec()))
    }

    /// The mailbox repeat (ETG.1000.4): toggles the send mailbox's repeat request (SM1
    /// activate bit 1) and waits a while for the slave's acknowledge (PDI control bit 1 the
    /// same), after which the message it last sent is in the mailbox again. The frame lost may
    /// have found the mailbox empty (a poll while the reply was not ready), and the message put
    /// back is then one already taken: the next one read with its counter is dropped. A slave
    /// that does not acknowledge in time is polled on as before (not every firmware repeats).
    fn repeat(&mut self, position: u16) -> Result<()> {
        let st = self.slave(position)?.station;
        let Some(request) = self.request_repeat(position)? else { return Ok(()) };
        let deadline = self.engine.io.now_ns() + REPEAT_ACK_WAIT_NS.min(self.timeout_ns);
        loop {
            let mut ack = [0u8];
            if self.engine.one(Command::FPRD, Address::Device { adp: st, ado: SM1_PDI_CONTROL }, &mut ack)? == 1
                && (ack[0] ^ request) & 0x02 == 0
            {
                return Ok(());
            }
            let now = self.engine.io.now_ns();
            if now > deadline {
                return Ok(());
            }
            self.engine.io.sleep_until(now + 50_000);
        }
    }

    /// The first half of [`repeat`](Self::repeat): the repeat request toggled; the request
    /// bit written, or `None` where the slave does not repeat or a datagram went unanswered.
    fn request_repeat(&mut self, position: u16) -> Result<Option<u8>> {
        let st = self.slave(position)?.station;
        let mut reg = [0u8; 2];
        if self.engine.one(Command::FPRD, Address::Device { adp: st, ado: SM1_ACTIVATE }, &mut reg)? != 1 {
            return Ok(None);
        }
        // A slave whose acknowledge does not follow its request does not repeat.
        if (reg[0] ^ reg[1]) & 0x02 != 0 {
            return Ok(None);
        }
        let request = reg[0] ^ 0x02;
        if self.engine.one(Command::FPWR, Address::Device { adp: st, ado: SM1_ACTIVATE }, &mut [request])? != 1 {
            return Ok(None);
        }
        let slave = &mut self.slaves[position as usize];
        slave.mbx_repeated = Some(slave.mbx_in_counter);
        slave.mbx_repeats += 1;
        Ok(Some(request))
    }

    /// Takes an EoE message met while reading a mailbox if it is a fragment: `true` if taken.
    pub(crate) fn take_eoe_fragment(&mut self, position: u16, payload: &[u8]) -> bool {
        let Ok(h) = EoeHeader::parse(payload) else { return false };
        if h.frame_type != frame_type::FRAGMENT {
            return false;
        }
        let link = &mut self.slaves[position as usize].eoe;
        match link.reassembler.push(&h, &payload[eoe::HEADER_LEN..]) {
            Ok(Some(r)) => {
                if link.inbox.len() == INBOX_FRAMES {
                    link.inbox.pop_front();
                    link.dropped += 1;
                }
                link.inbox.push_back(r.frame.to_vec());
            }
            Ok(None) => {}
            Err(_) => link.fragment_errors += 1,
        }
        true
    }

    /// Reads every CoE slave's send mailbox once (see [`Acyclic::poll_mailboxes`](crate::part::Acyclic::poll_mailboxes)).
    pub(crate) fn poll_all(&mut self) -> Result<usize> {
        let mut read = 0;
        for k in 0..self.slaves.len() {
            let s = &self.slaves[k];
            if s.mailbox.is_none() || !s.mailbox().is_some_and(|mb| mb.has_coe()) {
                continue;
            }
            // Through the one mailbox read: EoE fragments kept, counters followed, a lost read
            // asked for again. A message that is an error or does not parse is read and left.
            match self.poll(k as u16) {
                Ok(Polled::Empty) => {}
                Ok(_) | Err(MasterError::Slave { .. }) => read += 1,
                Err(e) => return Err(e),
            }
        }
        Ok(read)
    }
}
