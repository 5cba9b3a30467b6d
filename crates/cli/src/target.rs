//! Where a master command talks to: a real interface, or the embedded virtual segment.
use std::fs::File;
use std::io::BufWriter;
use std::path::{Path, PathBuf};
use std::time::Duration;

use anyhow::{bail, Context};
use clap::Args;
use ferrocat_capture::{CaptureWriter, Format};
use ferrocat_master::io::{Io, RawIo, UdpIo};
use ferrocat_master::Master;
use ferrocat_segment::{HostModel, VirtualIo};

#[derive(Args, Debug, Clone)]
pub struct Target {
    /// Network interface with the EtherCAT segment (raw socket; needs CAP_NET_RAW).
    #[arg(long, conflicts_with_all = ["config", "device"])]
    pub iface: Option<String>,
    /// With --iface: the master's second port, where the segment's far end comes back (cable
    /// redundancy).
    #[arg(long, requires = "iface", value_name = "IF")]
    pub secondary_iface: Option<String>,
    /// On a broken ring, how the far half gets its clock: from its first DC slave, kept on the
    /// reference's time by the master (far-reference), the same left to hold its rate
    /// (far-reference-held), every far clock on its own (hold-over), or the reference's time
    /// of the first pass, as SOEM sends it (as-sent).
    #[arg(long, value_enum, default_value = "far-reference")]
    pub split_ring_clocks: SplitClocks,
    /// EtherCAT over UDP to this address (e.g. 127.0.0.1:34980).
    #[arg(long, value_name = "ADDR:PORT", conflicts_with_all = ["iface", "config", "device"])]
    pub udp: Option<String>,
    /// Send even on an interface that has an IPv4 or a global IPv6 address.
    #[arg(long, requires = "iface")]
    pub force: bool,
    /// With --iface: how frames move. io_uring sends a cycle's frames and waits for the answer
    /// in one system call; socket makes a sendto per frame, a read of the transmit stamp, a
    /// ppoll until the answer and a recvmsg of it; ring maps a PACKET_MMAP receive ring and spins on it for the answer
    /// (--spin-us) before it sleeps, a sendto per frame and no call to receive, holding the CPU
    /// while it spins (for a core of the master's own); auto takes io_uring where the kernel
    /// allows it (a cable-redundant pair always uses socket calls).
    #[arg(long, value_enum, default_value = "auto", requires = "iface")]
    pub io: IoPath,
    /// With --io ring: how long a receive spins on the ring before it sleeps, in µs. The spin
    /// holds the CPU; an answer that comes within it costs no system call.
    #[arg(long, value_name = "US", default_value_t = ferrocat_link::DEFAULT_RING_SPIN_NS / 1000, requires = "iface")]
    pub spin_us: u64,
    /// Use the embedded virtual segment described by this file.
    #[arg(long, value_name = "SEG.toml")]
    pub config: Option<PathBuf>,
    /// Use an embedded virtual line of these devices (EEPROM dump, ESI:PRODUCT, a modular
    /// device's ESI:PRODUCT:MODULE,MODULE…, or built-in name).
    #[arg(long, value_name = "FILE[:PRODUCT[:MODULES]]")]
    pub device: Vec<String>,
    /// Seed of the virtual segment.
    #[arg(long)]
    pub seed: Option<u64>,
    /// ESI files describing the slaves (their PDOs are used where CoE and the SII say nothing).
    #[arg(long, value_name = "FILE")]
    pub esi: Vec<PathBuf>,
    /// Write every frame sent and received to this pcapng file.
    #[arg(long, value_name = "FILE")]
    pub pcap: Option<PathBuf>,
    /// The expected network, as an ENI file (ETG.2100) describes it: after the scan, before any
    /// slave leaves INIT, every slave's identity is compared with the file's and any difference
    /// (missing, extra, swapped, another device or revision) is an error. Without --iface,
    /// --udp, --config or --device, the embedded virtual segment is the file's network.
    #[arg(long, value_name = "FILE", conflicts_with = "machine")]
    pub eni: Option<PathBuf>,
    /// The expected network, as a ferrocat machine description (TOML, docs/machine.md)
    /// describes it: checked as with --eni. Without --iface, --udp, --config or --device, the
    /// embedded virtual segment serves each slave's `device`.
    #[arg(long, value_name = "FILE")]
    pub machine: Option<PathBuf>,
    /// With --eni or --machine: report the differences and go on.
    #[arg(long)]
    pub allow_mismatch: bool,
    /// The control socket of a master running on this target: `run` serves it there, and the
    /// other commands reach that master through it. Default: IF.sock (--iface) or
    /// udp-ADDR:PORT.sock (--udp) in /run/ferrocat for root ($FERROCAT_RUN_DIR,
    /// $XDG_RUNTIME_DIR/ferrocat or /tmp/ferrocat-UID otherwise); on the embedded virtual
    /// segment, none unless given.
    #[arg(long, value_name = "PATH")]
    pub control_socket: Option<PathBuf>,
    /// The --eni file and the --machine description, read once, by whichever step asks first.
    #[arg(skip)]
    pub(crate) loaded_eni: std::cell::OnceCell<ferrocat_machine::eni::Eni>,
    #[arg(skip)]
    pub(crate) loaded_machine: std::cell::OnceCell<ferrocat_machine::Machine>,
    /// The segment's lock, held while this process works on it.
    #[arg(skip)]
    pub(crate) lock: std::cell::OnceCell<std::rc::Rc<ferrocat_service::MasterLock>>,
}

