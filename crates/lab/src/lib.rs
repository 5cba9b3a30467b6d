//! The lab: the papers' experiments run on the virtual segment, every method on the same
//! random realisation (same seed), the error taken from the true clocks the simulator knows.
pub mod chen2016;
pub mod demo;
mod error;
pub mod fit;
pub mod gpi;
pub mod paprocki2022;
pub mod park2020;
pub mod robustness;
pub mod sampler;
pub mod scenario;
pub mod stats;
mod world;

pub use error::{LabError, Result, SettingOrigin};
pub use world::World;

use ferrocat_master::sync::{ClockSync, Coupling, SyncMethod};
use ferrocat_master::{DcConfig, DcReport, Master};
use ferrocat_segment::SegmentConfig;
use ferrocat_segment::{HostModel, VirtualIo};

/// The methods the master–slave error tables compare: those where the reference follows the
/// master, and ferrocat in both couplings.
pub const ERROR_METHODS: [&str; 4] = ["conventional", "park2020", "ferrocat", "ferrocat-mfr"];

/// Every method the lab knows.
pub const METHODS: [&str; 7] = ["none", "conventional", "park2020", "chen2016", "pi", "ferrocat", "ferrocat-mfr"];

/// A variant [`method`] also knows, for comparison where the reference follows the master:
/// ferrocat steering the reference's time control loop instead of its offset.
pub const FERROCAT_TCL: &str = "ferrocat-tcl";

/// Variants of ferrocat in either coupling that probe the reference in half of every cycle,
/// not only while the line is uncertain (`Ferrocat::dense`).
pub const FERROCAT_DENSE: [&str; 2] = ["ferrocat-dense", "ferrocat-mfr-dense"];

/// ferrocat in either coupling without a follower's crystal for its flywheel: the line through
/// the reference's own points alone, for comparison.
pub const FERROCAT_DIRECT: [&str; 2] = ["ferrocat-direct", "ferrocat-mfr-direct"];

/// A line of `slaves` EK1100-like DC slaves (E-Bus hops), crystals spread ±50 ppm.
pub fn line(slaves: usize) -> SegmentConfig {
    let mut cfg = SegmentConfig { drift_spread_ppm: Some(50.0), ..SegmentConfig::default() };
    cfg.devices = (0..slaves)
        .map(|_| ferrocat_segment::DeviceToml { builtin: Some("EK1100".into()), ..Default::default() })
        .collect();
    cfg
}

/// `cfg` (its own seed replaced by `seed`, so that rounds differ and the scenario's seed rules)
/// brought up and DC-initialised, in virtual time on `host`, and `method` prepared on it for
/// `cycle_ns`, with the DC initialisation's report (see [`master`], [`method`]). ferrocat's
/// methods are made before the DC initialisation, so that one that steers the reference's
/// offset does so from the static drift compensation on (`Dc::init_dc_with`); the others
/// after it, as published.
pub fn segment(
    cfg: &SegmentConfig,
    host: HostModel,
    seed: u64,
    method: &str,
    cycle_ns: u64,
    coupling: Coupling,
) -> crate::Result<(Master<VirtualIo>, Box<dyn ClockSync>, DcReport)> {
    let mut m = master(SegmentConfig { seed, ..cfg.clone() }, host, seed, method)?;
    m.states().bring_up()?;
    let dc = DcConfig { sync0_slaves: Some(vec![]), ..DcConfig::default() };
    let (sync, report) = init_with_method(&mut m, &dc, method, cycle_ns, coupling)?;
    Ok((m, sync, report))
}

/// The method named `name` (a [`SyncMethod::PRESETS`] name) as the master's configuration;
/// `coupling` is the one the plain ferrocat variants take.
pub fn sync_method(name: &str, coupling: Coupling) -> crate::Result<SyncMethod> {
    SyncMethod::preset(name, coupling)
        .ok_or_else(|| LabError::UnknownMethod { name: name.into(), known: SyncMethod::PRESETS.join(", ") })
}

