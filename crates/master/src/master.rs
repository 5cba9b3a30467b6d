//! Bring-up: finding the slaves, reading what they are, configuring mailboxes and process data,
//! and walking them through the AL states.
use ferrocat_wire::register::{AlState, AlStatus, AlStatusCode, DlStatus, Fmmu, PortDescriptor, SyncManager};
use ferrocat_wire::sii::{SiiHeader, SiiInfo, SmEntry, CATEGORY_HEADER_LEN, HEADER_LEN as SII_HEADER};
use ferrocat_wire::{Address, Command};

use crate::engine::{Engine, Pdu, SlaveTag};
use crate::error::{code_text, MasterError, Result};
use crate::io::Io;
use crate::slave::{MailboxConfig, Mapped, Slave};

/// First station address; slave k gets `STATION_BASE + k` (SOEM's convention).
pub const STATION_BASE: u16 = 0x1001;

/// Something that happened to a slave during operation, reported once.
#[derive(Debug, Clone, PartialEq, Eq)]
pub enum MasterEvent {
    /// The slave left OP (its AL status and code).
    LeftOp { position: u16, name: String, status: AlStatus, code: AlStatusCode },
    /// The slave stopped answering (link lost or powered off).
    Lost { position: u16, name: String },
    /// The slave is back in OP.
    Recovered { position: u16, name: String },
    /// A CoE emergency.
    Emergency { position: u16, name: String, error_code: u16, error_register: u8, data: [u8; 5] },
}

impl std::fmt::Display for MasterEvent {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        match self {
            MasterEvent::LeftOp { position, name, status, code } => {
                let st = status.state().map(|s| s.name()).unwrap_or("?");
                write!(
                    f,
                    "slave {position} ({name}) left OP: now {st}{}{}",
                    if status.error() { " with an error" } else { "" },
                    code_text(*code)
                )
            }
            MasterEvent::Lost { position, name } => write!(f, "slave {position} ({name}) is not answering"),
            MasterEvent::Recovered { position, name } => write!(f, "slave {position} ({name}) is back in OP"),
            MasterEvent::Emergency { position, name, error_code, error_register, data } => {
                write!(f, "slave {position} ({name}): emergency {error_code:#06x}, error register {error_register:#04x}, data {data:02x?}")
            }
        }
    }
}

#[derive(Debug)]
pub struct Master<I: Io> {
    pub engine: Engine<I>,
    pub slaves: Vec<Slave>,
    /// The process image: all outputs, then all inputs.
    pub image: Vec<u8>,
    pub out_bytes: u32,
    pub in_bytes: u32,
    /// The LRW working counter a complete cycle gives: 2 per slave with outputs, 1 per slave
    /// with inputs.
    pub expected_wkc: u16,
    pub events: Vec<MasterEvent>,
    /// How long a state transition may take before it is an error.
    pub state_timeout_ns: u64,
    /// How long an SDO may take.
    pub mailbox_timeout_ns: u64,
    pub(crate) cyc: crate::process::CycleState,
    /// How long a cyclic frame may take before it counts as lost.
    pub cyclic_timeout_ns: u64,
    /// Check the slaves after a cycle with a short working counter.
    pub supervise_on_wkc: bool,
    /// Device descriptions from ESI files: the PDO mapping of slaves whose CoE and SII do not
    /// give one (vendor, device).
    pub esi: Vec<(u32, ferrocat_esi::Device)>,
    /// Station address of the reference clock when the cycle distributes it (FRMW of 0x0910).
    pub dc_reference: Option<u16>,
    /// The reference clock's system time as the last cycle's FRMW read it.
    pub dc_time: u64,
    pub(crate) frmw: [u8; 8],
    /// Master clock → DC system time (ns since 2000), fixed at first use.
    pub(crate) epoch_offset_ns: Option<u64>,
    /// What a closed port's loop-back adds to a frame's way, for the delay computation (0:
    /// assume nothing, as SOEM, IgH and ethercrab do). See `measure_delays`.
    pub closed_port_loop_ns: u32,
}

impl<I: Io> Master<I> {
    pub fn new(io: I) -> Self {
        Master {
            engine: Engine::new(io),
            slaves: Vec::new(),
            image: Vec::new(),
            out_bytes: 0,
            in_bytes: 0,
            expected_wkc: 0,
            events: Vec::new(),
            state_timeout_ns: 10_000_000_000,
            mailbox_timeout_ns: 2_000_000_000,
            cyc: Default::default(),
            cyclic_timeout_ns: 1_000_000,
            supervise_on_wkc: true,
            esi: Vec::new(),
            dc_reference: None,
            dc_time: 0,
            frmw: [0; 8],
            epoch_offset_ns: None,
            closed_port_loop_ns: 0,
        }
    }

    pub fn slave(&self, position: u16) -> Result<&Slave> {
        self.slaves
            .get(position as usize)
            .ok_or_else(|| MasterError::Config(format!("no slave at position {position}")))
    }

    /// Finds the slaves and reads everything about them: count, station addresses, identity
    /// and the whole SII, ESC features, DL status and topology, DC receive times and delays.
    pub fn scan(&mut self) -> Result<()> {
        // Reset: every slave to INIT, DL control default, no FMMUs/SMs (as SOEM and IgH do).
        let mut buf = [0u8; 2];
        let count = self.engine.one(Command::BRD, Address::Device { adp: 0, ado: 0 }, &mut buf)?;
        if count == 0 {
            return Err(MasterError::NoSlaves);
        }
        self.engine.one(Command::BWR, Address::Device { adp: 0, ado: 0x0120 }, &mut [0x11, 0])?;
        self.engine.one(Command::BWR, Address::Device { adp: 0, ado: 0x0600 }, &mut [0u8; 256])?;
        self.engine.one(Command::BWR, Address::Device { adp: 0, ado: 0x0800 }, &mut [0u8; 128])?;
        self.slaves.clear();
        for pos in 0..count {
            let station = STATION_BASE + pos;
            self.engine.expect(Command::APWR, Address::position(pos, 0x0010), &mut station.to_le_bytes(), 1)?;
        }
        let stations: Vec<u16> = (0..count).map(|p| STATION_BASE + p).collect();
        let images = self.read_all_sii(&stations)?;
        for (pos, img) in images.into_iter().enumerate() {
            let slave = self.read_slave(pos as u16, stations[pos], img)?;
            self.slaves.push(slave);
        }
        self.engine.directory = self
            .slaves
            .iter()
            .map(|s| SlaveTag { position: s.position, station: s.station, alias: s.alias, name: s.name.clone() })
            .collect();
        self.wait_state_all(AlState::Init)?;
        self.topology();
        self.measure_delays()?;
        Ok(())
    }

