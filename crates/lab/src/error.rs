//! What can go wrong in an experiment, each error naming what and where.
use std::path::PathBuf;

use ferrocat_master::cia402::State;
use ferrocat_master::MasterError;
use ferrocat_segment::SegmentError;

/// An experiment's error: the master's, the segment's, a setting's, or the experiment's own.
#[derive(Debug, thiserror::Error)]
#[non_exhaustive]
pub enum LabError {
    /// The master failed.
    #[error(transparent)]
    Master(#[from] MasterError),
    /// The simulated segment could not be built.
    #[error(transparent)]
    Segment(#[from] SegmentError),
    /// A method name that no preset has.
    #[error("unknown method {name:?} (known: {known})")]
    UnknownMethod {
        /// The name given.
        name: String,
        /// The presets, comma-separated.
        known: String,
    },
    /// A disturbance the robustness experiment does not know.
    #[error("unknown scenario {name:?} (known: {known})")]
    UnknownDisturbance {
        /// The name given.
        name: String,
        /// The known ones, comma-separated.
        known: String,
    },
    /// A setting out of its range, from the command line or a scenario file.
    #[error("{}: {what}", origin)]
    Setting {
        /// Where the setting came from.
        origin: SettingOrigin,
        /// What is wrong with it.
        what: String,
    },
    /// A scenario file that could not be read.
    #[error("reading scenario {}: {error}", path.display())]
    ScenarioRead {
        /// The file.
        path: PathBuf,
        /// Why.
        error: std::io::Error,
    },
    /// A scenario file that is no scenario.
    #[error("scenario {}: {error}", path.display())]
    ScenarioParse {
        /// The file.
        path: PathBuf,
        /// The TOML reader's error, with line and column.
        error: toml::de::Error,
    },
    /// A segment with no DC slave.
    #[error("the segment has no slave with distributed clocks")]
    NoDcSlave,
    /// A segment with fewer DC slaves than the experiment needs.
    #[error("{what} needs {needed} DC slaves; the segment has {found}")]
    TooFewDcSlaves {
        /// What needs them.
        what: &'static str,
        /// How many it needs.
        needed: usize,
        /// How many the segment has.
        found: usize,
    },
    /// A disturbance that needs a ring segment, on a line.
    #[error("{0} needs a ring segment (one with [secondary])")]
    NeedsRing(&'static str),
    /// Chen 2016's experiment on a segment whose slaves do not count SYNC0 events.
    #[error("the segment has no DC-synchronous slave (app = \"dc\")")]
    NoDcSynchronousSlave,
    /// Chen 2016's experiment on DC-synchronous slaves without outputs.
    #[error(
        "no DC-synchronous slave (app = \"dc\") of the segment has process-data outputs (slaves {0:?} have none): \
         there would be no cycle to lose or repeat"
    )]
    NoSynchronousOutputs(Vec<u16>),
    /// The demo asked for no drive.
    #[error("at least one drive")]
    NoDrives,
    /// A demo segment without a CiA402 drive.
    #[error("no CiA402 drive on the segment (no slave maps 0x6040 and 0x6041)")]
    NoDrive,
    /// The demo's `--drive` names a device without a CoE mailbox.
    #[error("--drive {drive}: {name} has no CoE mailbox in its SII, so it is no CiA402 drive")]
    NotADrive {
        /// The `--drive` argument.
        drive: String,
        /// The device's name.
        name: String,
    },
    /// The demo's `--drive` names a drive of the SoE profile, which the demo does not drive.
    #[error(
        "--drive {drive}: {name} is a drive of the SoE profile (its SII names SoE{}, its objects no CiA402 \
         controlword 0x6040 or statusword 0x6041): the demo drives CiA402 drives only; the SoE profile's \
         master control word (S-0-0134) and drive status word (S-0-0135) are not modelled in it \
         (`ferrocat soe` reads and writes its IDNs)",
        if *coe { " beside CoE" } else { ", not CoE" }
    )]
    SoeProfile {
        /// The `--drive` argument.
        drive: String,
        /// The device's name.
        name: String,
        /// Whether its mailbox speaks CoE too.
        coe: bool,
    },
    /// A drive axis whose process image has neither target.
    #[error(
        "slave {position} axis {axis}: neither a target position (0x607A) nor a target velocity (0x60FF) in the process image, so no cyclic synchronous mode to run; its outputs: {outputs} (set-points of another kind are not driven by the demo)"
    )]
    NoTarget {
        /// The drive's position.
        position: u16,
        /// The axis.
        axis: u8,
        /// The objects its outputs map (`0x606B Velocity demand value, …`).
        outputs: String,
    },
    /// A drive whose SYNC pulse outlasts the cycle: its SYNC0 output stays active.
    #[error(
        "slave {position}: its SYNC pulse (0x0982, from its SII) is {} µs, longer than the {} µs cycle: \
         its SYNC0 output stays active after the first pulse (ESC datasheet section I, 9.2.3.1), so the drive \
         would run once; give a cycle of at least the pulse",
        *pulse_ns as f64 / 1e3, *cycle_ns as f64 / 1e3
    )]
    Sync0Held {
        /// The drive's position.
        position: u16,
        /// Its SYNC pulse, ns.
        pulse_ns: u64,
        /// The cycle asked, ns.
        cycle_ns: u64,
    },
    /// Drives that did not reach Operation enabled.
    #[error("drives not enabled: {0:?}")]
    DrivesNotEnabled(Vec<Option<State>>),
    /// The SYNC0 pulses the experiment counts stopped.
    #[error("SYNC0 pulses stopped")]
    Sync0Stopped,
    /// A robustness run's control that is not the same run before the disturbance.
    #[error("the undisturbed control of {0} differs from its disturbed run before the disturbance")]
    ControlDiffers(String),
    /// A result the experiment needs and did not get.
    #[error("{0}")]
    MissingRow(String),
    /// A master on a real network could not be opened (the caller's error).
    #[error("{0}")]
    Open(Box<dyn std::error::Error + Send + Sync>),
    /// The experiment's own segment description (a bug of the lab's, never the user's).
    #[error("the experiment's own segment description: {0}")]
    OwnSegment(#[from] toml::de::Error),
    /// One run of an experiment failed.
    #[error("{run}: {error}")]
    Run {
        /// The run ("1000 µs, ferrocat").
        run: String,
        /// What failed.
        error: Box<LabError>,
    },
}

/// Where a setting came from.
#[derive(Debug, Clone, PartialEq, Eq)]
pub enum SettingOrigin {
    /// A command-line flag ("--cycle-us").
    Flag(String),
    /// A key of a scenario file.
    File {
        /// The file.
        path: PathBuf,
        /// The key.
        key: String,
    },
}

impl std::fmt::Display for SettingOrigin {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        match self {
            SettingOrigin::Flag(flag) => write!(f, "--{flag}"),
            SettingOrigin::File { path, key } => write!(f, "scenario {}: `{key}`", path.display()),
        }
    }
}

impl LabError {
    /// This error, within the run named `run`.
    pub fn in_run(self, run: impl Into<String>) -> LabError {
        LabError::Run { run: run.into(), error: Box::new(self) }
    }
}

/// An experiment's result.
pub type Result<T> = std::result::Result<T, LabError>;
