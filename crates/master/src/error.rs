//! What can go wrong, each error naming what and where.
use ferrocat_wire::coe::AbortCode;
use ferrocat_wire::mailbox::{MailboxErrorCode, MailboxType};
use ferrocat_wire::register::{AlState, AlStatusCode};

/// A slave as errors name it: its position on the segment, from 0, and its name from the SII
/// ("?" where the SII could not be read).
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct SlaveRef {
    /// Position on the segment, from 0.
    pub position: u16,
    /// The slave's name from its SII.
    pub name: String,
}

impl std::fmt::Display for SlaveRef {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        write!(f, "slave {} ({})", self.position, self.name)
    }
}

/// What a slave did, or lacks, as a value: the mailbox and its protocols, its SII, its
/// process-data entries, its addresses.
#[derive(Debug, thiserror::Error)]
#[non_exhaustive]
pub enum SlaveError {
    /// Its SII gives no mailbox.
    #[error("has no mailbox")]
    NoMailbox,
    /// Its mailbox was asked for while the slave is in INIT, where the master has not set its
    /// SyncManagers up (`States::configure` takes it to PREOP).
    #[error("its mailbox is not set up in INIT: configure the slaves first (PREOP)")]
    MailboxInInit,
    /// Its SII does not name the mailbox protocol.
    #[error("does not support {}", .0.name())]
    Unsupported(MailboxType),
    /// Its receive mailbox stayed full for the whole mailbox timeout.
    #[error("mailbox stays full")]
    MailboxFull,
    /// A request longer than its receive mailbox.
    #[error("request of {len} bytes exceeds the {mailbox}-byte mailbox")]
    RequestTooLong {
        /// The request's bytes.
        len: usize,
        /// The mailbox's bytes.
        mailbox: usize,
    },
    /// No reply in its send mailbox within the mailbox timeout.
    #[error("no mailbox reply (timeout)")]
    NoReply,
    /// A datagram addressed to the slave came back with working counter 0.
    #[error("does not answer at its station address")]
    NotAnswering,
    /// A reply that does not parse.
    #[error("mailbox reply: {0}")]
    MalformedReply(ferrocat_wire::Error),
    /// A mailbox error reply that does not parse.
    #[error("mailbox error reply: {0}")]
    MalformedErrorReply(ferrocat_wire::Error),
    /// A mailbox error reply (ETG.1000.4 Table 30).
    #[error("{0}")]
    MailboxError(MailboxErrorCode),
    /// A reply of a kind the request does not take, as it was read.
    #[error("unexpected reply {0}")]
    UnexpectedReply(String),
    /// A segmented SDO upload whose toggle bit did not alternate.
    #[error("segment toggle bit out of step")]
    ToggleOutOfStep,
    /// Its SII image does not parse.
    #[error("SII: {0}")]
    Sii(ferrocat_wire::Error),
    /// An EEPROM word write the ESC reported failed (0x0502's error bits).
    #[error("EEPROM write of word {word:#x} failed (status {status:#06x})")]
    EepromWrite {
        /// The word address.
        word: u32,
        /// The SII control/status register after the write.
        status: u16,
    },
    /// An image with more data than the EEPROM holds (its SII word 0x3E): nothing written.
    #[error("the image holds {image} bytes of data, its EEPROM {eeprom} (SII word 0x3E): nothing written")]
    EepromTooSmall {
        /// Bytes of the image up to its last byte that is not 0xFF.
        image: usize,
        /// The EEPROM's bytes.
        eeprom: usize,
    },
    /// No output entry of that name in its process data.
    #[error("no output named '{0}'")]
    NoOutput(String),
    /// No input entry of that name in its process data.
    #[error("no input named '{0}'")]
    NoInput(String),
    /// Its EEPROM gives no station alias (0x0012 is 0).
    #[error("has no station alias")]
    NoAlias,
    /// Another slave on the segment has the same station alias.
    #[error("alias {0:#06x} is not unique on this segment")]
    AliasNotUnique(u16),
    /// Its SII gives no bootstrap mailbox, which FoE firmware updates need.
    #[error("its SII gives no bootstrap mailbox")]
    NoBootstrapMailbox,
    /// A DC slave with receive times only was asked for SYNC0.
    #[error("has receive times only (no DC system time): no SYNC0 there")]
    NoSystemTime,
    /// A calibration pulse asked of a slave without a DC system time to latch it.
    #[error("has no DC system time to latch the calibration pulse")]
    NoLatchTime,
    /// Its SII interface did not acknowledge a read (0x0502 bit 13).
    #[error("SII read not acknowledged")]
    SiiNotAcknowledged,
    /// Its SII interface stayed busy past the timeout.
    #[error("EEPROM stays busy")]
    EepromBusy,
    /// An SDO the configuration sends (an ESI init command or a plan's) failed.
    #[error("{}", config_sdo(origin, *index, *subindex, comment, error))]
    ConfigSdo {
        /// Where the SDO came from.
        origin: SdoSource,
        /// The object's index.
        index: u16,
        /// The object's subindex.
        subindex: u8,
        /// Its comment in the description.
        comment: String,
        /// What went wrong: an abort with its code, a mailbox failure.
        error: Box<MasterError>,
    },
    /// An SoE init command the configuration sends (an ESI's or the application's) failed.
    #[error("{}", config_idn(origin, *drive, *idn, comment, error))]
    ConfigIdn {
        /// Where the command came from.
        origin: SdoSource,
        /// The drive (axis) of the device.
        drive: u8,
        /// The IDN written.
        idn: ferrocat_wire::soe::Idn,
        /// Its comment in the description.
        comment: String,
        /// What went wrong: the drive's SoE error, a mailbox failure.
        error: Box<MasterError>,
    },
    /// Modular devices (ETG.5001): the modules configured and detected.
    #[error("{0}")]
    Modules(ModuleError),
    /// A file transfer (FoE) failed.
    #[error("FoE '{file}': {error}")]
    Foe {
        /// The file's name.
        file: String,
        /// What went wrong.
        error: FoeError,
    },
    /// A receive mailbox too small to carry any FoE data.
    #[error("FoE: a {0}-byte mailbox carries no data")]
    FoeMailboxTooSmall(u16),
    /// Ethernet over EtherCAT failed.
    #[error("EoE{0}")]
    Eoe(EoeError),
    /// A CiA402 drive's process data or state.
    #[error("{0}")]
    Cia402(Cia402Error),
    /// An SoE drive refused a read or write of an IDN.
    #[error("SoE {idn} (drive {drive}): {error}")]
    Soe {
        /// The IDN.
        idn: ferrocat_wire::soe::Idn,
        /// The drive (axis) of the device.
        drive: u8,
        /// The drive's error code.
        error: ferrocat_wire::soe::SoeError,
    },
}

