use ferrocat_wire::coe::AbortCode;
use ferrocat_wire::register::{AlState, AlStatusCode};

#[derive(Debug, thiserror::Error)]
pub enum MasterError {
    #[error(transparent)]
    Io(#[from] std::io::Error),
    #[error("no answer to {what} after {tries} tries (frame lost or the segment answers nothing)")]
    Timeout { what: String, tries: u32 },
    #[error("working counter {got}, expected {expected}, for {what}{slaves}")]
    Wkc { what: String, expected: u16, got: u16, slaves: String },
    #[error("malformed reply: {0}")]
    Frame(#[from] ferrocat_wire::Error),
    #[error("no slaves found")]
    NoSlaves,
    #[error("slave {position} ({name}) did not reach {requested}: {status}{code}")]
    State { position: u16, name: String, requested: AlState, status: String, code: String },
    #[error("slave {position} ({name}): SDO {index:#06x}:{subindex:02x} aborted: {code}")]
    Abort { position: u16, name: String, index: u16, subindex: u8, code: AbortCode },
    #[error("slave {position} ({name}): {message}")]
    Slave { position: u16, name: String, message: String },
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

pub type Result<T> = std::result::Result<T, MasterError>;
