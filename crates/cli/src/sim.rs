//! `ferrocat sim`: serve a virtual segment on a real interface or over UDP.
use std::path::{Path, PathBuf};
use std::process::ExitCode;
use std::sync::atomic::AtomicBool;
use std::sync::Arc;

use anyhow::{bail, Context};
use ferrocat_esc::DigitalIo;
use ferrocat_segment::{Segment, SegmentConfig};
use ferrocat_sim::serve::{
    serve_raw, serve_ring, serve_udp, serve_uring, RawSocket, RingSocket, ServeStats, UringSocket,
};
use serde_json::json;

pub struct SimArgs {
    pub config: Option<PathBuf>,
    /// An ENI file whose slaves to serve.
    pub eni: Option<PathBuf>,
    /// A machine description whose slaves' devices to serve.
    pub machine: Option<PathBuf>,
    pub devices: Vec<String>,
    pub iface: Option<String>,
    pub secondary_iface: Option<String>,
    pub udp: Option<String>,
    pub report: Option<PathBuf>,
    pub clock_log: Option<PathBuf>,
    pub seed: Option<u64>,
    /// DEVICE:TAP bridges of EoE endpoints to the host.
    pub eoe_taps: Vec<String>,
    /// How frames move on `iface` (a ring's two ports always use socket calls).
    pub io: crate::target::IoPath,
    /// With `io` ring: how long a receive spins before it sleeps, µs.
    pub spin_us: u64,
}

/// `--eoe-tap DEVICE:TAP`: the device's EoE endpoint bridged to a new TAP interface.
fn eoe_tap(seg: &mut Segment, spec: &str) -> anyhow::Result<ferrocat_sim::serve::EoeTap> {
    let (dev, name) = spec.split_once(':').with_context(|| format!("--eoe-tap '{spec}': give DEVICE:TAP"))?;
    let node: usize = dev.parse().with_context(|| format!("--eoe-tap '{spec}': '{dev}' is not a device position"))?;
    let n = seg.nodes.get_mut(node).with_context(|| format!("--eoe-tap '{spec}': no device {node}"))?;
    if !n.esc.set_eoe_bridged(true) {
        bail!("--eoe-tap '{spec}': device {node} ({}) has no EoE endpoint (its SII does not name EoE)", n.name);
    }
    let tap = ferrocat_link::Tap::open(name)
        .with_context(|| format!("creating TAP interface '{name}' (needs CAP_NET_ADMIN)"))?;
    Ok(ferrocat_sim::serve::EoeTap { node, tap, to_host: 0, from_host: 0, dropped: 0 })
}

/// The segment a machine description describes (`SegmentConfig::from_machine`), with `seed`.
pub fn machine_segment(path: &Path, seed: Option<u64>) -> anyhow::Result<SegmentConfig> {
    let mut cfg = SegmentConfig::from_machine(path)?;
    cfg.seed = seed.unwrap_or(0);
    Ok(cfg)
}

/// Builds the segment a command describes with `--config` or `--device`.
pub fn segment_from(config: Option<&Path>, devices: &[String], seed: Option<u64>) -> anyhow::Result<Segment> {
    Ok(segment_config(config, devices, seed)?.build()?)
}

fn segment_config(config: Option<&Path>, devices: &[String], seed: Option<u64>) -> anyhow::Result<SegmentConfig> {
    let mut cfg = match (config, devices.is_empty()) {
        (Some(p), true) => SegmentConfig::from_file(p)?,
        (None, false) => SegmentConfig::from_device_args(devices)?,
        (Some(_), false) => bail!("give either --config or --device, not both"),
        (None, true) => bail!("no segment: give --config SEG.toml or --device FILE[:PRODUCT] (repeated)"),
    };
    if let Some(s) = seed {
        cfg.seed = s;
    }
    Ok(cfg)
}

