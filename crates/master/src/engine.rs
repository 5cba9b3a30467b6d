//! The frame engine: packs datagrams into frames, keeps several frames in flight, matches
//! replies by index, retries on timeout and counts what went missing. The cyclic path does not
//! allocate: frame buffers are made once.
use ferrocat_wire::datagram::{HEADER_LEN, WKC_LEN};
use ferrocat_wire::ethernet::{EthernetRepr, BROADCAST};
use ferrocat_wire::frame::MAX_PDU_LEN;
use ferrocat_wire::{Address, Command, DatagramHeader, Frame, FrameWriter};

use crate::error::{MasterError, Result};
use crate::io::Io;

/// One datagram to send: its data goes out and the reply's data comes back in place.
#[derive(Debug)]
pub struct Pdu<'a> {
    pub cmd: Command,
    pub address: Address,
    pub data: &'a mut [u8],
    pub wkc: u16,
}

impl<'a> Pdu<'a> {
    pub fn new(cmd: Command, address: Address, data: &'a mut [u8]) -> Self {
        Pdu { cmd, address, data, wkc: 0 }
    }
}

#[derive(Debug, Clone, Copy, Default, PartialEq, Eq)]
/// Counts of the frames the master sent and what became of them.
pub struct EngineStats {
    /// Frames sent.
    pub frames_sent: u64,
    /// Frames received.
    pub frames_received: u64,
    /// Frames never answered, even after retries.
    pub lost: u64,
    /// Replies that came after their frame had been given up or answered.
    pub late: u64,
    /// Frames sent again after a timeout.
    pub retries: u64,
    /// Cable redundancy: frames sent round the second half of a broken ring again.
    pub resent: u64,
}

/// What the master's two ports show of a ring (cable redundancy).
#[derive(Debug, Clone, Copy, Default, PartialEq, Eq)]
pub enum RingState {
    /// One port, or no frame yet.
    #[default]
    Unknown,
    /// The primary's frames come back on the secondary port: every slave on one pass.
    Intact,
    /// Each port's frames come back to it: the primary's answer goes round the second half
    /// again from the secondary port.
    Broken,
    /// The primary's frames come back to it and nothing answers on the secondary.
    Line,
}

/// How a frame that goes round the second half of a broken ring again treats the clock
/// distribution in it (docs/master.md, "Cable redundancy").
#[derive(Debug, Clone, Copy, Default, PartialEq, Eq)]
pub enum SplitRingClocks {
    /// The far half follows its first slave with a system time, which the master chooses
    /// (`Redundancy::far_reference`): the FRMW of the second pass reads that slave's time instead
    /// of carrying the reference's, a whole master round trip old, and the far half keeps
    /// together. The master keeps that slave on the reference's time through its offset
    /// (`far_clock.rs`).
    #[default]
    FarReference,
    /// As [`SplitRingClocks::FarReference`], the far reference held over at its last rate
    /// and left alone.
    FarReferenceHeld,
    /// FRMW and ARMW become NOPs: every clock behind the break holds its last rate on its own.
    HoldOver,
    /// As sent: the second half takes the reference time read on the first pass (SOEM).
    AsSent,
}

/// A frame that went round both halves of a broken ring: when the master sent and had each
/// pass (world clock) and, for a frame with an FRMW, what it read on each. The master keeps
/// the far half's reference on the reference's time with these, and times the far half's
/// latch of a ring split from the start (docs/master.md, "Cable redundancy").
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct SplitPasses {
    /// Each pass's transmit stamp (on a link without them, when its send was asked for) and
    /// receive stamp.
    pub near_tx_ns: u64,
    pub near_rx_ns: u64,
    pub far_tx_ns: u64,
    pub far_rx_ns: u64,
    /// The FRMW's data after the first pass (the reference's system time) and after the
    /// second (the far reference's), little-endian over its `len` bytes (4 or 8; 0 and no
    /// data for a frame without an FRMW).
    pub near_time: u64,
    pub far_time: u64,
    pub len: usize,
    /// What the second pass added to the FRMW's working counter (one per clock behind the
    /// break: the far reference read, the others took).
    pub far_wkc: u16,
}

