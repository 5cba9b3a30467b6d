//! The two worlds the master runs in, behind one small trait: virtual time with the in-process
//! segment and a model of the host, or real time on a network interface.
use ferrocat_segment::{MasterPort, Segment};
use rand::{Rng, SeedableRng};
use rand_chacha::ChaCha8Rng;
use rand_distr::{Distribution, Normal};

mod tamper;
pub use tamper::Tamper;

/// Time and frames. All times are ns of the world's clock (CLOCK_MONOTONIC in real time).
pub trait Io {
    fn now_ns(&mut self) -> u64;
    /// Sends one Ethernet frame (without FCS).
    fn send(&mut self, frame: &[u8]) -> std::io::Result<()>;
    /// The next received frame, waiting until `deadline_ns` at most: its length and receive time.
    fn recv(&mut self, buf: &mut [u8], deadline_ns: u64) -> std::io::Result<Option<(usize, u64)>>;
    /// Sleeps until `t_ns` (absolute); the world may wake late.
    fn sleep_until(&mut self, t_ns: u64);
    /// The instant the last [`Io::sleep_until`] aimed at: where a caller sleeps to its
    /// schedule, the planned start of the cycle that woke (however late it woke).
    fn wake_target_ns(&self) -> Option<u64> {
        None
    }
    /// When the last frame sent actually left, if the world knows (a kernel or NIC timestamp).
    fn last_tx_ns(&mut self) -> Option<u64> {
        None
    }
    /// Receive times mark the start of the frame (a NIC stamp) rather than its end.
    fn rx_stamps_start_of_frame(&self) -> bool {
        false
    }
    /// Virtual time (deterministic) rather than a real clock.
    fn is_virtual(&self) -> bool {
        false
    }
    /// The in-process segment when the world is virtual: what only a simulator can measure
    /// (true clocks, what each device saw).
    fn segment(&self) -> Option<&Segment> {
        None
    }
    fn segment_mut(&mut self) -> Option<&mut Segment> {
        None
    }
    /// The granularity of the host's timer: a master that follows a clock rounds its periods
    /// to it (Chen 2016's Algorithm 1).
    fn timer_resolution_ns(&self) -> u64 {
        1
    }
    /// The master has a second port (cable redundancy): the segment is a ring, closed back to
    /// it, and the engine sends through both.
    fn has_secondary(&self) -> bool {
        false
    }
    /// Sends one Ethernet frame from the secondary port.
    fn send_secondary(&mut self, _frame: &[u8]) -> std::io::Result<()> {
        Err(std::io::Error::new(std::io::ErrorKind::Unsupported, "this link has no secondary port"))
    }
    /// Whether the frame the last [`Io::recv`] returned came in on the secondary port.
    fn last_rx_secondary(&self) -> bool {
        false
    }
    /// [`Io::last_tx_ns`] of the secondary port.
    fn last_tx_secondary_ns(&mut self) -> Option<u64> {
        None
    }
    /// Drives the host's calibration output (a GPIO wired to a slave's LATCH input) to
    /// `level`; the pin changes one output latency after the call. Unsupported where the host
    /// has no such output or nothing is wired to it.
    fn set_gpio(&mut self, _level: bool) -> std::io::Result<()> {
        Err(std::io::Error::new(std::io::ErrorKind::Unsupported, "this host has no calibration output"))
    }
}

/// A latency distribution: normal, clipped below, with rare outliers.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Latency {
    pub mean_ns: f64,
    pub sd_ns: f64,
    pub min_ns: f64,
    /// Probability of an outlier, and its extra delay (uniform up to this).
    pub outlier_p: f64,
    pub outlier_ns: f64,
}

impl Latency {
    pub const ZERO: Latency = Latency { mean_ns: 0.0, sd_ns: 0.0, min_ns: 0.0, outlier_p: 0.0, outlier_ns: 0.0 };

    pub fn fixed(ns: f64) -> Self {
        Latency { mean_ns: ns, min_ns: ns, ..Latency::ZERO }
    }

