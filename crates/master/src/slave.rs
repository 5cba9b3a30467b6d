//! What the master knows about each slave.
use ferrocat_wire::register::{AlState, AlStatus, AlStatusCode, DlStatus};
use ferrocat_wire::sii::{SiiInfo, SmEntry};

/// A mapped process-data entry and where it sits in the process image.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct Mapped {
    /// The object's index.
    pub index: u16,
    /// The object's subindex.
    pub subindex: u8,
    /// Its size in bits.
    pub bits: u8,
    /// Its name, from the PDO entry's name in CoE, the SII or the ESI.
    pub name: String,
    /// Bit offset in the whole process image.
    pub image_bit: u32,
}

impl Mapped {
    /// An entry as its PDO describes it, not yet placed in the image (`image_bit` 0 until
    /// the image is laid out).
    pub fn unplaced(index: u16, subindex: u8, bits: u8, name: String) -> Self {
        Mapped { index, subindex, bits, name, image_bit: 0 }
    }
}

/// Where a slave's mailbox lies, and what it speaks.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct MailboxConfig {
    /// Master → slave (SM0): start, length.
    pub out: (u16, u16),
    /// Slave → master (SM1): start, length.
    pub inp: (u16, u16),
    /// The mailbox protocols the SII names (`sii::mailbox_protocol` bits).
    pub protocols: u16,
}

impl MailboxConfig {
    /// The standard mailbox the SII gives (INIT to OP), if any.
    pub fn standard(h: &ferrocat_wire::sii::SiiHeader) -> Option<Self> {
        (h.mailbox_rx_size > 0 && h.mailbox_tx_size > 0).then_some(MailboxConfig {
            out: (h.mailbox_rx_offset, h.mailbox_rx_size),
            inp: (h.mailbox_tx_offset, h.mailbox_tx_size),
            protocols: h.mailbox_protocols,
        })
    }

    /// The bootstrap mailbox the SII gives (BOOT), if any.
    pub fn bootstrap(h: &ferrocat_wire::sii::SiiHeader) -> Option<Self> {
        (h.bootstrap_rx_size > 0 && h.bootstrap_tx_size > 0).then_some(MailboxConfig {
            out: (h.bootstrap_rx_offset, h.bootstrap_rx_size),
            inp: (h.bootstrap_tx_offset, h.bootstrap_tx_size),
            protocols: h.mailbox_protocols,
        })
    }
}

/// Everything the master knows of one slave, from the scan on, grouped by what it describes:
/// identity, controller, ports, DC unit, mailbox and process data. The master fills it in;
/// an application reads it through the accessors.
#[derive(Debug, Clone)]
pub struct Slave {
    pub(crate) position: u16,
    pub(crate) station: u16,
    pub(crate) alias: u16,
    pub(crate) name: String,
    pub(crate) identity: Identity,
    pub(crate) esc: EscInfo,
    pub(crate) sii: SiiInfo,
    pub(crate) ports: Ports,
    pub(crate) dc: DcInfo,
    pub(crate) mailbox: Option<MailboxConfig>,
    pub(crate) mbx_counter: u8,
    /// The counter of the last message taken from the slave's send mailbox; after a repeat
    /// request, the counter then (a message with it again is the one already taken).
    pub(crate) mbx_in_counter: u8,
    pub(crate) mbx_repeated: Option<u8>,
    /// A read of the send mailbox went unanswered and was not sent again.
    pub(crate) mbx_read_lost: bool,
    pub(crate) mbx_repeats: u64,
    pub(crate) mapping: Mapping,
    pub(crate) state: AlState,
    pub(crate) health: Health,
    /// The PDO assignment the application chose (written again after a power cycle).
    pub(crate) assignment: [Option<Vec<u16>>; 2],
    /// EoE frames from the slave, put together and waiting.
    pub(crate) eoe: crate::eoe_link::EoeLink,
    /// The process-data watchdog the application chose (0x0420, in 100 µs steps; 0: off),
    /// written again whenever the master configures the slave's process data.
    pub(crate) pd_watchdog_steps: Option<u16>,
    /// What the application asks of the slave's configuration beyond the master's own.
    pub(crate) setup: Setup,
}

