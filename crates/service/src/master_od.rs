//! The master's own object dictionary (ETG.1510 "Profile for Master Diagnosis"), as a mailbox
//! gateway serves it at station address 0 and the control socket gives it whole.
//!
//! It is built from a [`Facts`] snapshot that the cyclic loop hands over (the slave table, the
//! master's counters, the events) and, for a slave's diagnosis object, the registers read from
//! that slave just before ([`Live`]). Nothing here runs in the loop.
//!
//! Encoding, where ETG.1510 leaves it open, follows what `pyetg1510` (a client written against
//! TwinCAT) reads: a complete access starts subindex 0 as 16 bits, an entry of 16 bits or more
//! starts at an even byte offset, a BOOLEAN takes a byte, and a VISIBLE_STRING is as long as
//! its text rounded up to an even length (never cut).
use ferrocat_master::wire::coe::AbortCode;

pub use ferrocat_master::wire::coe::{data_type, object_code};

/// Read in PREOP, SAFEOP and OP; never written (ETG.1000.6 object access bits 0–2).
pub const READ_ONLY: u16 = 0x0007;

/// One entry: its subindex, name, type, length and value as it goes on the wire.
#[derive(Debug, Clone, PartialEq, Eq, serde::Serialize)]
pub struct Entry {
    /// The subindex.
    pub subindex: u8,
    /// Its name (SDO information's entry description).
    pub name: String,
    /// Its CoE data type.
    pub data_type: u16,
    /// Its length in bits (a BOOLEAN 1, though its value takes a byte).
    pub bit_length: u16,
    /// Its value, little-endian, as an upload gives it.
    #[serde(serialize_with = "hex_of")]
    pub value: Vec<u8>,
}

fn hex_of<S: serde::Serializer>(v: &[u8], s: S) -> Result<S::Ok, S::Error> {
    s.serialize_str(&crate::protocol::hex(v))
}

/// One object: its index, name, object code and entries (subindex 0 first for a record or an
/// array; a VAR has subindex 0 only).
#[derive(Debug, Clone, PartialEq, Eq, serde::Serialize)]
pub struct Object {
    /// The index.
    pub index: u16,
    /// Its name (SDO information's object description).
    pub name: String,
    /// VAR, ARRAY or RECORD.
    pub object_code: u8,
    /// Its entries in subindex order.
    pub entries: Vec<Entry>,
}

impl Object {
    fn var(index: u16, name: &str, entry: Entry) -> Object {
        Object { index, name: name.into(), object_code: object_code::VAR, entries: vec![entry] }
    }

    fn record(index: u16, name: &str, code: u8, mut entries: Vec<Entry>) -> Object {
        let max = entries.last().map_or(0, |e| e.subindex);
        entries.insert(0, u8_entry(0, "SubIndex 000", max));
        Object { index, name: name.into(), object_code: code, entries }
    }

    /// The highest subindex.
    pub fn max_subindex(&self) -> u8 {
        self.entries.last().map_or(0, |e| e.subindex)
    }

    /// The object's data type as its description gives it: a VAR's or an array's entry type,
    /// RECORD (0x002A, ETG.1000.6's "record of" placeholder) otherwise.
    pub fn data_type(&self) -> u16 {
        match self.object_code {
            object_code::RECORD => 0x002A,
            _ => self.entries.last().map_or(0, |e| e.data_type),
        }
    }

    /// What an upload of `subindex` gives, the whole object from `subindex` on with
    /// `complete_access`.
    pub fn upload(&self, subindex: u8, complete_access: bool) -> Result<Vec<u8>, AbortCode> {
        if !complete_access {
            return self
                .entries
                .iter()
                .find(|e| e.subindex == subindex)
                .map(|e| e.value.clone())
                .ok_or(AbortCode::NO_SUBINDEX);
        }
        if self.object_code == object_code::VAR {
            return Err(AbortCode::COMPLETE_ACCESS_UNSUPPORTED);
        }
        if subindex > 1 {
            return Err(AbortCode::COMPLETE_ACCESS_UNSUPPORTED);
        }
        let mut out = Vec::new();
        for e in self.entries.iter().filter(|e| e.subindex >= subindex) {
            if e.subindex == 0 {
                out.extend_from_slice(&[e.value[0], 0]);
                continue;
            }
            if e.bit_length >= 16 && out.len() % 2 == 1 {
                out.push(0);
            }
            out.extend_from_slice(&e.value);
        }
        Ok(out)
    }
}

