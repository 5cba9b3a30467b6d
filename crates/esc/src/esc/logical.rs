//! Logical datagrams (LRD, LWR, LRW) through the FMMUs, bit by bit where they are not
//! byte-aligned.
//!
//! The walk from a datagram's span to this ESC's bytes depends only on the FMMU and
//! SyncManager registers, which change at configuration, not every cycle. So it is resolved
//! once per datagram shape into a [`Plan`]: the runs of bits each FMMU moves, in the order the
//! byte-wise walk visits them, each with what a write or read of its physical byte does. A
//! cyclic frame then costs the runs, not the search. What depends on the moment (a buffered
//! SyncManager's staging, a register's side effect) is left to run time: such a byte is
//! resolved as [`Access::Byte`] and goes through `write_byte` / `read_byte` as before.
use ferrocat_wire::register::Fmmu;
use ferrocat_wire::Command;

use super::{sm_area, Esc};

/// Plans kept per ESC: a frame layout's logical datagrams (one per process-data group, or a
/// few split at the frame's size) fit; more evict the oldest.
const PLANS_KEPT: usize = 8;

/// What a byte's write or read does, resolved from the configuration.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
enum Access {
    /// Not accessible (an absent byte, a SyncManager the PDI deactivated): nothing happens.
    Fail,
    /// Plain memory: process RAM outside every SyncManager, or a buffer read directly.
    Mem,
    /// A byte of a read-direction buffered SyncManager the master writes: memory, and being
    /// its last byte, the buffer's completion.
    MemLast { sm: u8 },
    /// A byte of a buffered SyncManager the master writes: into its staging buffer.
    Staging { sm: u8, off: u16, area_start: u16, area_len: u16, last: bool },
    /// Resolved at run time by `write_byte` / `read_byte` (registers, mailboxes).
    Byte,
}

/// One run of bits: within one physical and one frame byte.
#[derive(Debug, Clone, Copy)]
struct Run {
    /// Frame byte (from the datagram's data) and physical address.
    fi: u16,
    pa: u16,
    mask_f: u8,
    mask_p: u8,
    /// Bit positions of the run in the frame byte and the physical byte.
    fbit: u8,
    pbit: u8,
    write: Option<Access>,
    read: Option<Access>,
}

/// A logical datagram's walk through this ESC, for one command, span and configuration.
#[derive(Debug, Clone)]
pub(super) struct Plan {
    /// The command, span and whether process memory is accessible, as [`Plan::key`] packs them.
    key: u64,
    /// The frame bytes some FMMU maps, `first..last`, and whether more than one FMMU does
    /// (then writes take the bytes as they arrived, kept aside first).
    first: usize,
    last: usize,
    several: bool,
    runs: Vec<Run>,
}

impl Plan {
    /// What a plan holds for: a datagram's length has 11 bits, its address 32.
    fn key(cmd: Command, logical: u32, len: usize, sii_loaded: bool) -> u64 {
        (sii_loaded as u64) << 52 | (cmd.0 as u64) << 44 | (len as u64 & 0x7FF) << 32 | logical as u64
    }
}

fn shift(v: u8, from: u8, to: u8) -> u8 {
    if to >= from {
        v << (to - from)
    } else {
        v >> (from - to)
    }
}

impl Esc {
    /// LRD/LWR/LRW through the FMMUs. Returns the WKC increment: +1 if something was read,
    /// +2 if something was written (LWR: +1).
    pub(super) fn logical(&mut self, cmd: Command, logical: u32, data: &mut [u8]) -> u16 {
        let key = Plan::key(cmd, logical, data.len(), self.sii_loaded);
        let k = match self.plans.iter().position(|p| p.key == key) {
            Some(k) => k,
            None => {
                let plan = self.plan(cmd, logical, data.len(), true);
                if self.plans.len() == PLANS_KEPT {
                    self.plans.remove(0);
                }
                self.plans.push(plan);
                self.plans.len() - 1
            }
        };
        // The plans leave the ESC for the walk (their runs borrow nothing of the ESC's).
        let plans = std::mem::take(&mut self.plans);
        let inc = self.walk(&plans[k], cmd, data);
        self.plans = plans;
        inc
    }

