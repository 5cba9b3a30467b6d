//! A ring already split when the master latches its receive times (cable redundancy).
//!
//! The latching frame goes round each half from its own port: the near half from the primary,
//! the far half from the secondary a whole master round trip later, entered at the far end.
//! No frame passes both, so the far half's delays cannot be the reference's: they are taken
//! from the far reference (its first clock, which reads the second pass's FRMW), a tree of
//! their own rooted where the secondary's cable comes in. What ties the halves together is the
//! master, which timed both passes: with the loops behind the reference and behind the far
//! root (from the latched receive times) the passes' stamps give how much later the far
//! reference took the frame than the reference did — the far half's offsets are written for
//! that instant — and what a cyclic frame's two passes measure when both clocks agree (the
//! anchor a ring that split under the master learns from the break instead).
//!
//! Once DC is set up, every port is auto-close, so that the ring cannot close behind the
//! master's back; the master watches the DL status, and when the cable at the break is back
//! it opens the ring itself and latches the far half again from the reference, as a line whose
//! end is the port the secondary's cable comes in by, and writes its delays before any clock
//! goes round.
use ferrocat_wire::register::addr;
use ferrocat_wire::register::DlStatus;
use ferrocat_wire::{Address, Command};

use super::Master;
use crate::engine::{Pdu, RingState, SplitPasses};
use crate::error::Result;
use crate::io::Io;

/// How often the master reads the slaves' DL status for the break's link, and how many per
/// frame.
const WATCH_EVERY_NS: u64 = 100_000_000;
const WATCH_CHUNK: usize = 32;
/// Loop control 0x0101: every port auto-close (01), or auto (00).
const AUTO_CLOSE: u8 = 0x55;
const AUTO: u8 = 0x00;

/// What the latch of a split ring found.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct SplitLatch {
    /// The first position behind the break: the far half is it and those after it.
    pub first_far: usize,
    /// The far half's root (the slave the secondary's cable reaches) and its entry port.
    pub root: usize,
    /// The port of the far root the secondary's cable comes in by.
    pub root_port: u8,
    /// The far reference (the far half's first slave with a system time), if any.
    pub far_reference: Option<usize>,
    /// What a frame's two passes measure (the far reference's FRMW reading less the
    /// reference's, less the master's time from the first pass's mid-point to the second's)
    /// when the two clocks agree: half the loop behind the reference less half the loop
    /// behind the far root, plus the far reference's processing after the root's entry.
    pub anchor_ns: i64,
    /// The latching frame's two passes.
    pub passes: Option<SplitPasses>,
    /// Watched (DC set up for the split): every port is auto-close, and the master next
    /// looks for the break's link at this time (docs/master.md, "Cable redundancy").
    pub watch_next_ns: Option<u64>,
}

impl SplitLatch {
    /// How much later (master ns) the far reference took the latching frame than the
    /// reference did.
    pub fn far_lag_ns(&self) -> Option<i64> {
        let (near, far) = self.passes?.mid_points_ns();
        Some((far.wrapping_sub(near) as i64).wrapping_add(self.anchor_ns))
    }
}

impl<I: Io> Master<I> {
    /// What a latch that went round both halves found: `view` and `epu_at` (each DC slave's
    /// processing unit after its tree's root's entry) as the delay computation has them,
    /// `reference` the first clock, `first_far` the first position behind the break.
    pub(super) fn split_latch_of(
        &self,
        view: &[crate::topology::PortView],
        epu_at: &[Option<i64>],
        reference: Option<usize>,
        first_far: usize,
        passes: Option<SplitPasses>,
    ) -> SplitLatch {
        let n = self.slaves.len();
        // The frame's way in and out of each half, less the loops behind the reference and
        // behind the far root (a closed port's loop-back after the last latch counted).
        let way_back = |k: usize| {
            view[k].span_ns().unwrap_or(0) + view[k].loops_after_last_event() * self.settings.closed_port_loop_ns as i64
        };
        let near = reference.map_or(0, way_back);
        let root = (first_far..n).find(|&k| self.slaves[k].ports.parent.is_none()).unwrap_or(first_far);
        let far_reference = (first_far..n).find(|&k| self.slaves[k].dc.has_system_time);
        let far_at = far_reference.and_then(|r| epu_at[r]).unwrap_or(0);
        SplitLatch {
            first_far,
            root,
            root_port: self.slaves[root].ports.entry,
            far_reference,
            anchor_ns: (near - way_back(root)) / 2 + far_at,
            passes,
            watch_next_ns: None,
        }
    }

