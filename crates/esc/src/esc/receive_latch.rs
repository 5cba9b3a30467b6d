//! Which frame each receive-time latch 0x0900–0x090F takes (esc-spec 0x0900, 0x0936).
//!
//! Port 0 always takes the frame that carries the write to 0x0900. Ports 1–3 differ by
//! controller: an ET1100 takes that same frame also where it passed the port before the
//! processing unit saw the write (an ESC entered elsewhere than on port 0); an ET1200 or
//! ESC20 only enables its ports 1–3, each of which takes the first frame it receives after;
//! the IP core does the latter in forwarding mode and in reverse mode takes the last frame each
//! port received before the write. A frame a port received before the processing unit saw
//! the write is, for the last two, not the writing frame.
use super::{Esc, FrameTiming};
use crate::config::ReceiveLatch;

impl Esc {
    /// The IP core's receive time latch mode 0x0936 bit 0: reverse mode.
    fn reverse_mode(&self) -> bool {
        self.config.receive_latch == ReceiveLatch::Selectable && self.mem[0x0936] & 1 != 0
    }

    /// Port `port`'s latch takes the local time at true time `at_ns`.
    fn put_receive_time(&mut self, port: usize, at_ns: u64) {
        if let Some(v) = self.dc.as_ref().map(|dc| dc.local_at(at_ns) as u32) {
            self.set_receive_time(port, v);
        }
    }

    fn set_receive_time(&mut self, port: usize, local: u32) {
        self.mem[0x0900 + 4 * port..0x0904 + 4 * port].copy_from_slice(&local.to_le_bytes());
    }

    /// Ports 1–3 that received the frame in `range` (relative times): an enabled one takes
    /// it, and the IP core notes it for reverse mode.
    fn receptions(&mut self, timing: &FrameTiming, origin_ns: u64, range: std::ops::Range<u64>) {
        let notes = self.config.receive_latch == ReceiveLatch::Selectable;
        if self.rx_armed == 0 && !notes {
            return;
        }
        for p in 1..4 {
            let Some(at) = timing.port_ns[p].filter(|at| range.contains(at)) else { continue };
            if notes {
                if let Some(dc) = &self.dc {
                    self.rx_hidden[p] = dc.local_at(at + origin_ns) as u32;
                }
            }
            if self.rx_armed & (1 << p) != 0 {
                self.rx_armed &= !(1 << p);
                self.put_receive_time(p, at + origin_ns);
            }
        }
    }

    /// The frame's receptions before its processing unit, before its datagrams are processed
    /// (a read in this frame sees what they latched).
    pub(super) fn receptions_before_epu(&mut self, timing: &FrameTiming, origin_ns: u64) {
        self.receptions(timing, origin_ns, 0..timing.epu_ns);
    }

    /// A frame that passed this ESC's ports without reaching its processing unit (the ring's
    /// frames in the forwarding direction).
    pub fn frame_passed(&mut self, timing: &FrameTiming, origin_ns: u64) {
        self.receptions(timing, origin_ns, 0..u64::MAX);
    }

    /// At the end of the frame: the latch of a write to 0x0900 (`write`: by BWR or FPWR,
    /// which latches an ET1100 or the IP core; `any_write`: by any command, which latches an
    /// ET1200 or ESC20), then the frame's receptions after the processing unit.
    pub(super) fn latch_receive_times(&mut self, timing: &FrameTiming, origin_ns: u64, write: bool, any_write: bool) {
        if self.dc.is_none() {
            return;
        }
        let latch = match self.config.receive_latch {
            ReceiveLatch::NextFrame => any_write,
            _ => write,
        };
        if latch {
            match self.config.receive_latch {
                ReceiveLatch::ThisFrame => {
                    // Ports the frame did not reach keep their old value (esc-spec §3.3).
                    for p in 0..4 {
                        if let Some(at) = timing.port_ns[p] {
                            self.put_receive_time(p, at + origin_ns);
                        }
                    }
                }
                _ => {
                    if let Some(at) = timing.port_ns[0] {
                        self.put_receive_time(0, at + origin_ns);
                    }
                    if self.reverse_mode() {
                        for p in 1..4 {
                            self.set_receive_time(p, self.rx_hidden[p]);
                        }
                    } else {
                        self.rx_armed = (1..4u8).filter(|&p| self.config.has_port(p)).fold(0, |m, p| m | 1 << p);
                    }
                }
            }
        }
        self.receptions(timing, origin_ns, timing.epu_ns..u64::MAX);
    }
}
