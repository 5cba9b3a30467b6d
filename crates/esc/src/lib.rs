//! A simulated EtherCAT slave controller (ESC), following `../shared/reference/esc-spec.md`.
//!
//! The [`Esc`] is sans-IO: the segment hands it each frame as the frame passes its processing
//! unit, together with the true times at which the frame reached its ports, and advances it in
//! time between frames. Register writes are shadow-buffered and take effect at the end of the
//! frame (esc-spec §1.4); every command's addressing and working-counter rule is applied.
mod al;
mod app;
mod coe_server;
mod config;
pub mod dc;
pub mod drive;
mod eeprom;
mod eoe_server;
mod esc;
mod foe_server;
pub mod od;
mod rate_table;
mod regs;
mod soe_server;
mod sync_monitor;

pub use al::AlMachine;
pub use app::{Application, DigitalIo, NoApplication, Pdi, SyncApp, SyncMode};
pub use coe_server::{CoeDevice, DeviceLogic, Mapped, PassiveLogic};
pub use config::{DcWidth, EscConfig, ReceiveLatch};
pub use drive::{Cia402Drive, DriveAxis, DriveStats, MotorParams, ProcessingTime, Switches};
pub use eoe_server::EoeServer;
pub use esc::{Esc, FrameTiming, LinkState, MailboxResponse, SyncLog};
pub use foe_server::FoeServer;
pub use soe_server::{standard_idns, IdnEntry, SoeServer};
pub use sync_monitor::{SmSyncMonitor, DEFAULT_SYNC_ERROR_LIMIT};
