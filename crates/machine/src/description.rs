//! ferrocat's own machine description: one TOML file a person reads and edits, naming the slaves
//! a machine expects and how strictly each is checked. `ferrocat scan --write-machine FILE`
//! writes one from the network it finds, so that nobody starts from an empty file.
//!
//! ```toml
//! name = "press line 3"
//!
//! [[slave]]
//! name = "coupler"
//! vendor = 0x2
//! product = 0x044C2C52
//! revision = 0x00120000            # exactly; or revision_min/revision_max, or "any"
//! device = "EK1100"                # what a simulator serves here (as --device takes it)
//!
//! [[slave]]
//! name = "axis X"
//! vendor = 0x0
//! product = 0x402
//! revision = "any"
//! serial = 1234                    # checked where given
//! alias = 0x10                     # checked where given
//! optional = true                  # may be absent
//!
//! [[slave.init]]                   # a CoE write at a transition
//! transition = "PS"
//! index = 0x6060
//! value = 8
//! type = "i8"
//!
//! [[variable]]                     # a name for an entry, for --set, --show and the image
//! name = "x_mode"
//! entry = "axis X:Modes of operation"
//! ```
use serde::Deserialize;
use toml::Spanned;

use crate::compare::{Expected, Found, Identity, RevisionCheck};
use crate::Place;

/// An error in a machine description: where, and what.
#[derive(Debug, Clone, PartialEq, Eq, thiserror::Error)]
#[error("{place}: {message}")]
pub struct DescriptionError {
    /// Where.
    pub place: Place,
    /// What is wrong.
    pub message: String,
}

/// A machine: the slaves it expects, in network order, and its process-data groups.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct Machine {
    /// What the machine is called, where given.
    pub name: Option<String>,
    /// The slaves, position 0 first.
    pub slaves: Vec<SlaveDesc>,
    /// Process-data groups, each with its own frame and rate.
    pub groups: Vec<GroupDesc>,
    /// Slave-to-slave copies through the master: (from, to), each `SLAVE:ENTRY` with the slave
    /// by its name in the description or its position.
    pub copies: Vec<(String, String)>,
    /// Names the user gives to slaves' entries.
    pub variables: Vec<VariableDesc>,
    /// Distributed clocks: `Some` turns them on for `run`.
    pub dc: Option<DcDesc>,
}

/// The machine's distributed clocks (`[dc]`).
#[derive(Debug, Clone, PartialEq, Eq, Default)]
pub struct DcDesc {
    /// The clock-sync method, as `run --sync` names it (`None`: run's default).
    pub sync: Option<String>,
    /// SYNC0 after each cycle's start, µs (`None`: run's default, half a cycle after the
    /// frame's passage).
    pub sync0_shift_us: Option<u32>,
    /// SYNC1 after SYNC0, µs (0: no SYNC1).
    pub sync1_us: u32,
    /// The clock-sync probes' time per cycle, µs (`None`: run's default, from the loop's cost).
    pub probe_budget_us: Option<u32>,
    /// The static drift compensation's frames at most (`None`: run's default).
    pub static_frames: Option<u32>,
}

/// A name for one of a slave's process-data entries.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct VariableDesc {
    /// The name (no `:` in it, so that it never reads as `POS:ENTRY`).
    pub name: String,
    /// The slave's position.
    pub position: u16,
    /// The entry's name, as the slave maps it (`ferrocat pdos`).
    pub entry: String,
}

/// A process-data group: its slaves' process data in a frame of their own, every `every`
/// base cycles.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct GroupDesc {
    /// Its name.
    pub name: String,
    /// Its slaves, by position.
    pub positions: Vec<u16>,
    /// Every how many base cycles its frame is sent.
    pub every: u32,
}

/// A slave the machine expects.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct SlaveDesc {
    /// The name the user gives it (default: `slave N`).
    pub name: String,
    /// Vendor, product, and the serial number where one is required.
    pub identity: Identity,
    /// Which revisions pass.
    pub revision: RevisionCheck,
    /// The serial number is checked.
    pub check_serial: bool,
    /// The station alias it must have, where given.
    pub alias: Option<u16>,
    /// It may be absent.
    pub optional: bool,
    /// What a simulator serves in its place: an EEPROM dump, `ESI.xml:PRODUCT`, or a built-in
    /// name, as `ferrocat sim --device` takes them.
    pub device: Option<String>,
    /// Its process-data (SM) watchdog, µs, a multiple of 100 (0: off); `None`: the slave's own.
    pub watchdog_us: Option<u32>,
    /// The RxPDOs (outputs) to assign (0x1C12), in order; `None`: the slave's own assignment.
    pub rx_pdos: Option<Vec<u16>>,
    /// The TxPDOs (inputs) to assign (0x1C13), likewise.
    pub tx_pdos: Option<Vec<u16>>,
    /// CoE writes at transitions, in order (after the ESI's own init commands).
    pub init: Vec<ferrocat_esi::InitCmd>,
    /// Whether its SYNC0 is started (`None`: where its SII declares a DC op-mode with SYNC0).
    pub sync0: Option<bool>,
    /// A modular device's modules, slot by slot, by their ESI module idents (`None`: what it
    /// carries is not checked).
    pub modules: Option<Vec<u32>>,
    /// Its assign-activate word, as ESI's `AssignActivate` gives it (`None`: the master's).
    pub assign_activate: Option<u16>,
}

