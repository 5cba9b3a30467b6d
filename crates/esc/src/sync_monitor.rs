//! The SM-synchronisation supervision of a DC-synchronous slave (ETG.1020's error settings,
//! object 0x10F1), as Beckhoff's Slave Stack Code runs it (Application Note ET9300; SSC 5.11 is
//! what Paprocki 2022's drives ran): a SYNC0 that finds no SM2 event since the one before the
//! last adds 3 to a counter, each SM2 event takes 1 off, and a counter at the limit (0x10F1:02,
//! 4 by default; 0 turns the reaction off) takes the slave from OP to SAFEOP with error 0x001A.
//!
//! One SYNC0 interval without outputs is tolerated (a frame that crossed its SYNC0 comes in the
//! next interval); a master that sends nothing for three cycles trips it. The SSC compares the
//! counter with the limit in a 1 ms timer; here it is compared at each SYNC0, the same or up to
//! 1 ms earlier. Its SYNC0 watchdog as well: SYNC0 gone in OP is a fatal sync error (0x002C).
use ferrocat_wire::register::AlStatusCode;

/// SSC's default limit (`MAX_SM_EVENT_MISSED`).
pub const DEFAULT_SYNC_ERROR_LIMIT: u16 = 4;

/// How long SYNC0 may stay away in OP before the SSC's SYNC0 watchdog takes the slave to
/// SAFEOP with a fatal sync error (0x002C): its value is 1 ms below a 500 µs cycle, else twice
/// the cycle in whole ms (0.1 ms units, truncated), counted in 1 ms ticks reset by each SYNC0,
/// which expire one tick after the value; here from the last SYNC0, exactly.
pub fn sync0_watchdog_ns(cycle_ns: u64) -> u64 {
    let tenths = cycle_ns / 100_000;
    let ms = if tenths < 5 { 1 } else { tenths * 2 / 10 };
    (ms + 1) * 1_000_000
}

#[derive(Debug, Clone, Copy, Default, PartialEq, Eq)]
pub struct SmSyncMonitor {
    /// Supervising at all (the drive has the SSC's 0x10F1; `sync_error_limit` was given). Off,
    /// the counter still counts and nothing is a fault.
    pub on: bool,
    /// 0x10F1:02; 0: counted, never a sync error (the SYNC0 watchdog still applies).
    pub limit: u16,
    /// The SM-event-missed counter (+3 per missed event, −1 per SM2 event).
    pub missed: u16,
    /// SYNC0 pulses since the last SM2 event.
    sync0_since_sm: u16,
    /// Supervising: in OP and outputs have come at least once.
    armed: bool,
    /// The limit was reached since OP was last entered (0x1C32:20, "sync error").
    pub sync_error: bool,
    /// The last SYNC0 in OP (ns), for the SYNC0 watchdog.
    last_sync0_ns: Option<u64>,
    /// A fault found and not yet taken by the ESC.
    fault: Option<AlStatusCode>,
}

impl SmSyncMonitor {
    /// Supervising with `limit`.
    pub fn new(limit: u16) -> Self {
        SmSyncMonitor { on: true, limit, ..Default::default() }
    }

    /// Entering OP starts the supervision afresh; it arms on the first outputs.
    pub fn restart(&mut self) {
        *self = SmSyncMonitor { on: self.on, limit: self.limit, ..Default::default() };
    }

    /// A complete output buffer in OP at `now_ns` (the SM2 event); `sync0_cycle_ns`, where the
    /// application runs on SYNC0, for the SYNC0 watchdog.
    pub fn outputs(&mut self, now_ns: u64, sync0_cycle_ns: Option<u64>) {
        self.sm_event();
        if sync0_cycle_ns.is_some_and(|c| self.sync0_lost(now_ns, c)) {
            self.fault = self.fault.or(Some(AlStatusCode::FATAL_SYNC_ERROR));
        }
    }

    /// A SYNC0 pulse in OP at `now_ns`.
    pub fn pulse(&mut self, now_ns: u64) {
        if self.sync0(now_ns) {
            self.fault = self.fault.or(Some(AlStatusCode::SYNC_ERROR));
        }
    }

    /// The fault found since last asked: the slave leaves OP with it.
    pub fn take_fault(&mut self) -> Option<AlStatusCode> {
        self.fault.take()
    }

    fn sm_event(&mut self) {
        self.armed = true;
        self.sync0_since_sm = 0;
        self.missed = self.missed.saturating_sub(1);
    }

