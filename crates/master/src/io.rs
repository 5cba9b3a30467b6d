//! The links the master runs on in real time: a raw socket on a network interface, or
//! EtherCAT over UDP. Anything else (the virtual segment, a recording) plugs in through the
//! [`Io`] trait.
pub use ferrocat_io::Io;

/// How a [`RawIo`] moves its frames.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
pub enum LinkPath {
    /// io_uring where the kernel allows it, else the socket calls (and a log line says why).
    #[default]
    Auto,
    /// io_uring: the frames sent leave with the wait for the answer, one system call per
    /// exchange; an error where it is not available.
    Uring,
    /// The socket calls: a `sendto` per frame and a `recvmsg` per answer, and a read of the
    /// transmit stamp.
    Socket,
    /// A PACKET_MMAP receive ring: a receive spins on the ring for up to `spin_ns` before it
    /// sleeps, so that an answer met within the spin costs no system call; frames go out
    /// with `sendto`. The spin holds the CPU: for a core of the master's own. An error where
    /// the kernel refuses the ring.
    Ring {
        /// How long a receive spins before it sleeps, ns.
        spin_ns: u64,
    },
}

#[derive(Debug)]
enum Port {
    Socket(ferrocat_link::RawSocket),
    Uring(Box<ferrocat_link::UringSocket>),
    Ring(Box<ferrocat_link::RingSocket>),
}

/// Real time on a network interface through an AF_PACKET raw socket, with kernel (or NIC)
/// timestamps where available, driven through io_uring where the kernel allows it
/// ([`LinkPath`]). On io_uring a frame sent leaves with the next receive or sleep.
#[derive(Debug)]
pub struct RawIo {
    port: Port,
    /// The second port of a ring (cable redundancy).
    secondary: Option<ferrocat_link::RawSocket>,
    last_rx_secondary: bool,
    wake_target_ns: Option<u64>,
    /// Each port's last transmit stamp, taken once from the socket's queue (which reading
    /// drains) and kept until that port sends again, so that it can be asked twice.
    tx_stamps: [Option<u64>; 2],
}

impl RawIo {
    /// A raw socket on the interface `iface` (needs root or CAP_NET_RAW), on io_uring where
    /// the kernel allows it.
    pub fn open(iface: &str) -> std::io::Result<Self> {
        Self::open_with(iface, LinkPath::Auto)
    }

    /// A raw socket on `iface`, moving frames by `path`.
    pub fn open_with(iface: &str, path: LinkPath) -> std::io::Result<Self> {
        let sock = ferrocat_link::RawSocket::open(iface)?;
        let port = match path {
            LinkPath::Socket => Port::Socket(sock),
            LinkPath::Ring { spin_ns } => Port::Ring(Box::new(ferrocat_link::RingSocket::new(sock, spin_ns)?)),
            LinkPath::Uring => Port::Uring(Box::new(ferrocat_link::UringSocket::new(sock).map_err(|(e, _)| e)?)),
            LinkPath::Auto => match ferrocat_link::UringSocket::new(sock) {
                Ok(u) => Port::Uring(Box::new(u)),
                Err((e, sock)) => {
                    tracing::info!("{iface}: io_uring not available ({e}); socket calls instead");
                    Port::Socket(sock)
                }
            },
        };
        Ok(RawIo { port, secondary: None, last_rx_secondary: false, tx_stamps: [None; 2], wake_target_ns: None })
    }

    /// Both ports of a ring: the line starts at `primary`, its far end comes back to
    /// `secondary` (socket calls: the two ports are waited on together).
    pub fn open_redundant(primary: &str, secondary: &str) -> std::io::Result<Self> {
        let mut io = RawIo::open_with(primary, LinkPath::Socket)?;
        io.secondary = Some(ferrocat_link::RawSocket::open(secondary)?);
        Ok(io)
    }

    fn sock(&self) -> &ferrocat_link::RawSocket {
        match &self.port {
            Port::Socket(s) => s,
            Port::Uring(u) => u.socket(),
            Port::Ring(r) => r.socket(),
        }
    }

    /// Which timestamps are in use, in words.
    pub fn timestamps(&self) -> &'static str {
        self.sock().timestamps().describe()
    }

    /// How frames move: "io_uring", "socket calls", "a packet ring" (sending through
    /// io_uring) or "a packet ring, sending with sendto" (io_uring refused).
    pub fn path(&self) -> &'static str {
        match &self.port {
            Port::Socket(_) => "socket calls",
            Port::Uring(_) => "io_uring",
            Port::Ring(r) if r.sends_through_io_uring() => "a packet ring",
            Port::Ring(_) => "a packet ring, sending with sendto (io_uring not available)",
        }
    }
}

