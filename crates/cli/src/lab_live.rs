//! `ferrocat lab live`: the master–slave clock measurement on this machine's real kernel. The
//! master runs in real time on one end of a veth pair in a network namespace of its own,
//! `ferrocat sim` serves the other end in another, and the simulator logs every slave's true
//! system time at each frame's CLOCK_MONOTONIC instant; the master's clock is CLOCK_MONOTONIC
//! plus its epoch offset (or, for a master that follows the reference, the method's line on
//! that), so both are compared on the same time base. Every method's cyclic frames are also
//! placed on the reference's cycle: the reference's system time as each passed it, modulo the
//! cycle — the phase Chen 2016 measures, and the only figure for the methods that keep no
//! master clock (chen2016, SOEM's PI).
use std::io::Read;
use std::path::{Path, PathBuf};
use std::process::{Child, Command, ExitCode, Stdio};
use std::time::{Duration, Instant};

use anyhow::{bail, ensure, Context};
use ferrocat_lab::stats::Moments;
use ferrocat_master::sync::Coupling;
use ferrocat_master::DcConfig;
use serde::Serialize;

use crate::outln;

/// `lab live`'s settings.
#[derive(clap::Args)]
pub struct LiveArgs {
    /// Methods (repeatable): none, conventional, park2020, ferrocat, ferrocat-mfr and their variants -direct, -dense (whose master clock is its estimate of the reference's), chen2016 and pi (which keep no master clock: their phase only).
    #[arg(long = "method", value_name = "METHOD", default_values = ["conventional", "park2020", "chen2016", "pi", "ferrocat", "ferrocat-mfr"])]
    pub methods: Vec<String>,
    /// Slaves on the simulated line (EK1100s; the first is the reference clock).
    #[arg(long, default_value_t = 2)]
    pub slaves: usize,
    /// The cycle time (µs, 100 to 100 000).
    #[arg(long, default_value_t = 1000, allow_negative_numbers = true, value_parser = |s: &str| crate::args::cycle_us(s, 100, 100_000))]
    pub cycle_us: u64,
    /// Seconds of cyclic operation before measuring.
    #[arg(long, default_value_t = 2.0)]
    pub settle_s: f64,
    /// Seconds measured per method.
    #[arg(long, default_value_t = 10.0)]
    pub seconds: f64,
    /// Seed of the simulator's random draws (crystals, latencies): the same seed gives the same segment.
    #[arg(long, default_value_t = 1)]
    pub seed: u64,
    /// How the master's frames move (as `run --io`).
    #[arg(long, value_enum, default_value = "auto")]
    pub io: crate::target::IoPath,
    /// With --io ring: how long a receive spins before it sleeps, in µs (as `run --spin-us`).
    #[arg(long, value_name = "US", default_value_t = ferrocat_link::DEFAULT_RING_SPIN_NS / 1000)]
    pub spin_us: u64,
    /// How the simulator's frames move (as `sim --io`).
    #[arg(long, value_enum, default_value = "socket")]
    pub sim_io: crate::target::IoPath,
    /// How long ferrocat's probe frames may take per cycle on average (µs, as `run
    /// --probe-budget-us`). Default: as many as the method wants within the cycle.
    #[arg(long)]
    pub probe_budget_us: Option<u64>,
    /// Print JSON instead of text.
    #[arg(long)]
    pub json: bool,
}

