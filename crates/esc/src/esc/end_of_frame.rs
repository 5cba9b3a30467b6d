//! What a frame's writes do once it has passed: registers applied, SyncManager buffers
//! completed, SII commands, the DC unit's registers, AL control.
use ferrocat_wire::register::{addr, AlState, SiiControl, SyncManager};

use super::{sm_area, Esc, FrameTiming};
use crate::app::Pdi;
use crate::config::DcWidth;
use crate::dc::DcUnit;

/// Which groups of registers a frame wrote.
#[derive(Debug, Default, Clone, Copy)]
struct Written {
    reset: bool,
    dl_ctl: bool,
    al_ctl: bool,
    sii_cmd: bool,
    fmmu_cfg: bool,
    sm_cfg: bool,
    dc_offset: bool,
    dc_delay: bool,
    scs: bool,
    depths: bool,
    event_mask: bool,
    sync_cfg: bool,
    activation: bool,
    start_time: bool,
}

impl Written {
    #[inline]
    fn of(pending: &[(u16, u8)]) -> Written {
        let mut w = Written::default();
        for &(a, _) in pending {
            match a {
                0x0040 => w.reset = true,
                0x0100..=0x0103 => w.dl_ctl = true,
                0x0120..=0x0121 => w.al_ctl = true,
                0x0502..=0x0503 => w.sii_cmd = true,
                0x0600..=0x06FF => w.fmmu_cfg = true,
                0x0800..=0x087F => w.sm_cfg = true,
                0x0920..=0x0927 => w.dc_offset = true,
                0x0928..=0x092B => w.dc_delay = true,
                0x0930..=0x0931 => w.scs = true,
                0x0934..=0x0935 => w.depths = true,
                0x0200..=0x0201 => w.event_mask = true,
                0x0981 => {
                    w.sync_cfg = true;
                    w.activation = true;
                }
                0x0990..=0x0997 => {
                    w.sync_cfg = true;
                    w.start_time = true;
                }
                0x0980..=0x09A7 => w.sync_cfg = true,
                _ => {}
            }
        }
        w
    }

    /// Whether a write reconfigured the DC unit beyond a TCL sample.
    fn dc_config(&self) -> bool {
        self.dc_offset || self.dc_delay || self.scs || self.depths || self.sync_cfg
    }
}

impl Esc {
    pub(super) fn end_of_frame(&mut self, timing: &FrameTiming, origin_ns: u64) {
        let t = timing.epu_ns + origin_ns;
        let mut pending = std::mem::take(&mut self.pending);
        if pending.is_empty() && self.effects.sm_done == 0 {
            self.pending = pending;
            // Nothing but (perhaps) a system-time write: a TCL sample, which changes only the
            // difference (0x092C) and the speed counter difference (0x0932).
            if let (Some(dc), Some(bytes)) = (self.dc.as_mut(), self.effects.tcl.take()) {
                Self::feed_tcl(dc, Some(bytes), t);
                self.refresh_tcl_registers();
            }
            return;
        }
        let w = Written::of(&pending);
        if w.dl_ctl {
            // Loop control changes which ports the frame walks, and shows in the DL status;
            // written again, it opens auto-close ports waiting closed.
            self.port_generation = self.port_generation.wrapping_add(1);
            self.closed_wait = [false; 4];
        }
        self.apply_writes(&pending);
        if w.event_mask {
            self.update_irq();
        }
        if w.reset && self.reset_sequence_complete() {
            self.power_on(t);
            return;
        }
        if w.sm_cfg || w.fmmu_cfg {
            self.reload_sm_fmmu();
        }
        if w.sm_cfg {
            self.sm_reconfigured(&pending);
            self.check_repeat_request();
        }
        let (deliver, mailbox_moved) = self.complete_sm_buffers(t);
        if deliver || w.sm_cfg {
            self.deliver_mailbox();
        }
        if w.sii_cmd {
            self.sii_command(t);
        }
        let tcl_fed = self.dc_end_of_frame(timing, origin_ns, &w);
        // Without a loaded configuration area neither device emulation nor a PDI acts on AL
        // control: the write stays in the register.
        if w.al_ctl && self.sii_loaded {
            let control = u16::from_le_bytes([self.mem[0x0120], self.mem[0x0121]]);
            if self.device_emulation() || self.al_response_ns == 0 {
                self.al_control(control);
            } else {
                self.pending_al = Some((control, t + self.al_response_ns));
            }
        }
        let dc_only = !(w.al_ctl
            || w.sii_cmd
            || w.sm_cfg
            || w.reset
            || w.dl_ctl
            || mailbox_moved
            || self.sms.iter().any(|s| s.full));
        if dc_only {
            if w.dc_config() {
                self.refresh_dc_registers();
            } else if tcl_fed {
                self.refresh_tcl_registers();
            }
        } else {
            self.refresh_registers();
        }
        pending.clear();
        self.pending = pending;
    }

