//! Mailboxes, process-data mapping (CoE or SII), SyncManagers, FMMUs and the process image.
use ferrocat_wire::register::addr;
use ferrocat_wire::register::{AlState, Fmmu, SyncManager};
use ferrocat_wire::sii::SmEntry;

use super::Master;
use crate::error::Result;
use crate::io::Io;
use crate::slave::Mapped;

/// The watchdog divider the master writes (0x0400): 2 498 + 2 cycles of 40 ns, 100 µs a step of
/// the watchdog time (ESC datasheet section II, 0x0400).
pub(crate) const WATCHDOG_DIVIDER: u16 = 2498;
pub(crate) const WATCHDOG_STEP_NS: u64 = (WATCHDOG_DIVIDER as u64 + 2) * 40;

impl<I: Io> Master<I> {
    /// The plan's SDO downloads for the slave at `position`, if a plan gives any.
    fn run_plan_sdos(&mut self, position: u16) -> Result<()> {
        let sdos = match &self.plan {
            Some((p, _)) => p.sdos.get(position as usize).cloned().unwrap_or_default(),
            None => return Ok(()),
        };
        for c in &sdos {
            self.acyclic().coe().sdo_download(position, c.index, c.subindex, c.complete_access, &c.data).map_err(
                |e| {
                    let name = self.slaves[position as usize].name.clone();
                    crate::error::MasterError::of(
                        position,
                        &name,
                        crate::error::SlaveError::ConfigSdo {
                            origin: crate::error::SdoSource::Plan,
                            index: c.index,
                            subindex: c.subindex,
                            comment: c.comment.clone(),
                            error: Box::new(e),
                        },
                    )
                },
            )?;
        }
        Ok(())
    }

    /// The plan's SoE writes for the slave at `position`, if a plan gives any, each with its
    /// `timeout_ms` where that is longer than the mailbox's.
    fn run_plan_idns(&mut self, position: u16) -> Result<()> {
        let idns = match &self.plan {
            Some((p, _)) => p.idns.get(position as usize).cloned().unwrap_or_default(),
            None => return Ok(()),
        };
        for c in &idns {
            self.soe_write_waiting(position, (c.drive, c.idn, c.elements), &c.data, c.timeout_ms).map_err(|e| {
                let name = self.slaves[position as usize].name.clone();
                crate::error::MasterError::of(
                    position,
                    &name,
                    crate::error::SlaveError::ConfigIdn {
                        origin: crate::error::SdoSource::Plan,
                        drive: c.drive,
                        idn: c.idn,
                        comment: c.comment.clone(),
                        error: Box::new(e),
                    },
                )
            })?;
        }
        Ok(())
    }

