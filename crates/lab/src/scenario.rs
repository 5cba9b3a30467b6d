//! Lab scenarios in TOML: which experiment, on which segment and host, with which methods,
//! cycle times, durations, samples, rounds and seed. Every key but `experiment` is optional
//! (the experiment's published set-up fills the rest); a key that does not apply to the
//! experiment, an unknown method or an out-of-range value is an error naming the file and key.
use std::path::{Path, PathBuf};

use crate::{LabError, SettingOrigin};
use ferrocat_segment::HostModel;
use ferrocat_segment::SegmentConfig;
use serde::Deserialize;

/// The shortest time measured after a robustness disturbance (s): ten recovery criteria of 100 ms.
const MIN_AFTER_S: f64 = 1.0;

#[derive(Debug, Clone, Copy, PartialEq, Eq, Deserialize)]
#[serde(rename_all = "lowercase")]
pub enum Experiment {
    Park2020,
    Chen2016,
    Paprocki2022,
    Robustness,
}

impl Experiment {
    pub fn name(self) -> &'static str {
        match self {
            Experiment::Park2020 => "park2020",
            Experiment::Chen2016 => "chen2016",
            Experiment::Paprocki2022 => "paprocki2022",
            Experiment::Robustness => "robustness",
        }
    }

    /// The host each experiment is published (or set up) with.
    pub fn default_host(self) -> &'static str {
        match self {
            Experiment::Park2020 => "beaglebone-rt",
            Experiment::Chen2016 => "rtx-10us",
            Experiment::Paprocki2022 | Experiment::Robustness => "pc-rt",
        }
    }
}

/// One cycle time or several.
#[derive(Debug, Clone, PartialEq, Deserialize)]
#[serde(untagged)]
pub enum CycleUs {
    One(u64),
    Many(Vec<u64>),
}

impl CycleUs {
    fn list(&self) -> Vec<u64> {
        match self {
            CycleUs::One(c) => vec![*c],
            CycleUs::Many(v) => v.clone(),
        }
    }
}

/// A scenario file as written.
#[derive(Debug, Clone, Default, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct Scenario {
    pub experiment: Option<Experiment>,
    /// A host-model preset (`HostModel::PRESETS`).
    pub host: Option<String>,
    pub seed: Option<u64>,
    /// A segment file (as for `ferrocat sim --config`), relative to the scenario's folder.
    pub segment: Option<PathBuf>,
    pub methods: Option<Vec<String>>,
    pub cycle_us: Option<CycleUs>,
    /// park2020 and robustness: lines of this many EK1100s (no `segment`).
    pub slaves: Option<Vec<usize>>,
    pub settle_s: Option<f64>,
    /// chen2016: seconds per run; robustness: seconds measured after the disturbance.
    pub duration_s: Option<f64>,
    pub samples: Option<u64>,
    /// park2020: a sample every this many cycles.
    pub sample_every: Option<u64>,
    pub rounds: Option<u32>,
    /// chen2016: the reference's crystal error without a `segment`.
    pub reference_ppm: Option<f64>,
    /// robustness: which disturbances.
    pub disturbances: Option<Vec<String>>,
    /// park2020: whether ferrocat calibrates through the host's GPIO (default true).
    pub gpio_calibration: Option<bool>,
    /// robustness: whether each method also runs undisturbed, the control every disturbed run
    /// is compared with (default true).
    pub control: Option<bool>,
    /// paprocki2022: whether the second drive's propagation delay is compensated (default
    /// true; false tests the paper's ≈ 0.8 µs against a delay its master left out).
    pub drive_delay_compensated: Option<bool>,
    #[serde(skip)]
    pub path: PathBuf,
}

/// The experiment's options with a scenario applied.
#[derive(Debug, Clone)]
pub enum Plan {
    Park2020(crate::park2020::Options),
    Chen2016(crate::chen2016::Options),
    Paprocki2022(crate::paprocki2022::Options),
    Robustness(crate::robustness::Options),
}

