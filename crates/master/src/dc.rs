//! Distributed-clock initialisation: delays and offsets written, the time control loops reset,
//! static drift compensation until every slave has converged, SYNC0/SYNC1 started on the cycle
//! grid, and a sync monitor (esc-spec §3.4).
use ferrocat_wire::register::addr;
use ferrocat_wire::register::{dc_activation as act, PortDescriptor, SystemTimeDifference};
use ferrocat_wire::{Address, Command};

use crate::dc_writes::{Rider, Riders, MAX_RIDERS};
use crate::engine::{frame_bytes, Pdu, SplitRingClocks};
use crate::error::{DcError, MasterError, Result};
use crate::io::Io;
use crate::master::{loop_of, Master};
use crate::sync::SyncState;

/// What a frame of the sync datagrams alone leaves for riders: four headers and working
/// counters, the reference's time or offset, the FRMW, 0x092C and a follower's clock.
pub(crate) const SYNC_ROOM_BYTES: usize =
    ferrocat_wire::frame::MAX_PDU_LEN - 4 * NOP_LEN - 8 - 8 - 4 - FOLLOWER_CLOCK_LEN;

/// A NOP datagram without data in the follower's place, where riders follow.
const NOP_LEN: usize = ferrocat_wire::datagram::HEADER_LEN + ferrocat_wire::datagram::WKC_LEN;

/// The clock-synchronisation datagrams of one cycle and their buffers.
#[derive(Debug)]
pub(crate) struct SyncPdus {
    station: u16,
    /// Whether the reference's DC is 64 bits wide (else its registers are unwrapped).
    wide: bool,
    built_ns: u64,
    first: FirstPdu,
    pub(crate) frmw: [u8; 8],
    diff: [u8; 4],
    /// A follower whose clock the frame reads ([`crate::sync::CyclePlan::read_follower_clock`]):
    /// its station and which way its speed counter turns, where measured; and its 0x0910–0x0933.
    follower: Option<(u16, Option<bool>)>,
    clock: [u8; FOLLOWER_CLOCK_LEN],
    /// The method's writes riding on this frame ([`crate::dc_writes`]), and whether writes
    /// wait that could not ride (too many, or no room in the frame).
    riders: Riders,
    stuck: bool,
}

/// The sync datagrams, a follower's clock and the riders at most.
pub(crate) const MAX_SYNC_PDUS: usize = 4 + MAX_RIDERS;

/// A follower's 0x0910 (system time) to 0x0933 (speed counter difference) in one read.
const FOLLOWER_CLOCK_LEN: usize = (addr::DC_SYSTEM_TIME_DIFF_FILTER_DEPTH - addr::DC_SYSTEM_TIME) as usize;

/// What the sync frame does to the reference before its FRMW.
#[derive(Debug)]
enum FirstPdu {
    Nop,
    /// The master's time for the reference's 0x0910 (its time control loop steers to it).
    Time([u8; 8]),
    /// The reference's System_Time_Offset (0x0920, `len` bytes): read (FPRD) or replaced
    /// (FPRW, which answers the value it replaced). Writes apply at the frame's end, so the
    /// value read is the one in force when the FRMW read the reference's time.
    Offset {
        data: [u8; 8],
        len: usize,
        write: bool,
    },
}

/// Which of the sync frame's datagrams were answered.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub(crate) struct SyncAnswers {
    /// The FRMW and the 0x092C read.
    pub(crate) sync: bool,
    /// The reference's 0x0920 (read or replaced).
    pub(crate) offset: bool,
    /// The follower's clock, where the frame read one.
    pub(crate) follower: bool,
    /// Every rider, where the frame carried some.
    pub(crate) riders: bool,
}

impl SyncAnswers {
    /// A frame that did not come back.
    pub(crate) const NONE: SyncAnswers = SyncAnswers { sync: false, offset: false, follower: false, riders: false };
}

impl SyncPdus {
    /// [FPWR 0x0910 | FPRD/FPRW 0x0920 | NOP, FRMW 0x0910, FPRD 0x092C] on the reference, an
    /// FPRD of a follower's clock where one is read (a NOP in its place where riders follow),
    /// and the riders: the datagrams and how many there are.
    pub(crate) fn pdus<'a>(&'a mut self, nop: &'a mut [u8; 0]) -> ([Pdu<'a>; MAX_SYNC_PDUS], usize) {
        let station = self.station;
        let at = |ado| Address::Device { adp: station, ado };
        let riders = self.riders.count;
        let n = if riders > 0 { 4 + riders } else { 3 + self.follower.is_some() as usize };
        let nop_pdu = || Pdu::new(Command::NOP, Address::Device { adp: 0, ado: 0 }, &mut []);
        let mut clock = Some(match self.follower {
            Some((f, _)) => {
                Pdu::new(Command::FPRD, Address::Device { adp: f, ado: addr::DC_SYSTEM_TIME }, &mut self.clock)
            }
            None => nop_pdu(),
        });
        let mut first = Some(match &mut self.first {
            FirstPdu::Time(w) => Pdu::new(Command::FPWR, at(addr::DC_SYSTEM_TIME), w),
            FirstPdu::Offset { data, len, write } => Pdu::new(
                if *write { Command::FPRW } else { Command::FPRD },
                at(addr::DC_SYSTEM_TIME_OFFSET),
                &mut data[..*len],
            ),
            FirstPdu::Nop => Pdu::new(Command::NOP, Address::Device { adp: 0, ado: 0 }, nop),
        });
        let mut frmw = Some(Pdu::new(Command::FRMW, at(addr::DC_SYSTEM_TIME), &mut self.frmw));
        let mut diff = Some(Pdu::new(Command::FPRD, at(addr::DC_SYSTEM_TIME_DIFFERENCE), &mut self.diff));
        let mut rest = self.riders.list.iter_mut().take(riders).map(|r| {
            let cmd = if r.write { Command::FPWR } else { Command::FPRD };
            Pdu::new(cmd, Address::Device { adp: r.station, ado: r.ado }, &mut r.data[..r.len as usize])
        });
        let pdus = std::array::from_fn(|k| {
            let taken = match k {
                0 => first.take(),
                1 => frmw.take(),
                2 => diff.take(),
                3 => clock.take(),
                _ => rest.next(),
            };
            taken.unwrap_or_else(nop_pdu)
        });
        (pdus, n)
    }

    /// The follower's clock as the frame read it.
    fn follower_clock(&self) -> Option<crate::sync::FollowerClock> {
        let (_, speed_diff_slows) = self.follower?;
        let c = &self.clock;
        let u64_at = |k: usize| u64::from_le_bytes(c[k..k + 8].try_into().unwrap_or_default());
        let u16_at = |k: usize| u16::from_le_bytes([c[k], c[k + 1]]);
        let (system, offset) = (u64_at(0), u64_at(0x10));
        let delay = u32::from_le_bytes(c[0x18..0x1C].try_into().unwrap_or_default()) as u64;
        Some(crate::sync::FollowerClock {
            // An ECAT read of 0x0910 gives the system time less the delay (esc-spec §3).
            local_ns: system.wrapping_add(delay).wrapping_sub(offset),
            speed_start: u16_at(0x20),
            speed_diff: u16_at(0x22) as i16,
            speed_diff_slows,
        })
    }

    /// Which datagrams the reference answered (an FPRW counts 3: read and write).
    pub(crate) fn answered(pdus: &[Pdu<'_>]) -> SyncAnswers {
        let sync = pdus.len() >= 3 && pdus[1].wkc > 0 && pdus[2].wkc == 1;
        let follower = pdus.len() >= 4 && pdus[3].cmd == Command::FPRD && pdus[3].wkc == 1;
        let offset = pdus.first().is_some_and(|p| match p.cmd {
            Command::FPRD => p.wkc == 1,
            Command::FPRW => p.wkc == 3,
            _ => false,
        });
        let riders = pdus.len() > 4 && pdus[4..].iter().all(|p| p.wkc == 1);
        SyncAnswers { sync, offset, follower, riders }
    }

    /// The reference's offset the frame read, if it carried a read.
    fn offset_read(&self) -> Option<u64> {
        match &self.first {
            FirstPdu::Offset { data, .. } => Some(u64::from_le_bytes(*data)),
            _ => None,
        }
    }
}

