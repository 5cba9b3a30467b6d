//! What a master waits for, and what it does on its own: the settings an application may
//! change at any time.

/// The master's settings ([`Config::settings_mut`](crate::part::Config::settings_mut)).
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct Settings {
    /// How long a state transition may take before it is an error, in ns. Default 10 s.
    pub state_timeout_ns: u64,
    /// How long a mailbox exchange (an SDO, an FoE packet) may take, in ns. Default 2 s.
    pub mailbox_timeout_ns: u64,
    /// How long a cyclic frame may take before it counts as lost, in ns. Default 1 ms. A
    /// cyclic application sets it below its cycle, ¾ of it as `ferrocat run` does: a wait for
    /// a lost frame past the next cycle's start makes that cycle late.
    pub cyclic_timeout_ns: u64,
    /// Check the slaves after a cycle with a short working counter. Default on.
    pub supervise_on_wkc: bool,
    /// What a closed port's loop-back adds to a frame's way, for the delay computation, in ns.
    /// Default 0: assume nothing, as SOEM, IgH and ethercrab do.
    pub closed_port_loop_ns: u32,
    /// How long a mapped TxPDO Toggle may stand still before diagnosis says the slave's inputs
    /// are not refreshed, in ns. Default 1 s (a slow converter refreshes every few 10 ms).
    pub txpdo_stale_ns: u64,
}

impl Default for Settings {
    fn default() -> Self {
        Settings {
            state_timeout_ns: 10_000_000_000,
            mailbox_timeout_ns: 2_000_000_000,
            cyclic_timeout_ns: 1_000_000,
            supervise_on_wkc: true,
            closed_port_loop_ns: 0,
            txpdo_stale_ns: 1_000_000_000,
        }
    }
}
