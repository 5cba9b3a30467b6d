//! The raw socket with a PACKET_MMAP receive ring (TPACKET_V2), shared with the kernel, so
//! that a receive is a read of memory: the kernel writes each frame with its stamp into the
//! ring in its softirq, and the caller spins on the slot's status for a while before it sleeps
//! in `ppoll`. A frame is sent through io_uring with a read of its transmit stamp linked
//! behind it, in one `io_uring_enter` that does not wait, so that an exchange answered within
//! the spin costs one system call, stamps included. Without io_uring, frames go out with
//! `sendto` and a stamp read from the error queue is one call more.
//!
//! Not through a transmit ring: a transmit ring's frame reaches the kernel as pages of the
//! ring, which a veth copies before it hands the frame on, and its stamps then differed from
//! the socket calls' by a tenth of a microsecond (docs/benchmarks.md).
//! TPACKET_V2 rather than V3: V3 hands the ring over in blocks, and a block holding one frame
//! is handed over only when its retire timer runs out (a millisecond at least), too late for
//! an answer awaited in microseconds; V2 hands over each frame.
use std::io;
use std::os::fd::AsRawFd;
use std::ptr::NonNull;
use std::sync::atomic::{AtomicU32, Ordering};

use crate::{realtime_offset_ns, RawSocket, UringSocket};

/// Room per frame: the 32-byte header, the link-layer address the kernel places after it, and
/// an Ethernet frame with a VLAN tag. A longer frame (jumbo, never EtherCAT) arrives cut short:
/// it is dropped and counted.
const FRAME_SIZE: usize = 2048;
/// A block of the ring: 32 frames (a multiple of the page size, as the kernel wants).
const BLOCK_SIZE: usize = 1 << 16;
/// 128 frames: room for every answer of a burst while the caller is busy.
const BLOCKS: usize = 4;
/// TPACKET_V2 (linux/if_packet.h `enum tpacket_versions`).
const TPACKET_V2: libc::c_int = 1;

/// How long a receive spins on the ring before it sleeps, unless told otherwise (the command
/// line's `--spin-us` default): longer than
/// an exchange with a short line takes, so that a cycle's answer is met awake.
pub const DEFAULT_SPIN_NS: u64 = 200_000;

/// How frames leave.
enum Tx {
    Uring(Box<UringSocket>),
    Calls(RawSocket),
}

/// A [`RawSocket`] with a receive ring mapped into the process (see the module's doc).
pub struct RingSocket {
    tx: Tx,
    map: NonNull<u8>,
    frames: usize,
    next: usize,
    spin_ns: u64,
    tx_stamp: Option<u64>,
    truncated: u64,
    sleeps: u64,
}

// SAFETY: the mapping belongs to this socket alone; nothing in it is tied to a thread.
unsafe impl Send for RingSocket {}

impl std::fmt::Debug for RingSocket {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("RingSocket")
            .field("sock", self.socket())
            .field("spin_ns", &self.spin_ns)
            .finish_non_exhaustive()
    }
}

fn setsockopt<T>(sock: &RawSocket, name: libc::c_int, value: &T, what: &str) -> io::Result<()> {
    // SAFETY: setsockopt reads size_of::<T>() bytes of the value we own.
    let r = unsafe {
        libc::setsockopt(
            sock.fd.as_raw_fd(),
            libc::SOL_PACKET,
            name,
            value as *const T as *const libc::c_void,
            std::mem::size_of::<T>() as u32,
        )
    };
    crate::check(r, what).map(|_| ())
}

