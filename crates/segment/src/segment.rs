//! The segment: ESCs wired into a topology, frames walking it in processing order.
use ferrocat_esc::{Esc, FrameTiming};
use rand::{Rng, SeedableRng};
use rand_chacha::ChaCha8Rng;
use std::collections::VecDeque;

use crate::watch::Watch;

use crate::timing::{EscTiming, PortKind, FCS_BYTES, IFG_BYTES, NS_PER_BYTE, PREAMBLE_BYTES};

/// The far end of a link.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct Peer {
    pub node: usize,
    pub port: u8,
    pub delay_ns: u32,
}

/// The master's two ports: the line starts at the primary; with cable redundancy the last
/// device's free port is wired back to the secondary, closing the line into a ring.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash)]
pub enum MasterPort {
    Primary,
    Secondary,
}

/// Where the master's secondary port is wired: a device's port and the link's one-way delay.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct SecondaryLink {
    pub node: usize,
    pub port: u8,
    pub delay_ns: u32,
}

/// One slave: its ESC and how it is wired.
#[derive(Debug)]
pub struct Node {
    pub name: String,
    pub esc: Esc,
    /// Delays and wiring are fixed once frames flow: the segment keeps its route across
    /// frames and re-walks it only when power, pulled links or an ESC's ports change.
    pub timing: EscTiming,
    pub port_kinds: [Option<PortKind>; 4],
    pub peers: [Option<Peer>; 4],
    /// Links pulled (the wiring stays, so they can be restored).
    pub cut: [bool; 4],
    /// Port facing the master.
    pub entry_port: u8,
    pub powered: bool,
    /// Oscillator: base error and its random walk (ppb per √s).
    pub drift_ppb: i64,
    pub wander_ppb_per_sqrt_s: f64,
}

impl Node {
    pub fn new(name: String, esc: Esc, port_kinds: [Option<PortKind>; 4], drift_ppb: i64) -> Self {
        Node {
            name,
            esc,
            timing: EscTiming::default(),
            port_kinds,
            peers: [None; 4],
            cut: [false; 4],
            entry_port: 0,
            powered: true,
            drift_ppb,
            wander_ppb_per_sqrt_s: 0.0,
        }
    }
}

/// A scheduled change of the segment.
#[derive(Debug, Clone, PartialEq)]
pub enum Event {
    LinkDown {
        node: usize,
        port: u8,
    },
    LinkUp {
        node: usize,
        port: u8,
    },
    PowerOff {
        node: usize,
    },
    PowerOn {
        node: usize,
    },
    /// An oscillator's frequency error jumps (a temperature step).
    DriftStep {
        node: usize,
        delta_ppb: i64,
    },
    /// A CiA402 drive's first axis faults by itself (over-current, under-voltage …): its fault
    /// reaction, FAULT, and an emergency with `code`. Nothing happens on another device.
    DriveFault {
        node: usize,
        code: u16,
    },
    /// A drive of the SoE profile sends an SoE notification or emergency about `idn` with
    /// `data`. Nothing happens on a device that speaks no SoE.
    SoeMessage {
        node: usize,
        drive: u8,
        idn: ferrocat_wire::soe::Idn,
        emergency: bool,
        data: Vec<u8>,
    },
    /// A device's application reports a local error (ETG.1000.6, AL status code): from OP or
    /// SAFEOP it goes to SAFEOP with the error indication and `code`; in a lower state it stays
    /// there, with them.
    AlError {
        node: usize,
        code: u16,
    },
}

/// Counters of what the segment did.
#[derive(Debug, Clone, Copy, Default, PartialEq, Eq)]
pub struct SegmentStats {
    pub frames: u64,
    pub returned: u64,
    pub lost: u64,
    pub corrupted: u64,
    pub destroyed_circulating: u64,
}