#[derive(Debug, Clone, PartialEq, Eq)]
/// How the DC initialisation runs ([`Dc::init_dc`](crate::part::Dc::init_dc)).
pub struct DcConfig {
    /// Static drift compensation stops when every |0x092C| stays at or below this…
    pub converged_ns: u32,
    /// …for this many checks in a row (one check every `check_every` frames)…
    pub stable_checks: u32,
    /// Frames between checks of 0x092C (default 250).
    pub check_every: u32,
    /// …or after this many frames at the most (the ETG example: 15 000).
    pub max_frames: u32,
    /// SYNC0 cycle and shift; SYNC1 delay after SYNC0 (0: no SYNC1).
    pub sync0_cycle_ns: u32,
    /// SYNC0's shift after the cycle's start, ns (default 0).
    pub sync0_shift_ns: i32,
    /// SYNC1's delay after SYNC0, ns (default 0: no SYNC1).
    pub sync1_ns: u32,
    /// The first SYNC0 this far after the reference's present time, rounded to the cycle.
    pub start_delay_ns: u64,
    /// Slaves to start SYNC0 on (positions); `None`: those whose SII declares a DC op-mode.
    pub sync0_slaves: Option<Vec<u16>>,
    /// Assign-activate words of the application's (position, word), as ESI's `AssignActivate`
    /// writes them: the high byte to 0x0981 (activation), the low byte to 0x0980 (cyclic unit
    /// control). A slave without one gets cyclic operation, SYNC0 and, where `sync1_ns` is set,
    /// SYNC1 (0x0981), and 0x0980 stays 0.
    pub assign_activate: Vec<(u16, u16)>,
}

impl Default for DcConfig {
    fn default() -> Self {
        DcConfig {
            converged_ns: 50,
            stable_checks: 3,
            check_every: 250,
            max_frames: 15_000,
            sync0_cycle_ns: 1_000_000,
            sync0_shift_ns: 0,
            sync1_ns: 0,
            start_delay_ns: 100_000_000,
            sync0_slaves: None,
            assign_activate: Vec::new(),
        }
    }
}

/// The slaves the DC initialisation starts SYNC0 on when [`DcConfig::sync0_slaves`] is
/// `None`: those with a system time whose SII declares a DC op-mode that activates SYNC0
/// (assign-activate bit 9).
pub fn sync0_by_sii(slaves: &[crate::slave::Slave]) -> Vec<u16> {
    slaves
        .iter()
        .filter(|s| s.dc.has_system_time && s.sii.dc_op_modes().iter().any(|m| m.assign_activate & 0x0200 != 0))
        .map(|s| s.position)
        .collect()
}

#[derive(Debug, Clone, PartialEq, Eq)]
/// What the DC initialisation did.
pub struct DcReport {
    /// Position of the reference clock.
    pub reference: u16,
    /// Frames of static drift compensation sent.
    pub static_frames: u32,
    /// How long the static drift compensation took.
    pub static_ns: u64,
    /// Whether the reference followed the master through it (`init_dc_with`).
    pub reference_steered: bool,
    /// Whether every |0x092C| came within `converged_ns`.
    pub converged: bool,
    /// Largest |0x092C| at the end of the static drift compensation.
    pub max_difference_ns: u32,
    /// System time of the first SYNC0, and the slaves it was started on.
    pub sync0_start: Option<u64>,
    /// The slaves SYNC0 was started on.
    pub sync0_slaves: Vec<u16>,
    /// Those of them whose SYNC pulse (0x0982, which their SII sets) is longer than the SYNC0
    /// cycle, with the pulse (ns): their SYNC0 output stays active after its first pulse (ESC
    /// datasheet section I, 9.2.3.1), so an application that runs on its edges runs once.
    pub sync0_held: Vec<(u16, u64)>,
}

impl<I: Io> Master<I> {
    /// The targets whose SYNC pulse is longer than a `cycle_ns` SYNC0 cycle, with the pulse
    /// (ns), each a warning. The pulse is the SII's word 2, which the ESC loads into 0x0982
    /// (read-only from ECAT): read from the SII the scan read, no frame sent.
    fn sync0_held(&self, targets: &[u16], cycle_ns: u32) -> Result<Vec<(u16, u64)>> {
        let mut held = Vec::new();
        for &p in targets {
            let s = self.slave(p)?;
            let pulse_ns = s.sii.header.sync_impulse_len as u64 * 10;
            if cycle_ns > 0 && pulse_ns > cycle_ns as u64 {
                tracing::warn!(
                    "slave {p} ({}): its SYNC pulse (0x0982, from its SII) is {} µs, longer than the {} µs SYNC0 \
                     cycle: its SYNC0 output stays active after the first pulse (ESC datasheet section I, 9.2.3.1)",
                    s.name,
                    pulse_ns as f64 / 1e3,
                    cycle_ns as f64 / 1e3
                );
                held.push((p, pulse_ns));
            }
        }
        Ok(held)
    }