/// What the application asks of a slave's configuration beyond what the master finds (a
/// machine description's), applied whenever the master configures the slave
/// (`Config::setup_mut`).
#[derive(Debug, Clone, Default, PartialEq, Eq)]
pub struct Setup {
    /// CoE init commands, sent at their transitions after the ESI's own, in order.
    pub init_cmds: Vec<ferrocat_esi::InitCmd>,
    /// SoE init commands, sent at their transitions after the ESI's own, in order.
    pub soe_init_cmds: Vec<ferrocat_esi::SoeInitCmd>,
    /// The modules a modular device is to carry, slot by slot (their ESI module idents):
    /// written to 0xF030 and checked against 0xF050 in PREOP, after the IP and PS init
    /// commands and before the process data are read.
    pub modules: Option<Vec<u32>>,
}

/// Who a slave is: the SII's identity (words 0x08–0x0F).
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
pub struct Identity {
    /// The vendor's ETG number.
    pub vendor_id: u32,
    /// The product code.
    pub product_code: u32,
    /// The revision number.
    pub revision: u32,
    /// The serial number (0 where the vendor writes none).
    pub serial: u32,
}

/// What a slave's controller (ESC) has, read at the scan.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
pub struct EscInfo {
    /// The ESC's type (0x0000).
    pub kind: u8,
    /// FMMUs the ESC has (0x0004).
    pub fmmu_count: u8,
    /// SyncManagers the ESC has (0x0005).
    pub sm_count: u8,
    /// ESC features supported (0x0008).
    pub features: u16,
    /// Device emulation (ESC configuration 0x0141 bit 0): the ESC copies AL control into AL
    /// status itself, the error-indication bit included, and the status code stays 0. Real
    /// EK1100, EL1004 and EL2004 run so.
    pub device_emulation: bool,
    /// The SII interface's status 0x0502, read at the scan where DL status bit 0 (PDI
    /// operational) was clear (0 otherwise): bits 11–12 say why the ESC did not load the
    /// EEPROM's configuration area.
    pub eeprom_status: u16,
    /// DL status bit 0 at the scan: the PDI is operational, the ESC loaded its EEPROM's
    /// configuration area.
    pub pdi_operational: bool,
}

/// Where a slave sits: its ports, and the neighbour towards the master.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
pub struct Ports {
    /// DL status (0x0110) at the scan.
    pub dl_status: DlStatus,
    /// Ports 0–3 with a link and an open loop, at the scan.
    pub active: [bool; 4],
    /// Ports the ESC has (0x0007: two bits per port, 00 for none).
    pub descriptor: u8,
    /// The port the frame enters by (the one towards the master).
    pub entry: u8,
    /// The slave this one hangs on (its position), none for the first.
    pub parent: Option<u16>,
    /// Port of the parent this slave hangs on.
    pub parent_port: u8,
}

/// A slave's distributed-clock unit, as the master found and measured it.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
pub struct DcInfo {
    /// Distributed clocks (0x0008 bit 2): at least the receive times 0x0900–0x090F.
    pub supported: bool,
    /// The DC unit's system time (0x0910–0x09FF) answers: a clock that can be synchronised.
    /// An ET1200 with its SYNC and latch units off has receive times only (found at the latch:
    /// 0x0918 reads with WKC 0), like the real EL1004 and EL2828.
    pub has_system_time: bool,
    /// The DC unit's times are 64 bits wide (0x0008 bit 3).
    pub is_64bit: bool,
    /// Receive times of ports 0–3 (local time, low 32 bits), from the delay measurement.
    pub receive_times: [u32; 4],
    /// Receive time at the processing unit (0x0918), local time.
    pub receive_time_epu: u64,
    /// Which way a positive speed counter difference (0x0932) moves this ESC's clock, where
    /// the master measured it (`Master::measure_speed_direction`): true if it slows it.
    pub speed_diff_slows: Option<bool>,
    /// Propagation delay from the reference clock (the first DC slave), in ns.
    pub delay_ns: u32,
}

