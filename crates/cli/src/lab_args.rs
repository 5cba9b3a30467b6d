//! The flags of the virtual-time lab experiments: what every experiment takes, then each
//! experiment's own, so that `--help` lists what applies and clap refuses the rest by name.
//! `lab run SCENARIO` takes every flag: the file says which experiment it is.
use std::path::PathBuf;
use std::process::ExitCode;

/// The cycle times the virtual-time lab takes, µs (the scenario reader's bounds).
fn lab_cycle_us(s: &str) -> Result<u64, String> {
    crate::args::cycle_us(s, 10, 100_000)
}

/// What every experiment takes.
#[derive(clap::Args)]
pub struct Common {
    /// The experiment's short form, in under a minute (docs/lab.md gives each one's).
    #[arg(long)]
    quick: bool,
    /// Seed of the simulation's random draws (crystals, latencies, faults): the same seed gives the same numbers on any machine (default: the scenario's, else 1).
    #[arg(long)]
    seed: Option<u64>,
    /// Host model: ideal, pc-rt, pc-stock, nic-hwts, beaglebone-rt, rtx-10us (default: the
    /// experiment's own).
    #[arg(long)]
    host: Option<String>,
    /// A segment file (as for `sim --config`) instead of the experiment's own segment.
    #[arg(long)]
    segment: Option<PathBuf>,
    /// Print JSON instead of text.
    #[arg(long)]
    json: bool,
    /// Folder for the CSV, the figures (SVG and PNG) and a Markdown report (made if missing).
    #[arg(long)]
    out: Option<PathBuf>,
}

/// A scenario file whose keys the flags override.
#[derive(clap::Args)]
pub struct ScenarioFile {
    /// A scenario file (TOML); the flags override its keys.
    #[arg(long = "scenario", value_name = "FILE")]
    file: Option<PathBuf>,
}

#[derive(clap::Args)]
pub struct Park2020 {
    #[command(flatten)]
    file: ScenarioFile,
    #[command(flatten)]
    common: Common,
    /// Methods (repeatable): none, conventional, park2020, ferrocat, ferrocat-mfr, and
    /// ferrocat's variants ferrocat-tcl, ferrocat-dense, ferrocat-mfr-dense, ferrocat-direct,
    /// ferrocat-mfr-direct (docs/clock-sync.md). Default: conventional, park2020, ferrocat,
    /// ferrocat-mfr.
    #[arg(long)]
    method: Vec<String>,
    /// Segment sizes (repeatable; default 2 and 6).
    #[arg(long)]
    slaves: Vec<usize>,
    /// The cycle time (µs, 10 to 100 000; default 1000).
    #[arg(long, allow_negative_numbers = true, value_parser = lab_cycle_us)]
    cycle_us: Option<u64>,
    /// Rounds per (segment, method).
    #[arg(long)]
    rounds: Option<u32>,
    /// ferrocat without its GPIO calibration of the stamps' asymmetry.
    #[arg(long)]
    no_gpio_calibration: bool,
    /// Fit the paper's set-up model on the part of its table it is fitted on, from the
    /// presets, and print every step instead of the table (docs/lab.md).
    #[arg(long)]
    fit: bool,
}

#[derive(clap::Args)]
pub struct Chen2016 {
    #[command(flatten)]
    file: ScenarioFile,
    #[command(flatten)]
    common: Common,
    /// Methods (repeatable): none, chen2016, pi, ferrocat (default: all four).
    #[arg(long)]
    method: Vec<String>,
    /// Cycle times (µs, 10 to 100 000; repeatable; default the paper's 500, 250, 100 and 50).
    #[arg(long, allow_negative_numbers = true, value_parser = lab_cycle_us)]
    cycle_us: Vec<u64>,
    /// Fit the paper's set-up model on the part of its table it is fitted on, from the
    /// presets, and print every step instead of the table (docs/lab.md).
    #[arg(long)]
    fit: bool,
}