#[derive(Debug)]
pub struct Segment {
    pub nodes: Vec<Node>,
    /// One-way delay between the master's NIC and the first slave's entry port.
    pub master_link_ns: u32,
    /// The master's secondary port, where the segment is a ring (cable redundancy); set it
    /// with [`Segment::connect_secondary`].
    secondary: Option<SecondaryLink>,
    /// The oscillators' wander, drawn at fixed instants: the same for every master.
    rng: ChaCha8Rng,
    /// Frame faults, one draw per frame: a master that sends more frames does not change the
    /// oscillators' realisation.
    fault_rng: ChaCha8Rng,
    /// Probability that a frame vanishes on its way (a link glitch): it reaches no further ESC
    /// and never returns.
    pub loss_probability: f64,
    /// Probability that a frame is corrupted on its way: the ESCs behind the fault do not
    /// process it, the first of them counts an invalid frame, the master's NIC drops it.
    pub corruption_probability: f64,
    events: Vec<(u64, Event)>,
    now_ns: u64,
    wander_step_ns: u64,
    next_wander_ns: u64,
    pub stats: SegmentStats,
    /// The walk from each master port.
    routes: [Route; 2],
    /// Instants whose system times are still being filled in, oldest first.
    watches: VecDeque<Watch>,
    /// When each master link can take the next frame's first bit, and when the last frame's
    /// first bit left: one frame at a time on a wire.
    link_free_ns: [u64; 2],
    last_departure_ns: u64,
    /// The port the last frame was sent from (whose route `last_visits` reports).
    last_route: MasterPort,
}

/// The last walk through the segment, relative to the instant the frame reached the first ESC:
/// a frame's path and timing follow from the wiring, the delays and the port states alone, so
/// every frame sent while those stay as they were walks the same way, shifted in time.
#[derive(Debug, Default)]
struct Route {
    /// Per node: powered, pulled links and open ports, as when the walk was made.
    key: Vec<u64>,
    scratch: Vec<u64>,
    valid: bool,
    visits: Vec<(usize, FrameTiming)>,
    /// Where the frame leaves for the master and when (None: it circles until it dies).
    exit: Exit,
    /// The auto-close port waiting closed (node, port) where the frame ends, which it opens.
    lands: Option<(usize, u8)>,
    /// Nodes whose ports the frame passes without reaching their processing unit (a ring's
    /// frames in the forwarding direction): receive-time latches that wait for a frame take it.
    passes: Vec<(usize, FrameTiming)>,
    /// When the last frame reached the first ESC: the route's origin for `last_visits`.
    last_at: u64,
}

/// The master port a walk leaves by, and when relative to its start.
type Exit = Option<(MasterPort, u64)>;

/// Nodes and their port times on a walk, in the order the walk reached them.
type Visits = Vec<(usize, FrameTiming)>;

/// The auto-close port waiting closed (node, port) where a walk ends.
type Lands = Option<(usize, u8)>;

/// Processing order: after port 0 comes 3, after 3 comes 1, after 1 comes 2, after 2 comes 0.
fn next_port(p: u8) -> u8 {
    [3, 2, 0, 1][p as usize & 3]
}

impl Segment {
    pub fn new(nodes: Vec<Node>, seed: u64) -> Self {
        Segment {
            nodes,
            master_link_ns: 500,
            secondary: None,
            rng: ChaCha8Rng::seed_from_u64(seed),
            fault_rng: ChaCha8Rng::seed_from_u64(seed ^ 0xFA17),
            loss_probability: 0.0,
            corruption_probability: 0.0,
            events: Vec::new(),
            now_ns: 0,
            wander_step_ns: 100_000_000,
            next_wander_ns: 100_000_000,
            stats: SegmentStats::default(),
            routes: [Route::default(), Route::default()],
            watches: VecDeque::new(),
            link_free_ns: [0; 2],
            last_departure_ns: 0,
            last_route: MasterPort::Primary,
        }
    }

