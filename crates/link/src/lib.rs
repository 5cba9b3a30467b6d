//! Linux links for EtherCAT: an AF_PACKET raw socket bound to one interface, CLOCK_MONOTONIC,
//! and what a real-time cyclic task needs (absolute sleeps, SCHED_FIFO, locked memory, a pinned
//! CPU), and the [`Io`] trait (from `ferrocat-io`, re-exported) through which the master meets its world. Shared by the live
//! segment and the master.
mod ring;
mod tap;
mod uring;

pub use ferrocat_io::Io;
pub use ring::{RingSocket, DEFAULT_SPIN_NS as DEFAULT_RING_SPIN_NS};
pub use tap::Tap;
pub use uring::UringSocket;

use std::io;
use std::os::fd::{AsRawFd, FromRawFd, OwnedFd};

/// How much longer than asked a receive timeout already set may be and still be kept: an
/// eighth of the time asked, between 10 and 50 µs.
pub fn timeout_slack_ns(want_ns: u64) -> u64 {
    (want_ns / 8).clamp(10_000, 50_000)
}

/// The receive timeout to set for a wait of `want_ns`, where `current_ns` is set (0: none);
/// `None`: keep the current one. A new one is set half the slack above the wait, so that the
/// next waits of a cyclic loop, a little shorter or longer, keep it.
fn timeout_to_set(current_ns: u64, want_ns: u64) -> Option<u64> {
    let want_ns = want_ns.clamp(1_000, 1_000_000_000);
    if current_ns >= want_ns && current_ns - want_ns <= timeout_slack_ns(want_ns) {
        return None;
    }
    Some(want_ns + timeout_slack_ns(want_ns) / 2)
}

/// Sockets [`RawSocket::wait_readable_into`] waits on at most: a ring's two ports and room.
pub const WAIT_SOCKETS: usize = 4;

/// Whether `fd` has something to read, or an error to report, within `timeout_ns`; waited
/// for in `ppoll` (to the microsecond, unlike a blocking receive's timeout, which runs on the
/// scheduler's tick).
pub fn wait_fd_readable(fd: std::os::fd::BorrowedFd<'_>, timeout_ns: u64) -> io::Result<bool> {
    let mut fds = [libc::pollfd { fd: fd.as_raw_fd(), events: libc::POLLIN, revents: 0 }];
    poll_in(&mut fds, timeout_ns)?;
    Ok(fds[0].revents & READY != 0)
}

/// What makes a socket worth a read after `ppoll`: a frame, or an error or stamp to take.
const READY: libc::c_short = libc::POLLIN | libc::POLLERR | libc::POLLHUP;

/// `ppoll` of `fds` for up to `timeout_ns`: how many are ready, 0 when the time ran out or a
/// signal ended the wait (nothing ready then).
pub(crate) fn poll_in(fds: &mut [libc::pollfd], timeout_ns: u64) -> io::Result<usize> {
    let ts = libc::timespec {
        tv_sec: (timeout_ns / 1_000_000_000) as libc::time_t,
        tv_nsec: (timeout_ns % 1_000_000_000) as libc::c_long,
    };
    // SAFETY: ppoll reads and writes the pollfds of the slice we are lent, of its length, and
    // reads the timespec; no signal mask.
    let r = unsafe { libc::ppoll(fds.as_mut_ptr(), fds.len() as libc::nfds_t, &ts, std::ptr::null()) };
    if r < 0 {
        let e = io::Error::last_os_error();
        fds.iter_mut().for_each(|f| f.revents = 0);
        return if e.kind() == io::ErrorKind::Interrupted { Ok(0) } else { Err(e) };
    }
    Ok(r as usize)
}

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
    stamps: Timestamps,
    flags: libc::c_uint,
    /// The receive timeout last set, so that an unchanged one costs no system call.
    timeout_ns: std::cell::Cell<u64>,
    /// Transmit stamps the kernel owes: one per frame sent while it stamps transmissions.
    stamps_pending: std::cell::Cell<u32>,
}

/// Which timestamps the kernel gives this socket.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Timestamps {
    /// None: the application's own clock readings are all there is.
    None,
    /// Kernel software timestamps, on receive and transmit (SO_TIMESTAMPING).
    Software,
    /// The NIC's hardware timestamps (SIOCSHWTSTAMP accepted).
    Hardware,
}

