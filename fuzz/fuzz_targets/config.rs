#![no_main]
//! Any text as a segment description (`ferrocat sim --config`) and as a lab scenario
//! (`ferrocat lab run`). A segment that builds — any topology of built-in devices, ports,
//! cables, timings, oscillators, faults — is scanned by our master, which initialises its
//! clocks; with the ESCs' default timing every DC slave's computed delay must be the true one
//! within ±10 ns (tests/delays.rs's oracle, on any topology), and on a ring whose port the
//! master found, the delays of the line that port makes when closed. A scenario is planned for every
//! experiment. Errors are expected; a panic, a hang or a wrong delay is the fault. Files the text names (EEPROM dumps, ESI files, a scenario's
//! segment) are left out: the `sii`, `esi` and `device` targets take their bytes.
use ferrocat_lab::scenario::{Experiment, Scenario};
use ferrocat_master::{DcConfig, Master};
use ferrocat_segment::SegmentConfig;
use ferrocat_segment::{HostModel, VirtualIo};
use libfuzzer_sys::fuzz_target;

fuzz_target!(|data: &[u8]| {
    let Ok(text) = std::str::from_utf8(data) else { return };
    if let Ok(cfg) = toml::from_str::<SegmentConfig>(text) {
        let names_files = cfg.devices.iter().any(|d| d.eeprom.is_some() || d.esi.is_some());
        if !names_files && cfg.devices.len() <= 64 {
            // Delays are checked where the master can know them: the ESCs' default timing
            // (processing and forwarding alike, a 20 ns loop-back), every frame delivered.
            let knowable = cfg.devices.iter().all(|d| d.timing.is_none())
                && cfg.loss_probability.unwrap_or(0.0) == 0.0
                && cfg.corruption_probability.unwrap_or(0.0) == 0.0
                && cfg.events.is_empty();
            if let Ok(seg) = cfg.build() {
                // A LAN9252 has its own processing and forwarding delays (its ESC kind's, not
                // the default): where it sits among others, no master can know the delays.
                let default = ferrocat_segment::timing::EscTiming::default();
                let knowable = knowable && seg.nodes.iter().all(|n| n.timing == default);
                let mut m = Master::new(VirtualIo::new(seg, HostModel::ideal(), 1));
                m.config().settings_mut().closed_port_loop_ns = 20;
                if m.states().scan().is_ok() {
                    if knowable && cfg.secondary.is_none() {
                        check_delays(&m, text);
                    }
                    if knowable && m.dc().ring_port().is_some() {
                        check_ring_delays(&m, &cfg, text);
                    }
                    let _ = m.dc().init_dc(&DcConfig { max_frames: 300, ..DcConfig::default() });
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

/// A ring whose port the master found has the delays of the line that port makes when closed:
/// the forward path is the same (the line's own delays are `check_delays`'s).
fn check_ring_delays(ring: &Master<VirtualIo>, cfg: &SegmentConfig, text: &str) {
    let line_cfg = SegmentConfig { secondary: None, ..cfg.clone() };
    let Ok(seg) = line_cfg.build() else { return };
    let mut line = Master::new(VirtualIo::new(seg, HostModel::ideal(), 1));
    line.config().settings_mut().closed_port_loop_ns = 20;
    if line.states().scan().is_err() || line.slaves().len() != ring.slaves().len() {
        return;
    }
    for (k, (r, l)) in ring.slaves().iter().zip(line.slaves()).enumerate() {
        assert!(
            (r.dc().delay_ns as i64 - l.dc().delay_ns as i64).abs() <= 10,
            "slave {k}: ring {} ns, line {} ns, on\n{text}",
            r.dc().delay_ns,
            l.dc().delay_ns
        );
    }
}

/// Each DC slave's delay from the reference (the first with a system time) against the
/// simulator's truth: when the last frame of the scan reached its processing unit, less when it
/// reached the reference's. A slave with receive times only has no 0x0918: its processing
/// unit's time is taken as its port 0's, which is exact where it is entered on port 0; one before
/// the reference has no delay (clamped to 0).
fn check_delays(m: &Master<VirtualIo>, text: &str) {
    let visits = m.io().seg.last_visits();
    if visits.len() != m.slaves().len() {
        return;
    }
    let Some(reference) = m.slaves().iter().position(|s| s.dc().has_system_time) else { return };
    let checked = |s: &&ferrocat_master::Slave| s.dc().has_system_time || (s.dc().supported && s.ports().entry == 0);
    for (k, s) in m.slaves().iter().enumerate().filter(|(k, s)| *k >= reference && checked(s)) {
        let truth = visits[k].1.epu_ns as i64 - visits[reference].1.epu_ns as i64;
        assert!(
            (s.dc().delay_ns as i64 - truth).abs() <= 10,
            "slave {k}: computed {} ns, true {truth} ns, on\n{text}",
            s.dc().delay_ns
        );
    }
}
