//! The slave controller: memory, datagram processing, end-of-frame effects.
use ferrocat_wire::datagram::HEADER_LEN;
use ferrocat_wire::register::{addr, AlState, AlStatus, AlStatusCode, Fmmu, SiiControl, SyncManager};
use ferrocat_wire::sii::{SiiInfo, SmEntry};
use ferrocat_wire::Command;

use crate::al::AlMachine;
use crate::app::{Application, Pdi};
use crate::config::{DcWidth, EscConfig};
use crate::dc::DcUnit;
use crate::eeprom::Eeprom;
use crate::regs::ecat_writable;

/// When a frame met this ESC: the true time its first bit reached each port, and the time it
/// passed the processing unit.
#[derive(Debug, Clone, Copy, Default, PartialEq, Eq)]
pub struct FrameTiming {
    pub port_ns: [Option<u64>; 4],
    pub epu_ns: u64,
}

impl FrameTiming {
    /// The same timing `by_ns` later.
    pub fn shifted(&self, by_ns: u64) -> FrameTiming {
        FrameTiming { port_ns: self.port_ns.map(|t| t.map(|t| t + by_ns)), epu_ns: self.epu_ns + by_ns }
    }
}

/// Link of one port, as the segment wires it.
#[derive(Debug, Clone, Copy, Default, PartialEq, Eq)]
pub struct LinkState {
    pub link: bool,
}

#[derive(Debug, Clone, Default)]
struct SmState {
    /// Mailbox mode: the buffer holds a message.
    full: bool,
    /// Buffered mode, ECAT writes: the buffer being written (committed when its last byte is).
    /// The allocation is kept across cycles; `staged` says whether it holds a write in progress.
    staging: Vec<u8>,
    staged: bool,
    last_byte_written: bool,
    last_byte_read: bool,
    /// Status bits 0 and 1 (mailbox mode): a buffer was completely written / read; each is
    /// cleared when the other side opens the buffer (accesses its first byte).
    int_write: bool,
    int_read: bool,
}

/// What the SII says the device needs, for the AL checks.
#[derive(Debug, Clone, Default)]
struct Expected {
    mailbox: Option<(SmEntry, SmEntry)>,
    /// SM index, SII entry, expected length in bytes.
    process_data: Vec<(u8, SmEntry, u16)>,
}

impl Expected {
    fn from_sii(info: &SiiInfo) -> Self {
        let h = &info.header;
        let sms = info.sync_managers();
        let mailbox = (h.mailbox_rx_size > 0 && h.mailbox_tx_size > 0).then(|| {
            let out = sms.first().copied().unwrap_or(SmEntry {
                start: h.mailbox_rx_offset,
                length: h.mailbox_rx_size,
                control: 0x26,
                ..Default::default()
            });
            let inp = sms.get(1).copied().unwrap_or(SmEntry {
                start: h.mailbox_tx_offset,
                length: h.mailbox_tx_size,
                control: 0x22,
                ..Default::default()
            });
            (
                SmEntry { start: h.mailbox_rx_offset, length: h.mailbox_rx_size, ..out },
                SmEntry { start: h.mailbox_tx_offset, length: h.mailbox_tx_size, ..inp },
            )
        });
        let mut process_data = Vec::new();
        for (i, s) in sms.iter().enumerate() {
            if s.sm_type == SmEntry::TYPE_OUTPUTS || s.sm_type == SmEntry::TYPE_INPUTS {
                let pdos = if s.sm_type == SmEntry::TYPE_OUTPUTS { info.rx_pdos() } else { info.tx_pdos() };
                let bits: u32 = pdos.iter().filter(|p| p.sync_manager as usize == i).map(|p| p.bit_len()).sum();
                let len = if s.length > 0 { s.length } else { bits.div_ceil(8) as u16 };
                process_data.push((i as u8, *s, len));
            }
        }
        Expected { mailbox, process_data }
    }
}

/// A bounded record of recent SYNC0 events.
#[derive(Debug, Clone, Default)]
pub struct SyncLog {
    /// The last SYNC0 events the application saw: (system time, true time), newest last, at
    /// most 64.
    pub pulses: std::collections::VecDeque<(u64, u64)>,
    /// Every pulse the unit gave, including those that fell while the PDI still serviced an
    /// earlier one, while the output was held active, or with only SYNC1's output on.
    pub count: u64,
    /// Pulses the application did not see for those reasons.
    pub merged: u64,
}

impl SyncLog {
    fn push(&mut self, p: (u64, u64), pulses: u64) {
        if self.pulses.len() == 64 {
            self.pulses.pop_front();
        }
        self.pulses.push_back(p);
        self.count += pulses;
        self.merged += pulses - 1;
    }
}

/// How long after a SYNC0 edge the PDI side is busy with it: an interrupt entry and the read of
/// 0x098E that acknowledges it. Pulses in that time raise no new edge (model choice; the
/// datasheet gives no figure, and the lab's and tests' cycles, ≥ 50 µs, are far longer).
pub const SYNC0_SERVICE_NS: u64 = 1_000;

/// Per-frame bookkeeping of writes with side effects.
#[derive(Debug, Default)]
struct FrameEffects {
    latch_ports: bool,
    latch_epu: bool,
    tcl: Option<[Option<u8>; 4]>,
    /// Some SyncManager's last byte was written or read.
    sm_buffer_done: bool,
}