/// A number: a TOML integer (`0x2`, `2`) or text (`"#x2"`, `"0x2"`).
#[derive(Debug, Clone, Deserialize)]
#[serde(untagged)]
enum Number {
    Int(i64),
    Text(String),
}

#[derive(Debug, Deserialize)]
#[serde(deny_unknown_fields)]
struct Raw {
    name: Option<String>,
    #[serde(default, rename = "slave")]
    slaves: Vec<RawSlave>,
    #[serde(default, rename = "group")]
    groups: Vec<RawGroup>,
    #[serde(default, rename = "copy")]
    copies: Vec<RawCopy>,
    #[serde(default, rename = "variable")]
    variables: Vec<RawVariable>,
    dc: Option<RawDc>,
}

#[derive(Debug, Deserialize)]
#[serde(deny_unknown_fields)]
struct RawDc {
    sync: Option<String>,
    sync0_shift_us: Option<Spanned<i64>>,
    sync1_us: Option<Spanned<i64>>,
    probe_budget_us: Option<Spanned<i64>>,
    static_frames: Option<Spanned<i64>>,
}

#[derive(Debug, Deserialize)]
#[serde(deny_unknown_fields)]
struct RawVariable {
    name: Spanned<String>,
    entry: Spanned<String>,
}

/// One transition or several.
#[derive(Debug, Clone, Deserialize)]
#[serde(untagged)]
enum Transitions {
    One(String),
    Many(Vec<String>),
}

#[derive(Debug, Deserialize)]
#[serde(deny_unknown_fields)]
struct RawInit {
    transition: Spanned<Transitions>,
    index: Spanned<Number>,
    subindex: Option<Spanned<Number>>,
    value: Option<Spanned<i64>>,
    #[serde(rename = "type")]
    ty: Option<Spanned<String>>,
    data: Option<Spanned<String>>,
    #[serde(default)]
    complete_access: bool,
    comment: Option<String>,
}

/// The transitions the master sends init commands at (ETG.2000's names).
pub const INIT_TRANSITIONS: [&str; 3] = ["IP", "PS", "SO"];

/// A value's type in an init command: its name, its width in bytes, and whether it is signed.
const INIT_TYPES: [(&str, usize, bool); 8] = [
    ("u8", 1, false),
    ("i8", 1, true),
    ("u16", 2, false),
    ("i16", 2, true),
    ("u32", 4, false),
    ("i32", 4, true),
    ("u64", 8, false),
    ("i64", 8, true),
];

#[derive(Debug, Deserialize)]
#[serde(deny_unknown_fields)]
struct RawCopy {
    from: Spanned<String>,
    to: Spanned<String>,
}

/// A slave of a group: its name in the description, or its position.
#[derive(Debug, Clone, Deserialize)]
#[serde(untagged)]
enum SlaveRef {
    Position(i64),
    Name(String),
}

#[derive(Debug, Deserialize)]
#[serde(deny_unknown_fields)]
struct RawGroup {
    name: Spanned<String>,
    slaves: Vec<Spanned<SlaveRef>>,
    every: Option<Spanned<i64>>,
}

#[derive(Debug, Deserialize)]
#[serde(deny_unknown_fields)]
struct RawSlave {
    name: Option<String>,
    vendor: Spanned<Number>,
    product: Spanned<Number>,
    revision: Option<Spanned<Number>>,
    revision_min: Option<Spanned<Number>>,
    revision_max: Option<Spanned<Number>>,
    serial: Option<Spanned<Number>>,
    alias: Option<Spanned<Number>>,
    #[serde(default)]
    optional: bool,
    device: Option<String>,
    watchdog_us: Option<Spanned<i64>>,
    rx_pdos: Option<Vec<Spanned<Number>>>,
    tx_pdos: Option<Vec<Spanned<Number>>>,
    #[serde(default)]
    init: Vec<RawInit>,
    sync0: Option<bool>,
    modules: Option<Vec<Spanned<Number>>>,
    assign_activate: Option<Spanned<Number>>,
}

/// Line and column of a byte offset in `text`.
fn place_at(text: &str, offset: usize) -> Place {
    let before = &text[..offset.min(text.len())];
    let line = before.matches('\n').count() as u32 + 1;
    let column = before.rsplit('\n').next().map_or(0, |l| l.chars().count()) as u32 + 1;
    Place { line, column }
}

/// How a description's numbers are read: the value, its key and its largest value.
type ReadNumber<'a> = &'a dyn Fn(&Spanned<Number>, &str, u64) -> Result<u32, DescriptionError>;

