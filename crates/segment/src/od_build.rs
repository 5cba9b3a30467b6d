//! Object dictionaries for simulated CoE devices: from an ESI `<Dictionary>`, completed from
//! the SII (identity, SyncManager types, PDO mapping and assignment) where the ESI is silent.
use ferrocat_esc::od::{data_type as dt, Access, Entry, Object, ObjectCode, ObjectDictionary};
use ferrocat_wire::sii::{Pdo, SiiInfo, SmEntry};

fn ro() -> Access {
    Access::RO
}

/// PDO assignment and mapping objects may only be written in PREOP.
fn rw_preop() -> Access {
    Access { read: true, write: true, write_preop_only: true, ..Default::default() }
}

fn u32_entry(sub: u8, name: &str, v: u32, access: Access) -> Entry {
    Entry {
        subindex: sub,
        name: name.into(),
        data_type: dt::UNSIGNED32,
        bit_len: 32,
        bit_offset: 0,
        access,
        value: v.to_le_bytes().to_vec(),
    }
}

fn widen(t: u8) -> u16 {
    t as u16
}

/// The dictionary a device with this SII implies.
pub fn from_sii(info: &SiiInfo) -> ObjectDictionary {
    let mut od = ObjectDictionary::default();
    let h = &info.header;
    let drive = info.general().is_some_and(|g| g.ds402_channels > 0);
    od.insert(Object::var(
        0x1000,
        "Device type",
        dt::UNSIGNED32,
        32,
        ro(),
        (if drive { 0x0002_0192u32 } else { 0 }).to_le_bytes().to_vec(),
    ));
    let name = info.name().unwrap_or_default();
    od.insert(Object::var(
        0x1008,
        "Device name",
        dt::VISIBLE_STRING,
        (name.len() * 8) as u16,
        ro(),
        name.bytes().collect(),
    ));
    od.insert(Object::list(
        0x1018,
        "Identity",
        ObjectCode::Record,
        dt::IDENTITY,
        ro(),
        vec![
            u32_entry(1, "Vendor ID", h.vendor_id, ro()),
            u32_entry(2, "Product code", h.product_code, ro()),
            u32_entry(3, "Revision", h.revision, ro()),
            u32_entry(4, "Serial number", h.serial, ro()),
        ],
    ));
    let sms = info.sync_managers();
    od.insert(Object::list(
        0x1C00,
        "Sync manager type",
        ObjectCode::Array,
        dt::UNSIGNED8,
        ro(),
        sms.iter()
            .enumerate()
            .map(|(i, s)| Entry {
                subindex: i as u8 + 1,
                name: format!("SM{i}"),
                data_type: dt::UNSIGNED8,
                bit_len: 8,
                bit_offset: 0,
                access: ro(),
                value: vec![s.sm_type],
            })
            .collect(),
    ));
    let out_sm = sms.iter().position(|s| s.sm_type == SmEntry::TYPE_OUTPUTS).unwrap_or(2) as u8;
    let in_sm = sms.iter().position(|s| s.sm_type == SmEntry::TYPE_INPUTS).unwrap_or(3) as u8;
    add_pdos(&mut od, info.rx_pdos(), out_sm, 0x1C12, true, info);
    add_pdos(&mut od, info.tx_pdos(), in_sm, 0x1C13, false, info);
    od
}

