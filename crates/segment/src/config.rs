//! Segment descriptions: a TOML file, or a line of devices from the command line.
//!
//! ```toml
//! seed = 7
//! [[device]]
//! eeprom = "../shared/captures/eeprom/ek1100.hex"
//! [[device]]
//! esi = "../shared/esi/Nanotec_C5-E-2-21.xml"
//! product = 0x4F
//! drift_ppm = 12.5
//! parent = 0        # index or name; default: the device before
//! parent_port = 1   # default: the parent's next free port in processing order
//! port = 0          # this device's port toward the parent (the master for the first)
//! ```
use std::path::{Path, PathBuf};

use ferrocat_esc::{
    Application, Cia402Drive, CoeDevice, DigitalIo, Esc, EscConfig, FoeServer, MailboxResponse, NoApplication,
    PassiveLogic, Switches, SyncApp, SyncMode,
};
use ferrocat_esi::EsiFile;
use ferrocat_wire::register::{PortDescriptor, PortType};
use ferrocat_wire::sii::dump::parse_dump;
use ferrocat_wire::sii::SiiInfo;
use rand::{Rng, SeedableRng};
use rand_chacha::ChaCha8Rng;
use serde::Deserialize;

use crate::files::{read_eeprom_dump, read_esi, read_toml};
use crate::segment::{Event, Node, Segment};
use crate::timing::{link_delay_ns, EscTiming, PortKind};

#[derive(Debug, thiserror::Error)]
pub enum SegmentError {
    /// The reason is in the message and not a `source`: shown with its chain (`{:#}`), it
    /// would appear twice.
    #[error("{path}: {reason}")]
    Io { path: PathBuf, reason: std::io::Error },
    #[error("{path}: {message}")]
    Parse { path: PathBuf, message: String },
    #[error("{place}: {message}")]
    Device { place: String, message: String },
}

/// Changes an SII image's header (its first 16 bytes) and keeps its CRC right; an image too
/// short to have one is left alone (loading it reports that).
fn patch_sii_header(sii: &mut [u8], change: impl FnOnce(&mut [u8])) {
    if sii.len() >= 16 {
        change(&mut sii[..16]);
        sii[14] = ferrocat_wire::sii::header_crc(sii);
    }
}

fn device_err(place: impl Into<String>, message: impl Into<String>) -> SegmentError {
    SegmentError::Device { place: place.into(), message: message.into() }
}

/// A drive's switches from its device table: finite positions, the negative limit below the
/// positive one.
fn switches(d: &DeviceToml, place: &str) -> Result<Switches, SegmentError> {
    let rev = |key: &str, v: Option<f64>| v.map(|v| in_range(place, key, v, -1e9..=1e9)).transpose();
    let sw = Switches {
        negative_limit_rev: rev("negative_limit_rev", d.negative_limit_rev)?,
        positive_limit_rev: rev("positive_limit_rev", d.positive_limit_rev)?,
        home_rev: rev("home_switch_rev", d.home_switch_rev)?,
        home_active_below: d.home_switch_below.unwrap_or(false),
        home_to_rev: rev("home_switch_to_rev", d.home_switch_to_rev)?,
    };
    if let Some(to) = sw.home_to_rev {
        match sw.home_rev {
            Some(from) if from < to && !sw.home_active_below => {}
            Some(from) if from >= to => {
                return Err(device_err(
                    place,
                    format!("home_switch_to_rev ({to}) must lie above home_switch_rev ({from})"),
                ));
            }
            Some(_) => return Err(device_err(place, "home_switch_to_rev makes a cam: not with home_switch_below")),
            None => return Err(device_err(place, "home_switch_to_rev needs home_switch_rev")),
        }
    }
    if let (Some(n), Some(p)) = (sw.negative_limit_rev, sw.positive_limit_rev) {
        if n >= p {
            return Err(device_err(place, format!("negative_limit_rev ({n}) must lie below positive_limit_rev ({p})")));
        }
    }
    Ok(sw)
}

/// A number from the file, checked against the range it may take (NaN and infinities never do).
fn in_range(place: &str, key: &str, v: f64, range: std::ops::RangeInclusive<f64>) -> Result<f64, SegmentError> {
    if range.contains(&v) {
        Ok(v)
    } else {
        Err(device_err(place, format!("{key} {v:?} out of range ({:?} to {:?})", range.start(), range.end())))
    }
}

/// No crystal is off by more than 0.1 %: a larger frequency error is a mistake in the file.
const MAX_DRIFT_PPM: f64 = 1000.0;

/// Where a device's SII comes from.
#[derive(Debug, Clone, PartialEq, Eq)]
pub enum DeviceSource {
    Eeprom(PathBuf),
    /// An ESI file's device; a modular one with `modules` plugged (their idents, slot by
    /// slot; `None`: the slots' defaults).
    Esi {
        path: PathBuf,
        product: Option<Product>,
        revision: Option<u32>,
        modules: Option<Vec<u32>>,
    },
    Builtin(String),
    /// The slave at position `slave` (from 0) of an ENI file, as the file describes it.
    Eni {
        path: PathBuf,
        slave: usize,
    },
}

/// Which device of an ESI file: by product code, or by its `<Type>` name (any case).
#[derive(Debug, Clone, PartialEq, Eq)]
pub enum Product {
    Code(u32),
    Name(String),
}

#[derive(Debug, Clone, Copy, Deserialize, PartialEq)]
#[serde(deny_unknown_fields)]
pub struct TimingToml {
    pub processing_ns: Option<u32>,
    pub forwarding_ns: Option<u32>,
    pub loopback_ns: Option<u32>,
}

#[derive(Debug, Clone, Deserialize, PartialEq)]
#[serde(untagged)]
pub enum NodeRef {
    Index(usize),
    Name(String),
}

/// A number in a segment file: an integer, or text (`"#x1A00"`, `"0x1A00"`, decimal).
#[derive(Debug, Clone, Deserialize, PartialEq)]
#[serde(untagged)]
pub enum Number {
    /// A TOML integer.
    Int(i64),
    /// A number as text.
    Text(String),
}

impl Number {
    fn get(&self) -> Option<u32> {
        match self {
            Number::Int(v) => u32::try_from(*v).ok(),
            Number::Text(s) => ferrocat_esi::parse_number(s).and_then(|v| u32::try_from(v).ok()),
        }
    }

    /// The whole u64 range: TOML integers stop at 2^63 − 1, so larger values come as text
    /// ("0xFFFF_FFFF_FFFF_0000" or decimal).
    fn get_u64(&self) -> Option<u64> {
        match self {
            Number::Int(v) => u64::try_from(*v).ok(),
            Number::Text(s) => {
                let t = s.trim().replace('_', "");
                match t.strip_prefix("0x").or_else(|| t.strip_prefix("0X")) {
                    Some(h) => u64::from_str_radix(h, 16).ok(),
                    None => t.parse().ok(),
                }
            }
        }
    }
}

