//! Serving a segment on a real interface: an AF_PACKET raw socket (Linux) or EtherCAT over UDP,
//! in real time, with CLOCK_MONOTONIC mapped onto the segment's true time.
use std::collections::HashMap;
use std::io;
use std::net::UdpSocket;
use std::sync::atomic::{AtomicBool, Ordering};
use std::time::Duration;

use ferrocat_segment::{MasterPort, Segment};

pub use ferrocat_link::{monotonic_ns, RawSocket, RingSocket, UringSocket};

/// Counters of a live run.
#[derive(Debug, Clone, Default)]
pub struct ServeStats {
    pub frames_in: u64,
    pub frames_out: u64,
    /// Of those, the frames taken from and answered on the secondary port of a ring.
    pub frames_in_secondary: u64,
    pub frames_out_secondary: u64,
    /// Frames that were not EtherCAT (dropped, as an ESC with DL control bit 0 set does).
    pub not_ethercat: u64,
    /// Malformed EtherCAT frames (counted and dropped).
    pub malformed: u64,
    /// Wall-clock time the simulator spent per frame, for the figures in docs/benchmarks.md.
    pub busy_ns: u64,
    /// The first 100 000 per-frame times (receive to send), for percentiles.
    pub busy_samples_ns: Vec<u32>,
    /// With clock logging: per frame, the CLOCK_MONOTONIC instant it was processed at and
    /// every node's true system time then (`u64::MAX` without DC), `1 + nodes` values a row —
    /// what `ferrocat lab live` compares the master's clock with.
    pub clock_log: Option<Vec<u64>>,
    /// Frames taken more than [`SHARED_WAIT_NS`] after they arrived (this thread woke late),
    /// and the longest such wait, ns.
    pub taken_late: u64,
    pub max_wait_ns: u64,
    /// Every time a device's application left OP with a sync error (the first 100), with what
    /// the simulator saw before it.
    pub sync_errors: Vec<SyncErrorCause>,
    /// Each device's sync errors counted so far.
    sync_errors_seen: Vec<u64>,
    /// The last frames that carried process data: when they arrived and when their trip began,
    /// segment time.
    recent: std::collections::VecDeque<(u64, u64)>,
}

/// How long after its arrival the simulator may take a frame and still place the frame's trip
/// in the middle of its answer (as a cable whose length changes frame by frame). Beyond it
/// (this thread preempted, or woken late), the trip is placed this long's half after the
/// arrival and the rest of the wait goes on the way back: a slave's SYNC0 does not wait for a
/// late simulator, and frames that arrived a cycle apart must reach it a cycle apart.
pub const SHARED_WAIT_NS: u64 = 100_000;

/// Who a sync error is down to, from what the simulator saw of the frames before it.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum SyncErrorSide {
    /// No frame with process data arrived for this long (ns): the master sent none, or the
    /// host held them (the master's own wake-up figures tell which).
    NoFrames { gap_ns: u64 },
    /// The frames arrived but the simulator took one this long (ns) after its arrival: its
    /// trip was placed late.
    Simulator { wait_ns: u64 },
    /// The frames arrived in time and were taken in time: they reached the slave on the wrong
    /// side of its SYNC0 (the master's cycle phase against SYNC0).
    Phase { gap_ns: u64 },
}

/// A device's application that left OP with a sync error (0x001A, 0x002C).
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct SyncErrorCause {
    /// Segment time it was seen at, ns from the start of serving.
    pub at_ns: u64,
    pub node: usize,
    pub code: u16,
    pub side: SyncErrorSide,
}

impl std::fmt::Display for SyncErrorSide {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        let us = |ns: u64| ns as f64 / 1e3;
        match *self {
            SyncErrorSide::NoFrames { gap_ns } => {
                write!(f, "no frame with process data arrived for {:.0} µs (the master's side or the host's)", us(gap_ns))
            }
            SyncErrorSide::Simulator { wait_ns } => {
                write!(f, "the simulator took a frame {:.0} µs after it arrived (the simulator's side)", us(wait_ns))
            }
            SyncErrorSide::Phase { gap_ns } => write!(
                f,
                "frames arrived at most {:.0} µs apart and were taken in time: they met the slave on the wrong side of its SYNC0 (the master's cycle phase)",
                us(gap_ns)
            ),
        }
    }
}

