//! The true system time of every DC unit at chosen instants, as a probe on each slave would see
//! it. Frames are processed when they are sent, so by the time a caller asks, a clock may
//! already have been changed by a frame that passed it *after* the instant; a watch is
//! therefore filled in node by node just before the first change of that node's clock at or
//! after its instant (a frame reaching the node, a scheduled event, an oscillator step), which
//! makes every value exact whenever it is read.

/// The system times at one instant.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct Watch {
    pub at_ns: u64,
    /// Per node: its system time at `at_ns` (None: no DC unit).
    pub system_ns: Vec<Option<u64>>,
    known: Vec<bool>,
    missing: usize,
}

impl Watch {
    pub(crate) fn new(at_ns: u64, nodes: usize) -> Self {
        Watch { at_ns, system_ns: vec![None; nodes], known: vec![false; nodes], missing: nodes }
    }

    pub(crate) fn is_complete(&self) -> bool {
        self.missing == 0
    }

    /// Takes every node's time not yet known from its clock as it stands.
    pub(crate) fn fill_all(&mut self, nodes: &[crate::Node]) {
        for (k, n) in nodes.iter().enumerate() {
            self.fill(k, &n.esc);
        }
    }

    /// Takes node `k`'s time from its clock as it stands, unless already known.
    pub(crate) fn fill(&mut self, k: usize, esc: &ferrocat_esc::Esc) {
        if let Some(known) = self.known.get_mut(k).filter(|known| !**known) {
            *known = true;
            self.missing -= 1;
            self.system_ns[k] = esc.dc.as_ref().map(|d| d.system_at(self.at_ns));
        }
    }
}