#[derive(Debug, Clone, Deserialize, PartialEq, Default)]
#[serde(deny_unknown_fields)]
pub struct DeviceToml {
    pub name: Option<String>,
    pub eeprom: Option<PathBuf>,
    pub esi: Option<PathBuf>,
    pub product: Option<Number>,
    pub revision: Option<Number>,
    /// A modular ESI device's modules, by ident, slot by slot (default: each slot's default).
    pub modules: Option<Vec<Number>>,
    pub builtin: Option<String>,
    /// An ENI file (ETG.2100) whose slave at position `eni_slave` (default 0) this device is.
    pub eni: Option<PathBuf>,
    pub eni_slave: Option<usize>,
    /// "et1100" (default), "lan9252", "esc20" (32-bit DC) or "nodc".
    pub esc: Option<String>,
    pub drift_ppm: Option<f64>,
    /// The DC local time at power-on (ns, default 0; text for values beyond 2^63).
    pub local_time_ns: Option<Number>,
    pub wander_ppb_per_sqrt_s: Option<f64>,
    pub parent: Option<NodeRef>,
    pub parent_port: Option<u8>,
    pub port: Option<u8>,
    pub cable_m: Option<f64>,
    pub link_ns: Option<u32>,
    pub timing: Option<TimingToml>,
    /// Device application: "io" (default for devices without mailbox), "sm", "dc" or
    /// "free-run" (with `app_period_us`), the last three counting lost and repeated cycles;
    /// "cia402" (default for CoE devices with the drive profile's objects).
    pub app: Option<String>,
    pub app_period_us: Option<f64>,
    /// The sync error counter limit (ETG.1020 0x10F1:02) of the SM-synchronisation supervision
    /// that takes a DC-synchronous application out of OP with 0x001A after missed outputs, and
    /// its SYNC0 watchdog (0x002C; docs/esc-model.md); 0 turns the first reaction off. Default: 4 (the Slave Stack Code's) for
    /// the built-in SERVO, off for `app = "dc"` and drives from ESI files (which get 0x10F1
    /// with this limit where it is given).
    pub sync_error_limit: Option<u16>,
    /// A CiA402 drive's limit switches (active at and below / at and above) and home switch
    /// (active at and above, or at and below with `home_switch_below`), in revolutions of the
    /// shaft on its own scale; used by homing methods 1–14 and 17–30, reported in 0x60FD; a
    /// limit switch also stops motion toward it outside homing.
    pub negative_limit_rev: Option<f64>,
    pub positive_limit_rev: Option<f64>,
    pub home_switch_rev: Option<f64>,
    pub home_switch_below: Option<bool>,
    /// Makes the home switch a cam, active from `home_switch_rev` up to here (methods 7–14,
    /// 23–30 need one).
    pub home_switch_to_rev: Option<f64>,
    /// How long the firmware of a device without device emulation takes to act on a write of
    /// AL control (µs, default 1000).
    pub al_response_us: Option<f64>,
    /// How long its firmware takes to answer a mailbox request (µs, default 0: at once); with
    /// `mailbox_response_max_us`, drawn uniformly between the two for each request.
    pub mailbox_response_us: Option<f64>,
    pub mailbox_response_max_us: Option<f64>,
    /// The password FoE read and write requests must carry (default 0: any), on a CoE device
    /// whose SII names FoE.
    pub foe_password: Option<u32>,
    /// How many times the FoE server answers busy to the first data packet of each write (a
    /// device erasing its flash; default 0), on a CoE device whose SII names FoE.
    pub foe_busy: Option<u32>,
    /// Overrides the configured station alias of the SII (word 4, loaded into 0x0012).
    pub station_alias: Option<u16>,
    /// Overrides the SII's device-emulation bit (word 0, ESC configuration bit 0): `false`
    /// puts a firmware behind AL control that checks each transition.
    pub device_emulation: Option<bool>,
    /// Overrides the SII's SYNC out unit bit (word 0, ESC configuration bit 2). An ET1100 or
    /// ET1200 with neither SYNC nor latch unit has receive times only; `app = "dc"` turns it on.
    pub sync_unit: Option<bool>,
    /// Overrides the SII's latch in unit bit (word 0, ESC configuration bit 3).
    pub latch_unit: Option<bool>,
    /// The ESC's identity registers 0x0000–0x0009 as a particular unit reads them, in hex, one
    /// byte per pair of digits (spaces allowed), `..` for a byte the ESC kind keeps: type,
    /// revision, build (2 bytes), FMMUs, SyncManagers, RAM (KiB), port descriptor, features
    /// (2 bytes). For example `"12 01 01 00 03 04 01 4a fc 01"`, an EL1004's ET1200.
    pub esc_identity: Option<String>,
}

/// `esc_identity`: ten bytes, `None` where the text says `..`.
fn parse_identity(text: &str) -> Result<[Option<u8>; 10], String> {
    let digits: String = text.chars().filter(|c| !c.is_whitespace()).collect();
    if digits.len() != 20 {
        return Err(format!("esc_identity: {} hex digits or dots where 20 are needed (10 bytes)", digits.len()));
    }
    let mut out = [None; 10];
    for (k, slot) in out.iter_mut().enumerate() {
        let pair = &digits[2 * k..2 * k + 2];
        if pair != ".." {
            *slot = Some(u8::from_str_radix(pair, 16).map_err(|_| format!("esc_identity: byte {k} is '{pair}'"))?);
        }
    }
    Ok(out)
}

/// The master's second port (cable redundancy): wired to a free port of a device, it closes
/// the line into a ring.
#[derive(Debug, Clone, Deserialize, PartialEq, Default)]
#[serde(deny_unknown_fields)]
pub struct SecondaryToml {
    /// Default: the last device.
    pub device: Option<NodeRef>,
    /// Default: the device's first free port in processing order after its entry port.
    pub port: Option<u8>,
    pub cable_m: Option<f64>,
    pub link_ns: Option<u32>,
}

/// A device's port, in an event.
#[derive(Debug, Clone, Deserialize, PartialEq)]
#[serde(deny_unknown_fields)]
pub struct PortToml {
    pub device: NodeRef,
    pub port: u8,
}

/// A change at a given instant of the segment's time (in live mode: since the simulator
/// started): exactly one of the kinds.
#[derive(Debug, Clone, Deserialize, PartialEq, Default)]
#[serde(deny_unknown_fields)]
pub struct EventToml {
    pub at_ms: f64,
    /// Pulls the cable at this port (both ends lose their link).
    pub link_down: Option<PortToml>,
    pub link_up: Option<PortToml>,
    pub power_off: Option<NodeRef>,
    pub power_on: Option<NodeRef>,
    /// A device's crystal changes frequency by `ppm` (a temperature step).
    pub drift_step: Option<DriftStepToml>,
    /// A CiA402 drive faults by itself, with an emergency of `code`.
    pub drive_fault: Option<DriveFaultToml>,
    /// A device's application reports a local error: SAFEOP with the error indication and
    /// the AL status code `code`.
    pub al_error: Option<DriveFaultToml>,
    /// A drive of the SoE profile sends an SoE notification or emergency.
    pub soe_message: Option<SoeMessageToml>,
}

/// An SoE notification or emergency, in an event.
#[derive(Debug, Clone, Deserialize, PartialEq)]
#[serde(deny_unknown_fields)]
pub struct SoeMessageToml {
    pub device: NodeRef,
    /// The drive (axis) of the device, 0–7 (default 0).
    pub drive: Option<u8>,
    /// The IDN it is about: `"S-0-0095"`, `"P-0-0001"` or its number.
    pub idn: Number,
    /// Its data, in hex (`"4f4b"`; default none).
    pub data: Option<String>,
    /// An emergency (opcode 6) rather than a notification (opcode 5); default false.
    pub emergency: Option<bool>,
}