    pub(crate) fn fprd(&mut self, station: u16, ado: u16, out: &mut [u8]) -> Result<()> {
        self.engine.expect(Command::FPRD, Address::Device { adp: station, ado }, out, 1)
    }

    pub(crate) fn fpwr(&mut self, station: u16, ado: u16, data: &[u8]) -> Result<()> {
        let mut d = data.to_vec();
        self.engine.expect(Command::FPWR, Address::Device { adp: station, ado }, &mut d, 1)
    }

    fn read_slave(&mut self, pos: u16, station: u16, sii_bytes: Vec<u8>) -> Result<Slave> {
        let (mut id, mut alias, mut dl) = ([0u8; 10], [0u8; 2], [0u8; 2]);
        let mut p = [
            Pdu::new(Command::FPRD, Address::Device { adp: station, ado: 0x0000 }, &mut id),
            Pdu::new(Command::FPRD, Address::Device { adp: station, ado: 0x0012 }, &mut alias),
            Pdu::new(Command::FPRD, Address::Device { adp: station, ado: 0x0110 }, &mut dl),
        ];
        self.engine.transact(&mut p)?;
        if p.iter().any(|x| x.wkc != 1) {
            return Err(MasterError::Wkc {
                what: format!("identity of slave {pos}"),
                expected: 1,
                got: 0,
                slaves: format!(" (station {station:#06x})"),
            });
        }
        let sii = SiiInfo::from_image(&sii_bytes).map_err(|e| MasterError::slave(pos, "?", format!("SII: {e}")))?;
        let h = sii.header;
        let features = u16::from_le_bytes([id[8], id[9]]);
        let dl_status = DlStatus(u16::from_le_bytes(dl));
        let mailbox = (h.mailbox_rx_size > 0 && h.mailbox_tx_size > 0).then_some(MailboxConfig {
            out: (h.mailbox_rx_offset, h.mailbox_rx_size),
            inp: (h.mailbox_tx_offset, h.mailbox_tx_size),
            protocols: h.mailbox_protocols,
        });
        Ok(Slave {
            position: pos,
            station,
            alias: u16::from_le_bytes(alias),
            name: sii.string(1).unwrap_or_else(|| format!("{:#010x}", h.product_code)),
            description: sii.name().unwrap_or_default(),
            vendor_id: h.vendor_id,
            product_code: h.product_code,
            revision: h.revision,
            serial: h.serial,
            esc_type: id[0],
            fmmu_count: id[4],
            sm_count: id[5],
            features,
            dl_status,
            active_ports: [0, 1, 2, 3].map(|p| dl_status.port_active(p)),
            port_descriptor: id[7],
            entry_port: 0,
            parent: None,
            parent_port: 0,
            has_dc: features & 0x04 != 0,
            has_system_time: features & 0x04 != 0,
            dc_64bit: features & 0x08 != 0,
            receive_times: [0; 4],
            receive_time_epu: 0,
            delay_ns: 0,
            mailbox,
            mbx_counter: 0,
            outputs: Vec::new(),
            inputs: Vec::new(),
            out_sm: None,
            in_sm: None,
            out_area: (0, 0),
            in_area: (0, 0),
            state: AlState::Init,
            health: Default::default(),
            assignment: [None, None],
            sii,
        })
    }

    /// Reads every slave's whole SII at once: each read command goes to all slaves in one frame,
    /// each status-and-data read in another, so the time does not grow with the slave count.
    fn read_all_sii(&mut self, stations: &[u16]) -> Result<Vec<Vec<u8>>> {
        let n = stations.len();
        self.engine.one(Command::BWR, Address::Device { adp: 0, ado: 0x0500 }, &mut [0])?;
        let mut imgs: Vec<Vec<u8>> = vec![Vec::with_capacity(2048); n];
        let mut done = vec![false; n];
        let mut ctl = vec![[0u8; 2]; n];
        {
            let mut p: Vec<Pdu<'_>> = stations
                .iter()
                .zip(ctl.iter_mut())
                .map(|(&st, c)| Pdu::new(Command::FPRD, Address::Device { adp: st, ado: 0x0502 }, c))
                .collect();
            self.engine.transact(&mut p)?;
        }
        let eight: Vec<bool> = ctl.iter().map(|c| u16::from_le_bytes(*c) & 0x0040 != 0).collect();
        let deadline = self.engine.io.now_ns() + 10_000_000_000;
        // The shortest read seen so far, command to data: real EEPROMs take ≈ 0.7 ms a read
        // (docs/esc-model.md), so after the first round the master sleeps most of that before
        // it polls, rather than polling every round trip (≈ 70 frames a read on a short line).
        let mut read_ns: Option<u64> = None;
        while done.iter().any(|d| !d) {
            let active: Vec<usize> = (0..n).filter(|&k| !done[k]).collect();
            let mut cmds: Vec<[u8; 6]> = active
                .iter()
                .map(|&k| {
                    let mut c = [0x00, 0x01, 0, 0, 0, 0];
                    c[2..6].copy_from_slice(&((imgs[k].len() / 2) as u32).to_le_bytes());
                    c
                })
                .collect();
            {
                let mut p: Vec<Pdu<'_>> = active
                    .iter()
                    .zip(cmds.iter_mut())
                    .map(|(&k, c)| Pdu::new(Command::FPWR, Address::Device { adp: stations[k], ado: 0x0502 }, c))
                    .collect();
                self.engine.transact(&mut p)?;
            }
            let commanded = self.engine.io.now_ns();
            if let Some(ns) = read_ns {
                self.engine.io.sleep_until(commanded + ns * 7 / 8);
            }
            // Status, address and data in one read; poll again only those still busy.
            let mut pending = active.clone();
            while !pending.is_empty() {
                let mut regs: Vec<[u8; 14]> = vec![[0; 14]; pending.len()];
                {
                    let mut p: Vec<Pdu<'_>> = pending
                        .iter()
                        .zip(regs.iter_mut())
                        .map(|(&k, r)| Pdu::new(Command::FPRD, Address::Device { adp: stations[k], ado: 0x0502 }, r))
                        .collect();
                    self.engine.transact(&mut p)?;
                }
                let mut still = Vec::new();
                for (&k, r) in pending.iter().zip(&regs) {
                    let c = u16::from_le_bytes([r[0], r[1]]);
                    if c & 0x8000 != 0 {
                        still.push(k);
                        continue;
                    }
                    if c & 0x2000 != 0 {
                        return Err(MasterError::Config(format!("slave {k}: SII read not acknowledged")));
                    }
                    imgs[k].extend_from_slice(&r[6..if eight[k] { 14 } else { 10 }]);
                    done[k] = sii_complete(&imgs[k]);
                }
                if still.len() < pending.len() {
                    let took = self.engine.io.now_ns().saturating_sub(commanded);
                    read_ns = Some(read_ns.map_or(took, |r| r.min(took)));
                }
                pending = still;
                if self.engine.io.now_ns() > deadline {
                    return Err(MasterError::Config("SII reads stay busy".into()));
                }
            }
        }
        for img in &mut imgs {
            let len = sii_used_len(img);
            img.truncate(len);
        }
        Ok(imgs)
    }