    /// The frame's writes into memory, with the registers a write clears.
    #[inline]
    fn apply_writes(&mut self, pending: &[(u16, u8)]) {
        for &(a, v) in pending {
            self.mem[a as usize] = v;
            if (0x0300..=0x0313).contains(&a) {
                self.mem[a as usize] = 0; // a write clears an error counter
            }
            if (0x0442..=0x0443).contains(&a) {
                self.mem[0x0442..=0x0443].fill(0); // either watchdog counter's write clears both
            }
        }
    }

    /// ESC reset: 'R' 'E' 'S' written to 0x0040 in three consecutive frames.
    fn reset_sequence_complete(&mut self) -> bool {
        let v = self.mem[0x0040];
        self.reset_seq = match (self.reset_seq, v) {
            (_, b'R') => 1,
            (1, b'E') => 2,
            (2, b'S') => 3,
            _ => 0,
        };
        self.reset_seq == 3
    }

    /// A SyncManager written to starts over: disabled, it forgets its buffer and interrupts.
    fn sm_reconfigured(&mut self, pending: &[(u16, u8)]) {
        for n in 0..self.config.sm_count {
            let a = addr::sm(n);
            if pending.iter().any(|(p, _)| (a..a + 8).contains(p)) {
                let s = self.sm(n);
                let st = &mut self.sms[n as usize];
                if !s.enabled() {
                    st.full = false;
                    st.int_write = false;
                    st.int_read = false;
                }
                st.staged = false;
            }
        }
    }

    /// SyncManager buffers this frame completed: mailboxes filled or emptied, process-data
    /// buffers handed to the application. Returns whether a mailbox was read (a reply may
    /// follow) and whether any mailbox changed.
    #[inline]
    fn complete_sm_buffers(&mut self, t: u64) -> (bool, bool) {
        let (mut deliver, mut mailbox_moved, mut handed) = (false, false, false);
        // Only a SyncManager whose last byte the frame wrote or read has anything to complete.
        let mut done = std::mem::take(&mut self.effects.sm_done);
        while done != 0 {
            let n = done.trailing_zeros() as u8;
            done &= done - 1;
            let s = self.sm(n);
            let st = &mut self.sms[n as usize];
            let (written, read) = (std::mem::take(&mut st.last_byte_written), std::mem::take(&mut st.last_byte_read));
            if !s.enabled() {
                continue;
            }
            if s.is_mailbox() {
                if s.ecat_writes() && written {
                    st.full = true;
                    st.int_write = true;
                    mailbox_moved = true;
                    self.mailbox_request(n);
                } else if !s.ecat_writes() && read {
                    st.full = false;
                    st.int_read = true;
                    mailbox_moved = true;
                    deliver = true;
                }
            } else if s.ecat_writes() && written {
                let area = sm_area(&s, self.mem.len());
                if st.staged && st.staging.len() == area.len() {
                    self.mem[area].copy_from_slice(&st.staging);
                }
                st.staged = false;
                if s.control & SyncManager::WATCHDOG != 0 {
                    self.wd_last_trigger_ns = t;
                    self.mem[0x0440] = 1;
                }
                if matches!(self.al.state, AlState::Op) {
                    let mut pdi = Pdi { mem: &mut self.mem, now_ns: t };
                    self.app.outputs_written(&mut pdi, n);
                    handed = true;
                }
            }
        }
        // Outputs handed over may show the SYNC0 watchdog expired.
        if let Some(code) = if handed { self.app.take_fault() } else { None } {
            self.leave_op(code);
        }
        (deliver, mailbox_moved)
    }

