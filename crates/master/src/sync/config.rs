//! Clock synchronisation as one configuration value: which method, with its settings, units
//! and defaults. [`Clock::start_clock_sync`](crate::part::Clock::start_clock_sync) turns it into a running method in the
//! right order with the DC initialisation.
use super::{Chen2016, ClockSync, Conventional, Coupling, Ferrocat, Nominal, Park2020, SoemPi, Steering};

/// A clock-synchronisation method and its settings. The default is ferrocat's own method with
/// the reference following the master.
#[derive(Debug, Clone, Copy, PartialEq)]
pub enum SyncMethod {
    /// No correction at all: the master keeps its nominal period and writes nothing (a
    /// baseline).
    None,
    /// What IgH and TwinCAT do by default: the master's time written into the reference's
    /// 0x0910 every cycle, its transit to the reference left uncompensated.
    Conventional,
    /// Park et al. 2020: the master's time plus the master–reference delay of eq. 3 averaged
    /// over `round_trips` round trips before cyclic operation, and every `period_ns` an EMA
    /// (weight `alpha`) of the reference's 0x092C taken out of every offset (eqs. 4–5).
    Park2020 {
        /// Round trips averaged for the delay (default 1 000, as published).
        round_trips: u32,
        /// EMA weight of the newest 0x092C reading (default 0.25).
        alpha: f64,
        /// How often the bias is corrected, ns (default 100 ms).
        period_ns: u64,
    },
    /// Chen et al. 2016: the master follows the reference, rescaling its period from `samples`
    /// timestamp differences per speed update, its periods rounded to the host's timer
    /// resolution (`Io::timer_resolution_ns`) with the truncation carried over.
    Chen2016 {
        /// Timestamp differences per speed update (default 100).
        samples: u32,
    },
    /// SOEM's examples: the master follows the reference with a PI loop on the reference's
    /// time modulo the cycle, less `shift_ns` (default 0).
    Pi {
        /// Where in the cycle the master aims to send, ns after the reference's cycle start.
        shift_ns: i64,
    },
    /// ferrocat's own: a line fitted through round-trip-corrected stamps of the reference's
    /// time (docs/clock-sync.md).
    Ferrocat(FerrocatSettings),
}

impl Default for SyncMethod {
    fn default() -> Self {
        SyncMethod::Ferrocat(FerrocatSettings::default())
    }
}

/// The settings of ferrocat's own method.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct FerrocatSettings {
    /// Who follows whom (default: the reference follows the master).
    pub coupling: Coupling,
    /// Reference follows master: steer the reference's System_Time_Offset (default) or write
    /// the master's time into its time control loop.
    pub steering: Steering,
    /// Use a 64-bit follower's crystal as a flywheel between the reference's points, where
    /// the segment has one (default true).
    pub flywheel: bool,
    /// Probe the reference in half of every cycle, not only while the line is uncertain, with
    /// the shorter dense window (default false; no flywheel then).
    pub dense: bool,
}

impl Default for FerrocatSettings {
    fn default() -> Self {
        FerrocatSettings {
            coupling: Coupling::ReferenceFollowsMaster,
            steering: Steering::Offset,
            flywheel: true,
            dense: false,
        }
    }
}

impl SyncMethod {
    /// The named presets: the papers' methods as published, the baselines, and ferrocat's
    /// variants.
    pub const PRESETS: [&'static str; 12] = {
        let mut all = ["none", "conventional", "park2020", "chen2016", "pi", "", "", "", "", "", "", ""];
        let mut k = 0;
        while k < Self::FERROCAT_PRESETS.len() {
            all[5 + k] = Self::FERROCAT_PRESETS[k];
            k += 1;
        }
        all
    };

    /// The presets of ferrocat's own method.
    pub const FERROCAT_PRESETS: [&'static str; 7] = [
        "ferrocat",
        "ferrocat-mfr",
        "ferrocat-tcl",
        "ferrocat-dense",
        "ferrocat-mfr-dense",
        "ferrocat-direct",
        "ferrocat-mfr-direct",
    ];