#[derive(Debug, Serialize)]
pub struct Row {
    pub method: String,
    pub slaves: usize,
    pub cycle_us: u64,
    /// Master − reference and master − last slave over the measured part (µs); `None` for a
    /// method that keeps no master clock (it follows the reference's phase only).
    pub ref_mean_us: Option<f64>,
    pub ref_rms_us: Option<f64>,
    /// The median of |master − reference| (µs): a kernel's rare stalls of tens of µs rule the
    /// RMS of a 10 s run, and not this.
    pub ref_median_abs_us: Option<f64>,
    pub last_mean_us: Option<f64>,
    pub last_rms_us: Option<f64>,
    /// Largest |master − slave| over all slaves and samples (µs).
    pub max_abs_us: Option<f64>,
    /// Where each cycle's frame passed the reference on its cycle: the reference's system time
    /// then, modulo the cycle — mean (0 … cycle), standard deviation and the width max − min,
    /// each phase taken within half a cycle of the recent ones' mean, so that a drifting phase
    /// counts whole and a frame more than half a cycle late counts as early (µs).
    pub phase_mean_us: f64,
    pub phase_sd_us: f64,
    pub phase_width_us: f64,
    /// Cycles whose frame the log shows (the phase's samples).
    pub phased: u64,
    /// What a DC-synchronous slave with SYNC0 half a cycle from the frames' mean phase would
    /// have lost (frames overwritten before its SYNC0 took them) and repeated (SYNC0s without
    /// a new frame): Chen 2016's packet loss, from the same frames.
    pub dc_lost: u64,
    pub dc_repeated: u64,
    /// Frames the simulator logged in the measured window: about one per cycle, and the
    /// probe frames (`probes`) ferrocat sent there.
    pub samples: u64,
    pub cycles: u64,
    pub frames_lost: u64,
    pub probes: u64,
}

/// Two network namespaces joined by a veth pair, removed on drop.
struct Veth {
    master_ns: String,
    sim_ns: String,
    master_if: String,
    sim_if: String,
}

fn ip(args: &[&str]) -> anyhow::Result<()> {
    let out = Command::new("ip").args(args).output().context("running ip (iproute2)")?;
    ensure!(out.status.success(), "ip {}: {}", args.join(" "), String::from_utf8_lossy(&out.stderr).trim());
    Ok(())
}

impl Veth {
    fn new() -> anyhow::Result<Veth> {
        let id = std::process::id() % 100_000;
        let v = Veth {
            master_ns: format!("fcl{id}m"),
            sim_ns: format!("fcl{id}s"),
            master_if: format!("fcl{id}a"),
            sim_if: format!("fcl{id}b"),
        };
        ip(&["netns", "add", &v.master_ns])?;
        ip(&["netns", "add", &v.sim_ns])?;
        ip(&[
            "link",
            "add",
            &v.master_if,
            "netns",
            &v.master_ns,
            "type",
            "veth",
            "peer",
            "name",
            &v.sim_if,
            "netns",
            &v.sim_ns,
        ])?;
        for (ns, ifc) in [(&v.master_ns, &v.master_if), (&v.sim_ns, &v.sim_if)] {
            ip(&["-n", ns, "link", "set", ifc, "up"])?;
        }
        Ok(v)
    }
}

impl Drop for Veth {
    fn drop(&mut self) {
        for ns in [&self.master_ns, &self.sim_ns] {
            let _ = Command::new("ip").args(["netns", "del", ns]).output();
        }
    }
}

/// `ferrocat sim` in the simulator's namespace; SIGTERM and wait on drop.
struct Sim(Child);

impl Sim {
    fn start(v: &Veth, slaves: usize, seed: u64, log: &Path, io: crate::target::IoPath) -> anyhow::Result<Sim> {
        let exe = std::env::current_exe().context("finding this executable")?;
        let mut c = Command::new("ip");
        c.args(["netns", "exec", &v.sim_ns]).arg(exe).arg("sim");
        for _ in 0..slaves {
            c.args(["--device", "EK1100"]);
        }
        c.args(["--seed", &seed.to_string(), "--iface", &v.sim_if, "--clock-log"]).arg(log);
        let io = clap::ValueEnum::to_possible_value(&io).context("the frame path's name")?;
        c.args(["--io", io.get_name()]);
        let mut sim = Sim(c.stdout(Stdio::null()).stderr(Stdio::piped()).spawn().context("starting ferrocat sim")?);
        let mut err = sim.0.stderr.take().context("sim stderr")?;
        let (t0, mut seen, mut b) = (Instant::now(), Vec::new(), [0u8; 256]);
        while !String::from_utf8_lossy(&seen).contains(" on ") {
            let n = err.read(&mut b).unwrap_or(0);
            ensure!(
                n > 0 && t0.elapsed() < Duration::from_secs(20),
                "ferrocat sim: {}",
                String::from_utf8_lossy(&seen)
            );
            seen.extend_from_slice(&b[..n]);
        }
        // Drain the rest (its statistics on exit) so that it never blocks on a full pipe.
        std::thread::spawn(move || std::io::copy(&mut err, &mut std::io::sink()));
        Ok(sim)
    }

