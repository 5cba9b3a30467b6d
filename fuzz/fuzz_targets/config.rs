#![no_main]
//! Any text as a segment description (`ferrocat sim --config`) and as a lab scenario
//! (`ferrocat lab run`). A segment that builds — any topology of built-in devices, ports,
//! cables, timings, oscillators, faults — runs for 50 ms and our master scans it and
//! initialises its clocks; a scenario is planned for every experiment. Errors are expected;
//! a panic or a hang is the fault. Files the text names (EEPROM dumps, ESI files, a scenario's
//! segment) are left out: the `sii`, `esi` and `device` targets take their bytes.
use ferrocat_lab::scenario::{Experiment, Scenario};
use ferrocat_master::io::{HostModel, VirtualIo};
use ferrocat_master::{DcConfig, Master};
use ferrocat_segment::SegmentConfig;
use libfuzzer_sys::fuzz_target;

fuzz_target!(|data: &[u8]| {
    let Ok(text) = std::str::from_utf8(data) else { return };
    if let Ok(cfg) = toml::from_str::<SegmentConfig>(text) {
        let names_files = cfg.devices.iter().any(|d| d.eeprom.is_some() || d.esi.is_some());
        if !names_files && cfg.devices.len() <= 64 {
            if let Ok(seg) = cfg.build() {
                let mut m = Master::new(VirtualIo::new(seg, HostModel::ideal(), 1));
                if m.scan().is_ok() {
                    let _ = m.init_dc(&DcConfig { max_frames: 300, ..DcConfig::default() });
                }
            }
        }
    }
    if let Ok(s) = toml::from_str::<Scenario>(text) {
        if s.segment.is_none() {
            for e in [Experiment::Park2020, Experiment::Chen2016, Experiment::Paprocki2022, Experiment::Robustness] {
                let _ = s.plan(Some(e), true);
                let _ = s.plan(Some(e), false);
            }
            let _ = s.plan(None, false);
        }
    }
});