    /// Resolves the walk of a logical datagram of `len` bytes at `logical`; with `resolve`
    /// false every byte is left to `write_byte` / `read_byte` (the reading the plan must match).
    fn plan(&self, cmd: Command, logical: u32, len: usize, resolve: bool) -> Plan {
        let dg_start = logical as u64 * 8;
        let dg_end = dg_start + len as u64 * 8;
        let overlap = |f: &Fmmu| {
            let f_start = f.logical_start as u64 * 8 + (f.logical_start_bit & 7) as u64;
            let f_end = (f.logical_start as u64 + f.length as u64 - 1) * 8 + (f.logical_stop_bit & 7) as u64 + 1;
            (f_start, f_start.max(dg_start), f_end.min(dg_end))
        };
        // Most ESCs map only a few bytes of a long LRW.
        let (first, last, hits) = self
            .fmmu_cache
            .iter()
            .map(overlap)
            .filter(|(_, lo, hi)| lo < hi)
            .fold((u64::MAX, 0, 0), |(a, b, n), (_, lo, hi)| {
                (a.min((lo - dg_start) / 8), b.max((hi - dg_start).div_ceil(8)), n + 1)
            });
        let mut plan = Plan {
            key: Plan::key(cmd, logical, len, self.sii_loaded),
            first: first.min(last) as usize,
            last: last as usize,
            several: hits > 1,
            runs: Vec::new(),
        };
        let access = |pa: u16, write: bool| if resolve { self.access(pa, write) } else { Access::Byte };
        for f in &self.fmmu_cache {
            let (f_start, lo, hi) = overlap(f);
            if lo >= hi {
                continue;
            }
            let phys0 = f.physical_start as u64 * 8 + (f.physical_start_bit & 7) as u64;
            let reads = f.fmmu_type & Fmmu::READ != 0 && matches!(cmd, Command::LRD | Command::LRW);
            let writes = f.fmmu_type & Fmmu::WRITE != 0 && matches!(cmd, Command::LWR | Command::LRW);
            if !reads && !writes {
                continue;
            }
            // The overlap in runs that stay within one physical and one frame byte.
            let mut bit = lo;
            while bit < hi {
                let pbit = phys0 + (bit - f_start);
                let fbit = bit - dg_start;
                let run = (8 - pbit % 8).min(8 - fbit % 8).min(hi - bit);
                // Physical addresses wrap at 64 KiB as the byte-wise walk's u16 did.
                let pa = (pbit / 8) as u16;
                plan.runs.push(Run {
                    fi: (fbit / 8) as u16,
                    pa,
                    mask_f: (((1u16 << run) - 1) << (fbit % 8)) as u8,
                    mask_p: (((1u16 << run) - 1) << (pbit % 8)) as u8,
                    fbit: (fbit % 8) as u8,
                    pbit: (pbit % 8) as u8,
                    write: writes.then(|| access(pa, true)),
                    read: reads.then(|| access(pa, false)),
                });
                bit += run;
            }
        }
        plan
    }

    /// What a write (or read) of physical byte `a` does, as far as the configuration decides
    /// it: the same tests `write_byte` and `read_byte` make, in their order.
    fn access(&self, a: u16, write: bool) -> Access {
        // Registers (their side effects, pending writes) and everything a mailbox does are
        // decided at the moment; so is the DC and status block whatever covers it.
        if a < 0x1000 && (0x0100..0x0A00).contains(&a) {
            return Access::Byte;
        }
        if self.absent(a) {
            return Access::Fail;
        }
        match self.sm_at(a) {
            Some((_, s)) if s.pdi_control & 1 != 0 => Access::Fail,
            Some((_, s)) if s.is_mailbox() => Access::Byte,
            Some(_) if !write => Access::Mem,
            Some((n, s)) => {
                let last = a as u32 == s.start as u32 + s.length as u32 - 1;
                if s.ecat_writes() {
                    let area = sm_area(&s, self.mem.len());
                    Access::Staging {
                        sm: n,
                        off: a - s.start,
                        area_start: area.start as u16,
                        area_len: area.len() as u16,
                        last,
                    }
                } else if last {
                    Access::MemLast { sm: n }
                } else {
                    Access::Mem
                }
            }
            None if a < 0x1000 => Access::Byte,
            None => Access::Mem,
        }
    }