/// [`ferrocat_master::io::LinkPath`] on the command line.
#[derive(clap::ValueEnum, Debug, Clone, Copy, PartialEq, Eq)]
pub enum IoPath {
    Auto,
    Uring,
    Socket,
    Ring,
}

impl IoPath {
    /// The master's link path, a ring spinning `spin_us` in each receive.
    pub fn link_path(self, spin_us: u64) -> ferrocat_master::io::LinkPath {
        use ferrocat_master::io::LinkPath;
        match self {
            IoPath::Auto => LinkPath::Auto,
            IoPath::Uring => LinkPath::Uring,
            IoPath::Socket => LinkPath::Socket,
            IoPath::Ring => LinkPath::Ring { spin_ns: spin_us.saturating_mul(1000) },
        }
    }
}

/// [`ferrocat_master::SplitRingClocks`] on the command line.
#[derive(clap::ValueEnum, Debug, Clone, Copy, PartialEq, Eq)]
pub enum SplitClocks {
    FarReference,
    FarReferenceHeld,
    HoldOver,
    AsSent,
}

impl From<SplitClocks> for ferrocat_master::SplitRingClocks {
    fn from(c: SplitClocks) -> Self {
        match c {
            SplitClocks::FarReference => Self::FarReference,
            SplitClocks::FarReferenceHeld => Self::FarReferenceHeld,
            SplitClocks::HoldOver => Self::HoldOver,
            SplitClocks::AsSent => Self::AsSent,
        }
    }
}

enum World {
    Virtual(Box<VirtualIo>),
    Raw(RawIo),
    Udp(UdpIo),
}

/// The master's I/O for the CLI: a virtual or a raw world, optionally recorded to pcapng.
pub struct CliIo {
    world: World,
    capture: Option<CaptureWriter<BufWriter<File>>>,
}

impl std::fmt::Debug for CliIo {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.write_str(match self.world {
            World::Virtual(_) => "CliIo(virtual)",
            World::Raw(_) => "CliIo(raw)",
            World::Udp(_) => "CliIo(udp)",
        })
    }
}

impl CliIo {
    fn record(&mut self, t_ns: u64, frame: &[u8]) {
        if let Some(c) = &mut self.capture {
            let _ = c.write(Duration::from_nanos(t_ns), frame);
        }
    }
    pub fn is_virtual(&self) -> bool {
        matches!(self.world, World::Virtual(_))
    }
    /// On the embedded virtual segment, the true system time of the slave at `station` when
    /// the world's clock reads `t_ns`: what only the simulator knows.
    pub fn true_system_time(&self, station: u16, t_ns: u64) -> Option<u64> {
        let World::Virtual(v) = &self.world else { return None };
        let node = v.seg.nodes.iter().find(|n| n.esc.station_address() == station)?;
        Some(node.esc.dc.as_ref()?.system_at(t_ns))
    }
    /// Which timestamps the link gives, in words.
    pub fn timestamps(&self) -> &'static str {
        match &self.world {
            World::Virtual(_) => "exact virtual time",
            World::Raw(r) => r.timestamps(),
            World::Udp(_) => "no kernel timestamps (UDP)",
        }
    }
    /// How frames move, in words.
    pub fn path(&self) -> &'static str {
        match &self.world {
            World::Virtual(_) => "the embedded virtual segment",
            World::Raw(r) => r.path(),
            World::Udp(_) => "UDP socket calls",
        }
    }
}