/// Where a command the configuration sends (an SDO, an SoE write) came from.
#[derive(Debug, Clone, PartialEq, Eq)]
pub enum SdoSource {
    /// An ESI init command, at a transition ("PS"), from the file's line.
    EsiInitCommand {
        /// The transition, as the ESI names it.
        transition: String,
        /// The line of the ESI file.
        line: u32,
    },
    /// A process-data plan's SDO.
    Plan,
    /// An init command the application gave (`Config::setup_mut`: a machine
    /// description's), at a transition, from the description's line.
    Description {
        /// The transition ("PS").
        transition: String,
        /// The line of the description.
        line: u32,
    },
}

/// A command's error as the slave's own: the slave is named once, before the command.
fn own(error: &MasterError) -> String {
    match error {
        MasterError::Slave { error, .. } => error.to_string(),
        MasterError::Abort { code, .. } => format!("aborted: {code}"),
        other => other.to_string(),
    }
}

fn config_sdo(source: &SdoSource, index: u16, subindex: u8, comment: &str, error: &MasterError) -> String {
    match source {
        SdoSource::EsiInitCommand { transition, line } => {
            format!(
                "ESI init command {transition} {index:#06x}:{subindex:#04x} ({comment:?}, line {line}): {}",
                own(error)
            )
        }
        SdoSource::Plan => format!("plan SDO {index:#06x}:{subindex:#04x} ({comment}): {}", own(error)),
        SdoSource::Description { transition, line } => {
            format!("init command {transition} {index:#06x}:{subindex:#04x} ({comment:?}, line {line}): {}", own(error))
        }
    }
}