fn entry(subindex: u8, name: &str, data_type: u16, bit_length: u16, value: Vec<u8>) -> Entry {
    Entry { subindex, name: name.into(), data_type, bit_length, value }
}

fn u8_entry(subindex: u8, name: &str, v: u8) -> Entry {
    entry(subindex, name, data_type::UNSIGNED8, 8, vec![v])
}

fn u16_entry(subindex: u8, name: &str, v: u16) -> Entry {
    entry(subindex, name, data_type::UNSIGNED16, 16, v.to_le_bytes().to_vec())
}

fn u32_entry(subindex: u8, name: &str, v: u32) -> Entry {
    entry(subindex, name, data_type::UNSIGNED32, 32, v.to_le_bytes().to_vec())
}

fn bool_entry(subindex: u8, name: &str, v: bool) -> Entry {
    entry(subindex, name, data_type::BOOLEAN, 1, vec![u8::from(v)])
}

/// A VISIBLE_STRING entry: the text NUL-padded to an even length, its bit length that.
fn text_entry(subindex: u8, name: &str, text: &str) -> Entry {
    let mut v = text.as_bytes().to_vec();
    if v.len() % 2 == 1 || v.is_empty() {
        v.push(0);
    }
    let bits = u16::try_from(v.len() * 8).unwrap_or(u16::MAX);
    entry(subindex, name, data_type::VISIBLE_STRING, bits, v)
}

/// What the cyclic loop knows of one slave, for the dictionary.
#[derive(Debug, Clone, Default)]
pub struct SlaveFacts {
    /// Position on the segment, from 0.
    pub position: u16,
    /// Station address.
    pub station: u16,
    /// The SII's order number (ESI `Type`), else its name.
    pub type_name: String,
    /// The SII's device name.
    pub name: String,
    /// Vendor, product code, revision, serial.
    pub identity: [u32; 4],
    /// Receive (master → slave) and send mailbox lengths, 0 without a mailbox.
    pub mailbox_out: u16,
    /// Send (slave → master) mailbox length.
    pub mailbox_in: u16,
    /// The SII's mailbox protocols (AoE 0x01, EoE 0x02, CoE 0x04, FoE 0x08, SoE 0x10, VoE 0x20).
    pub protocols: u16,
    /// The ports the ESC has (0x0007).
    pub port_descriptor: u8,
    /// Ports with a link at the scan.
    pub active: [bool; 4],
    /// DL status (0x0110) at the scan.
    pub dl_status: u16,
    /// The station address behind each port (0 for none; the master behind the first slave's
    /// entry port).
    pub neighbours: [u16; 4],
    /// The state the master keeps the slave in.
    pub requested_state: u8,
    /// Times the slave stopped answering, and times it left OP, while the master ran.
    pub lost_count: u32,
    /// Times it left OP.
    pub left_op_count: u32,
}

/// What the cyclic loop knows of the master, for the dictionary.
#[derive(Debug, Clone, Default)]
pub struct Facts {
    /// The slaves the scan found.
    pub slaves: Vec<SlaveFacts>,
    /// Cycles run.
    pub cycles: u64,
    /// Cycles whose working counter was not the expected one.
    pub wkc_errors: u64,
    /// Cyclic frames lost.
    pub cyclic_lost: u64,
    /// Every frame lost, cyclic or not.
    pub frames_lost: u64,
    /// Frames sent.
    pub frames_sent: u64,
    /// How long the loop has run, in ns.
    pub uptime_ns: u64,
    /// The master's events, oldest first: (ns since the loop started, severity 0 info / 1
    /// warning / 2 error, text).
    pub events: Vec<(u64, u8, String)>,
    /// Events the master had before the oldest kept.
    pub events_dropped: u64,
}