    pub fn sample(&self, rng: &mut ChaCha8Rng) -> u64 {
        let mut v = if self.sd_ns > 0.0 {
            Normal::new(self.mean_ns, self.sd_ns).map(|n| n.sample(rng)).unwrap_or(self.mean_ns)
        } else {
            self.mean_ns
        };
        if self.outlier_p > 0.0 && rng.gen_bool(self.outlier_p.clamp(0.0, 1.0)) {
            v += rng.gen_range(0.0..=self.outlier_ns.max(0.0));
        }
        v.max(self.min_ns).max(0.0) as u64
    }
}

/// How long the master's own host takes: to hand a frame to the wire, to deliver a received
/// frame to the master, and how late its timer wakes it.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct HostModel {
    pub name: &'static str,
    pub send: Latency,
    pub recv: Latency,
    pub wake: Latency,
    /// What the link tells about when frames really left and arrived.
    pub stamps: Stamps,
    /// The timer wakes only on multiples of this (0: any ns), as RTX's 10 µs timer in Chen 2016.
    pub timer_resolution_ns: u64,
    /// A general-purpose output, and how long after the program writes it its pin changes
    /// (None: the host has none).
    pub gpio: Option<Latency>,
}

/// Timestamps the link gives the master.
#[derive(Debug, Clone, Copy, PartialEq)]
pub enum Stamps {
    /// None: the master knows only when it handed a frame over and when it had the reply.
    None,
    /// The kernel's (SO_TIMESTAMPING software): transmit taken this long before the frame
    /// leaves, receive this long after its last byte arrived.
    Software { tx_early: Latency, rx_late: Latency },
    /// The NIC's: the start of each frame, both ways, exactly.
    Hardware,
}

impl HostModel {
    /// No host at all: frames leave and arrive instantly, timers are exact.
    pub fn ideal() -> Self {
        HostModel {
            name: "ideal",
            send: Latency::ZERO,
            recv: Latency::ZERO,
            wake: Latency::ZERO,
            stamps: Stamps::None,
            timer_resolution_ns: 0,
            gpio: None,
        }
    }

    /// A PC with a PREEMPT_RT kernel and a raw socket: a few µs through the stack, timer
    /// latency of a few µs with rare tens of µs.
    pub fn pc_rt() -> Self {
        HostModel {
            name: "pc-rt",
            send: Latency { mean_ns: 4_000.0, sd_ns: 1_000.0, min_ns: 2_000.0, outlier_p: 0.001, outlier_ns: 20_000.0 },
            recv: Latency { mean_ns: 5_000.0, sd_ns: 1_500.0, min_ns: 2_500.0, outlier_p: 0.001, outlier_ns: 20_000.0 },
            wake: Latency { mean_ns: 3_000.0, sd_ns: 1_500.0, min_ns: 1_000.0, outlier_p: 0.001, outlier_ns: 30_000.0 },
            stamps: Stamps::Software {
                tx_early: Latency { mean_ns: 1_000.0, sd_ns: 300.0, min_ns: 400.0, ..Latency::ZERO },
                rx_late: Latency { mean_ns: 1_500.0, sd_ns: 400.0, min_ns: 500.0, ..Latency::ZERO },
            },
            timer_resolution_ns: 0,
            gpio: Some(HostModel::PARALLEL_PORT),
        }
    }

    /// `pc_rt` with a NIC that stamps each frame's departure and arrival in hardware.
    pub fn nic_hwts() -> Self {
        HostModel { name: "nic-hwts", stamps: Stamps::Hardware, ..HostModel::pc_rt() }
    }

    /// A stock (non-RT) kernel: tens of µs through the stack and timer, rare hundreds.
    pub fn pc_stock() -> Self {
        HostModel {
            name: "pc-stock",
            send: Latency {
                mean_ns: 15_000.0,
                sd_ns: 6_000.0,
                min_ns: 5_000.0,
                outlier_p: 0.01,
                outlier_ns: 200_000.0,
            },
            recv: Latency {
                mean_ns: 20_000.0,
                sd_ns: 8_000.0,
                min_ns: 6_000.0,
                outlier_p: 0.01,
                outlier_ns: 200_000.0,
            },
            wake: Latency {
                mean_ns: 50_000.0,
                sd_ns: 25_000.0,
                min_ns: 5_000.0,
                outlier_p: 0.01,
                outlier_ns: 500_000.0,
            },
            stamps: Stamps::Software {
                tx_early: Latency {
                    mean_ns: 2_000.0,
                    sd_ns: 1_000.0,
                    min_ns: 500.0,
                    outlier_p: 0.01,
                    outlier_ns: 50_000.0,
                },
                rx_late: Latency {
                    mean_ns: 3_000.0,
                    sd_ns: 1_500.0,
                    min_ns: 500.0,
                    outlier_p: 0.01,
                    outlier_ns: 50_000.0,
                },
            },
            timer_resolution_ns: 0,
            // The same port, but the process may be preempted between reading its clock and
            // writing the pin.
            gpio: Some(Latency { outlier_p: 0.01, outlier_ns: 200_000.0, ..HostModel::PARALLEL_PORT }),
        }
    }

