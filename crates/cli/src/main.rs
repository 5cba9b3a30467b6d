//! `ferrocat`: one binary for every tool of the project.
use std::path::PathBuf;
use std::process::ExitCode;

use clap::{Parser, Subcommand};

mod args;
mod demo;
mod eni;
mod eoe_cmd;
mod esi;
mod image_cmd;
mod lab;
mod lab_args;
mod lab_live;
mod manpages;
mod master_cmd;
mod pcap;
mod plots;
mod reload;
mod report;
mod service_cmd;
mod sii;
mod sim;
mod soe_cmd;
mod target;
mod timing_stats;
mod values;
mod words;

#[derive(Parser)]
#[command(name = "ferrocat", version, about = "EtherCAT master, virtual segment and clock-synchronisation lab")]
struct Cli {
    #[command(subcommand)]
    command: Command,
    /// Log more on stderr: -v the steps, -vv the details. A command that runs a master logs
    /// with -v its bring-up and the slaves' events, with -vv each slave and state, each lost
    /// frame and each error before it is returned. RUST_LOG (e.g. `ferrocat_master=debug`)
    /// overrides both.
    #[arg(short, long, global = true, action = clap::ArgAction::Count, help_heading = "Logging")]
    verbose: u8,
    /// Log errors only (the default logs warnings too, such as what a master handled itself:
    /// a slave's error acknowledged to bring it back to OP).
    #[arg(short, long, global = true, conflicts_with = "verbose", help_heading = "Logging")]
    quiet: bool,
}

/// Logging to stderr at the level -v/-q ask for, unless RUST_LOG says otherwise.
fn init_logging(verbose: u8, quiet: bool) {
    use tracing_subscriber::EnvFilter;
    let level = match (quiet, verbose) {
        (true, _) => "error",
        (false, 0) => "warn",
        (false, 1) => "info",
        _ => "debug",
    };
    let filter = EnvFilter::try_from_default_env().unwrap_or_else(|_| EnvFilter::new(level));
    let _ = tracing_subscriber::fmt()
        .with_env_filter(filter)
        .with_writer(std::io::stderr)
        .with_ansi(std::io::IsTerminal::is_terminal(&std::io::stderr()))
        .with_target(false)
        .without_time()
        .try_init();
}

