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
    /// Reads and polls given up at the spare time's end (the answer came too late), and
    /// sync-error flag reads whose reply did not come within 1 s.
    pub given_up: u64,
    /// Counters that grew (each reported as an event).
    pub counters_grown: u64,
    /// Reads of a synchronised slave's sync-error flag (0x1C32:20) answered.
    pub sync_flag_reads: u64,
    /// Times a sync-error flag was found set where it had been clear (each an event).
    pub sync_errors: u64,
}

/// Diagnosis's state: the counters last read, whose turn it is, when the next round is due.
#[derive(Debug, Default)]
pub(crate) struct Diagnosis {
    pub counters: Vec<Option<ErrorCounters>>,
    pub next_counters: usize,
    pub next_mailbox: usize,
    pub round_due_ns: u64,
    pub stats: DiagnosisStats,
    /// The slaves whose SYNC0 the DC initialisation started: their 0x1C32:20 is read.
    pub sync0_slaves: Vec<u16>,
    pub next_sync: usize,
    pub sync_due_ns: u64,
    /// A read of 0x1C32:20 written to the slave's mailbox, its reply awaited: the slave, and
    /// when (the master's clock).
    pub sync_pending: Option<(u16, u64)>,
    /// The flag as last read, by position.
    pub sync_flags: Vec<Option<bool>>,
    /// Slaves that aborted the read (no such object): not asked again.
    pub sync_unreadable: Vec<u16>,
}