    /// The BeagleBone Green of Park 2020 (AM335x, RT kernel 4.9). Its send delay is the one
    /// free parameter, set so that `conventional`'s master–reference bias comes out at the
    /// paper's 10.6 µs. The bias is the send delay plus the wire to the reference (the master
    /// link, 0.5 µs in the segment model), less what the reference's time control loop makes
    /// of this much send jitter (measured: about −0.6 µs), so the send delay's mean is 10.7 µs.
    pub fn beaglebone_rt() -> Self {
        HostModel {
            name: "beaglebone-rt",
            send: Latency {
                mean_ns: 10_700.0,
                sd_ns: 2_500.0,
                min_ns: 5_000.0,
                outlier_p: 0.002,
                outlier_ns: 40_000.0,
            },
            recv: Latency {
                mean_ns: 12_000.0,
                sd_ns: 3_000.0,
                min_ns: 6_000.0,
                outlier_p: 0.002,
                outlier_ns: 40_000.0,
            },
            wake: Latency {
                mean_ns: 10_000.0,
                sd_ns: 4_000.0,
                min_ns: 3_000.0,
                outlier_p: 0.002,
                outlier_ns: 60_000.0,
            },
            stamps: Stamps::Software {
                tx_early: Latency { mean_ns: 2_000.0, sd_ns: 600.0, min_ns: 800.0, ..Latency::ZERO },
                rx_late: Latency { mean_ns: 3_000.0, sd_ns: 800.0, min_ns: 1_000.0, ..Latency::ZERO },
            },
            timer_resolution_ns: 0,
            // An AM335x GPIO register written through a mapping from the RT thread: a posted
            // write over the L4 interconnect, a few hundred ns (assumed; measure it with a scope).
            gpio: Some(Latency { mean_ns: 300.0, sd_ns: 40.0, min_ns: 200.0, outlier_p: 0.002, outlier_ns: 40_000.0 }),
        }
    }

    /// Chen 2016's master: Windows with the RTX real-time extension, its timer set to a 10 µs
    /// resolution (their §5.2), latencies as a PC with an RT kernel.
    pub fn rtx_10us() -> Self {
        HostModel { name: "rtx-10us", timer_resolution_ns: 10_000, stamps: Stamps::None, ..HostModel::pc_rt() }
    }

    /// A PC's calibration output: a parallel-port data pin written with `outb`, about 1 µs
    /// per ISA-style I/O cycle (assumed; measure it with a scope), rarely delayed by an
    /// interrupt between the clock read and the write.
    pub const PARALLEL_PORT: Latency =
        Latency { mean_ns: 1_000.0, sd_ns: 100.0, min_ns: 700.0, outlier_p: 0.001, outlier_ns: 20_000.0 };