    /// On a broken ring, the first position behind the break (the second passes reach it and
    /// those after it).
    pub(crate) fn first_far_position(&self) -> Option<usize> {
        let (n, far) = (self.slaves.len(), self.engine.redundancy.far_half_slaves as usize);
        let split = self.engine.io.has_secondary() && self.engine.redundancy.state == RingState::Broken;
        (split && far > 0 && far < n).then_some(n - far)
    }

    /// Adds `shift_ns` to the offset of every clock of the far half, `last` the last of them
    /// (the others follow it through their loops meanwhile); whether `last`'s moved.
    pub(crate) fn shift_far_half(&mut self, shift_ns: i64, last: Option<u16>) -> bool {
        let first_far = self.split_latch.as_ref().map_or(self.slaves.len(), |l| l.first_far);
        for k in first_far..self.slaves.len() {
            let (clock, st) = (self.slaves[k].dc.has_system_time, self.slaves[k].station);
            if clock && Some(st) != last {
                let _ = self.shift_offset(st, shift_ns);
            }
        }
        last.is_some_and(|st| self.shift_offset(st, shift_ns).is_ok())
    }

    /// Once the far half's clocks are set up for a split, the ring must not close behind
    /// the master's back: the first frame round it would give the far half the reference's
    /// time with delays from the far reference (805 ns off on the test ring, one sample that
    /// took the far coupler 263 ns away). Every port goes to auto-close, so that a link that
    /// comes back leaves its ports closed until the master opens them
    /// ([`Master::watch_split`]).
    pub(crate) fn arm_split_watch(&mut self) -> Result<()> {
        if self.split_latch.is_none() {
            return Ok(());
        }
        self.engine.one(Command::BWR, Address::Device { adp: 0, ado: addr::LOOP_CONTROL }, &mut [AUTO_CLOSE])?;
        let now = self.engine.io.now_ns();
        if let Some(l) = self.split_latch.as_mut() {
            l.watch_next_ns = Some(now);
        }
        Ok(())
    }

    /// While a ring split from the start is watched, every [`WATCH_EVERY_NS`] the slaves' DL
    /// status: a link on a port the latch found without one is the cable at the break back
    /// (or a new one). The master then opens the ports (loop control written again round both
    /// halves, auto from now on), sees the ring whole with a frame that carries no clock, and
    /// latches the far half again from the reference before the next cyclic frame. A ring
    /// still split (another cable came back) is watched on.
    pub(crate) fn watch_split(&mut self) -> Result<()> {
        let Some(next) = self.split_latch.as_ref().and_then(|l| l.watch_next_ns) else { return Ok(()) };
        let now = self.engine.io.now_ns();
        if now < next {
            return Ok(());
        }
        if let Some(l) = self.split_latch.as_mut() {
            l.watch_next_ns = Some(now.saturating_add(WATCH_EVERY_NS));
        }
        // A frame lost is tried again at the next look.
        let mut back = false;
        let read = self.each_dl_status(true, |s, d, answered| {
            back |= answered && (0..4u8).any(|p| d.physical_link(p) && !s.ports.active[p as usize]);
        });
        if read.is_err() {
            return Ok(());
        }
        if !back {
            return Ok(());
        }
        self.engine.one(Command::BWR, Address::Device { adp: 0, ado: addr::LOOP_CONTROL }, &mut [AUTO])?;
        self.engine.one(Command::BRD, Address::Device { adp: 0, ado: 0 }, &mut [0u8; 2])?;
        if self.engine.redundancy.state == RingState::Intact {
            self.rejoin_far_half()
        } else {
            self.engine.one(Command::BWR, Address::Device { adp: 0, ado: addr::LOOP_CONTROL }, &mut [AUTO_CLOSE])?;
            Ok(())
        }
    }