    /// The process-data mapping of one slave: from CoE (0x1C12/0x1C13 and the mapping objects,
    /// 0x1C10 + n for a further SyncManager n) when it speaks CoE, from drive 0's telegram
    /// configuration (S-0-0024, S-0-0016) when it speaks SoE alone, else the PDOs its ESI or
    /// SII assigns to SyncManagers. Every process-data SyncManager of the SII that gets entries is
    /// configured (a TwinSAFE controller's SM6 beside SM2).
    pub(crate) fn read_mapping(&mut self, position: u16) -> Result<()> {
        let k = position as usize;
        let sms = self.slaves[k].sii.sync_managers().to_vec();
        let of_type = |t: u8| -> Vec<(u8, SmEntry)> {
            sms.iter().enumerate().filter(|(_, s)| s.sm_type == t).map(|(i, s)| (i as u8, *s)).collect()
        };
        let (out_sms, in_sms) = (of_type(SmEntry::TYPE_OUTPUTS), of_type(SmEntry::TYPE_INPUTS));
        let esi_dev = self.esi_description(position).cloned();
        let sii_has_mapping = {
            let sii = &self.slaves[k].sii;
            sii.rx_pdos().iter().chain(sii.tx_pdos()).any(|p| p.sync_manager != 0xFF)
        };
        let coe = self.slaves[k].mailbox().is_some_and(|mb| mb.has_coe());
        let soe_alone = !coe
            && self.slaves[k].mailbox().is_some_and(|mb| mb.has_protocol(ferrocat_wire::sii::mailbox_protocol::SOE));
        // Each SyncManager's entries, the first SyncManager of a direction first.
        let mut per_sm: Vec<(bool, u8, SmEntry, Vec<Mapped>)> = Vec::new();
        for (outputs, list) in [(true, &out_sms), (false, &in_sms)] {
            for (j, &(n, e)) in list.iter().enumerate() {
                let first = j == 0;
                let entries = if coe {
                    let assign = match (first, outputs) {
                        (true, true) => 0x1C12,
                        (true, false) => 0x1C13,
                        _ => 0x1C10 + n as u16,
                    };
                    match self.coe_mapping(position, assign) {
                        // A device without the object (it aborts the read) has nothing
                        // assigned to a further SyncManager; any other failure is one.
                        Err(crate::error::MasterError::Abort { .. }) if !first => Vec::new(),
                        other => other?,
                    }
                } else if soe_alone {
                    // A drive that speaks SoE alone: its telegrams as its configuration lists
                    // name them (the MDT the outputs, the AT the inputs), a further
                    // SyncManager nothing.
                    if first {
                        self.soe_mapping(position, outputs)?
                    } else {
                        Vec::new()
                    }
                } else if let (Some(dev), false) = (&esi_dev, sii_has_mapping) {
                    // The ESI's default assignment: PDOs with an Sm attribute (one naming no
                    // process-data SyncManager goes with the direction's first).
                    let known: Vec<u8> = list.iter().map(|x| x.0).collect();
                    let pdos = if outputs { &dev.rx_pdos } else { &dev.tx_pdos };
                    pdos.iter()
                        .filter(|p| p.sm.is_some_and(|sm| sm == n || (first && !known.contains(&sm))))
                        .flat_map(|p| p.entries.iter())
                        .map(|e| Mapped::unplaced(e.index, e.subindex, e.bit_len, e.name.clone()))
                        .collect()
                } else {
                    let sii = &self.slaves[k].sii;
                    let pdos = if outputs { sii.rx_pdos() } else { sii.tx_pdos() };
                    pdos.iter()
                        .filter(|p| p.sync_manager == n)
                        .flat_map(|p| p.entries.iter())
                        .map(|e| {
                            let name = sii.string(e.name_idx);
                            let name = name.unwrap_or_else(|| format!("{:#06x}:{:02x}", e.index, e.subindex));
                            Mapped::unplaced(e.index, e.subindex, e.bit_len, name)
                        })
                        .collect()
                };
                per_sm.push((outputs, n, e, entries));
            }
        }
        let s = &mut self.slaves[k];
        s.mapping.outputs.clear();
        s.mapping.inputs.clear();
        s.mapping.more_out_sms.clear();
        s.mapping.more_in_sms.clear();
        s.mapping.out_sm = out_sms.first().copied();
        s.mapping.in_sm = in_sms.first().copied();
        for (outputs, n, e, entries) in per_sm {
            let (list, more, first) = if outputs {
                (&mut s.mapping.outputs, &mut s.mapping.more_out_sms, s.mapping.out_sm)
            } else {
                (&mut s.mapping.inputs, &mut s.mapping.more_in_sms, s.mapping.in_sm)
            };
            if first.is_some_and(|f| f.0 != n) {
                if entries.is_empty() {
                    continue;
                }
                more.push((n, e, list.len()));
            }
            list.extend(entries);
        }
        Ok(())
    }

    /// The MDT (`outputs`: S-0-0024) or AT (S-0-0016) of every drive of the device as entries,
    /// drive after drive (drive 0 first, up to the first drive number the device refuses): each
    /// IDN of a list as long as its attribute says, indexed by its number with the drive as
    /// subindex (drive 0's as ESI files write an SoE drive's PDO entries, subindex 0), named by
    /// its name element where it has one.
    pub(super) fn soe_mapping(&mut self, position: u16, outputs: bool) -> Result<Vec<Mapped>> {
        use crate::error::{MasterError, SlaveError};
        use ferrocat_wire::soe::Idn;
        let list_idn = if outputs { Idn::MDT_CONFIG } else { Idn::AT_CONFIG };
        let mut v = Vec::new();
        for drive in 0..8u8 {
            let list = match self.acyclic().soe().idn_list(position, drive, list_idn) {
                Ok(list) => list,
                // A device with fewer drives refuses the drive number (SoE error 0x800A on the
                // simulated drive; a real one may answer another error).
                Err(MasterError::Slave { error: SlaveError::Soe { .. } | SlaveError::MailboxError(_), .. })
                    if drive > 0 =>
                {
                    break
                }
                Err(e) => return Err(e),
            };
            self.soe_telegram(position, drive, list_idn, &list, &mut v)?;
        }
        Ok(v)
    }