impl ServeStats {
    fn record(&mut self, ns: u64) {
        self.busy_ns += ns;
        if self.busy_samples_ns.len() < 100_000 {
            self.busy_samples_ns.push(ns.min(u32::MAX as u64) as u32);
        }
    }

    /// A frame that arrived at `arrived_ns` (segment time) was taken `wait_ns` later and its
    /// trip placed at `entry_ns`; `outputs`: it carried process data.
    fn took(&mut self, arrived_ns: u64, wait_ns: u64, entry_ns: u64, outputs: bool) {
        self.max_wait_ns = self.max_wait_ns.max(wait_ns);
        self.taken_late += (wait_ns > SHARED_WAIT_NS) as u64;
        if outputs {
            if self.recent.len() == 8 {
                self.recent.pop_front();
            }
            self.recent.push_back((arrived_ns, entry_ns));
        }
    }

    /// Whether a device's application left OP with a sync error since last asked; if so, what
    /// the frames before it say of the cause.
    fn check_sync_errors(&mut self, seg: &Segment) {
        if self.sync_errors_seen.len() != seg.nodes.len() {
            self.sync_errors_seen = seg.nodes.iter().map(|n| n.esc.sync_errors).collect();
        }
        let now = seg.now_ns();
        for (node, n) in seg.nodes.iter().enumerate() {
            if n.esc.sync_errors == self.sync_errors_seen[node] {
                continue;
            }
            self.sync_errors_seen[node] = n.esc.sync_errors;
            if self.sync_errors.len() < 100 {
                let cycle_ns = u32::from_le_bytes(n.esc.peek(0x09A0, 4).try_into().unwrap_or_default()) as u64;
                let side = self.side(now, cycle_ns.max(1));
                self.sync_errors.push(SyncErrorCause { at_ns: now, node, code: n.esc.al.code.0, side });
            }
        }
    }

    /// The cause of a sync error seen at `now_ns` on a slave with a `cycle_ns` SYNC0.
    fn side(&self, now_ns: u64, cycle_ns: u64) -> SyncErrorSide {
        // The supervision trips after two SYNC0 intervals or more without outputs. The gaps
        // between the frames' arrivals are the master's (or its host's); those between their
        // trips through the segment add the simulator's placement.
        let window = now_ns.saturating_sub(4 * cycle_ns);
        let (mut arrival_gap, mut entry_gap, mut wait_ns) = (0u64, 0u64, 0u64);
        let mut last: Option<(u64, u64)> = None;
        for &(arrived, entry) in self.recent.iter().filter(|(a, _)| *a >= window) {
            let (a0, e0) = last.unwrap_or((window, window));
            arrival_gap = arrival_gap.max(arrived.saturating_sub(a0));
            entry_gap = entry_gap.max(entry.saturating_sub(e0));
            wait_ns = wait_ns.max(entry.saturating_sub(arrived));
            last = Some((arrived, entry));
        }
        let (a0, e0) = last.unwrap_or((window, window));
        arrival_gap = arrival_gap.max(now_ns.saturating_sub(a0));
        entry_gap = entry_gap.max(now_ns.saturating_sub(e0));
        // Within a quarter cycle of two, the master's gap is the cause, whatever the placement
        // added to it.
        if arrival_gap * 4 >= 7 * cycle_ns {
            SyncErrorSide::NoFrames { gap_ns: arrival_gap }
        } else if entry_gap >= 2 * cycle_ns || wait_ns >= cycle_ns / 4 {
            SyncErrorSide::Simulator { wait_ns }
        } else {
            SyncErrorSide::Phase { gap_ns: arrival_gap }
        }
    }

    /// The `q`-quantile (0–1) of the per-frame times, in ns.
    pub fn busy_quantile_ns(&self, q: f64) -> Option<u32> {
        let mut v = self.busy_samples_ns.clone();
        if v.is_empty() {
            return None;
        }
        v.sort_unstable();
        Some(v[((v.len() - 1) as f64 * q).round() as usize])
    }
}

/// One received frame through the segment: counted, dropped as an ESC drops it (not EtherCAT,
/// or malformed), or processed. Returns when the answer would be back at the master, if there is
/// one.
fn handle(
    seg: &mut Segment,
    from: MasterPort,
    frame: &mut [u8],
    t_ns: u64,
    stats: &mut ServeStats,
) -> Option<(MasterPort, u64)> {
    stats.frames_in += 1;
    match ferrocat_wire::Frame::parse(frame) {
        Ok(Some(f)) if f.pdu.header.frame_type == ferrocat_wire::frame::TYPE_DLPDU => {
            seg.exchange_on(from, frame, t_ns)
        }
        Ok(_) => {
            stats.not_ethercat += 1;
            None
        }
        Err(_) => {
            stats.malformed += 1;
            None
        }
    }
}

