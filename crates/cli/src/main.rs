//! `ferrocat`: one binary for every tool of the project.
use std::path::PathBuf;
use std::process::ExitCode;

use clap::{Parser, Subcommand};

mod esi;
mod pcap;
mod sii;
mod sim;

#[derive(Parser)]
#[command(name = "ferrocat", version, about = "EtherCAT master, virtual segment and clock-synchronisation lab")]
struct Cli {
    #[command(subcommand)]
    command: Command,
}

#[derive(Subcommand)]
enum Command {
    /// List every EtherCAT datagram of a pcap or pcapng file, one line per datagram.
    Pcap {
        file: PathBuf,
        /// One JSON object per line instead of text.
        #[arg(long)]
        json: bool,
    },
    /// Decode an SII EEPROM image (raw binary, Intel HEX or hex text).
    Sii {
        file: PathBuf,
        #[arg(long)]
        json: bool,
    },
    /// List the devices of an ESI file, show one, or write its SII image.
    Esi {
        file: PathBuf,
        /// Device to show or build: its position in the listing (0-based) or `#xPRODUCT[:#xREVISION]`.
        #[arg(long)]
        device: Option<String>,
        /// Write the device's SII EEPROM image to this file.
        #[arg(long, value_name = "OUT")]
        sii: Option<PathBuf>,
        #[arg(long)]
        json: bool,
    },
    /// Serve a virtual segment on a network interface (raw socket) or over UDP, until SIGINT/SIGTERM.
    Sim {
        /// Segment description (TOML).
        #[arg(long, value_name = "SEG.toml")]
        config: Option<PathBuf>,
        /// A device of a line segment, in order from the master: EEPROM dump, ESI file with
        /// `:PRODUCT`, or a built-in name (EK1100, EL1004, EL2004).
        #[arg(long, value_name = "FILE[:PRODUCT]")]
        device: Vec<String>,
        /// Network interface to serve (AF_PACKET raw socket; needs CAP_NET_RAW).
        #[arg(long)]
        iface: Option<String>,
        /// Serve EtherCAT over UDP on this address instead, e.g. 127.0.0.1:34980.
        #[arg(long, value_name = "ADDR:PORT")]
        udp: Option<String>,
        /// Write a JSON report of the devices (state, outputs) here on exit.
        #[arg(long)]
        report: Option<PathBuf>,
        /// Seed for oscillators and faults (overrides the file's).
        #[arg(long)]
        seed: Option<u64>,
        /// Instead of serving: measure virtual-time speed (6/64/256 slaves) and exit.
        #[arg(long, conflicts_with_all = ["config", "device", "iface", "udp", "report"])]
        bench: bool,
        #[arg(long, requires = "bench")]
        json: bool,
    },
    /// Send a segment's cyclic frame (LRW + FRMW) over an interface and print round-trip times.
    Rtt {
        #[arg(long)]
        iface: String,
        /// Frames to send.
        #[arg(long, default_value_t = 2000)]
        frames: u32,
        /// Slaves the frame is built for (one process-data nibble each, after the coupler).
        #[arg(long, default_value_t = 6)]
        slaves: u16,
    },
}

fn main() -> ExitCode {
    let cli = Cli::parse();
    let result = match cli.command {
        Command::Pcap { file, json } => pcap::run(&file, json),
        Command::Sii { file, json } => sii::run(&file, json),
        Command::Esi { file, device, sii, json } => esi::run(&file, device.as_deref(), sii.as_deref(), json),
        Command::Sim { bench: true, json, .. } => sim::bench(json),
        Command::Sim { config, device, iface, udp, report, seed, .. } => {
            sim::run(sim::SimArgs { config, devices: device, iface, udp, report, seed })
        }
        Command::Rtt { iface, frames, slaves } => sim::rtt(&iface, frames, slaves),
    };
    match result {
        Ok(code) => code,
        Err(e) => {
            eprintln!("ferrocat: error: {e:#}");
            ExitCode::FAILURE
        }
    }
}

/// Writes a line to stdout; a closed pipe (e.g. `| head`) ends the program quietly.
pub(crate) fn out(line: std::fmt::Arguments<'_>) {
    use std::io::Write;
    let mut o = std::io::stdout().lock();
    if writeln!(o, "{line}").is_err() {
        std::process::exit(0);
    }
}

#[macro_export]
macro_rules! outln {
    ($($t:tt)*) => { $crate::out(format_args!($($t)*)) };
}