impl Timestamps {
    pub fn describe(self) -> &'static str {
        match self {
            Timestamps::None => "no kernel timestamps (user-space clock readings only)",
            Timestamps::Software => "kernel software timestamps on receive and transmit (the NIC does not timestamp)",
            Timestamps::Hardware => "NIC hardware timestamps on receive and transmit",
        }
    }
}

/// CLOCK_REALTIME − CLOCK_MONOTONIC now: kernel timestamps are realtime. The realtime reading
/// is bracketed by two monotonic ones and set against their midpoint: set against the one
/// after it, the offset came out one reading short (≈ 20 ns on this VM), and every stamp
/// converted with it that much late.
fn realtime_offset_ns() -> i128 {
    let before = monotonic_ns() as i128;
    let real = realtime_ns();
    let after = monotonic_ns() as i128;
    real - (before + after) / 2
}

/// CLOCK_REALTIME now, ns.
fn realtime_ns() -> i128 {
    let mut r = libc::timespec { tv_sec: 0, tv_nsec: 0 };
    // SAFETY: clock_gettime writes into the timespec we own.
    unsafe { libc::clock_gettime(libc::CLOCK_REALTIME, &mut r) };
    r.tv_sec as i128 * 1_000_000_000 + r.tv_nsec as i128
}

/// The kernel's timestamp in a received message's control data (the NIC's where there is one),
/// as CLOCK_MONOTONIC ns.
///
/// # Safety
/// `msg` is a header a completed `recvmsg` filled: its control pointer and length describe
/// control data the kernel wrote.
unsafe fn stamp_of(msg: &libc::msghdr) -> Option<u64> {
    let mut stamp = None;
    let mut c = libc::CMSG_FIRSTHDR(msg);
    while !c.is_null() {
        if (*c).cmsg_level == libc::SOL_SOCKET && (*c).cmsg_type == libc::SO_TIMESTAMPING {
            let ts = libc::CMSG_DATA(c) as *const libc::timespec;
            let sw = std::ptr::read_unaligned(ts);
            let hw = std::ptr::read_unaligned(ts.add(2));
            let pick = if hw.tv_sec != 0 || hw.tv_nsec != 0 { hw } else { sw };
            if pick.tv_sec != 0 || pick.tv_nsec != 0 {
                let real = pick.tv_sec as i128 * 1_000_000_000 + pick.tv_nsec as i128;
                stamp = Some((real - realtime_offset_ns()).max(0) as u64);
            }
        }
        c = libc::CMSG_NXTHDR(msg, c);
    }
    stamp
}