/// A slave's process data: the entries mapped, their SyncManagers and where they lie in the
/// process image.
#[derive(Debug, Clone, PartialEq, Eq, Default)]
pub struct Mapping {
    /// The output entries mapped, in image order.
    pub outputs: Vec<Mapped>,
    /// The input entries mapped, in image order.
    pub inputs: Vec<Mapped>,
    /// The SyncManager (number, settings) of the outputs.
    pub out_sm: Option<(u8, SmEntry)>,
    /// The SyncManager (number, settings) of the inputs.
    pub in_sm: Option<(u8, SmEntry)>,
    /// Output SyncManagers after `out_sm` that carry data (a TwinSAFE controller's SM6 beside
    /// SM2): number, settings, and the index in `outputs` of the first entry it carries. Each
    /// SyncManager's entries start on a byte of their own, in the order listed.
    pub more_out_sms: Vec<(u8, SmEntry, usize)>,
    /// Input SyncManagers after `in_sm` that carry data, as `more_out_sms`.
    pub more_in_sms: Vec<(u8, SmEntry, usize)>,
    /// Byte offset and length of this slave's outputs in the process image.
    pub out_area: (u32, u32),
    /// Byte offset and length of this slave's inputs in the process image.
    pub in_area: (u32, u32),
}

/// Where a slave stands during cyclic operation.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
pub enum Health {
    /// Answering, and in OP.
    #[default]
    Operational,
    /// Not answering at its station address (powered off, link lost).
    Lost,
    /// Answering but not in OP: being walked back.
    Recovering,
}

impl Slave {
    /// The AL state last seen, whether it answers in OP or is being brought back, and the
    /// mailbox repeat requests made.
    pub fn status(&self) -> Status {
        Status { state: self.state, health: self.health, mailbox_repeats: self.mbx_repeats }
    }
    /// Position on the segment, from 0.
    pub fn position(&self) -> u16 {
        self.position
    }
    /// The configured station address the master gave it (0x1001 + position).
    pub fn station(&self) -> u16 {
        self.station
    }
    /// The station alias from 0x0012 (0: none).
    pub fn alias(&self) -> u16 {
        self.alias
    }
    /// The first string of the SII (what SOEM calls the name), e.g. "EL2004".
    pub fn name(&self) -> &str {
        &self.name
    }
    /// Identity from the SII.
    pub fn identity(&self) -> Identity {
        self.identity
    }
    /// What the controller has.
    pub fn esc(&self) -> EscInfo {
        self.esc
    }
    /// What the SII says: strings, general category, FMMUs, SyncManagers, PDOs.
    pub fn sii(&self) -> &SiiInfo {
        &self.sii
    }
    /// Its ports and its place in the topology.
    pub fn ports(&self) -> Ports {
        self.ports
    }
    /// Its DC unit.
    pub fn dc(&self) -> DcInfo {
        self.dc
    }
    /// The standard mailbox, where the slave has one.
    pub fn mailbox(&self) -> Option<&MailboxConfig> {
        self.mailbox.as_ref()
    }
    /// Its process data: entries, SyncManagers, image areas.
    pub fn mapping(&self) -> &Mapping {
        &self.mapping
    }
}

impl MailboxConfig {
    /// Whether the slave speaks CoE.
    pub fn has_coe(&self) -> bool {
        self.has_protocol(ferrocat_wire::sii::mailbox_protocol::COE)
    }
    /// Whether the SII names this mailbox protocol (a `sii::mailbox_protocol` bit).
    pub fn has_protocol(&self, bit: u16) -> bool {
        self.protocols & bit != 0
    }
}

impl Mapping {
    /// Bits of outputs mapped (where several SyncManagers carry them, each one's rounded up to
    /// a byte but the last).
    pub fn output_bits(&self) -> u32 {
        region_bits(&self.outputs, &self.more_out_sms).iter().map(|r| r.2).sum()
    }
    /// Bits of inputs mapped, as [`Mapping::output_bits`].
    pub fn input_bits(&self) -> u32 {
        region_bits(&self.inputs, &self.more_in_sms).iter().map(|r| r.2).sum()
    }

    /// The output SyncManagers with their byte offset in this slave's outputs and their length
    /// in bytes: `out_sm` first, then `more_out_sms`.
    pub fn output_sms(&self) -> Vec<(u8, SmEntry, u32, u32)> {
        sm_regions(self.out_sm, &self.outputs, &self.more_out_sms)
    }
    /// The input SyncManagers, as [`Mapping::output_sms`].
    pub fn input_sms(&self) -> Vec<(u8, SmEntry, u32, u32)> {
        sm_regions(self.in_sm, &self.inputs, &self.more_in_sms)
    }

