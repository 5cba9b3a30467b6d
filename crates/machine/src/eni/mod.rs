//! EtherCAT Network Information (ETG.2100): the expected network as a configuration tool
//! exported it.
//!
//! [`Eni::parse`] reads what a master needs to bring the network up and run it as the tool
//! planned: the master's settings and init commands, every slave's identity, addresses,
//! process data (SyncManagers, PDOs and their place in the image), mailbox and its CoE init
//! commands, register init commands per transition (with validation and timeouts), DC
//! settings, the cyclic frames with their datagrams, expected working counters and image
//! offsets, and the process image's variables. Elements it does not use (EoE settings, hot
//! connect, copy infos) are passed over.
//!
//! What TwinCAT and other tools write but the schema does not is read with a [`Warning`]:
//! numbers as `0x…` or `#x…` where the schema wants decimal, surrounding white space, hex data
//! of odd length, booleans in another case, an 8-bit encoding. Every error names line and
//! column.
mod device;
mod read;

use ferrocat_wire::register::AlState;
use ferrocat_wire::Command;
use serde::Serialize;

pub use crate::compare::Identity;
use crate::{Place, Warning};

/// An error in an ENI file: where, and what.
#[derive(Debug, Clone, PartialEq, Eq, thiserror::Error)]
#[error("{place}: {message}")]
pub struct EniError {
    /// Where (line 1, column 1 for a file that is no text).
    pub place: Place,
    /// What is wrong.
    pub message: String,
}

/// A whole ENI file.
#[derive(Debug, Clone, PartialEq, Eq, Serialize)]
pub struct Eni {
    /// The master's settings.
    pub master: MasterConfig,
    /// The slaves, in the order of the network (position 0 first).
    pub slaves: Vec<Slave>,
    /// The cyclic tasks, each with its frames.
    pub cyclic: Vec<Cyclic>,
    /// The process image the cyclic frames' data land in.
    pub process_image: ProcessImage,
    /// What the file does that the schema does not, in file order.
    pub warnings: Vec<Warning>,
}

/// `<Config><Master>`.
#[derive(Debug, Clone, Default, PartialEq, Eq, Serialize)]
pub struct MasterConfig {
    /// `<Info><Name>`.
    pub name: String,
    /// The destination MAC address of the master's frames.
    pub destination: Option<[u8; 6]>,
    /// The source MAC address of the master's frames.
    pub source: Option<[u8; 6]>,
    /// The logical address and count of the mailbox state bits (`<MailboxStates>`): one bit a
    /// slave whose send mailbox is full, read by a cyclic LRD.
    pub mailbox_states: Option<(u32, u16)>,
    /// The master's own init commands (broadcasts before and after the slaves').
    pub init_cmds: Vec<InitCmd>,
}

/// `<Config><Slave>`.
#[derive(Debug, Clone, PartialEq, Eq, Serialize)]
pub struct Slave {
    /// Where the element starts.
    pub place: Place,
    /// `<Info><Name>`: the name the configuration tool gave it.
    pub name: String,
    /// What it must be.
    pub identity: Identity,
    /// The station address the init commands give it and address it by (`<PhysAddr>`).
    pub station: Option<u16>,
    /// Its auto-increment address (`<AutoIncAddr>`: 0 for the first, then 0xFFFF, 0xFFFE, …).
    pub auto_inc: Option<u16>,
    /// Its ports' physics, one letter a port (`Y` 100BASE-TX, `K` E-Bus).
    pub physics: Option<String>,
    /// The order number and revision TwinCAT adds (`<ProductRevision>`: `EL2008-0000-0018`),
    /// where given.
    pub product_revision: Option<String>,
    /// Process data.
    pub process_data: ProcessData,
    /// The mailbox, if it has one.
    pub mailbox: Option<Mailbox>,
    /// Register init commands, in file order.
    pub init_cmds: Vec<InitCmd>,
    /// The port and station of the slave before it (`<PreviousPort Selected="true">`).
    pub previous_port: Option<(char, u16)>,
    /// Distributed clocks.
    pub dc: Option<Dc>,
}

/// `<ProcessData>`: where the slave's data sit in the image and how they are mapped.
#[derive(Debug, Clone, Default, PartialEq, Eq, Serialize)]
pub struct ProcessData {
    /// Its outputs in the output image (`<Send>`): first bit and bits.
    pub send: Option<BitRange>,
    /// Its inputs in the input image (`<Recv>`): first bit and bits.
    pub recv: Option<BitRange>,
    /// Its process-data SyncManagers (`<Sm0>`…`<Sm15>`).
    pub sms: Vec<ProcessSm>,
    /// Outputs (`<RxPdo>`).
    pub rx_pdos: Vec<Pdo>,
    /// Inputs (`<TxPdo>`).
    pub tx_pdos: Vec<Pdo>,
}