#[derive(Subcommand)]
enum Command {
    /// List every EtherCAT datagram of a pcap or pcapng file, one line per datagram.
    Pcap {
        /// The pcap or pcapng file.
        file: PathBuf,
        /// One JSON object per line instead of text.
        #[arg(long)]
        json: bool,
    },
    /// Decode an SII EEPROM image file (raw binary, Intel HEX or hex text), or read/write a
    /// slave's EEPROM with `sii read` / `sii write`.
    #[command(args_conflicts_with_subcommands = true)]
    Sii {
        #[command(subcommand)]
        action: Option<EepromCmd>,
        /// The SII image to decode (raw binary, Intel HEX or hex text).
        file: Option<PathBuf>,
        /// Print JSON instead of text.
        #[arg(long)]
        json: bool,
    },
    /// List the devices of an ESI file, show one, or write its SII image.
    Esi {
        /// The ESI XML file.
        file: PathBuf,
        /// Device to show or build: its position in the listing (0-based), `#xPRODUCT[:#xREVISION]`,
        /// or its type name (any case).
        #[arg(long, allow_negative_numbers = true)]
        device: Option<String>,
        /// Write the device's SII EEPROM image to this file.
        #[arg(long, value_name = "OUT")]
        sii: Option<PathBuf>,
        /// Print JSON instead of text.
        #[arg(long)]
        json: bool,
        /// Refuse a file that deviates from ETG.2000 where vendors' tools accept it (odd-length
        /// hex, `0x` numbers, `True`, a keyword's case, duplicates, missing names or data types);
        /// without it such files are read, each deviation a warning with line and column.
        #[arg(long)]
        strict: bool,
    },
    /// Show what an ENI file (ETG.2100, as TwinCAT or EC-Engineer export it) describes: its
    /// slaves, their identities, process data, mailboxes, init commands and DC, the cyclic
    /// frames and the process image.
    Eni {
        /// The ENI XML file.
        file: PathBuf,
        /// Print the whole description as JSON instead of a summary.
        #[arg(long)]
        json: bool,
        /// Refuse a file that departs from ETG.2100 where configuration tools accept it (`0x`
        /// numbers, white space, odd-length hex, `True`, unknown transitions or states, an
        /// 8-bit encoding); without it such files are read, each departure a warning with line
        /// and column.
        #[arg(long)]
        strict: bool,
    },
    /// Serve a virtual segment on a network interface (raw socket) or over UDP, until SIGINT/SIGTERM.
    Sim {
        /// Segment description (TOML).
        #[arg(long, value_name = "SEG.toml", conflicts_with = "eni")]
        config: Option<PathBuf>,
        /// Serve the slaves an ENI file describes, in its order, each with the identity,
        /// SyncManagers, PDOs, mailbox and DC the file gives it.
        #[arg(long, value_name = "FILE", conflicts_with_all = ["device", "machine"])]
        eni: Option<PathBuf>,
        /// Serve the slaves a machine description names, each its `device`.
        #[arg(long, value_name = "FILE", conflicts_with_all = ["device", "config"])]
        machine: Option<PathBuf>,
        /// A device of a line segment, in order from the master: EEPROM dump, ESI file with
        /// `:PRODUCT` (a modular device's modules after it: `:MODULE,MODULE…` by ident), or a
        /// built-in name (EK1100, EL1004, EL2004, SERVO, LAN9252-EVB).
        #[arg(long, value_name = "FILE[:PRODUCT[:MODULES]]")]
        device: Vec<String>,
        /// Network interface to serve (AF_PACKET raw socket; needs CAP_NET_RAW).
        #[arg(long)]
        iface: Option<String>,
        /// With --iface: the master's second port of a ring (cable redundancy), wired where the
        /// segment's `[secondary]` says or to the last device's free port.
        #[arg(long, requires = "iface", value_name = "IF")]
        secondary_iface: Option<String>,
        /// Serve EtherCAT over UDP on this address instead, e.g. 127.0.0.1:34980.
        #[arg(long, value_name = "ADDR:PORT")]
        udp: Option<String>,
        /// Write a JSON report of the devices (state, outputs) here on exit.
        #[arg(long)]
        report: Option<PathBuf>,
        /// With --iface: write, on exit, a CSV of every frame's CLOCK_MONOTONIC instant and each
        /// device's true system time then (what `lab live` compares the master's clock with).
        #[arg(long, requires = "iface")]
        clock_log: Option<PathBuf>,
        /// Seed for oscillators and faults (overrides the file's).
        #[arg(long)]
        seed: Option<u64>,
        /// DEVICE:TAP (repeatable) — with --iface: bridge the EoE endpoint of the device at
        /// position DEVICE to a new TAP interface TAP of this host, whose own network stack
        /// then answers for it.
        #[arg(long, requires = "iface")]
        eoe_tap: Vec<String>,
        /// With --iface: how frames move. socket makes a recvmsg, a sendto and a read of the
        /// transmit stamp per frame; io_uring answers a frame and waits for the next in one
        /// system call, but answered every master measured here more slowly
        /// (docs/benchmarks.md); ring maps a PACKET_MMAP receive ring and spins on it (--spin-us)
        /// before it sleeps, holding its CPU; auto takes io_uring where the kernel allows it. A ring's two ports always use socket calls.
        #[arg(long, value_enum, default_value = "socket", requires = "iface")]
        io: target::IoPath,
        /// With --io ring: how long a receive spins on the ring before it sleeps, in µs.
        #[arg(long, value_name = "US", default_value_t = ferrocat_link::DEFAULT_RING_SPIN_NS / 1000, requires = "iface")]
        spin_us: u64,
        /// Instead of serving: measure virtual-time speed (6/64/256 slaves) and exit.
        #[arg(long, conflicts_with_all = ["config", "device", "iface", "secondary_iface", "udp", "report", "clock_log"])]
        bench: bool,
        /// Print JSON instead of text.
        #[arg(long, requires = "bench")]
        json: bool,
    },
    /// Find the slaves and print what they are and how they are wired (like SOEM's slaveinfo).
    Scan {
        #[command(flatten)]
        target: target::Target,
        /// Print JSON instead of text.
        #[arg(long)]
        json: bool,
        /// Write a machine description of the network found (TOML, docs/machine.md) to this
        /// file: every slave's name, identity and alias, to edit and give to `--machine`.
        #[arg(long, value_name = "FILE")]
        write_machine: Option<PathBuf>,
    },
    /// Read, write or list CoE objects of a slave.
    Sdo {
        #[command(subcommand)]
        action: SdoCmd,
    },
    /// Read, write or list a servo drive's IDNs by SoE (S-0-0030, P-0-0001 …).
    Soe {
        #[command(subcommand)]
        action: soe_cmd::SoeCmd,
    },
    /// Read or write a file of a slave by FoE (firmware, parameter sets), in PREOP or BOOT.
    Foe {
        #[command(subcommand)]
        action: FoeCmd,
    },
    /// Set or read a slave's IP parameters by EoE, or ping it over EoE, in PREOP.
    Eoe {
        #[command(subcommand)]
        action: eoe_cmd::EoeCmd,
    },
    /// Bring the segment to OP and exchange process data for a while, with live statistics.
    Run {
        #[command(flatten)]
        target: target::Target,
        /// How long to exchange process data (s; 0: until SIGINT or SIGTERM, as a service
        /// runs it); SIGINT or SIGTERM end it sooner, with the same summary.
        #[arg(long, default_value_t = 5.0, allow_negative_numbers = true, value_parser = args::seconds)]
        seconds: f64,
        /// The cycle time (µs, 10 to 1 000 000).
        #[arg(long, default_value_t = 1000, allow_negative_numbers = true, value_parser = |s: &str| args::cycle_us(s, 10, 1_000_000))]
        cycle_us: u64,
        /// Distributed clocks: the DC initialisation, SYNC0, and the reference clock's time in
        /// every cyclic frame with the clock-sync method (a machine description's `[dc]` turns
        /// them on too).
        #[arg(long)]
        dc: bool,
        /// Cycle back to back, as fast as the segment answers (a benchmark), instead of every
        /// --cycle-us.
        #[arg(long)]
        max_rate: bool,
        /// How long a cyclic frame's answer is waited for before the frame counts as lost (µs,
        /// 10 to 1 000 000). Default: ¾ of --cycle-us, at most 1 000 (1 000 with --max-rate),
        /// so that a lost frame does not make the next cycle late; on a segment whose round trip
        /// (16 broadcasts before the run) leaves less room than that, the round trip and half
        /// the cycle's rest (twice the round trip with --max-rate). A round trip above 80 % of
        /// the cycle is warned of.
        #[arg(long, value_parser = clap::value_parser!(u64).range(10..=1_000_000))]
        frame_timeout_us: Option<u64>,
        /// With DC: at most this many frames of static drift compensation (it stops earlier
        /// once converged). Default: 15 000.
        #[arg(long)]
        dc_static_frames: Option<u32>,
        /// POS:TAP (repeatable) — bridge the slave at POS to a new TAP interface TAP by EoE
        /// during the run (one fragment each way between cycles, per slave).
        #[arg(long)]
        eoe_tap: Vec<String>,
        /// With DC: the clock-sync method the master runs each cycle, in the cyclic frame
        /// (docs/clock-sync.md); `none` only distributes the reference's time. Default: the
        /// machine description's `[dc] sync`, else ferrocat.
        #[arg(long, value_parser = clap::builder::PossibleValuesParser::new(ferrocat_master::sync::SyncMethod::PRESETS))]
        sync: Option<String>,
        /// With --dc: where SYNC0 falls after each cycle's start (µs, below --cycle-us).
        /// Default: half a cycle after the frame passes the reference (for SOEM's PI and
        /// ferrocat-mfr, which aim that passage at the cycle's start, half the cycle; for the
        /// others, which send on it, half the cycle and half the segment's round trip), so that
        /// a frame up to half a cycle late still reaches the slaves before their SYNC0.
        #[arg(long)]
        sync0_shift_us: Option<u64>,
        /// With DC: how long the clock sync's probe frames may take per cycle on average (µs;
        /// 0: no probes). Default: half the loop's own CPU time per cycle, measured over its
        /// first 0.2 s (at least 200 cycles), which run without probes.
        #[arg(long)]
        probe_budget_us: Option<u64>,
        /// How often each slave's error counters (0x0300–0x0313) are read while cyclic, ms; the
        /// mailboxes are polled for emergencies between. Both only in a cycle's spare time.
        #[arg(long, default_value_t = 1000, value_parser = clap::value_parser!(u64).range(1..=3_600_000))]
        counters_period_ms: u64,
        /// How long a mapped TxPDO Toggle may stand still before the run says that slave's
        /// inputs are not refreshed, ms (diagnosis; a TxPDO State set is said at once).
        #[arg(long, default_value_t = 1000, value_parser = clap::value_parser!(u64).range(1..=3_600_000))]
        txpdo_stale_ms: u64,
        /// No diagnosis while cyclic (error counters, emergencies).
        #[arg(long)]
        no_diagnosis: bool,
        /// NAME=VALUE (repeatable): write this output before OP and hold it. NAME is a
        /// variable of the ENI's process image (with --eni), a machine description's
        /// variable (with --machine), or POS:ENTRY, a slave's position (or its name in the
        /// description) and one of its entries; VALUE decimal or 0x hex, negative in two's
        /// complement.
        #[arg(long, value_name = "NAME=VALUE")]
        set: Vec<String>,
        /// FROM=TO (repeatable): after every cycle copy FROM (an input, named as --set names
        /// outputs) into the output TO, which the next cycle sends (slave-to-slave
        /// communication through the master), besides an ENI's CopyInfos and a machine
        /// description's `[[copy]]` tables.
        #[arg(long, value_name = "FROM=TO")]
        copy: Vec<String>,
        /// NAME (repeatable): print this input's (or output's) value at the end, and in --json
        /// under `values`; named as --set names them.
        #[arg(long, value_name = "NAME")]
        show: Vec<String>,
        /// Print the summary as one JSON object on standard output instead of text.
        #[arg(long)]
        json: bool,
        /// Serve no control socket (by default a master on --iface or --udp serves one, and on
        /// the embedded virtual segment where --control-socket names it).
        #[arg(long)]
        no_control: bool,
        /// The control socket's file mode, octal.
        #[arg(long, default_value = "660", value_name = "MODE", value_parser = parse_mode)]
        control_mode: u32,
        /// The group that owns the control socket (default: this process's).
        #[arg(long, value_name = "GROUP")]
        control_group: Option<String>,
        /// Take register writes through the control socket (`ferrocat reg write`); off by
        /// default, as a register write can take a slave off the segment.
        #[arg(long)]
        allow_register_writes: bool,
        /// Serve the mailbox gateway (ETG.8200) on UDP: engineering tools reach the slaves'
        /// mailboxes, and the master's object dictionary (ETG.1510) at station address 0.
        /// Without a value, 127.0.0.1:34980 (0x88A4); off by default. Needs the control socket.
        #[arg(long, value_name = "ADDR:PORT", num_args = 0..=1, default_missing_value = "127.0.0.1:34980",
              conflicts_with = "no_control")]
        mailbox_gateway: Option<std::net::SocketAddr>,
        /// A sender the mailbox gateway takes besides loopback (repeat for several); others
        /// are dropped and counted.
        #[arg(long, value_name = "IP", requires = "mailbox_gateway")]
        gateway_allow: Vec<std::net::IpAddr>,
        /// Requests a second each sender of the mailbox gateway may make on average (a burst
        /// of a fifth of it beyond); more are answered with mailbox error 0x07.
        #[arg(long, value_name = "N", default_value_t = 500, requires = "mailbox_gateway",
              value_parser = clap::value_parser!(u32).range(1..=100_000))]
        gateway_rate: u32,
        /// Leave the slaves in the state the run ends in (OP) instead of stepping them down to
        /// SAFEOP, then INIT, when it ends (after --seconds, or on SIGINT or SIGTERM).
        #[arg(long)]
        keep_state: bool,
        /// The application watchdog: once a client has written outputs to the shared image,
        /// this long without a write trips it (ms; default: none).
        #[arg(long, value_name = "MS", value_parser = clap::value_parser!(u64).range(1..=3_600_000))]
        app_watchdog_ms: Option<u64>,
        /// What a tripped application watchdog does: hold the last outputs, or take the
        /// slaves with outputs to SAFEOP until the application writes again.
        #[arg(long, value_enum, default_value = "hold", requires = "app_watchdog_ms")]
        app_watchdog: image_cmd::AppWatchdogAction,
    },
    /// The events of the master running on the target (the last 1 024 it keeps: slaves that
    /// left OP, came back or stopped answering, emergencies, sync errors, error counters that
    /// grew, ring changes); with --follow, each new one as it comes, until Ctrl-C.
    Events {
        #[command(flatten)]
        target: target::Target,
        /// Keep printing new events.
        #[arg(long)]
        follow: bool,
        /// One JSON object per event instead of text.
        #[arg(long)]
        json: bool,
    },
    /// The object dictionary of the master running on the target (ETG.1510: its identity, a
    /// configuration, information and diagnosis object per slave, the address lists, the
    /// master's diagnosis, the diagnosis history), an entry a line; the same objects the
    /// mailbox gateway serves at station address 0.
    MasterOd {
        #[command(flatten)]
        target: target::Target,
        /// One JSON object per object instead of text.
        #[arg(long)]
        json: bool,
    },
    /// The process data a slave maps (index, subindex, width, name, where in the image), from
    /// the master running on the target, or a scan of this command's own.
    Pdos {
        /// The slave's position on the segment, counted from 0 (as `scan` shows it).
        #[arg(allow_negative_numbers = true, value_parser = args::position)]
        position: u16,
        #[command(flatten)]
        target: target::Target,
        /// One JSON object instead of text.
        #[arg(long)]
        json: bool,
    },
    /// Print variables of the process image a running master shares (every one without NAME):
    /// outputs as the last cycle sent them, inputs as it received them.
    Get {
        /// Variables: POS:ENTRY, an ENI's variable, or a machine description's variable.
        #[arg(value_name = "NAME")]
        names: Vec<String>,
        #[command(flatten)]
        target: target::Target,
        /// One JSON object instead of text.
        #[arg(long)]
        json: bool,
    },
    /// Write outputs of the process image a running master shares, as one change (sent by one
    /// cycle, or none); waits until a cycle has sent them.
    Set {
        /// NAME=VALUE (decimal or 0x hex; negative in two's complement).
        #[arg(value_name = "NAME=VALUE", required = true, allow_negative_numbers = true)]
        values: Vec<String>,
        #[command(flatten)]
        target: target::Target,
    },
    /// The slaves of the master running on the target, with their AL state read now (as IgH's
    /// `ethercat slaves`); without a running master, the slaves a scan finds.
    Slaves {
        #[command(flatten)]
        target: target::Target,
        /// One JSON array instead of text.
        #[arg(long)]
        json: bool,
    },
    /// Read or write a slave's ESC registers, through the master running on the target or by
    /// a scan of its own.
    Reg {
        #[command(subcommand)]
        action: RegCmd,
    },
    /// Ask the master running on the target to take a slave to INIT, PREOP, SAFEOP or OP and
    /// keep it there.
    State {
        /// The slave's position on the segment, counted from 0 (as `scan` shows it).
        #[arg(allow_negative_numbers = true, value_parser = args::position)]
        position: u16,
        /// INIT, PREOP, SAFEOP or OP (any case).
        state: String,
        #[command(flatten)]
        target: target::Target,
    },
    /// Ask the master running on the target to read its machine description again and apply
    /// what can change while it cycles (as SIGHUP does): process-data watchdogs and
    /// slave-to-slave copies; the network compared again.
    Reload {
        #[command(flatten)]
        target: target::Target,
    },
    /// The statistics of the master running on the target: cycles, working counters, round
    /// trip, requests served, the clock sync's lock.
    Stats {
        #[command(flatten)]
        target: target::Target,
        /// One JSON object instead of text.
        #[arg(long)]
        json: bool,
    },
    /// CiA402 drives with DC on the embedded virtual segment: a synchronised move of every axis
    /// per clock-sync method and cycle time; the master–slave error, SYNC0 simultaneity,
    /// following errors and late or repeated set-points.
    Demo {
        /// Number of drives.
        #[arg(long, default_value_t = 2)]
        drives: usize,
        /// The drive: SERVO (built in), an ESI file with :PRODUCT, or an EEPROM image.
        #[arg(long)]
        drive: Option<String>,
        /// Cycle times (µs, 100 to 10 000; repeatable; default 1000 and 250).
        #[arg(long, allow_negative_numbers = true, value_parser = |s: &str| args::cycle_us(s, 100, 10_000))]
        cycle_us: Vec<u64>,
        /// Clock-sync methods (repeatable; default all: none, conventional, park2020, chen2016,
        /// pi, ferrocat, ferrocat-mfr).
        #[arg(long)]
        method: Vec<String>,
        /// Host model: ideal, pc-rt, pc-stock, nic-hwts, beaglebone-rt, rtx-10us.
        #[arg(long, default_value = "pc-rt")]
        host: String,
        /// Seed of the simulation's random draws (crystals, latencies): the same seed gives the same numbers on any machine (default 1).
        #[arg(long)]
        seed: Option<u64>,
        /// Print JSON instead of text.
        #[arg(long)]
        json: bool,
        /// Folder for the CSV and the plots (SVG and PNG).
        #[arg(long, default_value = "out/demo")]
        out: PathBuf,
        /// Run on this network interface (real drives, or `ferrocat sim` serving one) instead of
        /// the embedded virtual segment; needs CAP_NET_RAW.
        #[arg(long, conflicts_with_all = ["drives", "drive"])]
        iface: Option<String>,
        /// With --iface: send even on an interface that has an IPv4 or a global IPv6 address.
        #[arg(long, requires = "iface")]
        force: bool,
        /// Leave out ferrocat's GPIO calibration of its stamps (virtual segment only; on a
        /// real network nothing is wired).
        #[arg(long)]
        no_gpio_calibration: bool,
    },
    /// The papers' clock-synchronisation experiments, in virtual time.
    Lab {
        #[command(subcommand)]
        experiment: LabCmd,
    },
    /// Print a shell completion script for ferrocat (bash, zsh, fish, elvish or powershell).
    Completions {
        /// The shell the script is for.
        #[arg(value_enum)]
        shell: clap_complete::Shell,
    },
    /// Write the manual pages, ferrocat(1) and one per subcommand (roff), into a folder.
    Manpages {
        /// The folder to write them into (made if missing).
        dir: PathBuf,
    },
    /// Send a segment's cyclic frame (LRW + FRMW) over an interface and print round-trip times
    /// of the frames a slave answered. Stops with an error when 20 frames in a row get no
    /// answer (each waits at most 50 ms).
    Rtt {
        /// The network interface to send on (raw socket; needs CAP_NET_RAW).
        #[arg(long)]
        iface: String,
        /// Frames to send (at least 1).
        #[arg(long, default_value_t = 2000, value_parser = clap::value_parser!(u32).range(1..))]
        frames: u32,
        /// Slaves the frame is built for (one process-data nibble each, after the coupler).
        #[arg(long, default_value_t = 6)]
        slaves: u16,
        /// Send even on an interface that has an IPv4 or a global IPv6 address.
        #[arg(long)]
        force: bool,
    },
}

