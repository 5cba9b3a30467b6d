//! How the slaves are wired and the propagation delays between them (esc-spec §3.6).
use ferrocat_wire::register::addr;
use ferrocat_wire::register::PortDescriptor;
use ferrocat_wire::{Address, Command};

use super::Master;
use crate::engine::Pdu;
use crate::error::{MasterError, Result};
use crate::io::Io;

/// Round trips each way for the ring's shortening at the scan: `pc-rt`'s software stamps
/// scatter round trips by 430–550 ns, which left the difference of two medians of 32 307 ns
/// off in one lab run (its standard error ≈ 150 ns; of 256 ≈ 55 ns), and every master −
/// reference error on that ring with it.
const SHORTENING_TRIPS: usize = 256;
/// When a ring split from the start closes, in cyclic operation: fewer, to keep the pause
/// short (the cycles wait for them).
pub(super) const REJOIN_SHORTENING_TRIPS: usize = 64;

impl<I: Io> Master<I> {
    /// Parents and ports: parsed from the processing order, the active ports, entry ports and
    /// receive times where known (crate::topology); counting ports as SOEM does where no tree
    /// fits or the segment is too long to parse.
    pub(super) fn topology(&mut self) -> bool {
        let view = self.port_views();
        if view.len() <= 1024 {
            let links = match self.first_far_position() {
                // A split ring: two trees, each hanging on its own port of the master.
                Some(f) => {
                    crate::topology::infer(&view[..f]).zip(crate::topology::infer(&view[f..])).map(|(near, far)| {
                        let far =
                            far.into_iter().map(|l| l.map(|l| crate::topology::Link { parent: l.parent + f, ..l }));
                        near.into_iter().chain(far).collect()
                    })
                }
                None => crate::topology::infer(&view),
            };
            if let Some(links) = links {
                for (s, l) in self.slaves.iter_mut().zip(links) {
                    s.ports.parent = l.map(|l| l.parent as u16);
                    s.ports.parent_port = l.map_or(0, |l| l.port);
                }
                return true;
            }
        }
        self.count_ports_topology();
        false
    }

    /// SOEM's inference: every entry on port 0, the processing order a pre-order walk.
    pub(super) fn count_ports_topology(&mut self) {
        let count = self.slaves.len();
        let topo: Vec<i32> = self.slaves.iter().map(|s| s.ports.active.iter().filter(|&&a| a).count() as i32).collect();
        for i in 1..count {
            let mut c = 0i32;
            let mut j = i - 1;
            loop {
                match topo[j] {
                    1 => c -= 1,
                    3 => c += 1,
                    4 => c += 2,
                    _ => {}
                }
                if (c >= 0 && topo[j] > 1) || j == 0 {
                    self.slaves[i].ports.parent = Some(j as u16);
                    break;
                }
                j -= 1;
            }
        }
        // A child hangs on its parent's next active port, in processing order after the entry.
        for p in 0..count {
            let children: Vec<usize> = (0..count).filter(|&c| self.slaves[c].ports.parent == Some(p as u16)).collect();
            let mut port = self.slaves[p].ports.entry;
            for c in children {
                for _ in 0..4 {
                    port = [3, 2, 0, 1][port as usize];
                    if self.slaves[p].ports.active[port as usize] && port != self.slaves[p].ports.entry {
                        break;
                    }
                }
                self.slaves[c].ports.parent_port = port;
            }
        }
    }

    /// On an intact ring (the primary's frames come back on the secondary port), finds the port
    /// they leave by: closing it by loop control (0x0101) turns them back to the primary with
    /// every slave's working counter, which no other port does (closing a branch drops its
    /// slaves, and the frame still goes round). Tried from the last slave back, ports 3, 1, 2
    /// (a slave's entry, port 0 on a ring cabled in order, is never closed: nothing could
    /// reopen it). That port is taken out of the tree, and closed again while receive times
    /// are latched so that they are a line's (delays are the forward path's, the same on the
    /// ring).
    pub(super) fn find_ring_port(&mut self) -> Result<()> {
        self.ring_port = None;
        self.ring_shortening_ns = 0;
        if !self.engine.io.has_secondary() || self.engine.redundancy.state != crate::engine::RingState::Intact {
            return Ok(());
        }
        let n = self.slaves.len() as u16;
        for k in (0..self.slaves.len()).rev() {
            for port in [3u8, 1, 2] {
                if !self.slaves[k].ports.active[port as usize] {
                    continue;
                }
                let st = self.slaves[k].station;
                let loop_control = self.close_port(st, port)?;
                let mut b = [0u8; 2];
                let wkc = self.engine.one(Command::BRD, Address::Device { adp: 0, ado: 0 }, &mut b)?;
                let turned = self.engine.redundancy.state == crate::engine::RingState::Line && wkc == n;
                self.reopen_port(st, loop_control)?;
                if turned {
                    self.ring_port = Some((k as u16, port));
                    self.slaves[k].ports.active[port as usize] = false;
                    return self.measure_ring_shortening(st, port, SHORTENING_TRIPS);
                }
            }
        }
        Ok(())
    }