#[repr(C)]
struct IfreqHwts {
    name: [libc::c_char; 16],
    data: *mut libc::c_void,
    _pad: [u8; 16],
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
            // Timestamps: ask the NIC first, then the kernel.
            let mut cfg = libc::hwtstamp_config {
                flags: 0,
                tx_type: libc::HWTSTAMP_TX_ON as _,
                rx_filter: libc::HWTSTAMP_FILTER_ALL as _,
            };
            let mut req = IfreqHwts { name: [0; 16], data: &mut cfg as *mut _ as *mut libc::c_void, _pad: [0; 16] };
            for (d, c) in req.name.iter_mut().zip(iface.bytes().take(15)) {
                *d = c as libc::c_char;
            }
            let hw = libc::ioctl(fd.as_raw_fd(), libc::SIOCSHWTSTAMP as _, &mut req) == 0;
            let mut flags = libc::SOF_TIMESTAMPING_RX_SOFTWARE
                | libc::SOF_TIMESTAMPING_TX_SOFTWARE
                | libc::SOF_TIMESTAMPING_SOFTWARE
                | libc::SOF_TIMESTAMPING_OPT_TSONLY;
            if hw {
                flags |= libc::SOF_TIMESTAMPING_RX_HARDWARE
                    | libc::SOF_TIMESTAMPING_TX_HARDWARE
                    | libc::SOF_TIMESTAMPING_RAW_HARDWARE;
            }
            let stamps = if libc::setsockopt(
                fd.as_raw_fd(),
                libc::SOL_SOCKET,
                libc::SO_TIMESTAMPING,
                &flags as *const _ as *const libc::c_void,
                4,
            ) == 0
            {
                if hw {
                    Timestamps::Hardware
                } else {
                    Timestamps::Software
                }
            } else {
                Timestamps::None
            };
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
            Ok(RawSocket {
                fd,
                ifindex,
                stamps,
                flags,
                timeout_ns: std::cell::Cell::new(0),
                stamps_pending: std::cell::Cell::new(0),
            })
        }
    }

    /// Asks for transmit timestamps too (read them with `tx_timestamp`).
    pub fn enable_tx_timestamps(&mut self) -> io::Result<()> {
        let mut f = self.flags | libc::SOF_TIMESTAMPING_TX_SOFTWARE;
        if self.stamps == Timestamps::Hardware {
            f |= libc::SOF_TIMESTAMPING_TX_HARDWARE;
        }
        // SAFETY: setsockopt reads the flags we own.
        let r = unsafe {
            libc::setsockopt(
                self.fd.as_raw_fd(),
                libc::SOL_SOCKET,
                libc::SO_TIMESTAMPING,
                &f as *const _ as *const libc::c_void,
                4,
            )
        };
        check(r, "SO_TIMESTAMPING").map(|_| self.flags = f)
    }

    /// Sets the receive timeout to about `ns` (at least 1 µs; the kernel rounds to its tick).
    /// A timeout already set that is no shorter and at most [`timeout_slack_ns`] longer is
    /// kept: a cyclic receive asks nearly the same each time, and setting it again was a
    /// system call in most cycles. A receive that times out may so return up to that slack
    /// late, only when no frame came.
    pub fn set_timeout_ns(&self, ns: u64) -> io::Result<()> {
        let Some(ns) = timeout_to_set(self.timeout_ns.get(), ns) else { return Ok(()) };
        self.timeout_ns.set(ns);
        let tv = libc::timeval {
            tv_sec: (ns / 1_000_000_000) as libc::time_t,
            tv_usec: ((ns % 1_000_000_000) / 1000) as libc::suseconds_t,
        };
        // SAFETY: setsockopt reads the timeval we own.
        let r = unsafe {
            libc::setsockopt(
                self.fd.as_raw_fd(),
                libc::SOL_SOCKET,
                libc::SO_RCVTIMEO,
                &tv as *const _ as *const libc::c_void,
                std::mem::size_of::<libc::timeval>() as u32,
            )
        };
        check(r, "SO_RCVTIMEO").map(|_| ())
    }

    /// The socket's pending error (SO_ERROR), cleared by reading it.
    pub fn take_error(&self) -> io::Result<Option<io::Error>> {
        let mut e: libc::c_int = 0;
        let mut len = std::mem::size_of::<libc::c_int>() as libc::socklen_t;
        // SAFETY: getsockopt writes at most `len` bytes into the int we own.
        let r = unsafe {
            libc::getsockopt(
                self.fd.as_raw_fd(),
                libc::SOL_SOCKET,
                libc::SO_ERROR,
                &mut e as *mut _ as *mut libc::c_void,
                &mut len,
            )
        };
        check(r, "SO_ERROR")?;
        Ok((e != 0).then(|| io::Error::from_raw_os_error(e)))
    }

    /// Whether the socket is still bound to its interface (the kernel unbinds it when the
    /// interface is removed).
    pub fn still_bound(&self) -> io::Result<bool> {
        // SAFETY: getsockname writes at most `len` bytes into the address we own.
        let mut sll: libc::sockaddr_ll = unsafe { std::mem::zeroed() };
        let mut len = std::mem::size_of::<libc::sockaddr_ll>() as libc::socklen_t;
        let r = unsafe { libc::getsockname(self.fd.as_raw_fd(), &mut sll as *mut _ as *mut libc::sockaddr, &mut len) };
        check(r, "getsockname")?;
        Ok(sll.sll_ifindex == self.ifindex)
    }

    /// Which timestamps this socket gets.
    pub fn timestamps(&self) -> Timestamps {
        self.stamps
    }

    /// recvmsg with a control buffer; returns the length and the kernel timestamp (CLOCK_MONOTONIC
    /// ns) if there is one.
    fn recvmsg(&self, buf: &mut [u8], flags: libc::c_int) -> io::Result<Option<(usize, Option<u64>)>> {
        let mut control = [0u64; 64];
        let mut iov = libc::iovec { iov_base: buf.as_mut_ptr() as *mut libc::c_void, iov_len: buf.len() };
        // SAFETY: msghdr points at our iovec and control buffer, both live for the call; the
        // cmsg walk stays within the control length the kernel reports.
        unsafe {
            let mut msg: libc::msghdr = std::mem::zeroed();
            msg.msg_iov = &mut iov;
            msg.msg_iovlen = 1;
            msg.msg_control = control.as_mut_ptr() as *mut libc::c_void;
            msg.msg_controllen = std::mem::size_of_val(&control) as _;
            let n = libc::recvmsg(self.fd.as_raw_fd(), &mut msg, flags);
            if n < 0 {
                let e = io::Error::last_os_error();
                return match e.kind() {
                    io::ErrorKind::WouldBlock | io::ErrorKind::TimedOut | io::ErrorKind::Interrupted => Ok(None),
                    _ => Err(e),
                };
            }
            let stamp = stamp_of(&msg);
            Ok(Some((n as usize, stamp)))
        }
    }

    /// The next frame with its kernel receive timestamp, or `None` after the receive timeout.
    pub fn recv_stamped(&self, buf: &mut [u8]) -> io::Result<Option<(usize, Option<u64>)>> {
        self.recvmsg(buf, 0)
    }

    /// The next frame already queued, with its kernel receive timestamp, without waiting.
    pub fn try_recv_stamped(&self, buf: &mut [u8]) -> io::Result<Option<(usize, Option<u64>)>> {
        self.recvmsg(buf, libc::MSG_DONTWAIT)
    }

    /// Waits up to `timeout_ns` until one of `socks` has a frame, or an error or a transmit
    /// stamp to read; says which have.
    pub fn wait_readable(socks: &[&RawSocket], timeout_ns: u64) -> io::Result<Vec<bool>> {
        let mut ready = vec![false; socks.len()];
        Self::wait_readable_into(socks, timeout_ns, &mut ready)?;
        Ok(ready)
    }

    /// [`wait_readable`](Self::wait_readable) without allocating, for a cyclic receive: at
    /// most [`WAIT_SOCKETS`] sockets, `ready` as long as `socks`. The timeout is kept to the
    /// microsecond (`ppoll`), unlike a blocking receive's, which runs on the scheduler's tick.
    pub fn wait_readable_into(socks: &[&RawSocket], timeout_ns: u64, ready: &mut [bool]) -> io::Result<()> {
        if socks.len() > WAIT_SOCKETS || ready.len() != socks.len() {
            return Err(io::Error::new(
                io::ErrorKind::InvalidInput,
                format!(
                    "waiting on {} sockets with room for {} answers (at most {WAIT_SOCKETS})",
                    socks.len(),
                    ready.len()
                ),
            ));
        }
        let mut fds = [libc::pollfd { fd: -1, events: 0, revents: 0 }; WAIT_SOCKETS];
        for (f, s) in fds.iter_mut().zip(socks) {
            *f = libc::pollfd { fd: s.fd.as_raw_fd(), events: libc::POLLIN, revents: 0 };
        }
        let fds = &mut fds[..socks.len()];
        poll_in(fds, timeout_ns)?;
        for (r, f) in ready.iter_mut().zip(fds.iter()) {
            *r = f.revents & READY != 0;
        }
        Ok(())
    }

    /// Reads the whole error queue without waiting: the newest transmit stamp in it, if any.
    /// Stamps nobody counted (a queue not read for a while) keep every wait on the socket from
    /// sleeping (the queue makes it ready), so a caller that found nothing after a wait drains it.
    pub fn drain_error_queue(&self) -> Option<u64> {
        let mut b = [0u8; 64];
        let mut newest = None;
        while let Ok(Some((_, t))) = self.recvmsg(&mut b, libc::MSG_ERRQUEUE | libc::MSG_DONTWAIT) {
            newest = t.or(newest);
        }
        self.stamps_pending.set(0);
        newest
    }

    /// The kernel's transmit timestamp of the last frame sent, if it has arrived.
    pub fn tx_timestamp(&self) -> Option<u64> {
        // Every frame sent queues a stamp, whether or not anyone reads it: the newest is the
        // last frame's; older ones are drained (reading only the first gave a stamp hundreds
        // of frames stale after a bring-up, found by `lab live`). The frames sent say how many
        // are queued, so that the read that would find the queue empty is not made: one system
        // call per cycle. A stamp that never comes (the queue found empty after one that did)
        // is given up.
        let mut b = [0u8; 64];
        let mut newest = None;
        while self.stamps_pending.get() > 0 {
            match self.recvmsg(&mut b, libc::MSG_ERRQUEUE | libc::MSG_DONTWAIT) {
                Ok(Some((_, t))) => {
                    newest = t.or(newest);
                    self.stamps_pending.set(self.stamps_pending.get() - 1);
                }
                _ => {
                    if newest.is_some() {
                        self.stamps_pending.set(0);
                    }
                    break;
                }
            }
        }
        newest
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
        if self.stamps != Timestamps::None {
            // The kernel queues one transmit stamp for the frame (bounded: a stamp read or
            // given up for each one counted).
            self.stamps_pending.set(self.stamps_pending.get().saturating_add(1).min(4096));
        }
        Ok(())
    }
}