impl Scenario {
    /// `over`'s keys replace this scenario's (the command line over a file).
    pub fn overlay(mut self, over: Scenario) -> Scenario {
        macro_rules! take {
            ($($k:ident),*) => { $( if over.$k.is_some() { self.$k = over.$k; } )* };
        }
        take!(experiment, host, seed, segment, methods, cycle_us, slaves, settle_s, duration_s, samples);
        take!(sample_every, rounds, reference_ppm, disturbances, gpio_calibration, control, drive_delay_compensated);
        self
    }

    pub fn from_file(path: &Path) -> crate::Result<Scenario> {
        let text = ferrocat_segment::files::read_toml(path, "a scenario")
            .map_err(|error| LabError::ScenarioRead { path: path.to_path_buf(), error })?;
        let mut s: Scenario =
            toml::from_str(&text).map_err(|error| LabError::ScenarioParse { path: path.to_path_buf(), error })?;
        s.path = path.to_path_buf();
        Ok(s)
    }

    /// An error for `key` unless `ok` (a NaN fails every comparison, and so this check).
    fn require(&self, ok: bool, key: &str, what: impl std::fmt::Display) -> crate::Result<()> {
        if ok {
            Ok(())
        } else {
            Err(self.err(key, what))
        }
    }

    fn err(&self, key: &str, what: impl std::fmt::Display) -> LabError {
        let origin = if self.path.as_os_str().is_empty() {
            // The command line's flag for the key.
            SettingOrigin::Flag(if key == "methods" { "method".to_string() } else { key.replace('_', "-") })
        } else {
            SettingOrigin::File { path: self.path.clone(), key: key.into() }
        };
        LabError::Setting { origin, what: what.to_string() }
    }

    /// This scenario without its durations, sample counts and rounds: what `--quick` replaces.
    pub fn quick(self) -> Scenario {
        Scenario { settle_s: None, duration_s: None, samples: None, rounds: None, ..self }
    }

