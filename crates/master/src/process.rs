//! The cyclic exchange of the process image. `cycle` does not allocate: the image is split
//! over frames with slices of the image itself, and statistics are plain counters.
use ferrocat_wire::datagram::{HEADER_LEN, WKC_LEN};
use ferrocat_wire::frame::MAX_PDU_LEN;
use ferrocat_wire::register::addr;
use ferrocat_wire::{Address, Command};

use crate::cycle_state::{CycleState, CycleStats};
use crate::engine::Pdu;
use crate::error::{ConfigError, MasterError, Result};
use crate::io::Io;
use crate::master::Master;

/// Data bytes of one LRW that still fit a frame.
const CHUNK: usize = MAX_PDU_LEN - HEADER_LEN - WKC_LEN;
/// Up to this many frames per cycle (8 × 1486 bytes of process image).
const MAX_CHUNKS: usize = 8;
/// The image's LRWs and, with DC distribution, one FRMW or the sync datagrams (three, a
/// follower's clock where the method reads one, and the method's writes riding on the frame).
const MAX_PDUS: usize = MAX_CHUNKS + crate::dc::MAX_SYNC_PDUS;

pub use crate::handle::Handle;

impl<I: Io> Master<I> {
    fn apply_copies(&mut self) {
        for k in 0..self.copies.len() {
            let (from, to) = self.copies[k];
            let v = self.image().get(from);
            self.cyclic().set(to, v);
        }
    }

