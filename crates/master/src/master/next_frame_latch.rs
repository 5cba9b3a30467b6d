//! A second latch for controllers whose ports 1–3 take the frame after the write to 0x0900:
//! the ET1200 and ESC20 (register description, 0x0904) and the IP core in forwarding mode
//! (0x0936 = 0; esc-spec).
//!
//! Entered on port 0, such an ESC sees the writing frame at ports 1–3 only after its
//! processing unit, and takes it there. Entered elsewhere (reversed cabling, the far half of
//! a ring split before the master started), the ports the frame passed before the processing
//! unit take the next frame through them, a master round trip or more later: the times then
//! fit no tree, or a wrong one. The master latches such slaves again: a write R, then frames S
//! and T that each read the ports and then write 0x0900, then U that reads. A read runs before
//! its frame's write applies (at the end of the frame), so S reads what S's own arrival
//! latched at a port R enabled, and T reads what S's write latched (port 0, the processing
//! unit, the ports after it). A port's two readings differ by the spacing of R and S if they
//! are written frames' stamps (R's, then S's) and by that of S and T if they are arrivals
//! (S's, then T's); the ESC's own processing-unit (or port 0) times give both spacings, which
//! a pause before T keeps apart. Every time is then S's, and is carried into the first
//! latch's frame by the processing unit's (or port 0's) time in each: the offsets stay those
//! of one frame for every slave, and the geometry (times within one ESC) is exact.
use ferrocat_wire::register::addr;
use ferrocat_wire::{Address, Command};

use super::Master;
use crate::engine::Pdu;
use crate::error::{MasterError, Result};
use crate::io::Io;

/// ESC types (0x0000) whose ports 1–3 take the frame after the write: ESC20, IP core, ET1200.
const NEXT_FRAME_TYPES: [u8; 3] = [0x02, IP_CORE, 0x12];
const IP_CORE: u8 = 0x04;
/// Slaves per round: one frame of reads (16 + 8 bytes of data and two headers each).
const PER_ROUND: usize = 24;
/// The pause before T, so that the spacings R→S and S→T differ.
const PAUSE_NS: u64 = 50_000;
/// A reading within this of a spacing is of it: 10 ns latches, and drift over the spacing.
const MATCH_NS: i64 = 60;
const ATTEMPTS: usize = 3;

/// One slave's readings of 0x0900–0x090F and 0x0918 (where it has a system time).
#[derive(Debug, Clone, Copy, Default)]
struct Reading {
    ports: [u32; 4],
    epu: Option<u32>,
}

impl<I: Io> Master<I> {
    /// An IP core's receive-time latch in forwarding mode (0x0936 = 0, the reset value, which
    /// a master before may have changed): in reverse mode the ports after the processing unit
    /// would give the frame before the write.
    pub(super) fn forwarding_latch_mode(&mut self) -> Result<()> {
        if self.slaves.iter().any(|s| s.dc.supported && s.esc.kind == IP_CORE) {
            self.engine.one(
                Command::BWR,
                Address::Device { adp: 0, ado: addr::DC_RECEIVE_TIME_LATCH_MODE },
                &mut [0],
            )?;
        }
        Ok(())
    }

    /// DC slaves of a next-frame type with a port other than 0 in use (the one they are
    /// entered by, or a branch): the first latch may have given it a later frame's time.
    pub(super) fn next_frame_slaves(&self) -> Vec<usize> {
        (0..self.slaves.len())
            .filter(|&k| {
                let s = &self.slaves[k];
                s.dc.supported && NEXT_FRAME_TYPES.contains(&s.esc.kind) && s.ports.active[1..].iter().any(|&a| a)
            })
            .collect()
    }

    /// Latches `targets` again (module doc) and puts their receive times, as the first latch's
    /// frame would have given them, in place of the first latch's; returns where it did.
    pub(super) fn relatch_next_frame(&mut self, targets: &[usize]) -> Result<Vec<usize>> {
        let probes = std::mem::replace(&mut self.engine.redundancy.probes_off, true);
        let mut replaced = Vec::new();
        let done = targets.chunks(PER_ROUND).try_for_each(|chunk| self.relatch_round(chunk, &mut replaced));
        self.engine.redundancy.probes_off = probes;
        done.map(|()| replaced)
    }