#[derive(Debug)]
pub struct Esc {
    pub config: EscConfig,
    mem: Vec<u8>,
    pending: Vec<(u16, u8)>,
    eeprom: Eeprom,
    pub dc: Option<DcUnit>,
    links: [bool; 4],
    pub al: AlMachine,
    app: Box<dyn Application>,
    now_ns: u64,
    sms: Vec<SmState>,
    expected: Expected,
    effects: FrameEffects,
    wd_last_trigger_ns: u64,
    reset_seq: u8,
    /// True time of the last SYNC0 edge the application saw since the unit was activated.
    sync0_edge_ns: Option<u64>,
    pub sync0_log: SyncLog,
    /// Frames this ESC processed.
    pub frames: u64,
    /// AL status changes, for tests and tracing.
    pub al_changes: u64,
    /// Drift (ppb) and power-on local time the DC unit restarts with after a power cycle.
    dc_init: (i64, u64),
    /// Decoded SyncManagers and active FMMUs, refreshed when their registers are written.
    sm_cache: Vec<SyncManager>,
    /// Lowest start and highest end of the enabled SyncManagers' areas.
    sm_span: (u32, u32),
    fmmu_cache: Vec<Fmmu>,
    /// When the frame being processed passed the processing unit (0x0910's latch instant),
    /// until a read puts that time into the register.
    system_time_latch: Option<u64>,
    scratch: Vec<u8>,
    sii_busy_shown: bool,
    sync_pulsed: bool,
    /// An enabled output SyncManager triggers the process-data watchdog.
    wd_armed: bool,
    /// Messages waiting for the send mailbox (SM1) to be read.
    mbx_queue: std::collections::VecDeque<Vec<u8>>,
    /// Without device emulation the firmware reads AL control this long after the master
    /// wrote it; until then the register is locked (ESC datasheet, 0x0120).
    pub al_response_ns: u64,
    pending_al: Option<(u16, u64)>,
    port_generation: u32,
    /// ECAT event request bits 2 and 3: DL and AL status changed since the master last read them.
    dl_changed: bool,
    al_changed: bool,
    /// ECAT event request AND mask: what this ESC ORs into every datagram's IRQ field.
    irq: u16,
    /// The DC unit's system time part (0x0910–0x09FF) exists; without it only the receive
    /// times 0x0900–0x090F answer.
    system_time_unit: bool,
}

impl Esc {
    /// An ESC loaded with an SII image, running `app`; its DC oscillator has `drift_ppb`.
    pub fn new(config: EscConfig, sii: Vec<u8>, app: Box<dyn Application>, drift_ppb: i64, t_ns: u64) -> Self {
        let expected = SiiInfo::from_image(&sii).map(|i| Expected::from_sii(&i)).unwrap_or_default();
        let mut esc = Esc {
            mem: vec![0; config.memory_len()],
            sms: vec![SmState::default(); config.sm_count as usize],
            config,
            pending: Vec::with_capacity(64),
            eeprom: Eeprom::new(sii),
            dc: None,
            links: [false; 4],
            al: AlMachine::default(),
            app,
            now_ns: t_ns,
            expected,
            effects: FrameEffects::default(),
            wd_last_trigger_ns: t_ns,
            reset_seq: 0,
            sync0_edge_ns: None,
            sync0_log: SyncLog::default(),
            frames: 0,
            al_changes: 0,
            dc_init: (drift_ppb, 0),
            sm_cache: Vec::new(),
            sm_span: (0, 0),
            fmmu_cache: Vec::new(),
            system_time_latch: None,
            scratch: Vec::new(),
            sii_busy_shown: false,
            sync_pulsed: false,
            wd_armed: false,
            mbx_queue: Default::default(),
            al_response_ns: 1_000_000,
            pending_al: None,
            port_generation: 0,
            dl_changed: false,
            al_changed: false,
            irq: 0,
            system_time_unit: false,
        };
        esc.power_on(t_ns);
        esc
    }

    /// Power-on (or a reset): registers to their reset values, configuration words from the
    /// EEPROM, a fresh DC unit whose local time starts at zero.
    pub fn power_on(&mut self, t_ns: u64) {
        let c = self.config.clone();
        self.port_generation = self.port_generation.wrapping_add(1);
        self.mem.fill(0);
        self.pending.clear();
        self.sms.iter_mut().for_each(|s| *s = SmState::default());
        self.mbx_queue.clear();
        self.pending_al = None;
        self.al = AlMachine::default();
        self.now_ns = t_ns;
        self.wd_last_trigger_ns = t_ns;
        let m = &mut self.mem;
        m[0] = c.esc_type;
        m[1] = c.revision;
        m[2..4].copy_from_slice(&c.build.to_le_bytes());
        m[4] = c.fmmu_count;
        m[5] = c.sm_count;
        m[6] = c.ram_kb;
        m[7] = c.port_descriptor;
        m[8..10].copy_from_slice(&c.features.to_le_bytes());
        // Forwarding rule: destroy non-EtherCAT frames.
        m[0x0100] = 0x01;
        // RX FIFO size 7; Beckhoff's ASICs also come up with bits 6–7 set (TwinCAT reads 0xC7
        // from an EK1100's ET1100 and an EL1004's ET1200, 0x07 from the AKD's IP core).
        m[0x0102] = if matches!(c.esc_type, 0x11 | 0x12) { 0xC7 } else { 0x07 };
        m[0x0400..0x0402].copy_from_slice(&2498u16.to_le_bytes());
        m[0x0410..0x0412].copy_from_slice(&1000u16.to_le_bytes());
        m[0x0420..0x0422].copy_from_slice(&1000u16.to_le_bytes());
        m[0x0440] = 1;
        let e = &self.eeprom;
        m[0x0140..0x0142].copy_from_slice(&c.pdi_control.unwrap_or(e.word(0)).to_le_bytes());
        m[0x0150..0x0152].copy_from_slice(&e.word(1).to_le_bytes());
        m[0x0982..0x0984].copy_from_slice(&e.word(2).to_le_bytes());
        m[0x0152..0x0154].copy_from_slice(&e.word(3).to_le_bytes());
        m[0x0012..0x0014].copy_from_slice(&e.word(4).to_le_bytes());
        let size_kbit = e.word(0x3E) as u32 + 1;
        let ctl = if c.sii_read_8 { SiiControl::READ_8_BYTES } else { 0 }
            | if size_kbit > 16 { SiiControl::TWO_BYTE_ADDRESS } else { 0 }
            | if c.eeprom_emulation { SiiControl::EMULATION } else { 0 };
        m[0x0502..0x0504].copy_from_slice(&ctl.to_le_bytes());
        self.dc = match c.dc {
            DcWidth::None => None,
            w => {
                let (drift, local0) = self.dc_init;
                Some(DcUnit::new(w, t_ns, local0, drift))
            }
        };
        // An ET1100 or ET1200 with neither its SYNC out nor its latch in unit enabled (0x0141
        // bits 2–3, from SII word 0) answers its receive times only: the real EL1004 and EL2828
        // (ET1200, 0x0141 = 0x01) and EK1914 (ET1100) give WKC 0 for 0x0910–0x09FF, the EK1100
        // (ET1100, 0x0D) counts.
        self.system_time_unit = !matches!(c.esc_type, 0x11 | 0x12) || m[0x0141] & 0x0C != 0;
        self.reload_sm_fmmu();
        // The DL status comes up from reset (an event); AL status Init is its reset value.
        self.refresh_registers();
        self.al_changed = false;
        self.update_irq();
    }