#[derive(Subcommand)]
enum LabCmd {
    /// Park et al. 2020 Table 1: master–reference and master–last-slave errors per method
    /// (default host beaglebone-rt).
    Park2020(lab_args::Park2020),
    /// Chen et al. 2016 Table 2: jitter and lost process data per cycle time and method
    /// (default host rtx-10us).
    Chen2016(lab_args::Chen2016),
    /// Paprocki & Erwiński 2022 Table 2: how simultaneously two DC slaves see SYNC0.
    Paprocki2022(lab_args::Paprocki2022),
    /// Robustness: 1 % frame loss, a 50 ppm crystal step and a 3-cycle overrun, once each after
    /// settling, for every method of the error tables: peak excursion and recovery.
    Robustness(lab_args::Robustness),
    /// The master–slave clock errors on this machine's real kernel: the master in real time on a
    /// veth pair, `ferrocat sim` on the other end logging the true slave clocks (root); and
    /// where each cycle's frame passed the reference on its cycle.
    Live(lab_live::LiveArgs),
    /// Run the experiment a scenario file names (docs/lab.md, scenarios/).
    Run(lab_args::Run),
}

#[derive(Subcommand)]
enum SdoCmd {
    /// Read INDEX or INDEX:SUB of the slave at POSITION.
    Read {
        /// The slave's position on the segment, counted from 0 (as `scan` shows it).
        #[arg(allow_negative_numbers = true, value_parser = args::position)]
        position: u16,
        /// The object: INDEX or INDEX:SUB, decimal or 0x hex (e.g. 0x6041, 0x1018:1).
        object: String,
        /// Complete access (the whole object).
        #[arg(long)]
        complete: bool,
        /// How to show the value; a number type needs the object to have exactly its width.
        #[arg(long = "type", value_enum, default_value_t = master_cmd::SdoType::Hex)]
        ty: master_cmd::SdoType,
        #[command(flatten)]
        target: target::Target,
    },
    /// Write VALUE to INDEX or INDEX:SUB.
    Write {
        /// The slave's position on the segment, counted from 0 (as `scan` shows it).
        #[arg(allow_negative_numbers = true, value_parser = args::position)]
        position: u16,
        /// The object: INDEX or INDEX:SUB, decimal or 0x hex (e.g. 0x6060:0).
        object: String,
        /// The value to write, as --type reads it (numbers decimal or 0x hex).
        #[arg(allow_negative_numbers = true)]
        value: String,
        /// Complete access: the whole object, every subindex, in one transfer.
        #[arg(long)]
        complete: bool,
        /// How to encode VALUE (numbers decimal or 0x hex, range-checked for the type). Default:
        /// the object's data type, as the slave's SDO information gives it.
        #[arg(long = "type", value_enum)]
        ty: Option<master_cmd::SdoType>,
        #[command(flatten)]
        target: target::Target,
    },
    /// List the object dictionary (SDO information).
    List {
        /// The slave's position on the segment, counted from 0 (as `scan` shows it).
        #[arg(allow_negative_numbers = true, value_parser = args::position)]
        position: u16,
        #[command(flatten)]
        target: target::Target,
    },
}