impl SplitPasses {
    /// Each pass's mid-point between its transmit and receive stamps (near, far).
    pub fn mid_points_ns(&self) -> (u64, u64) {
        let mid = |tx: u64, rx: u64| tx.wrapping_add_signed(rx.wrapping_sub(tx) as i64 / 2);
        (mid(self.near_tx_ns, self.near_rx_ns), mid(self.far_tx_ns, self.far_rx_ns))
    }
}

const SLOTS: usize = 16;
const FRAME: usize = 1536;

#[derive(Debug)]
struct Slot {
    busy: bool,
    idx: u8,
    /// PDUs `first..first + count` travel in this frame.
    first: usize,
    count: usize,
    len: usize,
    tries: u32,
    deadline: u64,
    buf: Box<[u8; FRAME]>,
    /// Cable redundancy: the primary's answer, kept while the secondary's probe is awaited
    /// (length, receive time), and that probe's port and working counter once back.
    held: Option<(usize, u64)>,
    held_buf: Box<[u8; FRAME]>,
    probe: Option<(bool, u16)>,
    /// The held answer has been sent round the second half.
    resent: bool,
    /// The transmit stamps of the frame and of its second pass (on a link without them, when
    /// their sends were asked for; world clock).
    sent_ns: u64,
    resent_ns: u64,
}

#[derive(Debug)]
pub struct Engine<I: Io> {
    pub io: I,
    /// When the last send call returned (master clock), kept only while
    /// [`Engine::one_timed`] asks for it.
    send_returned_ns: Option<u64>,
    pub timeout_ns: u64,
    /// No frame is waited for past this (master clock), whatever `timeout_ns` says: the
    /// acyclic side's deadline, for steps of more than one datagram.
    pub wait_until_ns: Option<u64>,
    pub retries: u32,
    pub stats: EngineStats,
    next_idx: u8,
    slots: Vec<Slot>,
    rx: Box<[u8; FRAME]>,
    eth: EthernetRepr,
    /// When the last frame came in, as the link stamped it (world clock).
    pub last_rx_ns: u64,
    /// Who is on the segment, so that an error can name the slave a datagram was meant for.
    pub directory: Vec<SlaveTag>,
    /// Cable redundancy: what the frames show of the ring, and how a split ring's far half
    /// gets its clock.
    pub redundancy: Redundancy,
    /// The secondary's last probe came back: worth waiting for the next.
    secondary_alive: bool,
}

/// Cable redundancy as the engine sees it: what the last frame showed of the ring, and how a
/// split ring's far half gets its clock.
#[derive(Debug, Default)]
pub struct Redundancy {
    /// What the last frame showed of the ring.
    pub state: RingState,
    /// How a split ring's far half gets its clock.
    pub clocks: SplitRingClocks,
    /// While the ring is split ([`SplitRingClocks::FarReference`]): the station whose time the
    /// far half's FRMW carries (the first slave with a system time behind the break, which the
    /// master chooses); none: every far clock on its own.
    pub far_reference: Option<u16>,
    /// How many slaves the last secondary probe counted behind a break.
    pub far_half_slaves: u16,
    /// The last frame that went round both halves of a broken ring, since the last
    /// [`Engine::transact_once`] began (the master takes it after its cyclic frame).
    pub split_passes: Option<SplitPasses>,
    /// While set on a broken ring, frames go without a probe and round the far half as soon
    /// as they are back, counted as the last probe counted: a probe passes the far half's
    /// ports before the frame and would be the frame an ET1200's receive-time latch takes
    /// (the master's second latch, master/next_frame_latch.rs).
    pub probes_off: bool,
    /// The working counter of the last probe back on the primary port. On an intact ring it ran
    /// the ring backwards, which only a slave entered by a port other than 0 whose port 0 leads
    /// on round the ring processes — a slave the primary's frames pass unprocessed: 0 on a ring
    /// cabled right.
    pub backward_wkc: u16,
}

/// Source MAC address bytes: the primary's frames, and the probe sent from the secondary port
/// with the same index (the last byte tells them apart; ESCs change only the first).
const SRC_PRIMARY: [u8; 6] = [0x10; 6];
const SRC_PROBE: [u8; 6] = [0x10, 0x10, 0x10, 0x10, 0x10, 0x11];