fn config_idn(
    source: &SdoSource,
    drive: u8,
    idn: ferrocat_wire::soe::Idn,
    comment: &str,
    error: &MasterError,
) -> String {
    match source {
        SdoSource::EsiInitCommand { transition, line } => {
            format!("ESI SoE init command {transition} {idn} drive {drive} ({comment:?}, line {line}): {}", own(error))
        }
        SdoSource::Plan => format!("plan IDN {idn} drive {drive} ({comment}): {}", own(error)),
        SdoSource::Description { transition, line } => {
            format!("SoE init command {transition} {idn} drive {drive} ({comment:?}, line {line}): {}", own(error))
        }
    }
}

/// What a modular device (ETG.5001) got wrong.
#[derive(Debug, Clone, PartialEq, Eq, thiserror::Error)]
#[non_exhaustive]
pub enum ModuleError {
    /// More modules than 0xF030 holds.
    #[error("{0} modules: 0xF030 holds 255")]
    TooMany(usize),
    /// An entry of 0xF050 (detected modules) that is no 32-bit ident.
    #[error("0xF050:{subindex:#04x} is {len} bytes, not 4")]
    DetectedEntry {
        /// The entry's subindex.
        subindex: u8,
        /// Its bytes.
        len: usize,
    },
    /// The module configured in a slot is not the one detected there.
    #[error("slot {slot}: module {} configured, {} detected (0xF050 lists {detected_count} modules)", ident(*configured), ident(*detected))]
    Mismatch {
        /// The slot, from 0.
        slot: usize,
        /// The module ident configured there, if any.
        configured: Option<u32>,
        /// The module ident detected there, if any.
        detected: Option<u32>,
        /// How many modules 0xF050 lists.
        detected_count: usize,
    },
}

fn ident(v: Option<u32>) -> String {
    v.map_or("none".to_string(), |m| format!("{m:#010x}"))
}

/// What a file transfer (FoE) ran into.
#[derive(Debug, Clone, PartialEq, Eq, thiserror::Error)]
#[non_exhaustive]
pub enum FoeError {
    /// The slave answered with an FoE error (ETG.1000.6 Table 92), and its text where it gave
    /// one beyond the code's name.
    #[error("{code}{}", text.as_ref().map(|t| format!(": {t}")).unwrap_or_default())]
    Refused {
        /// The FoE error code.
        code: ferrocat_wire::foe::FoeErrorCode,
        /// Its text.
        text: Option<String>,
    },
    /// A reply of another kind than expected, as it was read.
    #[error("{reply} where {expected} was expected")]
    Unexpected {
        /// The reply.
        reply: String,
        /// What was expected.
        expected: String,
    },
    /// A reply that does not decode.
    #[error("reply does not decode: {0}")]
    Undecodable(ferrocat_wire::Error),
    /// Busy answers past the limit for one packet.
    #[error("busy {times} times at packet {packet}")]
    Busy {
        /// Busy answers taken.
        times: u32,
        /// The packet.
        packet: u32,
    },
    /// A file longer than the bound the reader gave: the transfer was aborted.
    #[error("longer than {0} bytes")]
    TooLong(usize),
}