impl CliIo {
    /// The world underneath, for the calls that only pass through.
    fn io(&self) -> &dyn Io {
        match &self.world {
            World::Virtual(v) => &**v,
            World::Raw(r) => r,
            World::Udp(u) => u,
        }
    }
    fn io_mut(&mut self) -> &mut dyn Io {
        match &mut self.world {
            World::Virtual(v) => &mut **v,
            World::Raw(r) => r,
            World::Udp(u) => u,
        }
    }
}

/// Every call passes through to the world; frames are recorded on their way.
impl Io for CliIo {
    fn now_ns(&mut self) -> u64 {
        self.io_mut().now_ns()
    }
    fn send(&mut self, frame: &[u8]) -> std::io::Result<()> {
        let t = self.now_ns();
        self.record(t, frame);
        self.io_mut().send(frame)
    }
    fn has_secondary(&self) -> bool {
        self.io().has_secondary()
    }
    fn send_secondary(&mut self, frame: &[u8]) -> std::io::Result<()> {
        let t = self.now_ns();
        self.record(t, frame);
        self.io_mut().send_secondary(frame)
    }
    fn last_rx_secondary(&self) -> bool {
        self.io().last_rx_secondary()
    }
    fn recv(&mut self, buf: &mut [u8], deadline_ns: u64) -> std::io::Result<Option<(usize, u64)>> {
        let r = self.io_mut().recv(buf, deadline_ns)?;
        if let Some((n, t)) = r {
            self.record(t, &buf[..n]);
        }
        Ok(r)
    }
    fn sleep_until(&mut self, t_ns: u64) {
        self.io_mut().sleep_until(t_ns)
    }
    fn wake_target_ns(&self) -> Option<u64> {
        self.io().wake_target_ns()
    }
    fn is_virtual(&self) -> bool {
        self.io().is_virtual()
    }
    fn timer_resolution_ns(&self) -> u64 {
        self.io().timer_resolution_ns()
    }
    fn last_tx_ns(&mut self) -> Option<u64> {
        self.io_mut().last_tx_ns()
    }
    fn last_tx_secondary_ns(&mut self) -> Option<u64> {
        self.io_mut().last_tx_secondary_ns()
    }
}

/// The lab reads the true clocks of the embedded segment; a real link has none.
impl ferrocat_lab::World for CliIo {
    fn segment(&self) -> Option<&ferrocat_segment::Segment> {
        match &self.world {
            World::Virtual(v) => Some(&v.seg),
            _ => None,
        }
    }
    fn segment_mut(&mut self) -> Option<&mut ferrocat_segment::Segment> {
        match &mut self.world {
            World::Virtual(v) => Some(&mut v.seg),
            _ => None,
        }
    }
}

impl Target {
    /// A real interface, one port, everything else as the flags' defaults.
    pub fn on_iface(iface: &str, force: bool) -> Self {
        Target {
            iface: Some(iface.to_string()),
            secondary_iface: None,
            split_ring_clocks: SplitClocks::FarReference,
            udp: None,
            force,
            io: IoPath::Auto,
            spin_us: ferrocat_link::DEFAULT_RING_SPIN_NS / 1000,
            config: None,
            device: Vec::new(),
            seed: None,
            esi: Vec::new(),
            pcap: None,
            eni: None,
            machine: None,
            allow_mismatch: false,
            control_socket: None,
            loaded_eni: Default::default(),
            loaded_machine: Default::default(),
            lock: Default::default(),
        }
    }