    /// Gives each entry its place in the image: outputs from bit `out_bit` on, inputs from
    /// `in_bit` on, a further SyncManager's entries from the next whole byte.
    pub(crate) fn place(&mut self, out_bit: u32, in_bit: u32) {
        place_entries(&mut self.outputs, &self.more_out_sms, out_bit);
        place_entries(&mut self.inputs, &self.more_in_sms, in_bit);
    }
}

/// The entries' regions, one per SyncManager, empty ones too (the first SyncManager may carry
/// nothing where a further one carries all): (first entry, end, bits, each rounded up to a byte
/// but the last region's).
fn region_bits(entries: &[Mapped], more: &[(u8, SmEntry, usize)]) -> Vec<(usize, usize, u32)> {
    let starts: Vec<usize> = std::iter::once(0).chain(more.iter().map(|m| m.2.min(entries.len()))).collect();
    let n = starts.len();
    (0..n)
        .map(|k| {
            let end = starts.get(k + 1).copied().unwrap_or(entries.len());
            let bits: u32 = entries[starts[k]..end].iter().map(|m| m.bits as u32).sum();
            (starts[k], end, if k + 1 < n { bits.div_ceil(8) * 8 } else { bits })
        })
        .collect()
}

fn sm_regions(
    first: Option<(u8, SmEntry)>,
    entries: &[Mapped],
    more: &[(u8, SmEntry, usize)],
) -> Vec<(u8, SmEntry, u32, u32)> {
    let Some(first) = first else { return Vec::new() };
    let sms = std::iter::once(first).chain(more.iter().map(|m| (m.0, m.1)));
    let mut at = 0u32;
    sms.zip(region_bits(entries, more))
        .map(|((n, e), (_, _, bits))| {
            let r = (n, e, at, bits.div_ceil(8));
            at += bits.div_ceil(8);
            r
        })
        .collect()
}

fn place_entries(entries: &mut [Mapped], more: &[(u8, SmEntry, usize)], from_bit: u32) {
    let mut bit = from_bit;
    for (first, end, bits) in region_bits(entries, more) {
        let start = bit;
        for m in &mut entries[first..end] {
            m.image_bit = bit;
            bit += m.bits as u32;
        }
        bit = start + bits;
    }
}

impl EscInfo {
    /// Why the ESC runs unconfigured, if it does: DL status bit 0 (PDI operational) clear
    /// because the EEPROM's configuration area did not load. Such a slave stays in INIT.
    pub fn eeprom_problem(&self) -> Option<String> {
        use ferrocat_wire::register::SiiControl;
        if self.pdi_operational {
            return None;
        }
        let sii_status = self.eeprom_status;
        let why = if sii_status & SiiControl::CHECKSUM_ERROR != 0 {
            "the checksum of its EEPROM's configuration area (word 7) is wrong"
        } else if sii_status & SiiControl::ACK_ERROR != 0 {
            "its EEPROM does not answer"
        } else if sii_status & SiiControl::NOT_LOADED != 0 {
            "its EEPROM's configuration area did not load"
        } else {
            "its PDI is not operational (DL status bit 0)"
        };
        Some(format!(
            "ESC unconfigured (0x0502 = {sii_status:#06x}): {why}; it stays in INIT until a good image \
             is programmed (`ferrocat sii write`) and it is powered off and on"
        ))
    }
    /// Whether the ESC's configuration area failed to load for good (the scan saw DL status
    /// bit 0 clear with a checksum error or no EEPROM acknowledge), not merely not yet.
    pub fn eeprom_failed(&self) -> bool {
        use ferrocat_wire::register::SiiControl;
        !self.pdi_operational && self.eeprom_status & (SiiControl::CHECKSUM_ERROR | SiiControl::ACK_ERROR) != 0
    }
    /// Whether AL status reports an error the master must deal with. Under device emulation
    /// the error-indication bit only mirrors the acknowledge bit the master wrote (real
    /// EK1100, EL1004 and EL2004 read back 0x0011 with code 0 after a write of 0x0011), so it
    /// is an error only with a status code.
    pub fn al_error(&self, status: AlStatus, code: AlStatusCode) -> bool {
        status.error() && !(self.device_emulation && code == AlStatusCode::NO_ERROR)
    }
}