/// Where each frame's trip through the virtual segment goes in real time. Hardware answers
/// within ns; a program answers tens of µs late, and processing a frame at its arrival would put
/// all of that on the way back, an asymmetry no round-trip measurement can see. Instead the trip
/// sits in the middle of the time the simulator takes to answer, from the frame's kernel receive
/// stamp (when it reached the "wire") to the answer's transmit stamp: a long symmetric cable
/// whose length changes frame by frame. The wait for this thread to wake, which varies most, is
/// known before the frame is processed; the processing and the send after it are taken as their
/// running mean for frames that take the same way (length and entry port: the cyclic frame, a
/// probe and a ring's second pass each cost their own), and the trip's own length (which
/// depends on the way only) as it was last time.
#[derive(Debug, Default)]
struct Placement {
    /// Segment time at the last frame's entry: it only moves forward.
    last_ns: u64,
    /// Running mean of the processing and send, to the answer's transmit stamp, by way; and
    /// over all frames, for a way not seen yet.
    finish_ns: HashMap<usize, u64>,
    finish_any_ns: Option<u64>,
    /// The segment's round trip by way: the frame's length, and the port it came in by.
    trip_ns: HashMap<usize, u64>,
}

impl Placement {
    /// The segment time at which a frame taking `way` (its length and entry port, as a key)
    /// that arrived at `arrived_ns` and is handled from `start_ns` on enters the segment.
    fn entry_ns(&mut self, way: usize, arrived_ns: u64, start_ns: u64) -> u64 {
        let finish = self.finish_ns.get(&way).copied().or(self.finish_any_ns).unwrap_or(0);
        let answer = start_ns.saturating_sub(arrived_ns).min(SHARED_WAIT_NS) + finish;
        let trip = self.trip_ns.get(&way).copied().unwrap_or(0);
        self.last_ns = self.last_ns.max(arrived_ns + answer.saturating_sub(trip) / 2);
        self.last_ns
    }

    /// The answer to the frame taking `way` left `finish_ns` after it was handled; its trip
    /// through the segment took `trip_ns`.
    fn answered(&mut self, way: usize, trip_ns: u64, finish_ns: u64) {
        self.trip_ns.insert(way, trip_ns);
        // Over ~16 frames; a preempted send counts as 1 ms at most.
        let f = finish_ns.min(1_000_000);
        let mean = |m: Option<u64>| m.map_or(f, |m| (m * 15 + f) / 16);
        let by_way = mean(self.finish_ns.get(&way).copied());
        self.finish_ns.insert(way, by_way);
        self.finish_any_ns = Some(mean(self.finish_any_ns));
    }

    /// No frame until `now_ns`: the segment's time moves on.
    fn idle(&mut self, now_ns: u64) -> u64 {
        self.last_ns = self.last_ns.max(now_ns);
        self.last_ns
    }
}

/// A device's EoE endpoint bridged to a TAP interface of the simulator's host: the host's
/// stack stands behind the simulated slave (`ferrocat sim --eoe-tap DEVICE:TAP`).
#[derive(Debug)]
pub struct EoeTap {
    pub node: usize,
    pub tap: ferrocat_link::Tap,
    /// Frames handed to the host, frames from it queued for the master, and those dropped
    /// (the host's interface down; a frame with no EoE form or no mailbox configured yet).
    pub to_host: u64,
    pub from_host: u64,
    pub dropped: u64,
}

impl EoeTap {
    /// Moves frames both ways between the TAP and the device, without waiting.
    fn exchange(&mut self, seg: &mut Segment, buf: &mut [u8]) -> io::Result<()> {
        let Some(n) = seg.nodes.get_mut(self.node) else { return Ok(()) };
        while let Some(len) = self.tap.try_read(buf)? {
            if n.esc.eoe_from_host(&buf[..len]) {
                self.from_host += 1;
            } else {
                self.dropped += 1;
            }
        }
        while let Some(f) = n.esc.eoe_to_host() {
            if self.tap.write(&f)? {
                self.to_host += 1;
            } else {
                self.dropped += 1;
            }
        }
        Ok(())
    }
}