    /// Asks for every DC unit's system time at true time `at_ns` ([`Watch`]), to be taken
    /// with [`Segment::watched`]. An instant the segment has already passed is read from the
    /// clocks as they stand.
    pub fn watch(&mut self, at_ns: u64) {
        let mut w = Watch::new(at_ns, self.nodes.len());
        if at_ns <= self.now_ns {
            w.fill_all(&self.nodes);
        }
        self.watches.push_back(w);
    }

    /// The oldest watch, once every node's time in it is known.
    pub fn watched(&mut self) -> Option<Watch> {
        if self.watches.front()?.is_complete() {
            self.watches.pop_front()
        } else {
            None
        }
    }

    /// The oldest watch, whatever is still missing read from the clocks as they stand: exact
    /// unless a scheduled event or an oscillator step falls between the last frame and its
    /// instant (for the end of a run, when no further frame will fill it in).
    pub fn watched_now(&mut self) -> Option<Watch> {
        let mut w = self.watches.pop_front()?;
        w.fill_all(&self.nodes);
        Some(w)
    }

    /// Fills in every watch of an instant up to `t_ns` before the segment moves on to it.
    fn close_watches_until(&mut self, t_ns: u64) {
        for w in self.watches.iter_mut().filter(|w| w.at_ns <= t_ns && !w.is_complete()) {
            w.fill_all(&self.nodes);
        }
    }

    pub fn now_ns(&self) -> u64 {
        self.now_ns
    }

    /// When the last frame given to [`Segment::exchange`] really left: later than asked if the
    /// link was still busy with the one before.
    pub fn last_departure_ns(&self) -> u64 {
        self.last_departure_ns
    }

    /// Schedules `event` at true time `t_ns`.
    pub fn schedule(&mut self, t_ns: u64, event: Event) {
        let at = self.events.partition_point(|(t, _)| *t <= t_ns);
        self.events.insert(at, (t_ns, event));
    }

    /// Wires `a.port_a` to `b.port_b` (b is the child) with a one-way delay.
    pub fn connect(&mut self, a: usize, port_a: u8, b: usize, port_b: u8, delay_ns: u32) {
        self.nodes[a].peers[port_a as usize] = Some(Peer { node: b, port: port_b, delay_ns });
        self.nodes[b].peers[port_b as usize] = Some(Peer { node: a, port: port_a, delay_ns });
        self.nodes[b].entry_port = port_b;
        self.invalidate_routes();
    }

    /// Wires the master's secondary port to `node.port` with a one-way delay: the segment
    /// becomes a ring (cable redundancy).
    pub fn connect_secondary(&mut self, node: usize, port: u8, delay_ns: u32) {
        self.secondary = Some(SecondaryLink { node, port, delay_ns });
        self.invalidate_routes();
    }

    /// The master's secondary link, if the segment is a ring.
    pub fn secondary(&self) -> Option<SecondaryLink> {
        self.secondary
    }

    fn invalidate_routes(&mut self) {
        for r in &mut self.routes {
            r.valid = false;
        }
    }

    /// The master port wired to `node.port`, if any.
    fn master_at(&self, node: usize, port: u8) -> Option<MasterPort> {
        if node == 0 && port == self.nodes[0].entry_port {
            Some(MasterPort::Primary)
        } else if self.secondary.is_some_and(|s| s.node == node && s.port == port) {
            Some(MasterPort::Secondary)
        } else {
            None
        }
    }

    /// Where a frame from the master's `port` enters, and the link's one-way delay.
    fn entry_of(&self, port: MasterPort) -> Option<(usize, u8, u32)> {
        match port {
            MasterPort::Primary => (!self.nodes.is_empty()).then(|| (0, self.nodes[0].entry_port, self.master_link_ns)),
            MasterPort::Secondary => self.secondary.map(|s| (s.node, s.port, s.delay_ns)),
        }
    }

    fn link_up(&self, node: usize, port: u8) -> bool {
        let n = &self.nodes[node];
        if !n.powered || n.cut[port as usize] {
            return false;
        }
        if self.master_at(node, port).is_some() {
            return true; // the master's NIC
        }
        n.peers[port as usize].is_some_and(|p| self.nodes[p.node].powered && !self.nodes[p.node].cut[p.port as usize])
    }

