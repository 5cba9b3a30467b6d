//! What the master keeps of the cyclic exchange between cycles, and its statistics.

/// Statistics of the cyclic exchange.
#[derive(Debug, Clone, Copy, Default, PartialEq, Eq)]
pub struct CycleStats {
    /// Cycles run.
    pub cycles: u64,
    /// Cycles whose working counter fell short.
    pub wkc_errors: u64,
    /// The last cycle's working counter.
    pub last_wkc: u16,
    /// Time between the starts of the last two cycles, and the largest deviation from the
    /// nominal period seen (when `nominal_period_ns` is set).
    pub last_period_ns: u64,
    /// The period the jitter is measured against, ns (0: none).
    pub nominal_period_ns: u64,
    /// The largest deviation of a period from the nominal, ns.
    pub max_jitter_ns: u64,
    /// The last cycle's round trip, ns.
    pub last_round_trip_ns: u64,
    /// The largest round trip, ns.
    pub max_round_trip_ns: u64,
    /// Cyclic frames that never came back.
    pub lost_frames: u64,
}

#[derive(Debug, Default)]
pub(crate) struct CycleState {
    pub stats: CycleStats,
    pub(crate) last_start: Option<u64>,
    /// The ring's state last reported (cable redundancy).
    pub(crate) ring: crate::engine::RingState,
    /// Slaves the last supervision found out of OP: supervised every cycle until all are back,
    /// since a slave in SAFEOP may answer its process data in full.
    pub recovering: bool,
}