    /// The presets by name, for the command line and scenarios.
    pub const PRESETS: [&'static str; 6] = ["ideal", "pc-rt", "pc-stock", "nic-hwts", "beaglebone-rt", "rtx-10us"];

    pub fn preset(name: &str) -> Option<Self> {
        Some(match name {
            "ideal" => HostModel::ideal(),
            "pc-rt" => HostModel::pc_rt(),
            "pc-stock" => HostModel::pc_stock(),
            "nic-hwts" => HostModel::nic_hwts(),
            "beaglebone-rt" => HostModel::beaglebone_rt(),
            "rtx-10us" => HostModel::rtx_10us(),
            _ => return None,
        })
    }
}

/// The virtual world: the in-process segment, a virtual clock, and the host model.
#[derive(Debug)]
pub struct VirtualIo {
    pub seg: Segment,
    pub host: HostModel,
    now: u64,
    seed: u64,
    /// The host's randomness. Before [`VirtualIo::start_cycles`] one stream; after it, each
    /// cycle slot of the master's schedule has its own for its wake-up and its first frame
    /// (send, stamps, delivery), and every other frame (a method's probes) draws from the
    /// common one: methods that send more frames, or sleep through a cycle, still meet the
    /// same host in every slot — a paired comparison.
    rng: ChaCha8Rng,
    slot_rng: ChaCha8Rng,
    cycles: Option<CycleSlots>,
    woke: bool,
    /// Frames on their way back: (time the master has them, length, bytes, in flight).
    /// Preallocated.
    slots: Vec<(u64, usize, Box<[u8; 1536]>, bool)>,
    /// Per slot: the frame comes back on the secondary port.
    slot_secondary: [bool; 32],
    last_rx_secondary: bool,
    /// Frames the segment did not return.
    pub lost: u64,
    last_tx: Option<u64>,
    last_tx_secondary: Option<u64>,
    /// The NIC's receive stamp of the frame in each slot.
    rx_stamps: [u64; 32],
    /// Where the host's calibration output is wired: (segment node, LATCH unit).
    pub gpio_wire: Option<(usize, u8)>,
    /// The output's latencies have their own stream, so that pulsing it leaves the frames'
    /// latencies as they would have been.
    gpio_rng: ChaCha8Rng,
    wake_target_ns: Option<u64>,
}

impl VirtualIo {
    pub fn new(seg: Segment, host: HostModel, seed: u64) -> Self {
        VirtualIo {
            seg,
            host,
            now: 0,
            seed,
            rng: ChaCha8Rng::seed_from_u64(seed ^ 0x4057),
            // Replaced at every slot; never drawn from before the first.
            slot_rng: ChaCha8Rng::seed_from_u64(seed ^ 0x5C1C),
            cycles: None,
            woke: false,
            slots: (0..32).map(|_| (0, 0, Box::new([0u8; 1536]), false)).collect(),
            slot_secondary: [false; 32],
            last_rx_secondary: false,
            lost: 0,
            last_tx: None,
            last_tx_secondary: None,
            rx_stamps: [0; 32],
            gpio_wire: None,
            gpio_rng: ChaCha8Rng::seed_from_u64(seed ^ 0x6710),
            wake_target_ns: None,
        }
    }
}

/// The master's cycle slots, counted from [`VirtualIo::start_cycles`].
#[derive(Debug, Clone, Copy)]
struct CycleSlots {
    cycle_ns: u64,
    slot: u64,
    last_target_ns: Option<u64>,
}

impl VirtualIo {
    /// Cyclic operation of `cycle_ns` begins: from here each wake-up is counted into the slots
    /// of that cycle (a wake-up two cycles after the last is two slots on), and a slot's
    /// wake-up and first frame draw from that slot's own stream. The labs call it where their
    /// cyclic phase begins, so that every method meets the same host there, whatever its
    /// bring-up did (Park's 1 000 round trips, a calibration) and however many extra frames
    /// it sends.
    pub fn start_cycles(&mut self, cycle_ns: u64) {
        self.cycles = Some(CycleSlots { cycle_ns: cycle_ns.max(1), slot: 0, last_target_ns: None });
        self.rng = ChaCha8Rng::seed_from_u64(self.seed.rotate_left(17) ^ 0x4057);
        self.woke = false;
    }
}

impl VirtualIo {
    /// A frame from either of the master's ports, through the host's send path.
    fn send_on(&mut self, port: MasterPort, frame: &[u8]) -> std::io::Result<()> {
        let rng = if std::mem::take(&mut self.woke) { &mut self.slot_rng } else { &mut self.rng };
        let t_wire = self.now + self.host.send.sample(rng);
        // The kernel stamps the hand-over to the NIC, which cannot see the NIC's queue. Each
        // port's stamps are its own socket's.
        let tx_stamp = match self.host.stamps {
            Stamps::None => None,
            Stamps::Software { tx_early, .. } => Some(t_wire.saturating_sub(tx_early.sample(rng))),
            Stamps::Hardware => None,
        };
        match port {
            MasterPort::Primary => self.last_tx = tx_stamp,
            MasterPort::Secondary => self.last_tx_secondary = tx_stamp,
        }
        let Some(k) = self.slots.iter().position(|s| !s.3) else {
            return Err(std::io::Error::new(std::io::ErrorKind::WouldBlock, "more than 32 frames in flight"));
        };
        let slot = &mut self.slots[k];
        let n = frame.len().min(slot.2.len());
        slot.2[..n].copy_from_slice(&frame[..n]);
        let back = self.seg.exchange_on(port, &mut slot.2[..n], t_wire);
        self.slot_secondary[k] = back.is_some_and(|(p, _)| p == MasterPort::Secondary);
        let back = back.map(|(_, t)| t);
        // A NIC stamps the end of the start-of-frame delimiter, 8 bytes after the first bit
        // leaves, which is later than handed over if the frame before was still on the wire.
        if self.host.stamps == Stamps::Hardware {
            let stamp = Some(self.seg.last_departure_ns() + 8 * 80);
            match port {
                MasterPort::Primary => self.last_tx = stamp,
                MasterPort::Secondary => self.last_tx_secondary = stamp,
            }
        }
        match back {
            Some(back) => {
                let deliver = back + self.host.recv.sample(rng);
                self.rx_stamps[k] = match self.host.stamps {
                    Stamps::None => deliver,
                    Stamps::Software { rx_late, .. } => (back + rx_late.sample(rng)).min(deliver),
                    // The start of the frame: its end minus the frame and FCS at 100 Mbit/s.
                    Stamps::Hardware => back.saturating_sub((n as u64 + 4) * 80),
                };
                slot.0 = deliver;
                slot.1 = n;
                slot.3 = true;
            }
            None => self.lost += 1,
        }
        // The send itself costs the master its host's send time.
        self.now = t_wire;
        Ok(())
    }
}

impl Io for VirtualIo {
    fn now_ns(&mut self) -> u64 {
        self.now
    }
    fn wake_target_ns(&self) -> Option<u64> {
        self.wake_target_ns
    }
    fn segment(&self) -> Option<&Segment> {
        Some(&self.seg)
    }
    fn segment_mut(&mut self) -> Option<&mut Segment> {
        Some(&mut self.seg)
    }
    fn timer_resolution_ns(&self) -> u64 {
        self.host.timer_resolution_ns.max(1)
    }
    fn is_virtual(&self) -> bool {
        true
    }

