//! A CoE object dictionary: objects with their subindices, access rights and current values.
use std::collections::BTreeMap;

use ferrocat_wire::coe::AbortCode;
use ferrocat_wire::register::AlState;

pub use ferrocat_wire::coe::data_type;
use ferrocat_wire::coe::object_code;

/// Object codes of SDO information.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum ObjectCode {
    Var = object_code::VAR as isize,
    Array = object_code::ARRAY as isize,
    Record = object_code::RECORD as isize,
}

#[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
pub struct Access {
    pub read: bool,
    pub write: bool,
    /// Writable only in PREOP (PDO assignment and mapping, most parameters per ESI
    /// WriteRestrictions="PreOP").
    pub write_preop_only: bool,
    pub rx_mappable: bool,
    pub tx_mappable: bool,
}

impl Access {
    pub const RO: Access =
        Access { read: true, write: false, write_preop_only: false, rx_mappable: false, tx_mappable: false };
    pub const RW: Access =
        Access { read: true, write: true, write_preop_only: false, rx_mappable: false, tx_mappable: false };

    /// The 16-bit object access word of an entry description (ETG.1000.6 §5.6.3.6).
    pub fn word(&self) -> u16 {
        let r = if self.read { 0b000111 } else { 0 };
        let w = if self.write {
            if self.write_preop_only {
                0b001000
            } else {
                0b111000
            }
        } else {
            0
        };
        r | w | if self.rx_mappable { 1 << 6 } else { 0 } | if self.tx_mappable { 1 << 7 } else { 0 }
    }
}

#[derive(Debug, Clone, PartialEq, Eq)]
pub struct Entry {
    pub subindex: u8,
    pub name: String,
    pub data_type: u16,
    pub bit_len: u16,
    /// Bit offset of the entry in a complete-access transfer.
    pub bit_offset: u32,
    pub access: Access,
    /// Current value, `bit_len.div_ceil(8)` bytes, little-endian.
    pub value: Vec<u8>,
}

#[derive(Debug, Clone, PartialEq, Eq)]
pub struct Object {
    pub index: u16,
    pub name: String,
    pub code: ObjectCode,
    pub data_type: u16,
    /// Subindex 0 first for arrays and records; a single entry for variables.
    pub entries: Vec<Entry>,
}

impl Object {
    pub fn entry(&self, sub: u8) -> Option<&Entry> {
        self.entries.iter().find(|e| e.subindex == sub)
    }
    pub fn entry_mut(&mut self, sub: u8) -> Option<&mut Entry> {
        self.entries.iter_mut().find(|e| e.subindex == sub)
    }
    pub fn max_subindex(&self) -> u8 {
        self.entries.iter().map(|e| e.subindex).max().unwrap_or(0)
    }

    /// A variable.
    pub fn var(index: u16, name: &str, data_type: u16, bit_len: u16, access: Access, value: Vec<u8>) -> Self {
        let mut value = value;
        value.resize((bit_len as usize).div_ceil(8), 0);
        Object {
            index,
            name: name.into(),
            code: ObjectCode::Var,
            data_type,
            entries: vec![Entry { subindex: 0, name: name.into(), data_type, bit_len, bit_offset: 0, access, value }],
        }
    }

    /// A record or array: subindex 0 (u8, the number of entries, padded to 16 bits) then the
    /// entries packed by their sizes, as ESI files lay them out (an array of USINT, 0x1C00,
    /// takes a byte per element).
    pub fn list(
        index: u16,
        name: &str,
        code: ObjectCode,
        data_type: u16,
        sub0_access: Access,
        items: Vec<Entry>,
    ) -> Self {
        let mut entries = vec![Entry {
            subindex: 0,
            name: "Number of entries".into(),
            data_type: data_type::UNSIGNED8,
            bit_len: 8,
            bit_offset: 0,
            access: sub0_access,
            value: vec![items.len() as u8],
        }];
        let mut off = 16;
        for mut e in items {
            e.bit_offset = off;
            off += (e.bit_len as u32).max(1);
            entries.push(e);
        }
        Object { index, name: name.into(), code, data_type, entries }
    }
}

/// The dictionary, ordered by index.
#[derive(Debug, Clone, Default, PartialEq, Eq)]
pub struct ObjectDictionary {
    pub objects: BTreeMap<u16, Object>,
}

impl ObjectDictionary {
    pub fn insert(&mut self, o: Object) {
        self.objects.insert(o.index, o);
    }

    pub fn get(&self, index: u16) -> Option<&Object> {
        self.objects.get(&index)
    }

