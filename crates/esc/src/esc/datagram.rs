//! One frame's datagrams: addressing, reads and writes of the register space (shadowed until
//! the frame ends), logical addressing through the FMMUs, and the working counter.
use ferrocat_wire::datagram::HEADER_LEN;
use ferrocat_wire::register::{AlState, SyncManager};
use ferrocat_wire::Command;

use super::{sm_area, Esc, FrameEffects, FrameTiming};
use crate::app::Pdi;
use crate::config::DcWidth;
use crate::dc::DcUnit;
use crate::regs::ecat_writable;

impl Esc {
    /// Processes the datagram chain of one frame passing the processing unit; `timing` is
    /// relative to `origin_ns` (the segment keeps one route and shifts it per frame).
    pub fn process_frame(&mut self, chain: &mut [u8], timing: &FrameTiming, origin_ns: u64) {
        let epu_ns = timing.epu_ns + origin_ns;
        self.advance_to(epu_ns);
        self.frames += 1;
        if self.expected.mailbox.is_some() {
            self.deliver_mailbox();
        }
        if matches!(self.al.state, AlState::SafeOp | AlState::Op) {
            let mut pdi = Pdi { mem: &mut self.mem, now_ns: self.now_ns };
            self.app.sample_inputs(&mut pdi);
            self.hand_over_single_buffer_inputs();
        }
        if self.eeprom.busy(self.now_ns) != self.sii_busy_shown {
            self.refresh_registers();
        }
        // ECAT reads of 0x0910 see the time the frame passed, minus the delay: latched now,
        // put into the register when a datagram reads it (most frames do not).
        self.system_time_latch = self.dc.as_ref().map(|_| epu_ns);
        self.effects = FrameEffects::default();
        self.receptions_before_epu(timing, origin_ns);
        let mut off = 0;
        while off + HEADER_LEN + 2 <= chain.len() {
            let len = (u16::from_le_bytes([chain[off + 6], chain[off + 7]]) & 0x07FF) as usize;
            let end = off + HEADER_LEN + len + 2;
            if end > chain.len() {
                break;
            }
            let more = chain[off + 7] & 0x80 != 0;
            self.datagram(&mut chain[off..end]);
            off = end;
            if !more {
                break;
            }
        }
        self.end_of_frame(timing, origin_ns);
    }

    /// Whether a device-addressed datagram is for this ESC: position-addressed ones where the
    /// incremented ADP reached 0, configured-address ones by station address or alias,
    /// broadcasts always.
    fn addressed(&self, cmd: Command, adp: u16) -> bool {
        match cmd {
            Command::APRD | Command::APWR | Command::APRW | Command::ARMW => adp == 0,
            Command::FPRD | Command::FPWR | Command::FPRW | Command::FRMW => self.addressed_fp(adp),
            _ => true,
        }
    }

    pub(super) fn addressed_fp(&self, adp: u16) -> bool {
        let alias_on = self.mem[0x0103] & 0x01 != 0;
        adp == self.station_address() || (alias_on && adp == u16::from_le_bytes([self.mem[0x12], self.mem[0x13]]))
    }

