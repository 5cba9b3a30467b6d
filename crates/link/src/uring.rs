//! The raw socket driven through io_uring, so that a cycle costs one system call: the frames
//! sent are queued, and go out with the wait for the answer in a single `io_uring_enter`
//! (submit the sends, a read of the transmit stamp linked to each, and a receive kept armed;
//! wait for the receive's completion or the deadline). A receive that is already complete
//! costs none.
//!
//! Frames queued by [`UringSocket::send`] leave at the next [`UringSocket::recv`],
//! [`UringSocket::flush`], or drop: a caller that sends and then does something else than
//! wait for the answer flushes first.
use std::io;
use std::os::fd::AsRawFd;

use io_uring::{opcode, squeue, types, IoUring};

use crate::{stamp_of, RawSocket};

/// Frames that may be queued or in flight at once (each with its buffer); a cycle sends a
/// handful.
const TX_SLOTS: usize = 32;
/// Longest frame sent: an Ethernet frame without FCS, with a VLAN tag.
const FRAME_LEN: usize = 1522;
/// Room for a frame received: a longer one (jumbo, not EtherCAT) is dropped and counted, never
/// handed on cut short.
const RX_LEN: usize = 9216;
/// Room for the SO_TIMESTAMPING control message (three timespecs) and others.
const CONTROL_LEN: usize = 256;

const RX_TAG: u64 = 1 << 32;
const ERR_TAG: u64 = 2 << 32;

/// A message buffer with the header and vector that point into it: boxed, so that the kernel
/// may hold the pointers while the request is in flight.
struct Msg {
    hdr: libc::msghdr,
    iov: libc::iovec,
    addr: libc::sockaddr_ll,
    control: [u64; CONTROL_LEN / 8],
    data: [u8; RX_LEN],
}

// SAFETY: the header's pointers point into the same boxed allocation (its vector, address,
// control and data), which moves with it; nothing else is shared. A master may so run its
// cycles in a thread of their own.
unsafe impl Send for Msg {}

impl Msg {
    fn new() -> Box<Msg> {
        // SAFETY: every field is plain data for which all-zero bytes are a valid value.
        let mut m: Box<Msg> = Box::new(unsafe { std::mem::zeroed() });
        m.iov = libc::iovec { iov_base: m.data.as_mut_ptr() as *mut libc::c_void, iov_len: RX_LEN };
        m.hdr.msg_iov = &mut m.iov;
        m.hdr.msg_iovlen = 1;
        m
    }

    /// Ready for a receive: whole buffer, control room, no address.
    fn arm_recv(&mut self) -> *mut libc::msghdr {
        self.iov.iov_len = RX_LEN;
        self.hdr.msg_name = std::ptr::null_mut();
        self.hdr.msg_namelen = 0;
        self.hdr.msg_control = self.control.as_mut_ptr() as *mut libc::c_void;
        self.hdr.msg_controllen = CONTROL_LEN as _;
        self.hdr.msg_flags = 0;
        &mut self.hdr
    }
}

impl std::fmt::Debug for Msg {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.write_str("Msg")
    }
}

/// A [`RawSocket`] whose sends and receives go through io_uring (see the module's doc).
pub struct UringSocket {
    sock: RawSocket,
    ring: IoUring,
    /// Boxed one by one: each header points into its own message (vector, address).
    #[allow(clippy::vec_box)]
    tx: Vec<Box<Msg>>,
    /// Which transmit buffers the kernel may still read.
    tx_busy: [bool; TX_SLOTS],
    rx: Box<Msg>,
    /// The receive is queued or in flight.
    rx_armed: bool,
    /// A completed receive not yet taken: its length (or error), stamp, and whether it was
    /// longer than the buffer.
    rx_done: Option<(i32, Option<u64>, bool)>,
    err: Box<Msg>,
    err_armed: bool,
    /// The newest transmit stamp read through the ring since the last send.
    tx_stamp: Option<u64>,
    /// Requests queued but not yet submitted.
    unsubmitted: usize,
    /// The first send error met, returned by the next call.
    send_error: Option<io::Error>,
    /// Frames received longer than the receive buffer, dropped.
    truncated: u64,
}

impl std::fmt::Debug for UringSocket {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("UringSocket").field("sock", &self.sock).finish_non_exhaustive()
    }
}

