//! The CoE client: SDO upload and download (expedited, normal, segmented, complete access),
//! SDO information, and emergencies handed to the application as events.
use ferrocat_wire::coe::{self, CoeHeader, CoeMessage, CoeService, InfoHeader, InfoOpcode, Sdo, SdoInfo};
use ferrocat_wire::mailbox::MailboxType;

use crate::error::{MasterError, Result, SlaveError};
use crate::io::Io;
use crate::mailbox::Mailboxes;

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

/// The CoE client of one master (see [`Master::coe`](crate::Master::coe)): it borrows the master's engine and
/// slave list for as long as it is used.
pub struct Coe<'a, I: Io> {
    pub(crate) mbx: Mailboxes<'a, I>,
}

impl<I: Io> Coe<'_, I> {
    /// Writes one CoE message into SM0 (waiting while it is full).
    fn send(&mut self, position: u16, service: CoeService, body: &[u8]) -> Result<()> {
        let mut payload = Vec::with_capacity(2 + body.len());
        payload.extend_from_slice(&CoeHeader::new(service).word().to_le_bytes());
        payload.extend_from_slice(body);
        self.mbx.write(position, MailboxType::COE, &payload)
    }

    /// The next CoE message from SM1 that is not an emergency (emergencies become events).
    fn receive(&mut self, position: u16) -> Result<Vec<u8>> {
        self.mbx.read(position, MailboxType::COE)
    }

    fn sdo_exchange(&mut self, position: u16, req: Sdo<'_>) -> Result<Vec<u8>> {
        // As long as the mailbox: a segment fills it (a 2 048-byte buffer here refused the
        // segments of mailboxes longer than that).
        let mailbox_len = self.mbx.mailbox_of(position, MailboxType::COE)?.2.out.1 as usize;
        let mut b = vec![0u8; mailbox_len.max(64)];
        let n = req.emit(&mut b)?;
        self.send(position, CoeService::SDO_REQUEST, &b[..n])?;
        self.receive(position)
    }

    fn abort(&self, position: u16, index: u16, subindex: u8, code: ferrocat_wire::coe::AbortCode) -> MasterError {
        let e = MasterError::Abort { position, name: self.mbx.name_of(position), index, subindex, code };
        tracing::debug!("{e}");
        e
    }

    /// Reads an object entry (or, with `complete_access`, the whole object).
    pub fn sdo_upload(&mut self, position: u16, index: u16, subindex: u8, complete_access: bool) -> Result<Vec<u8>> {
        let reply =
            self.sdo_exchange(position, Sdo::UploadRequest { index, subindex, complete_access, reserved: [0; 4] })?;
        let name = self.mbx.slave(position)?.name.clone();
        let unexpected =
            |m: &CoeMessage<'_>| MasterError::of(position, &name, SlaveError::UnexpectedReply(format!("{m:?}")));
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
                                return Err(MasterError::of(position, &name, SlaveError::ToggleOutOfStep));
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
        let (_, name, m) = self.mbx.mailbox_of(position, MailboxType::COE)?;
        let first_max = (m.out.1 as usize).saturating_sub(6 + 2 + 8);
        let seg_max = (m.out.1 as usize).saturating_sub(6 + 2 + 1);
        let check = |me: &Self, reply: &[u8]| -> Result<()> {
            match coe::parse(reply)?.1 {
                CoeMessage::Sdo(Sdo::DownloadResponse { .. })
                | CoeMessage::Sdo(Sdo::DownloadSegmentResponse { .. }) => Ok(()),
                CoeMessage::Sdo(Sdo::Abort { code, .. }) => Err(me.abort(position, index, subindex, code)),
                other => Err(MasterError::of(position, &name, SlaveError::UnexpectedReply(format!("{other:?}")))),
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
        self.send(position, CoeService::SDO_INFORMATION, &b[..n])?;
        let mut parts = Vec::new();
        loop {
            let r = self.receive(position)?;
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
                    let name = self.mbx.slave(position)?.name.clone();
                    return Err(MasterError::of(position, &name, SlaveError::UnexpectedReply(format!("{other:?}"))));
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
            other => Err(MasterError::of(
                position,
                &self.mbx.name_of(position),
                SlaveError::UnexpectedReply(format!("to SDO information: {other:?}")),
            )),
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
            other => Err(MasterError::of(
                position,
                &self.mbx.name_of(position),
                SlaveError::UnexpectedReply(format!("to SDO information: {other:?}")),
            )),
        }
    }
}