    /// Opens the world this target names and a master on it.
    pub fn master(&self) -> anyhow::Result<Master<CliIo>> {
        self.take_segment()?;
        let world = match (&self.iface, self.config.is_some() || !self.device.is_empty()) {
            _ if self.udp.is_some() => {
                let a = self.udp.as_deref().unwrap_or_default();
                World::Udp(UdpIo::open(a).with_context(|| format!("UDP to {a}"))?)
            }
            (Some(iface), false) => {
                // One interface as both ports would take each frame back as the ring's far
                // end: a ring "open" that is no ring.
                if self.secondary_iface.as_deref() == Some(iface.as_str()) {
                    bail!(
                        "--secondary-iface {iface} is --iface itself: cable redundancy takes the master's second \
                         port, where the segment's far end comes back"
                    );
                }
                check_iface(iface, self.force)?;
                match &self.secondary_iface {
                    Some(sec) => World::Raw(
                        RawIo::open_redundant(iface, sec)
                            .with_context(|| format!("opening {iface} and {sec}"))
                            .map_err(|e| crate::words::opening(iface, e))?,
                    ),
                    None => World::Raw(
                        RawIo::open_with(iface, self.io.link_path(self.spin_us))
                            .with_context(|| format!("opening {iface}"))
                            .map_err(|e| crate::words::opening(iface, e))?,
                    ),
                }
            }
            (None, true) => {
                let seg = crate::sim::segment_from(self.config.as_deref(), &self.device, self.seed)?;
                World::Virtual(Box::new(VirtualIo::new(seg, HostModel::pc_rt(), self.seed.unwrap_or(0))))
            }
            (None, false) if self.eni.is_some() => {
                let path = self.eni.as_deref().unwrap_or(Path::new(""));
                let mut cfg = ferrocat_segment::SegmentConfig::from_eni(path)?;
                cfg.seed = self.seed.unwrap_or(0);
                World::Virtual(Box::new(VirtualIo::new(cfg.build()?, HostModel::pc_rt(), self.seed.unwrap_or(0))))
            }
            (None, false) if self.machine.is_some() => {
                let path = self.machine.as_deref().unwrap_or(Path::new(""));
                let cfg = crate::sim::machine_segment(path, self.seed)?;
                World::Virtual(Box::new(VirtualIo::new(cfg.build()?, HostModel::pc_rt(), self.seed.unwrap_or(0))))
            }
            _ => bail!("give --iface IF, --udp ADDR:PORT, or --config SEG.toml / --device FILE / --eni FILE / --machine FILE for the embedded virtual segment"),
        };
        let capture = match &self.pcap {
            Some(p) => {
                let f = File::create(p).with_context(|| format!("creating {}", p.display()))?;
                Some(CaptureWriter::new(BufWriter::new(f), Format::PcapNg)?)
            }
            None => None,
        };
        let mut m = Master::new(CliIo { world, capture });
        m.dc().set_split_ring_clocks(self.split_ring_clocks.into());
        // A machine description's process-data groups.
        if let Some(d) = self.machine_file()? {
            m.config().set_groups(
                d.groups
                    .iter()
                    .map(|g| ferrocat_master::Group {
                        name: g.name.clone(),
                        positions: g.positions.clone(),
                        every: g.every,
                    })
                    .collect(),
            );
        }
        // An ENI's own layout: its station addresses, FMMUs, SyncManagers and cyclic frames.
        if let (Some(eni), Some(p)) = (self.eni_file()?, &self.eni) {
            m.config().set_plan(crate::eni::plan(eni)).with_context(|| format!("{}", p.display()))?;
        }
        for f in &self.esi {
            let xml = ferrocat_segment::files::read_esi(f).with_context(|| format!("reading {}", f.display()))?;
            let file = ferrocat_esi::EsiFile::parse(&xml).with_context(|| format!("{}", f.display()))?;
            for d in file.devices {
                m.config().add_esi(file.vendor_id, d);
            }
        }
        Ok(m)
    }

    /// The --eni file, read (its warnings shown) once.
    pub fn eni_file(&self) -> anyhow::Result<Option<&ferrocat_machine::eni::Eni>> {
        let Some(p) = &self.eni else { return Ok(None) };
        if self.loaded_eni.get().is_none() {
            let _ = self.loaded_eni.set(crate::eni::read(p, false)?);
        }
        Ok(self.loaded_eni.get())
    }

    /// The --machine description, read once.
    pub fn machine_file(&self) -> anyhow::Result<Option<&ferrocat_machine::Machine>> {
        let Some(p) = &self.machine else { return Ok(None) };
        if self.loaded_machine.get().is_none() {
            let _ = self.loaded_machine.set(crate::eni::read_machine(p)?);
        }
        Ok(self.loaded_machine.get())
    }

