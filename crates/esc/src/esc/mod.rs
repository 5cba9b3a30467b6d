//! The slave controller: memory, datagram processing, end-of-frame effects.
use ferrocat_wire::register::{addr, AlState, AlStatus, AlStatusCode, Fmmu, SiiControl, SyncManager};
use ferrocat_wire::sii::{SiiInfo, SmEntry};

use crate::al::AlMachine;
use crate::app::{Application, Pdi};
use crate::config::{DcWidth, EscConfig};
use crate::dc::DcUnit;
use crate::eeprom::Eeprom;

mod al_mailbox;
mod datagram;
mod end_of_frame;
mod logical;
mod receive_latch;
mod registers;

pub use al_mailbox::MailboxResponse;

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
    /// The bootstrap mailbox (SM0, SM1 in BOOT), where the SII gives one.
    bootstrap: Option<(SmEntry, SmEntry)>,
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
        let bootstrap = (h.bootstrap_rx_size > 0 && h.bootstrap_tx_size > 0).then(|| {
            let sm = |start, length, control| SmEntry { start, length, control, ..Default::default() };
            (sm(h.bootstrap_rx_offset, h.bootstrap_rx_size, 0x26), sm(h.bootstrap_tx_offset, h.bootstrap_tx_size, 0x22))
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
        Expected { mailbox, bootstrap, process_data }
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
    /// The SyncManagers whose last byte was written or read (bit n: SM n).
    sm_done: u32,
}

#[derive(Debug)]
pub struct Esc {
    pub config: EscConfig,
    mem: Vec<u8>,
    pending: Vec<(u16, u8)>,
    eeprom: Eeprom,
    pub dc: Option<DcUnit>,
    links: [bool; 4],
    /// Auto-close ports (loop control 01) whose link came back: closed until the master
    /// writes DL control again or a valid frame arrives at them (Beckhoff EtherCAT
    /// Technology, Section I, "Auto close").
    closed_wait: [bool; 4],
    pub al: AlMachine,
    app: Box<dyn Application>,
    now_ns: u64,
    sms: Vec<SmState>,
    /// SyncManagers the firmware deactivated by the PDI (bit n: SM n), until the error is
    /// acknowledged.
    pdi_deactivated: u32,
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
    /// SyncManagers from SM2 on that hold inputs in mailbox mode (bit n: SM n), enabled.
    single_buffer_inputs: u32,
    /// Logical datagrams' walks resolved for the configuration in `sm_cache` / `fmmu_cache`.
    plans: Vec<logical::Plan>,
    /// When the frame being processed passed the processing unit (0x0910's latch instant),
    /// until a read puts that time into the register.
    system_time_latch: Option<u64>,
    scratch: Vec<u8>,
    sii_busy_shown: bool,
    sync_pulsed: bool,
    /// An enabled output SyncManager triggers the process-data watchdog.
    wd_armed: bool,
    /// Messages waiting for the send mailbox (SM1) to be read, each with the true time from
    /// which the firmware has it ready.
    mbx_queue: std::collections::VecDeque<(u64, Vec<u8>)>,
    /// The last message the firmware put into the send mailbox, and when it will put it there
    /// again for a repeat request the master made (ETG.1000.4 mailbox repeat: the master
    /// toggles SM activate bit 1 after losing a read; the firmware answers by writing the
    /// message again and setting PDI control bit 1 to the same value).
    mbx_last: Vec<u8>,
    mbx_repeat_at: Option<u64>,
    /// The repeat request bit as the firmware last saw it (None: the mailbox not started).
    mbx_request_bit: Option<u8>,
    /// The counter of the last mailbox request taken (0: none since INIT), and how many
    /// requests were dropped as that one written again.
    mbx_in_counter: u8,
    pub mbx_duplicates: u64,
    /// Repeat requests the firmware answered.
    pub mbx_repeats: u64,
    /// Times the application took the slave out of OP with a sync error (0x001A, or 0x002C:
    /// SYNC0 lost).
    pub sync_errors: u64,
    /// How long the firmware takes to answer a mailbox request.
    pub mailbox_response: MailboxResponse,
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
    /// The ESC configuration area passed its checksum at power-on or a later reload: the PDI
    /// runs (DL status bit 0) and process memory is accessible.
    sii_loaded: bool,
    /// Ports 1–3 enabled to latch the next frame they receive (`ReceiveLatch::NextFrame`).
    rx_armed: u8,
    /// Each port's last receive time (local, low 32 bits): the IP core's reverse mode.
    rx_hidden: [u32; 4],
}

impl Esc {
    /// An ESC loaded with an SII image, running `app`; its DC oscillator has `drift_ppb`.
    pub fn new(config: EscConfig, sii: Vec<u8>, app: Box<dyn Application>, drift_ppb: i64, t_ns: u64) -> Self {
        let expected = SiiInfo::from_image(&sii).map(|i| Expected::from_sii(&i)).unwrap_or_default();
        let mut esc = Esc {
            mem: vec![0; config.memory_len()],
            sms: vec![SmState::default(); config.sm_count as usize],
            pdi_deactivated: 0,
            config,
            pending: Vec::with_capacity(64),
            eeprom: Eeprom::new(sii),
            dc: None,
            links: [false; 4],
            closed_wait: [false; 4],
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
            single_buffer_inputs: 0,
            plans: Vec::new(),
            system_time_latch: None,
            scratch: Vec::new(),
            sii_busy_shown: false,
            sync_pulsed: false,
            wd_armed: false,
            mbx_queue: Default::default(),
            mbx_last: Vec::new(),
            mbx_repeat_at: None,
            mbx_request_bit: None,
            mbx_in_counter: 0,
            mbx_duplicates: 0,
            mbx_repeats: 0,
            sync_errors: 0,
            mailbox_response: MailboxResponse::default(),
            al_response_ns: 1_000_000,
            pending_al: None,
            port_generation: 0,
            dl_changed: false,
            al_changed: false,
            irq: 0,
            system_time_unit: false,
            sii_loaded: false,
            rx_armed: 0,
            rx_hidden: [0; 4],
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
        self.closed_wait = [false; 4];
        (self.rx_armed, self.rx_hidden) = (0, [0; 4]);
        self.pending.clear();
        self.sms.iter_mut().for_each(|s| *s = SmState::default());
        self.mbx_queue.clear();
        (self.mbx_last, self.mbx_repeat_at, self.mbx_in_counter, self.mbx_request_bit) = (Vec::new(), None, 0, None);
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
        // The ESC configuration area is taken only when its checksum holds; otherwise the
        // registers it initialises keep their reset values, the PDI stays off (nothing acts on
        // AL control) and process memory is not accessible (Section I, "SII EEPROM errors").
        self.sii_loaded = self.eeprom.config_area_ok();
        self.eeprom.load_status = if self.sii_loaded { 0 } else { SiiControl::CHECKSUM_ERROR | SiiControl::NOT_LOADED };
        if let Some(pdi) = c.pdi_control {
            m[0x0140..0x0142].copy_from_slice(&pdi.to_le_bytes());
        }
        if self.sii_loaded {
            // The alias only at this first load, never at a reload.
            m[0x0012..0x0014].copy_from_slice(&self.eeprom.word(4).to_le_bytes());
            self.take_config_area(0);
        }
        let ctl = self.sii_mode_bits();
        let m = &mut self.mem;
        m[0x0502..0x0504].copy_from_slice(&ctl.to_le_bytes());
        self.dc = match c.dc {
            DcWidth::None => None,
            w => {
                let (drift, local0) = self.dc_init;
                Some(DcUnit::new(w, t_ns, local0, drift))
            }
        };
        self.system_time_unit = self.system_time_unit_on();
        self.reload_sm_fmmu();
        // The DL status comes up from reset (an event); AL status Init is its reset value.
        self.refresh_registers();
        self.al_changed = false;
        self.update_irq();
    }

    /// Words 0–3 of the ESC configuration area into their registers; the bits of 0x0141 in
    /// `keep_0141` keep their values (a reload leaves enhanced link detection, bits 1 and 4–7,
    /// as the first load set them).
    fn take_config_area(&mut self, keep_0141: u8) {
        let e = &self.eeprom;
        let mut pdi = self.config.pdi_control.unwrap_or(e.word(0)).to_le_bytes();
        pdi[1] = (pdi[1] & !keep_0141) | (self.mem[0x0141] & keep_0141);
        let m = &mut self.mem;
        m[0x0140..0x0142].copy_from_slice(&pdi);
        m[0x0150..0x0152].copy_from_slice(&e.word(1).to_le_bytes());
        m[0x0982..0x0984].copy_from_slice(&e.word(2).to_le_bytes());
        m[0x0152..0x0154].copy_from_slice(&e.word(3).to_le_bytes());
    }

    /// An EEPROM reload has finished: the configuration area taken again if its checksum
    /// holds, else bit 11 of 0x0502 and every register as it was (Section I, Table 40).
    fn finish_reload(&mut self) {
        if !self.eeprom.config_area_ok() {
            self.eeprom.load_status |= SiiControl::CHECKSUM_ERROR;
        } else {
            self.eeprom.load_status = 0;
            self.sii_loaded = true;
            self.take_config_area(0xF2);
            self.system_time_unit = self.system_time_unit_on();
        }
        self.refresh_registers();
    }

    /// An ET1100 or ET1200 with neither its SYNC out nor its latch in unit enabled (0x0141
    /// bits 2–3, from SII word 0) answers its receive times only: the real EL1004 and EL2828
    /// (ET1200, 0x0141 = 0x01) and EK1914 (ET1100) give WKC 0 for 0x0910–0x09FF, the EK1100
    /// (ET1100, 0x0D) counts.
    fn system_time_unit_on(&self) -> bool {
        !matches!(self.config.esc_type, 0x11 | 0x12) || self.mem[0x0141] & 0x0C != 0
    }

    /// Decodes the SyncManager and FMMU registers after they were written.
    fn reload_sm_fmmu(&mut self) {
        self.sm_cache = (0..self.config.sm_count)
            .map(|n| {
                let a = addr::sm(n) as usize;
                SyncManager::parse(&self.mem[a..a + 8]).unwrap_or_default()
            })
            .collect();
        self.single_buffer_inputs = (2..self.config.sm_count)
            .filter(|&n| {
                let s = self.sm(n);
                s.enabled() && s.is_mailbox() && !s.ecat_writes() && s.length > 0
            })
            .fold(0, |m, n| m | 1 << n);
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
        self.plans.clear();
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

    /// Word `word` of the EEPROM (ETG.2010's SII), as the ESC would read it.
    pub fn sii_word(&self, word: usize) -> u16 {
        self.eeprom.word(word)
    }

    /// Whether the ESC configuration area passed its checksum (DL status bit 0).
    pub fn sii_loaded(&self) -> bool {
        self.sii_loaded
    }

    /// Whether the DC unit's system time (0x0910–0x09FF) exists: a clock a master can
    /// synchronise, not only receive times.
    #[inline]
    pub fn has_system_time(&self) -> bool {
        self.dc.is_some() && self.system_time_unit
    }

    #[inline]
    pub fn station_address(&self) -> u16 {
        u16::from_le_bytes([self.mem[0x10], self.mem[0x11]])
    }

    pub fn set_link(&mut self, port: u8, link: bool) {
        let p = (port & 3) as usize;
        // Under auto-close a link that comes back leaves the port closed (closed wait); one
        // that goes closes it anyway.
        if link && !self.links[p] {
            self.closed_wait[p] = self.loop_control(port) == 1;
        } else if !link {
            self.closed_wait[p] = false;
        }
        self.links[p] = link;
        self.port_generation = self.port_generation.wrapping_add(1);
        self.refresh_registers();
    }

    /// Loop control 0x0101 for `port`: 00 auto, 01 auto-close, 10 open, 11 closed.
    fn loop_control(&self, port: u8) -> u8 {
        (self.mem[0x0101] >> (2 * (port & 3))) & 3
    }

    /// Whether a frame leaves through `port` (link up and loop open), or loops back.
    pub fn port_open(&self, port: u8) -> bool {
        let p = (port & 3) as usize;
        if !self.config.has_port(port) || !self.links[p] {
            return false;
        }
        match self.loop_control(port) {
            3 => false,
            1 => !self.closed_wait[p],
            _ => true,
        }
    }

    /// An auto-close port whose link came back and that stays closed until opened: a frame
    /// that arrives at it is taken in by nothing, but opens it ([`Esc::frame_arrived_closed`]).
    pub fn port_closed_waiting(&self, port: u8) -> bool {
        self.closed_wait[(port & 3) as usize] && self.links[(port & 3) as usize]
    }

    /// A valid frame arrived at an auto-close port waiting closed: it opens once the frame's
    /// CRC is in (the frame itself goes no further).
    pub fn frame_arrived_closed(&mut self, port: u8) {
        let p = (port & 3) as usize;
        if self.closed_wait[p] {
            self.closed_wait[p] = false;
            self.port_generation = self.port_generation.wrapping_add(1);
            self.refresh_registers();
        }
    }

    /// Loop control 0x0101 closes `port` whatever its link (11).
    pub fn port_forced_closed(&self, port: u8) -> bool {
        (self.mem[0x0101] >> (2 * (port & 3))) & 3 == 3
    }

    /// Port 0 closed for want of a link under automatic loop control (0x0101 00 or 01): the
    /// case in which the ESC marks and destroys circulating frames (esc-spec §1.6).
    pub fn port0_auto_closed(&self) -> bool {
        !self.links[0] && self.mem[0x0101] & 3 <= 1
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
    #[inline]
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
                    if let Some(code) = self.app.take_fault() {
                        self.leave_op(code);
                    }
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
            self.finish_reload();
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

    /// The SII interface's read-only mode bits (0x0502): read size, address algorithm and
    /// EEPROM emulation, which a command written leaves as they are (the AKD's IP core reads
    /// 0x0020 after SOEM's reads: `soem-sdinfo-akd.pcapng` frame 51).
    pub(super) fn sii_mode_bits(&self) -> u16 {
        let c = &self.config;
        let size_kbit = self.eeprom.word(0x3E) as u32 + 1;
        (if c.sii_read_8 { SiiControl::READ_8_BYTES } else { 0 })
            | if size_kbit > 16 { SiiControl::TWO_BYTE_ADDRESS } else { 0 }
            | if c.eeprom_emulation { SiiControl::EMULATION } else { 0 }
    }

    #[inline]
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
        if self.now_ns.saturating_sub(self.wd_last_trigger_ns) <= wd {
            return;
        }
        if self.device_emulation() {
            // No PDI writes AL status under device emulation: the ESC only resets its digital
            // outputs, once per expiry, and stays in OP (datasheet I, process data watchdog).
            if self.mem[0x0440] != 0 {
                self.mem[0x0440] = 0;
                self.mem[0x0442] = self.mem[0x0442].saturating_add(1);
                self.app.watchdog_expired();
            }
            return;
        }
        self.mem[0x0440] = 0;
        self.mem[0x0442] = self.mem[0x0442].saturating_add(1);
        self.leave_op(AlStatusCode::SM_WATCHDOG);
    }

    /// A local error in OP: SAFEOP with the error bit and `code` (esc-spec §5.1). A firmware
    /// (no device emulation) also deactivates its output SyncManager, as the Slave Stack Code
    /// does, so that the master sees the error in its working counter.
    fn leave_op(&mut self, code: AlStatusCode) {
        if self.al.state != AlState::Op {
            return;
        }
        if !self.device_emulation() {
            self.pdi_deactivate_outputs(true);
        }
        self.sync_errors += matches!(code, AlStatusCode::SYNC_ERROR | AlStatusCode::FATAL_SYNC_ERROR) as u64;
        self.al.fail(AlState::SafeOp, code);
        self.al_changes += 1;
        let mut pdi = Pdi { mem: &mut self.mem, now_ns: self.now_ns };
        self.app.state_changed(&mut pdi, AlState::SafeOp);
        self.refresh_registers();
    }

    /// SyncManager deactivation by the PDI (0x0807 bit 0; datasheet I §8.7) of the buffered
    /// output SyncManagers: their buffers are read/write protected, accesses to them do not
    /// count in the working counter, and their state starts afresh. Undone when the master
    /// acknowledges the error.
    pub(super) fn pdi_deactivate_outputs(&mut self, on: bool) {
        for n in 0..self.config.sm_count.min(32) {
            let a = addr::sm(n) as usize + 7;
            if on {
                let s = self.sm(n);
                if !s.enabled() || s.is_mailbox() || !s.ecat_writes() {
                    continue;
                }
                self.mem[a] |= 1;
                self.pdi_deactivated |= 1 << n;
                if let Some(st) = self.sms.get_mut(n as usize) {
                    let staging = std::mem::take(&mut st.staging);
                    *st = SmState { staging, ..SmState::default() };
                }
            } else if self.pdi_deactivated & (1 << n) != 0 {
                // Whatever the master did to the SyncManager meanwhile (disabled it in INIT).
                self.mem[a] &= !1;
            }
        }
        if !on {
            self.pdi_deactivated = 0;
        }
        self.reload_sm_fmmu();
    }

    #[inline]
    fn sm(&self, n: u8) -> SyncManager {
        self.sm_cache.get(n as usize).copied().unwrap_or_default()
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