    fn start_sync(&mut self, targets: &[u16], cfg: &DcConfig) -> Result<u64> {
        let cycle = cfg.sync0_cycle_ns.max(1) as u64;
        for &p in targets {
            let s = self.slave(p)?;
            if !s.dc.has_system_time {
                return Err(MasterError::of(p, &s.name, crate::error::SlaveError::NoSystemTime));
            }
        }
        // Stop first: a restart with 0x0981 still set is a classic cause of "no sync" errors.
        for &p in targets {
            let st = self.slave(p)?.station;
            self.engine.expect_wkc(
                Command::FPWR,
                Address::Device { adp: st, ado: addr::DC_ACTIVATION },
                &mut [0],
                1,
            )?;
            self.engine.expect_wkc(
                Command::FPWR,
                Address::Device { adp: st, ado: addr::DC_CYCLIC_UNIT_CONTROL },
                &mut [0],
                1,
            )?;
        }
        let ref_station = self.dc_reference.ok_or(DcError::NoReference)?;
        let mut now = [0u8; 8];
        self.engine.expect_wkc(
            Command::FPRD,
            Address::Device { adp: ref_station, ado: addr::DC_SYSTEM_TIME },
            &mut now,
            1,
        )?;
        let now = u64::from_le_bytes(now);
        let start = ((now + cfg.start_delay_ns) / cycle + 1) * cycle;
        let start = (start as i128 + cfg.sync0_shift_ns as i128).max(0) as u64;
        for &p in targets {
            let (st, wide) = {
                let s = self.slave(p)?;
                (s.station, s.dc.is_64bit)
            };
            let fp = |m: &mut Self, ado: u16, d: &mut [u8]| {
                m.engine.expect_wkc(Command::FPWR, Address::Device { adp: st, ado }, d, 1)
            };
            fp(self, addr::DC_SYNC0_CYCLE_TIME, &mut (cfg.sync0_cycle_ns).to_le_bytes())?;
            fp(self, addr::DC_SYNC1_CYCLE_TIME, &mut cfg.sync1_ns.to_le_bytes())?;
            let mut s = start.to_le_bytes();
            fp(self, addr::DC_START_TIME, &mut s[..if wide { 8 } else { 4 }])?;
            let given = cfg.assign_activate.iter().find(|(q, _)| *q == p).map(|&(_, w)| w);
            let a = match given {
                Some(word) => {
                    fp(self, addr::DC_CYCLIC_UNIT_CONTROL, &mut [word as u8])?;
                    (word >> 8) as u8
                }
                None => act::CYCLIC_OPERATION | act::SYNC0 | if cfg.sync1_ns > 0 { act::SYNC1 } else { 0 },
            };
            fp(self, addr::DC_ACTIVATION, &mut [a])?;
        }
        Ok(start)
    }
}

/// `low` (the low 32 bits of a 32-bit DC's register) placed on the 64-bit line next to `prev`.
fn unwrap32(prev: Option<u64>, low: u64) -> u64 {
    match prev {
        Some(p) => p.wrapping_add_signed((low as u32).wrapping_sub(p as u32) as i32 as i64),
        None => low & 0xFFFF_FFFF,
    }
}

/// What a probe frame does with the reference's offset (offset steering).
#[derive(Debug, Clone, Copy)]
enum ProbeOffset {
    /// Reads it only.
    Read,
    /// Gives it the method's offset for the rest of the cycle (a lost frame made up).
    GiveUntilNextCycle,
    /// Gives it the method's offset for `holds_ns` after the probe's passage.
    GiveFor { holds_ns: u64 },
}

impl<I: Io> Master<I> {
    fn reference_index(&self) -> Result<usize> {
        let st = self.dc_reference.ok_or(DcError::NoReference)?;
        self.slaves.iter().position(|s| s.station == st).ok_or(DcError::ReferenceGone.into())
    }

    /// The reference's loop as the ring now is: on an intact ring the one `find_ring_port`
    /// measured; on a broken one (or a ring whose secondary cable is pulled, now a line) the
    /// frame turns where the link is gone, so the receive times are latched again and the
    /// reference's active ports read afresh.
    fn current_reference_loop_ns(&mut self) -> Result<u64> {
        use crate::engine::RingState;
        if matches!(self.engine.redundancy.state, RingState::Intact | RingState::Unknown) {
            // Closed after a latch that found it split: its delays and loop measured now.
            self.rejoin_far_half()?;
            return self.clock().reference_loop_ns();
        }
        let r = self.reference_index()?;
        let st = self.slaves[r].station;
        self.engine.one(Command::BWR, Address::Device { adp: 0, ado: addr::DC_RECEIVE_TIME_PORT0 }, &mut [0u8; 4])?;
        let mut dl = [0u8; 2];
        self.fprd(st, addr::DL_STATUS, &mut dl)?;
        let times = self.port_receive_times(st)?;
        let dl = ferrocat_wire::register::DlStatus(u16::from_le_bytes(dl));
        let view = crate::topology::PortView {
            entry_port: self.slaves[r].ports.entry,
            active_ports: [0, 1, 2, 3].map(|p| dl.port_active(p)),
            present_ports: [0, 1, 2, 3].map(|p| PortDescriptor(self.slaves[r].ports.descriptor).can_link(p)),
            receive_times: Some(times),
            epu_time: None,
        };
        // The port that lost its link now loops the frame back after the last latched return,
        // where on the ring it latched one: its loop-back belongs to the loop.
        let loops = view.loops_after_last_event() * self.settings.closed_port_loop_ns as i64;
        Ok(loop_of(&times, view.active_ports, view.entry_port) + loops.max(0) as u64)
    }

    /// The sync datagrams of this cycle, built now (the master's time goes into them).
    /// `room_bytes`: what the frame the sync datagrams go in has left for riders.
    pub(crate) fn sync_begin(
        &mut self,
        sync: &mut dyn crate::sync::ClockSync,
        st: &mut SyncState,
        room_bytes: usize,
    ) -> Result<SyncPdus> {
        let r = self.reference_index()?;
        st.cycle += 1;
        let built_ns = self.clock().master_system_time();
        let rfm = sync.coupling() == crate::sync::Coupling::ReferenceFollowsMaster;
        let wide = self.slaves[r].dc.is_64bit;
        let plan = sync.plan(st.cycle);
        let first = if rfm && plan.steer_reference_offset {
            let len = if wide { 8 } else { 4 };
            match sync.reference_steering().and_then(|s| s.reference_offset(built_ns, None)) {
                Some(v) => FirstPdu::Offset { data: v.to_le_bytes(), len, write: true },
                None => FirstPdu::Offset { data: [0; 8], len, write: false },
            }
        } else if rfm && plan.write_reference_time {
            FirstPdu::Time(sync.reference_time(built_ns).to_le_bytes())
        } else {
            FirstPdu::Nop
        };
        // The first 64-bit follower after the reference (a 32-bit one's 0x0910 is 4 bytes), on
        // the reference's side of a broken ring: behind the break the clocks follow another
        // reference, moved by their offsets, and the frame reaches them a pass later.
        let near = self.first_far_position().unwrap_or(self.slaves.len());
        let follower = plan
            .read_follower_clock
            .then(|| self.slaves[..near].iter().skip(r + 1).find(|s| s.dc.has_system_time && s.dc.is_64bit))
            .flatten()
            .map(|s| (s.station, s.dc.speed_diff_slows));
        let (riders, stuck) = match self.riders() {
            Some(r) if r.wire_len() + NOP_LEN <= room_bytes => (r, false),
            Some(_) => (Riders::default(), true),
            None => (Riders::default(), self.dc_writes.pending()),
        };
        Ok(SyncPdus {
            station: self.slaves[r].station,
            wide,
            built_ns,
            first,
            frmw: [0; 8],
            diff: [0; 4],
            follower,
            clock: [0; FOLLOWER_CLOCK_LEN],
            riders,
            stuck,
        })
    }