impl Ports {
    /// Active ports as SOEM prints them: "1.1.0.0".
    pub fn active_text(&self) -> String {
        self.active.iter().map(|&a| if a { "1" } else { "0" }).collect::<Vec<_>>().join(".")
    }
}

/// What the master last saw of a slave during operation ([`Slave::status`]).
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct Status {
    state: AlState,
    health: Health,
    mailbox_repeats: u64,
}

impl Status {
    /// The AL state last seen.
    pub fn state(&self) -> AlState {
        self.state
    }
    /// Operation: answering and in OP, or being brought back.
    pub fn health(&self) -> Health {
        self.health
    }
    /// Mailbox repeat requests made (reads lost after the slave handed its message over).
    pub fn mailbox_repeats(&self) -> u64 {
        self.mailbox_repeats
    }
}

/// The slave at `position` in `slaves`, or an error saying how many there are.
pub(crate) fn slave_at(slaves: &[Slave], position: u16) -> crate::error::Result<&Slave> {
    slaves.get(position as usize).ok_or(crate::error::MasterError::NoSuchSlave { position, count: slaves.len() })
}

/// The slave table: the slaves the scan found, by position ([`Master::slaves`](crate::Master::slaves)).
/// It reads as a slice (`len`, `iter`, indexing) and finds a slave with an error that says how
/// many there are ([`Slaves::at`]).
#[derive(Debug, Default)]
pub struct Slaves {
    pub(crate) all: Vec<Slave>,
}

impl Slaves {
    /// The slave at `position`, or an error saying how many there are.
    pub fn at(&self, position: u16) -> crate::error::Result<&Slave> {
        slave_at(&self.all, position)
    }
}

impl std::ops::Deref for Slaves {
    type Target = [Slave];
    fn deref(&self) -> &[Slave] {
        &self.all
    }
}

impl std::ops::DerefMut for Slaves {
    fn deref_mut(&mut self) -> &mut [Slave] {
        &mut self.all
    }
}

impl<'a> IntoIterator for &'a Slaves {
    type Item = &'a Slave;
    type IntoIter = std::slice::Iter<'a, Slave>;
    fn into_iter(self) -> Self::IntoIter {
        self.all.iter()
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn entry(bits: u8) -> Mapped {
        Mapped { index: 0x7000, subindex: 1, bits, name: String::new(), image_bit: 0 }
    }

    #[test]
    fn each_sync_manager_s_entries_start_on_a_byte_and_an_empty_first_one_keeps_its_place() {
        let sm = |start| SmEntry { start, ..SmEntry::default() };
        // SM2 with 12 bits, SM6 with 9: 2 bytes, then 2 bytes from the next whole byte.
        let mut m = Mapping {
            outputs: vec![entry(8), entry(4), entry(1), entry(8)],
            out_sm: Some((2, sm(0x1100))),
            more_out_sms: vec![(6, sm(0x1FF4), 2)],
            ..Mapping::default()
        };
        let regions: Vec<_> = m.output_sms().iter().map(|r| (r.0, r.2, r.3)).collect();
        assert_eq!(regions, [(2, 0, 2), (6, 2, 2)]);
        assert_eq!(m.output_bits(), 16 + 9);
        m.place(80, 0);
        let bits: Vec<u32> = m.outputs.iter().map(|e| e.image_bit).collect();
        assert_eq!(bits, [80, 88, 96, 97]);
        // Nothing on SM2, everything on SM6: SM2 stays (off, 0 bytes), SM6 carries the bytes.
        let mut m = Mapping {
            outputs: vec![entry(16)],
            out_sm: Some((2, sm(0x1100))),
            more_out_sms: vec![(6, sm(0x1FF4), 0)],
            ..Mapping::default()
        };
        let regions: Vec<_> = m.output_sms().iter().map(|r| (r.0, r.2, r.3)).collect();
        assert_eq!(regions, [(2, 0, 0), (6, 0, 2)]);
        m.place(8, 0);
        assert_eq!(m.outputs[0].image_bit, 8);
    }
}