fn add_pdos(od: &mut ObjectDictionary, pdos: &[Pdo], sm: u8, assign: u16, rx: bool, info: &SiiInfo) {
    for p in pdos {
        let entries = p
            .entries
            .iter()
            .enumerate()
            .map(|(k, e)| {
                u32_entry(
                    k as u8 + 1,
                    &format!("Mapping {}", k + 1),
                    (e.index as u32) << 16 | (e.subindex as u32) << 8 | e.bit_len as u32,
                    rw_preop(),
                )
            })
            .collect();
        let name = info.string(p.name_idx).unwrap_or_else(|| format!("PDO {:#06x}", p.index));
        od.insert(Object::list(p.index, &name, ObjectCode::Record, dt::PDO_MAPPING, rw_preop(), entries));
        for e in &p.entries {
            if e.index == 0 || od.get(e.index).is_some_and(|o| o.entry(e.subindex).is_some()) {
                continue;
            }
            let access = Access { read: true, write: rx, rx_mappable: rx, tx_mappable: !rx, ..Default::default() };
            let entry_name = info.string(e.name_idx).unwrap_or_else(|| format!("{:#06x}:{:02x}", e.index, e.subindex));
            let entry = Entry {
                subindex: e.subindex,
                name: entry_name.clone(),
                data_type: widen(e.data_type),
                bit_len: e.bit_len as u16,
                bit_offset: 0,
                access,
                value: vec![0; (e.bit_len as usize).div_ceil(8)],
            };
            if e.subindex == 0 {
                od.insert(Object::var(e.index, &entry_name, entry.data_type, entry.bit_len, access, entry.value));
            } else {
                let o = od
                    .objects
                    .entry(e.index)
                    .or_insert_with(|| Object::list(e.index, &entry_name, ObjectCode::Record, 0, ro(), vec![]));
                o.entries.push(Entry { bit_offset: 16 * e.subindex as u32, ..entry });
                let n = o.entries.iter().filter(|x| x.subindex > 0).map(|x| x.subindex).max().unwrap_or(0);
                if let Some(s0) = o.entry_mut(0) {
                    s0.value = vec![n];
                }
            }
        }
    }
    let assigned: Vec<u16> = pdos.iter().filter(|p| p.sync_manager == sm).map(|p| p.index).collect();
    if od.get(assign).is_none() {
        let capacity = pdos.len().max(1);
        let mut items: Vec<Entry> = (0..capacity)
            .map(|k| Entry {
                subindex: k as u8 + 1,
                name: format!("PDO {}", k + 1),
                data_type: dt::UNSIGNED16,
                bit_len: 16,
                bit_offset: 0,
                access: rw_preop(),
                value: assigned.get(k).copied().unwrap_or(0).to_le_bytes().to_vec(),
            })
            .collect();
        items.truncate(capacity);
        let mut o = Object::list(
            assign,
            if rx { "RxPDO assign" } else { "TxPDO assign" },
            ObjectCode::Array,
            dt::UNSIGNED16,
            rw_preop(),
            items,
        );
        if let Some(s0) = o.entry_mut(0) {
            s0.value = vec![assigned.len() as u8];
        }
        od.insert(o);
    }
}