    fn send(&mut self, frame: &[u8]) -> std::io::Result<()> {
        self.send_on(MasterPort::Primary, frame)
    }

    fn has_secondary(&self) -> bool {
        self.seg.secondary().is_some()
    }
    fn send_secondary(&mut self, frame: &[u8]) -> std::io::Result<()> {
        self.send_on(MasterPort::Secondary, frame)
    }
    fn last_rx_secondary(&self) -> bool {
        self.last_rx_secondary
    }
    fn last_tx_secondary_ns(&mut self) -> Option<u64> {
        self.last_tx_secondary
    }

    fn recv(&mut self, buf: &mut [u8], deadline_ns: u64) -> std::io::Result<Option<(usize, u64)>> {
        let next = self.slots.iter_mut().enumerate().filter(|(_, s)| s.3).min_by_key(|(_, s)| s.0);
        match next {
            Some((k, s)) if s.0 <= deadline_ns => {
                self.now = self.now.max(s.0);
                let n = s.1.min(buf.len());
                buf[..n].copy_from_slice(&s.2[..n]);
                s.3 = false;
                self.last_rx_secondary = self.slot_secondary[k];
                Ok(Some((n, self.rx_stamps[k])))
            }
            _ => {
                self.now = self.now.max(deadline_ns);
                Ok(None)
            }
        }
    }