    /// Scans, and with --eni or --machine compares the network found with the file's before
    /// any slave leaves INIT.
    /// Where the frames go, for messages.
    pub fn place(&self) -> crate::words::Place<'_> {
        match (&self.udp, &self.iface) {
            (Some(a), _) => crate::words::Place::Udp(a),
            (None, Some(i)) if self.config.is_none() && self.device.is_empty() => crate::words::Place::Iface(i),
            _ => crate::words::Place::Virtual,
        }
    }

    /// The master's configuration to PREOP, and a machine description's PDO assignments
    /// (`rx_pdos`, `tx_pdos`) in place of the slaves' own.
    pub fn configure(&self, m: &mut Master<CliIo>) -> anyhow::Result<()> {
        m.states().configure()?;
        let (Some(d), Some(path)) = (self.machine_file()?, &self.machine) else { return Ok(()) };
        let found = m.slaves().len();
        for (k, s) in d.slaves.iter().enumerate().filter(|(k, _)| *k < found) {
            for (outputs, pdos) in [(true, &s.rx_pdos), (false, &s.tx_pdos)] {
                if let Some(pdos) = pdos {
                    m.config().remap(k as u16, outputs, pdos).with_context(|| {
                        format!(
                            "{}: slave {k} ({})'s {}",
                            path.display(),
                            s.name,
                            if outputs { "rx_pdos" } else { "tx_pdos" }
                        )
                    })?;
                }
            }
        }
        Ok(())
    }

    pub fn scan(&self, m: &mut Master<CliIo>) -> anyhow::Result<()> {
        let expected = match (self.eni_file()?, self.machine_file()?, &self.eni, &self.machine) {
            (Some(e), _, Some(p), _) => Some((p, e.expected())),
            (None, Some(d), _, Some(p)) => Some((p, d.expected())),
            _ => None,
        };
        if self.allow_mismatch && expected.is_none() {
            bail!("--allow-mismatch goes with --eni or --machine");
        }
        m.states().scan().map_err(|e| crate::words::first_contact(self.place(), e.into()))?;
        if let Some((path, expected)) = expected {
            crate::eni::check(path, &expected, m.slaves(), self.allow_mismatch)?;
        }
        // A machine description's process-data watchdogs, before any output SM is enabled.
        if let (Some(d), Some(path)) = (self.machine_file()?, &self.machine) {
            let found = m.slaves().len();
            for (k, s) in d.slaves.iter().enumerate().filter(|(k, _)| *k < found) {
                if let Some(us) = s.watchdog_us {
                    m.config()
                        .set_process_data_watchdog(k as u16, us as u64 * 1000)
                        .with_context(|| format!("{}: slave {k} ({})'s watchdog_us", path.display(), s.name))?;
                }
                let setup = m.config().setup_mut(k as u16)?;
                setup.init_cmds = s.init.clone();
                setup.modules = s.modules.clone();
            }
        }
        Ok(())
    }
}

/// Refuses an interface with an IPv4 or a global IPv6 address unless `force`: EtherCAT
/// broadcasts do not belong on an office LAN. Every command that sends frames asks this.
pub fn check_iface(iface: &str, force: bool) -> anyhow::Result<()> {
    let addrs =
        ferrocat_link::routable_addresses(iface).with_context(|| format!("reading the addresses of {iface}"))?;
    if !addrs.is_empty() && !force {
        bail!(
            "{iface} has address(es) {}: EtherCAT broadcasts do not belong on an office LAN (use --force to send anyway)",
            addrs.join(", ")
        );
    }
    Ok(())
}

/// Flushes the pcap file, if any.
pub fn finish(m: Master<CliIo>) -> anyhow::Result<()> {
    if let Some(c) = m.into_io().capture {
        use std::io::Write;
        c.into_inner().flush()?;
    }
    Ok(())
}

/// Real-time set-up for a master on a real network (SCHED_FIFO 80, CPU 1, memory locked),
/// reported on stderr with whatever the system refused.
pub fn go_real_time() {
    let rt = ferrocat_link::real_time(80, Some(1));
    eprintln!(
        "real time: memory {}, {}, {}{}",
        if rt.memory_locked { "locked" } else { "not locked" },
        rt.fifo_priority.map_or(String::from("normal scheduling"), |p| format!("SCHED_FIFO priority {p}")),
        rt.cpu.map_or(String::from("any CPU"), |c| format!("CPU {c}")),
        if rt.refused.is_empty() { String::new() } else { format!(" (refused: {})", rt.refused.join("; ")) }
    );
}
