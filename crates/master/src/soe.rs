//! The SoE client: a servo drive's IDNs read and written through its mailbox (ETG.1000.6
//! §5.8): any of an IDN's elements (name, attribute, unit, minimum, maximum, value, default),
//! fragmented both ways where they do not fit one mailbox. The drive's notifications and
//! emergencies met on the way are events ([`MasterEvent::Soe`](crate::MasterEvent::Soe)).
use ferrocat_wire::mailbox::MailboxType;
use ferrocat_wire::soe::{self, opcode, Attribute, Elements, Idn, SoeError, SoeHeader, ValueLength};

use crate::error::{MasterError, Result, SlaveError};
use crate::io::Io;
use crate::mailbox::Mailboxes;

/// The SoE client of one master (see [`Acyclic::soe`](crate::part::Acyclic::soe)): it borrows
/// the master's engine and slave list for as long as it is used.
pub struct Soe<'a, I: Io> {
    pub(crate) mbx: Mailboxes<'a, I>,
}

/// What an IDN says of itself: its elements 2 to 7 where the drive has them.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct IdnDescription {
    /// The IDN described.
    pub idn: Idn,
    /// Element 2, its name (none where the drive has none).
    pub name: Option<String>,
    /// Element 3: how long its value is, its type, decimals and write protection.
    pub attribute: Attribute,
    /// Element 4, its unit.
    pub unit: Option<String>,
    /// Element 5, the smallest value (of a value of fixed length).
    pub min: Option<Vec<u8>>,
    /// Element 6, the largest value.
    pub max: Option<Vec<u8>>,
    /// Element 7, the value as the drive sent it (a list with its two length words).
    pub value: Vec<u8>,
}

/// Fragments a transfer may have, whichever way: past this a drive's reply is an error
/// rather than a loop (a drive's list of every IDN, S-0-0017, is a few KB).
const MAX_FRAGMENTS: usize = 4096;