    /// The options of `experiment` (the scenario's own when `None`): the published set-up
    /// (`quick`: its short form), then the scenario's keys.
    pub fn plan(&self, experiment: Option<Experiment>, quick: bool) -> crate::Result<Plan> {
        let exp = match (experiment, self.experiment) {
            (Some(a), Some(b)) if a != b => {
                return Err(self.err("experiment", format!("is {}, not {}", b.name(), a.name())))
            }
            (Some(a), _) | (None, Some(a)) => a,
            (None, None) => return Err(self.err("experiment", "missing")),
        };
        let h = self.host.as_deref().unwrap_or(exp.default_host());
        let host = HostModel::preset(h).ok_or_else(|| {
            self.err("host", format!("unknown preset {h:?} (known: {})", HostModel::PRESETS.join(", ")))
        })?;
        let segment = self.segment()?;
        let applies = |key: &str, set: bool, ok: &[Experiment]| -> crate::Result<()> {
            if set && !ok.contains(&exp) {
                return Err(self.err(key, format!("does not apply to {}", exp.name())));
            }
            Ok(())
        };
        use Experiment::*;
        applies("slaves", self.slaves.is_some(), &[Park2020, Robustness])?;
        applies("sample_every", self.sample_every.is_some(), &[Park2020])?;
        applies("rounds", self.rounds.is_some(), &[Park2020])?;
        applies("samples", self.samples.is_some(), &[Park2020, Paprocki2022])?;
        applies("duration_s", self.duration_s.is_some(), &[Chen2016, Robustness])?;
        applies("settle_s", self.settle_s.is_some(), &[Park2020, Paprocki2022, Robustness])?;
        applies("reference_ppm", self.reference_ppm.is_some(), &[Chen2016])?;
        applies("disturbances", self.disturbances.is_some(), &[Robustness])?;
        applies("gpio_calibration", self.gpio_calibration.is_some(), &[Park2020, Robustness])?;
        applies("control", self.control.is_some(), &[Robustness])?;
        applies("drive_delay_compensated", self.drive_delay_compensated.is_some(), &[Paprocki2022])?;
        if self.segment.is_some() && (self.slaves.is_some() || self.reference_ppm.is_some()) {
            let key = if self.slaves.is_some() { "slaves" } else { "reference_ppm" };
            return Err(self.err(key, "describes the default segment; with `segment` set it has no meaning"));
        }
        let cycles = self.cycles()?;
        let methods = |known: &[&str]| -> crate::Result<Option<Vec<String>>> {
            let Some(ms) = &self.methods else { return Ok(None) };
            self.require(!ms.is_empty(), "methods", "empty")?;
            if let Some(m) = ms.iter().find(|m| !known.contains(&m.as_str())) {
                return Err(self.err("methods", format!("{m:?} is not one of {}", known.join(", "))));
            }
            Ok(Some(ms.clone()))
        };
        let positive = |key: &str, v: Option<f64>| -> crate::Result<Option<f64>> {
            match v {
                Some(x) if !(0.0..=86_400.0).contains(&x) => {
                    Err(self.err(key, format!("{x:?} is not between 0 and 86400 s")))
                }
                v => Ok(v),
            }
        };
        let settle_s = positive("settle_s", self.settle_s)?;
        let duration_s = positive("duration_s", self.duration_s)?;
        if let Some(n) = self.samples {
            self.require((1..=100_000_000).contains(&n), "samples", format!("{n} is not between 1 and 10^8"))?;
        }
        let one_cycle = |cycles: &Option<Vec<u64>>| -> crate::Result<Option<u64>> {
            match cycles.as_deref() {
                None => Ok(None),
                Some([c]) => Ok(Some(*c)),
                Some(_) => Err(self.err("cycle_us", format!("{} takes one cycle time", exp.name()))),
            }
        };
        Ok(match exp {
            Park2020 => {
                let mut o =
                    if quick { crate::park2020::Options::quick(host) } else { crate::park2020::Options::full(host) };
                if let Some(m) = methods(&crate::park2020::METHODS)? {
                    o.methods = m;
                }
                if let Some(c) = one_cycle(&cycles)? {
                    o.cycle_ns = c * 1000;
                }
                if let Some(v) = self.slaves(&segment)? {
                    o.slaves = v;
                }
                o.segment = segment;
                if let Some(s) = settle_s {
                    o.settle_s = s;
                }
                if let Some(n) = self.samples {
                    o.samples = n;
                }
                if let Some(n) = self.sample_every {
                    self.require((1..=10_000).contains(&n), "sample_every", "must be between 1 and 10000")?;
                    o.sample_every = n;
                }
                if let Some(r) = self.rounds {
                    self.require((1..=1000).contains(&r), "rounds", "must be between 1 and 1000")?;
                    o.rounds = r;
                }
                o.gpio_calibration = self.gpio_calibration.unwrap_or(o.gpio_calibration);
                o.seed = self.seed.unwrap_or(o.seed);
                Plan::Park2020(o)
            }
            Chen2016 => {
                let mut o =
                    if quick { crate::chen2016::Options::quick(host) } else { crate::chen2016::Options::full(host) };
                if let Some(m) = methods(&crate::chen2016::METHODS)? {
                    o.methods = m;
                }
                if let Some(c) = cycles {
                    o.cycles_us = c;
                }
                o.segment = segment;
                if let Some(p) = self.reference_ppm {
                    self.require(p.is_finite() && p.abs() <= 1000.0, "reference_ppm", "must be within ±1000 ppm")?;
                    o.reference_ppm = p;
                }
                if let Some(d) = duration_s {
                    self.require(d > 0.0, "duration_s", "must be positive")?;
                    o.seconds = d;
                }
                o.seed = self.seed.unwrap_or(o.seed);
                Plan::Chen2016(o)
            }
            Paprocki2022 => {
                let mut o = crate::paprocki2022::Options::new(host);
                if let Some(m) = methods(&crate::METHODS)? {
                    o.methods = m;
                }
                if let Some(c) = cycles {
                    o.cycles_us = c;
                }
                o.segment = segment;
                if let Some(s) = settle_s {
                    o.settle_s = s;
                }
                if let Some(n) = self.samples {
                    o.samples = n as usize;
                }
                o.drive_delay_compensated = self.drive_delay_compensated.unwrap_or(true);
                o.seed = self.seed.unwrap_or(o.seed);
                Plan::Paprocki2022(o)
            }
            Robustness => {
                let mut o = crate::robustness::Options::new(host);
                if let Some(m) = methods(&crate::park2020::METHODS)? {
                    o.methods = m;
                }
                if let Some(c) = one_cycle(&cycles)? {
                    o.cycle_ns = c * 1000;
                }
                if let Some(v) = self.slaves(&segment)? {
                    match v.as_slice() {
                        [n] => o.slaves = *n,
                        _ => return Err(self.err("slaves", "robustness takes one segment size")),
                    }
                }
                o.segment = segment;
                if let Some(s) = settle_s {
                    self.require(
                        s > o.band_window_s,
                        "settle_s",
                        format!("must exceed the band window of {} s", o.band_window_s),
                    )?;
                    o.settle_s = s;
                }
                if let Some(d) = duration_s {
                    // Recovery is judged by the run's last 10 % and the after-figures are its
                    // last half: a shorter window had none of them (NaN in the table).
                    self.require(
                        d >= MIN_AFTER_S,
                        "duration_s",
                        format!("must be at least {MIN_AFTER_S} s after the disturbance"),
                    )?;
                    o.after_s = d;
                }
                o.gpio_calibration = self.gpio_calibration.unwrap_or(o.gpio_calibration);
                if let Some(ds) = &self.disturbances {
                    if let Some(d) = ds.iter().find(|d| !crate::robustness::KNOWN.contains(&d.as_str())) {
                        return Err(self.err(
                            "disturbances",
                            format!("{d:?} is not one of {}", crate::robustness::KNOWN.join(", ")),
                        ));
                    }
                    o.scenarios = ds.clone();
                }
                o.control = self.control.unwrap_or(o.control);
                o.seed = self.seed.unwrap_or(o.seed);
                Plan::Robustness(o)
            }
        })
    }