fn report(seg: &Segment, stats: &ServeStats) -> serde_json::Value {
    // What only a simulator knows: each clock's true system time less the first's, now.
    let now = seg.now_ns();
    let first = seg.nodes.iter().find(|n| n.esc.has_system_time()).and_then(|n| n.esc.dc.as_ref());
    let less_first = |n: &ferrocat_segment::Node| -> Option<i64> {
        let (dc, first) = (n.esc.dc.as_ref().filter(|_| n.esc.has_system_time())?, first?);
        let d = dc.system_at(now).wrapping_sub(first.system_at(now));
        // Either clock 32 bits wide: the difference in 32 bits.
        let wide = [dc, first].iter().all(|u| u.width == ferrocat_esc::DcWidth::Bits64);
        Some(if wide { d as i64 } else { d as u32 as i32 as i64 })
    };
    let devices: Vec<_> = seg
        .nodes
        .iter()
        .enumerate()
        .map(|(i, n)| {
            let io = n.esc.app().as_any().downcast_ref::<DigitalIo>();
            // A CoE device's outputs: its mapped objects as it last received them.
            let coe = n.esc.app().as_any().downcast_ref::<ferrocat_esc::CoeDevice>();
            let outputs = io.map(|d| d.outputs.clone()).or_else(|| coe.map(|c| c.image(true)));
            // Its FoE server's transfers, where it has one (a plain CoE device or a drive).
            let drive = n.esc.app().as_any().downcast_ref::<ferrocat_esc::Cia402Drive>();
            let coe = coe.or_else(|| drive.map(|d| &d.coe));
            let foe = coe.and_then(|c| c.foe.as_ref());
            // Its EoE endpoint: the address the master gave it and the frames it took and sent.
            let eoe = coe.and_then(|c| c.eoe.as_ref()).map(|e| {
                let ip = e.params.ip.map(|a| std::net::Ipv4Addr::from(a).to_string());
                json!({"ip": ip, "frames_in": e.frames_in, "frames_out": e.frames_out, "ignored": e.ignored,
                       "fragment_errors": e.fragment_errors})
            });
            json!({
                "position": i,
                "name": n.name,
                "station_address": n.esc.station_address(),
                "alias": u16::from_le_bytes(n.esc.peek(0x0012, 2).try_into().unwrap_or_default()),
                "eeprom_loaded": n.esc.sii_loaded(),
                "al_state": n.esc.al_status().state().map(|s| s.name()),
                "al_status_code": n.esc.al.code.0,
                // 0x0300–0x0313: invalid frames and RX errors by port, forwarded errors, lost links.
                "error_counters": n.esc.peek(0x0300, 0x14),
                "frames": n.esc.frames,
                "outputs": outputs,
                "output_updates": io.map(|d| d.output_updates),
                "system_time_difference": n.esc.dc.as_ref().map(|d| d.diff_mean_ns()),
                "system_time_less_first_ns": less_first(n),
                "foe": foe.map(|f| json!({"writes": f.writes, "reads": f.reads, "busy_sent": f.busy_sent})),
                "eoe": eoe,
                // Mailbox repeat requests answered, and requests taken once though written twice.
                "mailbox": {"repeats": n.esc.mbx_repeats, "duplicates": n.esc.mbx_duplicates},
                // Times its application took it out of OP with a sync error (0x001A; 0x002C: SYNC0 lost).
                "sync_errors": n.esc.sync_errors,
            })
        })
        .collect();
    json!({
        "frames_in": stats.frames_in,
        "frames_out": stats.frames_out,
        "frames_in_secondary": stats.frames_in_secondary,
        "frames_out_secondary": stats.frames_out_secondary,
        "frames_lost": seg.stats.lost,
        "frames_destroyed_circulating": seg.stats.destroyed_circulating,
        "not_ethercat": stats.not_ethercat,
        "malformed": stats.malformed,
        "busy_ns_per_frame": stats.busy_ns.checked_div(stats.frames_out).unwrap_or(0),
        "busy_ns_median": stats.busy_quantile_ns(0.5),
        "busy_ns_p99": stats.busy_quantile_ns(0.99),
        "taken_late": stats.taken_late,
        "max_wait_ns": stats.max_wait_ns,
        "sync_errors": stats.sync_errors.iter().map(|e| json!({
            "at_s": e.at_ns as f64 * 1e-9,
            "device": e.node,
            "al_status_code": e.code,
            "side": match e.side {
                ferrocat_sim::serve::SyncErrorSide::NoFrames { .. } => "no frames",
                ferrocat_sim::serve::SyncErrorSide::Simulator { .. } => "simulator",
                ferrocat_sim::serve::SyncErrorSide::Phase { .. } => "phase",
            },
            "why": e.side.to_string(),
        })).collect::<Vec<_>>(),
        "devices": devices,
    })
}

