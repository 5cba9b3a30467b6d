#![deny(missing_docs)]
//! The master's view of the world: its clock and its frames. A real network interface
//! (`ferrocat-link`), the virtual segment (`ferrocat-segment`), a recording or a faulty link all
//! plug into the master through this one trait, which compiles nothing else.

/// Time and frames. All times are ns of the world's clock (CLOCK_MONOTONIC in real time).
pub trait Io {
    /// The world's clock now.
    fn now_ns(&mut self) -> u64;
    /// Sends one Ethernet frame (without FCS).
    fn send(&mut self, frame: &[u8]) -> std::io::Result<()>;
    /// The next received frame, waiting until `deadline_ns` at most: its length and receive time.
    fn recv(&mut self, buf: &mut [u8], deadline_ns: u64) -> std::io::Result<Option<(usize, u64)>>;
    /// Sleeps until `t_ns` (absolute); the world may wake late.
    fn sleep_until(&mut self, t_ns: u64);
    /// The instant the last [`Io::sleep_until`] aimed at: where a caller sleeps to its
    /// schedule, the planned start of the cycle that woke (however late it woke).
    fn wake_target_ns(&self) -> Option<u64> {
        None
    }
    /// When the last frame sent actually left, if the world knows (a kernel or NIC timestamp).
    fn last_tx_ns(&mut self) -> Option<u64> {
        None
    }
    /// Receive times mark the start of the frame (a NIC stamp) rather than its end.
    fn rx_stamps_start_of_frame(&self) -> bool {
        false
    }
    /// Virtual time (deterministic) rather than a real clock.
    fn is_virtual(&self) -> bool {
        false
    }
    /// The granularity of the host's timer: a master that follows a clock rounds its periods
    /// to it (Chen 2016's Algorithm 1).
    fn timer_resolution_ns(&self) -> u64 {
        1
    }
    /// The master has a second port (cable redundancy): the segment is a ring, closed back to
    /// it, and the engine sends through both.
    fn has_secondary(&self) -> bool {
        false
    }
    /// Sends one Ethernet frame from the secondary port.
    fn send_secondary(&mut self, _frame: &[u8]) -> std::io::Result<()> {
        Err(std::io::Error::new(std::io::ErrorKind::Unsupported, "this link has no secondary port"))
    }
    /// Whether the frame the last [`Io::recv`] returned came in on the secondary port.
    fn last_rx_secondary(&self) -> bool {
        false
    }
    /// [`Io::last_tx_ns`] of the secondary port.
    fn last_tx_secondary_ns(&mut self) -> Option<u64> {
        None
    }
    /// Drives the host's calibration output (a GPIO wired to a slave's LATCH input) to
    /// `level`; the pin changes one output latency after the call. Unsupported where the host
    /// has no such output or nothing is wired to it.
    fn set_gpio(&mut self, _level: bool) -> std::io::Result<()> {
        Err(std::io::Error::new(std::io::ErrorKind::Unsupported, "this host has no calibration output"))
    }
}