    /// Carries out a plan on the datagram's data.
    fn walk(&mut self, plan: &Plan, cmd: Command, data: &mut [u8]) -> u16 {
        if plan.first >= plan.last {
            return 0;
        }
        // One FMMU's runs cover disjoint frame bits, each written before it is read: only a
        // second FMMU can read into bits another writes, so only then is a copy needed.
        let mut original = Vec::new();
        if plan.several {
            original = std::mem::take(&mut self.scratch);
            original.clear();
            original.extend_from_slice(&data[plan.first..plan.last]);
        }
        let (mut read_ok, mut write_ok) = (false, false);
        for r in &plan.runs {
            let fi = r.fi as usize;
            if let Some(w) = r.write {
                let arrived = if plan.several { original[fi - plan.first] } else { data[fi] };
                let bits = shift(arrived & r.mask_f, r.fbit, r.pbit);
                write_ok |= self.write_run(w, r, bits, cmd);
            }
            if let Some(a) = r.read {
                let v = match a {
                    Access::Fail => None,
                    Access::Byte => self.read_byte(r.pa),
                    _ => Some(self.mem[r.pa as usize]),
                };
                if let Some(v) = v {
                    data[fi] = (data[fi] & !r.mask_f) | shift(v & r.mask_p, r.pbit, r.fbit);
                    read_ok = true;
                }
            }
        }
        if plan.several {
            self.scratch = original;
        }
        match cmd {
            Command::LRD => read_ok as u16,
            Command::LWR => write_ok as u16,
            _ => read_ok as u16 + 2 * write_ok as u16,
        }
    }