    /// One drive's telegram list `list` (of `list_idn`) as entries, onto `v`.
    fn soe_telegram(
        &mut self,
        position: u16,
        drive: u8,
        list_idn: ferrocat_wire::soe::Idn,
        list: &[ferrocat_wire::soe::Idn],
        v: &mut Vec<Mapped>,
    ) -> Result<()> {
        use crate::error::{MasterError, SlaveError};
        use ferrocat_wire::soe::{list_items, Attribute, Elements, ValueLength};
        for &idn in list {
            let a = self.acyclic().soe().read(position, drive, idn, Elements::ATTRIBUTE)?;
            let attribute = a.get(..4).map(|b| Attribute(u32::from_le_bytes([b[0], b[1], b[2], b[3]])));
            let bits = match attribute.map(|a| a.length()) {
                Some(ValueLength::Fixed(n)) => u8::try_from(n as u16 * 8).ok(),
                _ => None,
            };
            let Some(bits) = bits else {
                let name = self.slaves[position as usize].name.clone();
                let why = format!(
                    "SoE {list_idn} of drive {drive} names {idn}, whose attribute {a:02x?} gives no fixed length of 1 to 31 bytes"
                );
                return Err(MasterError::of(position, &name, SlaveError::UnexpectedReply(why)));
            };
            let name = match self.acyclic().soe().read(position, drive, idn, Elements::NAME) {
                Ok(n) => {
                    let text = list_items(&n).map_or(&n[..], |(items, _)| items);
                    format!("{idn} {}", String::from_utf8_lossy(text))
                }
                Err(MasterError::Slave { error: SlaveError::Soe { .. }, .. }) => idn.to_string(),
                Err(e) => return Err(e),
            };
            let name = if drive > 0 { format!("drive {drive} {name}") } else { name };
            v.push(Mapped::unplaced(idn.0, drive, bits, name));
        }
        Ok(())
    }

    pub(super) fn coe_mapping(&mut self, position: u16, assign: u16) -> Result<Vec<Mapped>> {
        let mut v = Vec::new();
        let n = self.acyclic().coe().sdo_read(position, assign, 0)?.first().copied().unwrap_or(0);
        for k in 1..=n {
            let p = self.acyclic().coe().sdo_read(position, assign, k)?;
            let pdo = u16::from_le_bytes([p[0], *p.get(1).unwrap_or(&0)]);
            let m = self.acyclic().coe().sdo_read(position, pdo, 0)?.first().copied().unwrap_or(0);
            for j in 1..=m {
                let e = self.acyclic().coe().sdo_read(position, pdo, j)?;
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
                v.push(Mapped::unplaced(index, subindex, bits, name));
            }
        }
        Ok(v)
    }

    pub(super) fn write_assignment(&mut self, position: u16, outputs: bool, pdos: &[u16]) -> Result<()> {
        let assign = if outputs { 0x1C12 } else { 0x1C13 };
        self.acyclic().coe().sdo_write(position, assign, 0, &[0])?;
        for (k, p) in pdos.iter().enumerate() {
            self.acyclic().coe().sdo_write(position, assign, k as u8 + 1, &p.to_le_bytes())?;
        }
        self.acyclic().coe().sdo_write(position, assign, 0, &[pdos.len() as u8])
    }

