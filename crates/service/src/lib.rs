#![deny(missing_docs)]
//! Reach a running ferrocat master from another process.
//!
//! A master that runs as a service (`ferrocat run`) listens on a Unix socket, its *control
//! socket*, for acyclic work: the slave list, SDO transfers and SDO information, registers,
//! state requests, statistics. Each request is served in the cycles' spare time, so that no
//! client makes a cycle late. The protocol is JSON, a request and its reply per line
//! ([`protocol`], docs/service.md).
//!
//! ```no_run
//! use ferrocat_service::Client;
//!
//! # fn main() -> Result<(), Box<dyn std::error::Error>> {
//! let mut master = Client::connect(ferrocat_service::socket_path("eth0"))?;
//! for s in master.slaves()? {
//!     println!("{} {} {}", s.position, s.name, s.state);
//! }
//! let vendor = master.sdo_read(1, 0x1018, 1)?;
//! # Ok(())
//! # }
//! ```
//!
//! With the feature `server`, [`Server`] is the master's side: `ferrocat run` starts it and
//! calls [`Server::serve`] once a cycle.
pub mod client;
#[cfg(feature = "server")]
pub mod gateway;
pub mod image;
mod lock;
#[cfg(feature = "server")]
pub mod master_od;
pub mod protocol;
#[cfg(feature = "server")]
mod server;
mod shm;

pub use client::{Client, ClientError};
#[cfg(feature = "server")]
pub use gateway::{GatewayOptions, GatewayStats};
pub use image::{ImageClient, ImageError, SharedImage, Snapshot, Variable};
pub use lock::{find_socket, lock_path, runtime_dir, socket_path, Held, MasterLock, SYSTEM_DIR};
#[cfg(feature = "server")]
pub use server::{master_request, pdos_of, Server, ServerOptions};