/// A slave as errors name it.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct SlaveTag {
    pub position: u16,
    pub station: u16,
    pub alias: u16,
    pub name: String,
}

impl<I: Io> Engine<I> {
    pub fn new(io: I) -> Self {
        Engine {
            io,
            send_returned_ns: None,
            timeout_ns: 20_000_000,
            wait_until_ns: None,
            retries: 3,
            stats: EngineStats::default(),
            next_idx: 0,
            directory: Vec::new(),
            last_rx_ns: 0,
            slots: (0..SLOTS)
                .map(|_| Slot {
                    busy: false,
                    idx: 0,
                    first: 0,
                    count: 0,
                    len: 0,
                    tries: 0,
                    deadline: 0,
                    buf: Box::new([0; FRAME]),
                    held: None,
                    held_buf: Box::new([0; FRAME]),
                    probe: None,
                    resent: false,
                    sent_ns: 0,
                    resent_ns: 0,
                })
                .collect(),
            redundancy: Redundancy::default(),
            secondary_alive: true,
            rx: Box::new([0; FRAME]),
            // Locally administered source address; ESCs set bit 1 of the first byte on the way.
            eth: EthernetRepr { dst: BROADCAST, src: SRC_PRIMARY, vlan_tci: None, ethertype: 0 },
        }
    }