    /// The datagrams the waiting writes need on this frame: the offsets read for a shift, or
    /// written shifted; the followers' delays with the bias. `None` with nothing waiting, or
    /// more than ride on one frame.
    fn riders(&self) -> Option<Riders> {
        let w = &self.dc_writes;
        if !w.pending() {
            return None;
        }
        let mut riders = Riders::default();
        if let Some(shift) = &w.shift {
            match &shift.read {
                None => {
                    riders.reads_offsets = true;
                    for s in self.slaves.iter().filter(|s| s.dc.has_system_time && shift.skip != Some(s.station)) {
                        let len = if s.dc.is_64bit { 8 } else { 4 };
                        let r = Rider { station: s.station, ado: addr::DC_SYSTEM_TIME_OFFSET, len, ..Rider::default() };
                        if !riders.push(r) {
                            return None;
                        }
                    }
                }
                Some(read) => {
                    riders.writes_offsets = true;
                    for &(station, offset, len) in &read[..shift.count] {
                        let data = offset.wrapping_add_signed(shift.shift_ns).to_le_bytes();
                        let r = Rider { write: true, station, ado: addr::DC_SYSTEM_TIME_OFFSET, data, len };
                        if !riders.push(r) {
                            return None;
                        }
                    }
                }
            }
        }
        if let Some((bias_ns, reference)) = w.bias {
            riders.writes_bias = true;
            for s in self.slaves.iter().filter(|s| s.dc.has_system_time && s.station != reference) {
                let delay = (s.dc.delay_ns as i64 + bias_ns).clamp(0, u32::MAX as i64) as u32;
                let mut data = [0u8; 8];
                data[..4].copy_from_slice(&delay.to_le_bytes());
                let r = Rider { write: true, station: s.station, ado: addr::DC_SYSTEM_TIME_DELAY, data, len: 4 };
                if !riders.push(r) {
                    return None;
                }
            }
        }
        Some(riders)
    }

    /// What the riders of an answered frame did: offsets read are kept for the write, writes
    /// done are no longer waiting. Riders not all answered are sent again with the next frame.
    fn riders_answered(&mut self, riders: &Riders, answered: bool) {
        if riders.count == 0 {
            return;
        }
        let w = &mut self.dc_writes;
        if !answered {
            w.retried += 1;
            return;
        }
        w.rode += riders.count as u64;
        if riders.reads_offsets {
            if let Some(shift) = w.shift.as_mut() {
                let mut read = [(0u16, 0u64, 0u8); MAX_RIDERS];
                let mut count = 0;
                for (slot, r) in read.iter_mut().zip(riders.offsets_read()) {
                    *slot = r;
                    count += 1;
                }
                shift.read = Some(read);
                shift.count = count;
            }
        }
        if riders.writes_offsets {
            w.shift = None;
        }
        if riders.writes_bias {
            w.bias = None;
        }
    }

    /// Whether the cycle has room, before its period ends, for two more frames as long as its
    /// own: without a period (a caller that paces itself), always.
    fn room_for_frames(&mut self) -> bool {
        let (Some(start), period) = (self.engine.io.wake_target_ns(), self.cyc.stats.nominal_period_ns) else {
            return true;
        };
        if period == 0 {
            return true;
        }
        let now = self.engine.io.now_ns();
        now + 2 * self.cyc.stats.last_round_trip_ns <= start + period
    }

    /// The writes still waiting, each in frames of its own.
    fn flush_dc_writes(&mut self) -> Result<()> {
        if let Some(shift) = self.dc_writes.shift.take() {
            self.shift_offsets_but(shift.shift_ns, shift.skip)?;
        }
        if let Some((bias, reference)) = self.dc_writes.bias.take() {
            self.bias_follower_delays(bias, reference)?;
        }
        Ok(())
    }