/// The method named `name` made on `m`, whose DC is initialised already (see
/// [`Clock::make_clock_sync`](ferrocat_master::part::Clock::make_clock_sync)); `coupling` as [`sync_method`] takes it.
pub fn method<I: World>(
    name: &str,
    m: &mut Master<I>,
    cycle_ns: u64,
    coupling: Coupling,
) -> crate::Result<Box<dyn ClockSync>> {
    Ok(m.clock().make_clock_sync(&sync_method(name, coupling)?, cycle_ns)?)
}

/// `init_dc` on `m` and `method` made for it, in the order the master owns
/// ([`Clock::start_clock_sync`](ferrocat_master::part::Clock::start_clock_sync)); with the DC initialisation's report.
pub fn init_with_method<I: World>(
    m: &mut Master<I>,
    dc: &DcConfig,
    method: &str,
    cycle_ns: u64,
    coupling: Coupling,
) -> crate::Result<(Box<dyn ClockSync>, DcReport)> {
    let config = sync_method(method, coupling)?;
    let (sync, report, _) = m.clock().start_clock_sync(dc, &config, cycle_ns)?;
    Ok((sync, report))
}

/// A master on `cfg` in virtual time on `host`, for `method`: ferrocat's own methods compute
/// the delays knowing the ESCs' closed-port loop-back (`loop_back_ns`), the papers' and the
/// baselines' as SOEM and IgH do.
pub fn master(cfg: SegmentConfig, host: HostModel, seed: u64, method: &str) -> crate::Result<Master<VirtualIo>> {
    let mut m = Master::new(VirtualIo::new(cfg.build()?, host, seed));
    tell_loop_back(&mut m, method);
    Ok(m)
}

/// Tells a master for `method` what the ESCs' closed-port loop-back takes, where the method is
/// one of ferrocat's (in virtual time or against `ferrocat sim` on a real interface alike).
pub fn tell_loop_back<I: World>(m: &mut Master<I>, method: &str) {
    if CALIBRATED.contains(&method) {
        m.config().settings_mut().closed_port_loop_ns = loop_back_ns();
    }
}

/// The simulated ESCs' closed-port loop-back (docs/segment-model.md), as a master would take
/// it from the ESC's datasheet.
pub fn loop_back_ns() -> u32 {
    ferrocat_segment::timing::EscTiming::default().loopback_ns
}

/// Methods that take out what a calibration measured (`ReferenceSteering::take_error`).
pub const CALIBRATED: [&str; 7] = SyncMethod::FERROCAT_PRESETS;