    /// Reads the SII through the EEPROM interface: the header, then category by category up to
    /// the end marker (or the EEPROM's size).
    fn read_sii(&mut self, station: u16) -> Result<Vec<u8>> {
        // Take the EEPROM for the EtherCAT side.
        self.fpwr(station, 0x0500, &[0])?;
        let mut img = Vec::with_capacity(2048);
        let mut word = 0u32;
        let read = |m: &mut Self, img: &mut Vec<u8>, word: &mut u32| -> Result<()> {
            let chunk = m.sii_read(station, *word)?;
            img.extend_from_slice(&chunk);
            *word += (chunk.len() / 2) as u32;
            Ok(())
        };
        while img.len() < SII_HEADER {
            read(self, &mut img, &mut word)?;
        }
        let header = SiiHeader::parse(&img)?;
        let max = header.eeprom_size_bytes().clamp(SII_HEADER, 65536);
        let mut at = SII_HEADER;
        loop {
            while img.len() < at + CATEGORY_HEADER_LEN && img.len() < max {
                read(self, &mut img, &mut word)?;
            }
            if img.len() < at + CATEGORY_HEADER_LEN {
                break;
            }
            let kind = u16::from_le_bytes([img[at], img[at + 1]]);
            if kind == 0xFFFF {
                break;
            }
            let len = u16::from_le_bytes([img[at + 2], img[at + 3]]) as usize * 2;
            at += CATEGORY_HEADER_LEN + len;
            if at >= max {
                break;
            }
        }
        img.truncate(max.min(img.len()));
        if img.len() < at.min(max) + 2 {
            img.resize(at.min(max) + 2, 0xFF);
        }
        Ok(img)
    }

    /// 4 or 8 bytes of the SII at `word`.
    fn sii_read(&mut self, station: u16, word: u32) -> Result<Vec<u8>> {
        let mut ctl = [0u8; 2];
        self.fprd(station, 0x0502, &mut ctl)?;
        let eight = u16::from_le_bytes(ctl) & 0x0040 != 0;
        let mut cmd = [0x00, 0x01, 0, 0, 0, 0];
        cmd[2..6].copy_from_slice(&word.to_le_bytes());
        self.fpwr(station, 0x0502, &cmd)?;
        let deadline = self.engine.io.now_ns() + 100_000_000;
        loop {
            self.fprd(station, 0x0502, &mut ctl)?;
            let v = u16::from_le_bytes(ctl);
            if v & 0x8000 == 0 {
                if v & 0x2000 != 0 {
                    return Err(MasterError::Config(format!(
                        "slave {station:#06x}: SII read of word {word:#x} not acknowledged"
                    )));
                }
                break;
            }
            if self.engine.io.now_ns() > deadline {
                return Err(MasterError::Config(format!("slave {station:#06x}: SII stays busy")));
            }
        }
        let mut data = vec![0u8; if eight { 8 } else { 4 }];
        self.fprd(station, 0x0508, &mut data)?;
        Ok(data)
    }

    /// Programs the slave's EEPROM with `image`, word by word where it differs, and reloads it.
    /// Returns the number of words written.
    pub fn sii_write(&mut self, position: u16, image: &[u8]) -> Result<usize> {
        // An ESC does not load a header whose CRC is wrong: refuse to brick the slave.
        if image.len() < 16 {
            return Err(MasterError::Config(format!(
                "SII image of {} bytes: shorter than its 16-byte header",
                image.len()
            )));
        }
        let crc = ferrocat_wire::sii::header_crc(image);
        if image[14] != crc {
            return Err(MasterError::Config(format!(
                "SII image: header CRC at byte 14 is {:#04x}, bytes 0–13 give {crc:#04x}; an ESC would not load it",
                image[14]
            )));
        }
        let (st, current) = {
            let s = self.slave(position)?;
            (s.station, s.sii.to_image())
        };
        self.fpwr(st, 0x0500, &[0])?;
        let mut written = 0;
        for (w, pair) in image.chunks(2).enumerate() {
            let v = u16::from_le_bytes([pair[0], *pair.get(1).unwrap_or(&0xFF)]);
            let old = current.get(2 * w..2 * w + 2).map(|b| u16::from_le_bytes([b[0], b[1]]));
            if old == Some(v) {
                continue;
            }
            // The data first, then "write" with write enable and the word address.
            self.fpwr(st, 0x0508, &v.to_le_bytes())?;
            let mut cmd = [0u8; 6];
            cmd[0..2].copy_from_slice(&0x0201u16.to_le_bytes());
            cmd[2..6].copy_from_slice(&(w as u32).to_le_bytes());
            self.fpwr(st, 0x0502, &cmd)?;
            let deadline = self.engine.io.now_ns() + 100_000_000;
            loop {
                let mut ctl = [0u8; 2];
                self.fprd(st, 0x0502, &mut ctl)?;
                let c = u16::from_le_bytes(ctl);
                if c & 0x8000 == 0 {
                    if c & 0x6000 != 0 {
                        let name = self.slaves[position as usize].name.clone();
                        return Err(MasterError::slave(
                            position,
                            &name,
                            format!("EEPROM write of word {w:#x} failed (status {c:#06x})"),
                        ));
                    }
                    break;
                }
                if self.engine.io.now_ns() > deadline {
                    return Err(MasterError::Config(format!("slave {position}: EEPROM stays busy")));
                }
                let now = self.engine.io.now_ns();
                self.engine.io.sleep_until(now + 500_000);
            }
            written += 1;
        }
        let sii = self.read_sii(st)?;
        if let Ok(info) = SiiInfo::from_image(&sii) {
            self.slaves[position as usize].sii = info;
        }
        Ok(written)
    }