    fn stop(mut self) -> anyhow::Result<()> {
        // SAFETY: kill sends a signal to our own child's pid.
        unsafe { libc::kill(self.0.id() as i32, libc::SIGTERM) };
        let st = self.0.wait()?;
        ensure!(st.success(), "ferrocat sim exited with {st}");
        Ok(())
    }
}

impl Drop for Sim {
    fn drop(&mut self) {
        // SAFETY: as in stop.
        unsafe { libc::kill(self.0.id() as i32, libc::SIGTERM) };
        let _ = self.0.wait();
    }
}

/// What the master's side of one run knows: its clock's offset from CLOCK_MONOTONIC and the
/// window it measured.
struct MasterRun {
    epoch_offset_ns: u64,
    /// Where the method keeps a clock of its own (master follows reference), that clock as the
    /// line in force from each cycle on; `None` where the master's clock is its own.
    clock: Option<Vec<ClockPiece>>,
    from_ns: u64,
    to_ns: u64,
    cycles: u64,
    lost: u64,
    /// Probe frames sent within the measured window (the simulator logs them too).
    probes: u64,
    /// When each cycle of the window began (CLOCK_MONOTONIC): its frame is the first the
    /// simulator logs after it.
    cycle_starts: Vec<u64>,
}

/// The method's clock from `own_ns` (the master's own system time) until the next piece.
#[derive(Debug, Clone, Copy)]
struct ClockPiece {
    own_ns: u64,
    master_ns: u64,
    rate: f64,
}

impl ClockPiece {
    fn at(&self, own_ns: u64) -> u64 {
        let dx = own_ns.wrapping_sub(self.own_ns) as i64 as f64;
        self.master_ns.wrapping_add_signed((dx * self.rate) as i64)
    }
}

fn run_master(iface: &str, a: &LiveArgs, method: &str) -> anyhow::Result<MasterRun> {
    let target =
        crate::target::Target { io: a.io, spin_us: a.spin_us, ..crate::target::Target::on_iface(iface, false) };
    let mut m = target.master()?;
    // The simulator's ESCs, as in the virtual lab: ferrocat's methods are told their loop-back.
    ferrocat_lab::tell_loop_back(&mut m, method);
    m.states().bring_up()?;
    let cycle_ns = a.cycle_us * 1000;
    let dc = DcConfig { sync0_slaves: Some(vec![]), ..DcConfig::default() };
    let (mut sync, _) =
        ferrocat_lab::init_with_method(&mut m, &dc, method, cycle_ns, Coupling::ReferenceFollowsMaster)?;
    let mut st = m.clock().sync_state()?;
    st.probing.budget_ns = a.probe_budget_us.map(|us| us * 1000);
    let start = m.cyclic().now_ns();
    let from_ns = start + (a.settle_s * 1e9) as u64;
    let to_ns = from_ns + (a.seconds * 1e9) as u64;
    let mut clock = Vec::new();
    let (mut next, mut c, mut cycles) = (start, Default::default(), 0);
    let mut probes_from = None;
    let mut cycle_starts = Vec::new();
    while next < to_ns {
        // A master that follows the reference wakes when it says.
        next = ferrocat_lab::next_wake(next, cycle_ns, &c);
        m.cyclic().sleep_until(next);
        let now = m.cyclic().now_ns();
        if now >= from_ns && probes_from.is_none() {
            probes_from = Some(st.probing.sent);
        }
        if (from_ns..to_ns).contains(&now) {
            cycle_starts.push(now);
        }
        c = m.clock().sync_step(sync.as_mut(), &mut st)?;
        cycles += 1;
        if m.cyclic().now_ns() + 2 * cycle_ns >= from_ns {
            let own = m.clock().master_system_time();
            let ahead = own.wrapping_add(cycle_ns);
            if let (Some(a), Some(b)) = (sync.master_time(own), sync.master_time(ahead)) {
                let rate = b.wrapping_sub(a) as i64 as f64 / cycle_ns as f64;
                clock.push(ClockPiece { own_ns: own, master_ns: a, rate });
            }
        }
    }
    let epoch_offset_ns = m.clock().epoch_offset_ns().context("the master's clock was never read")?;
    // A method that keeps no clock of its own leaves the master's.
    let clock = (!clock.is_empty()).then_some(clock);
    let probes = st.probing.sent - probes_from.unwrap_or(st.probing.sent);
    Ok(MasterRun { epoch_offset_ns, clock, from_ns, to_ns, cycles, lost: st.lost, probes, cycle_starts })
}

