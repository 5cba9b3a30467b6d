//! The baselines: IgH's conventional method and no following at all.
use super::{ClockSync, Correction, Coupling, Sample};

/// IgH's way: the master's present time to the reference, no delay compensation.
#[derive(Debug, Default)]
pub struct Conventional;

impl ClockSync for Conventional {
    fn name(&self) -> &'static str {
        "conventional"
    }
    fn coupling(&self) -> Coupling {
        Coupling::ReferenceFollowsMaster
    }
    fn update(&mut self, _: Option<&Sample>) -> Correction {
        Correction::default()
    }
}

/// No following at all: the master keeps its nominal period on its own clock (the baseline of
/// Chen 2016's Table 2).
#[derive(Debug)]
pub struct Nominal {
    /// The cycle kept, ns.
    pub cycle_ns: u64,
}

impl ClockSync for Nominal {
    fn name(&self) -> &'static str {
        "none"
    }
    fn coupling(&self) -> Coupling {
        Coupling::MasterFollowsReference
    }
    fn update(&mut self, _: Option<&Sample>) -> Correction {
        Correction { shift_offsets_ns: 0, next_period_ns: Some(self.cycle_ns.max(1)) }
    }
}