    /// Sets every ESC's link bits from the wiring.
    pub fn refresh_links(&mut self) {
        for i in 0..self.nodes.len() {
            for p in 0..4u8 {
                let up = self.link_up(i, p);
                self.nodes[i].esc.set_link(p, up);
            }
        }
    }

    fn apply(&mut self, t: u64, e: Event) {
        match e {
            Event::LinkDown { node, port } | Event::LinkUp { node, port } => {
                let cut = matches!(e, Event::LinkDown { .. });
                self.nodes[node].cut[port as usize] = cut;
                if let Some(p) = self.nodes[node].peers[port as usize] {
                    self.nodes[p.node].cut[p.port as usize] = cut;
                }
            }
            Event::PowerOff { node } => self.nodes[node].powered = false,
            Event::PowerOn { node } => {
                self.nodes[node].powered = true;
                self.nodes[node].esc.power_on(t);
            }
            Event::DriftStep { node, delta_ppb } => {
                let n = &mut self.nodes[node];
                // However many steps, the crystal stays within ±1000 ppm (the DC unit's range).
                n.drift_ppb = n.drift_ppb.saturating_add(delta_ppb).clamp(-1_000_000, 1_000_000);
                if let Some(dc) = n.esc.dc.as_mut() {
                    dc.set_drift_ppb(t, n.drift_ppb);
                }
            }
            Event::DriveFault { node, code } => {
                if let Some(d) = self.nodes[node].esc.app_mut().as_any_mut().downcast_mut::<ferrocat_esc::Cia402Drive>()
                {
                    d.inject_fault(code);
                }
            }
            Event::SoeMessage { node, drive, idn, emergency, ref data } => {
                if let Some(dev) = ferrocat_esc::CoeDevice::of(self.nodes[node].esc.app_mut()) {
                    dev.soe_message(drive, idn, emergency, data);
                }
            }
            Event::AlError { node, code } => {
                let al = &mut self.nodes[node].esc.al;
                let state = match al.state {
                    ferrocat_wire::register::AlState::Op => ferrocat_wire::register::AlState::SafeOp,
                    s => s,
                };
                al.fail(state, ferrocat_wire::register::AlStatusCode(code));
            }
        }
        self.refresh_links();
    }

    /// Advances every ESC, scheduled event and oscillator to true time `t_ns`.
    pub fn advance_to(&mut self, t_ns: u64) {
        self.close_watches_until(t_ns);
        self.advance_shared(t_ns);
        self.advance_escs(t_ns);
    }

    /// Scheduled events and oscillator wander up to `t_ns`. ESCs interact only through frames,
    /// so each one otherwise catches up (its SYNC pulses at their exact instants) when a frame
    /// reaches it or when `advance_to` is called.
    fn advance_shared(&mut self, t_ns: u64) {
        while let Some(&(t, _)) = self.events.first() {
            if t > t_ns {
                break;
            }
            let (t, e) = self.events.remove(0);
            self.advance_escs(t);
            self.apply(t, e);
        }
        while self.next_wander_ns <= t_ns {
            let t = self.next_wander_ns;
            let dt_s = self.wander_step_ns as f64 * 1e-9;
            for n in &mut self.nodes {
                if n.wander_ppb_per_sqrt_s > 0.0 {
                    n.esc.advance_to(t);
                    // Random walk of the frequency error: a sum of uniform steps with the
                    // variance of the configured wander.
                    let u: f64 = self.rng.gen_range(-1.0..1.0);
                    let step = u * 3f64.sqrt() * n.wander_ppb_per_sqrt_s * dt_s.sqrt();
                    n.drift_ppb += step.round() as i64;
                    if let Some(dc) = n.esc.dc.as_mut() {
                        dc.set_drift_ppb(t, n.drift_ppb);
                    }
                }
            }
            self.next_wander_ns += self.wander_step_ns;
        }
        self.now_ns = self.now_ns.max(t_ns);
    }