/// Methods that follow the reference's phase with the master's period and keep no master
/// clock: their master − slave error would be the crystals' drift, so only the phase is theirs.
const PHASE_ONLY: [&str; 2] = ["chen2016", "pi"];

/// Where each cycle's frame passed the reference on its cycle (ns), and what a DC-synchronous
/// slave would have made of those frames.
#[derive(Debug, Clone, Copy, PartialEq)]
struct Phase {
    /// Mean (0 … cycle), standard deviation and width max − min.
    mean_ns: f64,
    sd_ns: f64,
    width_ns: f64,
    /// Cycles whose own frame the log shows.
    n: u64,
    /// With SYNC0 half a cycle from the frames' mean phase, as a master would place it: frames
    /// overwritten before a SYNC0 took them (two or more between two SYNC0s), and SYNC0s that
    /// found no new frame — Chen 2016's lost and repeated process data.
    lost: u64,
    repeated: u64,
}

/// The cyclic frames' [`Phase`]. `log` holds (CLOCK_MONOTONIC, reference system time) per
/// logged frame, in order; a cycle's frame is the first logged at or after its start and
/// before the next. A drifting phase is followed across the cycle's edge.
fn phase(log: &[(u64, u64)], cycle_starts: &[u64], cycle_ns: u64) -> Phase {
    let c = cycle_ns as i64;
    let (mut m, mut lo, mut hi) = (Moments::default(), f64::INFINITY, f64::NEG_INFINITY);
    let mut passed = Vec::with_capacity(cycle_starts.len());
    // Each phase is taken within half a cycle of a slowly moving centre (a 16-frame mean of
    // the phases so far): a drifting phase goes on across the cycle's edge, and a frame more
    // than half a cycle late counts as early rather than moving the others.
    let (mut j, mut centre): (usize, Option<f64>) = (0, None);
    for (k, &start) in cycle_starts.iter().enumerate() {
        j += log[j..].partition_point(|&(mono, _)| mono < start);
        let Some(&(mono, sys)) = log.get(j) else { break };
        if cycle_starts.get(k + 1).is_some_and(|&next| mono >= next) {
            continue;
        }
        passed.push(sys);
        let raw = (sys % cycle_ns) as i64;
        let x = match centre {
            None => raw as f64,
            Some(ctr) => {
                let near = ctr.round() as i64;
                (near + (raw - near + c / 2).rem_euclid(c) - c / 2) as f64
            }
        };
        centre = Some(centre.map_or(x, |ctr| ctr + (x - ctr) / 16.0));
        m.push(x);
        (lo, hi) = (lo.min(x), hi.max(x));
    }
    let sd = (m.rms().powi(2) - m.mean().powi(2)).max(0.0).sqrt();
    let mean = m.mean().rem_euclid(cycle_ns as f64);
    // SYNC0 at mean + cycle/2: count the frames between each two SYNC0s, from the first
    // frame's interval to the last's.
    let (mut lost, mut repeated) = (0, 0);
    if !passed.is_empty() {
        let sync0 = ((mean + cycle_ns as f64 / 2.0) as u64) % cycle_ns;
        let mut slots: Vec<i128> = passed.iter().map(|&t| (t as i128 - sync0 as i128).div_euclid(c as i128)).collect();
        slots.sort_unstable();
        for w in slots.windows(2) {
            match w[1] - w[0] {
                0 => lost += 1,
                gap => repeated += (gap - 1) as u64,
            }
        }
    }
    Phase { mean_ns: mean, sd_ns: sd, width_ns: hi - lo, n: m.n, lost, repeated }
}

