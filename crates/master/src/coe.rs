//! The CoE client: SDO upload and download (expedited, normal, segmented, complete access),
//! SDO information, and emergencies handed to the application as events.
use ferrocat_wire::coe::{self, CoeMessage, InfoHeader, InfoOpcode, SdoInfo};
use ferrocat_wire::mailbox::MailboxType;

use crate::error::{MasterError, Result, SlaveError};
use crate::io::Io;
use crate::mailbox::Mailboxes;
use crate::sdo_transfer::{InfoTransfer, Peer, SdoTransfer, Step};

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

/// The CoE client of one master (see [`Acyclic::coe`](crate::part::Acyclic::coe)): it borrows the master's engine and
/// slave list for as long as it is used.
pub struct Coe<'a, I: Io> {
    pub(crate) mbx: Mailboxes<'a, I>,
}

impl<I: Io> Coe<'_, I> {
    /// Who `position` is, for a transfer's requests and errors.
    fn peer(&self, position: u16) -> Result<Peer> {
        let (_, name, m) = self.mbx.mailbox_of(position, MailboxType::COE)?;
        Ok(Peer { position, name, mailbox_len: m.out.1 as usize })
    }

    /// Each request of `t`'s written into SM0 (waiting while it is full) and its reply read
    /// from SM1 (emergencies on the way become events), until it is over.
    fn drive(&mut self, position: u16, mut t: SdoTransfer) -> Result<Vec<u8>> {
        let mut request = t.start()?;
        loop {
            self.mbx.write(position, MailboxType::COE, &request)?;
            let reply = self.mbx.read(position, MailboxType::COE)?;
            match t.on_reply(&reply)? {
                Step::Send(next) => request = next,
                Step::Await => {}
                Step::Done(data) => return Ok(data),
            }
        }
    }

    /// Reads an object entry (or, with `complete_access`, the whole object).
    pub fn sdo_upload(&mut self, position: u16, index: u16, subindex: u8, complete_access: bool) -> Result<Vec<u8>> {
        let t = SdoTransfer::upload(self.peer(position)?, index, subindex, complete_access);
        self.drive(position, t)
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
        let t = SdoTransfer::download(self.peer(position)?, index, subindex, complete_access, data.to_vec());
        self.drive(position, t).map(drop)
    }

    /// Writes an object by SDO download (expedited up to 4 bytes, normal when it fits the mailbox, segmented beyond).
    pub fn sdo_write(&mut self, position: u16, index: u16, subindex: u8, data: &[u8]) -> Result<()> {
        self.sdo_download(position, index, subindex, false, data)
    }

    fn info(&mut self, position: u16, req: SdoInfo<'_>) -> Result<Vec<Vec<u8>>> {
        let mut t = InfoTransfer::new(self.peer(position)?, req)?;
        self.mbx.write(position, MailboxType::COE, &t.start()?)?;
        loop {
            let reply = self.mbx.read(position, MailboxType::COE)?;
            match t.on_reply(&reply)? {
                Step::Done(parts) => return Ok(parts),
                Step::Send(_) | Step::Await => {}
            }
        }
    }

    /// The indices of every object in the dictionary (SDO information, list type 1).
    pub fn od_list(&mut self, position: u16) -> Result<Vec<u16>> {
        let parts = self.info(position, od_list_request())?;
        od_list_of(&parts)
    }

    /// An object's description by SDO information.
    pub fn object_info(&mut self, position: u16, index: u16) -> Result<ObjectInfo> {
        let parts = self.info(position, object_request(index))?;
        object_info_of(&self.peer(position)?, &parts)
    }

    /// An entry's description by SDO information.
    pub fn entry_info(&mut self, position: u16, index: u16, subindex: u8) -> Result<EntryInfo> {
        let parts = self.info(position, entry_request(index, subindex))?;
        entry_info_of(&self.peer(position)?, &parts)
    }
}

/// The request for the list of every object (list type 1).
pub(crate) fn od_list_request() -> SdoInfo<'static> {
    let h = InfoHeader { opcode: InfoOpcode::GET_OD_LIST_REQUEST, incomplete: false, reserved: 0, fragments_left: 0 };
    SdoInfo::OdListRequest { header: h, list_type: 1 }
}

/// The request for `index`'s description.
pub(crate) fn object_request(index: u16) -> SdoInfo<'static> {
    let h = InfoHeader {
        opcode: InfoOpcode::GET_OBJECT_DESCRIPTION_REQUEST,
        incomplete: false,
        reserved: 0,
        fragments_left: 0,
    };
    SdoInfo::ObjectDescriptionRequest { header: h, index }
}

/// The request for `index:subindex`'s description.
pub(crate) fn entry_request(index: u16, subindex: u8) -> SdoInfo<'static> {
    let h = InfoHeader {
        opcode: InfoOpcode::GET_ENTRY_DESCRIPTION_REQUEST,
        incomplete: false,
        reserved: 0,
        fragments_left: 0,
    };
    SdoInfo::EntryDescriptionRequest { header: h, index, subindex, value_info: 0 }
}

/// The indices in an object list's fragments.
pub(crate) fn od_list_of(parts: &[Vec<u8>]) -> Result<Vec<u16>> {
    let mut data = Vec::new();
    for p in parts {
        if let CoeMessage::Information(SdoInfo::OdListResponse { data: d, .. }) = coe::parse(p)?.1 {
            data.extend_from_slice(d);
        }
    }
    // The first fragment starts with the list type.
    Ok(data.chunks_exact(2).skip(1).map(|c| u16::from_le_bytes([c[0], c[1]])).collect())
}

/// The object description in a reply's fragments.
pub(crate) fn object_info_of(peer: &Peer, parts: &[Vec<u8>]) -> Result<ObjectInfo> {
    match parts.first().map(|p| coe::parse(p)).transpose()?.map(|m| m.1) {
        Some(CoeMessage::Information(SdoInfo::ObjectDescriptionResponse {
            index,
            data_type,
            max_subindex,
            object_code,
            name,
            ..
        })) => Ok(ObjectInfo {
            index,
            data_type,
            max_subindex,
            object_code,
            name: String::from_utf8_lossy(name).into_owned(),
        }),
        other => Err(MasterError::of(
            peer.position,
            &peer.name,
            SlaveError::UnexpectedReply(format!("to SDO information: {other:?}")),
        )),
    }
}

/// The entry description in a reply's fragments.
pub(crate) fn entry_info_of(peer: &Peer, parts: &[Vec<u8>]) -> Result<EntryInfo> {
    match parts.first().map(|p| coe::parse(p)).transpose()?.map(|m| m.1) {
        Some(CoeMessage::Information(SdoInfo::EntryDescriptionResponse {
            subindex,
            data_type,
            bit_length,
            object_access,
            rest,
            ..
        })) => Ok(EntryInfo {
            subindex,
            data_type,
            bit_length,
            access: object_access,
            name: String::from_utf8_lossy(rest).into_owned(),
        }),
        other => Err(MasterError::of(
            peer.position,
            &peer.name,
            SlaveError::UnexpectedReply(format!("to SDO information: {other:?}")),
        )),
    }
}