/// Peak resident memory of this process (VmHWM), in KiB.
fn peak_rss_kib() -> Option<u64> {
    let s = std::fs::read_to_string("/proc/self/status").ok()?;
    s.lines().find_map(|l| l.strip_prefix("VmHWM:")).and_then(|v| v.trim().trim_end_matches("kB").trim().parse().ok())
}

/// The wall time (s) of `repeats` runs of `run`, shortest first.
fn sorted_walls_s(repeats: usize, mut run: impl FnMut()) -> Vec<f64> {
    let mut walls: Vec<f64> = (0..repeats)
        .map(|_| {
            let t0 = std::time::Instant::now();
            run();
            t0.elapsed().as_secs_f64()
        })
        .collect();
    walls.sort_by(f64::total_cmp);
    walls
}

/// `ferrocat sim --bench`: virtual-time speed with one LRW + FRMW frame per cycle; each size
/// runs `REPEATS` times on, and the median run is reported (one short run swings by ±25 % on a
/// shared VM).
pub fn bench(json: bool) -> anyhow::Result<ExitCode> {
    use ferrocat_sim::bench::{CyclicBench, TclBench};
    const REPEATS: usize = 7;
    let mut rows = Vec::new();
    for (slaves, cycle_us, sim_s) in [(6usize, 1000u64, 60.0f64), (64, 1000, 10.0), (256, 100, 1.0)] {
        let mut b = CyclicBench::new(slaves, cycle_us * 1000, 1)?;
        let cycles = (sim_s * 1e6 / cycle_us as f64) as u64;
        let walls = sorted_walls_s(REPEATS, || b.run(cycles));
        let wall = walls[REPEATS / 2];
        let speed = sim_s / wall;
        let (fast, slow) = (sim_s / walls[0], sim_s / walls[REPEATS - 1]);
        if !json {
            println!(
                "{slaves:4} slaves, {cycle_us:5} µs cycle: {sim_s:5.1} s simulated in {wall:6.3} s wall = {speed:8.1}x real time \
                 (median of {REPEATS}, {slow:.1}–{fast:.1}x; {:.0} ns per cycle, {:.0} per ESC visit, {} lost)",
                wall * 1e9 / cycles as f64,
                wall * 1e9 / (cycles * slaves as u64) as f64,
                b.lost
            );
        }
        rows.push(json!({"slaves": slaves, "cycle_us": cycle_us, "simulated_s": sim_s, "wall_s": wall,
                         "speedup": speed, "repeats": REPEATS, "speedup_min": slow, "speedup_max": fast}));
    }
    // A floor under the ESC visit: the time control loop's sample alone, which every follower
    // takes from the FRMW each cycle.
    let mut tcl = TclBench::new(256, 100_000);
    let tcl_cycles = 4_000u64;
    let samples = (tcl_cycles * tcl.units() as u64) as f64;
    let tcl_ns: Vec<f64> =
        sorted_walls_s(REPEATS, || tcl.run(tcl_cycles)).into_iter().map(|s| s * 1e9 / samples).collect();
    let tcl_sample_ns = tcl_ns[REPEATS / 2];
    // 20x real time for 256 slaves at 100 us: 100 us / 20 / 256 per ESC visit.
    let budget_ns = 100_000.0 / 20.0 / 256.0;
    if !json {
        println!(
            "time control loop sample alone: {tcl_sample_ns:.1} ns (median of {REPEATS}, {:.1}–{:.1}; SCD sum {}); \
             an ESC visit at 20x real time for 256 slaves at 100 µs may take {budget_ns:.1} ns",
            tcl_ns[0],
            tcl_ns[REPEATS - 1],
            tcl.scd_sum()
        );
    }
    let peak = peak_rss_kib();
    if json {
        println!(
            "{}",
            json!({"rows": rows, "peak_rss_kib": peak, "tcl_sample_ns": tcl_sample_ns, "visit_budget_20x_256_ns": budget_ns})
        );
    } else if let Some(k) = peak {
        println!("peak resident memory (all three runs, 256 slaves the largest): {:.1} MiB", k as f64 / 1024.0);
    }
    Ok(ExitCode::SUCCESS)
}