/// `a` then `b`, for method lists built from others (`C` must be their lengths' sum).
pub(crate) const fn concat_names<const A: usize, const B: usize, const C: usize>(
    a: [&'static str; A],
    b: [&'static str; B],
) -> [&'static str; C] {
    assert!(A + B == C, "concat_names: C must be A + B");
    let mut out = [""; C];
    let mut i = 0;
    while i < C {
        out[i] = if i < A { a[i] } else { b[i - A] };
        i += 1;
    }
    out
}

/// Pulses per calibration.
pub const CALIBRATION_PULSES: usize = 1000;

/// How many pulses a calibration over `settle_cycles` takes: its middle half, at most one a
/// cycle, at most [`CALIBRATION_PULSES`]. (Asked for 1 000 at 4 ms cycles, robustness's 3 s
/// before its band window had room for 375 and never finished: ferrocat ran uncalibrated,
/// −0.29 µs off on pc-rt; park2020 finished its pulses 62 cycles into the measurement.)
pub fn calibration_pulses(settle_cycles: u64) -> usize {
    CALIBRATION_PULSES.min((settle_cycles / 2) as usize)
}

/// Whether cycle `k` of a run that settles for `settle_cycles` pulses the calibration: the
/// pulses are spread evenly over the middle half of the settling time, since the master's
/// error wanders (on a stock kernel its one-second means spread by ≈ 80 ns) and a pulse
/// every cycle for one second would catch one excursion.
pub fn calibration_cycle(k: u64, settle_cycles: u64) -> bool {
    let every = (settle_cycles / 2 / CALIBRATION_PULSES as u64).max(1);
    k >= settle_cycles / 4 && (k - settle_cycles / 4) % every == 0
}

/// A GPIO calibration of `method` on `m` over `pulses` pulses, the host's output wired to
/// LATCH0 of the slave at position `reference`; `None` where the method takes no calibration
/// or the host model has no GPIO.
pub fn calibration(
    m: &mut Master<VirtualIo>,
    method: &str,
    reference: usize,
    pulses: usize,
) -> Option<ferrocat_master::calibrate::GpioCalibration> {
    let gpio = m.cyclic().io_mut().host.gpio?;
    if !CALIBRATED.contains(&method) {
        return None;
    }
    m.cyclic().io_mut().gpio_wire = Some((node_of(m, reference)?, 0));
    Some(ferrocat_master::calibrate::GpioCalibration::new(reference as u16, gpio.mean_ns.round() as u64, pulses))
}

/// The positions of the slaves with a DC unit, the reference first; an error if there are none.
pub fn dc_slaves<I: World>(m: &Master<I>) -> crate::Result<Vec<usize>> {
    let dc: Vec<usize> =
        m.slaves().iter().enumerate().filter(|(_, s)| s.dc().has_system_time).map(|(k, _)| k).collect();
    if dc.is_empty() {
        return Err(LabError::NoDcSlave);
    }
    Ok(dc)
}

/// The master's clock minus the system time of the slave at position `k` now (Park 2020's
/// sign: positive when the slave lags), on the low 32 bits so that 32-bit DCs compare too;
/// `None` outside a simulator. The slave is found by its station address, so any topology works.
pub fn clock_error_ns<I: World>(m: &mut Master<I>, k: usize) -> Option<i64> {
    let t = m.cyclic().now_ns();
    let master = m.clock().master_system_time() as u32;
    let node = &m.io().segment()?.nodes[node_of(m, k)?];
    let slave = node.esc.dc.as_ref().map(|d| d.system_at(t) as u32).unwrap_or(master);
    Some(master.wrapping_sub(slave) as i32 as i64)
}

/// The segment node of the slave at position `k`, by its station address.
pub fn node_of<I: World>(m: &Master<I>, k: usize) -> Option<usize> {
    let station = m.slaves().get(k)?.station();
    m.io().segment()?.nodes.iter().position(|n| n.esc.station_address() == station)
}

/// The next wake-up after `next`: one nominal cycle, or the period a master that follows the
/// reference asked for.
pub fn next_wake(next: u64, cycle_ns: u64, c: &ferrocat_master::sync::Correction) -> u64 {
    next.wrapping_add(c.next_period_ns.unwrap_or(cycle_ns))
}

#[cfg(test)]
mod tests {
    use super::{calibration_cycle, calibration_pulses};

    #[test]
    fn the_calibration_pulses_fit_the_settling() {
        // 5 s at 1 ms, 3 s at 4 ms (robustness before its band window), 5 s at 4 ms, 300 s at
        // 1 ms, one cycle: every pulse falls in the settling's middle half.
        for settle in [5_000u64, 750, 1_250, 300_000, 1] {
            let pulses = calibration_pulses(settle);
            let last = (0..settle).filter(|&k| calibration_cycle(k, settle)).nth(pulses.saturating_sub(1));
            match pulses {
                0 => assert!(settle < 2),
                _ => assert!(last.is_some_and(|k| k <= settle * 3 / 4), "{settle}: pulse {pulses} at {last:?}"),
            }
        }
        assert_eq!(calibration_pulses(750), 375);
        assert_eq!(calibration_pulses(300_000), super::CALIBRATION_PULSES);
    }
}