    fn relatch_round(&mut self, chunk: &[usize], replaced: &mut Vec<usize>) -> Result<()> {
        for _ in 0..ATTEMPTS {
            self.engine.one(Command::BWR, Address::Device { adp: 0, ado: addr::DC_RECEIVE_TIME_PORT0 }, &mut [0; 4])?;
            let s = self.read_receive_times(chunk, true)?;
            let resume_ns = self.engine.io.now_ns() + PAUSE_NS;
            self.engine.io.sleep_until(resume_ns);
            let t = self.read_receive_times(chunk, true)?;
            let u = self.read_receive_times(chunk, false)?;
            let merged: Vec<Merged> = chunk
                .iter()
                .enumerate()
                .map(|(i, &k)| as_written_by_s(&s[i], &t[i], &u[i], self.slaves[k].ports.active))
                .collect();
            if merged.contains(&Merged::Ambiguous) {
                continue;
            }
            for (i, (&k, merged)) in chunk.iter().zip(merged).enumerate() {
                // Without a processing-unit time or port 0 in use, nothing tells the readings
                // apart: the first latch's stand.
                let Merged::Times(times) = merged else { continue };
                let sl = &mut self.slaves[k];
                // S's times into the first latch's frame, by the processing unit's time in
                // each (port 0's without a system time: 0x0918's low word where it exists).
                let (first, in_s) = match t[i].epu {
                    Some(epu) if sl.dc.has_system_time => (sl.dc.receive_time_epu as u32, epu),
                    _ => (sl.dc.receive_times[0], times[0]),
                };
                let shift = first.wrapping_sub(in_s);
                sl.dc.receive_times = times.map(|x| x.wrapping_add(shift));
                sl.ports.entry = entry_by_times(sl.dc.receive_times, sl.ports.active, sl.ports.entry);
                replaced.push(k);
            }
            return Ok(());
        }
        Err(MasterError::Relatch {
            slaves: chunk
                .iter()
                .map(|&k| crate::error::SlaveRef { position: k as u16, name: self.slaves[k].name.clone() })
                .collect(),
            tries: ATTEMPTS as u32,
        })
    }

    /// One frame: each slave's 0x0900–0x090F and 0x0918, then (with `write`) a BWR of 0x0900.
    fn read_receive_times(&mut self, chunk: &[usize], write: bool) -> Result<Vec<Reading>> {
        let mut ports = vec![[0u8; 16]; chunk.len()];
        let mut epus = vec![[0u8; 8]; chunk.len()];
        let mut latch = [0u8; 4];
        let mut pdus = Vec::with_capacity(2 * chunk.len() + 1);
        let mut epu_at = Vec::with_capacity(chunk.len());
        for ((&k, p), e) in chunk.iter().zip(&mut ports).zip(&mut epus) {
            let st = self.slaves[k].station;
            pdus.push(Pdu::new(Command::FPRD, Address::Device { adp: st, ado: addr::DC_RECEIVE_TIME_PORT0 }, p));
            epu_at.push(self.slaves[k].dc.has_system_time.then_some(pdus.len()));
            if self.slaves[k].dc.has_system_time {
                pdus.push(Pdu::new(Command::FPRD, Address::Device { adp: st, ado: addr::DC_RECEIVE_TIME_EPU }, e));
            }
        }
        if write {
            pdus.push(Pdu::new(Command::BWR, Address::Device { adp: 0, ado: addr::DC_RECEIVE_TIME_PORT0 }, &mut latch));
        }
        self.engine.transact(&mut pdus)?;
        if let Some(p) = pdus.iter().find(|p| p.cmd == Command::FPRD && p.wkc != 1) {
            return Err(MasterError::Wkc {
                datagram: crate::engine::datagram_ref(p),
                expected: 1,
                got: p.wkc,
                slaves: " (latching receive times again)".into(),
            });
        }
        let epu_values: Vec<Option<u32>> =
            epu_at.iter().map(|at| at.map(|i| u32::from_le_bytes(pdus[i].data[..4].try_into().unwrap()))).collect();
        drop(pdus);
        Ok(ports.iter().zip(epu_values).map(|(p, epu)| Reading { ports: super::port_times(p), epu }).collect())
    }
}

/// The entry port: the active port that saw the frame first (reversed cabling puts it
/// elsewhere than port 0).
pub(super) fn entry_by_times(times: [u32; 4], active: [bool; 4], otherwise: u8) -> u8 {
    (0..4u8)
        .filter(|&p| active[p as usize])
        .min_by_key(|&p| times[p as usize].wrapping_sub(times[0]) as i32)
        .unwrap_or(otherwise)
}

#[derive(Debug, Clone, Copy, PartialEq, Eq)]
enum Merged {
    /// The port times as frame S latched them.
    Times([u32; 4]),
    /// Neither a processing-unit time nor port 0 in use to measure the spacings by.
    NoReference,
    /// The two spacings too close to tell apart, or a reading that fits neither.
    Ambiguous,
}