    /// Decodes the SyncManager and FMMU registers after they were written.
    fn reload_sm_fmmu(&mut self) {
        self.sm_cache = (0..self.config.sm_count)
            .map(|n| {
                let a = addr::sm(n) as usize;
                SyncManager::parse(&self.mem[a..a + 8]).unwrap_or_default()
            })
            .collect();
        let active = self.sm_cache.iter().filter(|s| s.enabled() && s.length > 0);
        let lo = active.clone().map(|s| s.start as u32).min().unwrap_or(0);
        let hi = active.map(|s| s.start as u32 + s.length as u32).max().unwrap_or(0);
        self.sm_span = (lo, hi);
        self.wd_armed = self
            .sm_cache
            .iter()
            .any(|s| s.enabled() && !s.is_mailbox() && s.ecat_writes() && s.control & SyncManager::WATCHDOG != 0);
        self.fmmu_cache = (0..self.config.fmmu_count)
            .filter_map(|i| {
                let a = addr::fmmu(i) as usize;
                Fmmu::parse(&self.mem[a..a + 16]).ok().filter(|f| f.active && f.length > 0)
            })
            .collect();
    }

    pub fn app(&self) -> &dyn Application {
        self.app.as_ref()
    }
    pub fn app_mut(&mut self) -> &mut dyn Application {
        self.app.as_mut()
    }

    /// The LATCH`unit` input pin changes to `level` at true time `t_ns`: the edge's system time
    /// goes to 0x09B0/0x09B8 (unit 0, rising/falling) or 0x09C0/0x09C8 (unit 1). In single-event
    /// mode (0x09A8/0x09A9 bit 0/1) only the first edge is kept until the master reads its time.
    pub fn latch_input(&mut self, unit: u8, level: bool, t_ns: u64) {
        let Some(dc) = self.dc.as_ref() else { return };
        let unit = (unit & 1) as usize;
        let status_at = 0x09AE + unit;
        let was = self.mem[status_at] & 0x04 != 0;
        self.mem[status_at] = (self.mem[status_at] & !0x04) | if level { 0x04 } else { 0 };
        if was == level {
            return;
        }
        let edge = if level { 0 } else { 1 };
        let single = self.mem[0x09A8 + unit] & (1 << edge) != 0;
        if single && self.mem[status_at] & (1 << edge) != 0 {
            return;
        }
        let at = 0x09B0 + 16 * unit + 8 * edge;
        let time = dc.system_at(t_ns);
        self.mem[at..at + 8].copy_from_slice(&time.to_le_bytes());
        if single {
            self.mem[status_at] |= 1 << edge;
            self.update_irq();
        }
    }

    /// A frame arrived broken on `port`: the invalid-frame counter (0x0300 + 2·port) counts,
    /// saturating at 255.
    pub fn count_rx_error(&mut self, port: u8) {
        let a = 0x0300 + 2 * (port as usize & 3);
        self.mem[a] = self.mem[a].saturating_add(1);
    }

    /// The DC local time this ESC starts from at power-on (default 0; a real ESC's counter
    /// starts at 0 but slaves powered at different moments differ, and a value near 2^32 or
    /// 2^64 makes latched times wrap soon after the start).
    pub fn set_power_on_local_time(&mut self, local_ns: u64) {
        self.dc_init.1 = local_ns;
        if let Some(dc) = &self.dc {
            self.dc = Some(DcUnit::new(dc.width, self.now_ns, local_ns, self.dc_init.0));
        }
    }

    /// Whether the DC unit's system time (0x0910–0x09FF) exists: a clock a master can
    /// synchronise, not only receive times.
    pub fn has_system_time(&self) -> bool {
        self.dc.is_some() && self.system_time_unit
    }

    pub fn station_address(&self) -> u16 {
        u16::from_le_bytes([self.mem[0x10], self.mem[0x11]])
    }

    pub fn set_link(&mut self, port: u8, link: bool) {
        self.links[(port & 3) as usize] = link;
        self.port_generation = self.port_generation.wrapping_add(1);
        self.refresh_registers();
    }

    /// Whether a frame leaves through `port` (link up and loop open), or loops back.
    pub fn port_open(&self, port: u8) -> bool {
        let p = (port & 3) as usize;
        if !self.config.has_port(port) || !self.links[p] {
            return false;
        }
        // Loop control 0x0101: 00 auto, 01 auto-close, 10 open, 11 closed.
        (self.mem[0x0101] >> (2 * p)) & 3 != 3
    }