/// One `[[slave.init]]`: its transitions, object and the bytes it writes (a `value` in its
/// `type`'s width, little-endian as CoE sends numbers, or `data` as hex).
fn init_command(
    c: &RawInit,
    text: &str,
    err: &dyn Fn(&std::ops::Range<usize>, String) -> DescriptionError,
    num: ReadNumber<'_>,
) -> Result<ferrocat_esi::InitCmd, DescriptionError> {
    let transitions = match c.transition.get_ref() {
        Transitions::One(t) => vec![t.trim().to_uppercase()],
        Transitions::Many(v) => v.iter().map(|t| t.trim().to_uppercase()).collect(),
    };
    if let Some(t) = transitions.iter().find(|t| !INIT_TRANSITIONS.contains(&t.as_str())) {
        return Err(err(
            &c.transition.span(),
            format!("transition '{t}': the master sends init commands at {}", INIT_TRANSITIONS.join(", ")),
        ));
    }
    if transitions.is_empty() {
        return Err(err(&c.transition.span(), "transition: give at least one".into()));
    }
    let index = num(&c.index, "index", u16::MAX as u64)? as u16;
    let subindex = c.subindex.as_ref().map(|n| num(n, "subindex", u8::MAX as u64)).transpose()?.unwrap_or(0) as u8;
    let data = match (&c.value, &c.ty, &c.data) {
        (Some(v), Some(ty), None) => {
            let Some(&(_, bytes, signed)) = INIT_TYPES.iter().find(|(n, _, _)| *n == ty.get_ref().trim()) else {
                let names: Vec<&str> = INIT_TYPES.iter().map(|t| t.0).collect();
                return Err(err(&ty.span(), format!("type '{}': give one of {}", ty.get_ref(), names.join(", "))));
            };
            let x = *v.get_ref();
            let bits = bytes as u32 * 8;
            let fits = match (signed, bits) {
                (_, 64) => signed || x >= 0,
                (true, b) => (-(1i64 << (b - 1))..(1i64 << (b - 1))).contains(&x),
                (false, b) => (0..(1i64 << b)).contains(&x),
            };
            if !fits {
                return Err(err(&v.span(), format!("value = {x}: does not fit {}", ty.get_ref().trim())));
            }
            x.to_le_bytes()[..bytes].to_vec()
        }
        (None, None, Some(d)) => {
            let bytes = ferrocat_wire::hex::decode(d.get_ref()).map_err(|e| err(&d.span(), format!("data: {e}")))?;
            if bytes.is_empty() {
                return Err(err(&d.span(), "data: no bytes".into()));
            }
            bytes
        }
        (Some(v), None, None) => return Err(err(&v.span(), "value: give its type too (type = \"u16\", …)".into())),
        (None, Some(t), None) => return Err(err(&t.span(), "type: give the value too".into())),
        _ => {
            return Err(err(&c.index.span(), "give value and type, or data (hex bytes), not both".into()));
        }
    };
    Ok(ferrocat_esi::InitCmd {
        line: place_at(text, c.index.span().start).line,
        transitions,
        index,
        index_depends: ferrocat_esi::Depend::None,
        subindex,
        data,
        complete_access: c.complete_access,
        comment: c.comment.clone().unwrap_or_default(),
    })
}