    /// The sample of an answered (or lost) sync frame to the method, and its correction done.
    pub(crate) fn sync_end(
        &mut self,
        sync: &mut dyn crate::sync::ClockSync,
        st: &mut SyncState,
        p: &SyncPdus,
        answered: SyncAnswers,
        frame_bytes: u64,
        data_bytes: u64,
    ) -> Result<crate::sync::Correction> {
        let wide = p.wide;
        let offset = p.offset_read().filter(|_| answered.offset);
        if let Some(o) = offset {
            st.reference_offset_ns = Some(if wide { o } else { unwrap32(st.reference_offset_ns, o) });
        }
        let sample = if answered.sync {
            let frmw = u64::from_le_bytes(p.frmw);
            st.reference_ns = Some(if wide { frmw } else { unwrap32(st.reference_ns, frmw) });
            let mut s = self.stamped_sample(st, p.built_ns, frame_bytes);
            // The ring broke or closed under this frame: the reference's loop is measured
            // again (after the stamps were taken, which its frames would replace).
            if self.engine.io.has_secondary() && self.engine.redundancy.state != st.ring {
                st.ring = self.engine.redundancy.state;
                st.loop_ns = self.current_reference_loop_ns()?;
                s.loop_ns = st.loop_ns;
            }
            s.reference_offset_ns = offset.and(st.reference_offset_ns);
            s.difference_ns = SystemTimeDifference(u32::from_le_bytes(p.diff)).as_ns();
            s.data_ns = data_bytes * 80;
            s.follower = p.follower_clock().filter(|_| answered.follower);
            Some(s)
        } else {
            st.lost += 1;
            None
        };
        let before = st.lock.state();
        let now = match sample.as_ref() {
            Some(s) => {
                let trip_ns = s.rx_ns.wrapping_sub(s.tx_ns.unwrap_or(s.built_ns)) as i64;
                let offset_ns = sync.offset_ns(s);
                tracing::trace!(
                    cycle = st.cycle,
                    offset_ns,
                    trip_ns,
                    built_ns = s.built_ns,
                    send_ns = s.tx_ns.map(|t| t.wrapping_sub(s.built_ns) as i64),
                    "clock sync sample"
                );
                st.lock.observe_frame(offset_ns, trip_ns)
            }
            None => {
                tracing::trace!(cycle = st.cycle, "clock sync frame lost");
                st.lock.observe(None, true)
            }
        };
        if now != before {
            tracing::info!(method = sync.name(), offset_ns = st.lock.offset_ns(), "clock sync {before} -> {now}");
        }
        let c = sync.update(sample.as_ref());
        self.riders_answered(&p.riders, answered.riders);
        // What follows the frame, as the method plans it with the frame's sample taken.
        let plan = sync.plan(st.cycle);
        // Writes go in frames of their own where the cycle has room for them, else on the next
        // cyclic frames; what cannot ride goes now, late or not.
        let room = self.room_for_frames();
        if c.shift_offsets_ns != 0 {
            // A method that gives the reference its offset moves the reference itself.
            let skip = if plan.steer_reference_offset { Some(p.station) } else { None };
            self.dc_writes.add_shift(c.shift_offsets_ns, skip);
        }
        if let Some(bias) = sync.reference_steering().and_then(|s| s.follower_delay_bias_ns()) {
            self.dc_writes.bias = Some((bias, p.station));
        }
        if self.dc_writes.pending() && (room || p.stuck) {
            self.flush_dc_writes()?;
        }
        if !answered.sync && plan.make_up_lost_frames && !st.probing.off && room {
            st.make_ups += 1;
            let timeout_ns = self.settings.cyclic_timeout_ns;
            self.probe(
                sync,
                st,
                (p.station, wide, plan.steer_reference_offset),
                ProbeOffset::GiveUntilNextCycle,
                timeout_ns,
            )?;
        }
        let probes = if st.probing.off { 0 } else { plan.probes };
        let window_ns = plan.probe_window_ns;
        if let Some(b) = st.probing.budget_ns {
            st.probing.credit_ns = st.probing.credit_ns.saturating_add(b).min(window_ns);
        }
        // The window counts from the cycle's planned start where the caller slept to one (a
        // target less than a window before the frame's build): a cycle that woke late has
        // that much less of it.
        let woke_late_ns = if probes == 0 {
            0
        } else {
            let since_build_ns = self.clock().master_system_time().wrapping_sub(p.built_ns);
            let built_io_ns = self.engine.io.now_ns().saturating_sub(since_build_ns);
            let target = self.engine.io.wake_target_ns();
            target.and_then(|t| built_io_ns.checked_sub(t)).filter(|&late| late < window_ns).unwrap_or(0)
        };
        // Before the first probe, the cycle so far from the frame's build (at least its
        // exchange) stands for one.
        let mut first_guess_ns = None;
        let steer = plan.probes_give_offset;
        for k in 0..probes {
            // Probing must not make the next cycle late: a probe twice as long as they have
            // taken on average still ends within the window.
            let since_build_ns = self.clock().master_system_time().wrapping_sub(p.built_ns);
            let elapsed_ns = since_build_ns.saturating_add(woke_late_ns);
            let expected_ns =
                if st.probing.mean_ns > 0 { st.probing.mean_ns } else { *first_guess_ns.get_or_insert(since_build_ns) };
            let fits = |done_ns: u64| done_ns.saturating_add(expected_ns.saturating_mul(2)) <= window_ns;
            if !fits(elapsed_ns) {
                st.probing.cut += 1;
                break;
            }
            if st.probing.budget_ns.is_some() && st.probing.credit_ns < expected_ns {
                st.probing.unfunded += u64::from(probes - k);
                break;
            }
            // An offset given stands until the next probe's passage, about one probe later,
            // or, after the last, until the next cycle's frame.
            let next_follows = k + 1 < probes && fits(elapsed_ns.saturating_add(expected_ns));
            let holds_ns = if next_follows { expected_ns } else { window_ns.saturating_sub(elapsed_ns) };
            let start_ns = self.engine.io.now_ns();
            st.probing.sent += 1;
            let offset = if steer { ProbeOffset::GiveFor { holds_ns } } else { ProbeOffset::Read };
            // Where the loop's period is known, a probe still unanswered at the window's end
            // is given up there rather than at the cyclic timeout, which would make the next
            // cycle late. An offset it gave may or may not be in force then: the next cycle's
            // frame reads the one in force with its own, and gives the next.
            let timeout_ns = if self.cyc.stats.nominal_period_ns > 0 {
                self.settings.cyclic_timeout_ns.min(window_ns.saturating_sub(elapsed_ns))
            } else {
                self.settings.cyclic_timeout_ns
            };
            self.probe(sync, st, (p.station, wide, plan.steer_reference_offset), offset, timeout_ns)?;
            // Mean over about 16 probes.
            let took_ns = self.engine.io.now_ns().saturating_sub(start_ns);
            st.probing.credit_ns = st.probing.credit_ns.saturating_sub(took_ns);
            st.probing.mean_ns = if st.probing.mean_ns == 0 {
                took_ns
            } else {
                st.probing.mean_ns - st.probing.mean_ns / 16 + took_ns / 16
            };
        }
        Ok(c)
    }

    /// One probe frame: the reference's time (and offset, where the method steers it) read,
    /// and as `give` says the reference given the offset the method wants
    /// ([`crate::sync::ReferenceSteering::reference_offset`]; the write answers the offset it
    /// replaced); its sample to the method. A lost probe is only counted.
    fn probe(
        &mut self,
        sync: &mut dyn crate::sync::ClockSync,
        st: &mut SyncState,
        (station, wide, steer): (u16, bool, bool),
        give: ProbeOffset,
        timeout_ns: u64,
    ) -> Result<()> {
        let n = if wide { 8 } else { 4 };
        let (mut time, mut offset) = ([0u8; 8], [0u8; 8]);
        let at = |ado| Address::Device { adp: station, ado };
        let built_ns = self.clock().master_system_time();
        let given = match give {
            _ if !steer => None,
            ProbeOffset::Read => None,
            ProbeOffset::GiveUntilNextCycle => {
                sync.reference_steering().and_then(|s| s.reference_offset(built_ns, None))
            }
            ProbeOffset::GiveFor { holds_ns } => {
                sync.reference_steering().and_then(|s| s.reference_offset(built_ns, Some(holds_ns)))
            }
        };
        let offset_cmd = match given {
            Some(v) => {
                offset = v.to_le_bytes();
                Command::FPRW
            }
            None => Command::FPRD,
        };
        let mut pdus = [
            Pdu::new(offset_cmd, at(addr::DC_SYSTEM_TIME_OFFSET), &mut offset[..n]),
            Pdu::new(Command::FPRD, at(addr::DC_SYSTEM_TIME), &mut time[..n]),
        ];
        let pdus = if steer { &mut pdus[..] } else { &mut pdus[1..] };
        let frame_bytes = frame_bytes(pdus);
        let sent = self.engine.transact_once(pdus, timeout_ns).is_ok();
        // An FPRW counts 3 (read and write).
        let answered = sent && pdus.iter().all(|p| p.wkc == if p.cmd == Command::FPRW { 3 } else { 1 });
        if !answered {
            st.probing.lost += 1;
            return Ok(());
        }
        let (time, offset) = (u64::from_le_bytes(time), u64::from_le_bytes(offset));
        let mut s = self.stamped_sample(st, built_ns, frame_bytes);
        s.reference_ns = if wide { time } else { unwrap32(st.reference_ns, time) };
        if steer {
            s.reference_offset_ns = Some(if wide { offset } else { unwrap32(st.reference_offset_ns, offset) });
        }
        if let Some(steering) = sync.reference_steering() {
            steering.probe(&s);
        }
        Ok(())
    }

    /// Writes every DC slave's System_Time_Delay (0x0928) as its measured delay plus
    /// `bias_ns` (at least 0), the reference at station `reference` left out.
    fn bias_follower_delays(&mut self, bias_ns: i64, reference: u16) -> Result<()> {
        for k in 0..self.slaves.len() {
            let s = &self.slaves[k];
            if !s.dc.has_system_time || s.station == reference {
                continue;
            }
            let (st, delay) = (s.station, (s.dc.delay_ns as i64 + bias_ns).clamp(0, u32::MAX as i64) as u32);
            self.fpwr(st, addr::DC_SYSTEM_TIME_DELAY, &delay.to_le_bytes())?;
        }
        Ok(())
    }

