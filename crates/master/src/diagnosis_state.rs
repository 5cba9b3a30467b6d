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
    /// Mapped TxPDO State and TxPDO Toggle entries watched.
    pub txpdo_watched: u64,
    /// Times a TxPDO State entry was found set (the slave says those inputs are invalid; each
    /// an event).
    pub inputs_invalid: u64,
    /// Times a TxPDO Toggle entry stayed unchanged for `Settings::txpdo_stale_ns` (the inputs
    /// were not refreshed; each an event).
    pub inputs_stale: u64,
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
    /// The TxPDO State and Toggle entries of the image, watched after every cycle; `None`:
    /// to be found again (the image was laid out anew).
    pub txpdo: Option<TxPdoWatch>,
}

/// What a TxPDO status entry says (ETG.1020's TxPDO State, 0x1800:07, and TxPDO Toggle,
/// 0x1800:09, or a device's own copies of them, such as Beckhoff's `Status__TxPDO Toggle` at
/// 0x6000:10).
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum TxPdoKind {
    /// Set: the slave says the TxPDO's data is invalid.
    State,
    /// Flips each time the slave refreshes the TxPDO's data.
    Toggle,
}

impl TxPdoKind {
    /// The kind of an input entry, by where ETG.1020 puts it (the TxPDO parameter objects
    /// 0x1800–0x1BFF, subindices 7 and 9) or by its name, as devices map their own copies.
    pub fn of(index: u16, subindex: u8, name: &str, bits: u8) -> Option<TxPdoKind> {
        if bits != 1 {
            return None;
        }
        let lower = name.to_ascii_lowercase();
        match (index, subindex) {
            (0x1800..=0x1BFF, 7) => Some(TxPdoKind::State),
            (0x1800..=0x1BFF, 9) => Some(TxPdoKind::Toggle),
            _ if lower.ends_with("txpdo state") => Some(TxPdoKind::State),
            _ if lower.ends_with("txpdo toggle") => Some(TxPdoKind::Toggle),
            _ => None,
        }
    }
}

/// One watched entry.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct Watched {
    pub position: u16,
    pub entry: String,
    pub kind: TxPdoKind,
    /// Its bit in the image.
    pub bit: u32,
    /// The value last seen, and since when (the master's clock).
    pub last: Option<(bool, u64)>,
    /// A State found set, or a Toggle found stale, and not yet back.
    pub reported: bool,
}

/// What changed in a watched entry.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct TxPdoChange {
    pub position: u16,
    pub entry: String,
    pub kind: TxPdoKind,
    /// How long the toggle had stood still, for a stale one.
    pub unchanged_ns: u64,
}

/// The image's TxPDO State and Toggle entries and what they last said.
#[derive(Debug, Clone, Default, PartialEq, Eq)]
pub struct TxPdoWatch {
    pub entries: Vec<Watched>,
}

impl TxPdoWatch {
    /// Watches `entries` (position, entry name, kind, image bit).
    pub fn new(entries: impl IntoIterator<Item = (u16, String, TxPdoKind, u32)>) -> TxPdoWatch {
        TxPdoWatch {
            entries: entries
                .into_iter()
                .map(|(position, entry, kind, bit)| Watched { position, entry, kind, bit, last: None, reported: false })
                .collect(),
        }
    }

    /// Looks at a cycle's image at `now_ns`: a State that became set, and a Toggle unchanged
    /// for `stale_ns` or more, each once until it is back (cleared, toggling again).
    pub fn observe(&mut self, image: &[u8], now_ns: u64, stale_ns: u64) -> Vec<TxPdoChange> {
        let mut out = Vec::new();
        for w in &mut self.entries {
            let Some(byte) = image.get((w.bit / 8) as usize) else { continue };
            let v = byte >> (w.bit % 8) & 1 != 0;
            let since = match w.last {
                Some((was, since)) if was == v => since,
                _ => {
                    w.last = Some((v, now_ns));
                    now_ns
                }
            };
            let problem = match w.kind {
                TxPdoKind::State => v,
                TxPdoKind::Toggle => now_ns.saturating_sub(since) >= stale_ns,
            };
            if problem && !w.reported {
                out.push(TxPdoChange {
                    position: w.position,
                    entry: w.entry.clone(),
                    kind: w.kind,
                    unchanged_ns: now_ns.saturating_sub(since),
                });
            }
            w.reported = problem;
        }
        out
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn entries_are_found_by_etg_s_place_or_by_name() {
        assert_eq!(TxPdoKind::of(0x1802, 7, "TxPDO State", 1), Some(TxPdoKind::State));
        assert_eq!(TxPdoKind::of(0x1A00, 9, "", 1), Some(TxPdoKind::Toggle));
        assert_eq!(TxPdoKind::of(0x6000, 0x10, "Status__TxPDO Toggle", 1), Some(TxPdoKind::Toggle));
        assert_eq!(TxPdoKind::of(0x6000, 0x0F, "Status__TxPDO State", 1), Some(TxPdoKind::State));
        assert_eq!(TxPdoKind::of(0x6000, 0x10, "Status__TxPDO Toggle", 8), None, "a bit, or not it");
        assert_eq!(TxPdoKind::of(0x6000, 1, "Status__Error", 1), None);
    }

    #[test]
    fn a_state_set_and_a_toggle_that_stands_still_are_said_once() {
        let mut w =
            TxPdoWatch::new([(1, "state".into(), TxPdoKind::State, 0), (1, "toggle".into(), TxPdoKind::Toggle, 1)]);
        let ms = 1_000_000;
        // Toggling every cycle, state clear: nothing.
        for k in 0..10u64 {
            let image = [((k % 2) as u8) << 1];
            assert!(w.observe(&image, k * ms, 5 * ms).is_empty(), "cycle {k}");
        }
        // The toggle stops at 1 (10 ms on): said once when 5 ms have passed, not again.
        let mut said = Vec::new();
        for k in 10..20u64 {
            said.extend(w.observe(&[0b10], k * ms, 5 * ms));
        }
        assert_eq!(said.len(), 1, "{said:?}");
        assert_eq!((said[0].entry.as_str(), said[0].kind, said[0].unchanged_ns), ("toggle", TxPdoKind::Toggle, 5 * ms));
        // It toggles again; then the state is set: said once.
        assert!(w.observe(&[0b00], 20 * ms, 5 * ms).is_empty());
        let set = w.observe(&[0b11], 21 * ms, 5 * ms);
        assert_eq!(set.iter().map(|c| c.kind).collect::<Vec<_>>(), [TxPdoKind::State]);
        assert!(w.observe(&[0b01], 22 * ms, 5 * ms).is_empty(), "still set: not again");
        // Cleared and set again: said again.
        assert!(w.observe(&[0b00], 23 * ms, 5 * ms).is_empty());
        assert_eq!(w.observe(&[0b11], 24 * ms, 5 * ms).len(), 1);
    }
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
