//! A slave's EoE link state, kept in its `Slave` (the EoE client in `eoe` works on it).
use std::collections::VecDeque;

use ferrocat_wire::eoe::Reassembler;

/// Frames kept per slave until the application takes them; older ones are dropped (and
/// counted) beyond this. The same bound holds frames queued for the slave by [`Eoe::queue`](crate::Eoe::queue).
pub const INBOX_FRAMES: usize = 64;

/// A slave's EoE receive side: the frame being put together and the frames waiting.
#[derive(Debug, Clone, Default)]
pub struct EoeLink {
    pub(crate) reassembler: Reassembler,
    pub(crate) inbox: VecDeque<Vec<u8>>,
    /// The next frame number the master sends (4 bits).
    pub(crate) frame_number: u8,
    /// Frames queued by `Eoe::queue`, each as its fragments still to go (EoE header and
    /// data), and the next fragment as a mailbox message once a write of it was tried (its
    /// counter kept for the next try).
    pub(crate) outbox: VecDeque<VecDeque<Vec<u8>>>,
    pub(crate) trying: Option<Vec<u8>>,
    /// Frames dropped because the inbox was full, and fragments that did not fit.
    pub dropped: u64,
    /// Fragments that did not fit the frame being put together.
    pub fragment_errors: u64,
}

impl EoeLink {
    /// Whether frames queued by `Eoe::queue` are still going out.
    pub fn sending(&self) -> bool {
        !self.outbox.is_empty() || self.trying.is_some()
    }
}
