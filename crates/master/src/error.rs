//! What can go wrong, each error naming what and where.
use ferrocat_wire::coe::AbortCode;
use ferrocat_wire::register::{AlState, AlStatusCode};

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
    /// Anything else a slave did wrong, in words.
    #[error("slave {position} ({name}): {message}")]
    Slave {
        /// Position on the segment, from 0.
        position: u16,
        /// The slave's name from its SII.
        name: String,
        /// What happened.
        message: String,
    },
    /// The master was asked something its configuration does not allow.
    #[error("{0}")]
    Config(String),
}

impl MasterError {
    pub(crate) fn slave(position: u16, name: &str, message: impl Into<String>) -> Self {
        MasterError::Slave { position, name: name.into(), message: message.into() }
    }
}

pub(crate) fn code_text(code: AlStatusCode) -> String {
    if code.0 == 0 {
        String::new()
    } else {
        format!(", AL status code {code}")
    }
}

/// The master's result.
pub type Result<T> = std::result::Result<T, MasterError>;
