//! Registers whose value follows from the ESC's state, rewritten after it changes.
use ferrocat_wire::register::{addr, SiiControl, SyncManager};

use super::{Esc, SYNC0_SERVICE_NS};
use crate::config::DcWidth;

impl Esc {
    /// Rewrites registers whose value follows from state: DL status, AL status, SM status,
    /// SII busy, DC times.
    pub(super) fn refresh_registers(&mut self) {
        let mut dl = self.sii_loaded as u16; // EEPROM loaded, PDI operational
        if self.mem[0x0140] != 0 {
            // A PDI (0x0140: its type, 0 = none) that runs reloads the PDI watchdog: bit 1.
            // The real captures: 1 on the EL1004 (digital I/O), EL2828 and AKD, 0 on the
            // EK1100, which has no PDI.
            dl |= 1 << 1;
        }
        if self.mem[0x0141] & 0x02 != 0 {
            // Enhanced link detection (ESC configuration bit 1, from SII word 0): the real
            // LAN9252 (0x0141 = 0x0E) reads 0x17, the EK1100 (0x0D) and AKD (0x0C) bit 2 clear.
            dl |= 1 << 2;
        }
        for p in 0..4u8 {
            let link = self.links[p as usize] && self.config.has_port(p);
            if link {
                dl |= 1 << (4 + p);
                dl |= 1 << (9 + 2 * p);
            }
            if !(self.port_open(p) || p == 0 && link) {
                dl |= 1 << (8 + 2 * p);
            }
        }
        let al = self.al.status().0.to_le_bytes();
        self.dl_changed |= self.mem[0x0110..0x0112] != dl.to_le_bytes();
        self.al_changed |= self.mem[0x0130..0x0132] != al;
        self.mem[0x0110..0x0112].copy_from_slice(&dl.to_le_bytes());
        self.mem[0x0130..0x0132].copy_from_slice(&al);
        self.mem[0x0134..0x0136].copy_from_slice(&self.al.code.0.to_le_bytes());
        for n in 0..self.config.sm_count {
            self.write_sm_status(n);
        }
        self.sii_busy_shown = self.eeprom.busy(self.now_ns);
        let busy = if self.sii_busy_shown { SiiControl::BUSY } else { 0 };
        // The command bits read back with busy while the command runs, and clear with it (a
        // real EK1100 reads 0x8140 during a read, 0x0040 after: soem-sdinfo-ek1100-only
        // frames 70–80).
        let command = if self.sii_busy_shown { 0 } else { 0x0700 };
        let ctl = u16::from_le_bytes([self.mem[0x0502], self.mem[0x0503]]) & !(SiiControl::BUSY | 0x7800 | command);
        let errors = self.eeprom.errors | self.eeprom.load_status;
        self.mem[0x0502..0x0504].copy_from_slice(&(ctl | busy | errors).to_le_bytes());
        self.refresh_dc_registers();
        self.update_irq();
    }

    /// SyncManager `n`'s status bits 0, 1 and 3 from its state.
    pub(super) fn write_sm_status(&mut self, n: u8) {
        let a = addr::sm(n) as usize + 5;
        let s = &self.sms[n as usize];
        let flags = SyncManager::STATUS_INT_WRITE | SyncManager::STATUS_INT_READ | SyncManager::STATUS_MAILBOX_FULL;
        let mut status = self.mem[a] & !flags;
        if s.full {
            status |= SyncManager::STATUS_MAILBOX_FULL;
        }
        if s.int_write {
            status |= SyncManager::STATUS_INT_WRITE;
        }
        if s.int_read {
            status |= SyncManager::STATUS_INT_READ;
        }
        self.mem[a] = status;
    }

    /// SyncManager `n`'s state changed: its status register and the events that follow.
    pub(super) fn put_sm_status(&mut self, n: u8) {
        self.write_sm_status(n);
        self.update_irq();
    }

    /// ECAT event request (0x0210) from the state, and what this ESC puts into IRQ fields.
    pub(super) fn update_irq(&mut self) {
        use ferrocat_wire::register::ecat_event;
        let mut req = 0u16;
        // Latch events wait in 0x09AE/0x09AF bits 0–1 of units the ECAT side controls.
        let latched = (0..2).any(|u| self.mem[0x0980] & (0x10 << u) == 0 && self.mem[0x09AE + u] & 0x03 != 0);
        if self.dc.is_some() && latched {
            req |= ecat_event::LATCH;
        }
        if self.dl_changed {
            req |= ecat_event::DL_STATUS;
        }
        if self.al_changed {
            req |= ecat_event::AL_STATUS;
        }
        for n in 0..self.config.sm_count.min(8) {
            let s = self.sm(n);
            let st = &self.sms[n as usize];
            // The master's event: the firmware wrote a buffer for it to read, or read one it wrote.
            let pending = if s.ecat_writes() { st.int_read } else { st.int_write };
            if s.enabled() && s.control & SyncManager::ECAT_EVENT != 0 && pending {
                req |= ecat_event::sync_manager(n);
            }
        }
        self.mem[0x0210..0x0212].copy_from_slice(&req.to_le_bytes());
        self.irq = req & u16::from_le_bytes([self.mem[0x0200], self.mem[0x0201]]);
    }