/// Serves `seg` on a raw socket until `stop` is set; `log_clocks` fills `clock_log`. With
/// `secondary`, that interface is the master's second port of a ring (the segment's
/// [`Segment::connect_secondary`]): frames are taken from both and answered on the port the
/// segment returns them to. `taps` bridge devices' EoE endpoints to the host, their frames
/// moved before and after each frame the master sends (the master reads a mailbox only then).
pub fn serve_raw(
    seg: &mut Segment,
    sock: &RawSocket,
    secondary: Option<&RawSocket>,
    stop: &AtomicBool,
    log_clocks: bool,
    taps: &mut [EoeTap],
) -> io::Result<ServeStats> {
    let Server { mut tap_buf, t0, mut buf, mut stats, mut place } = Server::new(log_clocks);
    let socks: Vec<&RawSocket> = [Some(sock), secondary].into_iter().flatten().collect();
    // With one port, a blocking receive (its timeout lets the segment's time move on); with
    // two, a poll of both, then whatever each has queued.
    let mut ready = vec![false; socks.len()];
    let mut next = 0usize;
    while !stop.load(Ordering::Relaxed) {
        let got = if socks.len() == 1 {
            sock.recv_stamped(&mut buf)?.map(|x| (MasterPort::Primary, x))
        } else {
            if !ready.iter().any(|r| *r) {
                ready = RawSocket::wait_readable(&socks, 50_000_000)?;
            }
            // Take turns, so that neither port starves the other.
            let mut got = None;
            for k in 0..socks.len() {
                let i = (next + k) % socks.len();
                if ready[i] {
                    match socks[i].try_recv_stamped(&mut buf)? {
                        Some(x) => {
                            got = Some(([MasterPort::Primary, MasterPort::Secondary][i], x));
                            next = i + 1;
                            break;
                        }
                        None => ready[i] = false,
                    }
                }
            }
            got
        };
        exchange_taps(seg, taps, &mut tap_buf)?;
        let Some((from, (n, stamp))) = got else {
            seg.advance_to(place.idle(monotonic_ns() - t0));
            stats.check_sync_errors(seg);
            continue;
        };
        let Some(fr) = take_frame(seg, &mut place, &mut stats, &mut buf, from, n, stamp, t0) else {
            exchange_taps(seg, taps, &mut tap_buf)?;
            log_clock(seg, &place, &mut stats, t0);
            continue;
        };
        let sock = match fr.to {
            MasterPort::Primary => sock,
            MasterPort::Secondary => secondary.unwrap_or(sock),
        };
        fr.hold();
        sock.send(&buf[..n])?;
        let sent = monotonic_ns();
        // The answer reaches the other end partway through the send call: its kernel
        // transmit stamp says when (the call's return, without one).
        let left = sock.tx_timestamp().map_or(sent, |t| t.clamp(fr.start, sent));
        fr.answered(seg, &mut place, &mut stats, left);
        exchange_taps(seg, taps, &mut tap_buf)?;
        log_clock(seg, &place, &mut stats, t0);
    }
    Ok(stats)
}

/// What serving keeps: buffers, the start instant, the counters and the placement.
struct Server {
    tap_buf: Vec<u8>,
    t0: u64,
    buf: Vec<u8>,
    stats: ServeStats,
    place: Placement,
}

impl Server {
    fn new(log_clocks: bool) -> Self {
        Server {
            tap_buf: vec![0u8; 65536],
            t0: monotonic_ns(),
            buf: vec![0u8; 9216],
            stats: ServeStats { clock_log: log_clocks.then(|| Vec::with_capacity(1 << 20)), ..Default::default() },
            place: Placement::default(),
        }
    }
}

/// A frame the segment answered, waiting for its answer to leave.
struct Answer {
    to: MasterPort,
    way: usize,
    /// When the answer is back at the segment's first port, segment time.
    back_ns: u64,
    /// CLOCK_MONOTONIC when its processing began.
    start: u64,
    /// CLOCK_MONOTONIC before which the answer may not leave: the frame's arrival and its trip.
    not_before: u64,
}