    pub(super) fn datagram(&mut self, d: &mut [u8]) {
        // The IRQ field passes before the data: it carries the events as they were before
        // this datagram's own reads and writes.
        if self.irq != 0 {
            let irq = u16::from_le_bytes([d[8], d[9]]) | self.irq;
            d[8..10].copy_from_slice(&irq.to_le_bytes());
        }
        let cmd = Command(d[0]);
        let adp = u16::from_le_bytes([d[2], d[3]]);
        let ado = u16::from_le_bytes([d[4], d[5]]);
        let logical = u32::from_le_bytes([d[2], d[3], d[4], d[5]]);
        let n = d.len() - 2;
        let (head, rest) = d.split_at_mut(HEADER_LEN);
        let (data, wkc) = rest.split_at_mut(n - HEADER_LEN);
        let mut inc = 0u16;
        match cmd {
            Command::APRD | Command::FPRD | Command::BRD => {
                inc = (self.addressed(cmd, adp) && self.read(ado, data, cmd == Command::BRD)) as u16;
            }
            Command::APWR | Command::FPWR | Command::BWR => {
                inc = (self.addressed(cmd, adp) && self.write(ado, data, cmd)) as u16;
            }
            Command::APRW | Command::FPRW | Command::BRW if self.addressed(cmd, adp) => {
                // What is written is the data as it came; a register's worth is copied aside
                // without allocating (an FPRW of an offset is cyclic traffic).
                let mut small = [0u8; 16];
                let big;
                let out: &[u8] = match small.get_mut(..data.len()) {
                    Some(s) => {
                        s.copy_from_slice(data);
                        s
                    }
                    None => {
                        big = data.to_vec();
                        &big
                    }
                };
                if self.read(ado, data, cmd == Command::BRW) {
                    inc += 1;
                }
                let rw_offset = u16::from_le_bytes([self.mem[0x0108], self.mem[0x0109]]);
                if self.write(ado.wrapping_add(rw_offset), out, cmd) {
                    inc += 2;
                }
            }
            Command::ARMW | Command::FRMW => {
                // The addressed ESC reads, every other one writes.
                let ok =
                    if self.addressed(cmd, adp) { self.read(ado, data, false) } else { self.write(ado, data, cmd) };
                inc = ok as u16;
            }
            Command::LRD | Command::LWR | Command::LRW => inc = self.logical(cmd, logical, data),
            _ => {}
        }
        if cmd.increments_adp() {
            head[2..4].copy_from_slice(&adp.wrapping_add(1).to_le_bytes());
        }
        let w = u16::from_le_bytes([wkc[0], wkc[1]]).wrapping_add(inc);
        wkc.copy_from_slice(&w.to_le_bytes());
    }

    pub(super) fn sm_at(&self, a: u16) -> Option<(u8, SyncManager)> {
        // Outside every enabled SyncManager's span (all registers, usually): no search.
        if (a as u32) < self.sm_span.0 || a as u32 >= self.sm_span.1 {
            return None;
        }
        (0..self.config.sm_count)
            .map(|n| (n, self.sm(n)))
            .find(|(_, s)| s.enabled() && s.length > 0 && a >= s.start && (a as u32) < s.start as u32 + s.length as u32)
    }

    /// Whether `a` is a register this ESC does not implement: FMMUs and SyncManagers beyond its
    /// count, the DC block without a DC unit. Accesses to them do not count in the WKC.
    pub(super) fn absent(&self, a: u16) -> bool {
        match a {
            0x0600..=0x06FF => (a - 0x0600) / 16 >= self.config.fmmu_count as u16,
            0x0800..=0x087F => (a - 0x0800) / 8 >= self.config.sm_count as u16,
            0x0900..=0x090F => self.dc.is_none(),
            0x0910..=0x09FF => self.dc.is_none() || !self.system_time_unit,
            // Process memory is not accessible until the configuration area has loaded.
            _ => a as usize >= self.mem.len() || a >= 0x1000 && !self.sii_loaded,
        }
    }

    /// Puts the time the frame passed (minus the delay) into 0x0910, once per frame.
    pub(super) fn latch_system_time(&mut self) {
        if let (Some(t), Some(dc)) = (self.system_time_latch.take(), &self.dc) {
            let v = dc.ecat_system_time(t);
            let n = if dc.width == DcWidth::Bits64 { 8 } else { 4 };
            self.mem[0x0910..0x0910 + n].copy_from_slice(&v.to_le_bytes()[..n]);
        }
    }