impl Io for RawIo {
    fn now_ns(&mut self) -> u64 {
        ferrocat_link::monotonic_ns()
    }
    fn send(&mut self, frame: &[u8]) -> std::io::Result<()> {
        self.tx_stamps[0] = None;
        match &mut self.port {
            Port::Socket(s) => s.send(frame),
            Port::Uring(u) => u.send(frame),
            Port::Ring(r) => r.send(frame),
        }
    }
    fn recv(&mut self, buf: &mut [u8], deadline_ns: u64) -> std::io::Result<Option<(usize, u64)>> {
        let sock = match &mut self.port {
            Port::Uring(u) => {
                return Ok(u.recv(buf, deadline_ns)?.map(|(n, t)| (n, t.unwrap_or_else(ferrocat_link::monotonic_ns))))
            }
            Port::Ring(r) => {
                return Ok(r.recv(buf, deadline_ns)?.map(|(n, t)| (n, t.unwrap_or_else(ferrocat_link::monotonic_ns))))
            }
            Port::Socket(s) => &*s,
        };
        // Waited for in `ppoll`, to the deadline's microsecond: a blocking receive's timeout
        // (SO_RCVTIMEO) runs on the scheduler's tick, and would give a lost frame up 4-7 ms
        // after a 1 ms deadline on a 250 Hz kernel (docs/benchmarks.md).
        let socks: &[&ferrocat_link::RawSocket] = match &self.secondary {
            Some(sec) => &[sock, sec],
            None => &[sock],
        };
        loop {
            let now = ferrocat_link::monotonic_ns();
            if now >= deadline_ns {
                return Ok(None);
            }
            // Transmit stamps queued would end the wait at once: taken first, and kept for
            // `last_tx_ns`.
            for (k, s) in socks.iter().enumerate() {
                if let Some(t) = s.tx_timestamp() {
                    self.tx_stamps[k] = Some(t);
                }
            }
            let ready = &mut [false; 2][..socks.len()];
            ferrocat_link::RawSocket::wait_readable_into(socks, deadline_ns - now, ready)?;
            for (k, s) in socks.iter().enumerate() {
                if !ready[k] {
                    continue;
                }
                // An error (the interface gone) is returned by the read.
                if let Some((n, stamp)) = s.try_recv_stamped(buf)? {
                    self.last_rx_secondary = k == 1;
                    return Ok(Some((n, stamp.unwrap_or_else(ferrocat_link::monotonic_ns))));
                }
                if let Some(t) = s.drain_error_queue() {
                    self.tx_stamps[k] = Some(t);
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
        if let Port::Uring(u) = &mut self.port {
            // Frames sent leave before the sleep, not after it.
            if let Err(e) = u.flush() {
                tracing::warn!("sending before a sleep: {e}");
            }
        }
        self.wake_target_ns = Some(t_ns);
        ferrocat_link::sleep_until_ns(t_ns);
    }
    fn wake_target_ns(&self) -> Option<u64> {
        self.wake_target_ns
    }
    fn last_tx_ns(&mut self) -> Option<u64> {
        let t = match &mut self.port {
            Port::Socket(s) => s.tx_timestamp(),
            Port::Uring(u) => u.tx_timestamp(),
            Port::Ring(r) => r.tx_timestamp(),
        };
        if let Some(t) = t {
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
        // Receives wait in `ppoll` (see `recv`), then take what came without blocking.
        sock.set_nonblocking(true)?;
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
        if buf.len() < 15 {
            return Ok(None);
        }
        // Waited for in `ppoll`, to the deadline's microsecond (a read timeout runs on the
        // scheduler's tick).
        use std::os::fd::AsFd;
        loop {
            let now = ferrocat_link::monotonic_ns();
            if now >= deadline_ns {
                return Ok(None);
            }
            if !ferrocat_link::wait_fd_readable(self.sock.as_fd(), deadline_ns - now)? {
                continue;
            }
            match self.sock.recv(&mut buf[14..]) {
                Ok(n) => {
                    buf[..12].fill(0xFF);
                    buf[12..14].copy_from_slice(&ferrocat_wire::ETHERTYPE_ETHERCAT.to_be_bytes());
                    return Ok(Some((14 + n, ferrocat_link::monotonic_ns())));
                }
                Err(e) if matches!(e.kind(), std::io::ErrorKind::WouldBlock | std::io::ErrorKind::Interrupted) => {}
                Err(e) => return Err(e),
            }
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