    fn sleep_until(&mut self, t_ns: u64) {
        let target = t_ns;
        self.wake_target_ns = Some(target);
        let res = self.host.timer_resolution_ns;
        let t_ns = if res > 1 { t_ns.div_ceil(res).saturating_mul(res) } else { t_ns };
        let late = match self.cycles.as_mut() {
            Some(c) => {
                // Slots on since the last wake-up's target, to the nearest: 0 for a second
                // sleep within a cycle, which goes on drawing from its slot's stream.
                let on = c
                    .last_target_ns
                    .map_or(1, |p| target.saturating_sub(p).saturating_add(c.cycle_ns / 2) / c.cycle_ns);
                c.last_target_ns = Some(target);
                if on > 0 {
                    c.slot = c.slot.saturating_add(on);
                    let key = c.slot.wrapping_mul(0x9E37_79B9_7F4A_7C15) ^ self.seed.rotate_left(29) ^ 0x5C1C;
                    self.slot_rng = ChaCha8Rng::seed_from_u64(key);
                    self.woke = true;
                }
                self.host.wake.sample(&mut self.slot_rng)
            }
            None => self.host.wake.sample(&mut self.rng),
        };
        self.now = self.now.max(t_ns + late);
    }

    fn last_tx_ns(&mut self) -> Option<u64> {
        self.last_tx
    }
    fn rx_stamps_start_of_frame(&self) -> bool {
        self.host.stamps == Stamps::Hardware
    }

    fn set_gpio(&mut self, level: bool) -> std::io::Result<()> {
        let unsupported = |what: &str| std::io::Error::new(std::io::ErrorKind::Unsupported, what.to_string());
        let latency = self.host.gpio.ok_or_else(|| unsupported("this host model has no calibration output"))?;
        let (node, unit) = self.gpio_wire.ok_or_else(|| unsupported("the calibration output is not wired"))?;
        let n = self.seg.nodes.len();
        let esc = &mut self.seg.nodes.get_mut(node).ok_or_else(|| unsupported(&format!("no node {node} of {n}")))?.esc;
        // The pin changes after the write; no frame passes the ESC in between that this
        // edge's latched time could depend on, so it is latched now.
        esc.latch_input(unit, level, self.now + latency.sample(&mut self.gpio_rng));
        Ok(())
    }
}

/// Real time on a network interface through an AF_PACKET raw socket, with kernel (or NIC)
/// timestamps where available.
#[derive(Debug)]
pub struct RawIo {
    sock: ferrocat_link::RawSocket,
    /// The second port of a ring (cable redundancy).
    secondary: Option<ferrocat_link::RawSocket>,
    last_rx_secondary: bool,
    wake_target_ns: Option<u64>,
    /// Each port's last transmit stamp, taken once from the socket's queue (which reading
    /// drains) and kept until that port sends again, so that it can be asked twice.
    tx_stamps: [Option<u64>; 2],
}

impl RawIo {
    pub fn open(iface: &str) -> std::io::Result<Self> {
        Ok(RawIo {
            sock: ferrocat_link::RawSocket::open(iface)?,
            secondary: None,
            last_rx_secondary: false,
            tx_stamps: [None; 2],
            wake_target_ns: None,
        })
    }

    /// Both ports of a ring: the line starts at `primary`, its far end comes back to
    /// `secondary`.
    pub fn open_redundant(primary: &str, secondary: &str) -> std::io::Result<Self> {
        let mut io = RawIo::open(primary)?;
        io.secondary = Some(ferrocat_link::RawSocket::open(secondary)?);
        Ok(io)
    }

    /// Which timestamps are in use, in words.
    pub fn timestamps(&self) -> &'static str {
        self.sock.timestamps().describe()
    }
}