#[derive(Subcommand)]
enum RegCmd {
    /// Print LEN bytes of the slave's registers from REGISTER, as hex.
    Read {
        /// The slave's position on the segment, counted from 0 (as `scan` shows it).
        #[arg(allow_negative_numbers = true, value_parser = args::position)]
        position: u16,
        /// The first register (decimal or 0x hex), e.g. 0x0130 for the AL status.
        #[arg(value_parser = service_cmd::register)]
        register: u16,
        /// Bytes to read (1 to 1 024).
        #[arg(default_value_t = 2, value_parser = clap::value_parser!(u16).range(1..=1024))]
        len: u16,
        #[command(flatten)]
        target: target::Target,
    },
    /// Write DATA (hex bytes, e.g. 0201) to the slave's registers from REGISTER; a running
    /// master takes it only when started with --allow-register-writes.
    Write {
        /// The slave's position on the segment, counted from 0 (as `scan` shows it).
        #[arg(allow_negative_numbers = true, value_parser = args::position)]
        position: u16,
        /// The first register (decimal or 0x hex).
        #[arg(value_parser = service_cmd::register)]
        register: u16,
        /// The bytes, as hex (in wire order: the low byte of a number first).
        data: String,
        #[command(flatten)]
        target: target::Target,
    },
}