/// Sleeps until CLOCK_MONOTONIC reaches `t_ns` (clock_nanosleep with TIMER_ABSTIME).
pub fn sleep_until_ns(t_ns: u64) {
    let ts = libc::timespec {
        tv_sec: (t_ns / 1_000_000_000) as libc::time_t,
        tv_nsec: (t_ns % 1_000_000_000) as libc::c_long,
    };
    // SAFETY: clock_nanosleep reads the timespec we own; EINTR just ends the sleep early.
    unsafe { libc::clock_nanosleep(libc::CLOCK_MONOTONIC, libc::TIMER_ABSTIME, &ts, std::ptr::null_mut()) };
}

/// What real-time setup was possible for this process.
#[derive(Debug, Clone, PartialEq, Eq, Default)]
pub struct RealTime {
    pub memory_locked: bool,
    pub fifo_priority: Option<i32>,
    pub cpu: Option<usize>,
    /// Why something could not be set, one line each.
    pub refused: Vec<String>,
}

/// Moves the calling thread into the network namespace `name` (as made by `ip netns add`,
/// under /run/netns); sockets opened afterwards belong to it.
pub fn enter_netns(name: &str) -> io::Result<()> {
    if name.is_empty() || name.contains('/') || name.starts_with('.') {
        return Err(io::Error::new(io::ErrorKind::InvalidInput, format!("bad namespace name {name:?}")));
    }
    let f = std::fs::File::open(format!("/run/netns/{name}"))?;
    use std::os::fd::AsRawFd;
    // SAFETY: setns takes a namespace file descriptor we hold open for the call.
    if unsafe { libc::setns(f.as_raw_fd(), libc::CLONE_NEWNET) } != 0 {
        return Err(io::Error::last_os_error());
    }
    Ok(())
}