/// The slave's port times as frame S latched them, from S's, T's and U's readings.
fn as_written_by_s(s: &Reading, t: &Reading, u: &Reading, active: [bool; 4]) -> Merged {
    let diff = |a: u32, b: u32| b.wrapping_sub(a) as i32 as i64;
    // R→S and S→T in this ESC's clock.
    let (rs, st) = match (s.epu, t.epu, u.epu) {
        (Some(a), Some(b), Some(c)) => (diff(a, b), diff(b, c)),
        _ if active[0] => (diff(s.ports[0], t.ports[0]), diff(t.ports[0], u.ports[0])),
        _ => return Merged::NoReference,
    };
    if (st - rs).abs() <= 2 * MATCH_NS {
        return Merged::Ambiguous;
    }
    let mut out = t.ports;
    for p in (1..4).filter(|&p| active[p]) {
        let d = diff(s.ports[p], t.ports[p]);
        if (d - st).abs() <= MATCH_NS {
            // S's arrival, which S read.
            out[p] = s.ports[p];
        } else if (d - rs).abs() > MATCH_NS {
            return Merged::Ambiguous;
        }
    }
    Merged::Times(out)
}

#[cfg(test)]
mod tests {
    use super::*;

    /// One ESC entered on port 1 with a branch on port 0 and one on port 3: port 1 (entry)
    /// 300 ns and port 0 20 ns before its processing unit, port 3 500 ns after; frames R, S,
    /// T written at `epu[0..3]` (local ns, wrapping), U reading.
    fn readings(next_frame: bool, epu: [u32; 3]) -> (Reading, Reading, Reading) {
        let at = |e: u32| [e.wrapping_sub(20), e.wrapping_sub(300), 0, e.wrapping_add(500)];
        let frame = |k: usize| at(epu[k]);
        // What a read finds after frame k wrote, read in frame `k + 1` (whose arrival an
        // enabled port 1 takes before the read).
        let read = |k: usize| {
            let mut p = frame(k);
            if next_frame {
                p[1] = epu.get(k + 1).map_or(epu[k].wrapping_add(200_000), |&e| e).wrapping_sub(300);
            }
            Reading { ports: p, epu: Some(epu[k]) }
        };
        (read(0), read(1), read(2))
    }

    const ACTIVE: [bool; 4] = [true, true, false, true];

    #[test]
    fn every_port_comes_out_as_frame_s_took_it_across_the_32_bit_wrap() {
        // R, S and T 40 µs then 90 µs apart, S's processing unit just past the wrap.
        let s_epu = 25u32;
        let epu = [s_epu.wrapping_sub(40_000), s_epu, s_epu.wrapping_add(90_000)];
        let want = [s_epu.wrapping_sub(20), s_epu.wrapping_sub(300), 0, s_epu.wrapping_add(500)];
        for next_frame in [false, true] {
            let (s, t, u) = readings(next_frame, epu);
            let Merged::Times(got) = as_written_by_s(&s, &t, &u, ACTIVE) else { panic!("{next_frame}") };
            assert_eq!([got[0], got[1], got[3]], [want[0], want[1], want[3]], "next frame: {next_frame}");
        }
    }

    #[test]
    fn spacings_too_close_or_nothing_to_measure_them_by() {
        let (s, t, u) = readings(true, [0, 40_000, 80_050]);
        assert_eq!(as_written_by_s(&s, &t, &u, ACTIVE), Merged::Ambiguous);
        let no_epu = |r: Reading| Reading { epu: None, ..r };
        let (s, t, u) = readings(true, [0, 40_000, 130_000]);
        assert_eq!(
            as_written_by_s(&no_epu(s), &no_epu(t), &no_epu(u), [false, true, false, false]),
            Merged::NoReference
        );
        // Without a processing-unit time, port 0 (in use) measures the spacings.
        assert!(matches!(as_written_by_s(&no_epu(s), &no_epu(t), &no_epu(u), ACTIVE), Merged::Times(_)));
        // A reading that fits neither spacing.
        let mut odd = t;
        odd.ports[3] = odd.ports[3].wrapping_add(7_000);
        assert_eq!(as_written_by_s(&s, &odd, &u, ACTIVE), Merged::Ambiguous);
    }

    #[test]
    fn the_entry_is_the_earliest_port_in_use() {
        let t = [1_000, 700, 5, u32::MAX];
        assert_eq!(entry_by_times(t, [true, true, false, false], 0), 1);
        assert_eq!(entry_by_times(t, [true, false, false, true], 3), 3, "across the wrap: earliest");
        assert_eq!(entry_by_times(t, [false; 4], 2), 2);
    }
}
