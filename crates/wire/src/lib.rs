//! EtherCAT on the wire, in the style of smoltcp's `wire` module: zero-copy views that validate
//! once and then read fields, plus plain `Repr` structs that parse from and emit into byte slices.
//!
//! Everything here is `no_std`; nothing on a parse path allocates. The optional `alloc` feature
//! adds owned descriptions (an SII image builder) that are convenient for tools and simulators.
//!
//! Untrusted input never panics: every parser returns [`Error`], which names what was being read
//! and the byte offset where it went wrong.
#![cfg_attr(not(test), no_std)]
#![forbid(unsafe_code)]
#![warn(missing_debug_implementations)]

#[cfg(feature = "alloc")]
extern crate alloc;

mod bytes;
pub mod cia402;
pub mod coe;
pub mod datagram;
pub mod eoe;
mod error;
pub mod ethernet;
pub mod foe;
pub mod frame;
#[cfg(feature = "alloc")]
pub mod hex;
pub mod inet;
pub mod mailbox;
pub mod register;
pub mod sii;
pub mod soe;

pub use datagram::{Address, Command, Datagram, DatagramHeader};
pub use error::{Error, Result};
pub use ethernet::{EthernetRepr, ETHERTYPE_ETHERCAT, ETHERTYPE_IPV4, ETHERTYPE_VLAN};
pub use frame::{EcatHeader, EcatPdu, Encapsulation, Frame, FrameWriter};