/// A range of bits in the process image.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize)]
pub struct BitRange {
    /// First bit.
    pub start: u32,
    /// Bits.
    pub length: u32,
}

/// A SyncManager of process data.
#[derive(Debug, Clone, PartialEq, Eq, Serialize)]
pub struct ProcessSm {
    /// Its number (the `N` of `<SmN>`).
    pub number: u8,
    /// `Outputs` or `Inputs` (as written).
    pub kind: String,
    /// Physical start address.
    pub start: u16,
    /// Its control byte (0x0804's first byte).
    pub control: u8,
    /// Enabled.
    pub enable: bool,
    /// Bytes by default.
    pub default_size: Option<u16>,
    /// The PDOs assigned to it, by index.
    pub pdos: Vec<u16>,
}

/// A PDO and its entries.
#[derive(Debug, Clone, PartialEq, Eq, Serialize)]
pub struct Pdo {
    /// The PDO's index.
    pub index: u16,
    /// Its name.
    pub name: String,
    /// The SyncManager it is assigned to (`Sm="…"`), none where it is only possible.
    pub sm: Option<u8>,
    /// Its mapping cannot be changed.
    pub fixed: bool,
    /// The entries, in order (index 0: a gap of `bits`).
    pub entries: Vec<PdoEntry>,
}

/// A PDO entry.
#[derive(Debug, Clone, PartialEq, Eq, Serialize)]
pub struct PdoEntry {
    /// Object index (0 for a gap).
    pub index: u16,
    /// Subindex.
    pub subindex: u8,
    /// Bits.
    pub bits: u16,
    /// Its name (empty for a gap).
    pub name: String,
    /// Its data type name (`UINT`, `DINT`, …), where given.
    pub data_type: Option<String>,
}

/// `<Mailbox>`.
#[derive(Debug, Clone, PartialEq, Eq, Serialize)]
pub struct Mailbox {
    /// The master's mailbox to the slave (`<Send>`: SM0): start and bytes.
    pub send: (u16, u16),
    /// The slave's mailbox to the master (`<Recv>`: SM1): start and bytes.
    pub recv: (u16, u16),
    /// How often to poll the slave's mailbox, where given (`<Recv><PollTime>`), ms.
    pub poll_time_ms: Option<u32>,
    /// The bootstrap mailboxes (send, receive), where given.
    pub bootstrap: Option<((u16, u16), (u16, u16))>,
    /// The protocols, as written (`CoE`, `FoE`, `EoE`, `SoE`, `AoE`, `VoE`).
    pub protocols: Vec<String>,
    /// CoE init commands, in file order.
    pub coe_init_cmds: Vec<CoeInitCmd>,
    /// SoE init commands, in file order (`<SoE><InitCmds>`): IDN writes to a drive.
    pub soe_init_cmds: Vec<SoeInitCmd>,
    /// The device profile (`<CoE><Profile><ChannelInfo><ProfileNo>`: 402 for a drive).
    pub profile_no: Option<u32>,
}

/// An AL state transition, as ENI files write them: two letters, from and to (`IP`: INIT to
/// PREOP; `B` is BOOT).
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct Transition {
    /// From.
    pub from: AlState,
    /// To.
    pub to: AlState,
}

impl Transition {
    /// Reads `IP`, `PS`, `SO`, … (`None` for anything else).
    pub fn parse(s: &str) -> Option<Transition> {
        let state = |c: u8| match c {
            b'I' => Some(AlState::Init),
            b'P' => Some(AlState::PreOp),
            b'B' => Some(AlState::Bootstrap),
            b'S' => Some(AlState::SafeOp),
            b'O' => Some(AlState::Op),
            _ => None,
        };
        match s.as_bytes() {
            [a, b] => Some(Transition { from: state(*a)?, to: state(*b)? }),
            _ => None,
        }
    }
}

impl Serialize for Transition {
    fn serialize<S: serde::Serializer>(&self, s: S) -> Result<S::Ok, S::Error> {
        s.collect_str(self)
    }
}

impl std::fmt::Display for Transition {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        let letter = |s: AlState| match s {
            AlState::Init => 'I',
            AlState::PreOp => 'P',
            AlState::Bootstrap => 'B',
            AlState::SafeOp => 'S',
            AlState::Op => 'O',
        };
        write!(f, "{}{}", letter(self.from), letter(self.to))
    }
}