    /// Changes whenever `port_open` may answer differently (link, loop control, power-on):
    /// the segment re-walks its route only then.
    pub fn port_generation(&self) -> u32 {
        self.port_generation
    }

    /// Reads memory as the PDI sees it (tests, tools).
    pub fn peek(&self, a: u16, len: usize) -> &[u8] {
        let a = a as usize;
        &self.mem[a.min(self.mem.len())..(a + len).min(self.mem.len())]
    }

    /// Current time of this ESC's model.
    pub fn now_ns(&self) -> u64 {
        self.now_ns
    }

    /// Advances the ESC to true time `t_ns`: SYNC pulses, watchdogs, EEPROM busy.
    pub fn advance_to(&mut self, t_ns: u64) {
        if t_ns < self.now_ns {
            return;
        }
        // SYNC0 edges and the application's own events up to t, each at its exact true instant.
        loop {
            let sync = self.next_sync0_edge_ns();
            let own = self.app.next_event_ns();
            let tp = match (sync, own) {
                (None, None) => break,
                (Some(s), None) => s,
                (None, Some(o)) => o,
                (Some(s), Some(o)) => s.min(o),
            };
            if tp > t_ns {
                break;
            }
            self.now_ns = self.now_ns.max(tp);
            if sync == Some(tp) {
                let due = self.dc.as_mut().and_then(|dc| dc.take_sync0_until(tp));
                if let Some(due) = due {
                    self.sync_pulsed = true;
                    self.sync0_edge_ns = Some(tp);
                    self.sync0_log.push((due.last_sys_ns, tp), due.pulses);
                    let mut pdi = Pdi { mem: &mut self.mem, now_ns: tp };
                    self.app.sync0(&mut pdi, due.last_sys_ns);
                }
            } else {
                let mut pdi = Pdi { mem: &mut self.mem, now_ns: tp };
                self.app.tick(&mut pdi);
            }
        }
        // Pulses that raised no edge (SYNC0 output off, output held, or the PDI still busy)
        // still move the schedule that 0x0990 shows. Past the service time every due pulse of
        // an active output was an edge.
        if let Some(dc) = self.dc.as_mut() {
            let edge = self.sync0_edge_ns;
            let silent = !dc.sync.output_enabled() || (edge.is_some() && dc.sync.output_held());
            let busy = edge.is_some_and(|e| e.saturating_add(SYNC0_SERVICE_NS) >= t_ns);
            if let Some(due) = if silent || busy { dc.take_sync0_until(t_ns) } else { None } {
                self.sync_pulsed = true;
                self.sync0_log.count += due.pulses;
                self.sync0_log.merged += due.pulses;
            }
        }
        if let Some(dc) = self.dc.as_mut() {
            dc.fold_to(t_ns);
        }
        if std::mem::take(&mut self.sync_pulsed) {
            self.refresh_registers();
        }
        if let Some((control, due)) = self.pending_al {
            if due <= t_ns {
                self.pending_al = None;
                self.now_ns = self.now_ns.max(due);
                self.al_control(control);
                self.refresh_registers();
            }
        }
        self.now_ns = t_ns;
        self.check_watchdog();
        if self.eeprom.reloaded && !self.eeprom.busy(t_ns) {
            self.eeprom.reloaded = false;
        }
    }

    /// True time of the next SYNC0 edge the application will see.
    fn next_sync0_edge_ns(&self) -> Option<u64> {
        let dc = self.dc.as_ref().filter(|dc| dc.sync.output_enabled())?;
        match self.sync0_edge_ns {
            Some(_) if dc.sync.output_held() => None,
            Some(edge) if edge.saturating_add(SYNC0_SERVICE_NS) >= self.now_ns => {
                dc.next_sync0_true_after(edge.saturating_add(SYNC0_SERVICE_NS))
            }
            _ => dc.next_sync0_true(self.now_ns),
        }
    }

    /// True time of the next internal event (a SYNC0 edge), for a virtual-time scheduler.
    pub fn next_event_ns(&self) -> Option<u64> {
        let sync = self.next_sync0_edge_ns();
        [sync, self.app.next_event_ns(), self.pending_al.map(|p| p.1)].into_iter().flatten().min()
    }

    fn device_emulation(&self) -> bool {
        self.mem[0x0141] & 0x01 != 0
    }

    fn process_data_watchdog_ns(&self) -> Option<u64> {
        let div = u16::from_le_bytes([self.mem[0x0400], self.mem[0x0401]]) as u64;
        let n = u16::from_le_bytes([self.mem[0x0420], self.mem[0x0421]]) as u64;
        (n > 0).then(|| n * (div + 2) * 40)
    }

    fn check_watchdog(&mut self) {
        if !self.wd_armed || self.al.state != AlState::Op {
            return;
        }
        let Some(wd) = self.process_data_watchdog_ns() else { return };
        if self.al.state == AlState::Op && self.now_ns.saturating_sub(self.wd_last_trigger_ns) > wd {
            self.mem[0x0440] = 0;
            self.mem[0x0442] = self.mem[0x0442].saturating_add(1);
            self.al.fail(AlState::SafeOp, AlStatusCode::SM_WATCHDOG);
            self.al_changes += 1;
            let mut pdi = Pdi { mem: &mut self.mem, now_ns: self.now_ns };
            self.app.state_changed(&mut pdi, AlState::SafeOp);
            self.refresh_registers();
        }
    }

    fn sm(&self, n: u8) -> SyncManager {
        self.sm_cache.get(n as usize).copied().unwrap_or_default()
    }

