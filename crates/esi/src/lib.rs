//! EtherCAT Slave Information (ESI) files (ETG.2000): a vendor's XML description of its devices.
//!
//! [`EsiFile::parse`] reads the parts a master and a simulator need: identity, SyncManagers,
//! FMMUs, PDOs with their entries, DC op-modes, mailbox protocols, EEPROM settings and the CoE
//! object dictionary. [`Device::to_sii`] builds the SII EEPROM image a device programmed from
//! this description would carry. Every error names the line and column in the XML.
//!
//! The reader is the `xml` feature (on by default, with roxmltree); without it the crate is
//! the descriptions alone, which is what the master compiles.
mod build;
mod dictionary;
#[cfg(feature = "xml")]
mod dictionary_xml;
mod modular;
mod number;
#[cfg(feature = "xml")]
mod parse;
#[cfg(feature = "xml")]
mod soe_init;
#[cfg(feature = "xml")]
pub mod text;

pub use build::coe_data_type;
pub use dictionary::{Access, DataType, Dictionary, Object, SubObject};
pub use modular::{Depend, ModuleDesc, SlotDesc, Slots};
pub use number::parse_number;

/// The place (line, column, from 1) just past the end of `text`: where an XML reader's "ended
/// too soon" belongs (roxmltree says line 1, column 1 for those), for a truncated file.
pub fn end_of_text(text: &str) -> (u32, u32) {
    let line = text.matches('\n').count() as u32 + 1;
    let column = text.rsplit('\n').next().map_or(0, |l| l.chars().count()) as u32 + 1;
    (line, column)
}

/// An error in an ESI file, with its 1-based line and column.
#[derive(Debug, Clone, PartialEq, Eq, thiserror::Error)]
#[error("line {line}, column {column}: {message}")]
pub struct EsiError {
    pub line: u32,
    pub column: u32,
    pub message: String,
}

#[derive(Debug, Clone, PartialEq, Eq)]
pub struct EsiFile {
    pub vendor_id: u32,
    pub vendor_name: String,
    pub devices: Vec<Device>,
    /// The modules of modular devices (`<Descriptions><Modules>`).
    pub modules: Vec<ModuleDesc>,
    /// What the file does that ETG.2000 does not allow but vendors' tools accept, each read
    /// as the message says.
    pub warnings: Vec<EsiError>,
    /// Passive devices: a `<Device>` whose `<Type>` has neither product code nor revision (an
    /// end terminal without an ESC, such as Beckhoff's EL9010), listed and not described.
    pub passive: Vec<PassiveDevice>,
}

/// A device the file names that has no EtherCAT identity (no ESC): nothing to simulate or
/// configure.
#[derive(Debug, Clone, PartialEq, Eq, Default)]
pub struct PassiveDevice {
    /// Line of the `<Device>` element.
    pub line: u32,
    /// The `<Type>` text.
    pub type_name: String,
    /// The English `<Name>`, or the first one.
    pub name: String,
}

#[derive(Debug, Clone, PartialEq, Eq, Default)]
pub struct Device {
    /// Line of the `<Device>` element, for messages.
    pub line: u32,
    /// The `<Type>` text, e.g. "EK1100" (used as the order number).
    pub type_name: String,
    /// The English `<Name>`, or the first one.
    pub name: String,
    pub product_code: u32,
    pub revision: u32,
    /// Physics attribute: one character per port ('Y' 100BASE-TX, 'K' E-Bus, ...).
    pub physics: String,
    pub group_type: String,
    pub profile_no: Option<u32>,
    pub fmmus: Vec<FmmuKind>,
    pub sync_managers: Vec<SmDesc>,
    pub rx_pdos: Vec<PdoDesc>,
    pub tx_pdos: Vec<PdoDesc>,
    pub mailbox: Option<MailboxDesc>,
    pub dc_op_modes: Vec<DcOpModeDesc>,
    pub eeprom: Option<EepromDesc>,
    /// E-Bus current in mA (negative: supplied).
    pub ebus_current_ma: i16,
    pub dictionary: Option<Dictionary>,
    /// Where modules plug in, for a modular device.
    pub slots: Option<Slots>,
    /// The modules plugged, slot by slot (their idents), in a device made by
    /// [`Device::plugged`]; empty otherwise.
    pub modules: Vec<u32>,
    /// The CoE commands a master sends at state transitions (`<Mailbox><CoE><InitCmd>`), with
    /// the plugged modules' after the device's own in a device made by [`Device::plugged`].
    pub init_cmds: Vec<InitCmd>,
    /// The SoE commands a master sends at state transitions (`<Mailbox><SoE><InitCmd>`), the
    /// plugged modules' after the device's own.
    pub soe_init_cmds: Vec<SoeInitCmd>,
}

