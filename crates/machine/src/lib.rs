#![deny(missing_docs)]
//! What an EtherCAT machine is expected to be, as files describe it, and how the network found
//! at start-up compares with it.
//!
//! - [`eni`]: EtherCAT Network Information files (ETG.2100), as TwinCAT, EC-Engineer and other
//!   configuration tools export them: the master's and every slave's settings, init commands,
//!   the cyclic frames and the process image. Read leniently, each departure from the schema a
//!   [`Warning`] naming line and column; [`eni::Eni::parse_strict`] refuses them.
//! - [`description`]: ferrocat's own machine description, a TOML file a person reads and edits
//!   ([`Machine`]), written from a scan to start from.
//! - [`mod@compare`]: the expected slaves against the scanned ones (ETG.1500 item 302), every
//!   difference named: missing, extra, swapped, another device, another revision, serial
//!   number or alias.
//!
//! The crate reads files and compares identities; it drives no network. The master applies what
//! it describes.
pub mod compare;
pub mod description;
pub mod eni;

pub use compare::{compare, Expected, Found, Identity, Mismatch, RevisionCheck};
pub use description::{DescriptionError, GroupDesc, Machine, SlaveDesc};

/// A file's place, 1-based: where an error or a warning points.
#[derive(Debug, Clone, Copy, PartialEq, Eq, PartialOrd, Ord, serde::Serialize)]
pub struct Place {
    /// Line, from 1.
    pub line: u32,
    /// Column, from 1.
    pub column: u32,
}

impl std::fmt::Display for Place {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        write!(f, "line {}, column {}", self.line, self.column)
    }
}

/// Something a file does that its writers' tools accept but the schema does not: read as
/// described in the message.
#[derive(Debug, Clone, PartialEq, Eq, serde::Serialize)]
pub struct Warning {
    /// Where.
    pub place: Place,
    /// What, and how it was read.
    pub message: String,
}

impl std::fmt::Display for Warning {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        write!(f, "{}: {}", self.place, self.message)
    }
}