    fn advance_escs(&mut self, t: u64) {
        for n in &mut self.nodes {
            if n.powered {
                n.esc.advance_to(t);
            }
        }
    }

    /// Earliest internal event (a SYNC0 pulse, a scheduled change) after now.
    pub fn next_event_ns(&self) -> Option<u64> {
        let esc = self.nodes.iter().filter(|n| n.powered).filter_map(|n| n.esc.next_event_ns()).min();
        let ev = self.events.first().map(|(t, _)| *t);
        [esc, ev].into_iter().flatten().min()
    }

    /// The walk of a frame's head from the master's `from` port, relative to its arrival at the
    /// first ESC: every ESC's port times and processing-unit pass in the order they happen, and
    /// where and when the head leaves for the master. Each port passes the frame to the next in
    /// processing order; an open port with a link sends it down the wire, a closed one loops it
    /// back; a port closed by loop control drops what its wire brings. On a tree and on a ring
    /// every port is passed at most twice, so a walk longer than that circles (a port closed by
    /// hand) and the frame never returns.
    fn walk(&mut self, from: MasterPort) -> (Visits, Exit, Lands, Visits) {
        let mut visits = std::mem::take(&mut self.routes[from as usize].visits);
        visits.clear();
        let Some((start, start_port, _)) = self.entry_of(from) else { return (visits, None, None, Vec::new()) };
        let mut lands = None;
        // Per node: its port times so far, and its visit's index once it has one.
        let mut timing = vec![FrameTiming::default(); self.nodes.len()];
        let mut slot = vec![None; self.nodes.len()];
        let (mut node, mut p, mut t, mut from_wire) = (start, start_port, 0u64, true);
        timing[node].port_ns[p as usize] = Some(0);
        let mut exit = None;
        // A port closed by loop control takes nothing in from its wire: its receive side is
        // the loop-back.
        let mut steps = if self.nodes[start].esc.port_forced_closed(start_port) { 0 } else { 8 * self.nodes.len() + 8 };
        if self.nodes[start].esc.port_closed_waiting(start_port) {
            (steps, lands) = (0, Some((start, start_port)));
        }
        while steps > 0 {
            steps -= 1;
            let esc_timing = self.nodes[node].timing;
            let mut t_tx = t;
            if p == 0 {
                timing[node].epu_ns = t;
                slot[node] = Some(visits.len());
                visits.push((node, FrameTiming::default()));
                t_tx += esc_timing.processing_ns as u64;
            } else if from_wire {
                t_tx += esc_timing.forwarding_ns as u64;
            }
            let q = next_port(p);
            if !self.nodes[node].esc.config.has_port(q) {
                (p, t, from_wire) = (q, t_tx, false);
                continue;
            }
            let open = self.link_up(node, q) && self.nodes[node].esc.port_open(q);
            if let Some(m) = self.master_at(node, q) {
                // The primary port's cable is checked before the frame leaves (a cut loses it).
                if open || m == MasterPort::Primary {
                    exit = Some((m, t_tx));
                    break;
                }
            }
            match self.nodes[node].peers[q as usize] {
                Some(peer) if open => {
                    if self.nodes[peer.node].esc.port_forced_closed(peer.port) {
                        break;
                    }
                    if self.nodes[peer.node].esc.port_closed_waiting(peer.port) {
                        lands = Some((peer.node, peer.port));
                        break;
                    }
                    t = t_tx + peer.delay_ns as u64;
                    (node, p, from_wire) = (peer.node, peer.port, true);
                    timing[node].port_ns[p as usize] = Some(t);
                }
                _ => (p, t, from_wire) = (q, t_tx + self.nodes[node].timing.loopback_ns as u64, false),
            }
        }
        let mut passes = Vec::new();
        for (n, s) in slot.iter().enumerate() {
            match s {
                Some(i) => visits[*i].1 = timing[n],
                None if timing[n].port_ns.iter().any(Option::is_some) => passes.push((n, timing[n])),
                None => {}
            }
        }
        (visits, exit, lands, passes)
    }

