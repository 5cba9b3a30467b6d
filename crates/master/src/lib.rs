//! The ferrocat EtherCAT master.
//!
//! The master runs on any world behind the [`io::Io`] trait: [`io::RawIo`] in real time on a
//! network interface, [`io::UdpIo`] over UDP, or (from the `ferrocat-segment` crate, which this
//! one does not depend on) the simulated segment in virtual time. The [`Master`] brings a segment up to OP ([`Master::bring_up`]),
//! speaks CoE, and exchanges process data every cycle without allocating ([`Master::cycle`]).
pub mod calibrate;
pub mod cia402;
mod coe;
mod dc;
mod engine;
mod eoe;
mod error;
pub mod far_clock;
mod foe;
pub mod io;
pub mod line_fit;
mod master;
mod process;
pub mod rtt_weight;
mod slave;
pub mod sync;
pub mod topology;
pub mod trajectory;
mod trimmed;

pub use coe::{EntryInfo, ObjectInfo};
pub use dc::{DcConfig, DcReport, SyncState};
pub use engine::{describe, Engine, EngineStats, Pdu, RingState, SlaveTag, SplitPasses, SplitRingClocks};
pub use eoe::{EoeLink, EoePing, INBOX_FRAMES};
pub use error::{MasterError, Result};
pub use master::{Master, MasterEvent, SplitLatch, STATION_BASE};
pub use process::{CycleStats, Handle};
pub use slave::{Health, MailboxConfig, Mapped, Slave};