impl Answer {
    /// Waits until the answer may leave. A segment's answer cannot come back before the frame
    /// has gone round it; a simulator that met the frame awake (spinning on a ring) is ready
    /// sooner, and sent then, the master's stamps would show a round trip shorter than the
    /// segment's, which no placement of the trip within the answer can make consistent
    /// (measured: `lab live` 2.7–3.0 µs off with the simulator on its ring).
    fn hold(&self) {
        let now = monotonic_ns();
        if now >= self.not_before {
            return;
        }
        if self.not_before - now > 100_000 {
            ferrocat_link::sleep_until_ns(self.not_before);
        }
        while monotonic_ns() < self.not_before {
            std::hint::spin_loop();
        }
    }

    /// The answer left at `left` (CLOCK_MONOTONIC): the placement learns how long answering
    /// took.
    fn answered(&self, seg: &Segment, place: &mut Placement, stats: &mut ServeStats, left: u64) {
        stats.frames_out += 1;
        stats.frames_out_secondary += (self.to == MasterPort::Secondary) as u64;
        stats.record(left.saturating_sub(self.start));
        // The trip from the frame's departure: a wait for the link is not part of it.
        place.answered(self.way, self.back_ns.saturating_sub(seg.last_departure_ns()), left.saturating_sub(self.start));
    }
}

/// Runs a frame that came in on `from` with its receive stamp through the segment, placed in
/// segment time; the answer, if any, is in `buf[..n]`.
#[allow(clippy::too_many_arguments)]
fn take_frame(
    seg: &mut Segment,
    place: &mut Placement,
    stats: &mut ServeStats,
    buf: &mut [u8],
    from: MasterPort,
    n: usize,
    stamp: Option<u64>,
    t0: u64,
) -> Option<Answer> {
    stats.frames_in_secondary += (from == MasterPort::Secondary) as u64;
    let start = monotonic_ns();
    let arrived = stamp.map_or(start, |s| s.clamp(t0, start));
    // A ring's two ports take different ways through the segment.
    let way = 2 * n + (from == MasterPort::Secondary) as usize;
    let entry = place.entry_ns(way, arrived - t0, start - t0);
    stats.took(arrived - t0, start - arrived, entry, carries_process_data(&buf[..n]));
    let answer = handle(seg, from, &mut buf[..n], entry, stats);
    stats.check_sync_errors(seg);
    let (to, back_ns) = answer?;
    let trip = back_ns.saturating_sub(seg.last_departure_ns());
    Some(Answer { to, way, back_ns, start, not_before: arrived + trip })
}

/// Whether the frame carries a logical datagram (process data).
fn carries_process_data(frame: &[u8]) -> bool {
    match ferrocat_wire::Frame::parse(frame) {
        Ok(Some(f)) => f.pdu.datagrams().any(|d| d.header().command.is_logical()),
        _ => false,
    }
}

fn exchange_taps(seg: &mut Segment, taps: &mut [EoeTap], buf: &mut [u8]) -> io::Result<()> {
    for t in taps.iter_mut() {
        t.exchange(seg, buf)?;
    }
    Ok(())
}

fn log_clock(seg: &Segment, place: &Placement, stats: &mut ServeStats, t0: u64) {
    if let Some(log) = stats.clock_log.as_mut() {
        log.push(t0 + place.last_ns);
        log.extend(seg.nodes.iter().map(|n| n.esc.dc.as_ref().map_or(u64::MAX, |d| d.system_at(place.last_ns))));
    }
}

/// [`serve_raw`] on one port through io_uring: an answer is queued and leaves with the wait
/// for the next frame, one system call per frame; its transmit stamp, read in the same call,
/// is learned from before the next frame is placed.
pub fn serve_uring(
    seg: &mut Segment,
    sock: &mut UringSocket,
    stop: &AtomicBool,
    log_clocks: bool,
    taps: &mut [EoeTap],
) -> io::Result<ServeStats> {
    let Server { mut tap_buf, t0, mut buf, mut stats, mut place } = Server::new(log_clocks);
    let mut pending: Option<(Answer, u64)> = None;
    while !stop.load(Ordering::Relaxed) {
        let got = sock.recv(&mut buf, monotonic_ns() + 50_000_000)?;
        if let Some((a, queued)) = pending.take() {
            // Without a stamp, the answer left when the wait that sent it began.
            let left = sock.tx_timestamp().map_or(queued, |t| t.max(a.start));
            a.answered(seg, &mut place, &mut stats, left);
        }
        exchange_taps(seg, taps, &mut tap_buf)?;
        let Some((n, stamp)) = got else {
            seg.advance_to(place.idle(monotonic_ns() - t0));
            stats.check_sync_errors(seg);
            continue;
        };
        if let Some(a) = take_frame(seg, &mut place, &mut stats, &mut buf, MasterPort::Primary, n, stamp, t0) {
            a.hold();
            sock.send(&buf[..n])?;
            pending = Some((a, monotonic_ns()));
        }
        exchange_taps(seg, taps, &mut tap_buf)?;
        log_clock(seg, &place, &mut stats, t0);
    }
    sock.flush()?;
    Ok(stats)
}