/// An SoE write of an IDN that a master sends at a state transition (`<Mailbox><SoE><InitCmd>`,
/// ETG.2000; the elements are those of an ENI's SoE init command, ETG.2100).
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct SoeInitCmd {
    /// Line of the `<InitCmd>` element.
    pub line: u32,
    /// The transitions it belongs to, as written ("IP", "PS", "SO", …).
    pub transitions: Vec<String>,
    /// The drive (axis) of the device, 0–7 (`<DriveNo>`, 0 where absent).
    pub drive: u8,
    /// The IDN written.
    pub idn: ferrocat_wire::soe::Idn,
    /// The elements written (`<Elements>`, the value where absent).
    pub elements: ferrocat_wire::soe::Elements,
    /// The bytes written, as the file gives them.
    pub data: Vec<u8>,
    /// How long the drive may take to answer, in ms (`<Timeout>`), where given.
    pub timeout_ms: Option<u32>,
    pub comment: String,
}

/// A CoE SDO download a master sends at a state transition (`<InitCmd>`, ETG.2000).
#[derive(Debug, Clone, PartialEq, Eq, Default)]
pub struct InitCmd {
    /// Line of the `<InitCmd>` element.
    pub line: u32,
    /// The transitions it belongs to, as written: "IP" (INIT → PREOP), "PS" (PREOP → SAFEOP),
    /// "SO" (SAFEOP → OP), and the others of ETG.2000.
    pub transitions: Vec<String>,
    pub index: u16,
    /// Whether the index moves with the slot its module is plugged into.
    pub index_depends: Depend,
    pub subindex: u8,
    /// The bytes written, as the file gives them (little-endian for numbers).
    pub data: Vec<u8>,
    /// Written with complete access (subindex 0 onward in one transfer).
    pub complete_access: bool,
    pub comment: String,
}

#[derive(Debug, Clone, PartialEq, Eq)]
pub enum FmmuKind {
    Outputs,
    Inputs,
    MailboxState,
    Other(String),
}

#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum SmKind {
    MailboxOut,
    MailboxIn,
    Outputs,
    Inputs,
    /// Declared but without a known role.
    Unused,
}

#[derive(Debug, Clone, PartialEq, Eq)]
pub struct SmDesc {
    pub kind: SmKind,
    pub start: u16,
    pub default_size: Option<u16>,
    pub control: u8,
    pub enable: bool,
}

#[derive(Debug, Clone, PartialEq, Eq, Default)]
pub struct PdoDesc {
    pub index: u16,
    /// Whether the index moves with a module's slot.
    pub index_depends: Depend,
    pub name: String,
    /// SyncManager the PDO is assigned to by default, if any.
    pub sm: Option<u8>,
    pub fixed: bool,
    pub mandatory: bool,
    pub entries: Vec<PdoEntryDesc>,
}

impl PdoDesc {
    pub fn bit_len(&self) -> u32 {
        self.entries.iter().map(|e| e.bit_len as u32).sum()
    }
}

#[derive(Debug, Clone, PartialEq, Eq, Default)]
pub struct PdoEntryDesc {
    pub index: u16,
    /// Whether the index moves with a module's slot.
    pub index_depends: Depend,
    pub subindex: u8,
    pub bit_len: u8,
    pub name: String,
    pub data_type: String,
}

#[derive(Debug, Clone, PartialEq, Eq, Default)]
pub struct MailboxDesc {
    pub coe: Option<CoeDesc>,
    pub foe: bool,
    pub eoe: bool,
    pub soe: bool,
    pub aoe: bool,
    pub voe: bool,
}

#[derive(Debug, Clone, PartialEq, Eq, Default)]
pub struct CoeDesc {
    pub sdo_info: bool,
    pub pdo_assign: bool,
    pub pdo_config: bool,
    pub pdo_upload: bool,
    pub complete_access: bool,
}

#[derive(Debug, Clone, PartialEq, Eq, Default)]
pub struct DcOpModeDesc {
    pub name: String,
    pub description: String,
    pub assign_activate: u16,
    pub cycle_time_sync0_ns: u32,
    pub cycle_time_sync0_factor: Option<i16>,
    pub shift_time_sync0_ns: i32,
    pub cycle_time_sync1_ns: u32,
    pub cycle_time_sync1_factor: Option<i16>,
    pub shift_time_sync1_ns: i32,
}

#[derive(Debug, Clone, PartialEq, Eq, Default)]
pub struct EepromDesc {
    pub byte_size: Option<u32>,
    /// Words 0–6 of the SII header (up to 14 bytes).
    pub config_data: Vec<u8>,
    /// Bootstrap mailbox: rx offset, rx size, tx offset, tx size (8 bytes).
    pub bootstrap: Vec<u8>,
}

impl EsiFile {
    /// Parses the text of an ESI file (the `xml` feature, on by default).
    #[cfg(feature = "xml")]
    pub fn parse(xml: &str) -> Result<EsiFile, EsiError> {
        parse::parse_file(xml)
    }

    /// The module with `ident`.
    pub fn module(&self, ident: u32) -> Option<&ModuleDesc> {
        self.modules.iter().find(|m| m.ident == ident)
    }

    /// The device with `product_code` (and `revision`, if given).
    pub fn device(&self, product_code: u32, revision: Option<u32>) -> Option<&Device> {
        self.devices.iter().find(|d| d.product_code == product_code && revision.is_none_or(|r| d.revision == r))
    }
}