    /// Places every slave's outputs, then every slave's inputs, byte-aligned in the image, and
    /// writes the SyncManagers and FMMUs; with a plan ([`Config::set_plan`](crate::part::Config::set_plan)), as the plan says.
    pub(crate) fn layout(&mut self) -> Result<()> {
        // Diagnosis finds the TxPDO status entries of the new image.
        self.diagnosis.txpdo = None;
        if !self.groups.is_empty() {
            let plan = self.plan_for_groups()?;
            self.config().set_plan(plan)?;
        }
        if self.plan.is_some() {
            return self.layout_by_plan();
        }
        let mut out = 0u32;
        for s in self.slaves.iter_mut() {
            let bytes = s.mapping().output_bits().div_ceil(8);
            s.mapping.out_area = (out, bytes);
            out += bytes;
        }
        let mut inp = out;
        for s in self.slaves.iter_mut() {
            let bytes = s.mapping().input_bits().div_ceil(8);
            s.mapping.in_area = (inp, bytes);
            inp += bytes;
        }
        self.out_bytes = out;
        self.in_bytes = inp - out;
        self.image = vec![0; inp as usize];
        self.expected_wkc = 0;
        for k in 0..self.slaves.len() {
            let s = &mut self.slaves[k];
            s.mapping.place(s.mapping.out_area.0 * 8, s.mapping.in_area.0 * 8);
            let has_out = s.mapping.out_area.1 > 0;
            let has_in = s.mapping.in_area.1 > 0;
            self.expected_wkc += 2 * has_out as u16 + has_in as u16;
            self.write_process_config(k as u16)?;
        }
        Ok(())
    }

    /// The plan's layout: the output image, then the input image, each entry from its slave's
    /// first bit on; the plan's registers written to each slave.
    fn layout_by_plan(&mut self) -> Result<()> {
        let Some((plan, _)) = &self.plan else { return Ok(()) };
        let (out_bytes, in_bytes) = (plan.output_bytes, plan.input_bytes);
        let entries_at = plan.entries_at.clone();
        let registers = plan.registers.clone();
        self.expected_wkc = plan.expected_wkc();
        self.out_bytes = out_bytes;
        self.in_bytes = in_bytes;
        self.image = vec![0; (out_bytes + in_bytes) as usize];
        for (k, s) in self.slaves.iter_mut().enumerate() {
            let (out_at, in_at) = entries_at.get(k).copied().unwrap_or((None, None));
            s.mapping.place(out_at.unwrap_or(0), out_bytes * 8 + in_at.unwrap_or(0));
            s.mapping.out_area = (out_at.unwrap_or(0) / 8, s.mapping().output_bits().div_ceil(8));
            s.mapping.in_area = (out_bytes + in_at.unwrap_or(0) / 8, s.mapping().input_bits().div_ceil(8));
        }
        for k in 0..registers.len().min(self.slaves.len()) {
            self.write_process_config(k as u16)?;
        }
        Ok(())
    }

    /// Writes the SyncManagers and FMMUs of one slave's process data, from its layout or the
    /// plan's registers (at the layout, and when the slave is brought back after a fall).
    pub(crate) fn write_process_config(&mut self, position: u16) -> Result<()> {
        if let Some((plan, _)) = &self.plan {
            let writes = plan.registers.get(position as usize).cloned().unwrap_or_default();
            let st = self.slaves[position as usize].station;
            for (ado, data) in &writes {
                self.fpwr(st, *ado, data)?;
            }
            return Ok(());
        }
        let s = &self.slaves[position as usize];
        let st = s.station;
        for (a, d) in process_registers(s, s.mapping.out_area.0, s.mapping.in_area.0) {
            self.fpwr(st, a, &d)?;
        }
        self.write_watchdog(position)
    }

    fn write_watchdog(&mut self, position: u16) -> Result<()> {
        let s = &self.slaves[position as usize];
        let Some(steps) = s.pd_watchdog_steps else { return Ok(()) };
        let st = s.station;
        self.fpwr(st, addr::WATCHDOG_DIVIDER, &WATCHDOG_DIVIDER.to_le_bytes())?;
        self.fpwr(st, addr::WATCHDOG_TIME_PROCESS_DATA, &steps.to_le_bytes())
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
        self.fpwr(st, addr::SM0, &both)
    }
}