/// What Ethernet over EtherCAT ran into.
#[derive(Debug, Clone, PartialEq, Eq, thiserror::Error)]
#[non_exhaustive]
pub enum EoeError {
    /// The slave's result code for a request (ETG.1000.6 Table 48).
    #[error(" {request}: {result}")]
    Result {
        /// The request ("Set IP Parameter").
        request: &'static str,
        /// The slave's result.
        result: ferrocat_wire::eoe::EoeResult,
    },
    /// IP parameters that do not parse.
    #[error(" Get IP Parameter: {0}")]
    IpParameters(ferrocat_wire::Error),
    /// A frame that does not go through the slave's mailbox.
    #[error(": a {len}-byte frame does not go through a {mailbox}-byte mailbox (1–{max} bytes, 32 per fragment)")]
    FrameTooLong {
        /// The frame's bytes.
        len: usize,
        /// The receive mailbox's bytes.
        mailbox: u16,
        /// The longest frame EoE carries.
        max: usize,
    },
    /// A frame sent while frames queued for the pump still go out.
    #[error(": frames queued for pump are still going out")]
    Busy,
}

/// What a CiA402 drive lacks or did.
#[derive(Debug, Clone, PartialEq, Eq, thiserror::Error)]
#[non_exhaustive]
pub enum Cia402Error {
    /// An axis past the last a drive may have.
    #[error("axis {axis}: a drive has at most {max}")]
    NoSuchAxis {
        /// The axis asked for, from 0.
        axis: u8,
        /// The axes a drive may have.
        max: u8,
    },
    /// An object the driver needs that is not mapped.
    #[error("no {}{object} ({index:#06x}) in the process image", if *axis > 0 { format!("axis {axis}'s ") } else { String::new() })]
    NotMapped {
        /// The axis, from 0.
        axis: u8,
        /// The object's name.
        object: &'static str,
        /// Its index on this axis.
        index: u16,
    },
    /// A drive that did not reach its goal in time.
    #[error("CiA402: still {} after {cycles} cycles (wanted {wanted})", state.map_or("unknown", |s| s.name()))]
    Stuck {
        /// Where it stayed, where its statusword says.
        state: Option<ferrocat_wire::cia402::State>,
        /// The goal's name.
        wanted: &'static str,
        /// Cycles waited.
        cycles: u64,
    },
}

/// A datagram as errors name it: "FPRD 0x1001:0x0130 (2 bytes)".
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct DatagramRef {
    /// Its command.
    pub command: ferrocat_wire::Command,
    /// Its address.
    pub address: ferrocat_wire::Address,
    /// Its data's bytes.
    pub len: usize,
}

impl std::fmt::Display for DatagramRef {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        let (cmd, len) = (self.command, self.len);
        match self.address {
            ferrocat_wire::Address::Device { adp, ado } => write!(f, "{cmd} {adp:#06x}:{ado:#06x} ({len} bytes)"),
            ferrocat_wire::Address::Logical(a) => write!(f, "{cmd} logical {a:#010x} ({len} bytes)"),
        }
    }
}

/// A request to a running master's acyclic side ([`Acyclic::submit`](crate::part::Acyclic::submit))
/// that it cannot take.
#[derive(Debug, Clone, PartialEq, Eq, thiserror::Error)]
#[non_exhaustive]
pub enum RequestError {
    /// Too many requests wait already.
    #[error("{limit} requests wait already: try again when one is answered")]
    QueueFull {
        /// The most that may wait.
        limit: usize,
    },
    /// A register read or write longer than a datagram of its own may be.
    #[error("{len} bytes of registers: give 1 to {max}")]
    RegisterLength {
        /// The length asked for.
        len: usize,
        /// The longest allowed.
        max: usize,
    },
    /// A register range past the ESC's 64 KiB address space.
    #[error("registers {register:#06x}+{len} go past 0xffff")]
    RegisterRange {
        /// The first register.
        register: u16,
        /// The length.
        len: usize,
    },
    /// A state that a master does not request of a slave while cyclic.
    #[error("{0}: request INIT, PREOP, SAFEOP or OP")]
    State(AlState),
    /// The cycle never left room for the request's datagram: its round trip is longer than
    /// the spare time after the cyclic frame, for the mailbox timeout.
    #[error(
        "no room in the cycle for {waited_ms} ms: a round trip of {round_trip_us} µs and {spare_us} µs to spare \
         (lengthen the cycle)"
    )]
    NoRoom {
        /// How long it waited, ms.
        waited_ms: u64,
        /// The last cyclic round trip, µs.
        round_trip_us: u64,
        /// The time left in the cycle for it at the last call, µs.
        spare_us: u64,
    },
    /// The request waited longer than its time for an answer (the master's clock).
    #[error("no answer within {waited_ms} ms")]
    TimedOut {
        /// How long it waited, ms.
        waited_ms: u64,
    },
}