    /// After a cyclic frame (`passes`: its two passes round a broken ring, if it made them):
    /// reports a change of the ring's state once (cable redundancy; the first state seen is
    /// the starting point, not news), sets the clocks up for it, and keeps a split ring's far
    /// reference on the reference's time.
    pub(crate) fn note_ring(&mut self, passes: Option<crate::SplitPasses>) -> Result<()> {
        use crate::engine::RingState;
        let now = self.engine.redundancy.state;
        let before = std::mem::replace(&mut self.cyc.ring, now);
        if now != before && before != RingState::Unknown && now != RingState::Unknown {
            self.push_event(crate::MasterEvent::Ring { state: now });
        }
        if now != before {
            self.ring_changed(before);
        }
        self.rejoin_far_half()?;
        self.keep_far_reference(passes)?;
        self.watch_split()
    }

    /// The ring split or closed (cable redundancy). Split, with
    /// [`SplitRingClocks::FarReference`](crate::SplitRingClocks::FarReference), the first slave
    /// with a system time behind the break becomes the far half's reference: the FRMW of the
    /// second pass reads it. Nothing else changes: an ECAT read of 0x0910 gives the system time
    /// less the reader's own delay register (esc-spec §3), so the far reference hands on the
    /// reference's time as of the reference's pass, and its followers add their delays from
    /// the reference as ever. Closed, the reference's FRMW again.
    pub(crate) fn ring_changed(&mut self, before: crate::engine::RingState) {
        use crate::engine::{RingState, SplitRingClocks};
        let now = self.engine.redundancy.state;
        if now == RingState::Broken && before != RingState::Broken {
            let far = self.engine.redundancy.far_half_slaves as usize;
            let n = self.slaves.len();
            let follows = matches!(
                self.engine.redundancy.clocks,
                SplitRingClocks::FarReference | SplitRingClocks::FarReferenceHeld
            );
            if follows && far > 0 && far < n {
                self.engine.redundancy.far_reference =
                    (n - far..n).find(|&k| self.slaves[k].dc.has_system_time).map(|k| self.slaves[k].station);
            }
        } else if now != RingState::Broken {
            self.engine.redundancy.far_reference = None;
        }
    }

    /// As [`Clock::shift_offsets`](crate::part::Clock::shift_offsets), leaving out the slave at station `skip`.
    fn shift_offsets_but(&mut self, shift_ns: i64, skip: Option<u16>) -> Result<()> {
        let clocks: Vec<(u16, usize)> = self
            .slaves
            .iter()
            .filter(|s| s.dc.has_system_time && skip != Some(s.station))
            .map(|s| (s.station, if s.dc.is_64bit { 8 } else { 4 }))
            .collect();
        // Every offset read in one frame and written in one: each ESC takes a write at the end
        // of the frame, so the clocks move nanoseconds apart. A read and a write per slave, a
        // frame each, left a round trip or more between two slaves' moves, and a SYNC0 there
        // fired one move apart (Park's eq. 5 on pc-stock: two drives' SYNC0s 2.2 µs apart).
        let mut offsets = vec![[0u8; 8]; clocks.len()];
        for cmd in [Command::FPRD, Command::FPWR] {
            if cmd == Command::FPWR {
                for o in offsets.iter_mut() {
                    *o = u64::from_le_bytes(*o).wrapping_add_signed(shift_ns).to_le_bytes();
                }
            }
            let mut pdus: Vec<Pdu<'_>> = clocks
                .iter()
                .zip(offsets.iter_mut())
                .map(|(&(st, n), o)| {
                    Pdu::new(cmd, Address::Device { adp: st, ado: addr::DC_SYSTEM_TIME_OFFSET }, &mut o[..n])
                })
                .collect();
            self.engine.expect_wkc_each(&mut pdus, 1)?;
        }
        Ok(())
    }
}

impl<'a, I: Io> crate::master::part::Dc<'a, I> {
    /// Initialises the distributed clocks of every DC slave (esc-spec §3.4 steps 1–9).
    pub fn init_dc(&mut self, cfg: &DcConfig) -> Result<DcReport> {
        self.m.dc().init_dc_with(cfg, None)
    }