/// The dictionary of an ESI device, completed from its SII where the ESI has no object.
pub fn from_esi(dev: &ferrocat_esi::Device, info: &SiiInfo) -> ObjectDictionary {
    let mut od = ObjectDictionary::default();
    if let Some(dict) = &dev.dictionary {
        for o in &dict.objects {
            let ty = |name: &str| widen(ferrocat_esi::coe_data_type(name));
            let mapping_or_assign = matches!(o.index, 0x1600..=0x17FF | 0x1A00..=0x1BFF | 0x1C12 | 0x1C13);
            let access = |a: ferrocat_esi::Access, pm: &Option<String>| Access {
                read: a.read,
                write: a.write,
                write_preop_only: mapping_or_assign,
                rx_mappable: pm.as_deref().is_some_and(|p| p.contains('R')),
                tx_mappable: pm.as_deref().is_some_and(|p| p.contains('T')),
            };
            let value = |d: &Option<Vec<u8>>, bits: u32| {
                let mut v = d.clone().unwrap_or_default();
                v.resize((bits as usize).div_ceil(8).max(v.len().min(255)), 0);
                v.truncate((bits as usize).div_ceil(8).max(1));
                v
            };
            let obj = if o.subs.is_empty() {
                let bits = o.bit_size.clamp(1, u16::MAX as u32);
                Object::var(
                    o.index,
                    &o.name,
                    ty(&o.type_name),
                    bits as u16,
                    access(o.access, &o.pdo_mapping),
                    value(&o.default_data, bits),
                )
            } else {
                let entries = o
                    .subs
                    .iter()
                    .map(|s| Entry {
                        subindex: s.subindex,
                        name: s.name.clone(),
                        data_type: ty(&s.type_name),
                        bit_len: s.bit_size.clamp(1, u16::MAX as u32) as u16,
                        bit_offset: s.bit_offset,
                        access: access(s.access, &o.pdo_mapping),
                        value: value(&s.default_data, s.bit_size.max(1)),
                    })
                    .collect();
                Object {
                    index: o.index,
                    name: o.name.clone(),
                    code: if o.is_array { ObjectCode::Array } else { ObjectCode::Record },
                    data_type: ty(&o.type_name),
                    entries,
                }
            };
            od.insert(obj);
        }
    }
    for (i, o) in from_sii(info).objects {
        od.objects.entry(i).or_insert(o);
    }
    add_init_command_targets(&mut od, &dev.init_cmds);
    // The assignment the ESI defines by default (PDOs with an Sm attribute); a modular device's
    // is the plugged modules' whatever its dictionary's default says, as its firmware fills it
    // from the modules it detects.
    // A PDO assigned to a further SyncManager of its direction (a TwinSAFE controller's SM6
    // beside SM2) is in that SyncManager's assignment object, 0x1C10 + n, made where the
    // dictionary lacks it (ETG.1000.6: 0x1C10–0x1C2F, one per SyncManager).
    let sms = info.sync_managers();
    let further = |p: &ferrocat_esi::PdoDesc, sm_type: u8, first: u8| {
        p.sm.filter(|&n| n != first && sms.get(n as usize).is_some_and(|s| s.sm_type == sm_type))
    };
    let mut assignments: Vec<(u16, Vec<u16>)> = Vec::new();
    for (pdos, sm_type, first) in [(&dev.rx_pdos, SmEntry::TYPE_OUTPUTS, 2u8), (&dev.tx_pdos, SmEntry::TYPE_INPUTS, 3)]
    {
        let main: Vec<u16> =
            pdos.iter().filter(|p| p.sm.is_some() && further(p, sm_type, first).is_none()).map(|p| p.index).collect();
        assignments.push((0x1C10 + first as u16, main));
        let mut more: Vec<u8> = pdos.iter().filter_map(|p| further(p, sm_type, first)).collect();
        more.sort_unstable();
        more.dedup();
        for n in more {
            let assign = 0x1C10 + n as u16;
            if od.get(assign).is_none() {
                let name = format!("SM{n} PDO assign");
                od.insert(Object::list(assign, &name, ObjectCode::Array, dt::UNSIGNED16, rw_preop(), vec![]));
            }
            let listed = pdos.iter().filter(|p| further(p, sm_type, first) == Some(n)).map(|p| p.index).collect();
            assignments.push((assign, listed));
        }
    }
    for (assign, default) in assignments {
        if let Some(o) = od.objects.get_mut(&assign) {
            let has_default = o.entry(0).and_then(|e| e.value.first()).is_some_and(|&n| n > 0);
            if (!has_default || dev.slots.is_some()) && !default.is_empty() {
                for (k, idx) in default.iter().enumerate() {
                    let sub = k as u8 + 1;
                    if o.entry(sub).is_none() {
                        // More PDOs than the dictionary's object has room for: it grows.
                        o.entries.push(Entry {
                            subindex: sub,
                            name: format!("PDO {sub}"),
                            data_type: dt::UNSIGNED16,
                            bit_len: 16,
                            bit_offset: 16 * sub as u32,
                            access: rw_preop(),
                            value: vec![0; 2],
                        });
                    }
                    if let Some(e) = o.entry_mut(sub) {
                        e.value = idx.to_le_bytes().to_vec();
                    }
                }
                if let Some(e) = o.entry_mut(0) {
                    e.value = vec![default.len() as u8];
                }
            }
        }
    }
    od
}