#[derive(Subcommand)]
enum FoeCmd {
    /// Read file NAME of the slave at POSITION into FILE.
    Read {
        /// The slave's position on the segment, counted from 0 (as `scan` shows it).
        #[arg(allow_negative_numbers = true, value_parser = args::position)]
        position: u16,
        /// The file's name on the slave.
        name: String,
        /// Where to write what the slave sends.
        file: PathBuf,
        /// The password the slave asks for (a number: decimal or 0x…).
        #[arg(long, default_value = "0", allow_negative_numbers = true)]
        password: String,
        /// A longer file is an error.
        #[arg(long, default_value_t = 64 << 20)]
        max_bytes: usize,
        /// In BOOT, through the SII's bootstrap mailbox (firmware), then back to INIT.
        #[arg(long)]
        boot: bool,
        #[command(flatten)]
        target: target::Target,
    },
    /// Write FILE to the slave at POSITION as file NAME.
    Write {
        /// The slave's position on the segment, counted from 0 (as `scan` shows it).
        #[arg(allow_negative_numbers = true, value_parser = args::position)]
        position: u16,
        /// The name the file gets on the slave.
        name: String,
        /// The file to send.
        file: PathBuf,
        /// The password the slave asks for (a number: decimal or 0x…).
        #[arg(long, default_value = "0", allow_negative_numbers = true)]
        password: String,
        /// In BOOT, through the SII's bootstrap mailbox (firmware), then back to INIT.
        #[arg(long)]
        boot: bool,
        #[command(flatten)]
        target: target::Target,
    },
}