/// An error of the master: the link's, the segment's, a slave's, or the configuration's.
#[derive(Debug, thiserror::Error)]
pub enum MasterError {
    /// The link failed (sending, receiving, opening the interface).
    #[error(transparent)]
    Io(#[from] std::io::Error),
    /// A frame went unanswered through every retry.
    #[error("no answer to {datagram} after {tries} tries (frame lost or the segment answers nothing)")]
    Timeout {
        /// Its first datagram.
        datagram: DatagramRef,
        /// Tries made, the first included.
        tries: u32,
    },
    /// A datagram reached fewer (or more) slaves than it had to.
    #[error("working counter {got}, expected {expected}, for {datagram}{slaves}")]
    Wkc {
        /// The datagram.
        datagram: DatagramRef,
        /// The working counter it had to come back with.
        expected: u16,
        /// The working counter it came back with.
        got: u16,
        /// Which slave it was meant for, where the master knows, in words (": slave 0
        /// (EK1100, …)").
        slaves: String,
    },
    /// A reply that does not parse.
    #[error("malformed reply: {0}")]
    Frame(#[from] ferrocat_wire::Error),
    /// The segment answered, but no slave counted itself.
    #[error("no slaves found")]
    NoSlaves,
    /// A position past the last slave.
    #[error("{}", no_such_slave(*position, *count))]
    NoSuchSlave {
        /// The position asked for.
        position: u16,
        /// The slaves on the segment.
        count: usize,
    },
    /// Distributed clocks asked of a segment that cannot give them.
    #[error(transparent)]
    Dc(#[from] DcError),
    /// A slave did not reach the AL state requested.
    #[error("slave {position} ({name}) did not reach {requested}: {}", state_failure(*stayed, *code, cause))]
    State {
        /// Position on the segment, from 0.
        position: u16,
        /// The slave's name from its SII.
        name: String,
        /// The state requested.
        requested: AlState,
        /// Where it stayed (AL status 0x0130), if that is a state.
        stayed: Option<AlState>,
        /// Its AL status code (0x0134).
        code: AlStatusCode,
        /// Why the master gave up.
        cause: StateCause,
    },
    /// The slave aborted an SDO transfer.
    #[error("slave {position} ({name}): SDO {index:#06x}:{subindex:#04x} aborted: {code}")]
    Abort {
        /// Position on the segment, from 0.
        position: u16,
        /// The slave's name from its SII.
        name: String,
        /// The object's index.
        index: u16,
        /// The object's subindex.
        subindex: u8,
        /// The SDO abort code.
        code: AbortCode,
    },
    /// What a slave did wrong or lacks.
    #[error("{slave}: {error}")]
    Slave {
        /// Which slave.
        slave: SlaveRef,
        /// What, as a value.
        error: SlaveError,
    },
    /// The master was asked something its configuration does not allow.
    #[error(transparent)]
    Config(#[from] ConfigError),
    /// A request to a running master's acyclic side that it cannot take.
    #[error(transparent)]
    Request(#[from] RequestError),
    /// Receive times that a second latch could not tell apart (the named slaves').
    #[error("receive times of {} could not be latched again: the spacings of the latching frames did not tell their readings apart in {tries} tries", names(slaves))]
    Relatch {
        /// The slaves whose receive times stayed ambiguous.
        slaves: Vec<SlaveRef>,
        /// Tries made.
        tries: u32,
    },
}

fn names(slaves: &[SlaveRef]) -> String {
    slaves.iter().map(|s| s.name.as_str()).collect::<Vec<_>>().join(", ")
}

/// Which of the two images.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum ImageSide {
    /// The outputs.
    Output,
    /// The inputs.
    Input,
}

impl std::fmt::Display for ImageSide {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.write_str(match self {
            ImageSide::Output => "output",
            ImageSide::Input => "input",
        })
    }
}

/// What the master was asked that its configuration does not allow, or that the segment
/// makes impossible.
#[derive(Debug, Clone, PartialEq, Eq, thiserror::Error)]
#[non_exhaustive]
pub enum ConfigError {
    /// An SII image shorter than its header.
    #[error("SII image of {0} bytes: shorter than its 16-byte header")]
    SiiImageTooShort(usize),
    /// An SII image whose header CRC is wrong: an ESC would not load it.
    #[error(
        "SII image: header CRC at byte 14 is {found:#04x}, bytes 0–13 give {computed:#04x}; an ESC would not load it"
    )]
    SiiHeaderCrc {
        /// The CRC the image carries.
        found: u8,
        /// The CRC of its bytes 0–13.
        computed: u8,
    },
    /// Slaves on the ring that only the secondary port's frames reach in order.
    #[error("{0} slave(s) on the ring answer only frames from the secondary port: a device is entered by a port other than 0 and its port 0 leads on round the ring, so the primary's frames pass it without processing it; cable it the other way round")]
    RingCabledBackwards(u16),
    /// A group of process data that runs every 0 cycles.
    #[error("group {0}: every 0 cycles: give 1 or more")]
    GroupEveryZero(String),
    /// A group naming a position past the last slave.
    #[error("group {group}: no slave at position {position} (the segment has {count})")]
    GroupNoSuchSlave {
        /// The group.
        group: String,
        /// The position it names.
        position: u16,
        /// The slaves on the segment.
        count: usize,
    },
    /// A slave in two groups.
    #[error("slave {position} is in groups {first} and {second}: a slave's process data go in one frame")]
    SlaveInTwoGroups {
        /// The slave.
        position: u16,
        /// The first group.
        first: String,
        /// The second group.
        second: String,
    },
    /// A group with more process data than a frame carries.
    #[error("group {group}: {bytes} bytes of process data, more than one frame carries ({max})")]
    GroupTooLarge {
        /// The group.
        group: String,
        /// Its bytes.
        bytes: u32,
        /// What a frame carries.
        max: u32,
    },
    /// A datagram larger than a frame.
    #[error("{command} of {len} bytes does not fit a frame")]
    DatagramTooLarge {
        /// Its command.
        command: ferrocat_wire::Command,
        /// Its data's bytes.
        len: usize,
    },
    /// A slave-to-slave copy between entries of other widths, or of none, or of more than 64
    /// bits.
    #[error("copy {copy}: {from_bits} bits into {to_bits} bits: a copy takes 1 to 64 bits into as many")]
    CopyWidth {
        /// The copy, from 0.
        copy: usize,
        /// The source's bits.
        from_bits: u8,
        /// The destination's bits.
        to_bits: u8,
    },
    /// A slave-to-slave copy outside the image.
    #[error("copy {copy}: bits {}..{} into {}..{} of a {image_bits}-bit image", from.0, from.1, to.0, to.1)]
    CopyOutsideImage {
        /// The copy, from 0.
        copy: usize,
        /// The source's bits, start and end.
        from: (u32, u32),
        /// The destination's bits, start and end.
        to: (u32, u32),
        /// The image's bits.
        image_bits: u64,
    },
    /// A process image that more frames would carry than the cyclic exchange sends.
    #[error("process image of {bytes} bytes exceeds {max_frames} frames")]
    ImageTooLarge {
        /// The image's bytes.
        bytes: usize,
        /// The frames the exchange sends at most.
        max_frames: usize,
    },
    /// A plan's frame with more datagrams than the cyclic exchange takes.
    #[error("plan frame {frame}: {datagrams} datagrams, more than {max}")]
    PlanFrameTooLong {
        /// The frame, from 0.
        frame: usize,
        /// Its datagrams.
        datagrams: usize,
        /// The most the exchange takes.
        max: usize,
    },
    /// A plan's datagram whose data end past its image.
    #[error("plan frame {frame}, datagram {datagram}: its data end at byte {end} of the {bytes}-byte {side} image")]
    PlanDataOutsideImage {
        /// The frame, from 0.
        frame: usize,
        /// The datagram, from 0.
        datagram: usize,
        /// Where its data end.
        end: u64,
        /// The image's bytes.
        bytes: u32,
        /// Which image.
        side: ImageSide,
    },
    /// An interpolation period that 0x60C2 cannot express.
    #[error("an interpolation period of {0} ns is no u8 × 10^n s (0x60C2)")]
    InterpolationPeriod(u64),
    /// A CiA402 step asked of no axis.
    #[error("no axes")]
    NoAxes,
    /// A process-data watchdog longer than 0x0420 counts (65 535 steps of 100 µs).
    #[error("a process-data watchdog of {0} ns is longer than 0x0420 counts (6.5535 s in 100 µs steps)")]
    WatchdogTooLong(u64),
}

impl MasterError {
    /// A slave's error of a known kind.
    pub(crate) fn of(position: u16, name: &str, error: SlaveError) -> Self {
        MasterError::Slave { slave: SlaveRef { position, name: name.into() }, error }
    }
}

/// Why a state change failed.
#[derive(Debug, Clone, PartialEq, Eq)]
pub enum StateCause {
    /// The slave set AL status's error bit.
    Error,
    /// The state timeout passed.
    Timeout,
    /// Its ESC runs unconfigured: the EEPROM's configuration area did not load (the SII
    /// interface's status 0x0502, and why in words).
    EepromNotLoaded {
        /// 0x0502 as read.
        sii_status: u16,
        /// What that status means.
        why: String,
    },
}

fn state_failure(stayed: Option<AlState>, code: AlStatusCode, cause: &StateCause) -> String {
    let reached = stayed.map(|s| s.name()).unwrap_or("an unknown state");
    match cause {
        StateCause::EepromNotLoaded { why, .. } => why.clone(),
        StateCause::Error => format!("stays in {reached} with an error{}", code_text(code)),
        StateCause::Timeout => format!("stays in {reached} (timeout){}", code_text(code)),
    }
}

pub(crate) fn code_text(code: AlStatusCode) -> String {
    if code.0 == 0 {
        String::new()
    } else {
        format!(", AL status code {code}")
    }
}

/// Why distributed clocks cannot run.
#[derive(Debug, Clone, Copy, PartialEq, Eq, thiserror::Error)]
#[non_exhaustive]
pub enum DcError {
    /// No slave has a DC unit.
    #[error("no slave has a distributed clock")]
    NoDcSlave,
    /// DC slaves, but with receive times only: none can be the reference.
    #[error("no slave has a DC system time (receive times only)")]
    NoSystemTime,
    /// A step that needs the reference clock before the DC initialisation chose one.
    #[error("no reference clock: run init_dc first")]
    NoReference,
    /// The reference clock's slave is no longer on the segment (a new scan).
    #[error("reference clock gone")]
    ReferenceGone,
}

fn no_such_slave(position: u16, count: usize) -> String {
    match count {
        0 => format!("no slave at position {position}: the segment has none"),
        n => format!("no slave at position {position} (positions count from 0: 0 to {})", n - 1),
    }
}

/// The master's result.
pub type Result<T> = std::result::Result<T, MasterError>;
