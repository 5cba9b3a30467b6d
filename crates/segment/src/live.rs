//! Serving a segment on a real interface: an AF_PACKET raw socket (Linux) or EtherCAT over UDP,
//! in real time, with CLOCK_MONOTONIC mapped onto the segment's true time.
use std::io;
use std::net::UdpSocket;
use std::os::fd::{AsRawFd, FromRawFd, OwnedFd};
use std::sync::atomic::{AtomicBool, Ordering};
use std::time::Duration;

use crate::Segment;

/// CLOCK_MONOTONIC in ns.
pub fn monotonic_ns() -> u64 {
    let mut ts = libc::timespec { tv_sec: 0, tv_nsec: 0 };
    // SAFETY: clock_gettime writes into the timespec we own.
    unsafe { libc::clock_gettime(libc::CLOCK_MONOTONIC, &mut ts) };
    ts.tv_sec as u64 * 1_000_000_000 + ts.tv_nsec as u64
}

/// A raw socket bound to one interface, receiving every frame on it.
#[derive(Debug)]
pub struct RawSocket {
    fd: OwnedFd,
    ifindex: i32,
}

fn check(r: libc::c_int, what: &str) -> io::Result<libc::c_int> {
    if r < 0 {
        let e = io::Error::last_os_error();
        Err(io::Error::new(e.kind(), format!("{what}: {e}")))
    } else {
        Ok(r)
    }
}

impl RawSocket {
    pub fn open(iface: &str) -> io::Result<Self> {
        let name = std::ffi::CString::new(iface)
            .map_err(|_| io::Error::new(io::ErrorKind::InvalidInput, "interface name contains NUL"))?;
        // SAFETY: plain libc calls on values we own; results are checked.
        unsafe {
            let ifindex = libc::if_nametoindex(name.as_ptr()) as i32;
            if ifindex == 0 {
                return Err(io::Error::new(io::ErrorKind::NotFound, format!("no network interface named '{iface}'")));
            }
            let proto = (libc::ETH_P_ALL as u16).to_be() as i32;
            let fd = check(libc::socket(libc::AF_PACKET, libc::SOCK_RAW, proto), "raw socket (needs CAP_NET_RAW)")?;
            let fd = OwnedFd::from_raw_fd(fd);
            let mut sll: libc::sockaddr_ll = std::mem::zeroed();
            sll.sll_family = libc::AF_PACKET as u16;
            sll.sll_protocol = proto as u16;
            sll.sll_ifindex = ifindex;
            check(
                libc::bind(
                    fd.as_raw_fd(),
                    &sll as *const _ as *const libc::sockaddr,
                    std::mem::size_of::<libc::sockaddr_ll>() as u32,
                ),
                "bind",
            )?;
            // Our own transmissions are not for us.
            let one: libc::c_int = 1;
            libc::setsockopt(
                fd.as_raw_fd(),
                libc::SOL_PACKET,
                libc::PACKET_IGNORE_OUTGOING,
                &one as *const _ as *const libc::c_void,
                4,
            );
            let mut mr: libc::packet_mreq = std::mem::zeroed();
            mr.mr_ifindex = ifindex;
            mr.mr_type = libc::PACKET_MR_PROMISC as u16;
            libc::setsockopt(
                fd.as_raw_fd(),
                libc::SOL_PACKET,
                libc::PACKET_ADD_MEMBERSHIP,
                &mr as *const _ as *const libc::c_void,
                std::mem::size_of::<libc::packet_mreq>() as u32,
            );
            let tv = libc::timeval { tv_sec: 0, tv_usec: 50_000 };
            check(
                libc::setsockopt(
                    fd.as_raw_fd(),
                    libc::SOL_SOCKET,
                    libc::SO_RCVTIMEO,
                    &tv as *const _ as *const libc::c_void,
                    std::mem::size_of::<libc::timeval>() as u32,
                ),
                "SO_RCVTIMEO",
            )?;
            Ok(RawSocket { fd, ifindex })
        }
    }

    /// The next frame, or `None` after the receive timeout.
    pub fn recv(&self, buf: &mut [u8]) -> io::Result<Option<usize>> {
        // SAFETY: recv writes at most buf.len() bytes into buf.
        let n = unsafe { libc::recv(self.fd.as_raw_fd(), buf.as_mut_ptr() as *mut libc::c_void, buf.len(), 0) };
        if n < 0 {
            let e = io::Error::last_os_error();
            return match e.kind() {
                io::ErrorKind::WouldBlock | io::ErrorKind::TimedOut | io::ErrorKind::Interrupted => Ok(None),
                _ => Err(e),
            };
        }
        Ok(Some(n as usize))
    }

    pub fn send(&self, frame: &[u8]) -> io::Result<()> {
        // SAFETY: sockaddr_ll is fully initialised; send reads frame.len() bytes.
        unsafe {
            let mut sll: libc::sockaddr_ll = std::mem::zeroed();
            sll.sll_family = libc::AF_PACKET as u16;
            sll.sll_ifindex = self.ifindex;
            sll.sll_halen = 6;
            sll.sll_addr[..6].copy_from_slice(&frame[..6.min(frame.len())]);
            let n = libc::sendto(
                self.fd.as_raw_fd(),
                frame.as_ptr() as *const libc::c_void,
                frame.len(),
                0,
                &sll as *const _ as *const libc::sockaddr,
                std::mem::size_of::<libc::sockaddr_ll>() as u32,
            );
            check(n as libc::c_int, "send")?;
        }
        Ok(())
    }
}

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

fn is_ethercat(frame: &[u8]) -> Result<bool, ()> {
    match ferrocat_wire::Frame::parse(frame) {
        Ok(Some(f)) => Ok(f.pdu.header.frame_type == ferrocat_wire::frame::TYPE_DLPDU),
        Ok(None) => Ok(false),
        Err(_) => Err(()),
    }
}

/// Serves `seg` on a raw socket until `stop` is set.
pub fn serve_raw(seg: &mut Segment, sock: &RawSocket, stop: &AtomicBool) -> io::Result<ServeStats> {
    let t0 = monotonic_ns();
    let mut buf = vec![0u8; 9216];
    let mut stats = ServeStats::default();
    while !stop.load(Ordering::Relaxed) {
        let Some(n) = sock.recv(&mut buf)? else {
            seg.advance_to(monotonic_ns() - t0);
            continue;
        };
        let start = monotonic_ns();
        stats.frames_in += 1;
        match is_ethercat(&buf[..n]) {
            Ok(true) => {}
            Ok(false) => {
                stats.not_ethercat += 1;
                continue;
            }
            Err(()) => {
                stats.malformed += 1;
                continue;
            }
        }
        if seg.exchange(&mut buf[..n], start - t0).is_some() {
            sock.send(&buf[..n])?;
            stats.frames_out += 1;
        }
        stats.record(monotonic_ns() - start);
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
        stats.frames_in += 1;
        // Wrap the PDU in an Ethernet header so that the segment sees a frame.
        buf[..12].fill(0xFF);
        buf[12..14].copy_from_slice(&ferrocat_wire::ETHERTYPE_ETHERCAT.to_be_bytes());
        match is_ethercat(&buf[..HDR + n]) {
            Ok(true) => {}
            Ok(false) => {
                stats.not_ethercat += 1;
                continue;
            }
            Err(()) => {
                stats.malformed += 1;
                continue;
            }
        }
        if seg.exchange(&mut buf[..HDR + n], start - t0).is_some() {
            sock.send_to(&buf[HDR..HDR + n], from)?;
            stats.frames_out += 1;
        }
        stats.record(monotonic_ns() - start);
    }
    Ok(stats)
}