    /// One run's write of `bits` (already at the physical bit position); whether it succeeded.
    #[inline]
    fn write_run(&mut self, w: Access, r: &Run, bits: u8, cmd: Command) -> bool {
        let a = r.pa as usize;
        match w {
            Access::Fail => false,
            Access::Byte => {
                let cur = self.current_byte(r.pa);
                self.write_byte(r.pa, (cur & !r.mask_p) | bits, cmd)
            }
            Access::Mem => {
                self.mem[a] = (self.mem[a] & !r.mask_p) | bits;
                true
            }
            Access::MemLast { sm } => {
                self.mem[a] = (self.mem[a] & !r.mask_p) | bits;
                self.sms[sm as usize].last_byte_written = true;
                self.effects.sm_done |= 1 << sm;
                true
            }
            Access::Staging { sm, off, area_start, area_len, last } => {
                let st = &mut self.sms[sm as usize];
                if !st.staged || st.staging.len() != area_len as usize {
                    st.staging.clear();
                    let area = area_start as usize..area_start as usize + area_len as usize;
                    st.staging.extend_from_slice(&self.mem[area]);
                    st.staged = true;
                }
                let b = &mut st.staging[off as usize];
                *b = (*b & !r.mask_p) | bits;
                if last {
                    st.last_byte_written = true;
                    self.effects.sm_done |= 1 << sm;
                }
                true
            }
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::app::NoApplication;
    use crate::config::EscConfig;
    use ferrocat_wire::register::{addr, SyncManager};
    use proptest::prelude::*;

    /// An ESC with process memory accessible and the given SyncManagers and FMMUs configured.
    fn esc(sms: &[SyncManager], fmmus: &[Fmmu]) -> Esc {
        let mut e = Esc::new(EscConfig::et1100(), Vec::new(), Box::new(NoApplication), 0, 0);
        e.sii_loaded = true;
        for (n, s) in sms.iter().enumerate() {
            let a = addr::sm(n as u8) as usize;
            e.mem[a..a + 8].copy_from_slice(&s.to_bytes());
        }
        for (n, f) in fmmus.iter().enumerate() {
            let a = addr::fmmu(n as u8) as usize;
            e.mem[a..a + 16].copy_from_slice(&f.to_bytes());
        }
        e.reload_sm_fmmu();
        // Memory with something in it, so that reads show where they read from.
        for (i, b) in e.mem[0x0F00..0x1200].iter_mut().enumerate() {
            *b = (i * 7 + 3) as u8;
        }
        e
    }

    fn sm() -> impl Strategy<Value = SyncManager> {
        (
            prop::sample::select(vec![0x0F00u16, 0x0F02, 0x1000, 0x1002, 0x1FFE]),
            1u16..5,
            prop::sample::select(vec![0x00u8, 0x04, 0x44, 0x02, 0x06, 0x20]),
            prop::sample::select(vec![0u8, 0, 0, 1]),
            any::<bool>(),
        )
            .prop_map(|(start, length, control, pdi_control, on)| SyncManager {
                start,
                length,
                control,
                status: 0,
                activate: on as u8,
                pdi_control,
            })
    }

    fn fmmu() -> impl Strategy<Value = Fmmu> {
        (
            0u32..6,
            1u16..5,
            0u8..8,
            0u8..8,
            prop::sample::select(vec![0x0F00u16, 0x0F01, 0x1000, 0x1001, 0x1FFE, 0x0130, 0x0910, 0x0800, 0x3000]),
            0u8..8,
            1u8..4,
        )
            .prop_map(
                |(logical_start, length, start_bit, stop_bit, physical_start, physical_start_bit, fmmu_type)| Fmmu {
                    logical_start,
                    length,
                    logical_start_bit: start_bit,
                    logical_stop_bit: stop_bit,
                    physical_start,
                    physical_start_bit,
                    fmmu_type,
                    active: true,
                },
            )
    }

    proptest! {
        /// Whatever the FMMUs and SyncManagers (bit-wise, overlapping, in registers, beyond
        /// memory, mailboxes, deactivated), a resolved plan does what the byte-wise walk does:
        /// the same frame bytes, WKC, memory, staging and buffer completions, datagram after
        /// datagram.
        #[test]
        fn a_plan_walks_as_the_bytes_do(
            sms in proptest::collection::vec(sm(), 0..4),
            fmmus in proptest::collection::vec(fmmu(), 1..4),
            datagrams in proptest::collection::vec(
                (prop::sample::select(vec![Command::LRD, Command::LWR, Command::LRW]), 0u32..5, 1usize..10, any::<u8>()),
                1..6,
            ),
        ) {
            let (mut fast, mut bytes) = (esc(&sms, &fmmus), esc(&sms, &fmmus));
            for (cmd, logical, len, seed) in datagrams {
                let data: Vec<u8> = (0..len).map(|i| seed.wrapping_mul(31).wrapping_add(i as u8 * 17)).collect();
                let (mut a, mut b) = (data.clone(), data);
                let plan_a = fast.plan(cmd, logical, len, true);
                let plan_b = bytes.plan(cmd, logical, len, false);
                let wkc_a = fast.walk(&plan_a, cmd, &mut a);
                let wkc_b = bytes.walk(&plan_b, cmd, &mut b);
                prop_assert_eq!(wkc_a, wkc_b);
                prop_assert_eq!(&a, &b);
                prop_assert_eq!(&fast.mem, &bytes.mem);
                prop_assert_eq!(&fast.pending, &bytes.pending);
                prop_assert_eq!(fast.effects.sm_done, bytes.effects.sm_done);
                for (x, y) in fast.sms.iter().zip(&bytes.sms) {
                    prop_assert_eq!((x.staged, x.last_byte_written, x.last_byte_read), (y.staged, y.last_byte_written, y.last_byte_read));
                    if x.staged {
                        prop_assert_eq!(&x.staging, &y.staging);
                    }
                }
            }
        }
    }

    /// The plans follow the configuration: a new FMMU mapping drops them, so the next LRW
    /// reads where the FMMU now points.
    #[test]
    fn a_reconfigured_fmmu_is_walked_anew() {
        let read = |physical_start| Fmmu {
            logical_start: 0,
            length: 1,
            logical_start_bit: 0,
            logical_stop_bit: 7,
            physical_start,
            physical_start_bit: 0,
            fmmu_type: Fmmu::READ,
            active: true,
        };
        let mut e = esc(&[], &[read(0x1000)]);
        let mut data = [0u8];
        assert_eq!(e.logical(Command::LRD, 0, &mut data), 1);
        assert_eq!(data[0], e.mem[0x1000]);
        e.mem[0x0600..0x0610].copy_from_slice(&read(0x1001).to_bytes());
        e.reload_sm_fmmu();
        assert_eq!(e.logical(Command::LRD, 0, &mut data), 1);
        assert_eq!(data[0], e.mem[0x1001]);
        assert_ne!(e.mem[0x1000], e.mem[0x1001]);
    }
}