/// Master − slave errors from the simulator's clock log over the master's window, and the
/// cyclic frames' phase on the reference's cycle.
fn errors(log: &Path, r: &MasterRun, method: &str, a: &LiveArgs) -> anyhow::Result<Row> {
    let text = std::fs::read_to_string(log).with_context(|| format!("reading {}", log.display()))?;
    let (mut reference, mut last, mut max_abs) = (Moments::default(), Moments::default(), 0f64);
    let mut reference_times = Vec::new();
    let mut reference_abs = Vec::new();
    for (i, line) in text.lines().enumerate().skip(1) {
        let v: Vec<Option<u64>> = line.split(',').map(|x| x.parse().ok()).collect();
        let Some(Some(mono)) = v.first().copied() else { bail!("{}: line {}: no time", log.display(), i + 1) };
        if mono < r.from_ns || mono > r.to_ns {
            continue;
        }
        if let Some(Some(sys)) = v.get(1).copied() {
            reference_times.push((mono, sys));
        }
        let own = mono.wrapping_add(r.epoch_offset_ns);
        let master = match &r.clock {
            None => own,
            Some(pieces) => {
                // The line in force then; none yet (not fitted) leaves the frame out.
                let i = pieces.partition_point(|p| p.own_ns.wrapping_sub(own) as i64 <= 0);
                let Some(p) = i.checked_sub(1).map(|i| pieces[i]) else { continue };
                p.at(own)
            }
        } as u32;
        let e: Vec<f64> = v[1..].iter().flatten().map(|&s| master.wrapping_sub(s as u32) as i32 as f64).collect();
        ensure!(e.len() == a.slaves, "{}: line {}: {} slave clocks, not {}", log.display(), i + 1, e.len(), a.slaves);
        reference.push(e[0]);
        reference_abs.push(e[0].abs());
        last.push(e[e.len() - 1]);
        max_abs = e.iter().fold(max_abs, |m, x| m.max(x.abs()));
    }
    ensure!(reference.n > 0, "the simulator logged no frame in the measured window");
    let ph = phase(&reference_times, &r.cycle_starts, a.cycle_us * 1000);
    let clock = !PHASE_ONLY.contains(&method);
    let us = |x: f64| clock.then_some(x / 1e3);
    Ok(Row {
        method: method.into(),
        slaves: a.slaves,
        cycle_us: a.cycle_us,
        ref_mean_us: us(reference.mean()),
        ref_rms_us: us(reference.rms()),
        ref_median_abs_us: us(ferrocat_lab::stats::median(&reference_abs)),
        last_mean_us: us(last.mean()),
        last_rms_us: us(last.rms()),
        max_abs_us: us(max_abs),
        phase_mean_us: ph.mean_ns / 1e3,
        phase_sd_us: ph.sd_ns / 1e3,
        phase_width_us: ph.width_ns / 1e3,
        phased: ph.n,
        dc_lost: ph.lost,
        dc_repeated: ph.repeated,
        samples: reference.n,
        cycles: r.cycles,
        frames_lost: r.lost,
        probes: r.probes,
    })
}