    /// As [`Dc::init_dc`](crate::part::Dc::init_dc); where `sync` makes the reference follow the master through its
    /// System_Time_Offset, its frames are the static drift compensation's, so that the
    /// reference already runs at the master's rate while the other slaves learn its rate:
    /// cyclic operation then starts without the rate change every follower would have to
    /// relearn (docs/clock-sync.md, lock time).
    pub fn init_dc_with(&mut self, cfg: &DcConfig, sync: Option<&mut dyn crate::sync::ClockSync>) -> Result<DcReport> {
        if !self.m.slaves.iter().any(|s| s.dc.supported) {
            return Err(DcError::NoDcSlave.into());
        }
        // 1–3. Latch receive times, compute delays, and take the master's time at the latch:
        //    when the latching frame passed the reference, from its stamps (half its round
        //    trip, less the segment's own loop and the frame's length), not when the master
        //    read its clock before sending it (KickCAT) or after it came back (SOEM).
        let t_master = match self.m.latch_and_measure_delays()? {
            Some(latch) => latch.built_ns.wrapping_add_signed(latch.lead_ns()),
            None => self.m.clock().master_system_time(),
        };
        // The reference: the first slave whose system time answers (the latch found out).
        let reference = self.m.slaves.iter().position(|s| s.dc.has_system_time).ok_or(DcError::NoSystemTime)?;
        // 4. Offsets, including each slave's delay: all local copies equal the reference's,
        //    and the reference's equals the master's time at the latch.
        let r_ref = self.m.slaves[reference].dc.receive_time_epu;
        let offset_ref = t_master.wrapping_sub(r_ref);
        // A ring split from the start: the far half latched on the second pass, this much
        // later, and its delays are from its own reference (master/split_start.rs).
        let far_lag = self.m.split_latch.as_ref().and_then(|l| Some((l.first_far, l.far_lag_ns()?)));
        for k in 0..self.m.slaves.len() {
            let s = &self.m.slaves[k];
            if !s.dc.has_system_time {
                continue;
            }
            let lag = far_lag.filter(|&(f, _)| k >= f).map_or(0, |(_, lag)| lag);
            let offset = r_ref
                .wrapping_add(offset_ref)
                .wrapping_sub(s.dc.receive_time_epu)
                .wrapping_add(s.dc.delay_ns as u64)
                .wrapping_add_signed(lag);
            let mut d = [0u8; 12];
            let n = if s.dc.is_64bit { 8 } else { 4 };
            d[..8].copy_from_slice(&offset.to_le_bytes());
            let (st, delay) = (s.station, s.dc.delay_ns);
            self.m.engine.expect_wkc(
                Command::FPWR,
                Address::Device { adp: st, ado: addr::DC_SYSTEM_TIME_OFFSET },
                &mut d[..n],
                1,
            )?;
            self.m.engine.expect_wkc(
                Command::FPWR,
                Address::Device { adp: st, ado: addr::DC_SYSTEM_TIME_DELAY },
                &mut delay.to_le_bytes(),
                1,
            )?;
        }
        // 5. Reset the time control loops: filter depth first, then the speed counter start.
        let dc_count = self.m.slaves.iter().filter(|s| s.dc.has_system_time).count() as u16;
        self.m.engine.one(
            Command::BWR,
            Address::Device { adp: 0, ado: addr::DC_SYSTEM_TIME_DIFF_FILTER_DEPTH },
            &mut [4],
        )?;
        self.m.engine.expect_wkc(
            Command::BWR,
            Address::Device { adp: 0, ado: addr::DC_SPEED_COUNTER_START },
            &mut 0x1000u16.to_le_bytes(),
            dc_count,
        )?;
        // 5a. For a method that takes the loops' corrections back out of a follower's clock:
        //     the raw crystal rates now, which way the speed counter moves them once converged.
        //     Not where the method steers the reference's offset from here on: the followers
        //     then converge on the master's rate, not the reference crystal's (that method's
        //     offsets work the loops hard enough for its own trial to tell the direction).
        let measure =
            sync.as_ref().map(|s| s.plan(0)).is_some_and(|p| p.read_follower_clock && !p.steer_reference_offset);
        let crystal_rates = match measure {
            true => Some(self.m.measure_crystal_rates(reference)?),
            false => None,
        };
        // 6. Static drift compensation, until converged (checked, not a fixed count).
        let ref_station = self.m.slaves[reference].station;
        // (`steer_reference_offset` implies the reference follows the master.)
        let mut steer = match sync.filter(|s| s.plan(0).steer_reference_offset) {
            Some(sync) => {
                self.m.dc_reference = Some(ref_station);
                let mut st = self.m.clock().sync_state()?;
                st.probing.off = true;
                Some((sync, st))
            }
            None => None,
        };
        // Split from the start: the far half follows its own reference from now on.
        let far = self.m.split_latch.as_ref().and_then(|l| l.far_reference).map(|r| self.m.slaves[r].station);
        if matches!(self.m.engine.redundancy.clocks, SplitRingClocks::FarReference | SplitRingClocks::FarReferenceHeld)
        {
            self.m.engine.redundancy.far_reference = far;
        }
        self.m.far_steer = None;
        let (mut frames, mut stable, mut max_diff) = (0u32, 0u32, u32::MAX);
        let mut converged = false;
        let static_from_ns = self.m.engine.io.now_ns();
        while frames < cfg.max_frames {
            match steer.as_mut() {
                Some((sync, st)) => {
                    self.m.clock().sync_step(&mut **sync, st)?;
                }
                None => {
                    let mut t = [0u8; 8];
                    self.m.engine.redundancy.split_passes = None;
                    self.m.engine.one(
                        Command::FRMW,
                        Address::Device { adp: ref_station, ado: addr::DC_SYSTEM_TIME },
                        &mut t,
                    )?;
                    let passes = self.m.engine.redundancy.split_passes.take();
                    self.m.keep_far_reference(passes)?;
                }
            }
            frames += 1;
            if frames % cfg.check_every.max(1) == 0 {
                max_diff =
                    self.m.dc().dc_differences()?.iter().map(|&(_, d)| d.unsigned_abs() as u32).max().unwrap_or(0);
                stable = if max_diff <= cfg.converged_ns { stable + 1 } else { 0 };
                if stable >= cfg.stable_checks {
                    converged = true;
                    break;
                }
            }
        }
        let static_ns = self.m.engine.io.now_ns().wrapping_sub(static_from_ns);
        // The far half's offsets were written for the latching frame's two passes, one
        // sample (scattered by microseconds on a PC's software stamps); the static drift
        // compensation's frames gave hundreds: the far half is moved by what they say, all
        // its clocks together. Their line goes on into the cycles: it knows the far
        // reference's rate, which a new one took 128 samples to learn while the far half
        // drifted away (3.8 µs at 30 ppm).
        if let Some(e) = self.m.far_steer.as_ref().and_then(|f| f.clock.error_now()) {
            self.m.shift_far_half(-e, None);
            if let Some(f) = self.m.far_steer.as_mut() {
                f.clock.applied(-e);
                f.forget_offset();
            }
        }
        if !converged {
            max_diff = self.m.dc().dc_differences()?.iter().map(|&(_, d)| d.unsigned_abs() as u32).max().unwrap_or(0);
        }
        if let Some(rates) = crystal_rates.filter(|_| converged) {
            self.m.measure_speed_direction(&rates)?;
        }
        // A ring split from the start closes only when the master opens it.
        self.m.arm_split_watch()?;
        // 7. Cyclic distribution from now on.
        self.m.distribute_dc();
        // 9. SYNC0 on the cycle grid of the reference's time.
        let targets: Vec<u16> = match &cfg.sync0_slaves {
            Some(v) => v.clone(),
            None => sync0_by_sii(&self.m.slaves),
        };
        let sync0_start = if targets.is_empty() { None } else { Some(self.m.start_sync(&targets, cfg)?) };
        let sync0_held = self.m.sync0_held(&targets, cfg.sync0_cycle_ns)?;
        tracing::info!(
            "DC set up: reference slave {reference}, static drift compensation {frames} frames, {}, SYNC0 on {} slave(s)",
            if converged { "converged" } else { "not converged" },
            targets.len()
        );
        // Diagnosis reads the sync-error flag of the slaves SYNC0 now runs on.
        self.m.diagnosis.sync0_slaves = targets.clone();
        self.m.diagnosis.sync_pending = None;
        Ok(DcReport {
            reference: reference as u16,
            static_frames: frames,
            static_ns,
            reference_steered: steer.is_some(),
            converged,
            max_difference_ns: max_diff,
            sync0_start,
            sync0_slaves: targets,
            sync0_held,
        })
    }

    /// Every DC slave's filtered system time difference (0x092C), signed.
    pub fn dc_differences(&mut self) -> Result<Vec<(u16, i64)>> {
        let dc: Vec<(u16, u16)> =
            self.m.slaves.iter().filter(|s| s.dc.has_system_time).map(|s| (s.position, s.station)).collect();
        let mut bufs = vec![[0u8; 4]; dc.len()];
        {
            let mut p: Vec<Pdu<'_>> = dc
                .iter()
                .zip(bufs.iter_mut())
                .map(|(&(_, st), b)| {
                    Pdu::new(Command::FPRD, Address::Device { adp: st, ado: addr::DC_SYSTEM_TIME_DIFFERENCE }, b)
                })
                .collect();
            // A slave that did not answer read zero: not "synchronised".
            self.m.engine.expect_wkc_each(&mut p, 1)?;
        }
        Ok(dc
            .iter()
            .zip(&bufs)
            .map(|(&(pos, _), b)| (pos, SystemTimeDifference(u32::from_le_bytes(*b)).as_ns()))
            .collect())
    }

    /// The sync monitor: one BRD of 0x092C, the OR of every slave's |difference| (an upper
    /// bound of the largest), as IgH's monitor reads it.
    pub fn dc_monitor(&mut self) -> Result<u32> {
        let mut d = [0u8; 4];
        self.m.engine.one(Command::BRD, Address::Device { adp: 0, ado: addr::DC_SYSTEM_TIME_DIFFERENCE }, &mut d)?;
        Ok(u32::from_le_bytes(d) & 0x7FFF_FFFF)
    }
}