/// A slave's registers read live for its diagnosis object, 0x0100–0x0313 in one read: DL
/// control to AL status code, and the error counters. `None` where the read failed.
#[derive(Debug, Clone, Default)]
pub struct Live {
    /// 0x0100–0x0313.
    pub registers: Option<Vec<u8>>,
}

/// The live read's first register and length (DL control to the error counters' end).
pub const LIVE: (u16, u16) = (0x0100, 0x0214);
/// Where the error counters start in it.
const COUNTERS_AT: usize = 0x0200;

/// Configuration objects per slave: 0x8000 + position.
pub const CONFIGURATION: u16 = 0x8000;
/// Information objects per slave.
pub const INFORMATION: u16 = 0x9000;
/// Diagnosis objects per slave.
pub const DIAGNOSIS: u16 = 0xA000;
/// Slaves the dictionary describes at most (0x8000–0x8FFF).
pub const MAX_SLAVES: usize = 0x1000;
/// Messages the diagnosis history (0x10F3) keeps.
pub const HISTORY: usize = 64;

/// The objects that do not depend on a slave's live registers (the index list, and what SDO
/// information describes): values from `facts` alone.
pub fn dictionary(facts: &Facts) -> Vec<Object> {
    let mut od = vec![
        Object::var(0x1000, "Device type", u32_entry(0, "Device type", 0)),
        Object::var(0x1008, "Device name", text_entry(0, "Device name", "ferrocat EtherCAT master")),
        Object::var(0x1009, "Hardware version", text_entry(0, "Hardware version", "")),
        Object::var(0x100A, "Software version", text_entry(0, "Software version", env!("CARGO_PKG_VERSION"))),
        Object::record(
            0x1018,
            "Identity",
            object_code::RECORD,
            vec![
                u32_entry(1, "Vendor ID", 0),
                u32_entry(2, "Product code", 0),
                u32_entry(3, "Revision", version_number()),
                u32_entry(4, "Serial number", 0),
            ],
        ),
        history(facts),
    ];
    let slaves = &facts.slaves[..facts.slaves.len().min(MAX_SLAVES)];
    od.extend(slaves.iter().map(configuration));
    od.extend(slaves.iter().map(information));
    od.extend(slaves.iter().map(|s| diagnosis(s, facts, &Live::default())));
    od.push(address_list(0xF020, "Configured address list", slaves));
    od.push(address_list(0xF040, "Detected address list", slaves));
    od.push(master_diagnosis(facts));
    od.sort_by_key(|o| o.index);
    od
}

/// Object `index` with its live values: a slave's diagnosis object from `live`.
pub fn object(facts: &Facts, index: u16, live: &Live) -> Option<Object> {
    if (DIAGNOSIS..DIAGNOSIS + MAX_SLAVES as u16).contains(&index) {
        let s = facts.slaves.get(usize::from(index - DIAGNOSIS))?;
        return Some(diagnosis(s, facts, live));
    }
    dictionary(facts).into_iter().find(|o| o.index == index)
}

/// The slave whose diagnosis object `index` is, if it is one.
pub fn diagnosis_slave(facts: &Facts, index: u16) -> Option<u16> {
    let k = index.checked_sub(DIAGNOSIS)?;
    (usize::from(k) < facts.slaves.len().min(MAX_SLAVES)).then_some(k)
}

/// The crate's version as one number: major × 10⁶ + minor × 10³ + patch.
fn version_number() -> u32 {
    let part = |s: &str| s.parse::<u32>().unwrap_or(0);
    part(env!("CARGO_PKG_VERSION_MAJOR")) * 1_000_000
        + part(env!("CARGO_PKG_VERSION_MINOR")) * 1_000
        + part(env!("CARGO_PKG_VERSION_PATCH"))
}