impl<I: Io> Soe<'_, I> {
    fn fail(&self, position: u16, error: SlaveError) -> MasterError {
        MasterError::of(position, &self.mbx.name_of(position), error)
    }

    /// One reply of `opcode` for `idn` (fragments joined): its data; an error reply is the
    /// drive's error code.
    fn reply(&mut self, position: u16, drive: u8, idn: Idn, want: u8) -> Result<(SoeHeader, Vec<u8>)> {
        let mut data = Vec::new();
        for _ in 0..MAX_FRAGMENTS {
            let payload = self.mbx.read(position, MailboxType::SOE)?;
            let h = SoeHeader::parse(&payload).map_err(|e| self.fail(position, SlaveError::MalformedReply(e)))?;
            if h.opcode != want {
                return Err(self.fail(
                    position,
                    SlaveError::UnexpectedReply(format!("SoE opcode {} where {want} was due", h.opcode)),
                ));
            }
            let body = &payload[soe::HEADER_LEN..];
            if h.error {
                let code = body.get(..2).map(|b| u16::from_le_bytes([b[0], b[1]])).unwrap_or(SoeError::GENERAL.0);
                return Err(self.fail(position, SlaveError::Soe { idn, drive, error: SoeError(code) }));
            }
            data.extend_from_slice(body);
            if !h.incomplete {
                if h.idn != idn.0 || h.drive != drive {
                    return Err(self.fail(
                        position,
                        SlaveError::UnexpectedReply(format!(
                            "SoE reply for {} of drive {} where {idn} of drive {drive} was asked",
                            Idn(h.idn),
                            h.drive
                        )),
                    ));
                }
                return Ok((h, data));
            }
        }
        Err(self.fail(position, SlaveError::UnexpectedReply(format!("SoE {idn}: more than {MAX_FRAGMENTS} fragments"))))
    }

    /// Reads `elements` of `idn` of drive `drive` (0 on a one-axis device) of the slave at
    /// `position`: their data in the order of the element bits, fragments joined.
    pub fn read(&mut self, position: u16, drive: u8, idn: Idn, elements: Elements) -> Result<Vec<u8>> {
        let h =
            SoeHeader { opcode: opcode::READ_REQUEST, incomplete: false, error: false, drive, elements, idn: idn.0 };
        let mut req = [0u8; soe::HEADER_LEN];
        h.emit(&mut req).map_err(|e| self.fail(position, SlaveError::MalformedReply(e)))?;
        self.mbx.write(position, MailboxType::SOE, &req)?;
        Ok(self.reply(position, drive, idn, opcode::READ_RESPONSE)?.1)
    }

    /// Writes `data` to `elements` (the value, mostly) of `idn` of drive `drive`, in fragments
    /// where it does not fit one mailbox (each but the last counting the fragments left; the
    /// drive answers the last).
    pub fn write(&mut self, position: u16, drive: u8, idn: Idn, elements: Elements, data: &[u8]) -> Result<()> {
        let out_len = self.mbx.mailbox_of(position, MailboxType::SOE)?.2.out.1 as usize;
        let per = soe::max_fragment_len(out_len);
        if per == 0 {
            return Err(self.fail(position, SlaveError::RequestTooLong { len: data.len(), mailbox: out_len }));
        }
        let parts: Vec<&[u8]> = if data.is_empty() { vec![&[][..]] } else { data.chunks(per).collect() };
        if parts.len() > MAX_FRAGMENTS {
            return Err(self.fail(position, SlaveError::RequestTooLong { len: data.len(), mailbox: out_len }));
        }
        for (k, part) in parts.iter().enumerate() {
            let left = parts.len() - 1 - k;
            let h = SoeHeader {
                opcode: opcode::WRITE_REQUEST,
                incomplete: left > 0,
                error: false,
                drive,
                elements,
                idn: if left > 0 { left as u16 } else { idn.0 },
            };
            let mut msg = vec![0u8; soe::HEADER_LEN + part.len()];
            h.emit(&mut msg).map_err(|e| self.fail(position, SlaveError::MalformedReply(e)))?;
            msg[soe::HEADER_LEN..].copy_from_slice(part);
            self.mbx.write(position, MailboxType::SOE, &msg)?;
        }
        self.reply(position, drive, idn, opcode::WRITE_RESPONSE).map(drop)
    }

    /// The IDN's value (element 7) alone.
    pub fn value(&mut self, position: u16, drive: u8, idn: Idn) -> Result<Vec<u8>> {
        self.read(position, drive, idn, Elements::VALUE)
    }

    /// The IDN's elements 2 to 7, each asked for alone (drives differ in which they combine in
    /// one reply): name, attribute, unit, minimum and maximum where the drive has them, and the
    /// value.
    pub fn describe(&mut self, position: u16, drive: u8, idn: Idn) -> Result<IdnDescription> {
        let optional = |s: &mut Self, e: Elements| match s.read(position, drive, idn, e) {
            Ok(v) => Ok(Some(v)),
            Err(MasterError::Slave { error: SlaveError::Soe { .. }, .. }) => Ok(None),
            Err(e) => Err(e),
        };
        let text = |v: Option<Vec<u8>>| -> Option<String> {
            let v = v?;
            Some(match soe::list_items(&v) {
                Ok((items, _)) => String::from_utf8_lossy(items).into_owned(),
                Err(_) => String::from_utf8_lossy(&v).into_owned(),
            })
        };
        let name = text(optional(self, Elements::NAME)?);
        let attribute = self.read(position, drive, idn, Elements::ATTRIBUTE)?;
        let attribute =
            Attribute(u32::from_le_bytes(attribute.get(..4).and_then(|b| b.try_into().ok()).ok_or_else(|| {
                self.fail(
                    position,
                    SlaveError::UnexpectedReply(format!("SoE {idn}: an attribute of {} bytes", attribute.len())),
                )
            })?));
        let unit = text(optional(self, Elements::UNIT)?);
        let (min, max) = match attribute.length() {
            ValueLength::Fixed(_) => (optional(self, Elements::MIN)?, optional(self, Elements::MAX)?),
            ValueLength::List(_) => (None, None),
        };
        let value = self.value(position, drive, idn)?;
        Ok(IdnDescription { idn, name, attribute, unit, min, max, value })
    }

    /// An IDN whose value is a list of IDNs (S-0-0017 every IDN, S-0-0016 and S-0-0024 the
    /// telegrams' configurations): the list's items.
    pub fn idn_list(&mut self, position: u16, drive: u8, idn: Idn) -> Result<Vec<Idn>> {
        let v = self.value(position, drive, idn)?;
        let (items, _) = soe::list_items(&v).map_err(|e| self.fail(position, SlaveError::MalformedReply(e)))?;
        Ok(items.chunks_exact(2).map(|c| Idn(u16::from_le_bytes([c[0], c[1]]))).collect())
    }
}

impl<'a, I: Io> crate::master::part::Acyclic<'a, I> {
    /// The SoE client: IDNs of a servo drive (AX5000, IndraDrive and others).
    pub fn soe(self) -> Soe<'a, I> {
        Soe { mbx: self.m.mailboxes() }
    }
}