    /// Whether SYNC0 has stayed away longer than the SYNC0 watchdog of a `cycle_ns` cycle at
    /// `now_ns` (in OP, after one SYNC0): the slave leaves OP with 0x002C, whatever the limit.
    fn sync0_lost(&self, now_ns: u64, cycle_ns: u64) -> bool {
        self.on && self.last_sync0_ns.is_some_and(|t| now_ns.saturating_sub(t) >= sync0_watchdog_ns(cycle_ns))
    }

    /// A SYNC0 pulse in OP at `now_ns`. True when this pulse takes the counter to the limit:
    /// the slave leaves OP with 0x001A.
    fn sync0(&mut self, now_ns: u64) -> bool {
        self.last_sync0_ns = Some(now_ns);
        if !self.armed {
            return false;
        }
        // One SYNC0 per SM cycle: more than one since the last outputs is a missed event. The
        // counter stops growing above the limit, as the SSC's does.
        if self.sync0_since_sm > 1 && self.missed <= self.limit {
            self.missed = self.missed.saturating_add(3);
        }
        self.sync0_since_sm = self.sync0_since_sm.saturating_add(1);
        if self.on && self.limit > 0 && self.missed >= self.limit && !self.sync_error {
            self.sync_error = true;
            return true;
        }
        false
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// SYNC0 pulses with outputs (true) or without (false) before each; the pulse that trips.
    fn run(limit: u16, outputs: &[bool]) -> (Option<usize>, u16) {
        let mut m = SmSyncMonitor::new(limit);
        m.restart();
        assert!(m.on);
        let mut tripped = None;
        for (k, &o) in outputs.iter().enumerate() {
            if o {
                m.sm_event();
            }
            if m.sync0(k as u64 * 1_000_000) && tripped.is_none() {
                tripped = Some(k);
            }
        }
        (tripped, m.missed)
    }

    #[test]
    fn one_empty_interval_is_tolerated_and_counts_nothing() {
        // A late frame: one interval empty, the next with two buffers.
        let mut o = vec![true; 10];
        o[4] = false;
        assert_eq!(run(4, &o), (None, 0));
        // Every other interval empty: never two in a row.
        let o: Vec<bool> = (0..100).map(|k| k % 2 == 0).collect();
        assert_eq!(run(4, &o), (None, 0));
    }

    #[test]
    fn three_cycles_without_outputs_trip_the_default_limit() {
        // Outputs, then none for three SYNC0s: the 2nd and 3rd empty pulses count 3 each.
        let o = [true, true, false, false, false, true, true];
        assert_eq!(run(DEFAULT_SYNC_ERROR_LIMIT, &o), (Some(4), 4));
        // Two empty pulses count once: 3, under the limit, and the outputs wear it down.
        let o = [true, true, false, false, true, true, true, true];
        assert_eq!(run(DEFAULT_SYNC_ERROR_LIMIT, &o), (None, 0));
    }

    #[test]
    fn a_limit_of_zero_counts_but_never_trips() {
        let o = [true, false, false, false, false, false, false];
        let (tripped, missed) = run(0, &o);
        assert_eq!(tripped, None);
        // The counter stops at the first step above the limit (0 + 3), as the SSC's.
        assert_eq!(missed, 3);
    }

    #[test]
    fn no_supervision_before_the_first_outputs() {
        assert_eq!(run(4, &[false; 20]), (None, 0));
    }

    #[test]
    fn the_sync0_watchdog_is_the_sscs() {
        // 1 ms: twice the cycle, one tick more; 250 µs: 1 ms, one tick more; 750 µs truncated.
        assert_eq!(sync0_watchdog_ns(1_000_000), 3_000_000);
        assert_eq!(sync0_watchdog_ns(250_000), 2_000_000);
        assert_eq!(sync0_watchdog_ns(750_000), 2_000_000);
        assert_eq!(sync0_watchdog_ns(4_000_000), 9_000_000);
        let mut m = SmSyncMonitor::new(4);
        assert!(!m.sync0_lost(10_000_000, 1_000_000), "no SYNC0 yet: nothing to miss");
        m.sync0(1_000_000);
        assert!(!m.sync0_lost(3_999_999, 1_000_000));
        assert!(m.sync0_lost(4_000_000, 1_000_000));
    }

    #[test]
    fn a_higher_limit_needs_more_missed_events() {
        let mut o = vec![true; 3];
        o.extend([false; 4]);
        // Empty pulses 2-4 count: 3, 6, 9; limit 9 trips on the third counted one.
        assert_eq!(run(9, &o).0, Some(6));
        assert_eq!(run(10, &o).0, None);
    }
}