    fn segment(&self) -> crate::Result<Option<SegmentConfig>> {
        let Some(p) = &self.segment else { return Ok(None) };
        let path = self.path.parent().unwrap_or(Path::new("")).join(p);
        let cfg = SegmentConfig::from_file(&path).map_err(|e| self.err("segment", e))?;
        // Build it once here so that an unknown device or unreadable file shows now, not per run.
        cfg.build().map_err(|e| self.err("segment", e))?;
        Ok(Some(cfg))
    }

    fn slaves(&self, segment: &Option<SegmentConfig>) -> crate::Result<Option<Vec<usize>>> {
        if let Some(cfg) = segment {
            return Ok(Some(vec![cfg.devices.len()]));
        }
        let Some(v) = &self.slaves else { return Ok(None) };
        self.require(!v.is_empty(), "slaves", "empty")?;
        if let Some(n) = v.iter().find(|n| !(1..=64).contains(*n)) {
            return Err(self.err("slaves", format!("{n} is not between 1 and 64")));
        }
        Ok(Some(v.clone()))
    }

    fn cycles(&self) -> crate::Result<Option<Vec<u64>>> {
        let Some(c) = &self.cycle_us else { return Ok(None) };
        let v = c.list();
        self.require(!v.is_empty(), "cycle_us", "empty")?;
        if let Some(c) = v.iter().find(|c| !(10..=100_000).contains(*c)) {
            return Err(self.err("cycle_us", format!("{c} µs is not between 10 and 100000")));
        }
        Ok(Some(v))
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn scenario(text: &str) -> crate::Result<Plan> {
        let mut s: Scenario = toml::from_str(text)?;
        s.path = "test.toml".into();
        s.plan(None, false)
    }

    #[test]
    fn a_scenario_overrides_the_published_set_up() {
        let Plan::Park2020(o) = scenario(
            "experiment = 'park2020'\nhost = 'beaglebone-rt'\nseed = 7\nslaves = [3]\nmethods = ['ferrocat']\n\
             settle_s = 1\nsamples = 10\nrounds = 2\ncycle_us = 500\ngpio_calibration = false\n",
        )
        .unwrap() else {
            panic!("not park2020")
        };
        assert_eq!((o.seed, o.slaves.clone(), o.methods.clone(), o.rounds), (7, vec![3], vec!["ferrocat".into()], 2));
        assert_eq!((o.settle_s, o.samples, o.cycle_ns, o.host.name), (1.0, 10, 500_000, "beaglebone-rt"));
        assert!(!o.gpio_calibration);
        let Plan::Robustness(o) =
            scenario("experiment = 'robustness'\ngpio_calibration = false\ncontrol = false\n").unwrap()
        else {
            panic!("not robustness")
        };
        assert!(!o.gpio_calibration && !o.control);
        let Plan::Chen2016(o) = scenario("experiment = 'chen2016'\ncycle_us = [100, 50]\nduration_s = 3\n").unwrap()
        else {
            panic!("not chen2016")
        };
        assert_eq!((o.cycles_us.clone(), o.seconds), (vec![100, 50], 3.0));
    }

    /// Every scenario shipped in scenarios/ plans, with its segment.
    #[test]
    fn the_shipped_scenarios_plan() {
        let dir = Path::new(env!("CARGO_MANIFEST_DIR")).join("../../scenarios");
        let mut n = 0;
        for e in std::fs::read_dir(&dir).unwrap() {
            let p = e.unwrap().path();
            if p.extension().is_some_and(|x| x == "toml") {
                Scenario::from_file(&p).and_then(|s| s.plan(None, false)).unwrap_or_else(|e| panic!("{e:#}"));
                n += 1;
            }
        }
        assert!(n >= 5, "{n} scenarios in {}", dir.display());
    }

    #[test]
    fn bad_scenarios_name_the_file_and_key() {
        for (text, key) in [
            ("experiment = 'chen2016'\nrounds = 3\n", "`rounds`"),
            ("experiment = 'park2020'\nmethods = ['magic']\n", "`methods`"),
            ("experiment = 'park2020'\nmethods = ['pi']\n", "`methods`"),
            ("experiment = 'park2020'\ncycle_us = [1000, 500]\n", "`cycle_us`"),
            ("experiment = 'paprocki2022'\ncycle_us = 5\n", "`cycle_us`"),
            ("experiment = 'park2020'\nhost = 'cray'\n", "`host`"),
            ("experiment = 'park2020'\nsettle_s = -1\n", "`settle_s`"),
            ("experiment = 'park2020'\nslaves = [0]\n", "`slaves`"),
            ("host = 'pc-rt'\n", "`experiment`"),
            ("experiment = 'robustness'\ndisturbances = ['earthquake']\n", "`disturbances`"),
            ("experiment = 'chen2016'\ngpio_calibration = false\n", "`gpio_calibration`"),
            ("experiment = 'park2020'\ncontrol = false\n", "`control`"),
            // Shorter than the recovery window: the table had NaN for its after-figures.
            ("experiment = 'robustness'\nduration_s = 0.0001\n", "`duration_s`"),
        ] {
            let e = format!("{:#}", scenario(text).unwrap_err());
            assert!(e.contains("test.toml") && e.contains(key), "{text}: {e}");
        }
        let e = toml::from_str::<Scenario>("experiment = 'park2020'\ncolour = 'red'\n").unwrap_err();
        assert!(e.to_string().contains("colour"), "{e}");
    }
}