impl Io for RawIo {
    fn now_ns(&mut self) -> u64 {
        ferrocat_link::monotonic_ns()
    }
    fn send(&mut self, frame: &[u8]) -> std::io::Result<()> {
        self.tx_stamps[0] = None;
        self.sock.send(frame)
    }
    fn recv(&mut self, buf: &mut [u8], deadline_ns: u64) -> std::io::Result<Option<(usize, u64)>> {
        loop {
            let now = ferrocat_link::monotonic_ns();
            if now >= deadline_ns {
                return Ok(None);
            }
            let Some(sec) = &self.secondary else {
                self.sock.set_timeout_ns(deadline_ns - now)?;
                if let Some((n, stamp)) = self.sock.recv_stamped(buf)? {
                    return Ok(Some((n, stamp.unwrap_or_else(ferrocat_link::monotonic_ns))));
                }
                continue;
            };
            let ready = ferrocat_link::RawSocket::wait_readable(&[&self.sock, sec], deadline_ns - now)?;
            for (k, sock) in [&self.sock, sec].into_iter().enumerate() {
                if ready[k] {
                    if let Some((n, stamp)) = sock.try_recv_stamped(buf)? {
                        self.last_rx_secondary = k == 1;
                        return Ok(Some((n, stamp.unwrap_or_else(ferrocat_link::monotonic_ns))));
                    }
                }
            }
        }
    }
    fn has_secondary(&self) -> bool {
        self.secondary.is_some()
    }
    fn send_secondary(&mut self, frame: &[u8]) -> std::io::Result<()> {
        self.tx_stamps[1] = None;
        match &self.secondary {
            Some(s) => s.send(frame),
            None => Err(std::io::Error::new(std::io::ErrorKind::Unsupported, "no secondary interface")),
        }
    }
    fn last_rx_secondary(&self) -> bool {
        self.last_rx_secondary
    }
    fn sleep_until(&mut self, t_ns: u64) {
        self.wake_target_ns = Some(t_ns);
        ferrocat_link::sleep_until_ns(t_ns);
    }
    fn wake_target_ns(&self) -> Option<u64> {
        self.wake_target_ns
    }
    fn last_tx_ns(&mut self) -> Option<u64> {
        if let Some(t) = self.sock.tx_timestamp() {
            self.tx_stamps[0] = Some(t);
        }
        self.tx_stamps[0]
    }
    fn last_tx_secondary_ns(&mut self) -> Option<u64> {
        if let Some(t) = self.secondary.as_ref().and_then(|s| s.tx_timestamp()) {
            self.tx_stamps[1] = Some(t);
        }
        self.tx_stamps[1]
    }
}

/// EtherCAT over UDP (port 0x88A4): the EtherCAT PDU of each frame travels as a UDP payload.
#[derive(Debug)]
pub struct UdpIo {
    sock: std::net::UdpSocket,
    wake_target_ns: Option<u64>,
}

impl UdpIo {
    /// A socket sending to `target` (e.g. "192.0.2.10:34980").
    pub fn open(target: &str) -> std::io::Result<Self> {
        let sock = std::net::UdpSocket::bind("0.0.0.0:0")?;
        sock.connect(target)?;
        Ok(UdpIo { sock, wake_target_ns: None })
    }
}

impl Io for UdpIo {
    fn now_ns(&mut self) -> u64 {
        ferrocat_link::monotonic_ns()
    }
    fn send(&mut self, frame: &[u8]) -> std::io::Result<()> {
        // The engine builds Ethernet frames: the PDU follows the 14-byte header.
        let (_, off) = ferrocat_wire::EthernetRepr::parse(frame)
            .map_err(|e| std::io::Error::new(std::io::ErrorKind::InvalidInput, e.to_string()))?;
        self.sock.send(&frame[off..]).map(|_| ())
    }
    fn recv(&mut self, buf: &mut [u8], deadline_ns: u64) -> std::io::Result<Option<(usize, u64)>> {
        let now = ferrocat_link::monotonic_ns();
        if now >= deadline_ns || buf.len() < 15 {
            return Ok(None);
        }
        self.sock.set_read_timeout(Some(std::time::Duration::from_nanos((deadline_ns - now).max(1_000))))?;
        match self.sock.recv(&mut buf[14..]) {
            Ok(n) => {
                buf[..12].fill(0xFF);
                buf[12..14].copy_from_slice(&ferrocat_wire::ETHERTYPE_ETHERCAT.to_be_bytes());
                Ok(Some((14 + n, ferrocat_link::monotonic_ns())))
            }
            Err(e) if matches!(e.kind(), std::io::ErrorKind::WouldBlock | std::io::ErrorKind::TimedOut) => Ok(None),
            Err(e) => Err(e),
        }
    }
    fn sleep_until(&mut self, t_ns: u64) {
        self.wake_target_ns = Some(t_ns);
        ferrocat_link::sleep_until_ns(t_ns);
    }
    fn wake_target_ns(&self) -> Option<u64> {
        self.wake_target_ns
    }
}