impl RingSocket {
    /// `sock` with its receive ring, spinning up to `spin_ns` in each receive before it
    /// sleeps; or why not (the kernel refused the ring or the mapping). The socket is not given
    /// back: a refused ring may leave it half set up, so a caller that falls back opens another.
    pub fn new(sock: RawSocket, spin_ns: u64) -> io::Result<Self> {
        setsockopt(&sock, libc::PACKET_VERSION, &TPACKET_V2, "PACKET_VERSION TPACKET_V2")?;
        // Each slot carries its frame's receive stamp: the NIC's where it gives them, else the
        // kernel's, the same as the socket calls' (`RawSocket::open` asked for them).
        let mut ts_flags = libc::SOF_TIMESTAMPING_SOFTWARE;
        if sock.stamps == crate::Timestamps::Hardware {
            ts_flags |= libc::SOF_TIMESTAMPING_RAW_HARDWARE;
        }
        setsockopt(&sock, libc::PACKET_TIMESTAMP, &ts_flags, "PACKET_TIMESTAMP")?;
        let req = libc::tpacket_req {
            tp_block_size: BLOCK_SIZE as u32,
            tp_block_nr: BLOCKS as u32,
            tp_frame_size: FRAME_SIZE as u32,
            tp_frame_nr: (BLOCKS * BLOCK_SIZE / FRAME_SIZE) as u32,
        };
        setsockopt(&sock, libc::PACKET_RX_RING, &req, "PACKET_RX_RING")?;
        // SAFETY: a fresh shared mapping of the socket's ring, of the length it was given;
        // the result is checked.
        let p = unsafe {
            libc::mmap(
                std::ptr::null_mut(),
                BLOCKS * BLOCK_SIZE,
                libc::PROT_READ | libc::PROT_WRITE,
                libc::MAP_SHARED,
                sock.fd.as_raw_fd(),
                0,
            )
        };
        if p == libc::MAP_FAILED {
            let e = io::Error::last_os_error();
            return Err(io::Error::new(e.kind(), format!("mapping the packet ring: {e}")));
        }
        let map = NonNull::new(p as *mut u8).ok_or_else(|| io::Error::other("mmap gave a null mapping"))?;
        let tx = match UringSocket::new(sock) {
            Ok(u) => Tx::Uring(Box::new(u)),
            Err((_, sock)) => Tx::Calls(sock),
        };
        let ring = RingSocket {
            tx,
            map,
            frames: BLOCKS * BLOCK_SIZE / FRAME_SIZE,
            next: 0,
            spin_ns,
            tx_stamp: None,
            truncated: 0,
            sleeps: 0,
        };
        // Frames that came between the socket's bind and its ring wait in its plain queue,
        // where nothing reads them and they would end every `ppoll` at once. (An error met
        // here, the interface gone, is the caller's.)
        let mut scratch = [0u8; 64];
        while ring.socket().try_recv_stamped(&mut scratch)?.is_some() {}
        Ok(ring)
    }

    /// The socket underneath.
    pub fn socket(&self) -> &RawSocket {
        match &self.tx {
            Tx::Uring(u) => u.socket(),
            Tx::Calls(s) => s,
        }
    }

    /// Whether frames leave through io_uring (else through `sendto`).
    pub fn sends_through_io_uring(&self) -> bool {
        matches!(self.tx, Tx::Uring(_))
    }

    /// Frames received longer than a ring slot holds (not EtherCAT): dropped, not handed on cut
    /// short.
    pub fn truncated_frames(&self) -> u64 {
        self.truncated
    }

    /// Receives that slept in `ppoll` because no frame came within the spin.
    pub fn sleeps(&self) -> u64 {
        self.sleeps
    }

    fn slot(&self, i: usize) -> *mut u8 {
        // SAFETY: i < the ring's frame count, so the slot lies within the mapping.
        unsafe { self.map.as_ptr().add(i * FRAME_SIZE) }
    }

    fn status(&self, i: usize) -> &AtomicU32 {
        // SAFETY: a slot starts with its 4-byte aligned status word, which the kernel and we
        // hand back and forth; it is only ever accessed atomically here.
        unsafe { AtomicU32::from_ptr(self.slot(i) as *mut u32) }
    }

    /// Sends one Ethernet frame, before the call returns.
    pub fn send(&mut self, frame: &[u8]) -> io::Result<()> {
        self.tx_stamp = None;
        match &mut self.tx {
            Tx::Uring(u) => {
                // The last send's completions, its stamp's read among them: until it is taken,
                // this frame's read could not be linked behind it.
                u.reap();
                u.send(frame)?;
                u.flush()
            }
            Tx::Calls(s) => s.send(frame),
        }
    }