/// Locks memory, switches the calling thread to SCHED_FIFO at `priority` and pins it to `cpu`,
/// as far as permitted; reports what took effect.
pub fn real_time(priority: i32, cpu: Option<usize>) -> RealTime {
    let mut rt = RealTime::default();
    // SAFETY: plain libc calls with valid arguments; failures are reported, not fatal.
    unsafe {
        if libc::mlockall(libc::MCL_CURRENT | libc::MCL_FUTURE) == 0 {
            rt.memory_locked = true;
        } else {
            rt.refused.push(format!("mlockall: {}", io::Error::last_os_error()));
        }
        let p = libc::sched_param { sched_priority: priority };
        if libc::sched_setscheduler(0, libc::SCHED_FIFO, &p) == 0 {
            rt.fifo_priority = Some(priority);
        } else {
            rt.refused.push(format!("SCHED_FIFO {priority}: {}", io::Error::last_os_error()));
        }
        if let Some(c) = cpu {
            let mut set: libc::cpu_set_t = std::mem::zeroed();
            libc::CPU_SET(c, &mut set);
            if libc::sched_setaffinity(0, std::mem::size_of::<libc::cpu_set_t>(), &set) == 0 {
                rt.cpu = Some(c);
            } else {
                rt.refused.push(format!("pin to CPU {c}: {}", io::Error::last_os_error()));
            }
        }
    }
    rt
}