    fn cycle_inner(
        &mut self,
        sync: Option<(&mut dyn crate::sync::ClockSync, &mut crate::SyncState)>,
    ) -> Result<(u16, Option<crate::sync::Correction>)> {
        let start = self.engine.io.now_ns();
        let st = &mut self.cyc.stats;
        if let Some(prev) = self.cyc.last_start {
            st.last_period_ns = start - prev;
            if st.nominal_period_ns > 0 {
                st.max_jitter_ns = st.max_jitter_ns.max(st.last_period_ns.abs_diff(st.nominal_period_ns));
            }
        }
        self.cyc.last_start = Some(start);
        if self.plan.is_some() {
            return self.cycle_plan(sync);
        }
        let mut sync = sync;
        // The sync datagrams follow the image's last chunk in its frame.
        let last_chunk = match self.image.len() % CHUNK {
            0 if self.image.is_empty() => 0,
            0 => CHUNK,
            r => r,
        };
        let room = crate::dc::SYNC_ROOM_BYTES.saturating_sub(last_chunk + HEADER_LEN + WKC_LEN);
        let mut sp = match sync.as_mut() {
            Some((m, st)) => Some(self.sync_begin(&mut **m, st, room)?),
            None => None,
        };
        if self.image.is_empty() && self.dc_reference.is_none() {
            return Ok((0, None));
        }
        let chunks = self.image.len().div_ceil(CHUNK);
        if chunks > MAX_CHUNKS {
            return Err(ConfigError::ImageTooLarge { bytes: self.image.len(), max_frames: MAX_CHUNKS }.into());
        }
        let mut empty: [[u8; 0]; MAX_PDUS] = [[]; MAX_PDUS];
        let mut nop: [u8; 0] = [];
        let cyclic_timeout_ns = self.settings.cyclic_timeout_ns;
        let Master { image, frmw, engine, dc_reference, .. } = self;
        let mut parts = image.chunks_mut(CHUNK);
        let mut e = empty.iter_mut();
        let mut frmw = Some(&mut frmw[..]);
        let reference = *dc_reference;
        let with_sync = sp.is_some();
        let mut extra = sp.as_mut().map(|p| {
            let (pdus, n) = p.pdus(&mut nop);
            pdus.into_iter().take(n)
        });
        let n = chunks + extra.as_ref().map_or(reference.is_some() as usize, |x| x.len());
        let mut pdus: [Pdu<'_>; MAX_PDUS] = std::array::from_fn(|k| {
            if let Some(p) = parts.next() {
                return Pdu::new(Command::LRW, Address::Logical((k * CHUNK) as u32), p);
            }
            if let Some(x) = extra.as_mut().and_then(|x| x.next()) {
                return x;
            }
            match (reference, frmw.take()) {
                (Some(st), Some(f)) => {
                    Pdu::new(Command::FRMW, Address::Device { adp: st, ado: addr::DC_SYSTEM_TIME }, f)
                }
                _ => Pdu::new(
                    Command::NOP,
                    Address::Device { adp: 0, ado: 0 },
                    e.next().map(|x| &mut x[..]).unwrap_or_default(),
                ),
            }
        });
        drop(extra);
        let frame_bytes = crate::engine::frame_bytes(&pdus[..n]);
        let data_bytes = crate::engine::bytes_through(&pdus[..chunks]);
        // Process data is not sent twice: a lost frame costs this cycle, not the next ones.
        let r = engine.transact_once(&mut pdus[..n], cyclic_timeout_ns);
        let exchanged = engine.io.now_ns();
        let passes = engine.redundancy.split_passes.take();
        let answered = match (r.is_ok(), with_sync) {
            (true, true) => crate::dc::SyncPdus::answered(&pdus[chunks..n]),
            _ => crate::dc::SyncAnswers::NONE,
        };
        let lost = matches!(r, Err(MasterError::Timeout { .. }));
        let wkc = match r {
            Ok(()) => {
                if reference.is_some() && !with_sync {
                    let f = &pdus[chunks];
                    let mut b = [0u8; 8];
                    b.copy_from_slice(&f.data[..8]);
                    self.dc_time = u64::from_le_bytes(b);
                }
                pdus[..chunks].iter().map(|p| p.wkc).min().unwrap_or(self.expected_wkc)
            }
            Err(MasterError::Timeout { .. }) => {
                self.cyc.stats.lost_frames += 1;
                tracing::debug!("cyclic frame lost ({} so far)", self.cyc.stats.lost_frames);
                0
            }
            Err(e) => return Err(e),
        };
        let correction = match (sync, sp) {
            (Some((m, st)), Some(p)) => {
                if answered.sync {
                    self.dc_time = u64::from_le_bytes(p.frmw);
                }
                Some(self.sync_end(m, st, &p, answered, frame_bytes, data_bytes)?)
            }
            _ => None,
        };
        self.note_ring(passes)?;
        let expected = self.expected_wkc;
        self.apply_copies();
        self.finish_cycle(start, exchanged, wkc, expected, lost)?;
        Ok((wkc, correction))
    }

    /// The plan's frames, one after the other: each datagram's data from the output image, its
    /// answer into the input image, its working counter added to the cycle's. A clock-sync
    /// method's datagrams ride behind the first frame's, as they ride behind the image's LRW
    /// without a plan.
    fn cycle_plan(
        &mut self,
        sync: Option<(&mut dyn crate::sync::ClockSync, &mut crate::SyncState)>,
    ) -> Result<(u16, Option<crate::sync::Correction>)> {
        use crate::plan::{Plan, MAX_PLAN_DATAGRAMS};
        let start = self.cyc.last_start.unwrap_or_else(|| self.engine.io.now_ns());
        let mut sync = sync;
        let room = self.plan_room_bytes();
        let mut sp = match sync.as_mut() {
            Some((m, st)) => Some(self.sync_begin(&mut **m, st, room)?),
            None => None,
        };
        let mut nop: [u8; 0] = [];
        let cycle = self.cyc.stats.cycles;
        let Master { image, engine, settings, plan, out_bytes, .. } = self;
        let Some((plan, buffers)) = plan.as_mut() else { return Ok((0, None)) };
        let (out_len, timeout) = (*out_bytes as usize, settings.cyclic_timeout_ns);
        let (mut wkc, mut expected, mut lost) = (0u16, 0u16, false);
        let mut timing = None;
        let mut extra = sp.as_mut().map(|p| {
            let (pdus, n) = p.pdus(&mut nop);
            pdus.into_iter().take(n)
        });
        let mut first = true;
        for (f, (datagrams, bufs)) in plan.frames.iter().zip(buffers.frames.iter_mut()).enumerate() {
            if !plan.due(f, cycle) {
                continue;
            }
            let fs = &mut buffers.stats[f];
            fs.sent += 1;
            expected = expected.saturating_add(fs.expected_wkc);
            for (d, b) in datagrams.iter().zip(bufs.iter_mut()) {
                let len = b.len();
                match d.output_offset {
                    Some(o) => b.copy_from_slice(&image[Plan::data_at(o)..Plan::data_at(o) + len]),
                    None => b.fill(0),
                }
            }
            let own = datagrams.len().min(MAX_PLAN_DATAGRAMS);
            // The clock-sync method's datagrams ride behind the first frame due.
            let mut behind = if first { extra.take() } else { None };
            let n = own + behind.as_ref().map_or(0, |x| x.len());
            let mut parts = bufs.iter_mut();
            let mut pdus: [Pdu<'_>; MAX_PLAN_DATAGRAMS + crate::dc::MAX_SYNC_PDUS] =
                std::array::from_fn(|k| match (datagrams.get(k).filter(|_| k < own), parts.next()) {
                    (Some(d), Some(b)) => Pdu::new(d.command, d.address, b),
                    _ => match behind.as_mut().and_then(|x| x.next()) {
                        Some(p) => p,
                        None => Pdu::new(Command::NOP, Address::Device { adp: 0, ado: 0 }, &mut []),
                    },
                });
            let r = engine.transact_once(&mut pdus[..n], timeout);
            if std::mem::take(&mut first) {
                let answered = match (&r, n > own) {
                    (Ok(()), true) => crate::dc::SyncPdus::answered(&pdus[own..n]),
                    _ => crate::dc::SyncAnswers::NONE,
                };
                let bytes = (crate::engine::frame_bytes(&pdus[..n]), crate::engine::bytes_through(&pdus[..own]));
                timing = Some((bytes, answered));
            }
            let fs = &mut buffers.stats[f];
            match r {
                Ok(()) => {}
                Err(MasterError::Timeout { .. }) => {
                    lost = true;
                    fs.lost += 1;
                    continue;
                }
                Err(e) => return Err(e),
            }
            let mut frame_wkc = 0u16;
            for (d, p) in datagrams.iter().zip(&pdus[..own]) {
                if let Some(o) = d.input_offset {
                    let at = out_len + Plan::data_at(o);
                    image[at..at + p.data.len()].copy_from_slice(p.data);
                }
                if d.expected_wkc.is_some() {
                    frame_wkc = frame_wkc.saturating_add(p.wkc);
                }
            }
            fs.last_wkc = frame_wkc;
            fs.short += (frame_wkc != fs.expected_wkc) as u64;
            wkc = wkc.saturating_add(frame_wkc);
        }
        drop(extra);
        let exchanged = engine.io.now_ns();
        if lost {
            self.cyc.stats.lost_frames += 1;
        }
        let correction = match (sync, sp, timing) {
            (Some((m, st)), Some(p), Some(((frame_bytes, data_bytes), answered))) => {
                if answered.sync {
                    self.dc_time = u64::from_le_bytes(p.frmw);
                }
                Some(self.sync_end(m, st, &p, answered, frame_bytes, data_bytes)?)
            }
            _ => None,
        };
        let passes = self.engine.redundancy.split_passes.take();
        self.note_ring(passes)?;
        self.apply_copies();
        self.finish_cycle(start, exchanged, wkc, expected, lost)?;
        Ok((wkc, correction))
    }

    /// What the first frame of the plan due this cycle leaves for the sync datagrams' riders.
    fn plan_room_bytes(&self) -> usize {
        let Some((plan, buffers)) = self.plan.as_ref() else { return 0 };
        let cycle = self.cyc.stats.cycles;
        let due = (0..plan.frames.len()).find(|&f| plan.due(f, cycle));
        let used: usize = due
            .map(|f| buffers.frames[f].iter().map(|b| HEADER_LEN + b.len() + WKC_LEN).sum())
            .unwrap_or(ferrocat_wire::frame::MAX_PDU_LEN);
        crate::dc::SYNC_ROOM_BYTES.saturating_sub(used)
    }

    /// A cycle's statistics, and the slaves checked after a cycle answered short.
    fn finish_cycle(&mut self, start: u64, exchanged: u64, wkc: u16, expected: u16, lost: bool) -> Result<()> {
        let st = &mut self.cyc.stats;
        st.cycles += 1;
        st.last_wkc = wkc;
        // The cycle's frames alone: a method's probes after them are not their round trip.
        let trip = exchanged.saturating_sub(start);
        st.last_round_trip_ns = trip;
        st.max_round_trip_ns = st.max_round_trip_ns.max(trip);
        let short = wkc != expected;
        if short {
            st.wkc_errors += 1;
        }
        // A cycle answered short: find out why (a frame lost says nothing of the slaves, and
        // a read after it would cost the cycle a second wait); and until every fallen slave is
        // back, since one acknowledged in SAFEOP answers its process data in full (its outputs
        // given back) and would stay there.
        if ((short && !lost) || self.cyc.recovering) && self.settings.supervise_on_wkc {
            self.states().supervise()?;
        }
        Ok(())
    }
}