#[derive(Subcommand)]
enum EepromCmd {
    /// Read the SII of the slave at POSITION (hex dump, or --out FILE).
    Read {
        /// The slave's position on the segment, counted from 0 (as `scan` shows it).
        #[arg(allow_negative_numbers = true, value_parser = args::position)]
        position: u16,
        /// Write the image to this file (raw binary) instead of printing a hex dump.
        #[arg(long)]
        out: Option<PathBuf>,
        #[command(flatten)]
        target: target::Target,
    },
    /// Program the SII of the slave at POSITION from an image file.
    Write {
        /// The slave's position on the segment, counted from 0 (as `scan` shows it).
        #[arg(allow_negative_numbers = true, value_parser = args::position)]
        position: u16,
        /// The image to program (raw binary, Intel HEX or hex text).
        file: PathBuf,
        /// Program an image of another device (vendor or product code) than the slave's; without
        /// it such an image is refused before anything is written.
        #[arg(long)]
        overwrite_identity: bool,
        /// Where the EEPROM's contents as they were go before anything is written (default:
        /// sii-backup-slavePOS.bin in this folder, numbered where one exists).
        #[arg(long, value_name = "FILE")]
        backup: Option<PathBuf>,
        #[command(flatten)]
        target: target::Target,
    },
    /// Write a configured station alias (decimal or 0x…) into the EEPROM of the slave at
    /// POSITION, with the header checksum; the ESC takes it at its next power-on.
    Alias {
        /// The slave's position on the segment, counted from 0 (as `scan` shows it).
        #[arg(allow_negative_numbers = true, value_parser = args::position)]
        position: u16,
        /// The station alias to configure (0 to 65535, decimal or 0x…).
        alias: String,
        #[command(flatten)]
        target: target::Target,
    },
}