pub fn run(a: SimArgs) -> anyhow::Result<ExitCode> {
    let mut cfg = match (&a.eni, &a.machine) {
        (None, Some(path)) => machine_segment(path, a.seed)?,
        (Some(path), _) => {
            // Its warnings, once, as `ferrocat eni` shows them.
            crate::eni::read(path, false)?;
            let mut cfg = SegmentConfig::from_eni(path)?;
            cfg.seed = a.seed.unwrap_or(0);
            cfg
        }
        (None, None) => segment_config(a.config.as_deref(), &a.devices, a.seed)?,
    };
    // A second interface closes the segment into a ring: at the last device's free port
    // unless the description says where.
    if a.secondary_iface.is_some() && cfg.secondary.is_none() {
        cfg.secondary = Some(Default::default());
    }
    let mut seg = cfg.build()?;
    if let (Some(_), None) = (seg.secondary(), &a.secondary_iface) {
        eprintln!("ferrocat sim: the segment is a ring but no --secondary-iface serves its second port");
    }
    for (k, n) in seg.nodes.iter().enumerate().filter(|(_, n)| !n.esc.sii_loaded()) {
        // As hardware with such an EEPROM: served, but unconfigured and held in INIT.
        eprintln!(
            "ferrocat sim: device {k} ({}): its EEPROM's configuration area fails its checksum (word 7); \
             its ESC stays unconfigured and in INIT",
            n.name
        );
    }
    let stop = Arc::new(AtomicBool::new(false));
    for sig in [signal_hook::consts::SIGINT, signal_hook::consts::SIGTERM] {
        signal_hook::flag::register(sig, Arc::clone(&stop)).context("installing signal handlers")?;
    }
    let names: Vec<String> = seg.nodes.iter().map(|n| n.name.clone()).collect();
    let stats = match (&a.iface, &a.udp) {
        (Some(iface), None) => {
            let sock = RawSocket::open(iface).with_context(|| format!("serving interface {iface}"))?;
            let secondary = match &a.secondary_iface {
                Some(s) => Some(RawSocket::open(s).with_context(|| format!("serving interface {s}"))?),
                None => None,
            };
            let mut taps = a.eoe_taps.iter().map(|t| eoe_tap(&mut seg, t)).collect::<anyhow::Result<Vec<_>>>()?;
            for t in &taps {
                eprintln!("ferrocat sim: device {}'s EoE bridged to {}", t.node, t.tap.name());
            }
            // Answer like hardware: real-time priority on CPU 0 (a master pins itself to CPU 1),
            // below a master's 80 so that neither starves the other on a shared core. Set up
            // before saying it serves: locking the memory can take a while, and a master that
            // starts on the word would wait for its first answers.
            let rt = ferrocat_link::real_time(70, Some(0));
            if !rt.refused.is_empty() {
                eprintln!("ferrocat sim: real time refused ({}); answers may be late", rt.refused.join("; "));
            }
            match (&a.secondary_iface, seg.secondary()) {
                (Some(s), Some(l)) => eprintln!(
                    "ferrocat sim: {} slaves ({}) in a ring on {iface} and {s} (port {} of device {})",
                    names.len(),
                    names.join(", "),
                    l.port,
                    l.node
                ),
                _ => eprintln!("ferrocat sim: {} slaves ({}) on {iface}", names.len(), names.join(", ")),
            }
            use crate::target::IoPath;
            let log = a.clock_log.is_some();
            let stats = match (secondary, a.io) {
                (None, IoPath::Uring | IoPath::Auto) => match UringSocket::new(sock) {
                    Ok(mut u) => {
                        eprintln!("ferrocat sim: frames through io_uring");
                        serve_uring(&mut seg, &mut u, &stop, log, &mut taps)?
                    }
                    Err((e, _)) if a.io == IoPath::Uring => {
                        return Err(anyhow::Error::new(e).context(format!("io_uring on {iface}")))
                    }
                    Err((e, sock)) => {
                        eprintln!("ferrocat sim: io_uring not available ({e}); socket calls instead");
                        serve_raw(&mut seg, &sock, None, &stop, log, &mut taps)?
                    }
                },
                (None, IoPath::Ring) => {
                    let mut r = RingSocket::new(sock, a.spin_us.saturating_mul(1000))
                        .with_context(|| format!("a packet ring on {iface}"))?;
                    let send = if r.sends_through_io_uring() { "" } else { ", sending with sendto" };
                    eprintln!(
                        "ferrocat sim: frames through a packet ring (spinning {} µs before sleeping{send})",
                        a.spin_us
                    );
                    serve_ring(&mut seg, &mut r, &stop, log, &mut taps)?
                }
                (secondary, _) => serve_raw(&mut seg, &sock, secondary.as_ref(), &stop, log, &mut taps)?,
            };
            for t in &taps {
                eprintln!(
                    "ferrocat sim: device {}'s EoE bridged to {}: {} frames to the host, {} from it, {} dropped",
                    t.node,
                    t.tap.name(),
                    t.to_host,
                    t.from_host,
                    t.dropped
                );
            }
            stats
        }
        (None, Some(addr)) => {
            let sock = std::net::UdpSocket::bind(addr).with_context(|| format!("binding UDP {addr}"))?;
            eprintln!("ferrocat sim: {} slaves ({}) on UDP {}", names.len(), names.join(", "), sock.local_addr()?);
            serve_udp(&mut seg, &sock, &stop)?
        }
        _ => bail!("give exactly one of --iface IF or --udp ADDR:PORT"),
    };
    let r = report(&seg, &stats);
    eprintln!(
        "ferrocat sim: stopped after {} frames in, {} answered, {} not EtherCAT, {} malformed",
        stats.frames_in, stats.frames_out, stats.not_ethercat, stats.malformed
    );
    if let (Some(m), Some(p99)) = (stats.busy_quantile_ns(0.5), stats.busy_quantile_ns(0.99)) {
        eprintln!(
            "ferrocat sim: time per frame (receive to send) median {:.1} µs, p99 {:.1} µs",
            m as f64 / 1000.0,
            p99 as f64 / 1000.0
        );
    }
    if stats.frames_in > 0 {
        eprintln!(
            "ferrocat sim: {}taken more than {} µs after arriving (longest wait {:.0} µs)",
            crate::count(stats.taken_late as usize, "frame", ""),
            ferrocat_sim::serve::SHARED_WAIT_NS / 1000,
            stats.max_wait_ns as f64 / 1e3
        );
    }
    for e in &stats.sync_errors {
        eprintln!(
            "ferrocat sim: t={:.3} s device {} ({}) left OP with 0x{:04x}: {}",
            e.at_ns as f64 * 1e-9,
            e.node,
            seg.nodes.get(e.node).map_or("?", |n| n.name.as_str()),
            e.code,
            e.side
        );
    }
    if let Some(p) = a.report {
        std::fs::write(&p, format!("{r:#}\n")).with_context(|| format!("writing {}", p.display()))?;
    }
    if let (Some(p), Some(log)) = (a.clock_log, &stats.clock_log) {
        write_clock_log(&p, &seg, log).with_context(|| format!("writing {}", p.display()))?;
    }
    Ok(ExitCode::SUCCESS)
}