impl Machine {
    /// Reads a description.
    pub fn parse(text: &str) -> Result<Machine, DescriptionError> {
        let raw: Raw = toml::from_str(text).map_err(|e| DescriptionError {
            place: e.span().map_or(Place { line: 1, column: 1 }, |s| place_at(text, s.start)),
            message: e.message().to_string(),
        })?;
        let err =
            |s: &std::ops::Range<usize>, message: String| DescriptionError { place: place_at(text, s.start), message };
        let num = |n: &Spanned<Number>, key: &str, max: u64| -> Result<u32, DescriptionError> {
            let v = match n.get_ref() {
                Number::Int(v) => u64::try_from(*v).ok(),
                Number::Text(t) if t.trim() == "any" => None,
                Number::Text(t) => ferrocat_esi::parse_number(t).and_then(|v| u64::try_from(v).ok()),
            };
            match v {
                Some(v) if v <= max => Ok(v as u32),
                Some(v) => Err(err(&n.span(), format!("{key} = {v}: more than {max:#x}"))),
                None => Err(err(&n.span(), format!("{key}: not a number"))),
            }
        };
        let mut slaves = Vec::with_capacity(raw.slaves.len());
        for (k, s) in raw.slaves.iter().enumerate() {
            if k > u16::MAX as usize {
                return Err(err(&s.vendor.span(), "more than 65 536 slaves".into()));
            }
            let any = |n: &Option<Spanned<Number>>| matches!(n.as_ref().map(|n| n.get_ref()), Some(Number::Text(t)) if t.trim() == "any");
            let revision = match (&s.revision, &s.revision_min, &s.revision_max) {
                (Some(_), _, _) if any(&s.revision) => {
                    if let Some(m) = s.revision_min.as_ref().or(s.revision_max.as_ref()) {
                        return Err(err(&m.span(), "revision = \"any\" takes no revision_min or revision_max".into()));
                    }
                    (RevisionCheck::Any, 0)
                }
                (Some(r), None, None) => {
                    let r = num(r, "revision", u32::MAX as u64)?;
                    (RevisionCheck::Exact, r)
                }
                (Some(r), _, _) => {
                    return Err(err(&r.span(), "give revision, or revision_min and revision_max, not both".into()))
                }
                (None, None, None) => (RevisionCheck::Any, 0),
                (None, min, max) => {
                    let min = min.as_ref().map(|m| num(m, "revision_min", u32::MAX as u64)).transpose()?.unwrap_or(0);
                    let max =
                        max.as_ref().map(|m| num(m, "revision_max", u32::MAX as u64)).transpose()?.unwrap_or(u32::MAX);
                    if min > max {
                        let at = s.revision_min.as_ref().map(|m| m.span()).unwrap_or_default();
                        return Err(err(&at, format!("revision_min {min:#x} is above revision_max {max:#x}")));
                    }
                    (RevisionCheck::Range { min, max }, min)
                }
            };
            let serial = s.serial.as_ref().map(|n| num(n, "serial", u32::MAX as u64)).transpose()?;
            let watchdog_us = match &s.watchdog_us {
                // 0x0420 counts 100 µs steps in 16 bits.
                Some(w) if (0..=6_553_500).contains(w.get_ref()) && w.get_ref() % 100 == 0 => Some(*w.get_ref() as u32),
                Some(w) => {
                    return Err(err(
                        &w.span(),
                        format!("watchdog_us = {}: give 0 (off) to 6 553 500 µs in steps of 100", w.get_ref()),
                    ))
                }
                None => None,
            };
            // CiA 301's mapping objects: RxPDOs 0x1600–0x17FF, TxPDOs 0x1A00–0x1BFF.
            let pdos = |list: &Option<Vec<Spanned<Number>>>, key: &str, range: std::ops::RangeInclusive<u32>| {
                let Some(list) = list else { return Ok(None) };
                if list.len() > 254 {
                    return Err(err(&list[254].span(), format!("{key}: more than 254 PDOs (0x1C12/0x1C13 hold 254)")));
                }
                let mut v = Vec::with_capacity(list.len());
                for n in list {
                    let p = num(n, key, u16::MAX as u64)?;
                    if !range.contains(&p) {
                        return Err(err(
                            &n.span(),
                            format!("{key}: {p:#06x} is not one of {:#06x} to {:#06x}", range.start(), range.end()),
                        ));
                    }
                    v.push(p as u16);
                }
                Ok(Some(v))
            };
            let rx_pdos = pdos(&s.rx_pdos, "rx_pdos", 0x1600..=0x17FF)?;
            let tx_pdos = pdos(&s.tx_pdos, "tx_pdos", 0x1A00..=0x1BFF)?;
            let modules = match &s.modules {
                // 0xF030:00 counts the slots in 8 bits.
                Some(list) if list.len() > 255 => {
                    return Err(err(&list[255].span(), "modules: more than 255 slots (0xF030 holds 255)".into()))
                }
                Some(list) => {
                    Some(list.iter().map(|n| num(n, "modules", u32::MAX as u64)).collect::<Result<Vec<_>, _>>()?)
                }
                None => None,
            };
            let mut init = Vec::with_capacity(s.init.len());
            for c in &s.init {
                init.push(init_command(c, text, &err, &num)?);
            }
            slaves.push(SlaveDesc {
                name: s.name.clone().unwrap_or_else(|| format!("slave {k}")),
                identity: Identity {
                    vendor_id: num(&s.vendor, "vendor", u32::MAX as u64)?,
                    product_code: num(&s.product, "product", u32::MAX as u64)?,
                    revision: revision.1,
                    serial: serial.unwrap_or(0),
                },
                revision: revision.0,
                check_serial: serial.is_some(),
                alias: s.alias.as_ref().map(|n| num(n, "alias", u16::MAX as u64).map(|v| v as u16)).transpose()?,
                optional: s.optional,
                device: s.device.clone(),
                watchdog_us,
                rx_pdos,
                tx_pdos,
                init,
                sync0: s.sync0,
                modules,
                assign_activate: s
                    .assign_activate
                    .as_ref()
                    .map(|n| num(n, "assign_activate", u16::MAX as u64).map(|v| v as u16))
                    .transpose()?,
            });
        }
        let mut groups = Vec::new();
        for g in &raw.groups {
            let every = match &g.every {
                Some(e) if (1..=1_000_000).contains(e.get_ref()) => *e.get_ref() as u32,
                Some(e) => return Err(err(&e.span(), format!("every = {}: give 1 to 1 000 000 cycles", e.get_ref()))),
                None => 1,
            };
            let mut positions = Vec::new();
            for r in &g.slaves {
                let p = match r.get_ref() {
                    SlaveRef::Position(p) if (0..slaves.len() as i64).contains(p) => *p as u16,
                    SlaveRef::Position(p) => {
                        return Err(err(
                            &r.span(),
                            format!("slave {p}: the description has slaves 0 to {}", slaves.len() as i64 - 1),
                        ))
                    }
                    SlaveRef::Name(n) => match slaves.iter().position(|s| &s.name == n) {
                        Some(p) => p as u16,
                        None => return Err(err(&r.span(), format!("no slave named '{n}'"))),
                    },
                };
                if let Some(other) = groups.iter().find(|o: &&GroupDesc| o.positions.contains(&p)) {
                    return Err(err(&r.span(), format!("slave {p} is in group '{}' already", other.name)));
                }
                positions.push(p);
            }
            groups.push(GroupDesc { name: g.name.get_ref().clone(), positions, every });
        }
        let mut copies = Vec::new();
        for c in &raw.copies {
            for end in [&c.from, &c.to] {
                let slave = end.get_ref().split_once(':').map(|(s, _)| s.trim());
                let known = slave.is_some_and(|s| {
                    slaves.iter().any(|d| d.name == s) || s.parse::<usize>().is_ok_and(|p| p < slaves.len())
                });
                if !known {
                    return Err(err(
                        &end.span(),
                        format!("'{}': give SLAVE:ENTRY, the slave by its name or position", end.get_ref()),
                    ));
                }
            }
            copies.push((c.from.get_ref().clone(), c.to.get_ref().clone()));
        }
        let mut variables: Vec<VariableDesc> = Vec::new();
        for v in &raw.variables {
            let name = v.name.get_ref().trim();
            if name.is_empty() || name.contains(':') {
                return Err(err(&v.name.span(), format!("'{name}': a variable's name is not empty and has no ':'")));
            }
            if variables.iter().any(|o| o.name == name) {
                return Err(err(&v.name.span(), format!("a variable named '{name}' is there already")));
            }
            let resolved = v.entry.get_ref().split_once(':').and_then(|(slave, entry)| {
                let slave = slave.trim();
                let position = slaves
                    .iter()
                    .position(|d| d.name == slave)
                    .or_else(|| slave.parse::<usize>().ok().filter(|&p| p < slaves.len()))?;
                Some((position as u16, entry.trim().to_string()))
            });
            let Some((position, entry)) = resolved.filter(|(_, e)| !e.is_empty()) else {
                return Err(err(
                    &v.entry.span(),
                    format!("'{}': give SLAVE:ENTRY, the slave by its name or position", v.entry.get_ref()),
                ));
            };
            variables.push(VariableDesc { name: name.to_string(), position, entry });
        }
        let dc = match &raw.dc {
            None => None,
            Some(d) => {
                // 0x0990/0x09A0 hold SYNC0's start and SYNC1's cycle in ns, 32 bits.
                let us = |v: &Option<Spanned<i64>>, key: &str| -> Result<Option<u32>, DescriptionError> {
                    match v {
                        Some(x) if (0..=4_000_000).contains(x.get_ref()) => Ok(Some(*x.get_ref() as u32)),
                        Some(x) => Err(err(&x.span(), format!("{key} = {}: give 0 to 4 000 000 µs", x.get_ref()))),
                        None => Ok(None),
                    }
                };
                let static_frames = match &d.static_frames {
                    Some(x) if (0..=1_000_000).contains(x.get_ref()) => Some(*x.get_ref() as u32),
                    Some(x) => {
                        return Err(err(&x.span(), format!("static_frames = {}: give 0 to 1 000 000", x.get_ref())))
                    }
                    None => None,
                };
                Some(DcDesc {
                    sync: d.sync.as_ref().map(|s| s.trim().to_string()),
                    sync0_shift_us: us(&d.sync0_shift_us, "sync0_shift_us")?,
                    sync1_us: us(&d.sync1_us, "sync1_us")?.unwrap_or(0),
                    probe_budget_us: us(&d.probe_budget_us, "probe_budget_us")?,
                    static_frames,
                })
            }
        };
        Ok(Machine { name: raw.name, slaves, groups, copies, variables, dc })
    }

