//! The SoE client: a servo drive's IDNs read and written through its mailbox (ETG.1000.6
//! §5.8): any of an IDN's elements (name, attribute, unit, minimum, maximum, value, default),
//! fragmented both ways where they do not fit one mailbox. The drive's notifications and
//! emergencies met on the way are events ([`MasterEvent::Soe`](crate::MasterEvent::Soe)).
use ferrocat_wire::mailbox::MailboxType;
use ferrocat_wire::soe::{self, Attribute, Elements, Idn, ValueLength};

use crate::error::{MasterError, Result, SlaveError};
use crate::io::Io;
use crate::mailbox::Mailboxes;
use crate::soe_transfer::{SoePeer, SoeStep, SoeTransfer};

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

impl<I: Io> Soe<'_, I> {
    fn fail(&self, position: u16, error: SlaveError) -> MasterError {
        MasterError::of(position, &self.mbx.name_of(position), error)
    }

    /// Who `position` is, for a transfer's errors, and its receive mailbox's length.
    pub(crate) fn peer(&self, position: u16) -> Result<SoePeer> {
        let (_, name, m) = self.mbx.mailbox_of(position, MailboxType::SOE)?;
        Ok(SoePeer { position, name, out_len: m.out.1 as usize })
    }

    /// Each message of `t` written into SM0, then its replies read from SM1 until it is over.
    fn drive_transfer(&mut self, position: u16, mut t: SoeTransfer) -> Result<Vec<u8>> {
        while let Some(msg) = t.next_message() {
            self.mbx.write(position, MailboxType::SOE, &msg)?;
        }
        loop {
            let reply = self.mbx.read(position, MailboxType::SOE)?;
            if let SoeStep::Done(data) = t.on_reply(&reply)? {
                return Ok(data);
            }
        }
    }

    /// Reads `elements` of `idn` of drive `drive` (0 on a one-axis device) of the slave at
    /// `position`: their data in the order of the element bits, fragments joined.
    pub fn read(&mut self, position: u16, drive: u8, idn: Idn, elements: Elements) -> Result<Vec<u8>> {
        let t = SoeTransfer::read(self.peer(position)?, drive, idn, elements)?;
        self.drive_transfer(position, t)
    }

    /// Writes `data` to `elements` (the value, mostly) of `idn` of drive `drive`, in fragments
    /// where it does not fit one mailbox (each but the last counting the fragments left; the
    /// drive answers the last).
    pub fn write(&mut self, position: u16, drive: u8, idn: Idn, elements: Elements, data: &[u8]) -> Result<()> {
        let t = SoeTransfer::write(self.peer(position)?, drive, idn, elements, data)?;
        self.drive_transfer(position, t).map(drop)
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
