use core::fmt;

/// Why a byte sequence could not be read. Every variant says what was being read and where
/// (a byte offset from the start of the buffer handed to the parser).
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Error {
    /// The buffer ends before the structure does.
    Truncated { what: &'static str, offset: usize, needed: usize, available: usize },
    /// A length field claims more (or other) than the surrounding structure holds.
    BadLength { what: &'static str, offset: usize, claimed: usize, limit: usize },
    /// A field holds a value this parser does not know or accept.
    BadValue { what: &'static str, offset: usize, value: u32 },
    /// A checksum does not match.
    Checksum { what: &'static str, offset: usize, expected: u32, actual: u32 },
    /// An output buffer is too small for what is being emitted.
    BufferTooSmall { what: &'static str, needed: usize, available: usize },
}

pub type Result<T> = core::result::Result<T, Error>;

impl Error {
    /// The same error with its offset moved by `base`: used when a nested parser ran on a
    /// sub-slice and the caller knows where that slice started.
    pub fn shifted(self, base: usize) -> Self {
        match self {
            Error::Truncated { what, offset, needed, available } => {
                Error::Truncated { what, offset: offset + base, needed, available }
            }
            Error::BadLength { what, offset, claimed, limit } => {
                Error::BadLength { what, offset: offset + base, claimed, limit }
            }
            Error::BadValue { what, offset, value } => Error::BadValue { what, offset: offset + base, value },
            Error::Checksum { what, offset, expected, actual } => {
                Error::Checksum { what, offset: offset + base, expected, actual }
            }
            e @ Error::BufferTooSmall { .. } => e,
        }
    }
}

impl fmt::Display for Error {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        match *self {
            Error::Truncated { what, offset, needed, available } => {
                write!(f, "{what} at byte {offset} is truncated: needs {needed} bytes, {available} available")
            }
            Error::BadLength { what, offset, claimed, limit } => {
                write!(f, "{what} at byte {offset} claims length {claimed}, but at most {limit} fit")
            }
            Error::BadValue { what, offset, value } => {
                write!(f, "{what} at byte {offset} has unsupported value {value:#x}")
            }
            Error::Checksum { what, offset, expected, actual } => {
                write!(f, "{what} at byte {offset}: checksum {actual:#x} does not match computed {expected:#x}")
            }
            Error::BufferTooSmall { what, needed, available } => {
                write!(f, "output buffer for {what} too small: needs {needed} bytes, has {available}")
            }
        }
    }
}

impl core::error::Error for Error {}