fn configuration(s: &SlaveFacts) -> Object {
    // ETG.1510 Link Preset: bits 0–2 "port 1–3 expects a slave", bits 4–6 "a link"; the links
    // found at the scan are the configuration ferrocat keeps.
    let mut preset = 0u8;
    for p in 1..4 {
        if s.active[p] {
            preset |= (1 << (p - 1)) | (0x10 << (p - 1));
        }
    }
    Object::record(
        CONFIGURATION + s.position,
        &format!("Configuration data slave {}", s.position),
        object_code::RECORD,
        [
            vec![
                u16_entry(1, "Fixed station address", s.station),
                text_entry(2, "Type", &s.type_name),
                text_entry(3, "Name", &s.name),
                u32_entry(4, "Device type", 0),
            ],
            identity_entries(&s.identity),
            vec![
                u16_entry(33, "Mailbox out size", s.mailbox_out),
                u16_entry(34, "Mailbox in size", s.mailbox_in),
                u8_entry(35, "Link status", 0),
                u8_entry(36, "Link preset", preset),
                u8_entry(37, "Flags", 0),
                u16_entry(38, "Port physics", port_physics(s.port_descriptor)),
                u16_entry(39, "Mailbox protocols supported", s.protocols & 0x3F),
                bool_entry(40, "Diag history object supported", false),
            ],
        ]
        .concat(),
    )
}

/// Subindices 5–8 of the configuration and information records: the identity (0x1018's order).
fn identity_entries(identity: &[u32; 4]) -> Vec<Entry> {
    vec![
        u32_entry(5, "Vendor ID", identity[0]),
        u32_entry(6, "Product code", identity[1]),
        u32_entry(7, "Revision", identity[2]),
        u32_entry(8, "Serial number", identity[3]),
    ]
}

/// ETG.1510 port physics: a nibble per port, 1 for a port the ESC has (MII/EBUS alike: the
/// descriptor 0x0007 does not tell the medium apart reliably enough to say more).
fn port_physics(descriptor: u8) -> u16 {
    (0..4).filter(|p| (descriptor >> (2 * p)) & 3 != 0).fold(0, |acc, p| acc | (1 << (4 * p)))
}

fn information(s: &SlaveFacts) -> Object {
    Object::record(
        INFORMATION + s.position,
        &format!("Information data slave {}", s.position),
        object_code::RECORD,
        [
            vec![u16_entry(1, "Station address", s.station)],
            identity_entries(&s.identity),
            vec![u16_entry(32, "DL status register", s.dl_status)],
        ]
        .concat(),
    )
}

fn diagnosis(s: &SlaveFacts, facts: &Facts, live: &Live) -> Object {
    let reg = |at: usize| -> u16 {
        live.registers.as_ref().and_then(|r| r.get(at..at + 2)).map_or(0, |b| u16::from_le_bytes([b[0], b[1]]))
    };
    let (dl_control, dl_status) = (reg(0x00), reg(0x10));
    let (al_control, al_status, al_code) = (reg(0x20), reg(0x30), reg(0x34));
    // Link/connection status: bit p communication on port p (its loop open with a link),
    // bit 4 + p a physical link (DL status 0x0110 bits 4–7 and 8–15).
    let mut link = 0u8;
    for p in 0..4 {
        if dl_status & (1 << (4 + p)) != 0 {
            link |= 0x10 << p;
        }
        if dl_status & (1 << (9 + 2 * p)) != 0 {
            link |= 1 << p;
        }
    }
    // Link control: DL control's loop bits (0x0100 bits 8–15), two a port.
    let link_control = (dl_control >> 8) as u8;
    let counter = |p: usize| -> u32 {
        let c = live.registers.as_deref().and_then(|r| r.get(COUNTERS_AT..)).unwrap_or(&[]);
        let at = |k: usize| u32::from(c.get(k).copied().unwrap_or(0));
        // Invalid frames, RX errors, forwarded RX errors, lost links of the port, a byte each.
        at(2 * p) | at(2 * p + 1) << 8 | at(8 + p) << 16 | at(16 + p) << 24
    };
    let mut entries = vec![
        u16_entry(1, "AL status", al_status),
        u16_entry(2, "AL control", al_control),
        u16_entry(3, "AL status code", al_code),
        u8_entry(4, "Link connection status", link),
        u8_entry(5, "Link control", link_control),
    ];
    for p in 0..4u8 {
        entries.push(u16_entry(6 + p, &format!("Fixed address connected port {p}"), s.neighbours[p as usize]));
    }
    for p in 0..4u8 {
        entries.push(u32_entry(10 + p, &format!("Frame error counter port {p}"), counter(p as usize)));
    }
    let wkc = u32::try_from(facts.wkc_errors).unwrap_or(u32::MAX);
    entries.extend([
        u32_entry(14, "Cyclic working counter error counter", wkc),
        u32_entry(15, "Slave not present counter", s.lost_count),
        u32_entry(16, "Abnormal state change counter", s.left_op_count),
        bool_entry(17, "Disable automatic link control", false),
        u32_entry(18, "Last protocol error", 0),
        bool_entry(19, "New diag message available", false),
    ]);
    Object::record(
        DIAGNOSIS + s.position,
        &format!("Diagnosis data slave {}", s.position),
        object_code::RECORD,
        entries,
    )
}