/// A drive's own fault, in an event.
#[derive(Debug, Clone, Deserialize, PartialEq)]
#[serde(deny_unknown_fields)]
pub struct DriveFaultToml {
    pub device: NodeRef,
    /// The emergency error code (CiA 301/402), e.g. 0x2310 for over-current.
    pub code: Number,
}

/// A device's oscillator step, in an event.
#[derive(Debug, Clone, Deserialize, PartialEq)]
#[serde(deny_unknown_fields)]
pub struct DriftStepToml {
    pub device: NodeRef,
    pub ppm: f64,
}

#[derive(Debug, Clone, Deserialize, PartialEq, Default)]
#[serde(deny_unknown_fields)]
pub struct SegmentConfig {
    #[serde(default)]
    pub seed: u64,
    /// Oscillator errors not given per device are drawn uniformly from ±this (ppm).
    pub drift_spread_ppm: Option<f64>,
    pub master_link_ns: Option<u32>,
    pub loss_probability: Option<f64>,
    pub corruption_probability: Option<f64>,
    #[serde(default, rename = "device")]
    pub devices: Vec<DeviceToml>,
    /// The master's secondary port, for a ring (cable redundancy).
    pub secondary: Option<SecondaryToml>,
    #[serde(default, rename = "event")]
    pub events: Vec<EventToml>,
    /// Folder relative paths are resolved against (the TOML file's folder).
    #[serde(skip)]
    pub base: PathBuf,
}

impl SegmentConfig {
    pub fn from_file(path: &Path) -> Result<Self, SegmentError> {
        let text = read_toml(path, "a segment description")
            .map_err(|reason| SegmentError::Io { path: path.into(), reason })?;
        let mut cfg: SegmentConfig =
            toml::from_str(&text).map_err(|e| SegmentError::Parse { path: path.into(), message: e.to_string() })?;
        cfg.base = path.parent().map(Path::to_path_buf).unwrap_or_default();
        if cfg.devices.is_empty() {
            return Err(SegmentError::Parse { path: path.into(), message: "no [[device]]".into() });
        }
        Ok(cfg)
    }

    /// A line of devices from `--device FILE[:PRODUCT]` arguments, first one next to the master.
    pub fn from_device_args(args: &[String]) -> Result<Self, SegmentError> {
        let mut cfg = SegmentConfig::default();
        for a in args {
            let mut d = DeviceToml::default();
            // FILE.xml[:PRODUCT[:MODULE,MODULE…]]: PRODUCT a product code or a type name, the
            // modules of a modular device by ident.
            let at = a.to_ascii_lowercase().find(".xml:").map(|k| k + 4);
            let (file, rest) = match at {
                Some(k) => (&a[..k], Some(&a[k + 1..])),
                None => (a.as_str(), None),
            };
            let (product, modules) = match rest.map(|r| r.split_once(':').map_or((r, None), |(p, m)| (p, Some(m)))) {
                Some((p, m)) => (Some(p), m),
                None => (None, None),
            };
            if let Some(list) = modules {
                let idents = list
                    .split(',')
                    .map(|m| {
                        ferrocat_esi::parse_number(m)
                            .and_then(|v| u32::try_from(v).ok())
                            .map(|_| Number::Text(m.trim().into()))
                            .ok_or_else(|| device_err("--device", format!("'{m}' in '{list}' is not a module ident")))
                    })
                    .collect::<Result<Vec<_>, _>>()?;
                d.modules = Some(idents);
            }
            if let Some(p) = product.filter(|p| p.trim().is_empty()) {
                return Err(device_err("--device", format!("{a}: no product after the file ('{p}')")));
            }
            if file.ends_with(".xml") || file.ends_with(".XML") {
                d.esi = Some(file.into());
                d.product = product.map(|p| Number::Text(p.into()));
            } else if Path::new(file).exists() || file.contains('/') || file.contains('.') {
                d.eeprom = Some(file.into());
            } else {
                d.builtin = Some(file.into());
            }
            cfg.devices.push(d);
        }
        if cfg.devices.is_empty() {
            return Err(device_err("--device", "no devices given"));
        }
        Ok(cfg)
    }

    fn resolve(&self, p: &Path) -> PathBuf {
        if p.is_absolute() {
            p.into()
        } else {
            self.base.join(p)
        }
    }

    fn source(&self, i: usize, d: &DeviceToml) -> Result<DeviceSource, SegmentError> {
        let place = format!("device {i}");
        if let Some(p) = &d.eni {
            if d.eeprom.is_some() || d.esi.is_some() || d.builtin.is_some() {
                return Err(device_err(place, "give exactly one of eeprom, esi, builtin, eni"));
            }
            return Ok(DeviceSource::Eni { path: self.resolve(p), slave: d.eni_slave.unwrap_or(0) });
        }
        match (&d.eeprom, &d.esi, &d.builtin) {
            (Some(p), None, None) => Ok(DeviceSource::Eeprom(self.resolve(p))),
            (None, Some(p), None) => Ok(DeviceSource::Esi {
                path: self.resolve(p),
                product: d
                    .product
                    .as_ref()
                    .map(|n| match (n.get(), n) {
                        (Some(code), _) => Ok(Product::Code(code)),
                        (None, Number::Text(name))
                            if !name.trim().is_empty() && ferrocat_esi::parse_number(name).is_none() =>
                        {
                            Ok(Product::Name(name.trim().to_string()))
                        }
                        _ => Err(device_err(&place, "product: neither a 32-bit number nor a device's type name")),
                    })
                    .transpose()?,
                revision: d
                    .revision
                    .as_ref()
                    .map(|n| n.get().ok_or_else(|| device_err(&place, "revision: not a 32-bit number")))
                    .transpose()?,
                modules: d
                    .modules
                    .as_ref()
                    .map(|ms| {
                        ms.iter()
                            .map(|n| n.get().ok_or_else(|| device_err(&place, "modules: not 32-bit numbers")))
                            .collect::<Result<Vec<_>, _>>()
                    })
                    .transpose()?,
            }),
            (None, None, Some(b)) => Ok(DeviceSource::Builtin(b.clone())),
            _ => Err(device_err(place, "give exactly one of eeprom, esi, builtin, eni")),
        }
    }

    /// The segment an ENI file describes: each of its slaves a device as the file describes it,
    /// in its order, each after the slave its `<PreviousPort>` names (on that slave's next free
    /// port: the file's port letters are its tool's names, whose ESC port numbers depend on the
    /// device).
    pub fn from_eni(path: &Path) -> Result<Self, SegmentError> {
        let eni = read_eni(path)?;
        if eni.slaves.is_empty() {
            return Err(SegmentError::Parse { path: path.into(), message: "the file describes no slave".into() });
        }
        let mut cfg = SegmentConfig::default();
        for (k, s) in eni.slaves.iter().enumerate() {
            let parent = s
                .previous_port
                .and_then(|(_, station)| eni.slaves[..k].iter().position(|p| p.station == Some(station)))
                .filter(|&p| p + 1 != k);
            cfg.devices.push(DeviceToml {
                eni: Some(path.into()),
                eni_slave: Some(k),
                parent: parent.map(NodeRef::Index),
                ..DeviceToml::default()
            });
        }
        Ok(cfg)
    }

