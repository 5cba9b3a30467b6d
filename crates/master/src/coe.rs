//! The CoE client: SDO upload and download (expedited, normal, segmented, complete access),
//! SDO information, and emergencies handed to the application as events.
use ferrocat_wire::coe::{self, CoeHeader, CoeMessage, CoeService, InfoHeader, InfoOpcode, Sdo, SdoInfo};
use ferrocat_wire::mailbox::{next_counter, Mailbox, MailboxErrorCode, MailboxHeader, MailboxType};
use ferrocat_wire::{Address, Command};

use crate::error::{MasterError, Result};
use crate::io::Io;
use crate::master::{Master, MasterEvent};

/// An object's description from SDO information.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct ObjectInfo {
    /// The object's index.
    pub index: u16,
    /// Its data type (an index of the object dictionary's type area).
    pub data_type: u16,
    /// Its highest subindex.
    pub max_subindex: u8,
    /// Its object code (7 VAR, 8 ARRAY, 9 RECORD).
    pub object_code: u8,
    /// Its name.
    pub name: String,
}

/// An entry's description from SDO information.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct EntryInfo {
    /// The entry's subindex.
    pub subindex: u8,
    /// Its data type.
    pub data_type: u16,
    /// Its size in bits.
    pub bit_length: u16,
    /// Its access bits (read and write per state, mappable).
    pub access: u16,
    /// Its name.
    pub name: String,
}

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

impl<I: Io> Master<I> {
    /// The slave's station address, name and mailbox, if its SII names `protocol`.
    pub(crate) fn mailbox_of(
        &self,
        position: u16,
        protocol: MailboxType,
    ) -> Result<(u16, String, crate::slave::MailboxConfig)> {
        let (st, name, m) = self.mailbox_any(position)?;
        if !self.slave(position)?.has_protocol(protocol.sii_protocol()) {
            return Err(MasterError::slave(position, &name, format!("does not support {}", protocol.name())));
        }
        Ok((st, name, m))
    }

    /// The slave's station address, name and mailbox, whatever protocols it speaks.
    fn mailbox_any(&self, position: u16) -> Result<(u16, String, crate::slave::MailboxConfig)> {
        let s = self.slave(position)?;
        let m = s.mailbox.clone().ok_or_else(|| MasterError::slave(position, &s.name, "has no mailbox"))?;
        Ok((s.station, s.name.clone(), m))
    }

    /// Writes one CoE message into SM0 (waiting while it is full).
    fn mbx_send(&mut self, position: u16, service: CoeService, body: &[u8]) -> Result<()> {
        let mut payload = Vec::with_capacity(2 + body.len());
        payload.extend_from_slice(&CoeHeader::new(service).word().to_le_bytes());
        payload.extend_from_slice(body);
        self.mbx_write(position, MailboxType::COE, &payload)
    }

    /// Writes one message of `mailbox_type` into SM0 (waiting while it is full).
    pub(crate) fn mbx_write(&mut self, position: u16, mailbox_type: MailboxType, payload: &[u8]) -> Result<()> {
        let mut buf = self.mbx_message(position, mailbox_type, payload)?;
        let deadline = self.engine.io.now_ns() + self.mailbox_timeout_ns;
        loop {
            if self.mbx_try_write(position, &mut buf)? {
                return Ok(());
            }
            if self.engine.io.now_ns() > deadline {
                return Err(MasterError::slave(position, &self.name_of(position), "mailbox stays full"));
            }
            let now = self.engine.io.now_ns();
            self.engine.io.sleep_until(now + 100_000);
        }
    }

    /// A message of `mailbox_type` as the whole receive mailbox, under the next counter.
    pub(crate) fn mbx_message(&mut self, position: u16, mailbox_type: MailboxType, payload: &[u8]) -> Result<Vec<u8>> {
        let (_, name, m) = self.mailbox_of(position, mailbox_type)?;
        let mut buf = vec![0u8; m.out.1 as usize];
        if 6 + payload.len() > buf.len() {
            return Err(MasterError::slave(
                position,
                &name,
                format!("request of {} bytes exceeds the {}-byte mailbox", payload.len(), buf.len()),
            ));
        }
        let c = next_counter(self.slaves[position as usize].mbx_counter);
        self.slaves[position as usize].mbx_counter = c;
        MailboxHeader::new(mailbox_type, payload.len() as u16, c).emit(&mut buf)?;
        buf[6..6 + payload.len()].copy_from_slice(payload);
        Ok(buf)
    }

    /// One write of a message into SM0: whether the slave took it (not while it is full).
    pub(crate) fn mbx_try_write(&mut self, position: u16, buf: &mut [u8]) -> Result<bool> {
        let (st, _, m) = self.mailbox_any(position)?;
        Ok(self.engine.one(Command::FPWR, Address::Device { adp: st, ado: m.out.0 }, buf)? == 1)
    }