impl UringSocket {
    /// The socket on io_uring, or why not (io_uring disabled or absent, no timed wait) with
    /// the socket back.
    pub fn new(sock: RawSocket) -> Result<Self, (io::Error, RawSocket)> {
        let ring = match IoUring::new(64) {
            Ok(r) if r.params().is_feature_ext_arg() => r,
            Ok(_) => {
                let e = io::Error::new(io::ErrorKind::Unsupported, "io_uring without timed waits (kernel < 5.11)");
                return Err((e, sock));
            }
            Err(e) => return Err((e, sock)),
        };
        let mut tx: Vec<Box<Msg>> = (0..TX_SLOTS).map(|_| Msg::new()).collect();
        for m in &mut tx {
            m.addr.sll_family = libc::AF_PACKET as u16;
            m.addr.sll_ifindex = sock.ifindex;
            m.addr.sll_halen = 6;
            m.hdr.msg_name = &mut m.addr as *mut _ as *mut libc::c_void;
            m.hdr.msg_namelen = std::mem::size_of::<libc::sockaddr_ll>() as u32;
        }
        Ok(UringSocket {
            sock,
            ring,
            tx,
            tx_busy: [false; TX_SLOTS],
            rx: Msg::new(),
            rx_armed: false,
            rx_done: None,
            err: Msg::new(),
            err_armed: false,
            tx_stamp: None,
            unsubmitted: 0,
            send_error: None,
            truncated: 0,
        })
    }

    /// The socket underneath.
    pub fn socket(&self) -> &RawSocket {
        &self.sock
    }

    /// Frames received longer than 9 216 bytes (not EtherCAT): dropped, not handed on cut short.
    pub fn truncated_frames(&self) -> u64 {
        self.truncated
    }

    fn push(&mut self, e: &squeue::Entry) -> io::Result<()> {
        // SAFETY: every request points into a boxed buffer this socket owns and does not
        // reuse or free before the request's completion is reaped (`tx_busy`, `rx_armed`,
        // `err_armed`; drop waits for them).
        loop {
            if unsafe { self.ring.submission().push(e) }.is_ok() {
                self.unsubmitted += 1;
                return Ok(());
            }
            self.ring.submit()?;
            self.unsubmitted = 0;
        }
    }

    /// Queues one Ethernet frame; it leaves with the next receive or flush.
    pub fn send(&mut self, frame: &[u8]) -> io::Result<()> {
        if frame.len() > FRAME_LEN {
            return Err(io::Error::new(io::ErrorKind::InvalidInput, format!("frame of {} bytes", frame.len())));
        }
        if self.tx_busy.iter().all(|b| *b) {
            // Sends that completed and were not reaped yet (a caller that never receives here).
            self.reap();
        }
        let slot = match self.tx_busy.iter().position(|b| !b) {
            Some(s) => s,
            None => {
                self.flush()?;
                self.ring.submit_and_wait(1)?;
                self.reap();
                self.tx_busy.iter().position(|b| !b).ok_or_else(|| io::Error::other("no transmit buffer free"))?
            }
        };
        let m = &mut self.tx[slot];
        m.data[..frame.len()].copy_from_slice(frame);
        m.addr.sll_addr[..6].copy_from_slice(&frame[..6.min(frame.len())]);
        m.iov.iov_len = frame.len();
        let fd = types::Fd(self.sock.fd.as_raw_fd());
        let stamped = self.sock.stamps != crate::Timestamps::None;
        let mut send = opcode::SendMsg::new(fd, &m.hdr).build().user_data(slot as u64);
        // Its transmit stamp is read right after it (the kernel stamps it on the way out), in
        // the same submission.
        let read_stamp = stamped && !self.err_armed;
        if read_stamp {
            send = send.flags(squeue::Flags::IO_LINK);
        }
        self.tx_busy[slot] = true;
        self.push(&send)?;
        self.tx_stamp = None;
        if stamped {
            self.sock.stamps_pending.set(self.sock.stamps_pending.get().saturating_add(1).min(4096));
        }
        if read_stamp {
            let hdr = self.err.arm_recv();
            let e = opcode::RecvMsg::new(fd, hdr)
                .flags((libc::MSG_ERRQUEUE | libc::MSG_DONTWAIT) as u32)
                .build()
                .user_data(ERR_TAG);
            self.err_armed = true;
            self.push(&e)?;
        }
        Ok(())
    }

    /// Submits what is queued without waiting.
    pub fn flush(&mut self) -> io::Result<()> {
        if self.unsubmitted > 0 {
            self.ring.submit()?;
            self.unsubmitted = 0;
        }
        Ok(())
    }

    fn arm_rx(&mut self) -> io::Result<()> {
        if self.rx_armed || self.rx_done.is_some() {
            return Ok(());
        }
        let hdr = self.rx.arm_recv();
        let e = opcode::RecvMsg::new(types::Fd(self.sock.fd.as_raw_fd()), hdr).build().user_data(RX_TAG);
        self.rx_armed = true;
        self.push(&e)
    }