impl<'a, I: Io> crate::master::part::Cyclic<'a, I> {
    /// Writes `value` (its low `bits` bits) into the image.
    pub fn set(&mut self, h: Handle, value: u64) {
        for b in 0..h.bits as u32 {
            let at = (h.bit + b) as usize;
            let Some(byte) = self.m.image.get_mut(at / 8) else { return };
            let bit = 1u8 << (at % 8);
            if value >> b & 1 == 1 {
                *byte |= bit;
            } else {
                *byte &= !bit;
            }
        }
    }

    /// Slave-to-slave communication through the master (ETG.1500 item 1201): after every
    /// cycle, each `from`'s value (an input) is written into `to` (an output), which the next
    /// cycle sends, so that it reaches its slave one cycle after it was read. Each pair the
    /// same width, at most 64 bits, within the image (after the layout).
    pub fn set_copies(&mut self, copies: Vec<(Handle, Handle)>) -> Result<()> {
        let bits = self.m.image.len() as u64 * 8;
        for (k, (from, to)) in copies.iter().enumerate() {
            if from.bits != to.bits || from.bits == 0 || from.bits > 64 {
                return Err(ConfigError::CopyWidth { copy: k, from_bits: from.bits, to_bits: to.bits }.into());
            }
            if [from, to].iter().any(|h| h.bit as u64 + h.bits as u64 > bits) {
                return Err(ConfigError::CopyOutsideImage {
                    copy: k,
                    from: (from.bit, from.bit + from.bits as u32),
                    to: (to.bit, to.bit + to.bits as u32),
                    image_bits: bits,
                }
                .into());
            }
        }
        self.m.copies = copies;
        Ok(())
    }