    /// A command written to the SII interface (0x0502): the EEPROM starts it, and the control
    /// register keeps only its mode bits.
    fn sii_command(&mut self, t: u64) {
        let ctl = u16::from_le_bytes([self.mem[0x0502], self.mem[0x0503]]);
        let word = u32::from_le_bytes([self.mem[0x0504], self.mem[0x0505], self.mem[0x0506], self.mem[0x0507]]);
        let data = u16::from_le_bytes([self.mem[0x0508], self.mem[0x0509]]);
        if let Some(out) = self.eeprom.command(t, ctl, word, data, self.config.sii_read_8) {
            self.mem[0x0508..0x0510].copy_from_slice(&out);
        }
        let keep = (ctl & (SiiControl::WRITE_ENABLE | 0x0700)) | self.sii_mode_bits();
        self.mem[0x0502..0x0504].copy_from_slice(&keep.to_le_bytes());
    }

    /// The DC unit's part of the frame: receive times latched, the TCL sample, and the DC
    /// registers written applied. Returns whether the TCL took a sample.
    #[inline]
    fn dc_end_of_frame(&mut self, timing: &FrameTiming, origin_ns: u64, w: &Written) -> bool {
        let t = timing.epu_ns + origin_ns;
        self.latch_receive_times(timing, origin_ns, self.effects.latch_ports, self.effects.latch_epu);
        let Some(dc) = self.dc.as_mut() else {
            return false;
        };
        if self.effects.latch_epu {
            let local = dc.local_at(t);
            self.mem[0x0918..0x0920].copy_from_slice(&local.to_le_bytes());
        }
        // The time written is compared with the copy latched at SOF (esc-spec 0x0910): with
        // the offset and delay in force before this frame's writes apply.
        let tcl_fed = self.effects.tcl.is_some();
        if tcl_fed {
            Self::feed_tcl(dc, self.effects.tcl.take(), t);
        }
        apply_dc_registers(dc, &self.mem, w, t);
        if w.sync_cfg {
            let auto = dc.sync.activation & ferrocat_wire::register::dc_activation::AUTO_ACTIVATE != 0;
            if w.activation || (w.start_time && auto) {
                dc.sync_activation_written(t);
                self.sync0_edge_ns = None;
            }
        }
        tcl_fed
    }
}

/// The DC registers a frame wrote, into the DC unit.
#[inline]
fn apply_dc_registers(dc: &mut DcUnit, mem: &[u8], w: &Written, t: u64) {
    let wide = dc.width == DcWidth::Bits64;
    let rd64 = |a: usize| -> u64 {
        let v = u64::from_le_bytes(mem[a..a + 8].try_into().expect("8 bytes"));
        if wide {
            v
        } else {
            v & 0xFFFF_FFFF
        }
    };
    let rd32 = |a: usize| u32::from_le_bytes(mem[a..a + 4].try_into().expect("4 bytes"));
    if w.dc_offset {
        dc.fold_to(t);
        dc.offset = rd64(0x0920);
    }
    if w.dc_delay {
        dc.delay = rd32(0x0928);
    }
    if w.depths {
        dc.depth_diff = mem[0x0934] & 0x0F;
        dc.depth_speed = mem[0x0935] & 0x0F;
    }
    if w.scs {
        let v = u16::from_le_bytes([mem[0x0930], mem[0x0931]]) & 0x7FFF;
        dc.scs = v.clamp(0x0080, 0x3FFF);
        dc.reset_filters(t);
    }
    if w.sync_cfg {
        dc.sync.activation = mem[0x0981];
        dc.sync.pulse_len_10ns = u16::from_le_bytes([mem[0x0982], mem[0x0983]]);
        dc.sync.start_time = rd64(0x0990);
        dc.sync.cycle0_ns = rd32(0x09A0);
        dc.sync.cycle1_ns = rd32(0x09A4);
    }
}