/// Addresses an interface carries that say it is on an office network: any IPv4 address or a
/// global IPv6 address. EtherCAT broadcasts do not belong there.
pub fn routable_addresses(iface: &str) -> io::Result<Vec<String>> {
    let mut found = Vec::new();
    // SAFETY: getifaddrs allocates a list we walk read-only and free with freeifaddrs.
    unsafe {
        let mut list: *mut libc::ifaddrs = std::ptr::null_mut();
        if libc::getifaddrs(&mut list) != 0 {
            return Err(io::Error::last_os_error());
        }
        let mut p = list;
        while !p.is_null() {
            let a = &*p;
            let name = std::ffi::CStr::from_ptr(a.ifa_name).to_string_lossy();
            if name == iface && !a.ifa_addr.is_null() {
                match (*a.ifa_addr).sa_family as i32 {
                    libc::AF_INET => {
                        let sin = &*(a.ifa_addr as *const libc::sockaddr_in);
                        found.push(std::net::Ipv4Addr::from(u32::from_be(sin.sin_addr.s_addr)).to_string());
                    }
                    libc::AF_INET6 => {
                        let sin6 = &*(a.ifa_addr as *const libc::sockaddr_in6);
                        let ip = std::net::Ipv6Addr::from(sin6.sin6_addr.s6_addr);
                        // Link-local (fe80::/10) and unique-local (fc00::/7) are not global.
                        let seg0 = ip.segments()[0];
                        if (seg0 & 0xFFC0) != 0xFE80 && (seg0 & 0xFE00) != 0xFC00 && !ip.is_loopback() {
                            found.push(ip.to_string());
                        }
                    }
                    _ => {}
                }
            }
            p = a.ifa_next;
        }
        libc::freeifaddrs(list);
    }
    Ok(found)
}

#[cfg(test)]
mod tests {
    #[test]
    fn a_cyclic_wait_keeps_its_timeout_and_a_longer_or_much_shorter_one_sets_it() {
        use super::{timeout_slack_ns, timeout_to_set};
        // 1 ms asked: set 1.025 ms; the next waits, some µs shorter or longer, keep it.
        let set = timeout_to_set(0, 1_000_000).unwrap();
        assert_eq!(set, 1_025_000);
        for want in [1_000_000, 998_000, 980_000, 1_020_000] {
            assert_eq!(timeout_to_set(set, want), None, "{want}");
        }
        // Longer than set: it would return early, so set it.
        assert!(timeout_to_set(set, 1_030_000).is_some());
        // Far shorter: kept, it could return up to 1 ms late; set it.
        assert_eq!(timeout_to_set(set, 200_000), Some(212_500));
        // The slack never lets a receive run more than 50 µs late, nor less than 10 µs.
        assert_eq!(timeout_slack_ns(100_000_000), 50_000);
        assert_eq!(timeout_slack_ns(20_000), 10_000);
        assert_eq!(timeout_to_set(0, 0), Some(6_000));
    }

    use super::*;

    /// A realtime reading converted with the offset lands where monotonic readings around it
    /// put it: the median over many, against the midpoint of the two readings around each.
    #[test]
    fn a_realtime_reading_converts_to_the_monotonic_instant_it_was_taken() {
        let mut errors: Vec<i128> = (0..20_000)
            .map(|_| {
                let before = monotonic_ns() as i128;
                let real = realtime_ns();
                let after = monotonic_ns() as i128;
                real - realtime_offset_ns() - (before + after) / 2
            })
            .collect();
        errors.sort_unstable();
        let median = errors[errors.len() / 2];
        println!("median conversion error {median} ns (p10 {}, p90 {})", errors[2_000], errors[18_000]);
        assert!(median.abs() <= 5, "median {median} ns");
    }
}