    /// Rewrites registers whose value follows from state: DL status, AL status, SM status,
    /// SII busy, DC times.
    fn refresh_registers(&mut self) {
        let mut dl = 1u16; // EEPROM loaded, PDI operational
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
        let ctl = u16::from_le_bytes([self.mem[0x0502], self.mem[0x0503]]) & !(SiiControl::BUSY | 0x7800);
        self.mem[0x0502..0x0504].copy_from_slice(&(ctl | busy | self.eeprom.errors).to_le_bytes());
        self.refresh_dc_registers();
        self.update_irq();
    }

    /// SyncManager `n`'s status bits 0, 1 and 3 from its state.
    fn write_sm_status(&mut self, n: u8) {
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
    fn put_sm_status(&mut self, n: u8) {
        self.write_sm_status(n);
        self.update_irq();
    }

    /// ECAT event request (0x0210) from the state, and what this ESC puts into IRQ fields.
    fn update_irq(&mut self) {
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
    fn refresh_dc_registers(&mut self) {
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

    fn refresh_sync1_registers(&mut self) {
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
    fn refresh_pdi_events(&mut self) {
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
    fn refresh_tcl_registers(&mut self) {
        if let Some(dc) = &self.dc {
            self.mem[0x092C..0x0930].copy_from_slice(&dc.difference_register().to_le_bytes());
            self.mem[0x0932..0x0934].copy_from_slice(&dc.scd.to_le_bytes());
        }
    }

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
        }
        if self.eeprom.busy(self.now_ns) != self.sii_busy_shown {
            self.refresh_registers();
        }
        // ECAT reads of 0x0910 see the time the frame passed, minus the delay: latched now,
        // put into the register when a datagram reads it (most frames do not).
        self.system_time_latch = self.dc.as_ref().map(|_| epu_ns);
        self.effects = FrameEffects::default();
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

    fn addressed_fp(&self, adp: u16) -> bool {
        let alias_on = self.mem[0x0103] & 0x01 != 0;
        adp == self.station_address() || (alias_on && adp == u16::from_le_bytes([self.mem[0x12], self.mem[0x13]]))
    }

    fn datagram(&mut self, d: &mut [u8]) {
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
        let rw_offset = u16::from_le_bytes([self.mem[0x0108], self.mem[0x0109]]);
        let mut inc = 0u16;
        match cmd {
            Command::APRD | Command::FPRD | Command::BRD => {
                let hit = match cmd {
                    Command::APRD => adp == 0,
                    Command::FPRD => self.addressed_fp(adp),
                    _ => true,
                };
                if hit && self.read(ado, data, cmd == Command::BRD) {
                    inc = 1;
                }
            }
            Command::APWR | Command::FPWR | Command::BWR => {
                let hit = match cmd {
                    Command::APWR => adp == 0,
                    Command::FPWR => self.addressed_fp(adp),
                    _ => true,
                };
                if hit && self.write(ado, data, cmd) {
                    inc = 1;
                }
            }
            Command::APRW | Command::FPRW | Command::BRW => {
                let hit = match cmd {
                    Command::APRW => adp == 0,
                    Command::FPRW => self.addressed_fp(adp),
                    _ => true,
                };
                if hit {
                    let out = data.to_vec();
                    if self.read(ado, data, cmd == Command::BRW) {
                        inc += 1;
                    }
                    if self.write(ado.wrapping_add(rw_offset), &out, cmd) {
                        inc += 2;
                    }
                }
            }
            Command::ARMW | Command::FRMW => {
                let reader = if cmd == Command::ARMW { adp == 0 } else { self.addressed_fp(adp) };
                let ok = if reader { self.read(ado, data, false) } else { self.write(ado, data, cmd) };
                if ok {
                    inc = 1;
                }
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

    fn sm_at(&self, a: u16) -> Option<(u8, SyncManager)> {
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
    fn absent(&self, a: u16) -> bool {
        match a {
            0x0600..=0x06FF => (a - 0x0600) / 16 >= self.config.fmmu_count as u16,
            0x0800..=0x087F => (a - 0x0800) / 8 >= self.config.sm_count as u16,
            0x0900..=0x090F => self.dc.is_none(),
            0x0910..=0x09FF => self.dc.is_none() || !self.system_time_unit,
            _ => a as usize >= self.mem.len(),
        }
    }

    /// Puts the time the frame passed (minus the delay) into 0x0910, once per frame.
    fn latch_system_time(&mut self) {
        if let (Some(t), Some(dc)) = (self.system_time_latch.take(), &self.dc) {
            let v = dc.ecat_system_time(t);
            let n = if dc.width == DcWidth::Bits64 { 8 } else { 4 };
            self.mem[0x0910..0x0910 + n].copy_from_slice(&v.to_le_bytes()[..n]);
        }
    }

    /// One byte read by the master; `None` if it cannot be read.
    fn read_byte(&mut self, a: u16) -> Option<u8> {
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
                    self.effects.sm_buffer_done = true;
                }
            }
        }
        Some(self.mem[a as usize])
    }

    fn read(&mut self, ado: u16, data: &mut [u8], or: bool) -> bool {
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
    fn write_byte(&mut self, a: u16, v: u8, cmd: Command) -> bool {
        if self.absent(a) {
            return false;
        }
        if let Some((n, s)) = self.sm_at(a) {
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
                self.effects.sm_buffer_done = true;
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

    fn write(&mut self, ado: u16, data: &[u8], cmd: Command) -> bool {
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

    /// LRD/LWR/LRW through the FMMUs, bit by bit where they are not byte-aligned. Returns the
    /// WKC increment: +1 if something was read, +2 if something was written (LWR: +1).
    fn logical(&mut self, cmd: Command, logical: u32, data: &mut [u8]) -> u16 {
        let dg_start = logical as u64 * 8;
        let dg_end = dg_start + data.len() as u64 * 8;
        let overlap = |f: &Fmmu| {
            let f_start = f.logical_start as u64 * 8 + (f.logical_start_bit & 7) as u64;
            let f_end = (f.logical_start as u64 + f.length as u64 - 1) * 8 + (f.logical_stop_bit & 7) as u64 + 1;
            (f_start, f_start.max(dg_start), f_end.min(dg_end))
        };
        // The frame bytes some FMMU maps: writes take them as they arrived (a read through
        // another FMMU may change them first), so they are kept aside; most ESCs map only a
        // few bytes of a long LRW.
        let (first, last, hits) = self
            .fmmu_cache
            .iter()
            .map(overlap)
            .filter(|(_, lo, hi)| lo < hi)
            .fold((u64::MAX, 0, 0), |(a, b, n), (_, lo, hi)| {
                (a.min((lo - dg_start) / 8), b.max((hi - dg_start).div_ceil(8)), n + 1)
            });
        if first >= last {
            return 0;
        }
        // One FMMU's runs cover disjoint frame bits, each written before it is read: only a
        // second FMMU can read into bits another writes, so only then is a copy needed.
        let mut original = std::mem::take(&mut self.scratch);
        original.clear();
        if hits > 1 {
            original.extend_from_slice(&data[first as usize..last as usize]);
        }
        let (mut read_ok, mut write_ok) = (false, false);
        for i in 0..self.fmmu_cache.len() {
            let f = self.fmmu_cache[i];
            let (f_start, lo, hi) = overlap(&f);
            if lo >= hi {
                continue;
            }
            let phys0 = f.physical_start as u64 * 8 + (f.physical_start_bit & 7) as u64;
            let reads = f.fmmu_type & Fmmu::READ != 0 && matches!(cmd, Command::LRD | Command::LRW);
            let writes = f.fmmu_type & Fmmu::WRITE != 0 && matches!(cmd, Command::LWR | Command::LRW);
            // Walk the overlap in runs that stay within one physical and one frame byte.
            let mut bit = lo;
            while bit < hi {
                let pbit = phys0 + (bit - f_start);
                let fbit = bit - dg_start;
                let run = (8 - pbit % 8).min(8 - fbit % 8).min(hi - bit);
                let pa = (pbit / 8) as u16;
                let fi = (fbit / 8) as usize;
                let mask_p = (((1u16 << run) - 1) << (pbit % 8)) as u8;
                let mask_f = (((1u16 << run) - 1) << (fbit % 8)) as u8;
                let shift = |v: u8, from: u64, to: u64| -> u8 {
                    if to >= from {
                        v << (to - from)
                    } else {
                        v >> (from - to)
                    }
                };
                if writes {
                    let cur = self.current_byte(pa);
                    let arrived = if hits > 1 { original[fi - first as usize] } else { data[fi] };
                    let bits = shift(arrived & mask_f, fbit % 8, pbit % 8);
                    if self.write_byte(pa, (cur & !mask_p) | bits, cmd) {
                        write_ok = true;
                    }
                }
                if reads {
                    if let Some(v) = self.read_byte(pa) {
                        data[fi] = (data[fi] & !mask_f) | shift(v & mask_p, pbit % 8, fbit % 8);
                        read_ok = true;
                    }
                }
                bit += run;
            }
        }
        self.scratch = original;
        match cmd {
            Command::LRD => read_ok as u16,
            Command::LWR => write_ok as u16,
            _ => read_ok as u16 + 2 * write_ok as u16,
        }
    }

    /// The value a partial (bit-wise) write builds on: the staging buffer of a buffered output
    /// SM, a pending register write, or memory.
    fn current_byte(&self, a: u16) -> u8 {
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
    fn system_time_byte_written(&mut self, a: u16, v: u8) {
        let t = self.effects.tcl.get_or_insert([None; 4]);
        if let Some(slot) = t.get_mut(a.wrapping_sub(0x0910) as usize) {
            *slot = Some(v);
        }
    }

    /// A frame's write of 0x0910 (the bytes it wrote): one TCL sample at `t`.
    fn feed_tcl(dc: &mut DcUnit, bytes: Option<[Option<u8>; 4]>, t: u64) {
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

    fn end_of_frame(&mut self, timing: &FrameTiming, origin_ns: u64) {
        let t = timing.epu_ns + origin_ns;
        let mut pending = std::mem::take(&mut self.pending);
        if pending.is_empty() && !self.effects.sm_buffer_done {
            self.pending = pending;
            // Nothing but (perhaps) a system-time write: a TCL sample, which changes only the
            // difference (0x092C) and the speed counter difference (0x0932).
            if let (Some(dc), Some(bytes)) = (self.dc.as_mut(), self.effects.tcl.take()) {
                Self::feed_tcl(dc, Some(bytes), t);
                self.refresh_tcl_registers();
            }
            return;
        }
        let (mut al_ctl, mut sii_cmd, mut dc_offset, mut dc_delay, mut scs, mut depths) =
            (false, false, false, false, false, false);
        let (mut sync_cfg, mut activation, mut start_time, mut sm_cfg, mut fmmu_cfg, mut reset) =
            (false, false, false, false, false, false);
        let (mut event_mask, mut dl_ctl) = (false, false);
        for &(a, _) in &pending {
            match a {
                0x0040 => reset = true,
                0x0100..=0x0103 => {
                    self.port_generation = self.port_generation.wrapping_add(1);
                    dl_ctl = true; // loop control shows in the DL status
                }
                0x0120..=0x0121 => al_ctl = true,
                0x0502..=0x0503 => sii_cmd = true,
                0x0600..=0x06FF => fmmu_cfg = true,
                0x0800..=0x087F => sm_cfg = true,
                0x0920..=0x0927 => dc_offset = true,
                0x0928..=0x092B => dc_delay = true,
                0x0930..=0x0931 => scs = true,
                0x0934..=0x0935 => depths = true,
                0x0200..=0x0201 => event_mask = true,
                0x0981 => {
                    sync_cfg = true;
                    activation = true;
                }
                0x0990..=0x0997 => {
                    sync_cfg = true;
                    start_time = true;
                }
                0x0980..=0x09A7 => sync_cfg = true,
                _ => {}
            }
        }
        for &(a, v) in &pending {
            self.mem[a as usize] = v;
            if (0x0300..=0x0313).contains(&a) {
                self.mem[a as usize] = 0; // a write clears an error counter
            }
            if (0x0442..=0x0443).contains(&a) {
                self.mem[0x0442..=0x0443].fill(0); // either watchdog counter's write clears both
            }
        }
        if event_mask {
            self.update_irq();
        }
        if reset {
            // ESC reset: 'R' 'E' 'S' in three consecutive frames.
            let v = self.mem[0x0040];
            self.reset_seq = match (self.reset_seq, v) {
                (_, b'R') => 1,
                (1, b'E') => 2,
                (2, b'S') => 3,
                _ => 0,
            };
            if self.reset_seq == 3 {
                self.power_on(t);
                return;
            }
        }
        let mut tcl_fed = false;
        if sm_cfg || fmmu_cfg {
            self.reload_sm_fmmu();
        }
        if sm_cfg {
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
        // SyncManager buffers completed by this frame.
        let mut deliver = false;
        let mut mailbox_moved = false;
        for n in 0..self.config.sm_count {
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
                }
            }
        }
        if deliver || sm_cfg {
            self.deliver_mailbox();
        }
        if sii_cmd {
            let ctl = u16::from_le_bytes([self.mem[0x0502], self.mem[0x0503]]);
            let word = u32::from_le_bytes([self.mem[0x0504], self.mem[0x0505], self.mem[0x0506], self.mem[0x0507]]);
            let data = u16::from_le_bytes([self.mem[0x0508], self.mem[0x0509]]);
            if let Some(out) = self.eeprom.command(t, ctl, word, data, self.config.sii_read_8) {
                self.mem[0x0508..0x0510].copy_from_slice(&out);
            }
            let keep = ctl & (SiiControl::READ_8_BYTES | SiiControl::TWO_BYTE_ADDRESS | SiiControl::WRITE_ENABLE);
            let base = if self.config.sii_read_8 { SiiControl::READ_8_BYTES } else { 0 };
            self.mem[0x0502..0x0504].copy_from_slice(&(keep | base).to_le_bytes());
        }
        if let Some(dc) = self.dc.as_mut() {
            if self.effects.latch_epu {
                let local = dc.local_at(t);
                self.mem[0x0918..0x0920].copy_from_slice(&local.to_le_bytes());
            }
            if self.effects.latch_ports {
                for (p, at) in timing.port_ns.iter().enumerate() {
                    // Ports the frame did not reach keep their old value (esc-spec §3.3).
                    if let Some(at) = at {
                        let v = dc.local_at(at + origin_ns) as u32;
                        self.mem[0x0900 + 4 * p..0x0904 + 4 * p].copy_from_slice(&v.to_le_bytes());
                    }
                }
            }
            let wide = dc.width == DcWidth::Bits64;
            let rd64 = |m: &[u8], a: usize| -> u64 {
                let mut b = [0u8; 8];
                b.copy_from_slice(&m[a..a + 8]);
                let v = u64::from_le_bytes(b);
                if wide {
                    v
                } else {
                    v & 0xFFFF_FFFF
                }
            };
            // The time written is compared with the copy latched at SOF (esc-spec 0x0910): with
            // the offset and delay in force before this frame's writes apply.
            if self.effects.tcl.is_some() {
                tcl_fed = true;
                Self::feed_tcl(dc, self.effects.tcl.take(), t);
            }
            if dc_offset {
                dc.fold_to(t);
                dc.offset = rd64(&self.mem, 0x0920);
            }
            if dc_delay {
                dc.delay = u32::from_le_bytes([self.mem[0x0928], self.mem[0x0929], self.mem[0x092A], self.mem[0x092B]]);
            }
            if depths {
                dc.depth_diff = self.mem[0x0934] & 0x0F;
                dc.depth_speed = self.mem[0x0935] & 0x0F;
            }
            if scs {
                let v = u16::from_le_bytes([self.mem[0x0930], self.mem[0x0931]]) & 0x7FFF;
                dc.scs = v.clamp(0x0080, 0x3FFF);
                dc.reset_filters(t);
            }
            if sync_cfg {
                dc.sync.activation = self.mem[0x0981];
                dc.sync.pulse_len_10ns = u16::from_le_bytes([self.mem[0x0982], self.mem[0x0983]]);
                dc.sync.start_time = rd64(&self.mem, 0x0990);
                dc.sync.cycle0_ns =
                    u32::from_le_bytes([self.mem[0x09A0], self.mem[0x09A1], self.mem[0x09A2], self.mem[0x09A3]]);
                dc.sync.cycle1_ns =
                    u32::from_le_bytes([self.mem[0x09A4], self.mem[0x09A5], self.mem[0x09A6], self.mem[0x09A7]]);
                let auto = dc.sync.activation & ferrocat_wire::register::dc_activation::AUTO_ACTIVATE != 0;
                if activation || (start_time && auto) {
                    dc.sync_activation_written(t);
                    self.sync0_edge_ns = None;
                }
            }
        }
        if al_ctl {
            let control = u16::from_le_bytes([self.mem[0x0120], self.mem[0x0121]]);
            if self.device_emulation() || self.al_response_ns == 0 {
                self.al_control(control);
            } else {
                self.pending_al = Some((control, t + self.al_response_ns));
            }
        }
        let dc_only =
            !(al_ctl || sii_cmd || sm_cfg || reset || dl_ctl || mailbox_moved || self.sms.iter().any(|s| s.full));
        if dc_only {
            if dc_offset || dc_delay || scs || depths || sync_cfg {
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

    fn al_control(&mut self, control: u16) {
        let before = self.al.clone();
        if self.device_emulation() {
            // Device emulation: the ESC copies AL control to AL status (esc-spec §5.1).
            if let Some(s) = AlState::from_bits(control as u8) {
                self.al.state = s;
                self.al.error = false;
                self.al.code = AlStatusCode::NO_ERROR;
            }
        } else {
            let mut expected = self.expected.clone();
            for (_, e, len) in expected.process_data.iter_mut() {
                if let Some(b) = self.app.process_data_bytes(e.sm_type == SmEntry::TYPE_OUTPUTS) {
                    *len = b;
                }
            }
            let sms: Vec<SyncManager> = (0..self.config.sm_count).map(|n| self.sm(n)).collect();
            let Esc { app, mem, now_ns, .. } = self;
            let mut check = |from: AlState, to: AlState| -> Result<(), AlStatusCode> {
                if from == AlState::Init && to == AlState::PreOp {
                    if let Some((out, inp)) = &expected.mailbox {
                        let good = |s: Option<&SyncManager>, e: &SmEntry, writes: bool| {
                            s.is_some_and(|s| {
                                s.enabled()
                                    && s.is_mailbox()
                                    && s.ecat_writes() == writes
                                    && s.start == e.start
                                    && s.length == e.length
                            })
                        };
                        if !good(sms.first(), out, true) || !good(sms.get(1), inp, false) {
                            return Err(AlStatusCode::INVALID_MAILBOX_CONFIG);
                        }
                    }
                }
                if from == AlState::PreOp && to == AlState::SafeOp {
                    for (n, e, len) in &expected.process_data {
                        let s = sms.get(*n as usize).copied().unwrap_or_default();
                        let outputs = e.sm_type == SmEntry::TYPE_OUTPUTS;
                        let good = if *len == 0 {
                            !s.enabled() || s.length == 0
                        } else {
                            s.enabled() && s.length == *len && s.ecat_writes() == outputs && !s.is_mailbox()
                        };
                        if !good {
                            return Err(if outputs {
                                AlStatusCode::INVALID_OUTPUT_CONFIG
                            } else {
                                AlStatusCode::INVALID_INPUT_CONFIG
                            });
                        }
                    }
                }
                let mut pdi = Pdi { mem, now_ns: *now_ns };
                app.check_transition(&mut pdi, from, to)
            };
            self.al.request(control, &mut check);
        }
        if self.al.state == AlState::Op && before.state != AlState::Op {
            self.wd_last_trigger_ns = self.now_ns;
        }
        if self.al != before {
            self.al_changes += 1;
            let mut pdi = Pdi { mem: &mut self.mem, now_ns: self.now_ns };
            self.app.state_changed(&mut pdi, self.al.state);
        }
    }

    /// A complete request arrived in the mailbox SM: the application answers into SM1.
    fn mailbox_request(&mut self, sm: u8) {
        let s = self.sm(sm);
        let req = self.mem[sm_area(&s, self.mem.len())].to_vec();
        // SM0 is consumed by the PDI at once: opened (clearing the write event) and read.
        let st = &mut self.sms[sm as usize];
        st.full = false;
        st.int_write = false;
        st.int_read = true;
        let reply = {
            let mut pdi = Pdi { mem: &mut self.mem, now_ns: self.now_ns };
            self.app.mailbox(&mut pdi, &req)
        };
        let reply = reply.unwrap_or_else(|| unsupported_protocol_reply(&req));
        self.mbx_queue.push_back(reply);
        self.deliver_mailbox();
    }

    /// Moves the next waiting message into the send mailbox if it is free.
    fn deliver_mailbox(&mut self) {
        let Some((n, out)) = (0..self.config.sm_count)
            .map(|n| (n, self.sm(n)))
            .find(|(_, s)| s.enabled() && s.is_mailbox() && !s.ecat_writes())
        else {
            return;
        };
        if self.sms[n as usize].full {
            return;
        }
        let msg = match self.mbx_queue.pop_front() {
            Some(m) => m,
            None => match self.app.pending_mailbox() {
                Some(m) => m,
                None => return,
            },
        };
        let area = sm_area(&out, self.mem.len());
        let area = &mut self.mem[area];
        let len = area.len().min(msg.len());
        area.fill(0);
        area[..len].copy_from_slice(&msg[..len]);
        let st = &mut self.sms[n as usize];
        st.full = true;
        st.int_write = true;
        st.int_read = false;
        self.put_sm_status(n);
    }
}

/// The memory a SyncManager's buffer occupies: its area, less what lies beyond the ESC's
/// memory (a master may configure that; those bytes do not exist, so its last byte can be
/// neither written nor read and the buffer never completes).
fn sm_area(s: &SyncManager, mem_len: usize) -> std::ops::Range<usize> {
    let start = (s.start as usize).min(mem_len);
    start..(s.start as usize + s.length as usize).min(mem_len)
}

/// A mailbox error reply "protocol not supported" for a request no application handles.
fn unsupported_protocol_reply(req: &[u8]) -> Vec<u8> {
    use ferrocat_wire::mailbox::{MailboxErrorCode, MailboxHeader, MailboxType};
    let counter = req.get(5).map(|b| (b >> 4) & 7).unwrap_or(0);
    let mut v = MailboxHeader::new(MailboxType::ERR, 4, counter).to_bytes().to_vec();
    v.extend_from_slice(&MailboxErrorCode::UNSUPPORTED_PROTOCOL.to_bytes());
    v
}

/// AL status as the master reads it (tests).
impl Esc {
    pub fn al_status(&self) -> AlStatus {
        self.al.status()
    }
}
