#![deny(missing_docs)]
//! The ferrocat EtherCAT master.
//!
//! ```no_run
//! use ferrocat_master::{io::RawIo, Master};
//!
//! # fn main() -> Result<(), Box<dyn std::error::Error>> {
//! let mut master = Master::new(RawIo::open("eth0")?);
//! master.states().bring_up()?; // scan, configure, and every slave to OP
//! let light = master.image().output(1, "Output")?; // an entry by slave position and name
//! let mut cyclic = master.cyclic(); // the cyclic core, held for the loop
//! let mut next = cyclic.now_ns();
//! for k in 0..1_000u64 {
//!     cyclic.set(light, (k / 100) & 1);
//!     cyclic.cycle()?; // one exchange of the whole process image
//!     next += 1_000_000;
//!     cyclic.sleep_until(next);
//! }
//! # Ok(())
//! # }
//! ```
//!
//! Complete programs are in `examples/`: `scan`, `cyclic_io`, `dc_sync` (a clock-sync method
//! and its lock state), `two_axes_csp` (two CiA402 drives in CSP with DC) and `sdo`.
//!
//! The master runs on any world behind the [`io::Io`] trait: [`io::RawIo`] in real time on a
//! network interface, [`io::UdpIo`] over UDP, or (from the `ferrocat-segment` crate, which this
//! one does not depend on) the simulated segment in virtual time.
//!
//! The [`Master`] owns the world, the slave table ([`Master::slaves`]) and the process image;
//! an application reaches the rest through its parts ([`part`]), each one concern's
//! operations: [`Master::states`] (scan, bring-up to OP, state requests, supervision),
//! [`Master::config`] (settings, ESI descriptions, groups, the set-up of each slave),
//! [`Master::cyclic`] (the link, its frames and the cycle, which exchanges process data
//! without allocating), [`Master::image`] (the image, to read, through `&Master`),
//! [`Master::dc`] (distributed clocks), [`Master::clock`] (the master's clock and its
//! clock-sync method), [`Master::acyclic`] (the mailbox clients, the EEPROM, the requests of
//! other processes) and [`Master::diagnosis`] (events, counters, statistics).
pub mod acyclic;
mod acyclic_state;
mod bring_up;
pub mod calibrate;
pub mod cia402;
mod coe;
mod cycle_state;
mod dc;
mod dc_writes;
mod diagnosis;
mod diagnosis_state;
mod engine;
mod eoe;
mod eoe_link;
mod error;
mod event;
mod far_clock;
mod foe;
mod foe_transfer;
mod handle;
pub mod io;
mod line_fit;
mod mailbox;
mod master;
mod pass_filter;
pub mod plan;
mod process;
mod rtt_weight;
mod sdo_transfer;
mod settings;
mod slave;
mod soe;
mod soe_transfer;
pub mod sync;
mod topology;
pub mod trajectory;
mod trimmed;

pub use acyclic::{AcyclicStats, Answer, Request, RequestId};
pub use coe::{Coe, EntryInfo, ObjectInfo};
pub use cycle_state::CycleStats;
pub use dc::{sync0_by_sii, DcConfig, DcReport};
pub use diagnosis_state::{DiagnosisStats, SyncFlags, SyncSm};
pub(crate) use engine::SplitPasses;
pub use engine::{EngineStats, RingState, SplitRingClocks};
pub use eoe::{Eoe, EoeLink, EoePing, INBOX_FRAMES};
pub use error::{
    Cia402Error, ConfigError, DatagramRef, DcError, EoeError, FoeError, ImageSide, MasterError, ModuleError,
    RequestError, Result, SdoSource, SlaveError, SlaveRef, StateCause,
};
pub use event::MasterEvent;
/// The ESI descriptions the master takes ([`Config::add_esi`](crate::part::Config::add_esi)); the reader with the `esi-xml`
/// feature.
pub use ferrocat_esi as esi;
/// The wire crate whole, for what the re-exports below do not name.
pub use ferrocat_wire as wire;
pub use ferrocat_wire::coe::AbortCode;
pub use ferrocat_wire::register::{AlState, AlStatusCode, DlStatus};
pub use ferrocat_wire::sii::SiiInfo;
pub use ferrocat_wire::{Address, Command};
pub use foe::Foe;
pub use handle::Handle;
pub use master::part;
pub use master::{
    Acyclic, Clock, Config, Cyclic, Dc, Diagnosis, Eeprom, FarReferenceKept, Group, Image, Master, SplitLatch, States,
    STATION_BASE,
};
pub use settings::Settings;
pub use slave::{
    DcInfo, EscInfo, Health, Identity, MailboxConfig, Mapped, Mapping, Ports, Setup, Slave, Slaves, Status,
};
pub use soe::{IdnDescription, Soe};
pub use sync::SyncState;