fn address_list(index: u16, name: &str, slaves: &[SlaveFacts]) -> Object {
    let entries = slaves
        .iter()
        .take(255)
        .enumerate()
        .map(|(k, s)| u16_entry(k as u8 + 1, &format!("Slave {k}"), s.station))
        .collect();
    Object::record(index, name, object_code::ARRAY, entries)
}

fn master_diagnosis(f: &Facts) -> Object {
    let per_s = |n: u64| u32::try_from(n.saturating_mul(1_000_000_000) / f.uptime_ns.max(1)).unwrap_or(u32::MAX);
    let acyclic_sent = f.frames_sent.saturating_sub(f.cycles);
    let state = f.slaves.iter().map(|s| s.requested_state).min().unwrap_or(1);
    Object::record(
        0xF120,
        "Master diagnosis data",
        object_code::RECORD,
        vec![
            u32_entry(1, "Cyclic lost frames", u32::try_from(f.cyclic_lost).unwrap_or(u32::MAX)),
            u32_entry(
                2,
                "Acyclic lost frames",
                u32::try_from(f.frames_lost.saturating_sub(f.cyclic_lost)).unwrap_or(u32::MAX),
            ),
            u32_entry(3, "Cyclic frames per second", per_s(f.cycles)),
            u32_entry(4, "Acyclic frames per second", per_s(acyclic_sent)),
            u16_entry(16, "Master state", u16::from(state)),
        ],
    )
}

/// The diagnosis history (ETG.1020's object 0x10F3): the newest [`HISTORY`] events as
/// messages of the form diag code (u32), flags (u16: 0 info, 1 warning, 2 error), text ID
/// (u16, 0: the text is the message's parameter), time stamp (u64, ns since the loop
/// started), then one parameter: flags 0x2000 | length (an ASCII string) and the text.
fn history(f: &Facts) -> Object {
    let first = f.events.len().saturating_sub(HISTORY);
    let kept = &f.events[first..];
    let newest = if kept.is_empty() { 0 } else { 5 + kept.len() as u8 };
    let mut entries = vec![
        u8_entry(1, "Maximum messages", HISTORY as u8),
        u8_entry(2, "Newest message", newest),
        u8_entry(3, "Newest acknowledged message", 0),
        bool_entry(4, "New messages available", !kept.is_empty()),
        u16_entry(5, "Flags", 0),
    ];
    for (k, (at_ns, severity, text)) in kept.iter().enumerate() {
        let text = &text.as_bytes()[..text.len().min(0x0FFF)];
        let mut m = Vec::with_capacity(20 + text.len());
        m.extend_from_slice(&0xE000_0000u32.to_le_bytes());
        m.extend_from_slice(&u16::from(*severity).to_le_bytes());
        m.extend_from_slice(&0u16.to_le_bytes());
        m.extend_from_slice(&at_ns.to_le_bytes());
        m.extend_from_slice(&(0x2000 | text.len() as u16).to_le_bytes());
        m.extend_from_slice(text);
        let bits = u16::try_from(m.len() * 8).unwrap_or(u16::MAX);
        entries.push(entry(6 + k as u8, &format!("Diagnosis message {:03}", k + 1), data_type::OCTET_STRING, bits, m));
    }
    Object::record(0x10F3, "Diagnosis history", object_code::RECORD, entries)
}