    /// The value of an entry, or the abort code a read would get.
    pub fn read(&self, index: u16, sub: u8) -> Result<&[u8], AbortCode> {
        let o = self.objects.get(&index).ok_or(AbortCode::NO_OBJECT)?;
        let e = o.entry(sub).ok_or(AbortCode::NO_SUBINDEX)?;
        if !e.access.read {
            return Err(AbortCode::WRITE_ONLY);
        }
        Ok(&e.value)
    }

    /// A complete-access read from subindex `from` (0 or 1): the entries laid out at their
    /// bit offsets (subindex 0 as one byte, padded to 16 bits).
    pub fn read_complete(&self, index: u16, from: u8) -> Result<Vec<u8>, AbortCode> {
        let o = self.objects.get(&index).ok_or(AbortCode::NO_OBJECT)?;
        if o.code == ObjectCode::Var || from > 1 {
            return Err(AbortCode::COMPLETE_ACCESS_UNSUPPORTED);
        }
        // The whole object, every subindex, whatever subindex 0 currently says.
        let mut out = Vec::new();
        for e in &o.entries {
            if e.subindex < from {
                continue;
            }
            let at = if e.subindex == 0 { 0 } else { ((e.bit_offset - if from == 1 { 16 } else { 0 }) / 8) as usize };
            let len = if e.subindex == 0 { 2 } else { e.value.len() };
            if out.len() < at + len {
                out.resize(at + len, 0);
            }
            out[at..at + e.value.len()].copy_from_slice(&e.value);
        }
        Ok(out)
    }

    /// Checks and performs a write; `state` decides PREOP-only entries.
    pub fn write(&mut self, index: u16, sub: u8, data: &[u8], state: AlState) -> Result<(), AbortCode> {
        let o = self.objects.get_mut(&index).ok_or(AbortCode::NO_OBJECT)?;
        let e = o.entry_mut(sub).ok_or(AbortCode::NO_SUBINDEX)?;
        if !e.access.write {
            return Err(AbortCode::READ_ONLY);
        }
        if e.access.write_preop_only && state != AlState::PreOp {
            return Err(AbortCode::DEVICE_STATE);
        }
        let len = e.value.len();
        let is_string = matches!(e.data_type, data_type::VISIBLE_STRING | data_type::OCTET_STRING);
        if data.len() > len && !is_string {
            return Err(AbortCode::LENGTH_TOO_HIGH);
        }
        if data.len() < len && !is_string {
            return Err(AbortCode::LENGTH_TOO_LOW);
        }
        e.value = data.to_vec();
        if is_string {
            e.value.resize(len, 0);
        }
        Ok(())
    }

    /// A complete-access write from subindex `from`: subindex 0 and then every entry.
    pub fn write_complete(&mut self, index: u16, from: u8, data: &[u8], state: AlState) -> Result<(), AbortCode> {
        let o = self.objects.get(&index).ok_or(AbortCode::NO_OBJECT)?;
        if o.code == ObjectCode::Var || from > 1 {
            return Err(AbortCode::COMPLETE_ACCESS_UNSUPPORTED);
        }
        let base = if from == 1 { 16 } else { 0 };
        let n = if from == 0 { *data.first().ok_or(AbortCode::LENGTH_TOO_LOW)? } else { o.max_subindex() };
        if n > o.max_subindex() {
            return Err(AbortCode::VALUE_TOO_HIGH);
        }
        let plan: Vec<(u8, usize, usize)> = o
            .entries
            .iter()
            .filter(|e| e.subindex >= 1 && e.subindex <= n)
            .map(|e| (e.subindex, ((e.bit_offset - base) / 8) as usize, e.value.len()))
            .collect();
        let need = plan.iter().map(|(_, at, len)| at + len).max().unwrap_or(0);
        if data.len() < need {
            return Err(AbortCode::LENGTH_TOO_LOW);
        }
        // A writable subindex 0 goes to 0 first (mapping rules), then the entries, then the
        // count; a read-only one must already hold the count written.
        let sub0_writable = o.entry(0).is_some_and(|e| e.access.write);
        let current_n = o.entry(0).and_then(|e| e.value.first()).copied().unwrap_or(0);
        if from == 0 {
            if sub0_writable {
                self.write(index, 0, &[0], state)?;
            } else if n != current_n {
                return Err(AbortCode::READ_ONLY);
            }
        }
        for (sub, at, len) in plan {
            self.write(index, sub, &data[at..at + len], state)?;
        }
        if from == 0 && sub0_writable {
            self.write(index, 0, &[n], state)?;
        }
        Ok(())
    }
}