    /// The next CoE message from SM1 that is not an emergency (emergencies become events).
    fn mbx_receive(&mut self, position: u16) -> Result<Vec<u8>> {
        self.mbx_read(position, MailboxType::COE)
    }

    /// The next message of `mailbox_type` from SM1 (CoE emergencies met on the way become
    /// events, EoE fragments go to the slave's EoE inbox; a mailbox error reply is an error;
    /// messages of other protocols are dropped).
    pub(crate) fn mbx_read(&mut self, position: u16, mailbox_type: MailboxType) -> Result<Vec<u8>> {
        let name = self.mailbox_of(position, mailbox_type)?.1;
        let deadline = self.engine.io.now_ns() + self.mailbox_timeout_ns;
        loop {
            if let Polled::Message(t, payload) = self.mbx_poll(position)? {
                if t == mailbox_type {
                    return Ok(payload);
                }
            }
            if self.engine.io.now_ns() > deadline {
                return Err(MasterError::slave(position, &name, "no mailbox reply (timeout)"));
            }
            let now = self.engine.io.now_ns();
            self.engine.io.sleep_until(now + 50_000);
        }
    }

    /// One read of the slave's send mailbox (SM1).
    pub(crate) fn mbx_poll(&mut self, position: u16) -> Result<Polled> {
        let (st, name, m) = self.mailbox_any(position)?;
        let mut buf = vec![0u8; m.inp.1 as usize];
        let retries = self.engine.stats.retries;
        if self.engine.one(Command::FPRD, Address::Device { adp: st, ado: m.inp.0 }, &mut buf)? != 1 {
            // The read's frame was sent again and found the mailbox empty: the first may
            // have been lost after the slave handed its message over. Ask for it again.
            if self.engine.stats.retries > retries {
                self.mbx_repeat(position)?;
            }
            return Ok(Polled::Empty);
        }
        let mbx =
            Mailbox::parse(&buf).map_err(|e| MasterError::slave(position, &name, format!("mailbox reply: {e}")))?;
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
                .map_err(|e| MasterError::slave(position, &name, format!("mailbox error reply: {e}")))?;
            return Err(MasterError::slave(position, &name, code.to_string()));
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
        if mbx.header.mailbox_type == MailboxType::EOE && self.eoe_take_fragment(position, mbx.payload) {
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
    fn mbx_repeat(&mut self, position: u16) -> Result<()> {
        let st = self.slave(position)?.station;
        let mut reg = [0u8; 2];
        if self.engine.one(Command::FPRD, Address::Device { adp: st, ado: SM1_ACTIVATE }, &mut reg)? != 1 {
            return Ok(());
        }
        // A slave whose acknowledge does not follow its request does not repeat.
        if (reg[0] ^ reg[1]) & 0x02 != 0 {
            return Ok(());
        }
        let request = reg[0] ^ 0x02;
        if self.engine.one(Command::FPWR, Address::Device { adp: st, ado: SM1_ACTIVATE }, &mut [request])? != 1 {
            return Ok(());
        }
        let slave = &mut self.slaves[position as usize];
        slave.mbx_repeated = Some(slave.mbx_in_counter);
        slave.mbx_repeats += 1;
        let deadline = self.engine.io.now_ns() + REPEAT_ACK_WAIT_NS.min(self.mailbox_timeout_ns);
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

    /// Reads every CoE slave's send mailbox once: emergencies waiting there become events.
    /// Returns how many messages were read.
    pub fn poll_mailboxes(&mut self) -> Result<usize> {
        let mut read = 0;
        for k in 0..self.slaves.len() {
            let s = &self.slaves[k];
            if s.mailbox.is_none() || !s.has_coe() {
                continue;
            }
            // Through the one mailbox read: EoE fragments kept, counters followed, a lost read
            // asked for again. A message that is an error or does not parse is read and left.
            match self.mbx_poll(k as u16) {
                Ok(Polled::Empty) => {}
                Ok(_) | Err(MasterError::Slave { .. }) => read += 1,
                Err(e) => return Err(e),
            }
        }
        Ok(read)
    }

    fn sdo_exchange(&mut self, position: u16, req: Sdo<'_>) -> Result<Vec<u8>> {
        // As long as the mailbox: a segment fills it (a 2 048-byte buffer here refused the
        // segments of mailboxes longer than that).
        let mailbox_len = self.mailbox_of(position, MailboxType::COE)?.2.out.1 as usize;
        let mut b = vec![0u8; mailbox_len.max(64)];
        let n = req.emit(&mut b)?;
        self.mbx_send(position, CoeService::SDO_REQUEST, &b[..n])?;
        self.mbx_receive(position)
    }

    fn abort(&self, position: u16, index: u16, subindex: u8, code: ferrocat_wire::coe::AbortCode) -> MasterError {
        let e = MasterError::Abort { position, name: self.name_of(position), index, subindex, code };
        tracing::debug!("{e}");
        e
    }

    /// The name of the slave at `position`, for an error (empty if there is none).
    pub(crate) fn name_of(&self, position: u16) -> String {
        self.slaves.get(position as usize).map(|s| s.name.clone()).unwrap_or_default()
    }

    /// Reads an object entry (or, with `complete_access`, the whole object).
    pub fn sdo_upload(&mut self, position: u16, index: u16, subindex: u8, complete_access: bool) -> Result<Vec<u8>> {
        let reply =
            self.sdo_exchange(position, Sdo::UploadRequest { index, subindex, complete_access, reserved: [0; 4] })?;
        let name = self.slave(position)?.name.clone();
        let unexpected = |m: &CoeMessage<'_>| MasterError::slave(position, &name, format!("unexpected reply {m:?}"));
        let (_, msg) = coe::parse(&reply)?;
        match msg {
            CoeMessage::Sdo(Sdo::UploadExpeditedResponse { size, data, .. }) => {
                Ok(data[..size.unwrap_or(4) as usize].to_vec())
            }
            CoeMessage::Sdo(Sdo::UploadNormalResponse { complete_size, data, .. }) => {
                let total = complete_size as usize;
                let mut all = data[..data.len().min(total)].to_vec();
                let mut toggle = false;
                while all.len() < total {
                    let r = self.sdo_exchange(position, Sdo::UploadSegmentRequest { toggle, reserved: [0; 7] })?;
                    let (_, m) = coe::parse(&r)?;
                    match m {
                        CoeMessage::Sdo(s @ Sdo::UploadSegmentResponse { toggle: t, last, .. }) => {
                            if t != toggle {
                                return Err(MasterError::slave(position, &name, "segment toggle bit out of step"));
                            }
                            all.extend_from_slice(s.segment_data().unwrap_or(&[]));
                            toggle = !toggle;
                            if last {
                                break;
                            }
                        }
                        CoeMessage::Sdo(Sdo::Abort { code, .. }) => {
                            return Err(self.abort(position, index, subindex, code))
                        }
                        other => return Err(unexpected(&other)),
                    }
                }
                all.truncate(total);
                Ok(all)
            }
            CoeMessage::Sdo(Sdo::Abort { code, .. }) => Err(self.abort(position, index, subindex, code)),
            other => Err(unexpected(&other)),
        }
    }

    /// Reads an object by SDO upload (expedited, normal or segmented, as the slave answers).
    pub fn sdo_read(&mut self, position: u16, index: u16, subindex: u8) -> Result<Vec<u8>> {
        self.sdo_upload(position, index, subindex, false)
    }

    /// Writes an object entry (or, with `complete_access`, the whole object): expedited up to
    /// 4 bytes, normal when it fits the mailbox, segmented beyond.
    pub fn sdo_download(
        &mut self,
        position: u16,
        index: u16,
        subindex: u8,
        complete_access: bool,
        data: &[u8],
    ) -> Result<()> {
        let (_, name, m) = self.mailbox_of(position, MailboxType::COE)?;
        let first_max = (m.out.1 as usize).saturating_sub(6 + 2 + 8);
        let seg_max = (m.out.1 as usize).saturating_sub(6 + 2 + 1);
        let check = |me: &Self, reply: &[u8]| -> Result<()> {
            match coe::parse(reply)?.1 {
                CoeMessage::Sdo(Sdo::DownloadResponse { .. })
                | CoeMessage::Sdo(Sdo::DownloadSegmentResponse { .. }) => Ok(()),
                CoeMessage::Sdo(Sdo::Abort { code, .. }) => Err(me.abort(position, index, subindex, code)),
                other => Err(MasterError::slave(position, &name, format!("unexpected reply {other:?}"))),
            }
        };
        if data.len() <= 4 && !data.is_empty() {
            let mut four = [0u8; 4];
            four[..data.len()].copy_from_slice(data);
            let r = self.sdo_exchange(
                position,
                Sdo::DownloadExpeditedRequest {
                    index,
                    subindex,
                    complete_access,
                    size: Some(data.len() as u8),
                    data: four,
                },
            )?;
            return check(self, &r);
        }
        let first = data.len().min(first_max);
        let r = self.sdo_exchange(
            position,
            Sdo::DownloadNormalRequest {
                index,
                subindex,
                complete_access,
                complete_size: data.len() as u32,
                data: &data[..first],
            },
        )?;
        check(self, &r)?;
        let mut at = first;
        let mut toggle = false;
        while at < data.len() {
            let n = (data.len() - at).min(seg_max);
            let mut seg = data[at..at + n].to_vec();
            let unused = if n < 7 { (7 - n) as u8 } else { 0 };
            seg.resize(n.max(7), 0);
            at += n;
            let r = self.sdo_exchange(
                position,
                Sdo::DownloadSegmentRequest { toggle, last: at >= data.len(), unused, segment: &seg },
            )?;
            check(self, &r)?;
            toggle = !toggle;
        }
        Ok(())
    }

    /// Writes an object by SDO download (expedited up to 4 bytes, normal when it fits the mailbox, segmented beyond).
    pub fn sdo_write(&mut self, position: u16, index: u16, subindex: u8, data: &[u8]) -> Result<()> {
        self.sdo_download(position, index, subindex, false, data)
    }

    fn info(&mut self, position: u16, req: SdoInfo<'_>) -> Result<Vec<Vec<u8>>> {
        let mut b = vec![0u8; 64];
        let n = req.emit(&mut b)?;
        self.mbx_send(position, CoeService::SDO_INFORMATION, &b[..n])?;
        let mut parts = Vec::new();
        loop {
            let r = self.mbx_receive(position)?;
            let fragments_left = match coe::parse(&r)?.1 {
                CoeMessage::Information(SdoInfo::Error { code, .. }) => {
                    let index = match req {
                        SdoInfo::ObjectDescriptionRequest { index, .. }
                        | SdoInfo::EntryDescriptionRequest { index, .. } => index,
                        _ => 0,
                    };
                    return Err(self.abort(position, index, 0, code));
                }
                CoeMessage::Information(i) => i.header().fragments_left,
                other => {
                    let name = self.slave(position)?.name.clone();
                    return Err(MasterError::slave(position, &name, format!("unexpected reply {other:?}")));
                }
            };
            parts.push(r);
            if fragments_left == 0 {
                return Ok(parts);
            }
        }
    }

    /// The indices of every object in the dictionary (SDO information, list type 1).
    pub fn od_list(&mut self, position: u16) -> Result<Vec<u16>> {
        let h =
            InfoHeader { opcode: InfoOpcode::GET_OD_LIST_REQUEST, incomplete: false, reserved: 0, fragments_left: 0 };
        let parts = self.info(position, SdoInfo::OdListRequest { header: h, list_type: 1 })?;
        let mut data = Vec::new();
        for p in &parts {
            if let CoeMessage::Information(SdoInfo::OdListResponse { data: d, .. }) = coe::parse(p)?.1 {
                data.extend_from_slice(d);
            }
        }
        // The first fragment starts with the list type.
        Ok(data.chunks_exact(2).skip(1).map(|c| u16::from_le_bytes([c[0], c[1]])).collect())
    }

    /// An object's description by SDO information.
    pub fn object_info(&mut self, position: u16, index: u16) -> Result<ObjectInfo> {
        let h = InfoHeader {
            opcode: InfoOpcode::GET_OBJECT_DESCRIPTION_REQUEST,
            incomplete: false,
            reserved: 0,
            fragments_left: 0,
        };
        let parts = self.info(position, SdoInfo::ObjectDescriptionRequest { header: h, index })?;
        match coe::parse(&parts[0])?.1 {
            CoeMessage::Information(SdoInfo::ObjectDescriptionResponse {
                index,
                data_type,
                max_subindex,
                object_code,
                name,
                ..
            }) => Ok(ObjectInfo {
                index,
                data_type,
                max_subindex,
                object_code,
                name: String::from_utf8_lossy(name).into_owned(),
            }),
            other => Err(MasterError::Config(format!("unexpected SDO information reply {other:?}"))),
        }
    }

    /// An entry's description by SDO information.
    pub fn entry_info(&mut self, position: u16, index: u16, subindex: u8) -> Result<EntryInfo> {
        let h = InfoHeader {
            opcode: InfoOpcode::GET_ENTRY_DESCRIPTION_REQUEST,
            incomplete: false,
            reserved: 0,
            fragments_left: 0,
        };
        let parts =
            self.info(position, SdoInfo::EntryDescriptionRequest { header: h, index, subindex, value_info: 0 })?;
        match coe::parse(&parts[0])?.1 {
            CoeMessage::Information(SdoInfo::EntryDescriptionResponse {
                subindex,
                data_type,
                bit_length,
                object_access,
                rest,
                ..
            }) => Ok(EntryInfo {
                subindex,
                data_type,
                bit_length,
                access: object_access,
                name: String::from_utf8_lossy(rest).into_owned(),
            }),
            other => Err(MasterError::Config(format!("unexpected SDO information reply {other:?}"))),
        }
    }
}