    /// Sets the nominal period the jitter figures are measured against.
    pub fn set_period_ns(&mut self, ns: u64) {
        self.m.cyc.stats.nominal_period_ns = ns;
    }

    /// One exchange of the whole process image (LRW, split over frames when it is larger than
    /// one). Returns the working counter; a shortfall is counted, not an error, so that the
    /// control loop keeps running.
    pub fn cycle(&mut self) -> Result<u16> {
        self.m.cycle_inner(None).map(|(wkc, _)| wkc)
    }

    /// [`Cyclic::cycle`](crate::part::Cyclic::cycle) with the clock synchronisation of [`Clock::sync_step`](crate::part::Clock::sync_step) in the same
    /// frame, behind the process data (as SOEM appends its FRMW): one frame per cycle, and the
    /// method's timing is the process data's. Returns the working counter and the correction.
    pub fn cycle_sync(
        &mut self,
        sync: &mut dyn crate::sync::ClockSync,
        st: &mut crate::SyncState,
    ) -> Result<(u16, crate::sync::Correction)> {
        let (wkc, c) = self.m.cycle_inner(Some((sync, st)))?;
        Ok((wkc, c.unwrap_or_default()))
    }
}

impl<'a, I: Io> crate::master::part::Diagnosis<'a, I> {
    /// The cyclic exchange's statistics so far.
    pub fn cycle_stats(&self) -> CycleStats {
        self.m.cyc.stats
    }