    /// What decides a node's part of the route and may change between frames (timings and
    /// wiring are fixed when the segment is built; `connect` invalidates the route): power,
    /// pulled links, and the ESC's port state (its generation counts every change).
    fn route_state(&self, i: usize) -> u64 {
        let n = &self.nodes[i];
        let cut = u32::from_le_bytes(n.cut.map(u8::from));
        (n.esc.port_generation() as u64) << 32 | (n.powered as u64) << 31 | cut as u64
    }

    /// Walks the segment from `from` again if any node's route state changed since the last
    /// walk from there.
    fn refresh_route(&mut self, from: MasterPort) {
        let r = from as usize;
        let mut key = std::mem::take(&mut self.routes[r].scratch);
        key.clear();
        key.extend((0..self.nodes.len()).map(|i| self.route_state(i)));
        if !(self.routes[r].valid && key == self.routes[r].key) {
            let (visits, exit, lands, passes) = self.walk(from);
            self.routes[r].visits = visits;
            self.routes[r].passes = passes;
            self.routes[r].exit = exit;
            self.routes[r].lands = lands;
            self.routes[r].valid = true;
        }
        self.routes[r].scratch = std::mem::replace(&mut self.routes[r].key, key);
    }

    /// Sends an Ethernet frame (without FCS) from the master's primary port, its first preamble
    /// bit leaving at `t_tx_ns` or once the link is free of the frame before
    /// ([`Segment::last_departure_ns`]). Returns the true time at which the master has received
    /// the whole frame back (on either port: on a ring it comes back on the secondary), with
    /// `frame` modified in place, or `None` if it does not come back.
    pub fn exchange(&mut self, frame: &mut [u8], t_tx_ns: u64) -> Option<u64> {
        self.exchange_on(MasterPort::Primary, frame, t_tx_ns).map(|(_, t)| t)
    }