    /// The slaves as the comparison takes them.
    pub fn expected(&self) -> Vec<Expected> {
        self.slaves
            .iter()
            .enumerate()
            .map(|(k, s)| Expected {
                position: k as u16,
                name: s.name.clone(),
                identity: s.identity,
                revision: s.revision,
                check_serial: s.check_serial,
                alias: s.alias,
                optional: s.optional,
            })
            .collect()
    }

    /// The description of a network as found: every slave by its SII name, its identity with
    /// the revision exactly, its alias where it has one; no serial number (a replaced unit of
    /// the same type would fail).
    pub fn from_found(name: Option<String>, found: &[Found]) -> Machine {
        let slaves = found
            .iter()
            .map(|f| SlaveDesc {
                name: f.name.clone(),
                identity: Identity { serial: 0, ..f.identity },
                revision: RevisionCheck::Exact,
                check_serial: false,
                alias: (f.alias != 0).then_some(f.alias),
                optional: false,
                device: None,
                watchdog_us: None,
                rx_pdos: None,
                tx_pdos: None,
                init: Vec::new(),
                sync0: None,
                modules: None,
                assign_activate: None,
            })
            .collect();
        Machine { name, slaves, groups: Vec::new(), copies: Vec::new(), variables: Vec::new(), dc: None }
    }