    /// Takes the completions there are.
    pub(crate) fn reap(&mut self) {
        while let Some((tag, res)) = self.ring.completion().next().map(|c| (c.user_data(), c.result())) {
            match tag {
                RX_TAG => {
                    self.rx_armed = false;
                    // SAFETY: the completed receive filled the header and control it was given.
                    let stamp = if res >= 0 { unsafe { stamp_of(&self.rx.hdr) } } else { None };
                    self.rx_done = Some((res, stamp, self.rx.hdr.msg_flags & libc::MSG_TRUNC != 0));
                }
                ERR_TAG => {
                    self.err_armed = false;
                    if res >= 0 {
                        // SAFETY: as above, for the error queue's message.
                        if let Some(t) = unsafe { stamp_of(&self.err.hdr) } {
                            self.tx_stamp = Some(t);
                        }
                        let p = self.sock.stamps_pending.get();
                        self.sock.stamps_pending.set(p.saturating_sub(1));
                    }
                }
                slot => {
                    if let Some(b) = self.tx_busy.get_mut(slot as usize) {
                        *b = false;
                    }
                    // A send cancelled with the thread that submitted it (below) is a frame
                    // lost, which the master's retries cover, not a broken link.
                    if res < 0 && res != -libc::ECANCELED && self.send_error.is_none() {
                        self.send_error = Some(io::Error::from_raw_os_error(-res));
                    }
                }
            }
        }
    }

    /// The next frame and its receive stamp, waiting until `deadline_ns` (CLOCK_MONOTONIC) at
    /// most; frames queued by [`send`](Self::send) leave first, in the same system call.
    pub fn recv(&mut self, buf: &mut [u8], deadline_ns: u64) -> io::Result<Option<(usize, Option<u64>)>> {
        loop {
            self.reap();
            if let Some(e) = self.send_error.take() {
                return Err(io::Error::new(e.kind(), format!("send: {e}")));
            }
            if let Some((res, stamp, cut)) = self.rx_done.take() {
                // Copied out before the receive is armed again: arming may submit it.
                let got = match res {
                    ..0 => Err(io::Error::from_raw_os_error(-res)),
                    n if cut || n as usize > buf.len() => Ok(None),
                    n => {
                        buf[..n as usize].copy_from_slice(&self.rx.data[..n as usize]);
                        Ok(Some((n as usize, stamp)))
                    }
                };
                self.arm_rx()?;
                match got {
                    Ok(Some(frame)) => return Ok(Some(frame)),
                    Ok(None) => self.truncated += 1,
                    Err(e) if matches!(e.kind(), io::ErrorKind::WouldBlock | io::ErrorKind::Interrupted) => {}
                    // io_uring cancels a task's requests when the thread that submitted them
                    // exits: the socket went on in another thread (an application's cyclic
                    // thread ended), and the receive is armed again from this one.
                    Err(e) if e.raw_os_error() == Some(libc::ECANCELED) => {}
                    Err(e) => return Err(e),
                }
                continue;
            }
            self.arm_rx()?;
            let now = crate::monotonic_ns();
            if now >= deadline_ns {
                self.flush()?;
                return Ok(None);
            }
            let wait = deadline_ns - now;
            let ts = types::Timespec::new().sec(wait / 1_000_000_000).nsec((wait % 1_000_000_000) as u32);
            let args = types::SubmitArgs::new().timespec(&ts);
            // Sends and stamp reads complete as they are submitted: wait for those and for
            // one more, the answer (waiting for 1 returned at the first send's completion, a
            // second system call per cycle).
            let outstanding = self.tx_busy.iter().filter(|b| **b).count() + usize::from(self.err_armed);
            match self.ring.submitter().submit_with_args(outstanding + 1, &args) {
                Ok(_) => self.unsubmitted = 0,
                Err(e) if matches!(e.raw_os_error(), Some(libc::ETIME) | Some(libc::EINTR)) => self.unsubmitted = 0,
                Err(e) if e.raw_os_error() == Some(libc::EBUSY) => self.reap(),
                Err(e) => return Err(e),
            }
        }
    }

    /// The transmit stamp of the last frame sent, once it has left (after the receive that
    /// sent it); stamps the ring did not read are drained from the socket (a system call).
    pub fn tx_timestamp(&mut self) -> Option<u64> {
        self.reap();
        if self.sock.stamps_pending.get() == 0 {
            return self.tx_stamp;
        }
        let older = self.tx_stamp;
        self.sock.tx_timestamp().or(older)
    }
}

impl Drop for UringSocket {
    fn drop(&mut self) {
        // The kernel may still hold pointers into the buffers: wait for every request.
        let _ = self.flush();
        if self.rx_armed {
            let cancel = opcode::AsyncCancel::new(RX_TAG).build().user_data(u64::MAX);
            // SAFETY: a cancel request points at nothing of ours.
            let _ = unsafe { self.ring.submission().push(&cancel) };
        }
        for _ in 0..100 {
            self.reap();
            if !self.rx_armed && !self.err_armed && !self.tx_busy.iter().any(|b| *b) {
                return;
            }
            let ts = types::Timespec::new().nsec(10_000_000);
            let _ = self.ring.submitter().submit_with_args(1, &types::SubmitArgs::new().timespec(&ts));
        }
        // Requests that never completed: leak their buffers rather than free memory the kernel
        // may write.
        std::mem::forget(std::mem::take(&mut self.tx));
        std::mem::forget(std::mem::replace(&mut self.rx, Msg::new()));
        std::mem::forget(std::mem::replace(&mut self.err, Msg::new()));
    }
}