    /// The segment a machine description (docs/machine.md) describes: each slave's `device`
    /// (as `--device` takes it, paths from the description's folder), in order, with the
    /// description's modules plugged into an ESI device that names none of its own.
    pub fn from_machine(path: &Path) -> Result<Self, SegmentError> {
        let text = std::fs::read_to_string(path).map_err(|reason| SegmentError::Io { path: path.into(), reason })?;
        let m = ferrocat_machine::Machine::parse(&text)
            .map_err(|e| SegmentError::Parse { path: path.into(), message: e.to_string() })?;
        if m.slaves.is_empty() {
            return Err(SegmentError::Parse { path: path.into(), message: "the description names no slave".into() });
        }
        let devices = m
            .slaves
            .iter()
            .enumerate()
            .map(|(k, s)| {
                s.device.clone().ok_or_else(|| SegmentError::Parse {
                    path: path.into(),
                    message: format!(
                        "slave {k} ('{}') has no `device = …` to simulate (an ESI file with :PRODUCT, an EEPROM dump or a built-in name)",
                        s.name
                    ),
                })
            })
            .collect::<Result<Vec<String>, _>>()?;
        let mut cfg = SegmentConfig::from_device_args(&devices)
            .map_err(|e| SegmentError::Parse { path: path.into(), message: e.to_string() })?;
        for (d, s) in cfg.devices.iter_mut().zip(&m.slaves) {
            if let (Some(mods), true, None) = (&s.modules, d.esi.is_some(), &d.modules) {
                d.modules = Some(mods.iter().map(|i| Number::Text(format!("{i:#x}"))).collect());
            }
        }
        cfg.base = path.parent().map(Path::to_path_buf).unwrap_or_default();
        Ok(cfg)
    }

