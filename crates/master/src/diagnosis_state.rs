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
    /// Reads of a synchronised slave's sync-error flags (0x1C32:20, 0x1C33:20) answered.
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
    /// The slaves whose SYNC0 the DC initialisation started: their 0x1C32:20 and 0x1C33:20
    /// are read.
    pub sync0_slaves: Vec<u16>,
    /// The next read of a round: slave `next_sync / 2`'s output (even) or input (odd) flag.
    pub next_sync: usize,
    pub sync_due_ns: u64,
    /// A read of a flag written to the slave's mailbox, its reply awaited: the slave, which
    /// flag, and when (the master's clock).
    pub sync_pending: Option<(u16, SyncSm, u64)>,
    /// The flags as last read, by position.
    pub sync_flags: Vec<SyncFlags>,
    /// Flags a slave aborted the read of (no such object): not asked again.
    pub sync_unreadable: Vec<(u16, SyncSm)>,
}

/// Which SyncManager's parameter object a sync-error flag is in (ETG.1020).
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum SyncSm {
    /// The output SM's, 0x1C32:20.
    Outputs,
    /// The input SM's, 0x1C33:20.
    Inputs,
}

impl SyncSm {
    /// The flag's object and subindex.
    pub fn object(self) -> (u16, u8) {
        match self {
            SyncSm::Outputs => (0x1C32, 0x20),
            SyncSm::Inputs => (0x1C33, 0x20),
        }
    }
}

/// A slave's sync-error flags as diagnosis last read them (`None`: not read, or the slave has
/// no such object, or no SYNC0).
#[derive(Debug, Clone, Copy, Default, PartialEq, Eq)]
pub struct SyncFlags {
    /// The output SM parameter's (0x1C32:20).
    pub outputs: Option<bool>,
    /// The input SM parameter's (0x1C33:20).
    pub inputs: Option<bool>,
}

impl SyncFlags {
    /// The flag of `sm`.
    pub fn of(&mut self, sm: SyncSm) -> &mut Option<bool> {
        match sm {
            SyncSm::Outputs => &mut self.outputs,
            SyncSm::Inputs => &mut self.inputs,
        }
    }
}