/// Where a datagram goes.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize)]
pub enum Target {
    /// A position or station address and a register (`<Adp>`, `<Ado>`).
    Device {
        /// Auto-increment position or station address.
        adp: u16,
        /// Register.
        ado: u16,
    },
    /// A logical address (`<Addr>`).
    Logical(u32),
}

/// A register init command.
#[derive(Debug, Clone, PartialEq, Eq, Serialize)]
pub struct InitCmd {
    /// Where it starts in the file.
    pub place: Place,
    /// The transitions it belongs to.
    pub transitions: Vec<Transition>,
    /// For the master's: before the slaves' commands of the transition (else after).
    pub before_slave: bool,
    /// What it does, as the tool said.
    pub comment: String,
    /// `cycle` or `frame`, where given.
    pub requires: Option<String>,
    /// The datagram's command.
    #[serde(serialize_with = "command_code")]
    pub command: Command,
    /// Where it goes.
    pub target: Target,
    /// Its data (zeros of `<DataLength>` where it gives a length only).
    pub data: Vec<u8>,
    /// The working counter it must come back with, where given.
    pub cnt: Option<u16>,
    /// How often it may be sent again when it fails.
    pub retries: u16,
    /// How long it may take, where given, ms.
    pub timeout_ms: Option<u32>,
    /// What the answer must read, where given.
    pub validate: Option<Validate>,
}

/// `<Validate>`: the answer's data, masked, must equal `data` within `timeout_ms`.
#[derive(Debug, Clone, PartialEq, Eq, Serialize)]
pub struct Validate {
    /// The value.
    pub data: Vec<u8>,
    /// The mask (all ones where not given).
    pub mask: Option<Vec<u8>>,
    /// How long the master reads again until it does, ms.
    pub timeout_ms: Option<u32>,
}

/// A CoE init command: an SDO download (or upload) in a transition.
#[derive(Debug, Clone, PartialEq, Eq, Serialize)]
pub struct CoeInitCmd {
    /// Where it starts in the file.
    pub place: Place,
    /// The transitions it belongs to.
    pub transitions: Vec<Transition>,
    /// What it does, as the tool said.
    pub comment: String,
    /// The client command specifier: 1 download, 2 upload.
    pub ccs: u8,
    /// Object index.
    pub index: u16,
    /// Subindex.
    pub subindex: u8,
    /// The whole object at once.
    pub complete_access: bool,
    /// The data.
    pub data: Vec<u8>,
    /// The tool generated it from the mapping (`Fixed="true"`).
    pub fixed: bool,
    /// How long it may take, where given (0: the master's default), ms.
    pub timeout_ms: Option<u32>,
}

/// An SoE init command (`<Mailbox><SoE><InitCmds><InitCmd>`, ETG.2100): an IDN written to one
/// of the device's drives in a transition, as TwinCAT writes an AX5000's startup list.
#[derive(Debug, Clone, PartialEq, Eq, Serialize)]
pub struct SoeInitCmd {
    /// Where it starts in the file.
    pub place: Place,
    /// The transitions it belongs to.
    pub transitions: Vec<Transition>,
    /// What it does, as the tool said.
    pub comment: String,
    /// The drive (axis) of the device, 0–7 (`<DriveNo>`).
    pub drive: u8,
    /// The IDN (S-0-0015 is 15, P-0-0001 is 0x8001).
    pub idn: u16,
    /// The elements written (`<Elements>`: 0x40 the value).
    pub elements: u8,
    /// The data, as the file gives them.
    pub data: Vec<u8>,
    /// The tool generated it from the mapping (`Fixed="true"`).
    pub fixed: bool,
    /// How long it may take, where given (0: the master's default), ms.
    pub timeout_ms: Option<u32>,
}

/// `<DC>`.
#[derive(Debug, Clone, Copy, Default, PartialEq, Eq, Serialize)]
pub struct Dc {
    /// The slave is the reference clock.
    pub reference_clock: bool,
    /// SYNC0's cycle, ns (0: SYNC0 off).
    pub cycle_time0_ns: u32,
    /// SYNC1's cycle, ns.
    pub cycle_time1_ns: u32,
    /// SYNC0's shift from the cycle's start, ns.
    pub shift_time_ns: i32,
}

/// `<Cyclic>`: a task's frames.
#[derive(Debug, Clone, PartialEq, Eq, Serialize)]
pub struct Cyclic {
    /// Its cycle, µs, where given.
    pub cycle_time_us: Option<u32>,
    /// Its frames, sent each cycle.
    pub frames: Vec<CyclicFrame>,
}