    /// Sends all `pdus` (as few frames as fit), waits for every reply and fills in data and
    /// working counters. Fails if a frame stays unanswered after the retries.
    /// [`Engine::transact`] once, within `timeout_ns`: cyclic frames are not sent twice (a lost
    /// frame costs its cycle, not the next ones).
    pub fn transact_once(&mut self, pdus: &mut [Pdu<'_>], timeout_ns: u64) -> Result<()> {
        self.redundancy.split_passes = None;
        let (timeout, retries) = (self.timeout_ns, self.retries);
        (self.timeout_ns, self.retries) = (timeout_ns, 0);
        let r = self.transact(pdus);
        (self.timeout_ns, self.retries) = (timeout, retries);
        r
    }

    pub fn transact(&mut self, pdus: &mut [Pdu<'_>]) -> Result<()> {
        let mut next = 0;
        loop {
            // Fill free slots with the next frames.
            while next < pdus.len() {
                let Some(s) = self.slots.iter().position(|s| !s.busy) else { break };
                next = self.build(s, pdus, next)?;
                self.send(s)?;
            }
            if self.slots.iter().all(|s| !s.busy) {
                return Ok(());
            }
            self.receive(pdus)?;
        }
    }

    fn build(&mut self, s: usize, pdus: &[Pdu<'_>], first: usize) -> Result<usize> {
        self.next_idx = self.next_idx.wrapping_add(1);
        let idx = self.next_idx;
        let slot = &mut self.slots[s];
        let mut w = FrameWriter::new(&mut slot.buf[..], &self.eth)?;
        let mut used = 0;
        let mut k = first;
        while k < pdus.len() {
            let need = HEADER_LEN + pdus[k].data.len() + WKC_LEN;
            if k > first && used + need > MAX_PDU_LEN {
                break;
            }
            if need > MAX_PDU_LEN {
                return Err(crate::error::ConfigError::DatagramTooLarge {
                    command: pdus[k].cmd,
                    len: pdus[k].data.len(),
                }
                .into());
            }
            let h = DatagramHeader::new(pdus[k].cmd, idx, pdus[k].address, pdus[k].data.len() as u16);
            w.push_chained(&h, pdus[k].data, 0)?;
            used += need;
            k += 1;
        }
        slot.len = w.finish()?;
        slot.idx = idx;
        slot.first = first;
        slot.count = k - first;
        slot.tries = 0;
        slot.busy = true;
        Ok(k)
    }

    /// Whether to wait for the secondary's probe when the primary's frame comes back to the
    /// primary port (false while the master has closed the ring itself; a probe that comes
    /// back sets it again).
    pub fn expect_secondary(&mut self, wait: bool) {
        self.secondary_alive = wait;
    }

    /// Whether the secondary's last probe came back (before its frame was given up on).
    pub fn secondary_alive(&self) -> bool {
        self.secondary_alive
    }

    /// The secondary's probe for slot `s`: a BRD with the frame's index. On an intact ring it
    /// runs the ring backwards unprocessed; on a broken one it counts the second half.
    fn send_probe(&mut self, s: usize) -> Result<()> {
        let idx = self.slots[s].idx;
        let mut buf = [0u8; 64];
        let eth = EthernetRepr { src: SRC_PROBE, ..self.eth };
        let mut w = FrameWriter::new(&mut buf[..], &eth)?;
        w.push_chained(&DatagramHeader::new(Command::BRD, idx, Address::Device { adp: 0, ado: 0 }, 2), &[0, 0], 0)?;
        let n = w.finish()?;
        self.io.send_secondary(&buf[..n])?;
        Ok(())
    }

    fn send(&mut self, s: usize) -> Result<()> {
        let now = self.io.now_ns();
        let slot = &mut self.slots[s];
        slot.tries += 1;
        slot.deadline = (now + self.timeout_ns).min(self.wait_until_ns.unwrap_or(u64::MAX));
        slot.held = None;
        slot.probe = None;
        slot.resent = false;
        slot.sent_ns = now;
        self.io.send(&slot.buf[..slot.len])?;
        if self.send_returned_ns.is_some() {
            self.send_returned_ns = Some(self.io.now_ns());
        }
        self.stats.frames_sent += 1;
        if self.io.has_secondary() {
            // Its stamp now, before the probe and other frames follow (a ring's two passes
            // are timed from it).
            if let Some(t) = self.io.last_tx_ns() {
                self.slots[s].sent_ns = t;
            }
            if self.redundancy.probes_off && self.redundancy.state == RingState::Broken {
                self.slots[s].probe = Some((true, self.redundancy.far_half_slaves));
            } else {
                self.send_probe(s)?;
            }
        }
        Ok(())
    }

    /// Copies an answer's data and working counters into the PDUs `first..first + count`.
    fn fill(first: usize, count: usize, frame: &[u8], pdus: &mut [Pdu<'_>]) {
        if let Ok(Some(f)) = Frame::parse(frame) {
            let mut ds = f.pdu.datagrams();
            for p in &mut pdus[first..first + count] {
                let Some(d) = ds.next() else { break };
                let n = p.data.len().min(d.data().len());
                p.data[..n].copy_from_slice(&d.data()[..n]);
                p.wkc = d.wkc();
            }
        }
    }

    /// The FRMW and ARMW datagrams (as sent) of the slot, filled from its held first pass.
    fn fill_clock_datagrams(slot: &Slot, held_len: usize, pdus: &mut [Pdu<'_>]) {
        let (Ok(Some(sent)), Ok(Some(held))) =
            (Frame::parse(&slot.buf[..slot.len]), Frame::parse(&slot.held_buf[..held_len]))
        else {
            return;
        };
        let pairs = sent.pdu.datagrams().zip(held.pdu.datagrams());
        for (p, (a, b)) in pdus[slot.first..slot.first + slot.count].iter_mut().zip(pairs) {
            if matches!(a.header().command.0, 13 | 14) {
                let n = p.data.len().min(b.data().len());
                p.data[..n].copy_from_slice(&b.data()[..n]);
                p.wkc = b.wkc();
            }
        }
    }

    /// The held answer is the answer: the slot is done, its receive time the held one's (a
    /// probe may have come in since).
    fn complete_held(&mut self, s: usize, pdus: &mut [Pdu<'_>]) {
        let slot = &mut self.slots[s];
        if let Some((n, t)) = slot.held {
            Self::fill(slot.first, slot.count, &slot.held_buf[..n], pdus);
            self.last_rx_ns = t;
        }
        slot.busy = false;
        self.stats.frames_received += 1;
    }

    /// The primary's answer came back to the primary port and the probe is known (or given
    /// up): round the second half again if the probe found one, else done.
    fn decide(&mut self, s: usize, pdus: &mut [Pdu<'_>]) -> Result<()> {
        let slot = &mut self.slots[s];
        let Some((n, _)) = slot.held else { return Ok(()) };
        if let Some((true, wkc @ 1..)) = slot.probe {
            self.redundancy.far_half_slaves = wkc;
            match self.redundancy.clocks {
                SplitRingClocks::FarReference | SplitRingClocks::FarReferenceHeld => {
                    redirect_clock_distribution(&mut slot.held_buf[..n], self.redundancy.far_reference)
                }
                SplitRingClocks::HoldOver => redirect_clock_distribution(&mut slot.held_buf[..n], None),
                SplitRingClocks::AsSent => {}
            }
            slot.resent = true;
            let now = self.io.now_ns();
            slot.deadline = (now + self.timeout_ns).min(self.wait_until_ns.unwrap_or(u64::MAX));
            self.io.send_secondary(&slot.held_buf[..n])?;
            // Its stamp now: other frames' second passes may follow before it is back.
            slot.resent_ns = self.io.last_tx_secondary_ns().unwrap_or(now);
            self.stats.resent += 1;
            self.redundancy.state = RingState::Broken;
        } else {
            self.complete_held(s, pdus);
            self.redundancy.state = RingState::Line;
        }
        Ok(())
    }

    fn receive(&mut self, pdus: &mut [Pdu<'_>]) -> Result<()> {
        let deadline = self.slots.iter().filter(|s| s.busy).map(|s| s.deadline).min().unwrap_or(0);
        match self.io.recv(&mut self.rx[..], deadline)? {
            Some((n, t)) => {
                self.last_rx_ns = t;
                let on_secondary = self.io.last_rx_secondary();
                let Ok(Some(f)) = Frame::parse(&self.rx[..n]) else { return Ok(()) };
                let ds = f.pdu.datagrams();
                let Some(first) = ds.clone().next() else { return Ok(()) };
                let idx = first.header().index;
                if self.io.has_secondary() && self.rx.get(11) == Some(&SRC_PROBE[5]) {
                    // The secondary's probe: it tells whether a second half is there.
                    self.secondary_alive = true;
                    let wkc = first.wkc();
                    if !on_secondary {
                        self.redundancy.backward_wkc = wkc;
                    }
                    if let Some(s) = self.slots.iter().position(|s| s.busy && s.idx == idx && s.probe.is_none()) {
                        self.slots[s].probe = Some((on_secondary, wkc));
                        if self.slots[s].held.is_some() && !self.slots[s].resent {
                            self.decide(s, pdus)?;
                        }
                    }
                    return Ok(());
                }
                let Some(s) =
                    self.slots.iter().position(|s| s.busy && s.idx == idx && s.count == f.pdu.datagram_count())
                else {
                    self.stats.late += 1;
                    return Ok(());
                };
                if self.slots[s].resent {
                    // Round the second half: the whole ring's answer. Its timing is the first
                    // pass's, which passed the reference.
                    let slot = &self.slots[s];
                    self.last_rx_ns = slot.held.map_or(t, |h| h.1);
                    if let Some((h, near_rx_ns)) = slot.held {
                        // Only where the first pass went past the reference (not a frame
                        // the primary lost and the secondary sent round as it was).
                        let passes = match frmw_passes(&slot.held_buf[..h], &self.rx[..n]) {
                            Some((near, far)) if near.2 > 0 => Some((near, far)),
                            Some(_) => None,
                            None => Some(((0, 0, 0), (0, 0, 0))),
                        };
                        if let Some((near, far)) = passes {
                            self.redundancy.split_passes = Some(SplitPasses {
                                near_tx_ns: slot.sent_ns,
                                near_rx_ns,
                                far_tx_ns: slot.resent_ns,
                                far_rx_ns: t,
                                near_time: near.0,
                                far_time: far.0,
                                len: near.1,
                                far_wkc: far.2.wrapping_sub(near.2),
                            });
                        }
                    }
                }
                let slot = &mut self.slots[s];
                if !slot.resent && self.io.has_secondary() && !on_secondary {
                    // Back on the port it left: a line, or the first half of a broken ring.
                    slot.held_buf[..n].copy_from_slice(&self.rx[..n]);
                    slot.held = Some((n, t));
                    if slot.probe.is_some() || !self.secondary_alive {
                        self.decide(s, pdus)?;
                    }
                    return Ok(());
                } else if !slot.resent && self.io.has_secondary() {
                    self.redundancy.state = RingState::Intact;
                }
                let slot = &mut self.slots[s];
                Self::fill(slot.first, slot.count, &self.rx[..n], pdus);
                if slot.resent {
                    // The clock datagrams as the first pass left them: the reference's time,
                    // not what the far half did with them.
                    if let Some((h, _)) = slot.held {
                        Self::fill_clock_datagrams(slot, h, pdus);
                    }
                }
                slot.busy = false;
                self.stats.frames_received += 1;
                Ok(())
            }
            None => {
                let now = self.io.now_ns();
                for s in 0..self.slots.len() {
                    if !self.slots[s].busy || self.slots[s].deadline > now {
                        continue;
                    }
                    // Redundancy: an answer in hand whose probe or second pass did not come
                    // back is what there is; the secondary is not waited for again until a
                    // probe returns.
                    if self.slots[s].held.is_some() {
                        self.secondary_alive = false;
                        self.complete_held(s, pdus);
                        continue;
                    }
                    // The primary's frame lost (its cable pulled?) but the probe found slaves
                    // behind the secondary: the frame goes round from there.
                    let slot = &mut self.slots[s];
                    if matches!(slot.probe, Some((true, w)) if w > 0) && !slot.resent {
                        let len = slot.len;
                        slot.held_buf[..len].copy_from_slice(&slot.buf[..len]);
                        slot.held = Some((len, now));
                        self.decide(s, pdus)?;
                        continue;
                    }
                    if self.slots[s].tries > self.retries {
                        self.stats.lost += 1;
                        tracing::debug!("no answer after {} tries", self.retries + 1);
                        self.slots.iter_mut().for_each(|x| x.busy = false);
                        let p = &pdus[self.slots[s].first];
                        return Err(MasterError::Timeout { datagram: datagram_ref(p), tries: self.retries + 1 });
                    }
                    self.stats.retries += 1;
                    self.send(s)?;
                }
                Ok(())
            }
        }
    }

    /// One datagram; returns its working counter.
    pub fn one(&mut self, cmd: Command, address: Address, data: &mut [u8]) -> Result<u16> {
        let mut p = [Pdu::new(cmd, address, data)];
        self.transact(&mut p)?;
        Ok(p[0].wkc)
    }

    /// [`Engine::one`], and when its (last) send call returned, master clock: Park 2020's
    /// eq. 3 starts its round trip "immediately after sending". A link that queues its sends
    /// (io_uring) returns before the frame leaves, with the wait that follows.
    pub fn one_timed(&mut self, cmd: Command, address: Address, data: &mut [u8]) -> Result<(u16, u64)> {
        self.send_returned_ns = Some(0);
        let wkc = self.one(cmd, address, data);
        let sent = self.send_returned_ns.take().unwrap_or(0);
        Ok((wkc?, sent))
    }

    /// One datagram that must reach `expected` slaves.
    pub fn expect_wkc(&mut self, cmd: Command, address: Address, data: &mut [u8], expected: u16) -> Result<()> {
        self.expect_wkc_each(&mut [Pdu::new(cmd, address, data)], expected)
    }

    /// All `pdus` (in as few frames as fit), each of which must reach `expected` slaves.
    pub fn expect_wkc_each(&mut self, pdus: &mut [Pdu<'_>], expected: u16) -> Result<()> {
        self.transact(pdus)?;
        // On a ring, a short count can be a second pass that came back after the frame was
        // given up (a stalled host): reads are asked again, as often as a frame is retried.
        for _ in 0..self.retries {
            if !(self.io.has_secondary() && pdus.iter().any(|p| p.wkc != expected) && reads_only(pdus)) {
                break;
            }
            self.transact(pdus)?;
        }
        match pdus.iter().find(|p| p.wkc != expected) {
            Some(p) => Err(MasterError::Wkc {
                datagram: datagram_ref(p),
                expected,
                got: p.wkc,
                slaves: self.who(p.cmd, p.address, expected, p.wkc),
            }),
            None => Ok(()),
        }
    }

    /// Names the slave(s) a datagram was meant for, for an error message.
    fn who(&self, cmd: Command, address: Address, expected: u16, got: u16) -> String {
        let tag = |t: &SlaveTag| format!("slave {} ({}, station {:#06x})", t.position, t.name, t.station);
        let known = !self.directory.is_empty();
        match (cmd.0, address) {
            // Before the scan has named anyone, the address says it all.
            (1..=6 | 13 | 14, _) if !known => String::new(),
            // APxx / ARMW: auto-increment, the master sends −position.
            (1..=3 | 13, Address::Device { adp, .. }) => {
                let pos = 0u16.wrapping_sub(adp);
                match self.directory.iter().find(|t| t.position == pos) {
                    Some(t) => format!(": {}", tag(t)),
                    None => format!(": no slave at position {pos} ({} found)", self.directory.len()),
                }
            }
            // FPxx / FRMW: configured station address, or alias where the slave enabled it.
            (4..=6 | 14, Address::Device { adp, .. }) => {
                match self.directory.iter().find(|t| t.station == adp || (t.alias != 0 && t.alias == adp)) {
                    Some(t) => format!(": {}", tag(t)),
                    None => format!(": no slave has station address or alias {adp:#06x}"),
                }
            }
            _ => format!(": {got} of {expected} expected answers"),
        }
    }
}

/// The FRMW datagrams of a frame addressed to `far_reference` (its configured address), or
/// made NOPs (command 0) where there is none, as the ARMWs always are (addressed by position):
/// nobody behind the break takes the first pass's time.
fn redirect_clock_distribution(frame: &mut [u8], far_reference: Option<u16>) {
    let Ok((_, mut at)) = EthernetRepr::parse(frame) else { return };
    at += 2; // the EtherCAT header
    while at + HEADER_LEN + WKC_LEN <= frame.len() {
        match (frame[at], far_reference) {
            (14, Some(station)) => frame[at + 2..at + 4].copy_from_slice(&station.to_le_bytes()),
            (13 | 14, _) => frame[at] = 0,
            _ => {}
        }
        let len_field = u16::from_le_bytes([frame[at + 6], frame[at + 7]]);
        at += HEADER_LEN + (len_field & 0x07FF) as usize + WKC_LEN;
        if len_field & 0x8000 == 0 {
            break;
        }
    }
}

/// An FRMW as a pass left it: its data (little-endian), length and working counter.
type FrmwSeen = (u64, usize, u16);

/// The first FRMW of a frame's two passes round a broken ring, after each.
fn frmw_passes(first: &[u8], second: &[u8]) -> Option<(FrmwSeen, FrmwSeen)> {
    let frmw = |frame: &[u8]| {
        let f = Frame::parse(frame).ok()??;
        let d = f.pdu.datagrams().find(|d| d.header().command == Command::FRMW)?;
        let data = d.data();
        let len = data.len().min(8);
        let mut b = [0u8; 8];
        b[..len].copy_from_slice(&data[..len]);
        Some((u64::from_le_bytes(b), len, d.wkc()))
    };
    Some((frmw(first)?, frmw(second)?))
}

/// "FPRD 0x1001:0x0130 (2 bytes)": a datagram in words.
pub fn datagram_ref(p: &Pdu<'_>) -> crate::error::DatagramRef {
    crate::error::DatagramRef { command: p.cmd, address: p.address, len: p.data.len() }
}

/// A frame's bytes on the wire: Ethernet and EtherCAT headers, each datagram's header, data
/// and WKC, padded to Ethernet's minimum; then FCS and preamble.
pub(crate) fn frame_bytes(pdus: &[Pdu<'_>]) -> u64 {
    let payload: usize = 16 + pdus.iter().map(|p| 12 + p.data.len()).sum::<usize>();
    payload.max(60) as u64 + 4 + 8
}

/// From a frame's head (its first preamble bit) to the end of its first `pdus` datagrams, in
/// bytes: preamble, Ethernet and EtherCAT headers, each datagram's header, data and WKC.
pub(crate) fn bytes_through(pdus: &[Pdu<'_>]) -> u64 {
    if pdus.is_empty() {
        return 0;
    }
    (8 + 16 + pdus.iter().map(|p| 12 + p.data.len()).sum::<usize>()) as u64
}

/// Whether every datagram only reads (APRD, FPRD, BRD, LRD): asking again changes nothing.
pub(crate) fn reads_only(pdus: &[Pdu<'_>]) -> bool {
    pdus.iter().all(|p| matches!(p.cmd, Command::APRD | Command::FPRD | Command::BRD | Command::LRD))
}