/// "1 slave found", "3 slaves found": a count with its noun in the right number.
pub(crate) fn count(n: usize, noun: &str, rest: &str) -> String {
    format!("{n} {noun}{} {rest}", if n == 1 { "" } else { "s" })
}

fn main() -> ExitCode {
    // Output piped into `head` and closed: end quietly as Unix tools do, not with a panic.
    // SAFETY: restoring the default disposition of SIGPIPE before any thread starts.
    unsafe {
        libc::signal(libc::SIGPIPE, libc::SIG_DFL);
    }
    let cli = Cli::parse();
    init_logging(cli.verbose, cli.quiet);
    let result = match cli.command {
        Command::Pcap { file, json } => pcap::run(&file, json),
        Command::Sii { action: None, file: Some(file), json } => sii::run(&file, json),
        Command::Sii { action: None, file: None, .. } => {
            Err(anyhow::anyhow!("give an EEPROM image file, or `sii read` / `sii write`"))
        }
        Command::Sii { action: Some(action), .. } => match action {
            EepromCmd::Read { position, out, target } => master_cmd::sii_read(&target, position, out.as_deref()),
            EepromCmd::Write { position, file, overwrite_identity, backup, target } => {
                master_cmd::sii_write(&target, position, &file, overwrite_identity, backup.as_deref())
            }
            EepromCmd::Alias { position, alias, target } => master_cmd::sii_alias(&target, position, &alias),
        },
        Command::Eni { file, json, strict } => eni::run(&file, json, strict),
        Command::Esi { file, device, sii, json, strict } => {
            esi::run(&file, device.as_deref(), sii.as_deref(), json, strict)
        }
        Command::Sim { bench: true, json, .. } => sim::bench(json),
        Command::Sim {
            config,
            eni,
            machine,
            device,
            iface,
            secondary_iface,
            udp,
            report,
            clock_log,
            seed,
            eoe_tap,
            io,
            spin_us,
            ..
        } => sim::run(sim::SimArgs {
            config,
            eni,
            machine,
            devices: device,
            iface,
            secondary_iface,
            udp,
            report,
            clock_log,
            seed,
            eoe_taps: eoe_tap,
            io,
            spin_us,
        }),
        Command::Lab { experiment } => match experiment {
            LabCmd::Park2020(a) => a.run(),
            LabCmd::Chen2016(a) => a.run(),
            LabCmd::Paprocki2022(a) => a.run(),
            LabCmd::Robustness(a) => a.run(),
            LabCmd::Run(a) => a.run(),
            LabCmd::Live(a) => lab_live::run(a),
        },
        Command::Rtt { iface, frames, slaves, force } => sim::rtt(&iface, frames, slaves, force),
        Command::Completions { shell } => {
            use clap::CommandFactory;
            clap_complete::generate(shell, &mut Cli::command(), "ferrocat", &mut std::io::stdout());
            Ok(ExitCode::SUCCESS)
        }
        Command::Manpages { dir } => manpages::write_all(&dir),
        Command::Scan { target, json, write_machine } => master_cmd::scan(&target, json, write_machine.as_deref()),
        Command::Sdo { action } => match action {
            SdoCmd::Read { position, object, complete, ty, target } => {
                master_cmd::sdo(&target, position, master_cmd::SdoAction::Read { object, complete, ty })
            }
            SdoCmd::Write { position, object, value, complete, ty, target } => {
                master_cmd::sdo(&target, position, master_cmd::SdoAction::Write { object, value, complete, ty })
            }
            SdoCmd::List { position, target } => master_cmd::sdo(&target, position, master_cmd::SdoAction::List),
        },
        Command::Soe { action } => soe_cmd::run(action),
        Command::Foe { action } => match action {
            FoeCmd::Read { position, name, file, password, max_bytes, boot, target } => {
                let action = master_cmd::FoeAction::Read { file, max_bytes };
                master_cmd::foe(&target, position, &name, &password, boot, action)
            }
            FoeCmd::Write { position, name, file, password, boot, target } => {
                master_cmd::foe(&target, position, &name, &password, boot, master_cmd::FoeAction::Write { file })
            }
        },
        Command::Eoe { action } => eoe_cmd::run(action),
        Command::Demo { drives, drive, cycle_us, method, host, seed, json, out, iface, force, no_gpio_calibration } => {
            demo::demo(demo::DemoArgs {
                drives,
                drive,
                cycles_us: cycle_us,
                methods: method,
                host,
                seed,
                json,
                out,
                iface,
                force,
                no_gpio_calibration,
            })
        }
        Command::Run {
            target,
            seconds,
            cycle_us,
            dc,
            max_rate,
            frame_timeout_us,
            dc_static_frames,
            eoe_tap,
            sync,
            sync0_shift_us,
            probe_budget_us,
            set,
            show,
            copy,
            counters_period_ms,
            txpdo_stale_ms,
            no_diagnosis,
            json,
            no_control,
            control_mode,
            control_group,
            allow_register_writes,
            mailbox_gateway,
            gateway_allow,
            gateway_rate,
            app_watchdog_ms,
            app_watchdog,
            keep_state,
        } => {
            let flags = master_cmd::DcFlags { static_frames: dc_static_frames, sync, sync0_shift_us, probe_budget_us };
            master_cmd::DcOptions::merged(&target, dc, flags).and_then(|dc| {
                let mut run = master_cmd::RunOptions {
                    diagnosis_ms: (!no_diagnosis).then_some(counters_period_ms),
                    txpdo_stale_ms,
                    set: &set,
                    show: &show,
                    copy: &copy,
                    seconds,
                    cycle_us,
                    dc,
                    max_rate,
                    frame_timeout_us,
                    eoe_taps: &eoe_tap,
                    json,
                    keep_state,
                    control: (!no_control).then_some(master_cmd::ControlOptions {
                        mode: control_mode,
                        group: control_group,
                        register_writes: allow_register_writes,
                        gateway: mailbox_gateway.map(|bind| ferrocat_service::GatewayOptions {
                            bind,
                            allow: gateway_allow,
                            rate_per_s: gateway_rate,
                            burst: (gateway_rate / 5).max(1),
                        }),
                        app_watchdog: app_watchdog_ms
                            .map(|ms| image_cmd::AppWatchdog::new(ms * 1_000_000, app_watchdog)),
                    }),
                };
                master_cmd::run(&target, &mut run)
            })
        }
        Command::Slaves { target, json } => service_cmd::slaves(&target, json),
        Command::Reg { action } => match action {
            RegCmd::Read { position, register, len, target } => service_cmd::reg_read(&target, position, register, len),
            RegCmd::Write { position, register, data, target } => {
                service_cmd::reg_write(&target, position, register, &data)
            }
        },
        Command::State { position, state, target } => service_cmd::state(&target, position, &state),
        Command::Stats { target, json } => service_cmd::stats(&target, json),
        Command::Reload { target } => service_cmd::reload(&target),
        Command::Get { names, target, json } => image_cmd::get(&target, &names, json),
        Command::Events { target, follow, json } => service_cmd::events(&target, follow, json),
        Command::Pdos { position, target, json } => service_cmd::pdos(&target, position, json),
        Command::MasterOd { target, json } => service_cmd::master_od(&target, json),
        Command::Set { values, target } => image_cmd::set(&target, &values),
    };
    match result {
        Ok(code) => code,
        Err(e) => {
            eprintln!("ferrocat: error: {e:#}");
            ExitCode::FAILURE
        }
    }
}

