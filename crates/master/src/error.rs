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
    /// The rest, in words (module, EoE, FoE, CiA402 and init-command failures).
    #[error("{0}")]
    Other(String),
}

/// An error of the master: the link's, the segment's, a slave's, or the configuration's.
#[derive(Debug, thiserror::Error)]
pub enum MasterError {
    /// The link failed (sending, receiving, opening the interface).
    #[error(transparent)]
    Io(#[from] std::io::Error),
    /// A frame went unanswered through every retry.
    #[error("no answer to {what} after {tries} tries (frame lost or the segment answers nothing)")]
    Timeout {
        /// The datagram, e.g. "FPRD 0x1001:0x0130 (2 bytes)".
        what: String,
        /// Tries made, the first included.
        tries: u32,
    },
    /// A datagram reached fewer (or more) slaves than it had to.
    #[error("working counter {got}, expected {expected}, for {what}{slaves}")]
    Wkc {
        /// The datagram.
        what: String,
        /// The working counter it had to come back with.
        expected: u16,
        /// The working counter it came back with.
        got: u16,
        /// Which slave it was meant for, where the master knows (": slave 0 (EK1100, …)").
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
    #[error("slave {position} ({name}) did not reach {requested}: {status}{code}")]
    State {
        /// Position on the segment, from 0.
        position: u16,
        /// The slave's name from its SII.
        name: String,
        /// The state requested.
        requested: AlState,
        /// Where it stayed, in words ("stays in INIT with an error").
        status: String,
        /// Its AL status code in words, or empty.
        code: String,
    },
    /// The slave aborted an SDO transfer.
    #[error("slave {position} ({name}): SDO {index:#06x}:{subindex:02x} aborted: {code}")]
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
    #[error("{0}")]
    Config(String),
}

impl MasterError {
    /// A slave's error in words, where no [`SlaveError`] kind fits yet.
    pub(crate) fn slave(position: u16, name: &str, message: impl Into<String>) -> Self {
        Self::of(position, name, SlaveError::Other(message.into()))
    }

    /// A slave's error of a known kind.
    pub(crate) fn of(position: u16, name: &str, error: SlaveError) -> Self {
        MasterError::Slave { slave: SlaveRef { position, name: name.into() }, error }
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