    /// A preset by name (see [`SyncMethod::PRESETS`]). `ferrocat`, `ferrocat-dense` and
    /// `ferrocat-direct` take `coupling`; the `-mfr` ones have the master follow the
    /// reference; `ferrocat-tcl` has the reference follow the master through its time control
    /// loop.
    pub fn preset(name: &str, coupling: Coupling) -> Option<Self> {
        let ferrocat = |coupling, flywheel, dense| {
            SyncMethod::Ferrocat(FerrocatSettings { coupling, steering: Steering::Offset, flywheel, dense })
        };
        let mfr = Coupling::MasterFollowsReference;
        Some(match name {
            "none" => SyncMethod::None,
            "conventional" => SyncMethod::Conventional,
            "park2020" => SyncMethod::Park2020 { round_trips: 1000, alpha: 0.25, period_ns: 100_000_000 },
            "chen2016" => SyncMethod::Chen2016 { samples: 100 },
            "pi" => SyncMethod::Pi { shift_ns: 0 },
            "ferrocat" => ferrocat(coupling, true, false),
            "ferrocat-mfr" => ferrocat(mfr, true, false),
            "ferrocat-tcl" => SyncMethod::Ferrocat(FerrocatSettings {
                coupling: Coupling::ReferenceFollowsMaster,
                steering: Steering::TimeControlLoop,
                flywheel: false,
                dense: false,
            }),
            "ferrocat-dense" => ferrocat(coupling, false, true),
            "ferrocat-mfr-dense" => ferrocat(mfr, false, true),
            "ferrocat-direct" => ferrocat(coupling, false, false),
            "ferrocat-mfr-direct" => ferrocat(mfr, false, false),
            _ => return None,
        })
    }

    /// Whether the method is ferrocat's own, which the master makes before the DC
    /// initialisation (so that one steering the reference's offset does so from the static
    /// drift compensation on) and which takes out what a calibration measured.
    pub fn is_ferrocat(&self) -> bool {
        matches!(self, SyncMethod::Ferrocat(_))
    }

    /// Who follows whom under this method.
    pub fn coupling(&self) -> Coupling {
        match self {
            SyncMethod::None | SyncMethod::Chen2016 { .. } | SyncMethod::Pi { .. } => Coupling::MasterFollowsReference,
            SyncMethod::Ferrocat(f) => f.coupling,
            _ => Coupling::ReferenceFollowsMaster,
        }
    }

    /// The method for a cycle of `cycle_ns`: `park_delay_ns` is Park's measured delay
    /// (ignored by the others), `timer_resolution_ns` the host's timer granularity.
    pub(crate) fn build(&self, cycle_ns: u64, park_delay_ns: i64, timer_resolution_ns: u64) -> Box<dyn ClockSync> {
        match *self {
            SyncMethod::None => Box::new(Nominal { cycle_ns }),
            SyncMethod::Conventional => Box::new(Conventional),
            SyncMethod::Park2020 { alpha, period_ns, .. } => {
                let mut p = Park2020::new(park_delay_ns);
                p.alpha = alpha;
                p.period_ns = period_ns;
                Box::new(p)
            }
            SyncMethod::Chen2016 { samples } => Box::new(Chen2016::new(cycle_ns, samples, timer_resolution_ns)),
            SyncMethod::Pi { shift_ns } => Box::new(SoemPi::new(cycle_ns, shift_ns)),
            SyncMethod::Ferrocat(f) => {
                let mut s =
                    if f.dense { Ferrocat::dense(f.coupling, cycle_ns) } else { Ferrocat::new(f.coupling, cycle_ns) };
                s = s.with_steering(f.steering);
                if f.flywheel && !f.dense {
                    s = s.with_flywheel();
                }
                Box::new(s)
            }
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn every_preset_is_known_and_builds_the_method_of_its_name() {
        for name in SyncMethod::PRESETS {
            let m = SyncMethod::preset(name, Coupling::ReferenceFollowsMaster).unwrap();
            let built = m.build(1_000_000, 0, 1);
            let family = name.split('-').next().unwrap();
            assert!(built.name().starts_with(family), "{name} built {}", built.name());
            assert_eq!(built.coupling(), m.coupling(), "{name}");
        }
        assert!(SyncMethod::PRESETS.iter().all(|p| !p.is_empty()));
        assert_eq!(SyncMethod::preset("Ferrocat", Coupling::ReferenceFollowsMaster), None);
        assert_eq!(SyncMethod::default(), SyncMethod::preset("ferrocat", Coupling::ReferenceFollowsMaster).unwrap());
    }
}
