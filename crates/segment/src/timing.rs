//! Wire and ESC timing defaults (esc-spec §4), chosen so that SOEM's delay formula on a
//! simulated EK1100 + EL2004 + EL2004 gives the 145/300 ns that real hardware and ethercrab's
//! fixtures show (see docs/segment-model.md for the derivation).
use serde::Deserialize;

/// Physical kind of a port.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Deserialize)]
#[serde(rename_all = "lowercase")]
pub enum PortKind {
    /// E-Bus (LVDS) between terminals.
    Ebus,
    /// 100BASE-TX through PHYs and a cable.
    Mii,
}

#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct EscTiming {
    /// Port 0 → processing unit → next port.
    pub processing_ns: u32,
    /// A frame received from a wire on ports 1–3 → next port.
    pub forwarding_ns: u32,
    /// A closed port looping the frame back.
    pub loopback_ns: u32,
}

impl Default for EscTiming {
    fn default() -> Self {
        EscTiming { processing_ns: 65, forwarding_ns: 65, loopback_ns: 20 }
    }
}

impl EscTiming {
    /// A LAN9252, whose PHYs are on the chip: two EVB-LAN9252 boards gave SOEM a delay of
    /// 740 ns (../shared/captures/soem-sdinfo-2-lan9252.txt) where two ET1100s with external
    /// PHYs give 485–495 ns. The measurement does not split the extra 245 ns between PHY and
    /// ESC; it goes into the processing and forwarding delays, which SOEM's formula weighs
    /// one to one (a calibration from that one printout; the SOEM maintainer's "≈ 700 ns per
    /// hop" for LAN9252 chains, ../shared/reference/existing-masters.md, agrees).
    pub const LAN9252: EscTiming = EscTiming { processing_ns: 310, forwarding_ns: 310, loopback_ns: 20 };
}

/// One-way delay of a link between two ports: E-Bus ≈ 80 ns (145 ns hop with processing);
/// 100BASE-TX ≈ 420 ns (PHY + PHY + a few metres, 485 ns hop) plus 5 ns per metre beyond 2 m.
pub fn link_delay_ns(a: PortKind, b: PortKind, cable_m: f64) -> u32 {
    match (a, b) {
        (PortKind::Ebus, PortKind::Ebus) => 80,
        _ => 420 + ((cable_m - 2.0).max(0.0) * 5.0).round() as u32,
    }
}

/// 100 Mbit/s: 80 ns per byte.
pub const NS_PER_BYTE: u64 = 80;
/// Preamble and start-of-frame delimiter ahead of the frame; FCS after it.
pub const PREAMBLE_BYTES: u64 = 8;
pub const FCS_BYTES: u64 = 4;
/// The inter-frame gap: the least idle time between two frames on a link.
pub const IFG_BYTES: u64 = 12;