    /// The next frame and its receive stamp, waiting until `deadline_ns` (CLOCK_MONOTONIC) at
    /// most: spinning on the ring for the socket's spin time, then sleeping in `ppoll`.
    pub fn recv(&mut self, buf: &mut [u8], deadline_ns: u64) -> io::Result<Option<(usize, Option<u64>)>> {
        let spin_until = crate::monotonic_ns().saturating_add(self.spin_ns);
        loop {
            let i = self.next;
            if self.status(i).load(Ordering::Acquire) & libc::TP_STATUS_USER != 0 {
                let got = self.take(i, buf);
                self.status(i).store(libc::TP_STATUS_KERNEL, Ordering::Release);
                self.next = (i + 1) % self.frames;
                match got {
                    Some(frame) => return Ok(Some(frame)),
                    None => {
                        self.truncated += 1;
                        continue;
                    }
                }
            }
            let now = crate::monotonic_ns();
            if now >= deadline_ns {
                return Ok(None);
            }
            if now < spin_until {
                std::hint::spin_loop();
                continue;
            }
            self.sleeps += 1;
            self.sleep(deadline_ns - now)?;
        }
    }

    /// Sleeps until the ring has a frame, the socket an error, or `timeout_ns` has passed. An
    /// error (the interface gone) is returned: a ring does not report it any other way.
    fn sleep(&mut self, timeout_ns: u64) -> io::Result<()> {
        if self.socket().stamps_pending.get() > 0 {
            // Unread transmit stamps would end the sleep at once.
            self.tx_timestamp();
        }
        let mut fd = libc::pollfd { fd: self.socket().fd.as_raw_fd(), events: libc::POLLIN, revents: 0 };
        let ready = crate::poll_in(std::slice::from_mut(&mut fd), timeout_ns)?;
        if ready == 0 && !self.socket().still_bound()? {
            // The interface went away while its error was taken by another read.
            return Err(io::Error::new(io::ErrorKind::NotConnected, "receive: the interface is gone"));
        }
        if fd.revents & (libc::POLLERR | libc::POLLHUP | libc::POLLNVAL) == 0 {
            return Ok(());
        }
        if let Some(e) = self.socket().take_error()? {
            return Err(io::Error::new(e.kind(), format!("receive: {e}")));
        }
        if fd.revents & libc::POLLNVAL != 0 {
            return Err(io::Error::other("receive: the socket is closed"));
        }
        // An error queue that is not empty: transmit stamps nobody counted. Drained, so that
        // the next sleep sleeps.
        let mut b = [0u8; 64];
        while let Ok(Some(_)) = self.socket().recvmsg(&mut b, libc::MSG_ERRQUEUE | libc::MSG_DONTWAIT) {}
        Ok(())
    }

    /// Copies slot `i`'s frame out, with its stamp; `None` where it did not arrive whole or
    /// does not fit `buf`.
    fn take(&self, i: usize, buf: &mut [u8]) -> Option<(usize, Option<u64>)> {
        // SAFETY: the slot starts with a tpacket2_hdr, read after its status was seen with
        // Acquire, so the kernel's writes to it are visible.
        let h = unsafe { std::ptr::read_volatile(self.slot(i) as *const libc::tpacket2_hdr) };
        let (len, snap, mac) = (h.tp_len as usize, h.tp_snaplen as usize, h.tp_mac as usize);
        if snap < len || len > buf.len() || mac + snap > FRAME_SIZE {
            return None;
        }
        // SAFETY: mac + snap lies within the slot (checked above).
        unsafe { std::ptr::copy_nonoverlapping(self.slot(i).add(mac), buf.as_mut_ptr(), len) };
        // Realtime, as the socket calls' stamps: the NIC's where the status says
        // TP_STATUS_TS_RAW_HARDWARE, else the kernel's.
        let stamp = (h.tp_sec != 0 || h.tp_nsec != 0).then(|| {
            let real = h.tp_sec as i128 * 1_000_000_000 + h.tp_nsec as i128;
            (real - realtime_offset_ns()).max(0) as u64
        });
        Some((len, stamp))
    }

    /// The transmit stamp of the last frame sent, once it has left: read with the send
    /// through io_uring, else from the socket's error queue (a system call).
    pub fn tx_timestamp(&mut self) -> Option<u64> {
        let older = self.tx_stamp;
        let t = match &mut self.tx {
            Tx::Uring(u) => u.tx_timestamp(),
            Tx::Calls(s) => s.tx_timestamp(),
        };
        self.tx_stamp = t.or(older);
        self.tx_stamp
    }
}

impl Drop for RingSocket {
    fn drop(&mut self) {
        // SAFETY: the mapping made in `new`, of its length, unmapped once; the socket (closed
        // after this) owns the ring itself.
        unsafe { libc::munmap(self.map.as_ptr() as *mut libc::c_void, BLOCKS * BLOCK_SIZE) };
    }
}