impl<'a, I: Io> crate::master::part::Clock<'a, I> {
    /// Starts clock synchronisation with `method` for a cycle of `cycle_ns`: the DC
    /// initialisation (`cfg`) and the method, in the order the method needs. ferrocat's own is
    /// made first, so that one steering the reference's offset does so from the static drift
    /// compensation on; the others after it, as published (Park 2020's delay is measured over
    /// its round trips then). Returns the running method, the DC initialisation's report, and
    /// the state to pass to each [`Cyclic::cycle_sync`](crate::part::Cyclic::cycle_sync) or [`Clock::sync_step`](crate::part::Clock::sync_step).
    pub fn start_clock_sync(
        &mut self,
        cfg: &DcConfig,
        method: &crate::sync::SyncMethod,
        cycle_ns: u64,
    ) -> Result<(Box<dyn crate::sync::ClockSync>, DcReport, SyncState)> {
        let resolution_ns = self.m.engine.io.timer_resolution_ns();
        let (sync, report) = if method.is_ferrocat() {
            let mut sync = method.build(cycle_ns, 0, resolution_ns);
            let report = self.m.dc().init_dc_with(cfg, Some(sync.as_mut()))?;
            (sync, report)
        } else {
            let report = self.m.dc().init_dc(cfg)?;
            (self.m.clock().make_clock_sync(method, cycle_ns)?, report)
        };
        tracing::info!(method = sync.name(), cycle_ns, "clock sync started");
        let st = self.m.clock().sync_state()?;
        Ok((sync, report, st))
    }

    /// `method` made for a cycle of `cycle_ns` on a master whose DC is initialised already
    /// (Park 2020's delay is measured here, over its round trips). [`Clock::start_clock_sync`](crate::part::Clock::start_clock_sync)
    /// does the DC initialisation and this in the order the method needs.
    pub fn make_clock_sync(
        &mut self,
        method: &crate::sync::SyncMethod,
        cycle_ns: u64,
    ) -> Result<Box<dyn crate::sync::ClockSync>> {
        let park_delay_ns = match *method {
            crate::sync::SyncMethod::Park2020 { round_trips, .. } => self.m.clock().park_delay(round_trips)?,
            _ => 0,
        };
        Ok(method.build(cycle_ns, park_delay_ns, self.m.engine.io.timer_resolution_ns()))
    }

    /// A fresh state for cyclic synchronisation, with the reference's loop time.
    pub fn sync_state(&self) -> Result<SyncState> {
        Ok(SyncState {
            loop_ns: self.reference_loop_ns()?,
            ring: self.m.engine.redundancy.state,
            ..SyncState::default()
        })
    }

    /// How long a frame spends behind the reference before it passes it again on its way
    /// back: the latest receive time of its other open ports minus that of its entry port.
    /// On an intact ring the frame leaves for the secondary port instead of coming back through
    /// the reference: the loop is shorter by what `find_ring_port` measured.
    pub fn reference_loop_ns(&self) -> Result<u64> {
        let line = self.m.loop_ns_of(self.m.reference_index()?);
        Ok((line as i64 - self.m.ring_shortening_ns).max(0) as u64)
    }

    /// Park 2020 eq. 3 over `n` round trips: each a latching broadcast timed by the master from
    /// its send call's return to its arrival, then the reference's receive times. Returns the
    /// averaged delay.
    pub fn park_delay(&mut self, n: u32) -> Result<i64> {
        let r = self.m.reference_index()?;
        let (st, active, entry) =
            (self.m.slaves[r].station, self.m.slaves[r].ports.active, self.m.slaves[r].ports.entry);
        let mut trips = Vec::with_capacity(n as usize);
        for _ in 0..n {
            // Eq. 3's t_p0^m is taken "immediately after sending", t_p1^m once it is back.
            let (_, t0) = self.m.engine.one_timed(
                Command::BWR,
                Address::Device { adp: 0, ado: addr::DC_RECEIVE_TIME_PORT0 },
                &mut [0u8; 4],
            )?;
            let t1 = self.m.engine.io.now_ns();
            let times = self.m.port_receive_times(st)?;
            // Eq. 3's t_p1 − t_p0 is the time the frame spends behind the reference: on a line
            // through its port 1, but none where the reference is the last slave (port 1
            // closed, its receive time never latched: taken as it read, it put Park's delay,
            // and the reference, 2.1 s off with one slave), and its other ports' on a tree.
            trips.push((t1 - t0, loop_of(&times, active, entry)));
        }
        Ok(crate::sync::Park2020::delay_from(&trips))
    }

    /// One cycle of clock synchronisation: one frame with the master's time for the reference
    /// (reference-follows-master methods), the FRMW that distributes the reference's time and a
    /// read of its 0x092C; the sample goes to `sync`, and an offset shift it asks for is
    /// written to every DC slave. Returns the correction (the next period for
    /// master-follows-reference methods). Lost frames are counted, not errors.
    /// [`Cyclic::cycle_sync`](crate::part::Cyclic::cycle_sync) sends the same datagrams behind the process data, in one frame.
    pub fn sync_step(
        &mut self,
        sync: &mut dyn crate::sync::ClockSync,
        st: &mut SyncState,
    ) -> Result<crate::sync::Correction> {
        let mut p = self.m.sync_begin(sync, st, SYNC_ROOM_BYTES)?;
        let mut nop: [u8; 0] = [];
        let (mut pdus, n) = p.pdus(&mut nop);
        let pdus = &mut pdus[..n];
        let frame_bytes = frame_bytes(pdus);
        let res = self.m.engine.transact_once(pdus, self.m.settings.cyclic_timeout_ns);
        let passes = self.m.engine.redundancy.split_passes.take();
        let answered = match res {
            Ok(()) => SyncPdus::answered(pdus),
            Err(_) => SyncAnswers::NONE,
        };
        let c = self.m.sync_end(sync, st, &p, answered, frame_bytes, 0)?;
        self.m.note_ring(passes)?;
        Ok(c)
    }

    /// Adds `shift_ns` to every DC slave's System_Time_Offset (0x0920).
    pub fn shift_offsets(&mut self, shift_ns: i64) -> Result<()> {
        self.m.shift_offsets_but(shift_ns, None)
    }
}

#[cfg(test)]
mod tests {
    use super::unwrap32;

    #[test]
    fn a_32_bit_register_is_unwrapped_across_its_wrap_both_ways() {
        assert_eq!(unwrap32(None, 0x1_2345_6789), 0x2345_6789, "the first value is its low word");
        let before = (7u64 << 32) | 0xFFFF_FF00;
        assert_eq!(unwrap32(Some(before), 0x0000_0100), (8u64 << 32) | 0x100, "forward over the wrap");
        assert_eq!(unwrap32(Some((8u64 << 32) | 0x10), 0xFFFF_FFF0), (7u64 << 32) | 0xFFFF_FFF0, "back over it");
        assert_eq!(unwrap32(Some(5), 3), 3);
    }
}