/// A cyclic frame: its datagrams, in order.
#[derive(Debug, Clone, PartialEq, Eq, Serialize)]
pub struct CyclicFrame {
    /// The datagrams.
    pub cmds: Vec<CyclicCmd>,
}

/// A datagram of a cyclic frame.
#[derive(Debug, Clone, PartialEq, Eq, Serialize)]
pub struct CyclicCmd {
    /// Where it starts in the file.
    pub place: Place,
    /// The AL states in which it is sent.
    #[serde(serialize_with = "state_names")]
    pub states: Vec<AlState>,
    /// What it does, as the tool said.
    pub comment: String,
    /// The command.
    #[serde(serialize_with = "command_code")]
    pub command: Command,
    /// Where it goes.
    pub target: Target,
    /// Bytes of data.
    pub data_length: u16,
    /// The working counter a whole cycle gives, where given.
    pub cnt: Option<u16>,
    /// Where the datagram sits in the input image, bytes from its start (the image mirrors the
    /// frames: the datagram's 10-byte header first, then its data).
    pub input_offs: Option<u32>,
    /// Where it sits in the output image, likewise.
    pub output_offs: Option<u32>,
    /// Slave-to-slave copies made once its frame is back (`<CopyInfos>`).
    pub copies: Vec<CopyInfo>,
}

/// `<CopyInfo>`: bits of the input image copied into the output image, for the next cycle to
/// send (slave-to-slave communication through the master).
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize)]
pub struct CopyInfo {
    /// First bit in the input image.
    pub src_bit: u32,
    /// First bit in the output image.
    pub dst_bit: u32,
    /// Bits.
    pub bits: u32,
}

/// `<ProcessImage>`.
#[derive(Debug, Clone, Default, PartialEq, Eq, Serialize)]
pub struct ProcessImage {
    /// Input image bytes and variables.
    pub inputs: ImageArea,
    /// Output image bytes and variables.
    pub outputs: ImageArea,
}

/// One direction of the process image.
#[derive(Debug, Clone, Default, PartialEq, Eq, Serialize)]
pub struct ImageArea {
    /// Bytes.
    pub byte_size: u32,
    /// Named variables.
    pub variables: Vec<Variable>,
}

/// A named variable of the process image.
#[derive(Debug, Clone, PartialEq, Eq, Serialize)]
pub struct Variable {
    /// Its name (TwinCAT: `Slave.PDO.Entry`).
    pub name: String,
    /// Its data type name, where given.
    pub data_type: Option<String>,
    /// Bits.
    pub bit_size: u32,
    /// Bit offset in its image.
    pub bit_offs: u32,
}

fn state_names<S: serde::Serializer>(states: &[AlState], s: S) -> Result<S::Ok, S::Error> {
    s.collect_seq(states.iter().map(|st| st.name()))
}

fn command_code<S: serde::Serializer>(c: &Command, s: S) -> Result<S::Ok, S::Error> {
    s.serialize_str(c.name().unwrap_or("?"))
}

impl Eni {
    /// Reads an ENI file's bytes (UTF-8, or the encoding its XML declaration names),
    /// leniently: each departure from the schema is a warning in [`Eni::warnings`].
    pub fn parse(bytes: &[u8]) -> Result<Eni, EniError> {
        let start = Place { line: 1, column: 1 };
        let (text, note) = ferrocat_esi::text::decode(bytes).map_err(|message| EniError { place: start, message })?;
        let mut eni = read::read(&text)?;
        if let Some(n) = note {
            eni.warnings.insert(0, Warning { place: start, message: format!("not UTF-8: {n}") });
        }
        Ok(eni)
    }

    /// [`Eni::parse`], refusing a file with any departure from the schema (the first is the
    /// error).
    pub fn parse_strict(bytes: &[u8]) -> Result<Eni, EniError> {
        let eni = Self::parse(bytes)?;
        match eni.warnings.first() {
            Some(w) => Err(EniError { place: w.place, message: format!("{} (refused: strict)", w.message) }),
            None => Ok(eni),
        }
    }

    /// The identities the slaves must have, in order, for [`crate::compare()`]: vendor, product
    /// and revision exactly. Not the serial number: an ENI holds what its tool scanned, and a
    /// unit replaced by another of the same type would differ.
    pub fn expected(&self) -> Vec<crate::Expected> {
        self.slaves
            .iter()
            .enumerate()
            .map(|(k, s)| crate::Expected {
                position: k as u16,
                name: s.name.clone(),
                identity: s.identity,
                revision: crate::compare::RevisionCheck::Exact,
                check_serial: false,
                alias: None,
                optional: false,
            })
            .collect()
    }
}