/// A file mode in octal (e.g. 660).
fn parse_mode(s: &str) -> Result<u32, String> {
    match u32::from_str_radix(s.trim().trim_start_matches("0o"), 8) {
        Ok(m) if m <= 0o777 => Ok(m),
        _ => Err(format!("'{s}' is not a file mode (octal, 000 to 777, e.g. 660)")),
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

#[cfg(test)]
mod tests {
    use clap::CommandFactory;

    /// Every option and argument of every subcommand says what it means (the man pages are
    /// made from these), as linuxptp's pages do for every setting.
    #[test]
    fn every_argument_has_its_meaning() {
        fn walk(cmd: &clap::Command, path: String, missing: &mut Vec<String>) {
            for a in cmd.get_arguments() {
                let id = a.get_id().as_str();
                if id == "help" || id == "version" {
                    continue;
                }
                if a.get_help().is_none() && a.get_long_help().is_none() {
                    missing.push(format!("{path} {id}"));
                }
            }
            for s in cmd.get_subcommands() {
                walk(s, format!("{path} {}", s.get_name()), missing);
            }
        }
        // clap's own consistency checks first (a short flag given twice, a global clash).
        super::Cli::command().debug_assert();
        let mut missing = Vec::new();
        walk(&super::Cli::command(), "ferrocat".into(), &mut missing);
        assert!(missing.is_empty(), "{} without help:\n{}", missing.len(), missing.join("\n"));
    }
}