    /// Builds the segment: loads every device, wires the topology, draws oscillators.
    pub fn build(&self) -> Result<Segment, SegmentError> {
        let mut rng = ChaCha8Rng::seed_from_u64(self.seed ^ 0x5EED_05C1);
        let spread =
            in_range("segment", "drift_spread_ppm", self.drift_spread_ppm.unwrap_or(25.0), 0.0..=MAX_DRIFT_PPM)?;
        let mut nodes = Vec::new();
        let mut names = Vec::new();
        // Each ESI file is read once, however many of its devices the segment has.
        let mut esi_files = EsiFiles::default();
        for (i, d) in self.devices.iter().enumerate() {
            // Built-in names in any case: "ek1100" is the EK1100.
            let canonical = d.builtin.as_deref().and_then(crate::builtin::canonical);
            let d = &DeviceToml { builtin: canonical.map(String::from).or_else(|| d.builtin.clone()), ..d.clone() };
            let src = self.source(i, d)?;
            let (mut sii, default_name, esi_dev) = esi_files.load_device(&src)?;
            if let Some(alias) = d.station_alias {
                patch_sii_header(&mut sii, |h| h[8..10].copy_from_slice(&alias.to_le_bytes()));
            }
            // Word 0's high byte is the ESC configuration (→ 0x0141): bit 0 device emulation,
            // bit 2 the SYNC out unit.
            if let Some(emulate) = d.device_emulation {
                patch_sii_header(&mut sii, |h| h[1] = (h[1] & !1) | emulate as u8);
            }
            // A DC-synchronous application needs the SYNC out unit; without it and the latch
            // unit an ET1100 or ET1200 has no system time (docs/esc-model.md).
            let dc_app = d.app.as_deref() == Some("dc");
            if dc_app && d.sync_unit == Some(false) {
                return Err(device_err(format!("device {i}"), "app = \"dc\" needs sync_unit = true"));
            }
            if let Some(on) = d.sync_unit.or(dc_app.then_some(true)) {
                patch_sii_header(&mut sii, |h| h[1] = (h[1] & !0x04) | if on { 0x04 } else { 0 });
            }
            if let Some(on) = d.latch_unit {
                patch_sii_header(&mut sii, |h| h[1] = (h[1] & !0x08) | if on { 0x08 } else { 0 });
            }
            let info = SiiInfo::from_image(&sii)
                .map_err(|e| device_err(format!("device {i} ({})", describe(&src)), format!("SII: {e}")))?;
            let kinds = port_kinds(&info);
            // A device whose ESC the captures show carries it; otherwise E-Bus terminals carry an
            // ET1200, everything with an MII port an ET1100.
            // A device whose description asks for SYNC0 (a DC op mode with AssignActivate's
            // SYNC0 bit) while its ConfigData leaves 0x0141's SYNC out and latch units off (the
            // AX2000-B110: 0x0141 = 0x00) cannot be an ET1100 or ET1200, which would then have
            // no system time: its ESC is one whose DC units 0x0141 does not switch, as the AKD's
            // IP core (0x0141 = 0x00 in its dump, a system time on the wire).
            let wants_sync0 =
                esi_dev.as_ref().is_some_and(|dev| dev.dc_op_modes.iter().any(|m| m.assign_activate & 0x0200 != 0));
            let units_off = sii.get(1).is_some_and(|c| c & 0x0C == 0);
            let default_esc =
                known_esc(info.header.vendor_id, info.header.product_code).unwrap_or(if wants_sync0 && units_off {
                    "ipcore"
                } else if kinds.iter().flatten().all(|k| *k == PortKind::Ebus) {
                    "et1200"
                } else {
                    "et1100"
                });
            let esc_kind = d.esc.as_deref().unwrap_or(default_esc);
            let mut config = match esc_kind {
                "et1100" => EscConfig::et1100(),
                "et1200" => EscConfig::et1200(),
                "lan9252" => EscConfig::lan9252(),
                "esc20" => EscConfig::esc20(),
                "ipcore" => EscConfig::ipcore(),
                "nodc" => EscConfig::et1100().without_dc(),
                other => {
                    return Err(device_err(
                        format!("device {i}"),
                        format!("unknown esc '{other}' (et1100, et1200, lan9252, esc20, ipcore, nodc)"),
                    ))
                }
            };
            // The SyncManagers the SII places must lie in the ESC's process RAM: a real device's
            // EEPROM points only into memory its ESC has. Where they do not fit the default ESC,
            // the device has a larger one: an E-Bus terminal whose SMs reach past the ET1200's
            // 1 KB (Beckhoff's EL6751 places SM3 at 0x2400) an ET1100 (8 KB); an ENI, which names
            // no ESC, or a device beyond 8 KB, process RAM grown to hold them (the EtherCAT IP
            // core offers up to 60 KB).
            if d.esc.is_none() {
                let need = info.sync_managers().iter().map(|s| s.start as usize + s.length as usize).max().unwrap_or(0);
                let eni = matches!(src, DeviceSource::Eni { .. });
                if need > config.memory_len()
                    && !eni
                    && esc_kind == "et1200"
                    && need <= EscConfig::et1100().memory_len()
                {
                    config = EscConfig::et1100();
                }
                if need > config.memory_len() {
                    config.ram_kb = (need - 0x1000).div_ceil(1024).min(60) as u8;
                }
            }
            // The ports the SII uses; a port the ESC has but the SII leaves unused keeps the
            // preset's "not configured" (01) where it has one (the LAN9252's third port).
            let preset = config.port_descriptor;
            config.port_descriptor = kinds.iter().enumerate().fold(0u8, |acc, (p, k)| {
                acc | match k {
                    Some(PortKind::Ebus) => 0b10,
                    Some(PortKind::Mii) => 0b11,
                    None if PortDescriptor(preset).port(p as u8) == PortType::NotConfigured => 0b01,
                    None => 0,
                } << (2 * p)
            });
            let place = format!("device {i}");
            if let Some(text) = &d.esc_identity {
                let b = parse_identity(text).map_err(|e| device_err(&place, e))?;
                let c = &mut config;
                let keep = |v: &mut u8, k: usize| *v = b[k].unwrap_or(*v);
                keep(&mut c.esc_type, 0);
                keep(&mut c.revision, 1);
                let build = c.build.to_le_bytes();
                c.build = u16::from_le_bytes([b[2].unwrap_or(build[0]), b[3].unwrap_or(build[1])]);
                keep(&mut c.fmmu_count, 4);
                keep(&mut c.sm_count, 5);
                keep(&mut c.ram_kb, 6);
                keep(&mut c.port_descriptor, 7);
                let f = c.features.to_le_bytes();
                c.features = u16::from_le_bytes([b[8].unwrap_or(f[0]), b[9].unwrap_or(f[1])]);
                // The register map has room for 16 FMMUs (0x0600–0x06FF) and 16 SyncManagers
                // (0x0800–0x087F); process RAM ends at 0xFFFF.
                if c.fmmu_count > 16 || c.sm_count > 16 || c.ram_kb > 60 {
                    return Err(device_err(
                        &place,
                        format!(
                            "esc_identity: {} FMMUs, {} SyncManagers, {} KiB: at most 16, 16 and 60",
                            c.fmmu_count, c.sm_count, c.ram_kb
                        ),
                    ));
                }
            }
            let drift_ppb = match d.drift_ppm {
                Some(ppm) => {
                    (in_range(&place, "drift_ppm", ppm, -MAX_DRIFT_PPM..=MAX_DRIFT_PPM)? * 1000.0).round() as i64
                }
                None => (rng.gen_range(-spread..=spread) * 1000.0).round() as i64,
            };
            let sync = |mode| -> Box<dyn Application> {
                let mut app = SyncApp::new(mode, config.sm_count, drift_ppb);
                if let Some(limit) = d.sync_error_limit {
                    app.monitor = ferrocat_esc::SmSyncMonitor::new(limit);
                }
                Box::new(app)
            };
            let coe = info.header.mailbox_protocols & ferrocat_wire::sii::mailbox_protocol::COE != 0;
            // FoE is served next to the SDO server, where the SII names it.
            let foe = (info.header.mailbox_protocols & ferrocat_wire::sii::mailbox_protocol::FOE != 0).then(|| {
                let mut server = FoeServer::with_password(d.foe_password.unwrap_or(0));
                server.busy_per_write = d.foe_busy.unwrap_or(0);
                server
            });
            for (set, key) in [(d.foe_password.is_some(), "foe_password"), (d.foe_busy.is_some(), "foe_busy")] {
                if set && !(coe && foe.is_some()) {
                    return Err(device_err(&place, format!("{key} needs a device whose SII names CoE and FoE")));
                }
            }
            // So is EoE: an endpoint with no address until the master sets one.
            let eoe = (coe && info.header.mailbox_protocols & ferrocat_wire::sii::mailbox_protocol::EOE != 0)
                .then(ferrocat_esc::EoeServer::default);
            // And SoE: a drive's service channel with the standard IDNs, beside CoE or alone.
            let speaks_soe = info.header.mailbox_protocols & ferrocat_wire::sii::mailbox_protocol::SOE != 0;
            // As many drives as its file's SoE init commands address (ENI and ESI alike).
            let soe = speaks_soe.then(|| {
                ferrocat_esc::SoeServer::drives(
                    esi_dev.as_ref().map_or(1, |d| d.soe_drives()),
                    &format!("{} (ferrocat simulation)", info.name().unwrap_or_else(|| String::from("SoE drive"))),
                )
            });
            // The dictionary is built once, for CoE devices (and the empty one of a drive that
            // speaks SoE alone).
            let od = (coe || speaks_soe).then(|| match &esi_dev {
                Some(dev) => {
                    let mut od = crate::od_build::from_esi(dev, &info);
                    if let Some(slots) = &dev.slots {
                        crate::od_build::add_module_lists(&mut od, slots, &dev.modules);
                    }
                    od
                }
                None => crate::od_build::from_sii(&info),
            });
            let drive = coe && od.as_ref().is_some_and(|od| d.app.is_some() || is_drive(&info, od));
            let has_switches = d.negative_limit_rev.is_some()
                || d.positive_limit_rev.is_some()
                || d.home_switch_rev.is_some()
                || d.home_switch_below.is_some()
                || d.home_switch_to_rev.is_some();
            if has_switches && !(drive && matches!(d.app.as_deref(), None | Some("cia402"))) {
                return Err(device_err(&place, "limit and home switches need a CiA402 drive (app = \"cia402\")"));
            }
            let supervised =
                matches!(d.app.as_deref(), Some("dc")) || (drive && matches!(d.app.as_deref(), None | Some("cia402")));
            if d.sync_error_limit.is_some() && !supervised {
                return Err(device_err(&place, "sync_error_limit needs app = \"dc\" or a CiA402 drive"));
            }
            // Supervision is the firmware's: a device-emulating ESC has none to do it.
            if d.sync_error_limit.is_some() && sii.get(1).is_some_and(|c| c & 1 != 0) {
                return Err(device_err(
                    &place,
                    "sync_error_limit needs a firmware behind AL control (device_emulation = false)",
                ));
            }
            let app: Box<dyn Application> = match (d.app.as_deref(), od) {
                (None | Some("cia402"), Some(od)) if drive => {
                    // Each drive draws from its own stream: the others' draws stay as they were.
                    let seed = self.seed ^ (i as u64 + 1).wrapping_mul(0x9E37_79B9_7F4A_7C15);
                    let mut drive = Cia402Drive::new(od, config.sm_count, seed);
                    let builtin_limit =
                        (d.builtin.as_deref() == Some("SERVO")).then_some(ferrocat_esc::DEFAULT_SYNC_ERROR_LIMIT);
                    if let Some(limit) = d.sync_error_limit.or(builtin_limit) {
                        drive.supervise_sync(limit);
                    }
                    drive.set_switches(switches(d, &place)?);
                    drive.coe.foe = foe;
                    drive.coe.eoe = eoe;
                    drive.coe.soe = soe;
                    Box::new(drive)
                }
                (Some("cia402"), _) => return Err(device_err(&place, "app = \"cia402\" needs a CoE mailbox")),
                (None, Some(od)) => {
                    let mut dev = CoeDevice::new(od, config.sm_count, Box::new(PassiveLogic));
                    dev.serves_coe = coe;
                    dev.foe = foe;
                    dev.eoe = eoe;
                    dev.soe = soe;
                    Box::new(dev)
                }
                (None, None) if info.header.mailbox_rx_size > 0 => Box::new(NoApplication),
                (None | Some("io"), _) => Box::new(DigitalIo::new(config.sm_count)),
                // The synchronised applications have no mailbox: on a device whose SII names CoE
                // the master's first SDO would meet "protocol not supported", as no real device
                // of that SII answers.
                (Some(a @ ("sm" | "dc" | "free-run")), Some(_)) if coe => {
                    return Err(device_err(
                        &place,
                        format!(
                            "app = \"{a}\" has no CoE server, and this device's SII names CoE: for its SYNC0 \
                             give sync_unit = true instead"
                        ),
                    ))
                }
                (Some("sm"), _) => sync(SyncMode::SmSynchronous),
                (Some("dc"), _) => sync(SyncMode::DcSynchronous),
                (Some("free-run"), _) => {
                    let us =
                        d.app_period_us.ok_or_else(|| device_err(&place, "app = \"free-run\" needs app_period_us"))?;
                    // At least 1 µs: the application runs once per period, each run an event.
                    let us = in_range(&place, "app_period_us", us, 1.0..=1e9)?;
                    sync(SyncMode::FreeRun { period_ns: (us * 1000.0).round() as u64 })
                }
                (Some(other), _) => {
                    return Err(device_err(&place, format!("unknown app '{other}' (io, sm, dc, free-run, cia402)")))
                }
            };
            let mut esc = Esc::new(config, sii, app, drift_ppb, 0);
            if let Some(n) = &d.local_time_ns {
                let t = n
                    .get_u64()
                    .ok_or_else(|| device_err(&place, format!("local_time_ns {n:?} is not a u64 number of ns")))?;
                esc.set_power_on_local_time(t);
            }
            // A built-in device's own firmware times, unless the file gives others.
            let firmware = d.builtin.as_deref().and_then(crate::builtin::firmware_times_us);
            if let Some(us) = d.al_response_us.or(firmware.map(|f| f.0)) {
                esc.al_response_ns = (in_range(&place, "al_response_us", us, 0.0..=10e6)? * 1000.0) as u64;
            }
            let mailbox_us = d.mailbox_response_us.or(firmware.map(|f| f.1));
            if mailbox_us.is_some() || d.mailbox_response_max_us.is_some() {
                let key = "mailbox_response_us";
                let min = in_range(&place, key, mailbox_us.unwrap_or(0.0), 0.0..=10e6)?;
                let key = "mailbox_response_max_us";
                let max = in_range(&place, key, d.mailbox_response_max_us.unwrap_or(min), min..=10e6)?;
                // Each device its own stream, apart from the drives' (above).
                let seed = self.seed ^ (i as u64 + 1).wrapping_mul(0xD1B5_4A32_D192_ED03);
                esc.mailbox_response =
                    MailboxResponse::uniform((min * 1000.0).round() as u64, (max * 1000.0).round() as u64, seed);
            }
            let name = d.name.clone().unwrap_or(default_name);
            let mut node = Node::new(name.clone(), esc, kinds, drift_ppb);
            node.wander_ppb_per_sqrt_s =
                in_range(&place, "wander_ppb_per_sqrt_s", d.wander_ppb_per_sqrt_s.unwrap_or(0.0), 0.0..=1e6)?;
            let def = if esc_kind == "lan9252" { EscTiming::LAN9252 } else { EscTiming::default() };
            node.timing = def;
            if let Some(t) = d.timing {
                node.timing = EscTiming {
                    processing_ns: t.processing_ns.unwrap_or(def.processing_ns),
                    forwarding_ns: t.forwarding_ns.unwrap_or(def.forwarding_ns),
                    loopback_ns: t.loopback_ns.unwrap_or(def.loopback_ns),
                };
            }
            nodes.push(node);
            names.push(name);
        }
        let mut seg = Segment::new(nodes, self.seed);
        if let Some(m) = self.master_link_ns {
            seg.master_link_ns = m;
        }
        for (what, p) in
            [("loss_probability", self.loss_probability), ("corruption_probability", self.corruption_probability)]
        {
            if let Some(p) = p {
                in_range("segment", what, p, 0.0..=1.0)?;
            }
        }
        seg.loss_probability = self.loss_probability.unwrap_or(0.0);
        seg.corruption_probability = self.corruption_probability.unwrap_or(0.0);
        for (i, d) in self.devices.iter().enumerate() {
            let place = format!("device {i} ({})", names[i]);
            let port = d.port.unwrap_or(0);
            if port > 3 || seg.nodes[i].port_kinds[port as usize].is_none() {
                return Err(device_err(place, format!("port {port} does not exist on this device")));
            }
            if i == 0 {
                // The first device's port toward the master.
                if d.parent.is_some() || d.parent_port.is_some() {
                    return Err(device_err(place, "the first device hangs on the master: no parent"));
                }
                if d.cable_m.is_some() || d.link_ns.is_some() {
                    return Err(device_err(
                        place,
                        "the first device's link is the master's: set master_link_ns, not cable_m or link_ns",
                    ));
                }
                seg.nodes[0].entry_port = port;
                continue;
            }
            let parent = match &d.parent {
                None => i - 1,
                Some(NodeRef::Index(p)) if *p < i => *p,
                Some(NodeRef::Index(p)) => return Err(device_err(place, format!("parent {p} must come before it"))),
                Some(NodeRef::Name(n)) => names[..i]
                    .iter()
                    .position(|x| x == n)
                    .ok_or_else(|| device_err(&place, format!("no earlier device named '{n}'")))?,
            };
            let pport = match d.parent_port {
                Some(p) => p,
                None => free_port(&seg.nodes[parent])
                    .ok_or_else(|| device_err(&place, format!("parent '{}' has no free port", names[parent])))?,
            };
            let pn = &seg.nodes[parent];
            let Some(pkind) = pn.port_kinds.get(pport as usize).copied().flatten() else {
                return Err(device_err(place, format!("parent '{}' has no port {pport}", names[parent])));
            };
            if pn.peers[pport as usize].is_some() || pport == pn.entry_port {
                return Err(device_err(place, format!("port {pport} of '{}' is already in use", names[parent])));
            }
            let kind = seg.nodes[i].port_kinds[port as usize].unwrap_or(PortKind::Ebus);
            if d.cable_m.is_some() && d.link_ns.is_some() {
                return Err(device_err(place, "give cable_m or link_ns, not both (link_ns is the whole hop)"));
            }
            let cable_m = in_range(&place, "cable_m", d.cable_m.unwrap_or(2.0), 0.0..=1000.0)?;
            let delay = d.link_ns.unwrap_or_else(|| link_delay_ns(pkind, kind, cable_m));
            seg.connect(parent, pport, i, port, delay);
        }
        if let Some(sec) = &self.secondary {
            self.wire_secondary(&mut seg, sec, &names)?;
        }
        for (k, e) in self.events.iter().enumerate() {
            let (t_ns, event) = self.event(&seg, k, e, &names)?;
            seg.schedule(t_ns, event);
        }
        seg.refresh_links();
        Ok(seg)
    }