/// The SyncManager and FMMU registers of a slave's process data, its outputs at logical address
/// `out_logical` and its inputs at `in_logical`: each SyncManager as long as its data, one FMMU
/// per SyncManager that has data.
pub(crate) fn process_registers(s: &crate::slave::Slave, out_logical: u32, in_logical: u32) -> Vec<(u16, Vec<u8>)> {
    let mut writes: Vec<(u16, Vec<u8>)> = Vec::new();
    let mut fmmu = 0u8;
    for (logical, sms, write) in
        [(out_logical, s.mapping.output_sms(), true), (in_logical, s.mapping.input_sms(), false)]
    {
        for (n, e, offset, bytes) in sms {
            let smr = if bytes == 0 {
                SyncManager::default()
            } else {
                SyncManager {
                    start: e.start,
                    length: bytes as u16,
                    control: e.control,
                    status: 0,
                    activate: 1,
                    pdi_control: 0,
                }
            };
            writes.push((addr::sm(n), smr.to_bytes().to_vec()));
            if bytes > 0 {
                let f = Fmmu {
                    logical_start: logical + offset,
                    length: bytes as u16,
                    logical_start_bit: 0,
                    logical_stop_bit: 7,
                    physical_start: e.start,
                    physical_start_bit: 0,
                    fmmu_type: if write { Fmmu::WRITE } else { Fmmu::READ },
                    active: true,
                };
                writes.push((addr::fmmu(fmmu), f.to_bytes().to_vec()));
                fmmu += 1;
            }
        }
    }
    writes
}

impl<'a, I: Io> crate::master::part::States<'a, I> {
    /// Mailboxes, PREOP, process-data mapping (from CoE where the slave has it, else the SII),
    /// SyncManagers and FMMUs, the process image; leaves every slave in PREOP.
    pub fn configure(&mut self) -> Result<()> {
        for k in 0..self.m.slaves.len() as u16 {
            self.m.write_mailbox_config(k)?;
        }
        self.m.states().request_state_all(AlState::PreOp)?;
        for k in 0..self.m.slaves.len() as u16 {
            self.m.run_init_commands(k, "IP")?;
            self.m.run_init_commands(k, "PS")?;
            if self.m.slaves[k as usize].mailbox().is_some_and(|mb| mb.has_coe()) {
                if let Some(modules) = self.m.slaves[k as usize].setup.modules.clone() {
                    self.m.config().configure_modules(k, &modules)?;
                }
            }
            self.m.run_plan_sdos(k)?;
            self.m.run_plan_idns(k)?;
            self.m.read_mapping(k)?;
        }
        self.m.layout()
    }
}

impl<'a, I: Io> crate::master::part::Config<'a, I> {
    /// Lets the application choose the PDOs of one slave (PREOP only): writes the assignment
    /// object and reads the mapping back.
    pub fn remap(&mut self, position: u16, outputs: bool, pdos: &[u16]) -> Result<()> {
        self.m.slaves[position as usize].assignment[!outputs as usize] = Some(pdos.to_vec());
        self.m.write_assignment(position, outputs, pdos)?;
        self.m.read_mapping(position)?;
        self.m.layout()
    }

    /// Sets the process-data watchdog of the slave at `position` (the SM watchdog, ESC
    /// registers 0x0400 and 0x0420) to `time_ns`, rounded to the 100 µs steps of the divider
    /// 2 498 (25 MHz / 2 500, the ESC's default, written with it); 0 turns it off. The ESC arms
    /// it when the output SyncManager is enabled with its watchdog trigger (control bit 6, from
    /// the SII): without process data for that long, it
    /// resets the outputs, and a slave with a firmware leaves OP (AL status code 0x001B). The
    /// master writes it now and again whenever it configures the slave's process data (after
    /// a power cycle, for instance). Without it the slave keeps its EEPROM's or the ESC's
    /// default (100 ms on ET1100 and the simulated ESC).
    pub fn set_process_data_watchdog(&mut self, position: u16, time_ns: u64) -> Result<()> {
        self.m.slave(position)?;
        let steps = time_ns.div_ceil(WATCHDOG_STEP_NS);
        let steps = u16::try_from(steps).map_err(|_| crate::error::ConfigError::WatchdogTooLong(time_ns))?;
        self.m.slaves[position as usize].pd_watchdog_steps = Some(steps);
        self.m.write_watchdog(position)
    }
}