    /// One byte read by the master; `None` if it cannot be read.
    pub(super) fn read_byte(&mut self, a: u16) -> Option<u8> {
        if self.absent(a) {
            return None;
        }
        // Registers whose read has a side effect; one match, as every byte of every read
        // (process data included) passes here.
        match a {
            0x0910..=0x0917 => self.latch_system_time(),
            // SYNC1 pulses are not events of their own: its registers are brought to the
            // frame's instant when read.
            0x0984 | 0x0998..=0x099F => self.refresh_sync1_registers(),
            0x098E..=0x098F | 0x0220..=0x0223 => self.refresh_pdi_events(),
            0x09B0..=0x09CF if (a - 0x09B0) % 8 == 0 => {
                // Reading a latch time clears its single-event flag (ECAT-controlled units).
                let unit = ((a - 0x09B0) / 16) as usize;
                let edge = ((a - 0x09B0) / 8 % 2) as u8;
                if self.mem[0x0980] & (0x10 << unit) == 0 {
                    self.mem[0x09AE + unit] &= !(1 << edge);
                    self.update_irq();
                }
            }
            // An ECAT read of DL or AL status clears its event (ESC datasheet, 0x0210).
            0x0110..=0x0111 if self.dl_changed => {
                self.dl_changed = false;
                self.update_irq();
            }
            0x0130..=0x0131 if self.al_changed => {
                self.al_changed = false;
                self.update_irq();
            }
            _ => {}
        }
        if let Some((n, s)) = self.sm_at(a) {
            if s.pdi_control & 1 != 0 {
                return None;
            }
            if s.is_mailbox() && a == s.start && !s.ecat_writes() && self.sms[n as usize].full {
                // The master opens the buffer the firmware wrote.
                self.sms[n as usize].int_write = false;
                self.put_sm_status(n);
            }
            let st = &mut self.sms[n as usize];
            if s.is_mailbox() {
                if s.ecat_writes() || !st.full {
                    return None;
                }
                if a as u32 == s.start as u32 + s.length as u32 - 1 {
                    st.last_byte_read = true;
                    self.effects.sm_done |= 1 << n;
                }
            }
        }
        Some(self.mem[a as usize])
    }

    /// Inputs in a SyncManager of mailbox mode (one buffer, from SM2 on: the AX2000's ESI has
    /// its inputs so): the firmware's last inputs are handed over whenever the master has read
    /// the buffer, so that each frame finds it full. No capture of such a device is at hand;
    /// the datasheets' mailbox rules (a read of an empty buffer is not counted) apply.
    fn hand_over_single_buffer_inputs(&mut self) {
        let mut inputs = self.single_buffer_inputs;
        while inputs != 0 {
            let n = inputs.trailing_zeros() as u8;
            inputs &= inputs - 1;
            if !self.sms[n as usize].full {
                self.sms[n as usize].full = true;
                self.sms[n as usize].int_write = true;
                self.put_sm_status(n);
            }
        }
    }

    pub(super) fn read(&mut self, ado: u16, data: &mut [u8], or: bool) -> bool {
        // The system time as a whole (the reference's FRMW every cycle): what `read_byte`
        // does byte by byte, at once.
        let end = ado as u32 + data.len() as u32;
        if (0x0910..0x0918).contains(&ado)
            && end <= 0x0918
            && !data.is_empty()
            && (end <= self.sm_span.0 || ado as u32 >= self.sm_span.1)
        {
            if self.dc.is_none() || !self.system_time_unit {
                return false;
            }
            self.latch_system_time();
            for (b, v) in data.iter_mut().zip(&self.mem[ado as usize..end as usize]) {
                *b = if or { *b | v } else { *v };
            }
            return true;
        }
        let mut ok = false;
        for (i, b) in data.iter_mut().enumerate() {
            let Some(a) = ado.checked_add(i as u16) else { break };
            if let Some(v) = self.read_byte(a) {
                *b = if or { *b | v } else { v };
                ok = true;
            }
        }
        ok
    }