    fn wire_secondary(&self, seg: &mut Segment, sec: &SecondaryToml, names: &[String]) -> Result<(), SegmentError> {
        let place = "[secondary]";
        let node = match &sec.device {
            None => names.len().checked_sub(1).ok_or_else(|| device_err(place, "no device to wire it to"))?,
            Some(r) => node_index(r, names).map_err(|m| device_err(place, m))?,
        };
        let n = &seg.nodes[node];
        let port = match sec.port {
            Some(p) => p,
            None => free_port(n)
                .ok_or_else(|| device_err(place, format!("device {node} ('{}') has no free port", names[node])))?,
        };
        let Some(kind) = n.port_kinds.get(port as usize).copied().flatten() else {
            return Err(device_err(place, format!("device {node} ('{}') has no port {port}", names[node])));
        };
        if n.peers[port as usize].is_some() || port == n.entry_port {
            return Err(device_err(
                place,
                format!("port {port} of device {node} ('{}') is already in use", names[node]),
            ));
        }
        if sec.cable_m.is_some() && sec.link_ns.is_some() {
            return Err(device_err(place, "give cable_m or link_ns, not both (link_ns is the whole hop)"));
        }
        let delay = match sec.link_ns {
            Some(ns) => ns,
            None if sec.cable_m.is_none() => seg.master_link_ns,
            None => link_delay_ns(
                PortKind::Mii,
                kind,
                in_range(place, "cable_m", sec.cable_m.unwrap_or(2.0), 0.0..=1000.0)?,
            ),
        };
        seg.connect_secondary(node, port, delay);
        Ok(())
    }

