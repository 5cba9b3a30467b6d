//! Where SYNC0 falls in the master's cycle, so that the cycle's frame never passes the slaves
//! at their SYNC0.
use super::{Coupling, SyncMethod};

/// SYNC0's place in the master's cycle, for a method and the segment's round trip.
///
/// A frame that passes a slave at its SYNC0 reaches it, with the host's jitter, in one SYNC0
/// interval or the next, which a drive's SM-synchronisation supervision takes for missed
/// outputs (AL status 0x001A). So SYNC0 goes half a cycle from the frame's passage of the
/// reference.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct Sync0Plan {
    /// SYNC0 after the cycle's start on the grid, ns (`DcConfig::sync0_shift_ns`).
    pub shift_ns: u64,
    /// Where the frames should pass the reference, after the SYNC0 before, ns.
    pub aimed_ns: u64,
}

impl Sync0Plan {
    /// SYNC0 half a cycle from the frame's passage of the reference unless `shift_ns` says
    /// where. A method that steers the master's phase (SOEM's PI loop, ferrocat following the
    /// reference) aims the passage at the grid itself; the others send the frame on the grid,
    /// and it passes half the segment's round trip later (`round_trip_ns`, measured before:
    /// on a segment whose master link is long, SYNC0 half a cycle after the departure would
    /// come soon after the passage).
    pub fn new(method: &SyncMethod, cycle_ns: u64, round_trip_ns: u64, shift_ns: Option<u64>) -> Self {
        let cycle_ns = cycle_ns.max(1);
        let aims_passage = matches!(method, SyncMethod::Pi { .. })
            || (method.is_ferrocat() && method.coupling() == Coupling::MasterFollowsReference);
        let lead_ns = if aims_passage { 0 } else { round_trip_ns / 2 };
        let shift_ns = shift_ns.unwrap_or((cycle_ns / 2 + lead_ns) % cycle_ns);
        let aimed_ns = (lead_ns as i128 - shift_ns as i128).rem_euclid(cycle_ns as i128) as u64;
        Sync0Plan { shift_ns, aimed_ns }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn sync0_is_half_a_cycle_from_the_passage() {
        // Sent on the grid: the frame passes 100 µs (half of 200) after the cycle's start,
        // SYNC0 500 µs after that.
        let p = Sync0Plan::new(&SyncMethod::None, 1_000_000, 200_000, None);
        assert_eq!(p.shift_ns, 600_000);
        assert_eq!(p.aimed_ns, 500_000);
        // A method that aims the passage at the grid: SYNC0 half a cycle on.
        let p = Sync0Plan::new(&SyncMethod::Pi { shift_ns: 0 }, 1_000_000, 200_000, None);
        assert_eq!((p.shift_ns, p.aimed_ns), (500_000, 500_000));
        // Given: kept, and the passage measured from it.
        let p = Sync0Plan::new(&SyncMethod::None, 1_000_000, 200_000, Some(50_000));
        assert_eq!((p.shift_ns, p.aimed_ns), (50_000, 50_000));
    }
}