#[derive(clap::Args)]
pub struct Paprocki2022 {
    #[command(flatten)]
    file: ScenarioFile,
    #[command(flatten)]
    common: Common,
    /// Methods (repeatable): none, conventional, park2020, chen2016, pi, ferrocat, ferrocat-mfr
    /// (default: none, conventional, park2020, ferrocat).
    #[arg(long)]
    method: Vec<String>,
    /// Cycle times (µs, 10 to 100 000; repeatable; default 1000 and 500).
    #[arg(long, allow_negative_numbers = true, value_parser = lab_cycle_us)]
    cycle_us: Vec<u64>,
    /// Leave the second drive's propagation delay uncompensated (its System_Time_Delay 0), as
    /// the paper's set-up does: the run is then held against the paper's Table 2.
    #[arg(long)]
    uncompensated_drive_delay: bool,
}

#[derive(clap::Args)]
pub struct Robustness {
    #[command(flatten)]
    file: ScenarioFile,
    #[command(flatten)]
    common: Common,
    /// Methods (repeatable): as park2020's.
    #[arg(long)]
    method: Vec<String>,
    /// The segment's size (slaves; default 2).
    #[arg(long)]
    slaves: Option<usize>,
    /// The cycle time (µs, 10 to 100 000; default 1000).
    #[arg(long, allow_negative_numbers = true, value_parser = lab_cycle_us)]
    cycle_us: Option<u64>,
    /// ferrocat without its GPIO calibration of the stamps' asymmetry.
    #[arg(long)]
    no_gpio_calibration: bool,
}

/// `lab run SCENARIO`: the file names the experiment; a flag that does not apply to it is
/// named by the scenario's check.
#[derive(clap::Args)]
pub struct Run {
    /// The scenario file (TOML; scenarios/ holds the papers' set-ups).
    scenario: PathBuf,
    #[command(flatten)]
    common: Common,
    /// Methods (repeatable): those the scenario's experiment takes (see its own --help).
    #[arg(long)]
    method: Vec<String>,
    /// park2020, robustness: segment sizes (repeatable for park2020).
    #[arg(long)]
    slaves: Vec<usize>,
    /// Cycle times (µs, 10 to 100 000; repeatable where the experiment takes several).
    #[arg(long, allow_negative_numbers = true, value_parser = lab_cycle_us)]
    cycle_us: Vec<u64>,
    /// park2020: rounds per (segment, method).
    #[arg(long)]
    rounds: Option<u32>,
    /// park2020, robustness: ferrocat without its GPIO calibration of the stamps' asymmetry.
    #[arg(long)]
    no_gpio_calibration: bool,
    /// paprocki2022: leave the second drive's propagation delay uncompensated.
    #[arg(long)]
    uncompensated_drive_delay: bool,
    /// park2020, chen2016: fit the paper's set-up model and print every step (docs/lab.md).
    #[arg(long)]
    fit: bool,
}

/// Every experiment's flags in one, as the scenario's check reads them.
#[derive(Default)]
struct Flags {
    scenario_file: Option<PathBuf>,
    quick: bool,
    seed: Option<u64>,
    host: Option<String>,
    segment: Option<PathBuf>,
    methods: Vec<String>,
    slaves: Vec<usize>,
    cycle_us: Vec<u64>,
    rounds: Option<u32>,
    no_gpio_calibration: bool,
    uncompensated_drive_delay: bool,
    fit: bool,
    json: bool,
    out: Option<PathBuf>,
}

impl Flags {
    fn new(file: Option<PathBuf>, c: Common) -> Flags {
        Flags {
            scenario_file: file,
            quick: c.quick,
            seed: c.seed,
            host: c.host,
            segment: c.segment,
            json: c.json,
            out: c.out,
            ..Flags::default()
        }
    }
}

use ferrocat_lab::scenario::Experiment;

impl Park2020 {
    pub fn run(self) -> anyhow::Result<ExitCode> {
        Flags {
            methods: self.method,
            slaves: self.slaves,
            cycle_us: self.cycle_us.into_iter().collect(),
            rounds: self.rounds,
            no_gpio_calibration: self.no_gpio_calibration,
            fit: self.fit,
            ..Flags::new(self.file.file, self.common)
        }
        .run(Some(Experiment::Park2020), None)
    }
}

impl Chen2016 {
    pub fn run(self) -> anyhow::Result<ExitCode> {
        Flags {
            methods: self.method,
            cycle_us: self.cycle_us,
            fit: self.fit,
            ..Flags::new(self.file.file, self.common)
        }
        .run(Some(Experiment::Chen2016), None)
    }
}