    /// The description as TOML that [`Machine::parse`] reads back, with a comment for each
    /// key a person may want to change.
    pub fn to_toml(&self) -> String {
        let quote = |s: &str| toml::Value::String(s.to_string()).to_string();
        let mut out = String::from(
            "# A ferrocat machine description (docs/machine.md): the slaves this machine expects, in\n\
             # network order. `ferrocat run --machine FILE` checks the network against it before any\n\
             # slave leaves INIT.\n",
        );
        if let Some(n) = &self.name {
            out += &format!("name = {}\n", quote(n));
        }
        for s in &self.slaves {
            out += "\n[[slave]]\n";
            out += &format!("name = {}\n", quote(&s.name));
            out += &format!("vendor = {:#x}\n", s.identity.vendor_id);
            out += &format!("product = {:#010x}\n", s.identity.product_code);
            match s.revision {
                RevisionCheck::Exact => {
                    out += &format!(
                        "revision = {:#010x}    # exactly; or revision_min/revision_max, or \"any\"\n",
                        s.identity.revision
                    )
                }
                RevisionCheck::Any => out += "revision = \"any\"\n",
                RevisionCheck::Range { min, max } => {
                    out += &format!("revision_min = {min:#010x}\nrevision_max = {max:#010x}\n");
                }
            }
            if s.check_serial {
                out += &format!("serial = {}\n", s.identity.serial);
            }
            if let Some(a) = s.alias {
                out += &format!("alias = {a:#06x}\n");
            }
            if s.optional {
                out += "optional = true\n";
            }
            if let Some(d) = &s.device {
                out += &format!("device = {}\n", quote(d));
            }
            if let Some(w) = s.watchdog_us {
                out += &format!("watchdog_us = {w}\n");
            }
            for (key, list) in [("rx_pdos", &s.rx_pdos), ("tx_pdos", &s.tx_pdos)] {
                if let Some(l) = list {
                    let l: Vec<String> = l.iter().map(|p| format!("{p:#06x}")).collect();
                    out += &format!("{key} = [{}]\n", l.join(", "));
                }
            }
            if let Some(on) = s.sync0 {
                out += &format!("sync0 = {on}\n");
            }
            if let Some(a) = s.assign_activate {
                out += &format!("assign_activate = {a:#06x}\n");
            }
            if let Some(m) = &s.modules {
                let m: Vec<String> = m.iter().map(|i| format!("{i:#x}")).collect();
                out += &format!("modules = [{}]\n", m.join(", "));
            }
            for c in &s.init {
                let t: Vec<String> = c.transitions.iter().map(|t| quote(t)).collect();
                let data: Vec<String> = c.data.iter().map(|b| format!("{b:02x}")).collect();
                out += &format!(
                    "\n[[slave.init]]\ntransition = [{}]\nindex = {:#06x}\nsubindex = {}\ndata = {}\n",
                    t.join(", "),
                    c.index,
                    c.subindex,
                    quote(&data.join(" "))
                );
                if c.complete_access {
                    out += "complete_access = true\n";
                }
                if !c.comment.is_empty() {
                    out += &format!("comment = {}\n", quote(&c.comment));
                }
            }
        }
        for g in &self.groups {
            let names: Vec<String> = g.positions.iter().map(|&p| quote(&self.slaves[p as usize].name)).collect();
            out += &format!(
                "\n[[group]]\nname = {}\nslaves = [{}]\nevery = {}\n",
                quote(&g.name),
                names.join(", "),
                g.every
            );
        }
        for (from, to) in &self.copies {
            out += &format!("\n[[copy]]\nfrom = {}\nto = {}\n", quote(from), quote(to));
        }
        if let Some(d) = &self.dc {
            out += "\n[dc]\n";
            if let Some(m) = &d.sync {
                out += &format!("sync = {}\n", quote(m));
            }
            if let Some(sh) = d.sync0_shift_us {
                out += &format!("sync0_shift_us = {sh}\n");
            }
            if d.sync1_us > 0 {
                out += &format!("sync1_us = {}\n", d.sync1_us);
            }
            if let Some(b) = d.probe_budget_us {
                out += &format!("probe_budget_us = {b}\n");
            }
            if let Some(n) = d.static_frames {
                out += &format!("static_frames = {n}\n");
            }
        }
        for v in &self.variables {
            // By name where that names this slave alone, else by position.
            let name = &self.slaves[v.position as usize].name;
            let unique = self.slaves.iter().filter(|s| &s.name == name).count() == 1;
            let plain = !name.contains(':') && name.trim() == name && name.parse::<usize>().is_err();
            let slave = if unique && plain { name.clone() } else { v.position.to_string() };
            out += &format!(
                "\n[[variable]]\nname = {}\nentry = {}\n",
                quote(&v.name),
                quote(&format!("{slave}:{}", v.entry))
            );
        }
        out
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_description_reads_writes_and_reads_back() {
        let text = "name = \"line 3\"\n[[copy]]\nfrom = \"slave 1:Input\"\nto = \"coupler:Output\"\n[[group]]\nname = \"slow\"\nslaves = [\"coupler\", 2]\nevery = 10\n\n[[slave]]\nname = \"coupler\"\nvendor = 0x2\nproduct = \"#x044C2C52\"\nrevision = 0x120000\ndevice = \"EK1100\"\nwatchdog_us = 20000\nrx_pdos = [0x1600, \"#x1601\"]\ntx_pdos = []\n\n[[slave]]\nvendor = 2\nproduct = 0x07D43052\nrevision_min = 0x100000\nrevision_max = 0x110000\nserial = 7\nalias = 0x10\noptional = true\n\n[[slave]]\nvendor = 0\nproduct = 0x402\nrevision = \"any\"\n";
        let m = Machine::parse(text).unwrap();
        assert_eq!(m.name.as_deref(), Some("line 3"));
        assert_eq!(
            m.slaves[0].identity,
            Identity { vendor_id: 2, product_code: 0x044C2C52, revision: 0x120000, serial: 0 }
        );
        assert_eq!(m.slaves[0].revision, RevisionCheck::Exact);
        assert_eq!(m.slaves[0].device.as_deref(), Some("EK1100"));
        assert_eq!((m.slaves[0].watchdog_us, m.slaves[1].watchdog_us), (Some(20_000), None));
        assert_eq!(
            (m.slaves[0].rx_pdos.as_deref(), m.slaves[0].tx_pdos.as_deref()),
            (Some(&[0x1600, 0x1601][..]), Some(&[][..]))
        );
        assert_eq!(m.slaves[1].rx_pdos, None);
        let s1 = &m.slaves[1];
        assert_eq!(s1.name, "slave 1");
        assert_eq!(s1.revision, RevisionCheck::Range { min: 0x100000, max: 0x110000 });
        assert!(s1.check_serial && s1.identity.serial == 7 && s1.alias == Some(0x10) && s1.optional);
        assert_eq!(m.slaves[2].revision, RevisionCheck::Any);
        assert_eq!(m.groups, [GroupDesc { name: "slow".into(), positions: vec![0, 2], every: 10 }]);
        assert_eq!(m.copies, [("slave 1:Input".to_string(), "coupler:Output".to_string())]);
        assert_eq!(Machine::parse(&m.to_toml()).unwrap(), m);
        // Init commands and variables.
        let text = format!(
            "{text}[[slave.init]]\ntransition = \"ps\"\nindex = 0x6060\nvalue = -3\ntype = \"i8\"\ncomment = \"mode\"\n\
             [[slave.init]]\ntransition = [\"PS\", \"SO\"]\nindex = \"#x8000\"\nsubindex = 0x11\ndata = \"01 02 0a\"\ncomplete_access = true\n\
             [[variable]]\nname = \"lamp\"\nentry = \"coupler:Output 1\"\n[[variable]]\nname = \"mode\"\nentry = \"2:Modes of operation\"\n"
        );
        let m = Machine::parse(&text).unwrap();
        let init = &m.slaves[2].init;
        assert_eq!(init.len(), 2);
        assert_eq!((init[0].transitions.clone(), init[0].index, init[0].subindex), (vec!["PS".to_string()], 0x6060, 0));
        assert_eq!((init[0].data.clone(), init[0].comment.as_str(), init[0].line), (vec![0xFD], "mode", 35));
        assert_eq!(init[1].transitions, ["PS", "SO"]);
        assert_eq!((init[1].index, init[1].subindex, init[1].data.clone()), (0x8000, 0x11, vec![1, 2, 0x0A]));
        assert!(init[1].complete_access && !init[0].complete_access);
        assert_eq!(
            m.variables,
            [
                VariableDesc { name: "lamp".into(), position: 0, entry: "Output 1".into() },
                VariableDesc { name: "mode".into(), position: 2, entry: "Modes of operation".into() }
            ]
        );
        let again = Machine::parse(&m.to_toml()).unwrap();
        let lines = |m: &Machine| m.slaves.iter().flat_map(|s| s.init.iter().map(|c| c.line)).collect::<Vec<_>>();
        // The written file puts each command on a line of its own; all else reads back the same.
        let strip = |mut m: Machine| {
            m.slaves.iter_mut().flat_map(|s| s.init.iter_mut()).for_each(|c| c.line = 0);
            m
        };
        assert_eq!(lines(&again).len(), 2);
        let dc = Machine::parse(&format!(
            "{text}[dc]\nsync = \"pi\"\nsync0_shift_us = 300\nsync1_us = 20\nprobe_budget_us = 40\nstatic_frames = 500\n"
        ))
        .unwrap();
        assert_eq!(
            dc.dc,
            Some(DcDesc {
                sync: Some("pi".into()),
                sync0_shift_us: Some(300),
                sync1_us: 20,
                probe_budget_us: Some(40),
                static_frames: Some(500)
            })
        );
        assert_eq!(strip(Machine::parse(&dc.to_toml()).unwrap()), strip(dc.clone()));
        let off = Machine::parse("[[slave]]\nvendor = 2\nproduct = 3\nsync0 = false\nmodules = [0x9010, \"#x9020\"]\n")
            .unwrap();
        assert_eq!((off.slaves[0].sync0, off.dc.clone()), (Some(false), None));
        assert_eq!(off.slaves[0].modules, Some(vec![0x9010, 0x9020]));
        let aa = Machine::parse("[[slave]]\nvendor = 2\nproduct = 3\nassign_activate = 0x0700\n").unwrap();
        assert_eq!(aa.slaves[0].assign_activate, Some(0x0700));
        assert_eq!(Machine::parse(&aa.to_toml()).unwrap(), aa);
        assert_eq!(Machine::parse(&off.to_toml()).unwrap(), off);
        assert_eq!(strip(again), strip(m.clone()));
        let e = m.expected();
        assert_eq!((e[1].position, e[1].alias, e[1].optional), (1, Some(0x10), true));
    }

    #[test]
    fn bad_descriptions_name_their_place() {
        let cases = [
            ("[[slave]]\nvendor = 2\nproduct = 3\nrevison = 1\n", (4, 1), "unknown field `revison`"),
            ("[[slave]]\nvendor = 2\n", (1, 1), "missing field `product`"),
            ("[[slave]]\nvendor = \"two\"\nproduct = 3\n", (2, 10), "vendor: not a number"),
            ("[[slave]]\nvendor = 0x100000000\nproduct = 3\n", (2, 10), "more than 0xffffffff"),
            ("[[slave]]\nvendor = -1\nproduct = 3\n", (2, 10), "vendor: not a number"),
            ("[[slave]]\nvendor = 2\nproduct = 3\nalias = 0x10000\n", (4, 9), "alias = 65536: more than 0xffff"),
            ("[[slave]]\nvendor = 2\nproduct = 3\nrevision = 1\nrevision_min = 1\n", (4, 12), "not both"),
            ("[[slave]]\nvendor = 2\nproduct = 3\nrevision_min = 5\nrevision_max = 4\n", (4, 16), "above revision_max"),
            (
                "[[slave]]\nvendor = 2\nproduct = 3\nrevision = \"any\"\nrevision_max = 4\n",
                (5, 16),
                "takes no revision_min",
            ),
            ("name = [\n", (2, 1), "invalid array"),
            ("[[slave]]\nvendor = 2\nproduct = 3\nwatchdog_us = 150\n", (4, 15), "in steps of 100"),
            ("[[slave]]\nvendor = 2\nproduct = 3\nwatchdog_us = 7000000\n", (4, 15), "6 553 500"),
            ("[[slave]]\nvendor = 2\nproduct = 3\nrx_pdos = [0x1600, 0x1A00]\n", (4, 20), "rx_pdos: 0x1a00 is not one of 0x1600 to 0x17ff"),
            ("[[slave]]\nvendor = 2\nproduct = 3\ntx_pdos = [\"x\"]\n", (4, 12), "tx_pdos: not a number"),
            ("[[slave]]\nvendor = 2\nproduct = 3\n[[group]]\nname = \"g\"\nslaves = [\"x\"]\n", (6, 11), "no slave named 'x'"),
            ("[[slave]]\nvendor = 2\nproduct = 3\n[[copy]]\nfrom = \"0:a\"\nto = \"x:b\"\n", (6, 6), "'x:b': give SLAVE:ENTRY"),
            ("[[slave]]\nvendor = 2\nproduct = 3\n[[group]]\nname = \"g\"\nslaves = [3]\n", (6, 11), "slave 3: the description has slaves 0 to 0"),
            ("[[slave]]\nvendor = 2\nproduct = 3\n[[group]]\nname = \"g\"\nslaves = [0]\nevery = 0\n", (7, 9), "every = 0"),
            ("[[slave]]\nvendor = 2\nproduct = 3\n[[group]]\nname = \"g\"\nslaves = [0]\n[[group]]\nname = \"h\"\nslaves = [0]\n", (9, 11), "slave 0 is in group 'g' already"),
            ("[[slave]]\nvendor = 2\nproduct = 3\n[[slave.init]]\ntransition = \"OI\"\nindex = 1\ndata = \"00\"\n", (5, 14), "transition 'OI': the master sends init commands at IP, PS, SO"),
            ("[[slave]]\nvendor = 2\nproduct = 3\n[[slave.init]]\ntransition = \"PS\"\nindex = 1\nvalue = 300\ntype = \"u8\"\n", (7, 9), "value = 300: does not fit u8"),
            ("[[slave]]\nvendor = 2\nproduct = 3\n[[slave.init]]\ntransition = \"PS\"\nindex = 1\nvalue = 3\ntype = \"word\"\n", (8, 8), "type 'word': give one of u8"),
            ("[[slave]]\nvendor = 2\nproduct = 3\n[[slave.init]]\ntransition = \"PS\"\nindex = 1\nvalue = 3\n", (7, 9), "give its type too"),
            ("[[slave]]\nvendor = 2\nproduct = 3\n[[slave.init]]\ntransition = \"PS\"\nindex = 1\ndata = \"0g\"\n", (7, 8), "data:"),
            ("[[slave]]\nvendor = 2\nproduct = 3\n[[slave.init]]\ntransition = \"PS\"\nindex = 0x10000\ndata = \"00\"\n", (6, 9), "index = 65536: more than 0xffff"),
            ("[[slave]]\nvendor = 2\nproduct = 3\n[[slave.init]]\ntransition = \"PS\"\nindex = 1\nvalue = 1\ntype = \"u8\"\ndata = \"00\"\n", (6, 9), "not both"),
            ("[dc]\nsync1_us = -1\n", (2, 12), "sync1_us = -1: give 0 to 4 000 000 µs"),
            ("[[slave]]\nvendor = 2\nproduct = 3\nmodules = [1, \"x\"]\n", (4, 15), "modules: not a number"),
            ("[[slave]]\nvendor = 2\nproduct = 3\nassign_activate = 0x10000\n", (4, 19), "assign_activate = 65536: more than 0xffff"),
            ("[dc]\nsync = \"pi\"\nlock = 3\n", (3, 1), "unknown field `lock`"),
            ("[[slave]]\nvendor = 2\nproduct = 3\n[[variable]]\nname = \"a:b\"\nentry = \"0:x\"\n", (5, 8), "has no ':'"),
            ("[[slave]]\nvendor = 2\nproduct = 3\n[[variable]]\nname = \"a\"\nentry = \"x\"\n", (6, 9), "'x': give SLAVE:ENTRY"),
            ("[[slave]]\nvendor = 2\nproduct = 3\n[[variable]]\nname = \"a\"\nentry = \"0:x\"\n[[variable]]\nname = \"a\"\nentry = \"0:y\"\n", (8, 8), "named 'a' is there already"),
        ];
        for (text, (line, column), want) in cases {
            let e = Machine::parse(text).unwrap_err();
            assert_eq!((e.place.line, e.place.column), (line, column), "{text}: {e}");
            assert!(e.message.contains(want), "{text}: {e}");
        }
    }
}
