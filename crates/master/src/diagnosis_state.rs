//! What diagnosis while cyclic keeps between cycles (the master holds it; `diagnosis` works on
//! it).
use ferrocat_wire::register::ErrorCounters;

/// What diagnosis did so far.
#[derive(Debug, Clone, Copy, Default, PartialEq, Eq)]
pub struct DiagnosisStats {
    /// Error-counter reads.
    pub counter_reads: u64,
    /// Mailbox polls.
    pub mailbox_polls: u64,
    /// Reads and polls given up at the spare time's end (the answer came too late).
    pub given_up: u64,
    /// Counters that grew (each reported as an event).
    pub counters_grown: u64,
}

/// Diagnosis's state: the counters last read, whose turn it is, when the next round is due.
#[derive(Debug, Default)]
pub(crate) struct Diagnosis {
    pub counters: Vec<Option<ErrorCounters>>,
    pub next_counters: usize,
    pub next_mailbox: usize,
    pub round_due_ns: u64,
    pub stats: DiagnosisStats,
}