    /// One byte written by the master; false if the write does not succeed.
    pub(super) fn write_byte(&mut self, a: u16, v: u8, cmd: Command) -> bool {
        if self.absent(a) {
            return false;
        }
        if let Some((n, s)) = self.sm_at(a) {
            if s.pdi_control & 1 != 0 {
                return false;
            }
            if s.is_mailbox() && a == s.start && s.ecat_writes() && !self.sms[n as usize].full {
                // The master opens the buffer the firmware read.
                self.sms[n as usize].int_read = false;
                self.put_sm_status(n);
            }
            let st = &mut self.sms[n as usize];
            let last = a as u32 == s.start as u32 + s.length as u32 - 1;
            if s.is_mailbox() {
                if !s.ecat_writes() || st.full {
                    return false;
                }
                self.mem[a as usize] = v;
            } else if s.ecat_writes() {
                let area = sm_area(&s, self.mem.len());
                if !st.staged || st.staging.len() != area.len() {
                    st.staging.clear();
                    st.staging.extend_from_slice(&self.mem[area]);
                    st.staged = true;
                }
                st.staging[(a - s.start) as usize] = v;
            } else {
                self.mem[a as usize] = v;
            }
            if last {
                st.last_byte_written = true;
                self.effects.sm_done |= 1 << n;
            }
            return true;
        }
        if a < 0x1000 {
            if (0x0120..=0x0121).contains(&a) && self.pending_al.is_some() && !self.device_emulation() {
                // AL control is locked until the firmware has read the last write.
                return false;
            }
            if ecat_writable(a) {
                match a {
                    0x0900..=0x0903 => {
                        self.effects.latch_epu = true;
                        if matches!(cmd, Command::BWR | Command::FPWR | Command::BRW | Command::FPRW) {
                            self.effects.latch_ports = true;
                        }
                    }
                    // A write of the system time feeds the time control loop and leaves the
                    // register as it is (esc-spec 0x0910): nothing to apply at the end.
                    0x0910..=0x0917 => {
                        self.system_time_byte_written(a, v);
                        return true;
                    }
                    _ => {}
                }
                self.pending.push((a, v));
                return true;
            }
            // A read-only register ignores the write and does not count it: real ESCs answer
            // a BWR of 0x092C alone with WKC 0 (replay-dc and seven more captures).
            return false;
        }
        self.mem[a as usize] = v;
        true
    }

    pub(super) fn write(&mut self, ado: u16, data: &[u8], cmd: Command) -> bool {
        // The system time as a whole (FRMW/ARMW/BWR of 0x0910, every follower every cycle):
        // what `write_byte` does byte by byte, at once — a TCL sample, nothing stored.
        let end = ado as u32 + data.len() as u32;
        if (0x0910..0x0918).contains(&ado)
            && end <= 0x0918
            && self.dc.is_some()
            && self.system_time_unit
            && (end <= self.sm_span.0 || ado as u32 >= self.sm_span.1)
        {
            if data.is_empty() {
                return false;
            }
            let t = self.effects.tcl.get_or_insert([None; 4]);
            for (slot, &v) in t.iter_mut().skip((ado - 0x0910) as usize).zip(data) {
                *slot = Some(v);
            }
            return true;
        }
        let mut ok = false;
        for (i, &v) in data.iter().enumerate() {
            let Some(a) = ado.checked_add(i as u16) else { break };
            ok |= self.write_byte(a, v, cmd);
        }
        ok
    }

    /// The value a partial (bit-wise) write builds on: the staging buffer of a buffered output
    /// SM, a pending register write, or memory.
    pub(super) fn current_byte(&self, a: u16) -> u8 {
        if let Some((n, s)) = self.sm_at(a) {
            let st = &self.sms[n as usize];
            if !s.is_mailbox() && s.ecat_writes() && st.staged && st.staging.len() == sm_area(&s, self.mem.len()).len()
            {
                return st.staging[(a - s.start) as usize];
            }
        }
        if let Some(&(_, v)) = self.pending.iter().rev().find(|(p, _)| *p == a) {
            return v;
        }
        self.mem.get(a as usize).copied().unwrap_or(0)
    }

    /// A byte of 0x0910–0x0917 written: the low four go to the frame's TCL sample, the
    /// register itself stays as it is (esc-spec 0x0910).
    pub(super) fn system_time_byte_written(&mut self, a: u16, v: u8) {
        let t = self.effects.tcl.get_or_insert([None; 4]);
        if let Some(slot) = t.get_mut(a.wrapping_sub(0x0910) as usize) {
            *slot = Some(v);
        }
    }

    /// A frame's write of 0x0910 (the bytes it wrote): one TCL sample at `t`.
    pub(super) fn feed_tcl(dc: &mut DcUnit, bytes: Option<[Option<u8>; 4]>, t: u64) {
        // Only a write that includes byte 0x0910 produces a sample (esc-spec §3.2).
        let Some(bytes @ [Some(_), ..]) = bytes else { return };
        // Bytes the write left out are what the register holds (a read's value).
        let v = match bytes {
            [Some(a), Some(b), Some(c), Some(d)] => [a, b, c, d],
            _ => {
                let cur = (dc.ecat_system_time(t) as u32).to_le_bytes();
                std::array::from_fn(|i| bytes[i].unwrap_or(cur[i]))
            }
        };
        dc.tcl_sample(t, u32::from_le_bytes(v));
    }
}