    /// Starts the statistics afresh (at the start of cyclic operation).
    pub fn reset_cycle_stats(&mut self) {
        let nominal = self.m.cyc.stats.nominal_period_ns;
        self.m.cyc = CycleState::default();
        self.m.cyc.stats.nominal_period_ns = nominal;
    }

    /// Each of the plan's frames' statistics (a process-data group's), in the plan's order;
    /// empty without a plan.
    pub fn plan_frame_stats(&self) -> Vec<crate::plan::FrameStats> {
        self.m.plan.as_ref().map_or(Vec::new(), |(_, b)| b.stats.clone())
    }
}

/// The handle of the first of `entries` named `name`, or of the entry `INDEX:SUB` in hex
/// (`0x7010:01`, `7010:1`): entries of one slave often share a name (each channel's `Output`).
fn handle_named(entries: &[crate::slave::Mapped], name: &str) -> Option<Handle> {
    let by_index = index_subindex(name);
    entries
        .iter()
        .find(|m| m.name == name || by_index == Some((m.index, m.subindex)))
        .map(|m| Handle { bit: m.image_bit, bits: m.bits })
}

/// `0xIIII:SS` or `IIII:SS`, both hex.
fn index_subindex(name: &str) -> Option<(u16, u8)> {
    let (i, s) = name.trim().split_once(':')?;
    let hex = |t: &str| t.trim().trim_start_matches("0x").trim_start_matches("0X").to_string();
    Some((u16::from_str_radix(&hex(i), 16).ok()?, u8::from_str_radix(&hex(s), 16).ok()?))
}

impl<'a, I: Io> crate::master::part::Image<'a, I> {
    /// The handle of an output entry of slave `position` by its name (first match) or its
    /// `INDEX:SUB` in hex (`0x7010:01`).
    pub fn output(&self, position: u16, name: &str) -> Result<Handle> {
        let s = self.m.slave(position)?;
        handle_named(&s.mapping.outputs, name)
            .ok_or_else(|| MasterError::of(position, &s.name, crate::error::SlaveError::NoOutput(name.into())))
    }

    /// The handle of an input entry of slave `position` by its name (first match) or its
    /// `INDEX:SUB` in hex (`0x6000:01`).
    pub fn input(&self, position: u16, name: &str) -> Result<Handle> {
        let s = self.m.slave(position)?;
        handle_named(&s.mapping.inputs, name)
            .ok_or_else(|| MasterError::of(position, &s.name, crate::error::SlaveError::NoInput(name.into())))
    }

    /// Reads an entry from the image.
    pub fn get(&self, h: Handle) -> u64 {
        let mut v = 0u64;
        for b in 0..h.bits as u32 {
            let at = (h.bit + b) as usize;
            if self.m.image.get(at / 8).is_some_and(|byte| byte >> (at % 8) & 1 == 1) {
                v |= 1 << b;
            }
        }
        v
    }
}

#[cfg(test)]
mod tests {
    use super::{handle_named, index_subindex};
    use crate::slave::Mapped;

    #[test]
    fn entries_sharing_a_name_are_told_apart_by_index() {
        let e = |index, bit| Mapped { index, subindex: 1, bits: 1, name: "Output".into(), image_bit: bit };
        let entries = [e(0x7000, 0), e(0x7010, 1)];
        assert_eq!(handle_named(&entries, "Output").map(|h| h.bit), Some(0), "a name: the first");
        assert_eq!(handle_named(&entries, "0x7010:01").map(|h| h.bit), Some(1));
        assert_eq!(handle_named(&entries, "7010:1").map(|h| h.bit), Some(1));
        assert_eq!(handle_named(&entries, "0x7020:01"), None);
        assert_eq!(index_subindex("Channel 1:Output"), None);
        assert_eq!(index_subindex("0x10000:1"), None, "past 16 bits");
    }
}
