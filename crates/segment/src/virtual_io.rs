//! The virtual world a master runs in: the in-process segment, a virtual clock and a model of
//! the host, behind the master's [`Io`] trait.
use ferrocat_io::Io;
use rand::SeedableRng;
use rand_chacha::ChaCha8Rng;

use crate::host::{HostModel, Stamps};
use crate::{MasterPort, Segment};

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
