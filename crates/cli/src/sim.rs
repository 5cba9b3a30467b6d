//! `ferrocat sim`: serve a virtual segment on a real interface or over UDP.
use std::path::{Path, PathBuf};
use std::process::ExitCode;
use std::sync::atomic::AtomicBool;
use std::sync::Arc;

use anyhow::{bail, Context};
use ferrocat_esc::DigitalIo;
use ferrocat_segment::live::{serve_raw, serve_udp, RawSocket, ServeStats};
use ferrocat_segment::{Segment, SegmentConfig};
use serde_json::json;

pub struct SimArgs {
    pub config: Option<PathBuf>,
    pub devices: Vec<String>,
    pub iface: Option<String>,
    pub udp: Option<String>,
    pub report: Option<PathBuf>,
    pub seed: Option<u64>,
}

/// Builds the segment a command describes with `--config` or `--device`.
pub fn segment_from(config: Option<&Path>, devices: &[String], seed: Option<u64>) -> anyhow::Result<Segment> {
    let mut cfg = match (config, devices.is_empty()) {
        (Some(p), true) => SegmentConfig::from_file(p)?,
        (None, false) => SegmentConfig::from_device_args(devices)?,
        (Some(_), false) => bail!("give either --config or --device, not both"),
        (None, true) => bail!("no segment: give --config SEG.toml or --device FILE[:PRODUCT] (repeated)"),
    };
    if let Some(s) = seed {
        cfg.seed = s;
    }
    Ok(cfg.build()?)
}

fn report(seg: &Segment, stats: &ServeStats) -> serde_json::Value {
    let devices: Vec<_> = seg
        .nodes
        .iter()
        .enumerate()
        .map(|(i, n)| {
            let io = n.esc.app().as_any().downcast_ref::<DigitalIo>();
            json!({
                "position": i,
                "name": n.name,
                "station_address": n.esc.station_address(),
                "al_state": n.esc.al_status().state().map(|s| s.name()),
                "al_status_code": n.esc.al.code.0,
                "frames": n.esc.frames,
                "outputs": io.map(|d| d.outputs.clone()),
                "output_updates": io.map(|d| d.output_updates),
                "system_time_difference": n.esc.dc.as_ref().map(|d| d.diff_mean_ns),
            })
        })
        .collect();
    json!({
        "frames_in": stats.frames_in,
        "frames_out": stats.frames_out,
        "not_ethercat": stats.not_ethercat,
        "malformed": stats.malformed,
        "busy_ns_per_frame": if stats.frames_out > 0 { stats.busy_ns / stats.frames_out } else { 0 },
        "devices": devices,
    })
}

pub fn run(a: SimArgs) -> anyhow::Result<ExitCode> {
    let mut seg = segment_from(a.config.as_deref(), &a.devices, a.seed)?;
    let stop = Arc::new(AtomicBool::new(false));
    for sig in [signal_hook::consts::SIGINT, signal_hook::consts::SIGTERM] {
        signal_hook::flag::register(sig, Arc::clone(&stop)).context("installing signal handlers")?;
    }
    let names: Vec<_> = seg.nodes.iter().map(|n| n.name.as_str()).collect();
    let stats = match (&a.iface, &a.udp) {
        (Some(iface), None) => {
            let sock = RawSocket::open(iface).with_context(|| format!("serving interface {iface}"))?;
            eprintln!("ferrocat sim: {} slaves ({}) on {iface}", names.len(), names.join(", "));
            serve_raw(&mut seg, &sock, &stop)?
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
    if let Some(p) = a.report {
        std::fs::write(&p, format!("{r:#}\n")).with_context(|| format!("writing {}", p.display()))?;
    }
    Ok(ExitCode::SUCCESS)
}