    /// On a ring, closes the ring's port so that frames turn there as at a line's end (for a
    /// latch of the receive times); what [`Master::reopen_ring_port`] restores.
    fn close_ring_port(&mut self) -> Result<Option<(u16, u8)>> {
        let Some((k, port)) = self.ring_port else { return Ok(None) };
        let st = self.slaves[k as usize].station;
        Ok(Some((st, self.close_port(st, port)?)))
    }

    fn reopen_ring_port(&mut self, closed: Option<(u16, u8)>) -> Result<()> {
        match closed {
            Some((st, loop_control)) => self.reopen_port(st, loop_control),
            None => Ok(()),
        }
    }

    /// Closes `port` of the slave at `station` by loop control (0x0101): the ring turns there as
    /// a line's end. The probes cannot come back through it, so they are not waited for.
    /// Returns the loop control to restore with [`Master::reopen_port`].
    fn close_port(&mut self, station: u16, port: u8) -> Result<u8> {
        let mut loop_control = [0u8; 1];
        self.fprd(station, addr::LOOP_CONTROL, &mut loop_control)?;
        self.fpwr(station, addr::LOOP_CONTROL, &[loop_control[0] | 3 << (2 * port)])?;
        self.engine.expect_secondary(false);
        Ok(loop_control[0])
    }

    fn reopen_port(&mut self, station: u16, loop_control: u8) -> Result<()> {
        self.fpwr(station, addr::LOOP_CONTROL, &[loop_control])?;
        self.engine.expect_secondary(true);
        Ok(())
    }

    /// How much sooner the frame is back on the intact ring (at the secondary port) than it
    /// is on the line the ring's port makes when closed: the median of `trips` round trips of
    /// the same broadcast each way, by the link's stamps. A master that follows the reference
    /// times the reference's pass from the round trip less the loop behind it; on the ring the
    /// loop is this much shorter than the line's receive times say.
    pub(super) fn measure_ring_shortening(&mut self, station: u16, port: u8, trips: usize) -> Result<()> {
        let ring = self.dc().median_round_trip_ns(trips)?;
        let loop_control = self.close_port(station, port)?;
        let line = self.dc().median_round_trip_ns(trips);
        self.reopen_port(station, loop_control)?;
        self.ring_shortening_ns = line? - ring;
        Ok(())
    }

    /// Latches the receive times (BWR 0x0900) and computes every DC slave's propagation delay
    /// from the reference (the first DC slave) for any tree: a child's hop is half of its
    /// parent's round trip through that port minus the child's own loop; slaves behind a later
    /// port also wait for the earlier branches (esc-spec §3.6).
    pub(crate) fn measure_delays(&mut self) -> Result<()> {
        self.latch_and_measure_delays().map(|_| ())
    }