/// The clock log as CSV: `monotonic_ns` and one `system_ns_K` column per device (empty
/// without DC).
fn write_clock_log(p: &Path, seg: &Segment, log: &[u64]) -> std::io::Result<()> {
    use std::io::Write;
    let mut w = std::io::BufWriter::new(std::fs::File::create(p)?);
    let n = seg.nodes.len();
    write!(w, "monotonic_ns")?;
    for k in 0..n {
        write!(w, ",system_ns_{k}")?;
    }
    writeln!(w)?;
    for row in log.chunks_exact(n + 1) {
        write!(w, "{}", row[0])?;
        for &v in &row[1..] {
            if v == u64::MAX {
                write!(w, ",")?;
            } else {
                write!(w, ",{v}")?;
            }
        }
        writeln!(w)?;
    }
    w.flush()
}

/// `ferrocat rtt`: round trips of an LRW + FRMW frame through whatever answers on `iface`.
pub fn rtt(iface: &str, frames: u32, slaves: u16, force: bool) -> anyhow::Result<ExitCode> {
    use ferrocat_sim::serve::{monotonic_ns, RawSocket};
    use ferrocat_wire::ethernet::{EthernetRepr, BROADCAST};
    use ferrocat_wire::{Address, Command, DatagramHeader, Frame, FrameWriter};
    /// Frames in a row that no slave answers before the measurement stops.
    const GIVE_UP: u32 = 20;
    const WAIT_NS: u64 = 50_000_000;
    crate::target::check_iface(iface, force)?;
    let sock = RawSocket::open(iface).with_context(|| format!("opening {iface}"))?;
    let image = (slaves.saturating_sub(1) as usize * 4).div_ceil(8).max(1);
    let eth = EthernetRepr { dst: BROADCAST, src: [0x02, 0, 0, 0, 0, 0x01], vlan_tci: None, ethertype: 0 };
    let mut frame = [0u8; 1514];
    let mut w = FrameWriter::new(&mut frame, &eth)?;
    w.push_chained(&DatagramHeader::new(Command::LRW, 0x42, Address::Logical(0), image as u16), &vec![0; image], 0)?;
    w.push_chained(
        &DatagramHeader::new(Command::FRMW, 0x43, Address::Device { adp: 0x1001, ado: 0x0910 }, 8),
        &[0; 8],
        0,
    )?;
    let len = w.finish()?;
    let (mut rtts, mut buf) = (Vec::new(), [0u8; 2048]);
    let (mut lost, mut unprocessed, mut in_a_row) = (0u32, 0u32, 0u32);
    let mut progress_at = monotonic_ns() + 2_000_000_000;
    for k in 0..frames {
        let t0 = monotonic_ns();
        sock.send(&frame[..len])?;
        let mut answered = false;
        while !answered && monotonic_ns() - t0 < WAIT_NS {
            let Some(n) = sock.recv(&mut buf)? else { continue };
            let Ok(Some(f)) = Frame::parse(&buf[..n]) else { continue };
            let mut d = f.pdu.datagrams();
            if d.next().is_none_or(|d| d.header().index != 0x42) {
                continue;
            }
            // A frame back with every working counter 0 passed no slave: a loopback (`lo`
            // hands our own frame back) or a port with a cable and nothing on it.
            if f.pdu.datagrams().all(|d| d.wkc() == 0) {
                unprocessed += 1;
                break;
            }
            rtts.push(monotonic_ns() - t0);
            answered = true;
        }
        lost += !answered as u32;
        in_a_row = if answered { 0 } else { in_a_row + 1 };
        if in_a_row >= GIVE_UP {
            let why = match unprocessed {
                0 => String::from("nothing came back"),
                n => format!("{n} came back unprocessed: a loopback or an open port, not an EtherCAT segment"),
            };
            anyhow::bail!(
                "no slave answered {GIVE_UP} frames in a row on {iface} ({why}); stopped after {} of {frames} frames",
                k + 1
            );
        }
        if monotonic_ns() > progress_at {
            eprintln!("rtt: {} of {frames} frames sent, {lost} unanswered", k + 1);
            progress_at += 2_000_000_000;
        }
    }
    rtts.sort_unstable();
    let q = |p: f64| rtts[((rtts.len() - 1) as f64 * p).round() as usize] as f64 / 1000.0;
    if rtts.is_empty() {
        anyhow::bail!("no slave answered any of {frames} frame(s) on {iface}");
    }
    println!(
        "{frames} {}, {lost} unanswered ({unprocessed} back unprocessed); round trip median {:.1} µs, p90 {:.1} µs, p99 {:.1} µs, max {:.1} µs, min {:.1} µs",
        if frames == 1 { "frame" } else { "frames" },
        q(0.5),
        q(0.9),
        q(0.99),
        q(1.0),
        q(0.0)
    );
    Ok(if lost == 0 { ExitCode::SUCCESS } else { ExitCode::FAILURE })
}