/// [`serve_raw`] on one port with a PACKET_MMAP receive ring: each frame is met on the ring
/// (spinning for the socket's spin time before sleeping), and its answer sent and its
/// transmit stamp read as on the socket calls.
pub fn serve_ring(
    seg: &mut Segment,
    sock: &mut RingSocket,
    stop: &AtomicBool,
    log_clocks: bool,
    taps: &mut [EoeTap],
) -> io::Result<ServeStats> {
    let Server { mut tap_buf, t0, mut buf, mut stats, mut place } = Server::new(log_clocks);
    while !stop.load(Ordering::Relaxed) {
        let got = sock.recv(&mut buf, monotonic_ns() + 50_000_000)?;
        exchange_taps(seg, taps, &mut tap_buf)?;
        let Some((n, stamp)) = got else {
            seg.advance_to(place.idle(monotonic_ns() - t0));
            stats.check_sync_errors(seg);
            continue;
        };
        if let Some(a) = take_frame(seg, &mut place, &mut stats, &mut buf, MasterPort::Primary, n, stamp, t0) {
            a.hold();
            sock.send(&buf[..n])?;
            let sent = monotonic_ns();
            let left = sock.tx_timestamp().map_or(sent, |t| t.clamp(a.start, sent));
            a.answered(seg, &mut place, &mut stats, left);
        }
        exchange_taps(seg, taps, &mut tap_buf)?;
        log_clock(seg, &place, &mut stats, t0);
    }
    Ok(stats)
}

/// Serves `seg` as EtherCAT over UDP: each datagram's payload is an EtherCAT PDU, answered to
/// its sender.
pub fn serve_udp(seg: &mut Segment, sock: &UdpSocket, stop: &AtomicBool) -> io::Result<ServeStats> {
    sock.set_read_timeout(Some(Duration::from_millis(50)))?;
    let t0 = monotonic_ns();
    let mut stats = ServeStats::default();
    let mut buf = vec![0u8; 9216];
    const HDR: usize = 14;
    while !stop.load(Ordering::Relaxed) {
        let (n, from) = match sock.recv_from(&mut buf[HDR..]) {
            Ok(x) => x,
            Err(e)
                if matches!(
                    e.kind(),
                    io::ErrorKind::WouldBlock | io::ErrorKind::TimedOut | io::ErrorKind::Interrupted
                ) =>
            {
                seg.advance_to(monotonic_ns() - t0);
                continue;
            }
            Err(e) => return Err(e),
        };
        let start = monotonic_ns();
        // Wrap the PDU in an Ethernet header so that the segment sees a frame.
        buf[..12].fill(0xFF);
        buf[12..14].copy_from_slice(&ferrocat_wire::ETHERTYPE_ETHERCAT.to_be_bytes());
        if handle(seg, MasterPort::Primary, &mut buf[..HDR + n], start - t0, &mut stats).is_some() {
            sock.send_to(&buf[HDR..HDR + n], from)?;
            stats.frames_out += 1;
            stats.record(monotonic_ns() - start);
        }
    }
    Ok(stats)
}

#[cfg(test)]
mod tests {
    use super::{Placement, ServeStats, SyncErrorSide, SHARED_WAIT_NS};

    const MS: u64 = 1_000_000;

    /// Frames with process data arriving at `arrivals` (ms), each taken `wait_ns` later.
    fn seen(arrivals: &[u64], wait_ns: u64) -> ServeStats {
        let mut s = ServeStats::default();
        for &a in arrivals {
            s.took(a * MS, wait_ns, a * MS + wait_ns.min(SHARED_WAIT_NS) / 2, true);
        }
        s
    }

