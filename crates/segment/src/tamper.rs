//! A world whose received frames pass through a hook first: a faulty or hostile device, or a
//! corrupting link, for tests and fuzzing.
use ferrocat_io::Io;

/// `inner` with `hook(frame, len, on_secondary)` applied to every frame received: it may
/// change the bytes and returns the length to deliver (shorter: cut), or `None` to drop the
/// frame (the next one, or the deadline, is waited for).
#[derive(Debug)]
pub struct Tamper<I, F> {
    pub inner: I,
    pub hook: F,
}

impl<I: Io, F: FnMut(&mut [u8], usize, bool) -> Option<usize>> Io for Tamper<I, F> {
    fn now_ns(&mut self) -> u64 {
        self.inner.now_ns()
    }
    fn send(&mut self, frame: &[u8]) -> std::io::Result<()> {
        self.inner.send(frame)
    }
    fn recv(&mut self, buf: &mut [u8], deadline_ns: u64) -> std::io::Result<Option<(usize, u64)>> {
        loop {
            let Some((n, t)) = self.inner.recv(buf, deadline_ns)? else { return Ok(None) };
            let secondary = self.inner.last_rx_secondary();
            if let Some(len) = (self.hook)(buf, n, secondary) {
                return Ok(Some((len.min(n), t)));
            }
        }
    }
    fn sleep_until(&mut self, t_ns: u64) {
        self.inner.sleep_until(t_ns)
    }
    fn wake_target_ns(&self) -> Option<u64> {
        self.inner.wake_target_ns()
    }
    fn last_tx_ns(&mut self) -> Option<u64> {
        self.inner.last_tx_ns()
    }
    fn rx_stamps_start_of_frame(&self) -> bool {
        self.inner.rx_stamps_start_of_frame()
    }
    fn is_virtual(&self) -> bool {
        self.inner.is_virtual()
    }
    fn timer_resolution_ns(&self) -> u64 {
        self.inner.timer_resolution_ns()
    }
    fn has_secondary(&self) -> bool {
        self.inner.has_secondary()
    }
    fn send_secondary(&mut self, frame: &[u8]) -> std::io::Result<()> {
        self.inner.send_secondary(frame)
    }
    fn last_rx_secondary(&self) -> bool {
        self.inner.last_rx_secondary()
    }
    fn last_tx_secondary_ns(&mut self) -> Option<u64> {
        self.inner.last_tx_secondary_ns()
    }
    fn set_gpio(&mut self, level: bool) -> std::io::Result<()> {
        self.inner.set_gpio(level)
    }
}