    fn event(&self, seg: &Segment, k: usize, e: &EventToml, names: &[String]) -> Result<(u64, Event), SegmentError> {
        let place = format!("event {k}");
        let at_ms = in_range(&place, "at_ms", e.at_ms, 0.0..=1e10)?;
        let node = |r: &NodeRef| node_index(r, names).map_err(|m| device_err(&place, m));
        let port = |p: &PortToml| -> Result<(usize, u8), SegmentError> {
            let i = node(&p.device)?;
            if p.port > 3 || seg.nodes[i].port_kinds[p.port as usize].is_none() {
                return Err(device_err(&place, format!("device {i} ('{}') has no port {}", names[i], p.port)));
            }
            Ok((i, p.port))
        };
        let mut kinds = Vec::new();
        if let Some(p) = &e.link_down {
            let (node, port) = port(p)?;
            kinds.push(Event::LinkDown { node, port });
        }
        if let Some(p) = &e.link_up {
            let (node, port) = port(p)?;
            kinds.push(Event::LinkUp { node, port });
        }
        if let Some(r) = &e.power_off {
            kinds.push(Event::PowerOff { node: node(r)? });
        }
        if let Some(r) = &e.power_on {
            kinds.push(Event::PowerOn { node: node(r)? });
        }
        if let Some(d) = &e.drift_step {
            let ppm = in_range(&place, "drift_step.ppm", d.ppm, -MAX_DRIFT_PPM..=MAX_DRIFT_PPM)?;
            kinds.push(Event::DriftStep { node: node(&d.device)?, delta_ppb: (ppm * 1000.0).round() as i64 });
        }
        let code = |f: &DriveFaultToml, key: &str| {
            f.code
                .get()
                .and_then(|c| u16::try_from(c).ok())
                .ok_or_else(|| device_err(&place, format!("{key}.code: not a 16-bit number")))
        };
        if let Some(f) = &e.drive_fault {
            kinds.push(Event::DriveFault { node: node(&f.device)?, code: code(f, "drive_fault")? });
        }
        if let Some(f) = &e.al_error {
            kinds.push(Event::AlError { node: node(&f.device)?, code: code(f, "al_error")? });
        }
        if let Some(m) = &e.soe_message {
            let i = node(&m.device)?;
            let ev = soe_message(m, i, &place)?;
            let esc = &seg.nodes[i].esc;
            if ferrocat_esc::CoeDevice::of_ref(esc.app()).is_none_or(|c| c.soe.is_none()) {
                return Err(device_err(&place, format!("soe_message: device {i} ('{}') speaks no SoE", names[i])));
            }
            // One message in the slave's send mailbox (SII word 0x1B, ETG.2010): the mailbox
            // header (6 bytes), the SoE header (4) and the data.
            let room = (esc.sii_word(0x1B) as usize).saturating_sub(10);
            if let Event::SoeMessage { data, .. } = &ev {
                if data.len() > room {
                    return Err(device_err(
                        &place,
                        format!(
                            "soe_message.data: {} bytes, more than the device's mailbox carries ({room})",
                            data.len()
                        ),
                    ));
                }
            }
            kinds.push(ev);
        }
        match (kinds.pop(), kinds.is_empty()) {
            (Some(ev), true) => Ok(((at_ms * 1e6).round() as u64, ev)),
            _ => Err(device_err(
                place,
                "give exactly one of link_down, link_up, power_off, power_on, drift_step, drive_fault, al_error, \
                 soe_message",
            )),
        }
    }
}

/// An event's SoE message to device `node`, its IDN, drive and data checked.
fn soe_message(m: &SoeMessageToml, node: usize, place: &str) -> Result<Event, SegmentError> {
    let (idn, given) = match &m.idn {
        Number::Int(n) => (u16::try_from(*n).ok().map(ferrocat_wire::soe::Idn), n.to_string()),
        Number::Text(t) => (ferrocat_wire::soe::Idn::parse(t), t.clone()),
    };
    let idn = idn.ok_or_else(|| {
        device_err(
            place,
            format!("soe_message.idn '{given}': give S-0-0095, P-0-0001 (set 0–7, block 0–4095) or a number"),
        )
    })?;
    let drive = m.drive.unwrap_or(0);
    if drive > 7 {
        return Err(device_err(place, format!("soe_message.drive {drive}: a drive 0–7")));
    }
    let text: String = m.data.as_deref().unwrap_or("").split_whitespace().collect();
    let data = (text.len() % 2 == 0 && text.bytes().all(|b| b.is_ascii_hexdigit()))
        .then(|| (0..text.len()).step_by(2).map(|i| u8::from_str_radix(&text[i..i + 2], 16).ok()).collect())
        .flatten()
        .ok_or_else(|| device_err(place, format!("soe_message.data '{text}': not hex bytes")))?;
    Ok(Event::SoeMessage { node, drive, idn, emergency: m.emergency.unwrap_or(false), data })
}

/// A device by index or name.
fn node_index(r: &NodeRef, names: &[String]) -> Result<usize, String> {
    match r {
        NodeRef::Index(i) if *i < names.len() => Ok(*i),
        NodeRef::Index(i) => Err(format!("no device {i} (there are {})", names.len())),
        NodeRef::Name(n) => names.iter().position(|x| x == n).ok_or_else(|| format!("no device named '{n}'")),
    }
}

/// A node's first free port in processing order after its entry port.
fn free_port(n: &Node) -> Option<u8> {
    let mut q = n.entry_port;
    for _ in 0..3 {
        q = [3, 2, 0, 1][q as usize];
        if n.port_kinds[q as usize].is_some() && n.peers[q as usize].is_none() && q != n.entry_port {
            return Some(q);
        }
    }
    None
}

/// A CiA402 drive: the SII says so (DS402 channels), or the dictionary has the profile's
/// controlword and statusword.
fn is_drive(info: &SiiInfo, od: &ferrocat_esc::od::ObjectDictionary) -> bool {
    info.general().is_some_and(|g| g.ds402_channels > 0) || (od.get(0x6040).is_some() && od.get(0x6041).is_some())
}

/// The ESC kind of devices whose real ESC the shared captures show, by SII identity: the
/// Kollmorgen AKD's IP core (docs/esc-model.md) and Microchip's LAN9252 evaluation board.
fn known_esc(vendor_id: u32, product_code: u32) -> Option<&'static str> {
    match (vendor_id, product_code) {
        (0x0000_006A, 0x0041_4B44) => Some("ipcore"),
        (0x0000_0009, 0x0000_9252) => Some("lan9252"),
        _ => None,
    }
}