impl Paprocki2022 {
    pub fn run(self) -> anyhow::Result<ExitCode> {
        Flags {
            methods: self.method,
            cycle_us: self.cycle_us,
            uncompensated_drive_delay: self.uncompensated_drive_delay,
            ..Flags::new(self.file.file, self.common)
        }
        .run(Some(Experiment::Paprocki2022), None)
    }
}

impl Robustness {
    pub fn run(self) -> anyhow::Result<ExitCode> {
        Flags {
            methods: self.method,
            slaves: self.slaves.into_iter().collect(),
            cycle_us: self.cycle_us.into_iter().collect(),
            no_gpio_calibration: self.no_gpio_calibration,
            ..Flags::new(self.file.file, self.common)
        }
        .run(Some(Experiment::Robustness), None)
    }
}

impl Run {
    pub fn run(self) -> anyhow::Result<ExitCode> {
        Flags {
            methods: self.method,
            slaves: self.slaves,
            cycle_us: self.cycle_us,
            rounds: self.rounds,
            no_gpio_calibration: self.no_gpio_calibration,
            uncompensated_drive_delay: self.uncompensated_drive_delay,
            fit: self.fit,
            ..Flags::new(None, self.common)
        }
        .run(None, Some(self.scenario))
    }
}

impl Flags {
    fn run(self, experiment: Option<Experiment>, file: Option<PathBuf>) -> anyhow::Result<ExitCode> {
        use ferrocat_lab::scenario::{CycleUs, Scenario};
        let mut base = match file.or(self.scenario_file) {
            Some(f) => Scenario::from_file(&f)?,
            None => Scenario::default(),
        };
        if self.quick {
            // The keys `--quick` replaces are still checked: a bad value in the file is an
            // error with or without the flag.
            if base.experiment.is_some() || experiment.is_some() {
                base.plan(experiment, false)?;
            }
            base = base.quick();
        }
        let over = Scenario {
            host: self.host,
            seed: self.seed,
            segment: self.segment.map(|p| std::env::current_dir().unwrap_or_default().join(p)),
            methods: (!self.methods.is_empty()).then_some(self.methods),
            slaves: (!self.slaves.is_empty()).then_some(self.slaves),
            cycle_us: (!self.cycle_us.is_empty()).then_some(CycleUs::Many(self.cycle_us)),
            rounds: self.rounds,
            gpio_calibration: self.no_gpio_calibration.then_some(false),
            drive_delay_compensated: self.uncompensated_drive_delay.then_some(false),
            ..Scenario::default()
        };
        // The flags checked on their own first, so that an error names the flag, not the file.
        if let Some(e) = experiment.or(base.experiment) {
            Scenario { experiment: Some(e), ..over.clone() }.plan(None, self.quick)?;
        }
        let plan = base.overlay(over).plan(experiment, self.quick)?;
        if self.fit {
            anyhow::ensure!(self.out.is_none(), "--fit prints the fit; it writes no report (--out)");
            return crate::lab::fit(plan, self.json);
        }
        crate::lab::run(plan, self.json, self.out.as_deref())
    }
}

#[cfg(test)]
mod tests {
    use clap::CommandFactory;

    /// The help of each experiment lists exactly the methods its scenario check takes.
    #[test]
    fn each_experiment_lists_the_methods_it_takes() {
        let cli = crate::Cli::command();
        let lab = cli.find_subcommand("lab").unwrap();
        for (name, known) in [
            ("park2020", &ferrocat_lab::park2020::METHODS[..]),
            ("chen2016", &ferrocat_lab::chen2016::METHODS[..]),
            // The scenario's check takes every method of the lab for paprocki2022.
            ("paprocki2022", &ferrocat_lab::METHODS[..]),
        ] {
            let cmd = lab.find_subcommand(name).unwrap();
            let help = cmd.get_arguments().find(|a| a.get_id() == "method").unwrap().get_help().unwrap().to_string();
            let listed: Vec<&str> = help
                .split(|c: char| !(c.is_ascii_alphanumeric() || c == '-'))
                .filter(|w| known.contains(w) || ferrocat_lab::METHODS.contains(w))
                .collect();
            for m in known {
                assert!(listed.contains(m), "{name} --help leaves out {m}: {help}");
            }
            for m in &listed {
                assert!(known.contains(m), "{name} --help lists {m}, which {name} refuses: {help}");
            }
        }
    }
}
