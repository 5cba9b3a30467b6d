//! Serving a segment on a real interface: an AF_PACKET raw socket (Linux) or EtherCAT over UDP,
//! in real time, with CLOCK_MONOTONIC mapped onto the segment's true time.
use std::io;
use std::net::UdpSocket;
use std::sync::atomic::{AtomicBool, Ordering};
use std::time::Duration;

use crate::Segment;

pub use ferrocat_link::{monotonic_ns, RawSocket};

/// Counters of a live run.
#[derive(Debug, Clone, Default)]
pub struct ServeStats {
    pub frames_in: u64,
    pub frames_out: u64,
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
}

impl ServeStats {
    fn record(&mut self, ns: u64) {
        self.busy_ns += ns;
        if self.busy_samples_ns.len() < 100_000 {
            self.busy_samples_ns.push(ns.min(u32::MAX as u64) as u32);
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
/// or malformed), or processed. Returns whether there is an answer to send.
fn handle(seg: &mut Segment, frame: &mut [u8], t_ns: u64, stats: &mut ServeStats) -> bool {
    stats.frames_in += 1;
    match ferrocat_wire::Frame::parse(frame) {
        Ok(Some(f)) if f.pdu.header.frame_type == ferrocat_wire::frame::TYPE_DLPDU => {
            seg.exchange(frame, t_ns).is_some()
        }
        Ok(_) => {
            stats.not_ethercat += 1;
            false
        }
        Err(_) => {
            stats.malformed += 1;
            false
        }
    }
}

/// Serves `seg` on a raw socket until `stop` is set; `log_clocks` fills `clock_log`.
pub fn serve_raw(seg: &mut Segment, sock: &RawSocket, stop: &AtomicBool, log_clocks: bool) -> io::Result<ServeStats> {
    let t0 = monotonic_ns();
    let mut buf = vec![0u8; 9216];
    let mut stats = ServeStats { clock_log: log_clocks.then(|| Vec::with_capacity(1 << 20)), ..Default::default() };
    // The segment's time only moves forward: a frame is processed at its kernel receive time
    // (when it reached the "wire") plus half of what answering costs the simulator (receive
    // stamp to send, a running mean). Hardware answers within ns; a program answers tens of µs
    // late, and processing at arrival would put all of that on the way back — an asymmetry no
    // round-trip measurement can see. Half each way makes it a long, symmetric cable instead.
    let mut last = 0u64;
    let mut answer_ns = 0u64;
    while !stop.load(Ordering::Relaxed) {
        let Some((n, stamp)) = sock.recv_stamped(&mut buf)? else {
            last = last.max(monotonic_ns() - t0);
            seg.advance_to(last);
            continue;
        };
        let start = monotonic_ns();
        let arrived = stamp.map_or(start, |s| s.clamp(t0, start)) - t0;
        last = last.max(arrived + answer_ns / 2);
        if handle(seg, &mut buf[..n], last, &mut stats) {
            sock.send(&buf[..n])?;
            stats.frames_out += 1;
            let sent = monotonic_ns();
            stats.record(sent - start);
            // A running mean over ~16 frames, outliers (a preempted answer) capped at 1 ms.
            let took = (sent - t0).saturating_sub(arrived).min(1_000_000);
            answer_ns = (answer_ns * 15 + took) / 16;
        }
        if let Some(log) = stats.clock_log.as_mut() {
            log.push(t0 + last);
            log.extend(seg.nodes.iter().map(|n| n.esc.dc.as_ref().map_or(u64::MAX, |d| d.system_at(last))));
        }
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
        if handle(seg, &mut buf[..HDR + n], start - t0, &mut stats) {
            sock.send_to(&buf[HDR..HDR + n], from)?;
            stats.frames_out += 1;
            stats.record(monotonic_ns() - start);
        }
    }
    Ok(stats)
}