pub fn run(a: LiveArgs) -> anyhow::Result<ExitCode> {
    // SAFETY: geteuid has no preconditions.
    ensure!(unsafe { libc::geteuid() } == 0, "lab live makes network namespaces and a veth pair: run it as root");
    ensure!((1..=64).contains(&a.slaves), "--slaves must be between 1 and 64");
    ensure!(
        a.seconds > 0.0 && a.seconds <= 3600.0 && (0.0..=3600.0).contains(&a.settle_s),
        "--seconds/--settle-s out of range"
    );
    // The methods of the master–slave error tables, which keep a master clock (the master's
    // own, or ferrocat-mfr's estimate of the reference's), and chen2016 and SOEM's PI, which
    // follow the reference's phase and are measured by it alone.
    let live: Vec<&str> = ferrocat_lab::park2020::METHODS.iter().chain(&PHASE_ONLY).copied().collect();
    for m in &a.methods {
        ensure!(live.contains(&m.as_str()), "--method {m:?}: one of {}", live.join(", "));
    }
    let veth = Veth::new()?;
    // This thread (the master) lives in its namespace from here on; the simulator is started
    // in the other through `ip netns exec`.
    ferrocat_link::enter_netns(&veth.master_ns).context("entering the master's namespace")?;
    crate::target::go_real_time();
    let mut rows = Vec::new();
    for method in &a.methods {
        let log: PathBuf = std::env::temp_dir().join(format!("ferrocat-live-{}-{method}.csv", std::process::id()));
        let sim = Sim::start(&veth, a.slaves, a.seed, &log, a.sim_io)?;
        let run = run_master(&veth.master_if, &a, method).with_context(|| format!("method {method}"));
        sim.stop()?;
        let row = errors(&log, &run?, method, &a);
        let _ = std::fs::remove_file(&log);
        rows.push(row?);
    }
    if a.json {
        outln!(
            "{}",
            serde_json::json!({ "experiment": "live", "seed": a.seed, "settle_s": a.settle_s, "seconds": a.seconds, "rows": rows })
        );
        return Ok(ExitCode::SUCCESS);
    }
    outln!(
        "Live — this kernel, veth pair, {} slaves, {} µs cycle, {} s after {} s; error = master − slave clock (true, from the simulator; — where the method keeps no master clock), phase = the cyclic frame's passage on the reference's cycle, µs; dc lost/rep = process data a DC-synchronous slave (SYNC0 half a cycle from that phase) loses or repeats",
        a.slaves, a.cycle_us, a.seconds, a.settle_s
    );
    outln!(
        "{:<13} {:>9} {:>9} {:>9} {:>9} {:>9} {:>9} {:>10} {:>8} {:>8} {:>7} {:>7} {:>8} {:>6} {:>7}",
        "method",
        "ref mean",
        "ref RMS",
        "ref |e|50",
        "last mean",
        "last RMS",
        "max |e|",
        "phase",
        "phase sd",
        "width",
        "dc lost",
        "dc rep",
        "samples",
        "lost",
        "probes"
    );
    let f = |x: Option<f64>| x.map_or("—".to_string(), |x| format!("{x:.3}"));
    for r in &rows {
        outln!(
            "{:<13} {:>9} {:>9} {:>9} {:>9} {:>9} {:>9} {:>10.3} {:>8.3} {:>8.3} {:>7} {:>7} {:>8} {:>6} {:>7}",
            r.method,
            f(r.ref_mean_us),
            f(r.ref_rms_us),
            f(r.ref_median_abs_us),
            f(r.last_mean_us),
            f(r.last_rms_us),
            f(r.max_abs_us),
            r.phase_mean_us,
            r.phase_sd_us,
            r.phase_width_us,
            r.dc_lost,
            r.dc_repeated,
            r.samples,
            r.frames_lost,
            r.probes
        );
    }
    Ok(ExitCode::SUCCESS)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn each_cycles_frame_is_placed_on_the_references_cycle() {
        const C: u64 = 1_000_000;
        // Cycles start at 0, 1, 2, 3 and 4 ms; the frames (and a probe) pass the reference at
        // system times whose phases are 999.0, 1.0 (2 µs on, across the cycle's edge), 3.0 and,
        // for the cycle at 4 ms, 4.0 µs; the cycle at 3 ms has no frame of its own (the next
        // one logged came after 4 ms).
        let log = [
            (100, 7 * C + 999_000),
            (1_000_100, 8 * C + 1_000),
            (1_000_300, 8 * C + 500_000),
            (2_000_100, 9 * C + 3_000),
            (4_000_100, 11 * C + 4_000),
        ];
        let starts = [0, C, 2 * C, 3 * C, 4 * C];
        let Phase { mean_ns: mean, sd_ns: sd, width_ns: width, n, lost, repeated } = phase(&log, &starts, C);
        assert_eq!(n, 4, "the probe and the frameless cycle left out");
        // SYNC0 at 501.75 µs of each cycle: the frames at 7.999 and 8.001 ms fall between the
        // same two SYNC0s (one overwritten), 9.003 between the next, and none between 9.50175
        // and 10.50175 ms (a SYNC0 without a new frame) before 11.004.
        assert_eq!((lost, repeated), (1, 1));
        // Unwrapped: 999, 1 001, 1 003, 1 004 µs.
        assert!((mean - 1_001_750.0 % C as f64).abs() < 1e-6, "mean {mean}");
        assert!((width - 5_000.0).abs() < 1e-6, "width {width}");
        let want_sd = ((999f64 - 1001.75).powi(2) + 0.75f64.powi(2) + 1.25f64.powi(2) + 2.25f64.powi(2)) / 4.0;
        assert!((sd - want_sd.sqrt() * 1e3).abs() < 1e-3, "sd {sd}");
        // Nothing logged: no samples, NaN statistics.
        assert_eq!(phase(&[], &starts, C).n, 0);
        // Frames at 375 µs, one 505 µs late (880), then 390 µs: the late one counts as 495 µs
        // early (−120) and the next is not a cycle away (from frame to frame it would have
        // been): width 390 − (−120).
        let log: Vec<(u64, u64)> = [375_000, 375_000, 880_000, 390_000, 375_000]
            .iter()
            .enumerate()
            .map(|(k, &p)| (k as u64 * C + 10, 5 * C + k as u64 * C + p))
            .collect();
        let starts: Vec<u64> = (0..5).map(|k| k * C).collect();
        let p = phase(&log, &starts, C);
        assert_eq!(p.n, 5);
        assert!((p.width_ns - 510_000.0).abs() < 1e-6, "width {}", p.width_ns);
        // SYNC0 at 779 µs (the mean, 279 µs with the late frame counted at −120, + 500): the
        // late frame (880) passed after its cycle's SYNC0, with the next cycle's frame before
        // the following one — one overwritten — and its own cycle's SYNC0 found none.
        assert_eq!((p.lost, p.repeated), (1, 1));
    }

    /// One slave, 1 ms, 1 s: the arguments the analysis tests share.
    fn one_second() -> LiveArgs {
        LiveArgs {
            methods: vec![],
            slaves: 1,
            cycle_us: 1000,
            settle_s: 0.0,
            seconds: 1.0,
            seed: 1,
            io: crate::target::IoPath::Auto,
            spin_us: ferrocat_link::DEFAULT_RING_SPIN_NS / 1000,
            sim_io: crate::target::IoPath::Socket,
            probe_budget_us: None,
            json: false,
        }
    }

    #[test]
    fn one_stall_rules_the_rms_and_not_the_median_error() {
        let a = one_second();
        let log = std::env::temp_dir().join(format!("ferrocat-live-median-{}.csv", std::process::id()));
        // Master − reference: +100, −200, +300 ns and one 50 µs stall.
        let lines: String = [100i64, -200, 300, 50_000]
            .iter()
            .enumerate()
            .map(|(k, e)| {
                let t = 1_000_000 * (k as i64 + 1);
                format!("{t},{}\n", t - e)
            })
            .collect();
        std::fs::write(&log, format!("t,s0\n{lines}")).unwrap();
        let run = MasterRun {
            epoch_offset_ns: 0,
            clock: None,
            from_ns: 0,
            to_ns: u64::MAX,
            cycles: 4,
            lost: 0,
            probes: 0,
            cycle_starts: vec![],
        };
        let row = errors(&log, &run, "conventional", &a).unwrap();
        std::fs::remove_file(&log).ok();
        assert!((row.ref_median_abs_us.unwrap() - 0.25).abs() < 1e-9, "{row:?}");
        assert!(row.ref_rms_us.unwrap() > 25.0, "{row:?}");
        assert!((row.max_abs_us.unwrap() - 50.0).abs() < 1e-9, "{row:?}");
    }

    #[test]
    fn a_method_without_a_master_clock_reports_its_phase_only() {
        let a = one_second();
        let log = std::env::temp_dir().join(format!("ferrocat-live-phase-{}.csv", std::process::id()));
        std::fs::write(
            &log,
            "t,s0
1000,7000250000
1001000,7001250100
",
        )
        .unwrap();
        let run = MasterRun {
            epoch_offset_ns: 0,
            clock: None,
            from_ns: 0,
            to_ns: u64::MAX,
            cycles: 2,
            lost: 0,
            probes: 0,
            cycle_starts: vec![0, 1_000_000],
        };
        for (method, clock) in [("chen2016", false), ("pi", false), ("conventional", true)] {
            let row = errors(&log, &run, method, &a).unwrap();
            assert_eq!(row.ref_mean_us.is_some(), clock, "{method}");
            assert_eq!(row.max_abs_us.is_some(), clock, "{method}");
            assert_eq!(row.phased, 2);
            assert!((row.phase_mean_us - 250.05).abs() < 1e-9, "{row:?}");
            assert!((row.phase_width_us - 0.1).abs() < 1e-9, "{row:?}");
        }
        std::fs::remove_file(&log).ok();
    }

    #[test]
    fn a_master_that_follows_the_reference_is_measured_on_its_own_line() {
        let a = one_second();
        let log = std::env::temp_dir().join(format!("ferrocat-live-unit-{}.csv", std::process::id()));
        // Monotonic 1 000 000 ns is own 5 001 000 000; the slave reads 7 000 000 000 + 500 then.
        std::fs::write(&log, "t,s0\n900000,1\n1000000,7000000500\n2000000,7001000600\n").unwrap();
        let epoch = 5_000_000_000;
        // From own 5 000 950 000 on, the method's clock is 7 000 000 000 − 50 000 + 1.0001 × Δ.
        let piece = ClockPiece { own_ns: 5_000_950_000, master_ns: 6_999_950_000, rate: 1.0001 };
        let mut run = MasterRun {
            epoch_offset_ns: epoch,
            clock: Some(vec![piece]),
            from_ns: 0,
            to_ns: u64::MAX,
            cycles: 3,
            lost: 0,
            probes: 0,
            cycle_starts: vec![],
        };
        let row = errors(&log, &run, "ferrocat-mfr", &a).unwrap();
        // The frame before the first piece is left out; the others: line − slave.
        assert_eq!(row.samples, 2);
        let e1 = 6_999_950_000.0 + 1.0001 * 50_000.0 - 7_000_000_500.0;
        let e2 = 6_999_950_000.0 + 1.0001 * 1_050_000.0 - 7_001_000_600.0;
        assert!((row.ref_mean_us.unwrap() * 1e3 - (e1 + e2) / 2.0).abs() < 1.0, "{row:?}");
        // Without a clock of the method's own, the master's is CLOCK_MONOTONIC + epoch.
        run.clock = None;
        let row = errors(&log, &run, "ferrocat", &a).unwrap();
        assert_eq!(row.samples, 3);
        std::fs::remove_file(&log).ok();
    }
}