    /// As [`Master::measure_delays`]; returns the stamps of the latching frame (without the
    /// reference's readings) when there are DC slaves.
    pub(crate) fn latch_and_measure_delays(&mut self) -> Result<Option<crate::sync::Sample>> {
        self.split_latch = None;
        self.relatched.clear();
        if !self.slaves.iter().any(|s| s.dc.supported) {
            return Ok(None);
        }
        self.forwarding_latch_mode()?;
        // On a ring, the frame turns at the ring's port as on a line's end.
        let ring = self.close_ring_port()?;
        // Sent once per try, so that the stamps are of the frame that latched.
        let mut tries = self.engine.retries.saturating_add(1);
        let mut passes = None;
        let latched = loop {
            let built_ns = self.clock().master_system_time();
            let mut latch = [0u8; 4];
            let mut pdus =
                [Pdu::new(Command::BWR, Address::Device { adp: 0, ado: addr::DC_RECEIVE_TIME_PORT0 }, &mut latch)];
            let bytes = crate::engine::frame_bytes(&pdus);
            tries -= 1;
            match self.engine.transact_once(&mut pdus, self.engine.timeout_ns) {
                Ok(()) => {
                    passes = self.engine.redundancy.split_passes.take();
                    break Ok(self.stamped_sample(&crate::sync::SyncState::default(), built_ns, bytes));
                }
                Err(MasterError::Timeout { .. }) if tries > 0 => continue,
                Err(e) => break Err(e),
            }
        };
        self.reopen_ring_port(ring)?;
        let mut stamps = latched?;
        for k in 0..self.slaves.len() {
            if !self.slaves[k].dc.supported {
                continue;
            }
            let st = self.slaves[k].station;
            let times = self.port_receive_times(st)?;
            let mut epu = [0u8; 8];
            let answered = self.engine.one(
                Command::FPRD,
                Address::Device { adp: st, ado: addr::DC_RECEIVE_TIME_EPU },
                &mut epu,
            )? == 1;
            let s = &mut self.slaves[k];
            s.dc.receive_times = times;
            // Without a system time (WKC 0) the processing unit's receive time is port 0's, as
            // 0x0918's low word is where it exists (esc-spec §3.3).
            s.dc.has_system_time = answered;
            s.dc.receive_time_epu = if answered { u64::from_le_bytes(epu) } else { s.dc.receive_times[0] as u64 };
            s.ports.entry = super::next_frame_latch::entry_by_times(s.dc.receive_times, s.ports.active, s.ports.entry);
        }
        let inferred = self.topology();
        // An ET1200, ESC20 or IP core entered elsewhere than on port 0 may have taken a later
        // frame at the ports before its processing unit: no tree fits, or (on a split ring,
        // whose probes pass the far half first) any may be off. Latch those again.
        let next_frame = self.next_frame_slaves();
        let far = self.first_far_position();
        // A tree that fits may still be wrong, or right on wrong times: one entered elsewhere
        // than on port 0 (by its times, or with port 0 closed, where nothing else can be) is
        // latched again too (an EL1004 entered on port 1 as the last slave fits the only tree
        // there is, with a later frame's time at port 1: its delay came out 0 for 230 ns).
        let reversed = next_frame.iter().any(|&k| self.slaves[k].ports.entry != 0 || !self.slaves[k].ports.active[0]);
        if !next_frame.is_empty() && (!inferred || reversed || far.is_some_and(|f| next_frame.iter().any(|&k| k >= f)))
        {
            let ring = self.close_ring_port()?;
            let relatched = self.relatch_next_frame(&next_frame);
            self.reopen_ring_port(ring)?;
            self.relatched = relatched?;
            self.topology();
        }
        let view = self.port_views();
        // When the frame reaches each DC slave's entry port, relative to the first DC slave on
        // its way; parents before children, whatever the processing order.
        let mut entry_at: Vec<Option<i64>> = vec![None; self.slaves.len()];
        for k in self.tree_order() {
            if !self.slaves[k].dc.supported {
                continue;
            }
            // Behind non-DC slaves (which latch no receive times), measure from the nearest DC
            // ancestor: the round trip it sees on the port toward them holds their hops both ways
            // and this slave's own loop.
            let (mut via, mut port) =
                (self.slaves[k].ports.parent.map(|p| p as usize), self.slaves[k].ports.parent_port);
            // Closed ports the frame loops through on its way out, less those on its way back,
            // that no latch separates: the child's after its last event, each non-DC slave's on
            // the way (one loop-back each, `closed_port_loop_ns`).
            let mut loops = -view[k].loops_after_last_event();
            while let Some(v) = via.filter(|&v| !self.slaves[v].dc.supported) {
                loops += view[v].loops_between(view[v].before(port), port)
                    - view[v].loops_between(port, view[v].after(port));
                port = self.slaves[v].ports.parent_port;
                via = self.slaves[v].ports.parent.map(|p| p as usize);
            }
            entry_at[k] = Some(match via.and_then(|v| Some((v, entry_at[v]?))) {
                Some((v, at)) => {
                    let (left, loops_out) = view[v].leaves_for(port).unwrap_or((0, 0));
                    loops += loops_out;
                    // A child's hop is half of what the frame spent behind the port, less the
                    // child's own loop (esc-spec §3.6), corrected for loop-backs that lengthen
                    // one way only (the return through a closed port behind a child's last
                    // latch: half of it would otherwise count as delay).
                    let back = view[v].between(view[v].entry_port, port).unwrap_or(0);
                    let behind = back - left - view[k].span_ns().unwrap_or(0);
                    let hop = (behind + loops * self.settings.closed_port_loop_ns as i64) / 2;
                    at + left + hop
                }
                None => 0,
            });
        }
        // The delay is between processing units: a slave entered on a port other than 0
        // processes the frame after its branches before port 0 (0x0918 latches that instant).
        let epu_at: Vec<Option<i64>> = self
            .slaves
            .iter()
            .zip(&entry_at)
            .map(|(s, at)| {
                let since_entry =
                    (s.dc.receive_time_epu as u32).wrapping_sub(s.dc.receive_times[s.ports.entry as usize]);
                Some((*at)? + since_entry as i32 as i64)
            })
            .collect();
        let reference = self.slaves.iter().position(|s| s.dc.has_system_time);
        let at_reference = reference.and_then(|r| epu_at[r]).unwrap_or(0);
        // A split ring's far half is its own tree: delays from its own first clock.
        let first_far = self.first_far_position().filter(|&f| reference.is_some_and(|r| r < f));
        let n = self.slaves.len();
        let far_reference = first_far.and_then(|f| (f..n).find(|&k| self.slaves[k].dc.has_system_time));
        let at_far_reference = far_reference.and_then(|r| epu_at[r]).unwrap_or(0);
        for (k, (s, at)) in self.slaves.iter_mut().zip(&epu_at).enumerate() {
            if s.dc.supported {
                let from = if first_far.is_some_and(|f| k >= f) { at_far_reference } else { at_reference };
                s.dc.delay_ns = at.map_or(0, |t| t - from).clamp(0, u32::MAX as i64) as u32;
            }
        }
        self.split_latch = first_far.map(|f| self.split_latch_of(&view, &epu_at, reference, f, passes));
        // The first DC slave is the reference (DC initialisation makes it so).
        if let Some(r) = reference {
            stamps.loop_ns = self.loop_ns_of(r);
        }
        Ok(Some(stamps))
    }