    /// Every slave's DL status (0x0110), up to [`WATCH_CHUNK`] slaves a frame, read into the
    /// stack (the watch runs among the cycles, which allocate nothing): `each` gets the slave,
    /// its status and whether it answered. A cyclic look sends each frame once, within the
    /// cyclic timeout; otherwise lost frames are sent again.
    fn each_dl_status(
        &mut self,
        cyclic: bool,
        mut each: impl FnMut(&mut crate::slave::Slave, DlStatus, bool),
    ) -> Result<()> {
        for first in (0..self.slaves.len()).step_by(WATCH_CHUNK) {
            let count = WATCH_CHUNK.min(self.slaves.len() - first);
            let mut dl = [[0u8; 2]; WATCH_CHUNK];
            let mut bufs = dl.iter_mut();
            let mut pdus: [Pdu<'_>; WATCH_CHUNK] = std::array::from_fn(|i| {
                let station = self.slaves.get(first + i).map_or(0, |s| s.station);
                Pdu::new(
                    Command::FPRD,
                    Address::Device { adp: station, ado: addr::DL_STATUS },
                    bufs.next().map_or(&mut [][..], |b| &mut b[..]),
                )
            });
            if cyclic {
                self.engine.transact_once(&mut pdus[..count], self.settings.cyclic_timeout_ns)?;
            } else {
                self.engine.transact(&mut pdus[..count])?;
            }
            let answered: [bool; WATCH_CHUNK] = std::array::from_fn(|i| pdus[i].wkc == 1);
            for i in 0..count {
                each(&mut self.slaves[first + i], DlStatus(u16::from_le_bytes(dl[i])), answered[i]);
            }
        }
        Ok(())
    }

    /// The ring closed after a latch that found it split: the far half's delays are latched
    /// again from the reference, the ring's port closed as on a line's end (it is the far
    /// root's entry), and written; the shortening of the intact ring measured. The clocks
    /// keep their offsets: the far half was kept on the reference's time meanwhile.
    pub(crate) fn rejoin_far_half(&mut self) -> Result<()> {
        let Some(l) = self.split_latch.take() else { return Ok(()) };
        if l.root >= self.slaves.len() {
            return Ok(());
        }
        if self.engine.redundancy.state != RingState::Intact {
            self.split_latch = Some(l);
            return Ok(());
        }
        // The ports at the break have their links again.
        let mut unanswered = None;
        self.each_dl_status(false, |s, d, answered| {
            if answered {
                s.ports.dl_status = d;
                s.ports.active = [0, 1, 2, 3].map(|p| d.port_active(p));
            } else {
                unanswered = unanswered.or(Some(s.position));
            }
        })?;
        if let Some(position) = unanswered {
            let name = self.slaves[position as usize].name.clone();
            return Err(crate::error::MasterError::Wkc {
                datagram: crate::error::DatagramRef {
                    command: Command::FPRD,
                    address: Address::Device { adp: self.slaves[position as usize].station, ado: addr::DL_STATUS },
                    len: 2,
                },
                expected: 1,
                got: 0,
                slaves: format!(": slave {position} ({name})"),
            });
        }
        self.ring_port = Some((l.root as u16, l.root_port));
        self.slaves[l.root].ports.active[l.root_port as usize] = false;
        self.latch_and_measure_delays()?;
        for k in l.first_far..self.slaves.len() {
            let s = &self.slaves[k];
            if s.dc.has_system_time {
                let (st, delay) = (s.station, s.dc.delay_ns);
                self.fpwr(st, addr::DC_SYSTEM_TIME_DELAY, &delay.to_le_bytes())?;
            }
        }
        let st = self.slaves[l.root].station;
        self.measure_ring_shortening(st, l.root_port, super::delays::REJOIN_SHORTENING_TRIPS)
    }
}