impl Device {
    /// How many drives (axes) an SoE device has by its file: one more than the highest drive
    /// number its SoE init commands address, and at least one. ETG.2000 gives the count no
    /// element of its own.
    pub fn soe_drives(&self) -> u8 {
        self.soe_init_cmds.iter().map(|c| c.drive).max().map_or(1, |d| d.saturating_add(1))
    }

    /// The modules a modular device has by default: each slot's default module, as many
    /// times as the slot's minimum and at least once; `None` where a slot needs a module and
    /// names no default.
    pub fn default_modules(&self) -> Option<Vec<u32>> {
        let slots = self.slots.as_ref()?;
        let mut out = Vec::new();
        for s in &slots.slots {
            // A slot's default module is plugged (ETG.2000: `Default` marks the module plugged
            // by default), at least once even where the slot may stay empty (MinInstances 0,
            // as a drive's optional axes write it).
            let n = match s.default_module {
                Some(_) => s.min_instances.max(1),
                None if s.min_instances > 0 => return None,
                None => 0,
            };
            out.extend(std::iter::repeat_n(s.default_module.unwrap_or(0), n as usize));
        }
        Some(out)
    }

    /// This modular device with `idents` plugged into its slots in order (a slot of up to N
    /// instances takes up to N modules): each module's PDOs added at the indices of its slot
    /// (ETG.5001's `DependOnSlot` arithmetic, [`ModuleDesc::pdos_in_slot`]). The error says
    /// which slot refused which module, or how many modules the slots take.
    pub fn plugged(&self, modules: &[ModuleDesc], idents: &[u32]) -> Result<Device, String> {
        let slots = self.slots.as_ref().ok_or_else(|| format!("{} has no slots", self.type_name))?;
        let (min, max): (usize, usize) =
            slots.slots.iter().fold((0, 0), |(a, b), s| (a + s.min_instances as usize, b + s.max_instances as usize));
        if idents.len() < min || idents.len() > max {
            return Err(format!("{} takes {min} to {max} modules, {} given", self.type_name, idents.len()));
        }
        let mut dev = self.clone();
        dev.modules = idents.to_vec();
        // Slot instances in order: every slot its minimum, the modules beyond the minima to the
        // first slots with room.
        let mut extra = idents.len() - min;
        let mut plan = Vec::new();
        for s in &slots.slots {
            let more = extra.min((s.max_instances - s.min_instances) as usize);
            extra -= more;
            plan.extend(std::iter::repeat_n(s, s.min_instances as usize + more));
        }
        for (n, (&ident, slot)) in idents.iter().zip(plan).enumerate() {
            let m = modules.iter().find(|m| m.ident == ident).ok_or_else(|| {
                format!(
                    "slot {n}: no module with ident {ident:#010x} in the file or an <EtherCATModule> file beside it"
                )
            })?;
            if !slot.fits(m) {
                return Err(format!(
                    "slot {n} ({}): module {} ({ident:#010x}) does not fit it",
                    slot.name, m.type_name
                ));
            }
            let group = slot.slot_group.unwrap_or(0);
            let (rx, tx) = m.pdos_in_slot(slots, n as u16, group);
            dev.rx_pdos.extend(rx);
            dev.tx_pdos.extend(tx);
            dev.init_cmds.extend(m.init_cmds_in_slot(slots, n as u16, group));
            dev.soe_init_cmds.extend(m.soe_init_cmds.iter().cloned());
            let objects = m.objects_in_slot(slots, n as u16, group);
            if !objects.is_empty() {
                let dict = dev.dictionary.get_or_insert_with(Dictionary::default);
                for t in m.dictionary.iter().flat_map(|d| &d.data_types) {
                    if dict.data_type(&t.name).is_none() {
                        dict.data_types.push(t.clone());
                    }
                }
                // An index the device (or an earlier slot) has already keeps its first object.
                for o in objects {
                    if dict.object(o.index).is_none() {
                        dict.objects.push(o);
                    }
                }
            }
        }
        Ok(dev)
    }

    /// The SII image this description implies, filled to the EEPROM size with 0xFF.
    pub fn to_sii(&self, vendor_id: u32) -> Result<Vec<u8>, ferrocat_wire::Error> {
        let mut info = self.sii_info(vendor_id);
        let size = build::eeprom_size(self, &info);
        // Without an <Eeprom><ByteSize>, word 0x3E says the EEPROM the image is built for (in
        // KiBit minus one), so that a master reading as far as it says reads every category.
        if info.header.eeprom_size_bytes() < size {
            info.header.eeprom_size = ((size as u64 * 8 / 1024).max(1) - 1).min(u16::MAX as u64) as u16;
        }
        info.to_image_sized(size)
    }

    /// The owned SII description this device implies.
    pub fn sii_info(&self, vendor_id: u32) -> ferrocat_wire::sii::SiiInfo {
        build::sii_info(self, vendor_id)
    }
}