    /// [`Segment::exchange`] from either master port: also says on which port the frame came
    /// back.
    pub fn exchange_on(&mut self, from: MasterPort, frame: &mut [u8], t_tx_ns: u64) -> Option<(MasterPort, u64)> {
        // A frame handed over while the last one is still on the master's link leaves after it
        // and the inter-frame gap, as from a NIC's transmit queue.
        let link = from as usize;
        let t_tx_ns = t_tx_ns.max(self.link_free_ns[link]);
        self.last_departure_ns = t_tx_ns;
        let wire_ns = (PREAMBLE_BYTES + frame.len().max(60) as u64 + FCS_BYTES) * NS_PER_BYTE;
        self.link_free_ns[link] = t_tx_ns + wire_ns + IFG_BYTES * NS_PER_BYTE;
        self.close_watches_until(t_tx_ns);
        self.advance_shared(t_tx_ns);
        self.stats.frames += 1;
        // No first slave powered, or the cable from the master pulled: nothing gets through.
        let Some((first, entry, link_ns)) = self.entry_of(from) else {
            self.stats.lost += 1;
            return None;
        };
        let n = &self.nodes[first];
        if !n.powered || n.cut[entry as usize & 3] {
            self.stats.lost += 1;
            return None;
        }
        let pdu_at = crate::frame_pdu_offset(frame)?;
        // Timing pass: where the frame head is when.
        // An ESC latches the start of the frame, its first preamble bit (esc-spec 0x0900): the
        // "head" that walks the segment is that bit.
        let head_at_first = t_tx_ns + link_ns as u64;
        self.refresh_route(from);
        let route = &mut self.routes[link];
        route.last_at = head_at_first;
        self.last_route = from;
        let (exit, mut lands) = (route.exit, route.lands);
        // Faults: a lost or corrupted frame is processed by the ESCs before the fault only.
        let mut reach = route.visits.len();
        let mut lost = exit.is_none();
        let mut corrupted = false;
        let mut faulted = false;
        if self.loss_probability > 0.0 && self.fault_rng.gen_bool(self.loss_probability.clamp(0.0, 1.0)) {
            reach = self.fault_rng.gen_range(0..=reach);
            (lost, lands, faulted) = (true, None, true);
        } else if self.corruption_probability > 0.0
            && self.fault_rng.gen_bool(self.corruption_probability.clamp(0.0, 1.0))
        {
            reach = self.fault_rng.gen_range(0..=reach);
            (lost, lands, faulted) = (true, None, true);
            corrupted = true;
            self.stats.corrupted += 1;
        }
        // Processing pass, in the order the frame passes the processing units.
        let visits = std::mem::take(&mut self.routes[link].visits);
        let hdr = ECAT_HEADER_LEN;
        // ESCs change neither the header nor the length: the chain's bounds hold for the walk.
        let len = crate::pdu_len(&frame[pdu_at..]).map(|(len, _)| len);
        for (i, (node, rel)) in visits.iter().enumerate() {
            if i >= reach {
                if corrupted {
                    if let Some(n) = self.nodes.get_mut(*node) {
                        n.esc.count_rx_error(n.entry_port);
                    }
                }
                break;
            }
            let n = &mut self.nodes[*node];
            let Some(len) = len else { break };
            let chain = &mut frame[pdu_at + hdr..pdu_at + hdr + len];
            if n.esc.port0_auto_closed() {
                // Circulating-frame prevention at an automatically closed port 0 (esc-spec §1.6).
                if crate::circulating(chain) {
                    self.stats.destroyed_circulating += 1;
                    (lost, lands) = (true, None);
                    break;
                }
                crate::set_circulating(chain);
            }
            if !self.watches.is_empty() {
                let epu_ns = head_at_first + rel.epu_ns;
                for w in self.watches.iter_mut().filter(|w| w.at_ns <= epu_ns) {
                    w.fill(*node, &n.esc);
                }
            }
            n.esc.process_frame(chain, rel, head_at_first);
        }
        let processed = !visits.is_empty();
        self.routes[link].visits = visits;
        // Faults are drawn for the processing units only: a lost or corrupted frame latches
        // nothing at the ports it merely passes.
        if !faulted {
            for (node, rel) in &self.routes[link].passes {
                self.nodes[*node].esc.frame_passed(rel, head_at_first);
            }
        }
        // A whole frame at an auto-close port waiting closed opens it.
        if let Some((node, port)) = lands.filter(|_| !corrupted) {
            self.nodes[node].esc.frame_arrived_closed(port);
        }
        // The ESC marks frames it processed by setting the locally administered bit of the
        // source MAC (DL control bit 0, esc-spec §1.1).
        if processed && frame.len() > 6 {
            frame[6] |= 0x02;
        }
        let Some((port, out_ns)) = exit.filter(|_| !lost) else {
            self.stats.lost += 1;
            return None;
        };
        let back_link_ns = match port {
            MasterPort::Primary => self.master_link_ns,
            MasterPort::Secondary => self.secondary.map_or(0, |s| s.delay_ns),
        };
        self.stats.returned += 1;
        Some((port, head_at_first + out_ns + back_link_ns as u64 + wire_ns))
    }

    /// The system time at true time `t_ns` of every node whose DC unit has one (in node
    /// order; ESCs with receive times only or no DC left out).
    pub fn system_times_at(&self, t_ns: u64) -> Vec<u64> {
        self.nodes
            .iter()
            .filter(|n| n.esc.has_system_time())
            .filter_map(|n| Some(n.esc.dc.as_ref()?.system_at(t_ns)))
            .collect()
    }

    /// The true time at which each ESC saw the last frame at its processing unit.
    pub fn last_visits(&self) -> Vec<(usize, FrameTiming)> {
        let r = &self.routes[self.last_route as usize];
        r.visits.iter().map(|(node, rel)| (*node, rel.shifted(r.last_at))).collect()
    }
}

use ferrocat_wire::frame::ECAT_HEADER_LEN;
