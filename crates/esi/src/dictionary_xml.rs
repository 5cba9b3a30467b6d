//! Reading an ESI `<Dictionary>` into a [`Dictionary`].
use roxmltree::Node;

use crate::dictionary::{Access, DataType, DataTypeSubItem, Dictionary, Object, SubObject};
use crate::parse::{child, child_number, child_text, children, err, hex_bytes, name_of, number, text, warn, R};

impl Access {
    pub(crate) fn parse(s: &str) -> Access {
        match s.trim() {
            "ro" => Access { read: true, write: false },
            "wo" => Access { read: false, write: true },
            "rw" => Access { read: true, write: true },
            _ => Access { read: true, write: false },
        }
    }
}

fn access_of(node: Node<'_, '_>) -> Option<Access> {
    child(node, "Flags").and_then(|f| child(f, "Access")).map(|a| Access::parse(text(a)))
}

pub(crate) fn parse_dictionary(dict: Node<'_, '_>) -> R<Dictionary> {
    let mut d = Dictionary::default();
    if let Some(types) = child(dict, "DataTypes") {
        for t in children(types, "DataType") {
            let array = match child(t, "ArrayInfo") {
                Some(a) => Some((child_number(a, "LBound")?.unwrap_or(0), child_number(a, "Elements")?.unwrap_or(0))),
                None => None,
            };
            let mut subitems = Vec::new();
            for s in children(t, "SubItem") {
                subitems.push(DataTypeSubItem {
                    subindex: child_number(s, "SubIdx")?,
                    name: child_text(s, "Name").unwrap_or_default(),
                    type_name: child_text(s, "Type").unwrap_or_default(),
                    bit_size: child_number(s, "BitSize")?.unwrap_or(0),
                    bit_offset: child_number(s, "BitOffs")?.unwrap_or(0),
                    access: access_of(s),
                });
            }
            let name = child_text(t, "Name").unwrap_or_default();
            if d.data_types.iter().any(|o| o.name == name) {
                warn(t, format!("data type {name} is defined again: the first is the one used"));
            }
            d.data_types.push(DataType {
                name,
                base_type: child_text(t, "BaseType"),
                bit_size: child_number(t, "BitSize")?.unwrap_or(0),
                array,
                subitems,
            });
        }
    }
    if let Some(objs) = child(dict, "Objects") {
        for o in children(objs, "Object") {
            let obj = parse_object(&d, o)?;
            if d.objects.iter().any(|x| x.index == obj.index) {
                warn(o, format!("object {:#06x} ({}) is defined again: the first kept", obj.index, obj.name));
                continue;
            }
            d.objects.push(obj);
        }
    }
    Ok(d)
}

/// A `<DefaultValue>` as the bytes of a value of `bits` (little-endian, as `<DefaultData>`
/// writes them): a string type's text as it stands, else a number (`#x…` or decimal). One that
/// is no number or does not fit is left out with a warning.
fn default_value(node: Node<'_, '_>, bits: u32, type_name: &str) -> Option<Vec<u8>> {
    let raw = text(node);
    if type_name.to_ascii_uppercase().contains("STRING") {
        return Some(raw.as_bytes().to_vec());
    }
    let Some(v) = crate::number::parse_number(raw) else {
        warn(node, format!("<DefaultValue> '{raw}' is not a number: no default read"));
        return None;
    };
    let bytes = (bits.div_ceil(8) as usize).clamp(1, 8);
    let fits = bits >= 64 || (v >= -(1i64 << (bits.max(1) - 1)) && v < (1i64 << bits.max(1)));
    if !fits {
        warn(node, format!("<DefaultValue> {raw} does not fit {bits} bits: no default read"));
        return None;
    }
    Some(v.to_le_bytes()[..bytes].to_vec())
}

fn parse_object(d: &Dictionary, o: Node<'_, '_>) -> R<Object> {
    let index = child(o, "Index").ok_or_else(|| err(o, "<Object> lacks <Index>"))?;
    let index: u16 = number(index, text(index), "object <Index>")?;
    let type_name = child_text(o, "Type").unwrap_or_default();
    let access = access_of(o).unwrap_or_default();
    let info = child(o, "Info");
    // `<DefaultData>` is the value's bytes; `<DefaultValue>` the value itself (a number, or a
    // string's text), as Inovance's files give their PDO mappings' defaults.
    let default_of = |n: Option<Node<'_, '_>>, bits: u32, type_name: &str| -> R<Option<Vec<u8>>> {
        let Some(i) = n else { return Ok(None) };
        if let Some(dd) = child(i, "DefaultData") {
            return hex_bytes(dd, text(dd)).map(Some);
        }
        Ok(child(i, "DefaultValue").and_then(|dv| default_value(dv, bits, type_name)))
    };
    let mut obj = Object {
        index,
        index_depends: crate::parse::depends(o),
        name: name_of(o),
        bit_size: child_number(o, "BitSize")?.unwrap_or(0),
        access,
        pdo_mapping: child(o, "Flags").and_then(|f| child_text(f, "PdoMapping")),
        default_data: default_of(info, child_number(o, "BitSize")?.unwrap_or(0), &type_name)?,
        subs: Vec::new(),
        is_array: false,
        type_name,
    };
    // Expand records and arrays into subindices.
    if let Some(t) = d.data_type(&obj.type_name) {
        for si in &t.subitems {
            match d.data_type(&si.type_name).filter(|at| at.array.is_some()) {
                Some(at) => {
                    obj.is_array = true;
                    let (_, n) = at.array.unwrap_or((0, 0));
                    let base = at.base_type.as_deref().and_then(|b| d.data_type(b)).map(|b| b.bit_size).unwrap_or(0);
                    let elem_bits = at.bit_size.checked_div(n).unwrap_or(base);
                    let first = si.subindex.unwrap_or(1);
                    for k in 0..n {
                        let Ok(sub) = u8::try_from(first as u32 + k) else { break };
                        obj.subs.push(SubObject {
                            subindex: sub,
                            name: format!("{} {}", si.name, k + 1),
                            type_name: at.base_type.clone().unwrap_or_default(),
                            bit_size: elem_bits,
                            bit_offset: si.bit_offset + k * elem_bits,
                            access: si.access.unwrap_or(access),
                            default_data: None,
                        });
                    }
                }
                None => obj.subs.push(SubObject {
                    subindex: si.subindex.unwrap_or(obj.subs.len() as u8),
                    name: si.name.clone(),
                    type_name: si.type_name.clone(),
                    bit_size: si.bit_size,
                    bit_offset: si.bit_offset,
                    access: si.access.unwrap_or(access),
                    default_data: None,
                }),
            }
        }
        // Info/SubItem carries per-subindex names and defaults, in subindex order.
        if let Some(info) = info {
            for (k, s) in children(info, "SubItem").enumerate() {
                if let Some(sub) = obj.subs.get_mut(k) {
                    sub.default_data = default_of(child(s, "Info"), sub.bit_size, &sub.type_name)?;
                    if let Some(dn) = child(s, "Info").and_then(|i| child_text(i, "DisplayName")) {
                        sub.name = dn;
                    }
                }
            }
        }
    }
    Ok(obj)
}