/// The objects the device's own init commands write, where its dictionary lacks them (a file
/// without `<Dictionary>`, or one that leaves out a vendor object): the vendor says the device
/// takes them, so the simulated one does, writable, as long as the command's data, zero until
/// written (the device's own default is not in the file). A model choice: the real device's
/// object may be longer or typed otherwise, and an application model (a CiA402 drive) keeps
/// its own objects' types where it defines them. Complete-access
/// commands are left alone (their layout is not known from the data).
fn add_init_command_targets(od: &mut ObjectDictionary, cmds: &[ferrocat_esi::InitCmd]) {
    for c in cmds.iter().filter(|c| !c.complete_access && !c.data.is_empty()) {
        if od.get(c.index).is_some_and(|o| o.entry(c.subindex).is_some()) {
            continue;
        }
        let bits = (c.data.len() * 8).min(u16::MAX as usize) as u16;
        let data_type = match c.data.len() {
            1 => dt::UNSIGNED8,
            2 => dt::UNSIGNED16,
            4 => dt::UNSIGNED32,
            8 => dt::UNSIGNED64,
            _ => dt::OCTET_STRING,
        };
        let access = Access { read: true, write: true, ..Default::default() };
        let name = format!("{:#06x}:{:02x} (an init command's)", c.index, c.subindex);
        if c.subindex == 0 && od.get(c.index).is_none() {
            od.insert(Object::var(c.index, &name, data_type, bits, access, vec![0; c.data.len()]));
            continue;
        }
        let o = od
            .objects
            .entry(c.index)
            .or_insert_with(|| Object::list(c.index, &name, ObjectCode::Record, 0, Access::RO, vec![]));
        let bit_offset = o.entries.iter().map(|e| e.bit_offset + e.bit_len as u32).max().unwrap_or(16);
        let value = vec![0; c.data.len()];
        o.entries.push(Entry { subindex: c.subindex, name, data_type, bit_len: bits, bit_offset, access, value });
        o.entries.sort_by_key(|e| e.subindex);
        let n = o.entries.iter().map(|e| e.subindex).max().unwrap_or(0);
        if let Some(s0) = o.entry_mut(0) {
            s0.value = vec![n];
        }
    }
}

/// The Modular Device Profile's objects (ETG.5001): 0xF000 (the object index distance between
/// modules and their greatest number, unless the ESI defines it), 0xF030, the configured module
/// idents the master writes in PREOP (empty until it does), and 0xF050, the modules detected,
/// slot by slot. A device refuses SAFEOP while a configured list differs from the detected one
/// (`CoeDevice::check_transition`).
pub fn add_module_lists(od: &mut ObjectDictionary, slots: &ferrocat_esi::Slots, plugged: &[u32]) {
    if od.get(0xF000).is_none() {
        let max: u32 = slots.slots.iter().map(|s| s.max_instances as u32).sum();
        let sub = |subindex: u8, name: &str, v: u16| Entry {
            subindex,
            name: name.into(),
            data_type: dt::UNSIGNED16,
            bit_len: 16,
            bit_offset: 0,
            access: Access::RO,
            value: v.to_le_bytes().to_vec(),
        };
        od.insert(Object::list(
            0xF000,
            "Modular device profile",
            ObjectCode::Record,
            dt::UNSIGNED16,
            Access::RO,
            vec![
                sub(1, "Index distance", slots.slot_index_increment),
                sub(2, "Maximum number of modules", max.min(u16::MAX as u32) as u16),
            ],
        ));
    }
    let entries = |access: Access, values: &[u32]| {
        values
            .iter()
            .enumerate()
            .map(|(k, v)| Entry {
                subindex: k as u8 + 1,
                name: format!("Module {}", k + 1),
                data_type: dt::UNSIGNED32,
                bit_len: 32,
                bit_offset: 0,
                access,
                value: v.to_le_bytes().to_vec(),
            })
            .collect::<Vec<_>>()
    };
    let preop = Access { write_preop_only: true, ..Access::RW };
    let mut configured = Object::list(
        0xF030,
        "Configured module ident list",
        ObjectCode::Array,
        dt::UNSIGNED32,
        preop,
        entries(preop, &vec![0; plugged.len()]),
    );
    if let Some(sub0) = configured.entry_mut(0) {
        sub0.value = vec![0];
    }
    od.insert(configured);
    od.insert(Object::list(
        0xF050,
        "Detected module ident list",
        ObjectCode::Array,
        dt::UNSIGNED32,
        Access::RO,
        entries(Access::RO, plugged),
    ));
}
