//! What the master keeps of cyclic synchronisation between steps.

/// State of cyclic synchronisation kept by the master between steps.
#[derive(Debug, Clone, Copy, Default, PartialEq, Eq)]
pub struct SyncState {
    /// Cycles stepped.
    pub cycle: u64,
    /// Time the frame spends behind the reference (from the latched receive times).
    pub loop_ns: u64,
    /// Cycle frames lost.
    pub lost: u64,
    /// The reference's time from the last answered step's FRMW (a 32-bit reference's unwrapped
    /// onto 64 bits, counting its wraps from the first).
    pub reference_ns: Option<u64>,
    /// The reference's System_Time_Offset as last read (unwrapped likewise).
    pub reference_offset_ns: Option<u64>,
    /// Probe frames: the budget and what became of them.
    pub probing: ProbeStats,
    /// Frames that made up for a lost cycle's frame ([`CyclePlan::make_up_lost_frames`](super::CyclePlan::make_up_lost_frames)).
    pub make_ups: u64,
    /// Cable redundancy: the ring's state `loop_ns` was measured for.
    pub ring: crate::engine::RingState,
    /// The method's lock state, from the offset each answered frame measures.
    pub lock: crate::sync::Lock,
}

/// Probe frames: the budget they run in and what became of them.
#[derive(Debug, Clone, Copy, Default, PartialEq, Eq)]
pub struct ProbeStats {
    /// No probe frames (the static drift compensation, whose frames are back to back anyway).
    pub off: bool,
    /// Probe frames sent.
    pub sent: u64,
    /// Probe frames lost.
    pub lost: u64,
    /// How long a probe has taken on average (ns of the host's clock).
    pub mean_ns: u64,
    /// Cycles whose probes stopped early so as not to make the next cycle late.
    pub cut: u64,
    /// Probing's budget: how long probes may take per cycle on average (ns of the host's
    /// clock; `None`: as long as the method's window allows, every cycle). A host whose every
    /// frame costs tens of µs of CPU spends its cycles on probes otherwise (`ferrocat run` sets
    /// it from the loop's own cost, docs/clock-sync.md, "Probing").
    pub budget_ns: Option<u64>,
    /// The budget saved up and not yet spent, at most one window.
    pub credit_ns: u64,
    /// Probes the method wanted and the budget did not allow.
    pub unfunded: u64,
}
