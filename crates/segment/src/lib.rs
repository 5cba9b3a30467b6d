//! A virtual EtherCAT segment: simulated ESCs in any topology, with exact wire timing,
//! oscillators and injectable faults, run in virtual time (deterministic for a seed).
mod builtin;
mod config;
pub mod files;
pub mod host;
pub mod od_build;
mod segment;
mod tamper;
pub mod timing;
mod virtual_io;
mod watch;

pub use config::{
    load_device, DeviceSource, DeviceToml, EventToml, Number, PortToml, Product, SecondaryToml, SegmentConfig,
    SegmentError,
};
pub use host::{HostModel, Latency, Stamps};
pub use segment::{Event, MasterPort, Node, Peer, SecondaryLink, Segment, SegmentStats};
pub use tamper::Tamper;
pub use virtual_io::VirtualIo;
pub use watch::Watch;

/// The names `builtin = …` accepts in a segment file.
pub use builtin::NAMES as BUILTIN_NAMES;

use ferrocat_wire::ethernet::{EthernetRepr, ETHERTYPE_ETHERCAT, ETHERTYPE_IPV4};
use ferrocat_wire::frame::{EcatHeader, TYPE_DLPDU};

/// Offset of the EtherCAT header in an Ethernet frame (raw or over UDP), if it is EtherCAT.
pub(crate) fn frame_pdu_offset(frame: &[u8]) -> Option<usize> {
    let (eth, off) = EthernetRepr::parse(frame).ok()?;
    match eth.ethertype {
        ETHERTYPE_ETHERCAT => Some(off),
        ETHERTYPE_IPV4 => {
            let ihl = (*frame.get(off)? & 0x0F) as usize * 4;
            let udp = off + ihl;
            let port = u16::from_be_bytes([*frame.get(udp + 2)?, *frame.get(udp + 3)?]);
            (port == ferrocat_wire::ethernet::UDP_PORT_ETHERCAT).then_some(udp + 8)
        }
        _ => None,
    }
}

/// Datagram bytes the EtherCAT header covers, for DLPDU frames that fit.
pub(crate) fn pdu_len(pdu: &[u8]) -> Option<(usize, EcatHeader)> {
    let h = EcatHeader::parse(pdu).ok()?;
    let len = h.length as usize;
    (h.frame_type == TYPE_DLPDU && len + 2 <= pdu.len()).then_some((len, h))
}

pub(crate) fn circulating(chain: &[u8]) -> bool {
    chain.get(7).is_some_and(|b| b & 0x40 != 0)
}

pub(crate) fn set_circulating(chain: &mut [u8]) {
    if let Some(b) = chain.get_mut(7) {
        *b |= 0x40;
    }
}