    #[test]
    fn a_sync_error_is_put_down_to_the_side_that_held_the_frames() {
        // Frames every ms until 10, none after: the master's side (or its host's).
        let s = seen(&[7, 8, 9, 10], 20_000);
        assert_eq!(s.side(13 * MS, MS), SyncErrorSide::NoFrames { gap_ns: 3 * MS });
        // Every ms, but taken 600 µs late: placed at most 50 µs after arriving, so the
        // simulator's wait shows only where it exceeds a quarter cycle of placement.
        let s = seen(&[10, 11, 12, 13], 600_000);
        assert_eq!(s.side(13 * MS + 500_000, MS), SyncErrorSide::Phase { gap_ns: MS });
        assert_eq!(s.taken_late, 4);
        assert_eq!(s.max_wait_ns, 600_000);
        // A frame whose trip was placed 400 µs after its arrival: the simulator's.
        let mut s = seen(&[10, 11, 12], 20_000);
        s.took(13 * MS, 400_000, 13 * MS + 400_000, true);
        assert_eq!(s.side(13 * MS + 500_000, MS), SyncErrorSide::Simulator { wait_ns: 400_000 });
        // 1.8 ms without a frame, the next placed 50 µs after it arrived: the master's gap.
        let mut s = seen(&[7, 8, 9], 20_000);
        s.took(10_800_000, 100_000, 10_850_000, true);
        assert_eq!(s.side(10_900_000, MS), SyncErrorSide::NoFrames { gap_ns: 1_800_000 });
        // Frames without process data do not count as the slave's outputs.
        let mut s = seen(&[7, 8], 20_000);
        s.took(9 * MS, 20_000, 9 * MS, false);
        s.took(10 * MS, 20_000, 10 * MS, false);
        assert!(matches!(s.side(10 * MS + 500_000, MS), SyncErrorSide::NoFrames { .. }));
    }

    #[test]
    fn a_late_wake_up_is_shared_with_the_way_in_only_up_to_its_bound() {
        let mut p = Placement::default();
        // Taken 50 µs after arriving: half of it before the trip.
        assert_eq!(p.entry_ns(0, 1_000_000, 1_050_000), 1_025_000);
        // Taken 5 ms after arriving: the trip begins at most half the bound after the arrival.
        assert_eq!(p.entry_ns(0, 2_000_000, 7_000_000), 2_000_000 + SHARED_WAIT_NS / 2);
    }

    #[test]
    fn a_frames_trip_sits_in_the_middle_of_the_simulators_answer() {
        let mut p = Placement::default();
        let (trip, finish) = (6_000, 8_000);
        // The first frame of a length teaches its trip and the finishing time.
        p.entry_ns(64, 10_000, 12_000);
        p.answered(64, trip, finish);
        for (arrived, wait) in [(1_000_000, 3_000), (2_000_000, 40_000), (3_000_000, 0)] {
            let entry = p.entry_ns(64, arrived, arrived + wait);
            let there = entry - arrived;
            let back = (arrived + wait + finish) - (entry + trip);
            assert_eq!(there, back, "wait {wait} ns");
            p.answered(64, trip, finish);
        }
        // Another length has its own trip, and until it has been answered the mean finishing
        // time of all; time never runs backwards.
        let before = p.last_ns;
        assert_eq!(p.entry_ns(1_500, 3_000_100, 3_000_100), before.max(3_000_100 + finish / 2));
        assert!(p.entry_ns(64, 10, 20) >= before);
    }

    #[test]
    fn frames_that_cost_the_simulator_differently_each_sit_in_the_middle_of_their_own_answer() {
        // A cyclic frame (way 64) costs 30 µs to process and send, a probe (way 60) 5 µs,
        // interleaved: with one mean for both (17.5 µs) each sat 6.25 µs off its middle.
        let mut p = Placement::default();
        let (cyclic, probe) = ((64, 30_000u64), (60, 5_000u64));
        for k in 0..64u64 {
            for (i, (way, finish)) in [cyclic, probe].into_iter().enumerate() {
                let arrived = 1_000_000 * (k + 1) + 200_000 * i as u64;
                let entry = p.entry_ns(way, arrived, arrived + 2_000);
                if k >= 32 {
                    let (there, back) = (entry - arrived, arrived + 2_000 + finish - entry);
                    assert_eq!(there, back, "way {way}, frame {k}");
                }
                p.answered(way, 0, finish);
            }
        }
    }
}