fn describe(src: &DeviceSource) -> String {
    match src {
        DeviceSource::Eeprom(p) => p.display().to_string(),
        DeviceSource::Esi { path, .. } => path.display().to_string(),
        DeviceSource::Builtin(b) => format!("builtin {b}"),
        DeviceSource::Eni { path, slave } => format!("{} slave {slave}", path.display()),
    }
}

/// Port kinds from the SII general category (4 bits per port: 1 MII, 3 E-Bus, 4 fast
/// hot-connect MII, 0 unused); two MII ports when the image has no general category.
fn port_kinds(info: &SiiInfo) -> [Option<PortKind>; 4] {
    let Some(g) = info.general() else { return [Some(PortKind::Mii), Some(PortKind::Mii), None, None] };
    let mut k = [None; 4];
    for (p, slot) in k.iter_mut().enumerate() {
        *slot = match (g.physical_ports >> (4 * p)) & 0xF {
            1 | 2 | 4 => Some(PortKind::Mii),
            3 => Some(PortKind::Ebus),
            _ => None,
        };
    }
    if k[0].is_none() {
        k[0] = Some(PortKind::Mii);
    }
    k
}

/// An ENI file, read leniently (its warnings are the reader's to show: `ferrocat eni`).
fn read_eni(path: &Path) -> Result<ferrocat_machine::eni::Eni, SegmentError> {
    let bytes = std::fs::read(path).map_err(|reason| SegmentError::Io { path: path.into(), reason })?;
    ferrocat_machine::eni::Eni::parse(&bytes)
        .map_err(|e| SegmentError::Parse { path: path.into(), message: e.to_string() })
}

/// Loads the SII image of a device and a default name for it.
pub fn load_device(src: &DeviceSource) -> Result<(Vec<u8>, String, Option<ferrocat_esi::Device>), SegmentError> {
    EsiFiles::default().load_device(src)
}

/// The ESI files a segment's devices come from, each read and parsed once.
#[derive(Default)]
struct EsiFiles {
    parsed: std::collections::HashMap<PathBuf, EsiFile>,
}

impl EsiFiles {
    fn file(&mut self, path: &Path) -> Result<&EsiFile, SegmentError> {
        if !self.parsed.contains_key(path) {
            let xml = read_esi(path).map_err(|reason| SegmentError::Io { path: path.to_path_buf(), reason })?;
            let mut f = EsiFile::parse(&xml)
                .map_err(|e| SegmentError::Parse { path: path.to_path_buf(), message: e.to_string() })?;
            crate::files::add_module_files(path, &mut f);
            self.parsed.insert(path.to_path_buf(), f);
        }
        Ok(&self.parsed[path])
    }

    fn load_device(
        &mut self,
        src: &DeviceSource,
    ) -> Result<(Vec<u8>, String, Option<ferrocat_esi::Device>), SegmentError> {
        match src {
            DeviceSource::Eeprom(path) => {
                let raw = read_eeprom_dump(path).map_err(|reason| SegmentError::Io { path: path.clone(), reason })?;
                let (img, _) =
                    parse_dump(&raw).map_err(|e| SegmentError::Parse { path: path.clone(), message: e.to_string() })?;
                let info = SiiInfo::from_image(&img).map_err(|e| SegmentError::Parse {
                    path: path.clone(),
                    message: format!("not an SII image: {e}"),
                })?;
                let name = info.string(1).unwrap_or_else(|| format!("{:#010x}", info.header.product_code));
                Ok((img, name, None))
            }
            DeviceSource::Esi { path, product, revision, modules } => {
                let f = self.file(path)?;
                let dev = match product {
                    Some(p) => f
                        .devices
                        .iter()
                        .filter(|d| match p {
                            Product::Code(c) => d.product_code == *c,
                            Product::Name(n) => d.type_name.eq_ignore_ascii_case(n),
                        })
                        .filter(|d| revision.is_none_or(|r| d.revision == r))
                        // The newest revision; of equal ones the first in the file.
                        .reduce(|best, d| if d.revision > best.revision { d } else { best })
                        .ok_or_else(|| SegmentError::Parse {
                            path: path.clone(),
                            message: format!(
                                "no device {} (the file has: {})",
                                match p {
                                    Product::Code(c) => format!("with product code {c:#x}"),
                                    Product::Name(n) => format!("of type {n}"),
                                },
                                f.devices
                                    .iter()
                                    .map(|d| format!("{} {:#x}", d.type_name, d.product_code))
                                    .collect::<Vec<_>>()
                                    .join(", ")
                            ),
                        })?,
                    None if f.devices.len() == 1 => &f.devices[0],
                    None => {
                        return Err(SegmentError::Parse {
                            path: path.clone(),
                            message: format!(
                                "{} devices: give the product code (FILE:PRODUCT or product = ...)",
                                f.devices.len()
                            ),
                        })
                    }
                };
                let parse_err = |message: String| SegmentError::Parse { path: path.clone(), message };
                let dev = match (&dev.slots, modules) {
                    (None, Some(_)) => return Err(parse_err(format!("{} has no slots for modules", dev.type_name))),
                    (None, None) => dev.clone(),
                    (Some(_), chosen) => {
                        let idents = match chosen {
                            Some(m) => m.clone(),
                            None => dev.default_modules().ok_or_else(|| {
                                parse_err(format!(
                                    "{}: a slot needs a module and names no default: give them (FILE:PRODUCT:MODULE,…)",
                                    dev.type_name
                                ))
                            })?,
                        };
                        dev.plugged(&f.modules, &idents).map_err(parse_err)?
                    }
                };
                let img = dev.to_sii(f.vendor_id).map_err(|e| parse_err(e.to_string()))?;
                Ok((img, dev.type_name.clone(), Some(dev)))
            }
            DeviceSource::Builtin(name) => {
                let dev = crate::builtin::device(name).ok_or_else(|| {
                    device_err(
                        format!("builtin {name}"),
                        format!("unknown built-in device (known: {})", crate::builtin::NAMES.join(", ")),
                    )
                })?;
                let img = dev
                    .to_sii(crate::builtin::vendor_id(name))
                    .map_err(|e| device_err(format!("builtin {name}"), e.to_string()))?;
                Ok((img, dev.type_name.clone(), Some(dev)))
            }
            DeviceSource::Eni { path, slave } => {
                let eni = read_eni(path)?;
                let s = eni.slaves.get(*slave).ok_or_else(|| SegmentError::Parse {
                    path: path.clone(),
                    message: format!("no slave at position {slave} (the file has {})", eni.slaves.len()),
                })?;
                let dev = s.to_device();
                let mut img = dev
                    .to_sii(s.identity.vendor_id)
                    .map_err(|e| SegmentError::Parse { path: path.clone(), message: format!("slave {slave}: {e}") })?;
                // The serial number the tool scanned (SII word 0x0E, outside the header's CRC).
                if let Some(b) = img.get_mut(0x1C..0x20) {
                    b.copy_from_slice(&s.identity.serial.to_le_bytes());
                }
                Ok((img, s.name.clone(), Some(dev)))
            }
        }
    }
}
