//! Where a Python master's frames go: the in-process virtual segment, a raw interface, or
//! EtherCAT over UDP. One enum, so that one Python class holds any of them.
use ferrocat_io::Io;
use ferrocat_master::io::{RawIo, UdpIo};
use ferrocat_segment::VirtualIo;

pub struct World {
    pub link: Link,
    /// Where the last sleep aimed, on a real clock: the master sizes a cycle's probes from it
    /// (`Io::wake_target_ns`), also where the cyclic loop's thread sleeps by itself
    /// ([`World::prepare_sleep`]).
    wake_target_ns: Option<u64>,
}

pub enum Link {
    Virtual(Box<VirtualIo>),
    Raw(RawIo),
    Udp(UdpIo),
}

impl World {
    pub fn new(link: Link) -> Self {
        World { link, wake_target_ns: None }
    }

    /// What a sleep to `t_ns` does before it sleeps (frames queued on io_uring sent, the wake
    /// target kept), for a thread that then sleeps without holding the master.
    pub fn prepare_sleep(&mut self, t_ns: u64) {
        if let Link::Raw(r) = &mut self.link {
            // A time past: RawIo sends what it queued and returns at once.
            r.sleep_until(0);
        }
        self.wake_target_ns = Some(t_ns);
    }
}

impl std::fmt::Debug for World {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.write_str(match self.link {
            Link::Virtual(_) => "virtual segment",
            Link::Raw(_) => "raw socket",
            Link::Udp(_) => "UDP",
        })
    }
}

impl World {
    fn io(&self) -> &dyn Io {
        match &self.link {
            Link::Virtual(v) => &**v,
            Link::Raw(r) => r,
            Link::Udp(u) => u,
        }
    }
    fn io_mut(&mut self) -> &mut dyn Io {
        match &mut self.link {
            Link::Virtual(v) => &mut **v,
            Link::Raw(r) => r,
            Link::Udp(u) => u,
        }
    }
    pub fn virtual_io(&mut self) -> Option<&mut VirtualIo> {
        match &mut self.link {
            Link::Virtual(v) => Some(v),
            _ => None,
        }
    }
    pub fn virtual_ref(&self) -> Option<&VirtualIo> {
        match &self.link {
            Link::Virtual(v) => Some(v),
            _ => None,
        }
    }
}

/// Every call passes through to the world underneath.
impl Io for World {
    fn now_ns(&mut self) -> u64 {
        self.io_mut().now_ns()
    }
    fn send(&mut self, frame: &[u8]) -> std::io::Result<()> {
        self.io_mut().send(frame)
    }
    fn recv(&mut self, buf: &mut [u8], deadline_ns: u64) -> std::io::Result<Option<(usize, u64)>> {
        self.io_mut().recv(buf, deadline_ns)
    }
    fn sleep_until(&mut self, t_ns: u64) {
        if !matches!(self.link, Link::Virtual(_)) {
            self.wake_target_ns = Some(t_ns);
        }
        self.io_mut().sleep_until(t_ns)
    }
    fn wake_target_ns(&self) -> Option<u64> {
        // A virtual world counts its own cycle slots.
        match self.link {
            Link::Virtual(_) => self.io().wake_target_ns(),
            _ => self.wake_target_ns,
        }
    }
    fn last_tx_ns(&mut self) -> Option<u64> {
        self.io_mut().last_tx_ns()
    }
    fn rx_stamps_start_of_frame(&self) -> bool {
        self.io().rx_stamps_start_of_frame()
    }
    fn is_virtual(&self) -> bool {
        self.io().is_virtual()
    }
    fn timer_resolution_ns(&self) -> u64 {
        self.io().timer_resolution_ns()
    }
    fn has_secondary(&self) -> bool {
        self.io().has_secondary()
    }
    fn send_secondary(&mut self, frame: &[u8]) -> std::io::Result<()> {
        self.io_mut().send_secondary(frame)
    }
    fn last_rx_secondary(&self) -> bool {
        self.io().last_rx_secondary()
    }
    fn last_tx_secondary_ns(&mut self) -> Option<u64> {
        self.io_mut().last_tx_secondary_ns()
    }
    fn set_gpio(&mut self, level: bool) -> std::io::Result<()> {
        self.io_mut().set_gpio(level)
    }
}