    pub(super) fn port_views(&self) -> Vec<crate::topology::PortView> {
        self.slaves
            .iter()
            .map(|s| crate::topology::PortView {
                entry_port: s.ports.entry,
                active_ports: s.ports.active,
                present_ports: [0, 1, 2, 3].map(|p| PortDescriptor(s.ports.descriptor).can_link(p)),
                receive_times: s.dc.supported.then_some(s.dc.receive_times),
                epu_time: s.dc.supported.then_some(s.dc.receive_time_epu as u32),
            })
            .collect()
    }

    /// Positions with every parent before its children (breadth first from the first slave).
    pub(super) fn tree_order(&self) -> Vec<usize> {
        let n = self.slaves.len();
        let mut order: Vec<usize> = (0..n).filter(|&k| self.slaves[k].ports.parent.is_none()).collect();
        let mut seen = vec![false; n];
        let mut i = 0;
        while i < order.len() {
            let p = order[i];
            seen[p] = true;
            for (c, s) in self.slaves.iter().enumerate() {
                if !seen[c] && s.ports.parent == Some(p as u16) {
                    seen[c] = true;
                    order.push(c);
                }
            }
            i += 1;
        }
        order
    }
}

impl<'a, I: Io> crate::master::part::Dc<'a, I> {
    /// The segment's round trip: the median of `n` two-byte broadcasts (BRD 0x0000), by the
    /// link's stamps (ns).
    pub fn median_round_trip_ns(&mut self, n: usize) -> Result<i64> {
        let mut trips = Vec::with_capacity(n);
        for _ in 0..n.max(1) {
            let built = self.m.engine.io.now_ns();
            self.m.engine.one(Command::BRD, Address::Device { adp: 0, ado: 0 }, &mut [0u8; 2])?;
            let tx = self.m.engine.io.last_tx_ns().unwrap_or(built);
            trips.push(self.m.engine.last_rx_ns.wrapping_sub(tx) as i64);
        }
        trips.sort_unstable();
        Ok(trips[trips.len() / 2])
    }
}