    /// Parents and ports: parsed from the processing order, the active ports, entry ports and
    /// receive times where known (crate::topology); counting ports as SOEM does where no tree
    /// fits or the segment is too long to parse.
    fn topology(&mut self) {
        let view = self.port_views();
        if view.len() <= 1024 {
            if let Some(links) = crate::topology::infer(&view) {
                for (s, l) in self.slaves.iter_mut().zip(links) {
                    s.parent = l.map(|l| l.parent as u16);
                    s.parent_port = l.map_or(0, |l| l.port);
                }
                return;
            }
        }
        self.count_ports_topology();
    }

    /// SOEM's inference: every entry on port 0, the processing order a pre-order walk.
    fn count_ports_topology(&mut self) {
        let count = self.slaves.len();
        let topo: Vec<i32> = self.slaves.iter().map(|s| s.active_ports.iter().filter(|&&a| a).count() as i32).collect();
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
                    self.slaves[i].parent = Some(j as u16);
                    break;
                }
                j -= 1;
            }
        }
        // A child hangs on its parent's next active port, in processing order after the entry.
        for p in 0..count {
            let children: Vec<usize> = (0..count).filter(|&c| self.slaves[c].parent == Some(p as u16)).collect();
            let mut port = self.slaves[p].entry_port;
            for c in children {
                for _ in 0..4 {
                    port = [3, 2, 0, 1][port as usize];
                    if self.slaves[p].active_ports[port as usize] && port != self.slaves[p].entry_port {
                        break;
                    }
                }
                self.slaves[c].parent_port = port;
            }
        }
    }

    /// Latches the receive times (BWR 0x0900) and computes every DC slave's propagation delay
    /// from the reference (the first DC slave) for any tree: a child's hop is half of its
    /// parent's round trip through that port minus the child's own loop; slaves behind a later
    /// port also wait for the earlier branches (esc-spec §3.6).
    pub fn measure_delays(&mut self) -> Result<()> {
        self.latch_and_measure_delays().map(|_| ())
    }

    /// As [`Master::measure_delays`]; returns the stamps of the latching frame (without the
    /// reference's readings) when there are DC slaves.
    pub(crate) fn latch_and_measure_delays(&mut self) -> Result<Option<crate::sync::Sample>> {
        if !self.slaves.iter().any(|s| s.has_dc) {
            return Ok(None);
        }
        // Sent once per try, so that the stamps are of the frame that latched.
        let mut tries = self.engine.retries.saturating_add(1);
        let mut stamps = loop {
            let built_ns = self.master_system_time();
            let mut latch = [0u8; 4];
            let mut pdus = [Pdu::new(Command::BWR, Address::Device { adp: 0, ado: 0x0900 }, &mut latch)];
            let bytes = crate::dc::frame_bytes(&pdus);
            tries -= 1;
            match self.engine.transact_once(&mut pdus, self.engine.timeout_ns) {
                Ok(()) => break self.stamped_sample(&crate::dc::SyncState::default(), built_ns, bytes),
                Err(MasterError::Timeout { .. }) if tries > 0 => continue,
                Err(e) => return Err(e),
            }
        };
        for k in 0..self.slaves.len() {
            if !self.slaves[k].has_dc {
                continue;
            }
            let st = self.slaves[k].station;
            let mut t = [0u8; 16];
            self.fprd(st, 0x0900, &mut t)?;
            let mut epu = [0u8; 8];
            let answered = self.engine.one(Command::FPRD, Address::Device { adp: st, ado: 0x0918 }, &mut epu)? == 1;
            let s = &mut self.slaves[k];
            for p in 0..4 {
                s.receive_times[p] = u32::from_le_bytes(t[4 * p..4 * p + 4].try_into().unwrap());
            }
            // Without a system time (WKC 0) the processing unit's receive time is port 0's, as
            // 0x0918's low word is where it exists (esc-spec §3.3).
            s.has_system_time = answered;
            s.receive_time_epu = if answered { u64::from_le_bytes(epu) } else { s.receive_times[0] as u64 };
            // The entry port saw the frame first (reversed cabling puts it elsewhere).
            let active: Vec<usize> = (0..4).filter(|&p| s.active_ports[p]).collect();
            if let Some(&e) = active.iter().min_by_key(|&&p| s.receive_times[p].wrapping_sub(s.receive_times[0]) as i32)
            {
                s.entry_port = e as u8;
            }
        }
        self.topology();
        let view = self.port_views();
        // When the frame reaches each DC slave's entry port, relative to the first DC slave on
        // its way; parents before children, whatever the processing order.
        let mut entry_at: Vec<Option<i64>> = vec![None; self.slaves.len()];
        for k in self.tree_order() {
            if !self.slaves[k].has_dc {
                continue;
            }
            // Behind non-DC slaves (which latch no receive times), measure from the nearest DC
            // ancestor: the round trip it sees on the port toward them holds their hops both ways
            // and this slave's own loop.
            let (mut via, mut port) = (self.slaves[k].parent.map(|p| p as usize), self.slaves[k].parent_port);
            // Closed ports the frame loops through on its way out, less those on its way back,
            // that no latch separates: the child's after its last event, each non-DC slave's on
            // the way (one loop-back each, `closed_port_loop_ns`).
            let mut loops = -view[k].loops_after_last_event();
            while let Some(v) = via.filter(|&v| !self.slaves[v].has_dc) {
                loops += view[v].loops_between(view[v].before(port), port)
                    - view[v].loops_between(port, view[v].after(port));
                port = self.slaves[v].parent_port;
                via = self.slaves[v].parent.map(|p| p as usize);
            }
            entry_at[k] = Some(match via.and_then(|v| Some((v, entry_at[v]?))) {
                Some((v, at)) => {
                    let before = view[v].before(port);
                    loops += view[v].loops_between(before, port);
                    // A child's hop is half of what the frame spent behind the port, less the
                    // child's own loop (esc-spec §3.6), corrected for loop-backs that lengthen
                    // one way only (the return through a closed port behind a child's last
                    // latch: half of it would otherwise count as delay).
                    let behind = view[v].between(before, port).unwrap_or(0) - view[k].span_ns().unwrap_or(0);
                    let hop = (behind + loops * self.closed_port_loop_ns as i64) / 2;
                    at + view[v].between(view[v].entry_port, before).unwrap_or(0) + hop
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
                let since_entry = (s.receive_time_epu as u32).wrapping_sub(s.receive_times[s.entry_port as usize]);
                Some((*at)? + since_entry as i32 as i64)
            })
            .collect();
        let reference = self.slaves.iter().position(|s| s.has_system_time);
        let at_reference = reference.and_then(|r| epu_at[r]).unwrap_or(0);
        for (s, at) in self.slaves.iter_mut().zip(epu_at) {
            if s.has_dc {
                s.delay_ns = at.map_or(0, |t| t - at_reference).clamp(0, u32::MAX as i64) as u32;
            }
        }
        // The first DC slave is the reference (DC initialisation makes it so).
        if let Some(r) = reference {
            stamps.loop_ns = self.loop_ns_of(r);
        }
        Ok(Some(stamps))
    }

    fn port_views(&self) -> Vec<crate::topology::PortView> {
        self.slaves
            .iter()
            .map(|s| crate::topology::PortView {
                entry_port: s.entry_port,
                active_ports: s.active_ports,
                present_ports: [0, 1, 2, 3].map(|p| PortDescriptor(s.port_descriptor).can_link(p)),
                receive_times: s.has_dc.then_some(s.receive_times),
                epu_time: s.has_dc.then_some(s.receive_time_epu as u32),
            })
            .collect()
    }

    /// Positions with every parent before its children (breadth first from the first slave).
    fn tree_order(&self) -> Vec<usize> {
        let n = self.slaves.len();
        let mut order: Vec<usize> = (0..n).filter(|&k| self.slaves[k].parent.is_none()).collect();
        let mut seen = vec![false; n];
        let mut i = 0;
        while i < order.len() {
            let p = order[i];
            seen[p] = true;
            for (c, s) in self.slaves.iter().enumerate() {
                if !seen[c] && s.parent == Some(p as u16) {
                    seen[c] = true;
                    order.push(c);
                }
            }
            i += 1;
        }
        order
    }

    /// Requests `state` from every slave and waits until all are there.
    pub fn request_state_all(&mut self, state: AlState) -> Result<()> {
        self.engine.one(Command::BWR, Address::Device { adp: 0, ado: 0x0120 }, &mut [state as u8, 0])?;
        self.wait_state_all(state)
    }

    /// Requests `state` from one slave and waits for it.
    pub fn request_state(&mut self, position: u16, state: AlState) -> Result<()> {
        let st = self.slave(position)?.station;
        self.fpwr(st, 0x0120, &[state as u8, 0])?;
        self.wait_state(position, state)
    }

    /// Lets a slave be addressed by its configured station alias (0x0012, from its EEPROM) as
    /// well as by its station address (DL control bit 24), and checks that it answers to it.
    pub fn enable_alias(&mut self, position: u16) -> Result<u16> {
        let (st, alias, name) = {
            let s = self.slave(position)?;
            (s.station, s.alias, s.name.clone())
        };
        if alias == 0 {
            return Err(MasterError::slave(position, &name, "has no station alias"));
        }
        if self
            .slaves
            .iter()
            .any(|s| s.position != position && (s.alias == alias && s.alias != 0 || s.station == alias))
        {
            return Err(MasterError::slave(
                position,
                &name,
                format!("alias {alias:#06x} is not unique on this segment"),
            ));
        }
        let mut dl = [0u8; 4];
        self.fprd(st, 0x0100, &mut dl)?;
        dl[3] |= 0x01;
        self.fpwr(st, 0x0100, &dl)?;
        let mut check = [0u8; 2];
        self.engine.expect(Command::FPRD, Address::Device { adp: alias, ado: 0x0010 }, &mut check, 1)?;
        Ok(alias)
    }

    /// Requests `state` from a group of slaves at once and waits until all of them are there.
    pub fn request_state_group(&mut self, positions: &[u16], state: AlState) -> Result<()> {
        let mut bufs: Vec<[u8; 2]> = vec![[state as u8, 0]; positions.len()];
        let stations: Vec<u16> = positions.iter().map(|&p| self.slave(p).map(|s| s.station)).collect::<Result<_>>()?;
        {
            let mut p: Vec<Pdu<'_>> = stations
                .iter()
                .zip(bufs.iter_mut())
                .map(|(&st, b)| Pdu::new(Command::FPWR, Address::Device { adp: st, ado: 0x0120 }, b))
                .collect();
            self.engine.transact(&mut p)?;
        }
        for &p in positions {
            self.wait_state(p, state)?;
        }
        Ok(())
    }

    fn wait_state_all(&mut self, state: AlState) -> Result<()> {
        for k in 0..self.slaves.len() as u16 {
            self.wait_state(k, state)?;
        }
        Ok(())
    }

    /// Polls AL status until `state` or an error; an error is acknowledged and reported by name.
    pub fn wait_state(&mut self, position: u16, state: AlState) -> Result<()> {
        let (st, name) = {
            let s = self.slave(position)?;
            (s.station, s.name.clone())
        };
        let deadline = self.engine.io.now_ns() + self.state_timeout_ns;
        loop {
            let mut d = [0u8; 6];
            self.fprd(st, 0x0130, &mut d)?;
            let status = AlStatus(u16::from_le_bytes([d[0], d[1]]));
            let code = AlStatusCode(u16::from_le_bytes([d[4], d[5]]));
            if status.state() == Some(state) && !status.error() {
                self.slaves[position as usize].state = state;
                return Ok(());
            }
            if status.error() || self.engine.io.now_ns() > deadline {
                let reached = status.state().map(|s| s.name()).unwrap_or("an unknown state");
                if status.error() {
                    // Acknowledge, so that the slave accepts requests again.
                    let ack = status.state_bits() as u16 | AlStatus::ERROR;
                    let _ = self.engine.one(
                        Command::FPWR,
                        Address::Device { adp: st, ado: 0x0120 },
                        &mut ack.to_le_bytes(),
                    );
                }
                return Err(MasterError::State {
                    position,
                    name,
                    requested: state,
                    status: format!(
                        "stays in {reached}{}",
                        if status.error() { " with an error" } else { " (timeout)" }
                    ),
                    code: code_text(code),
                });
            }
            // Give the slave time between polls.
            let now = self.engine.io.now_ns();
            self.engine.io.sleep_until(now + 100_000);
        }
    }

    /// Mailboxes, PREOP, process-data mapping (from CoE where the slave has it, else the SII),
    /// SyncManagers and FMMUs, the process image; leaves every slave in PREOP.
    pub fn configure(&mut self) -> Result<()> {
        for k in 0..self.slaves.len() {
            let s = &self.slaves[k];
            if let Some(m) = s.mailbox.clone() {
                let st = s.station;
                let sm0 = SyncManager {
                    start: m.out.0,
                    length: m.out.1,
                    control: 0x26,
                    status: 0,
                    activate: 1,
                    pdi_control: 0,
                };
                let sm1 = SyncManager {
                    start: m.inp.0,
                    length: m.inp.1,
                    control: 0x22,
                    status: 0,
                    activate: 1,
                    pdi_control: 0,
                };
                let mut both = [0u8; 16];
                both[..8].copy_from_slice(&sm0.to_bytes());
                both[8..].copy_from_slice(&sm1.to_bytes());
                self.fpwr(st, 0x0800, &both)?;
            }
        }
        self.request_state_all(AlState::PreOp)?;
        for k in 0..self.slaves.len() as u16 {
            self.read_mapping(k)?;
        }
        self.layout()
    }

    /// The process-data mapping of one slave: from CoE (0x1C12/0x1C13 and the mapping objects)
    /// when it speaks CoE, else the PDOs its SII assigns to SyncManagers.
    pub fn read_mapping(&mut self, position: u16) -> Result<()> {
        let k = position as usize;
        let sms = self.slaves[k].sii.sync_managers().to_vec();
        let out_sm =
            sms.iter().enumerate().find(|(_, s)| s.sm_type == SmEntry::TYPE_OUTPUTS).map(|(i, s)| (i as u8, *s));
        let in_sm = sms.iter().enumerate().find(|(_, s)| s.sm_type == SmEntry::TYPE_INPUTS).map(|(i, s)| (i as u8, *s));
        let esi_dev = {
            let s = &self.slaves[k];
            self.esi
                .iter()
                .filter(|(v, d)| *v == s.vendor_id && d.product_code == s.product_code)
                .max_by_key(|(_, d)| (d.revision == s.revision, d.revision))
                .map(|(_, d)| d.clone())
        };
        let sii_has_mapping = {
            let sii = &self.slaves[k].sii;
            sii.rx_pdos().iter().chain(sii.tx_pdos()).any(|p| p.sync_manager != 0xFF)
        };
        let (outputs, inputs) = if self.slaves[k].has_coe() {
            (self.coe_mapping(position, 0x1C12)?, self.coe_mapping(position, 0x1C13)?)
        } else if let (Some(dev), false) = (&esi_dev, sii_has_mapping) {
            // The ESI's default assignment: PDOs with an Sm attribute.
            let from = |pdos: &[ferrocat_esi::PdoDesc]| -> Vec<Mapped> {
                pdos.iter()
                    .filter(|p| p.sm.is_some())
                    .flat_map(|p| p.entries.iter())
                    .map(|e| Mapped {
                        index: e.index,
                        subindex: e.subindex,
                        bits: e.bit_len,
                        name: e.name.clone(),
                        image_bit: 0,
                    })
                    .collect()
            };
            (from(&dev.rx_pdos), from(&dev.tx_pdos))
        } else {
            let sii = &self.slaves[k].sii;
            let from = |pdos: &[ferrocat_wire::sii::Pdo], sm: Option<(u8, SmEntry)>| -> Vec<Mapped> {
                pdos.iter()
                    .filter(|p| sm.is_some_and(|(n, _)| p.sync_manager == n))
                    .flat_map(|p| p.entries.iter())
                    .map(|e| Mapped {
                        index: e.index,
                        subindex: e.subindex,
                        bits: e.bit_len,
                        name: sii.string(e.name_idx).unwrap_or_else(|| format!("{:#06x}:{:02x}", e.index, e.subindex)),
                        image_bit: 0,
                    })
                    .collect()
            };
            (from(sii.rx_pdos(), out_sm), from(sii.tx_pdos(), in_sm))
        };
        let s = &mut self.slaves[k];
        s.outputs = outputs;
        s.inputs = inputs;
        s.out_sm = out_sm;
        s.in_sm = in_sm;
        Ok(())
    }

    fn coe_mapping(&mut self, position: u16, assign: u16) -> Result<Vec<Mapped>> {
        let mut v = Vec::new();
        let n = self.sdo_read(position, assign, 0)?.first().copied().unwrap_or(0);
        for k in 1..=n {
            let p = self.sdo_read(position, assign, k)?;
            let pdo = u16::from_le_bytes([p[0], *p.get(1).unwrap_or(&0)]);
            let m = self.sdo_read(position, pdo, 0)?.first().copied().unwrap_or(0);
            for j in 1..=m {
                let e = self.sdo_read(position, pdo, j)?;
                if e.len() < 4 {
                    continue;
                }
                let w = u32::from_le_bytes([e[0], e[1], e[2], e[3]]);
                let (index, subindex, bits) = ((w >> 16) as u16, (w >> 8) as u8, w as u8);
                let name = self.slaves[position as usize]
                    .sii
                    .rx_pdos()
                    .iter()
                    .chain(self.slaves[position as usize].sii.tx_pdos())
                    .flat_map(|p| p.entries.iter())
                    .find(|e| e.index == index && e.subindex == subindex)
                    .and_then(|e| self.slaves[position as usize].sii.string(e.name_idx))
                    .unwrap_or_else(|| format!("{index:#06x}:{subindex:02x}"));
                v.push(Mapped { index, subindex, bits, name, image_bit: 0 });
            }
        }
        Ok(v)
    }

    /// Lets the application choose the PDOs of one slave (PREOP only): writes the assignment
    /// object and reads the mapping back.
    pub fn remap(&mut self, position: u16, outputs: bool, pdos: &[u16]) -> Result<()> {
        self.slaves[position as usize].assignment[!outputs as usize] = Some(pdos.to_vec());
        self.write_assignment(position, outputs, pdos)?;
        self.read_mapping(position)?;
        self.layout()
    }

    fn write_assignment(&mut self, position: u16, outputs: bool, pdos: &[u16]) -> Result<()> {
        let assign = if outputs { 0x1C12 } else { 0x1C13 };
        self.sdo_write(position, assign, 0, &[0])?;
        for (k, p) in pdos.iter().enumerate() {
            self.sdo_write(position, assign, k as u8 + 1, &p.to_le_bytes())?;
        }
        self.sdo_write(position, assign, 0, &[pdos.len() as u8])
    }

    /// Checks every slave after a cycle came back short, reports what changed once per slave,
    /// and takes one step of bringing each fallen slave back to OP (so that the cyclic exchange
    /// keeps running meanwhile). Returns how many slaves are not operational.
    pub fn supervise(&mut self) -> Result<usize> {
        let mut down = 0;
        for k in 0..self.slaves.len() {
            let (st, name, pos) = (self.slaves[k].station, self.slaves[k].name.clone(), k as u16);
            let mut d = [0u8; 6];
            let mut wkc = self.engine.one(Command::FPRD, Address::Device { adp: st, ado: 0x0130 }, &mut d)?;
            if wkc == 0 {
                // Powered off and on again it has lost its station address: give it back.
                let mut a = [0u8; 2];
                if self.engine.one(Command::APRD, Address::position(pos, 0x0010), &mut a)? == 1 && a == [0, 0] {
                    self.engine.one(Command::APWR, Address::position(pos, 0x0010), &mut st.to_le_bytes())?;
                    wkc = self.engine.one(Command::FPRD, Address::Device { adp: st, ado: 0x0130 }, &mut d)?;
                }
            }
            if wkc == 0 {
                if self.slaves[k].health != crate::slave::Health::Lost {
                    self.slaves[k].health = crate::slave::Health::Lost;
                    self.events.push(MasterEvent::Lost { position: pos, name });
                }
                down += 1;
                continue;
            }
            let status = AlStatus(u16::from_le_bytes([d[0], d[1]]));
            let code = AlStatusCode(u16::from_le_bytes([d[4], d[5]]));
            if status.state() == Some(AlState::Op) && !status.error() {
                if self.slaves[k].health != crate::slave::Health::Operational {
                    self.slaves[k].health = crate::slave::Health::Operational;
                    self.events.push(MasterEvent::Recovered { position: pos, name });
                }
                continue;
            }
            down += 1;
            if self.slaves[k].health == crate::slave::Health::Operational {
                self.events.push(MasterEvent::LeftOp { position: pos, name, status, code });
            }
            self.slaves[k].health = crate::slave::Health::Recovering;
            // One step towards OP.
            if status.error() {
                let ack = status.state_bits() as u16 | AlStatus::ERROR;
                self.engine.one(Command::FPWR, Address::Device { adp: st, ado: 0x0120 }, &mut ack.to_le_bytes())?;
                continue;
            }
            match status.state() {
                Some(AlState::Init) | Some(AlState::Bootstrap) | None => {
                    self.write_mailbox_config(pos)?;
                    self.engine.one(
                        Command::FPWR,
                        Address::Device { adp: st, ado: 0x0120 },
                        &mut [AlState::PreOp as u8, 0],
                    )?;
                }
                Some(AlState::PreOp) => {
                    if self.slaves[k].has_coe() {
                        for (i, outputs) in [(0usize, true), (1, false)] {
                            if let Some(p) = self.slaves[k].assignment[i].clone() {
                                self.write_assignment(pos, outputs, &p)?;
                            }
                        }
                    }
                    self.write_process_config(pos)?;
                    self.engine.one(
                        Command::FPWR,
                        Address::Device { adp: st, ado: 0x0120 },
                        &mut [AlState::SafeOp as u8, 0],
                    )?;
                }
                Some(AlState::SafeOp) | Some(AlState::Op) => {
                    self.engine.one(
                        Command::FPWR,
                        Address::Device { adp: st, ado: 0x0120 },
                        &mut [AlState::Op as u8, 0],
                    )?;
                }
            }
        }
        Ok(down)
    }

    /// Places every slave's outputs, then every slave's inputs, byte-aligned in the image, and
    /// writes the SyncManagers and FMMUs.
    pub fn layout(&mut self) -> Result<()> {
        let mut out = 0u32;
        for s in &mut self.slaves {
            let bytes = s.output_bits().div_ceil(8);
            s.out_area = (out, bytes);
            out += bytes;
        }
        let mut inp = out;
        for s in &mut self.slaves {
            let bytes = s.input_bits().div_ceil(8);
            s.in_area = (inp, bytes);
            inp += bytes;
        }
        self.out_bytes = out;
        self.in_bytes = inp - out;
        self.image = vec![0; inp as usize];
        self.expected_wkc = 0;
        for k in 0..self.slaves.len() {
            let s = &mut self.slaves[k];
            let mut bit = s.out_area.0 * 8;
            for m in &mut s.outputs {
                m.image_bit = bit;
                bit += m.bits as u32;
            }
            let mut bit = s.in_area.0 * 8;
            for m in &mut s.inputs {
                m.image_bit = bit;
                bit += m.bits as u32;
            }
            let has_out = s.out_area.1 > 0;
            let has_in = s.in_area.1 > 0;
            self.expected_wkc += 2 * has_out as u16 + has_in as u16;
            self.write_process_config(k as u16)?;
        }
        Ok(())
    }

    /// Writes the SyncManagers and FMMUs of one slave's process data, from its layout.
    pub(crate) fn write_process_config(&mut self, position: u16) -> Result<()> {
        let s = &self.slaves[position as usize];
        let st = s.station;
        let mut writes: Vec<(u16, Vec<u8>)> = Vec::new();
        let mut fmmu = 0u16;
        for (area, sm, write) in [(s.out_area, s.out_sm, true), (s.in_area, s.in_sm, false)] {
            let Some((n, e)) = sm else { continue };
            let smr = if area.1 == 0 {
                SyncManager::default()
            } else {
                SyncManager {
                    start: e.start,
                    length: area.1 as u16,
                    control: e.control,
                    status: 0,
                    activate: 1,
                    pdi_control: 0,
                }
            };
            writes.push((0x0800 + 8 * n as u16, smr.to_bytes().to_vec()));
            if area.1 > 0 {
                let f = Fmmu {
                    logical_start: area.0,
                    length: area.1 as u16,
                    logical_start_bit: 0,
                    logical_stop_bit: 7,
                    physical_start: e.start,
                    physical_start_bit: 0,
                    fmmu_type: if write { Fmmu::WRITE } else { Fmmu::READ },
                    active: true,
                };
                writes.push((0x0600 + 16 * fmmu, f.to_bytes().to_vec()));
                fmmu += 1;
            }
        }
        for (a, d) in writes {
            self.fpwr(st, a, &d)?;
        }
        Ok(())
    }

    /// Writes the mailbox SyncManagers of one slave.
    pub(crate) fn write_mailbox_config(&mut self, position: u16) -> Result<()> {
        let s = &self.slaves[position as usize];
        let Some(m) = s.mailbox.clone() else { return Ok(()) };
        let sm0 =
            SyncManager { start: m.out.0, length: m.out.1, control: 0x26, status: 0, activate: 1, pdi_control: 0 };
        let sm1 =
            SyncManager { start: m.inp.0, length: m.inp.1, control: 0x22, status: 0, activate: 1, pdi_control: 0 };
        let mut both = [0u8; 16];
        both[..8].copy_from_slice(&sm0.to_bytes());
        both[8..].copy_from_slice(&sm1.to_bytes());
        let st = s.station;
        self.fpwr(st, 0x0800, &both)
    }

    /// PREOP → SAFEOP → OP for every slave, exchanging process data meanwhile (slaves with an
    /// SM watchdog want outputs before OP).
    pub fn start(&mut self) -> Result<()> {
        self.request_state_all(AlState::SafeOp)?;
        self.cycle()?;
        self.engine.one(Command::BWR, Address::Device { adp: 0, ado: 0x0120 }, &mut [AlState::Op as u8, 0])?;
        let deadline = self.engine.io.now_ns() + self.state_timeout_ns;
        loop {
            let now = self.engine.io.now_ns();
            self.cycle()?;
            let mut d = [0u8; 2];
            let wkc = self.engine.one(Command::BRD, Address::Device { adp: 0, ado: 0x0130 }, &mut d)?;
            if wkc as usize == self.slaves.len() && d[0] & 0x1F == AlState::Op as u8 {
                // BRD ORs every slave's state: all OP and no error flag.
                break;
            }
            if d[0] & 0x10 != 0 || now > deadline {
                for k in 0..self.slaves.len() as u16 {
                    self.wait_state(k, AlState::Op)?;
                }
                break;
            }
            self.engine.io.sleep_until(now + 1_000_000);
        }
        for s in &mut self.slaves {
            s.state = AlState::Op;
        }
        Ok(())
    }

    /// Adds an FRMW of the reference clock's system time (the first DC slave) to every cyclic
    /// frame, as SOEM and ethercrab do; returns the reference's position.
    pub fn distribute_dc(&mut self) -> Option<u16> {
        let r = self.slaves.iter().find(|s| s.has_system_time)?;
        self.dc_reference = Some(r.station);
        Some(r.position)
    }

    /// Scan, configure, start: the whole bring-up.
    pub fn bring_up(&mut self) -> Result<()> {
        self.scan()?;
        self.configure()?;
        self.start()
    }
}

/// Bytes of an SII image up to and including its end marker (or the whole of it).
fn sii_used_len(img: &[u8]) -> usize {
    if img.len() < SII_HEADER {
        return img.len();
    }
    let max = SiiHeader::parse(img).map(|h| h.eeprom_size_bytes()).unwrap_or(img.len()).clamp(SII_HEADER, 65536);
    let mut at = SII_HEADER;
    while at + 2 <= img.len().min(max) {
        let kind = u16::from_le_bytes([img[at], img[at + 1]]);
        if kind == 0xFFFF {
            return at + 2;
        }
        if at + CATEGORY_HEADER_LEN > img.len() {
            return img.len();
        }
        at += CATEGORY_HEADER_LEN + u16::from_le_bytes([img[at + 2], img[at + 3]]) as usize * 2;
    }
    img.len().min(max)
}

/// Whether `img` holds the whole SII: the end marker, or as much as the EEPROM is large.
fn sii_complete(img: &[u8]) -> bool {
    if img.len() < SII_HEADER {
        return false;
    }
    let max = SiiHeader::parse(img).map(|h| h.eeprom_size_bytes()).unwrap_or(2048).clamp(SII_HEADER, 65536);
    if img.len() >= max {
        return true;
    }
    let mut at = SII_HEADER;
    loop {
        if at + 2 > img.len() {
            return false;
        }
        if u16::from_le_bytes([img[at], img[at + 1]]) == 0xFFFF {
            return true;
        }
        if at + CATEGORY_HEADER_LEN > img.len() {
            return false;
        }
        at += CATEGORY_HEADER_LEN + u16::from_le_bytes([img[at + 2], img[at + 3]]) as usize * 2;
        if at >= max {
            return true;
        }
    }
}