    /// The DC registers that follow from the DC unit's state.
    pub(super) fn refresh_dc_registers(&mut self) {
        if let Some(dc) = &self.dc {
            let wide = dc.width == DcWidth::Bits64;
            let put = |m: &mut [u8], a: usize, v: u64| {
                let n = if wide { 8 } else { 4 };
                m[a..a + n].copy_from_slice(&v.to_le_bytes()[..n]);
            };
            put(&mut self.mem, 0x0920, dc.offset);
            self.mem[0x0928..0x092C].copy_from_slice(&dc.delay.to_le_bytes());
            self.mem[0x092C..0x0930].copy_from_slice(&dc.difference_register().to_le_bytes());
            self.mem[0x0930..0x0932].copy_from_slice(&dc.scs.to_le_bytes());
            self.mem[0x0932..0x0934].copy_from_slice(&dc.scd.to_le_bytes());
            self.mem[0x0934] = dc.depth_diff;
            self.mem[0x0935] = dc.depth_speed;
            self.mem[0x0984] = dc.activation_status_at(self.now_ns);
            put(&mut self.mem, 0x0990, dc.next_sync0_register());
            put(&mut self.mem, 0x0998, dc.next_sync1_register(self.now_ns));
        }
    }

    pub(super) fn refresh_sync1_registers(&mut self) {
        if let Some(dc) = &self.dc {
            self.mem[0x0984] = dc.activation_status_at(self.now_ns);
            let v = dc.next_sync1_register(self.now_ns).to_le_bytes();
            let n = if dc.width == DcWidth::Bits64 { 8 } else { 4 };
            self.mem[0x0998..0x0998 + n].copy_from_slice(&v[..n]);
        }
    }

    /// SYNC0/SYNC1 status (0x098E/0x098F) and the AL event request (0x0220) at this instant,
    /// as the master reads them. In acknowledge mode (pulse length 0) a SYNC signal stays
    /// active until the PDI reads its status register, which our firmware does
    /// `SYNC0_SERVICE_NS` after the pulse; the status reads 0 in pulse mode (the datasheet
    /// defines it for acknowledge mode only). Of 0x0220 we keep bit 0 (AL control written, not
    /// yet read by the firmware) and bits 2/3 (the SYNC signals, where 0x0151 bits 3/7 map them
    /// there); the firmware services every other event at once, so those read 0.
    pub(super) fn refresh_pdi_events(&mut self) {
        let ack_mode = self.mem[0x0982] == 0 && self.mem[0x0983] == 0;
        let (mut s0, mut s1) = (false, false);
        if let (Some(dc), true) = (&self.dc, ack_mode) {
            let now = self.now_ns;
            s0 = dc.sync.output_enabled() && self.sync0_edge_ns.is_some_and(|e| now >= e && now - e < SYNC0_SERVICE_NS);
            s1 = dc.sync1_within(now, SYNC0_SERVICE_NS);
        }
        self.mem[0x098E] = s0 as u8;
        self.mem[0x098F] = s1 as u8;
        let pdi_config = self.mem[0x0151];
        let mut events = 0u32;
        if self.pending_al.is_some() {
            events |= 1 << 0;
        }
        if s0 && pdi_config & 0x08 != 0 {
            events |= 1 << 2;
        }
        if s1 && pdi_config & 0x80 != 0 {
            events |= 1 << 3;
        }
        self.mem[0x0220..0x0224].copy_from_slice(&events.to_le_bytes());
    }

    /// The registers a TCL sample changes: the difference (0x092C) and SCD (0x0932).
    pub(super) fn refresh_tcl_registers(&mut self) {
        if let Some(dc) = &self.dc {
            self.mem[0x092C..0x0930].copy_from_slice(&dc.difference_register().to_le_bytes());
            self.mem[0x0932..0x0934].copy_from_slice(&dc.scd.to_le_bytes());
        }
    }
}
