//! `ferrocat esi`: devices of an ESI file, and the SII images built from them.
use std::path::Path;
use std::process::ExitCode;

use anyhow::{bail, Context};
use ferrocat_esi::{parse_number, Device, EsiFile};
use serde_json::json;

use crate::outln;

fn select<'a>(file: &'a EsiFile, sel: &str) -> anyhow::Result<&'a Device> {
    if let Ok(i) = sel.parse::<usize>() {
        return file.devices.get(i).with_context(|| {
            format!(
                "device {i}: the file has {} devices (0–{})",
                file.devices.len(),
                file.devices.len().saturating_sub(1)
            )
        });
    }
    let (p, r) = match sel.split_once(':') {
        Some((p, r)) => (p, Some(r)),
        None => (sel, None),
    };
    let num = |s: &str| -> anyhow::Result<u32> {
        parse_number(s)
            .and_then(|v| u32::try_from(v).ok())
            .with_context(|| format!("--device {sel}: '{s}' is not a number"))
    };
    let revision = r.map(num).transpose()?;
    // A product code, else a device's type name (any case).
    let code = num(p).ok();
    let matches = |d: &Device| code.map_or(d.type_name.eq_ignore_ascii_case(p), |c| d.product_code == c);
    let what = code.map_or(format!("type {p}"), |c| format!("product code {c:#010x}"));
    let found: Vec<&Device> =
        file.devices.iter().filter(|d| matches(d) && revision.is_none_or(|r| d.revision == r)).collect();
    // Without a revision, the newest; of equal ones the first in the file.
    let chosen =
        found.iter().copied().reduce(|best, d| if d.revision > best.revision { d } else { best }).with_context(
            || format!("no device with {what}{}", revision.map(|r| format!(" revision {r:#010x}")).unwrap_or_default()),
        )?;
    let mut revisions: Vec<u32> = found.iter().map(|d| d.revision).collect();
    revisions.sort_unstable();
    revisions.dedup();
    if revisions.len() > 1 {
        let all: Vec<String> = revisions.iter().map(|r| format!("{r:#010x}")).collect();
        eprintln!(
            "note: {what} has {} revisions in the file ({}): the newest, {:#010x}, is shown; --device {p}:REVISION chooses another",
            revisions.len(),
            all.join(", "),
            chosen.revision
        );
    }
    Ok(chosen)
}

pub fn run(
    path: &Path,
    device: Option<&str>,
    sii_out: Option<&Path>,
    json: bool,
    strict: bool,
) -> anyhow::Result<ExitCode> {
    let xml = ferrocat_segment::files::read_esi(path).with_context(|| format!("reading {}", path.display()))?;
    let mut file = EsiFile::parse(&xml).with_context(|| format!("{}", path.display()))?;
    for m in ferrocat_segment::files::add_module_files(path, &mut file) {
        eprintln!("modules also from {} (an <EtherCATModule> file beside it)", m.display());
    }
    let level = if strict { "error" } else { "warning" };
    for w in &file.warnings {
        eprintln!("{level}: {}: {w}", path.display());
    }
    if strict && !file.warnings.is_empty() {
        bail!(
            "{}: {} deviation{} from ETG.2000 that vendors' tools accept (--strict refuses them)",
            path.display(),
            file.warnings.len(),
            if file.warnings.len() == 1 { "" } else { "s" }
        );
    }
    if file.devices.is_empty() && file.passive.is_empty() && !file.modules.is_empty() {
        // A module file (<EtherCATModule>): its modules, for the devices whose slots name them.
        if device.is_some() || sii_out.is_some() {
            bail!("{}: a module file (<EtherCATModule>) describes no device", path.display());
        }
        if json {
            let modules: Vec<_> = file
                .modules
                .iter()
                .map(|m| {
                    json!({
                        "ident": m.ident, "type": m.type_name, "name": m.name, "class": m.class, "line": m.line,
                        "rx_pdos": m.rx_pdos.len(), "tx_pdos": m.tx_pdos.len(),
                    })
                })
                .collect();
            outln!(
                "{}",
                json!({"vendor_id": file.vendor_id, "vendor": file.vendor_name, "devices": [], "passive": [], "modules": modules})
            );
        } else {
            outln!("{}: module file, vendor {:#010x} {}", path.display(), file.vendor_id, file.vendor_name);
            for m in &file.modules {
                outln!(
                    "  MODULE {:#010x} {:14} {} ({} RxPDO, {} TxPDO)",
                    m.ident,
                    m.type_name,
                    m.name,
                    m.rx_pdos.len(),
                    m.tx_pdos.len()
                );
            }
        }
        return Ok(ExitCode::SUCCESS);
    }
    if file.devices.is_empty() && file.passive.is_empty() {
        bail!("{}: the file describes no device (no Descriptions/Devices/Device)", path.display());
    }
    if let Some(p) = device.and_then(|sel| file.passive.iter().find(|p| p.type_name.eq_ignore_ascii_case(sel.trim()))) {
        bail!(
            "{}: {} (line {}) is a passive device: no ESC, no EtherCAT identity, nothing to describe or simulate",
            path.display(),
            p.type_name,
            p.line
        );
    }
    let chosen = match (device, sii_out) {
        (Some(sel), _) => Some(select(&file, sel)?),
        (None, Some(_)) if file.devices.len() == 1 => Some(&file.devices[0]),
        (None, Some(_)) => {
            bail!("{} describes {} devices: choose one with --device", path.display(), file.devices.len())
        }
        (None, None) => None,
    };
    let Some(d) = chosen else {
        if json {
            let v: Vec<_> = file.devices.iter().enumerate().map(|(i, d)| json!({
                "position": i, "type": d.type_name, "name": d.name, "product_code": d.product_code, "revision": d.revision,
            })).collect();
            let passive: Vec<_> =
                file.passive.iter().map(|p| json!({"type": p.type_name, "name": p.name, "line": p.line})).collect();
            outln!(
                "{}",
                json!({"vendor_id": file.vendor_id, "vendor": file.vendor_name, "devices": v, "passive": passive})
            );
        } else {
            outln!("{}: vendor {:#010x} {}", path.display(), file.vendor_id, file.vendor_name);
            for (i, d) in file.devices.iter().enumerate() {
                outln!(
                    "{i:3}  product {:#010x} revision {:#010x}  {:14} {}",
                    d.product_code,
                    d.revision,
                    d.type_name,
                    d.name
                );
            }
            for p in &file.passive {
                outln!("     passive (no ESC, no EtherCAT identity)  {:14} {}", p.type_name, p.name);
            }
        }
        return Ok(ExitCode::SUCCESS);
    };
    if let Some(out) = sii_out {
        let img = d.to_sii(file.vendor_id).with_context(|| format!("building the SII image of {}", d.type_name))?;
        std::fs::write(out, &img).with_context(|| format!("writing {}", out.display()))?;
        eprintln!("wrote {} ({} bytes) for {} revision {:#010x}", out.display(), img.len(), d.type_name, d.revision);
    }
    if json {
        outln!(
            "{}",
            json!({
                "type": d.type_name, "name": d.name, "vendor_id": file.vendor_id, "product_code": d.product_code, "revision": d.revision,
                "profile": d.profile_no,
                "sync_managers": d.sync_managers.iter().map(|s| json!({"kind": format!("{:?}", s.kind), "start": s.start, "default_size": s.default_size, "control": s.control, "enable": s.enable})).collect::<Vec<_>>(),
                "rx_pdos": d.rx_pdos.iter().map(|p| json!({"index": p.index, "name": p.name, "sm": p.sm, "bit_len": p.bit_len()})).collect::<Vec<_>>(),
                "tx_pdos": d.tx_pdos.iter().map(|p| json!({"index": p.index, "name": p.name, "sm": p.sm, "bit_len": p.bit_len()})).collect::<Vec<_>>(),
                "dc_op_modes": d.dc_op_modes.iter().map(|m| json!({"name": m.name, "assign_activate": m.assign_activate, "cycle_time_sync0_ns": m.cycle_time_sync0_ns, "shift_time_sync0_ns": m.shift_time_sync0_ns})).collect::<Vec<_>>(),
                "objects": d.dictionary.as_ref().map(|x| x.objects.len()).unwrap_or(0),
                "slots": d.slots.as_ref().map(|s| json!({
                    "slot_index_increment": s.slot_index_increment, "slot_pdo_increment": s.slot_pdo_increment,
                    "slot_group_index_increment": s.slot_group_index_increment, "slot_group_pdo_increment": s.slot_group_pdo_increment,
                    "slots": s.slots.iter().map(|x| json!({
                        "name": x.name, "min_instances": x.min_instances, "max_instances": x.max_instances,
                        "slot_group": x.slot_group, "module_idents": x.module_idents, "default_module": x.default_module,
                        "module_classes": x.module_classes,
                    })).collect::<Vec<_>>(),
                })),
                "modules": modules_of(&file, d).iter().map(|m| json!({
                    "ident": m.ident, "type": m.type_name, "name": m.name, "class": m.class,
                    "rx_pdos": m.rx_pdos.iter().map(|p| json!({"index": p.index, "name": p.name, "bit_len": p.bit_len()})).collect::<Vec<_>>(),
                    "tx_pdos": m.tx_pdos.iter().map(|p| json!({"index": p.index, "name": p.name, "bit_len": p.bit_len()})).collect::<Vec<_>>(),
                    "objects": m.dictionary.as_ref().map_or(0, |d| d.objects.len()),
                    "init_cmds": m.init_cmds.iter().map(init_cmd_json).collect::<Vec<_>>(),
                    "soe_init_cmds": m.soe_init_cmds.iter().map(soe_init_cmd_json).collect::<Vec<_>>(),
                })).collect::<Vec<_>>(),
                "init_cmds": d.init_cmds.iter().map(init_cmd_json).collect::<Vec<_>>(),
                "soe_init_cmds": d.soe_init_cmds.iter().map(soe_init_cmd_json).collect::<Vec<_>>(),
                "warnings": file.warnings.iter().map(|w| w.to_string()).collect::<Vec<_>>(),
            })
        );
    } else if sii_out.is_none() {
        outln!(
            "{} — {} (vendor {:#010x} product {:#010x} revision {:#010x}, line {})",
            d.type_name,
            d.name,
            file.vendor_id,
            d.product_code,
            d.revision,
            d.line
        );
        for s in &d.sync_managers {
            outln!(
                "  SM  {:?} start {:#06x} size {} control {:#04x} enable {}",
                s.kind,
                s.start,
                s.default_size.map_or("from the PDOs".into(), |b| format!("{b} bytes")),
                s.control,
                s.enable
            );
        }
        for (kind, pdos) in [("RxPDO", &d.rx_pdos), ("TxPDO", &d.tx_pdos)] {
            for p in pdos {
                let sm = p.sm.map_or("unassigned (the master may assign it)".into(), |n| format!("SM{n}"));
                outln!("  {kind} {:#06x} {:?} {sm} ({} bits)", p.index, p.name, p.bit_len());
                for e in &p.entries {
                    outln!(
                        "        {:#06x}:{:#04x} {:2} bits {} {:?}",
                        e.index,
                        e.subindex,
                        e.bit_len,
                        e.data_type,
                        e.name
                    );
                }
            }
        }
        for m in &d.dc_op_modes {
            outln!(
                "  DC  {:?} AssignActivate {:#06x} SYNC0 {} ns shift {} ns",
                m.name,
                m.assign_activate,
                m.cycle_time_sync0_ns,
                m.shift_time_sync0_ns
            );
        }
        if let Some(dict) = &d.dictionary {
            outln!("  object dictionary: {} objects", dict.objects.len());
        }
        if let Some(slots) = &d.slots {
            outln!(
                "  slots: object index + {:#x} and PDO index + {:#x} per slot{}",
                slots.slot_index_increment,
                slots.slot_pdo_increment,
                if slots.slot_group_index_increment + slots.slot_group_pdo_increment > 0 {
                    format!(
                        "; + {:#x} and + {:#x} per slot group",
                        slots.slot_group_index_increment, slots.slot_group_pdo_increment
                    )
                } else {
                    String::new()
                }
            );
            for s in &slots.slots {
                let idents = s
                    .module_idents
                    .iter()
                    .map(|&i| {
                        if Some(i) == s.default_module {
                            format!("{i:#010x} (default)")
                        } else {
                            format!("{i:#010x}")
                        }
                    })
                    .chain(s.module_classes.iter().map(|c| format!("class {c}")))
                    .collect::<Vec<_>>()
                    .join(", ");
                outln!("  SLOT {:?} ×{}–{}: {idents}", s.name, s.min_instances, s.max_instances);
            }
            for m in modules_of(&file, d) {
                outln!(
                    "  MODULE {:#010x} {} {:?}{}",
                    m.ident,
                    m.type_name,
                    m.name,
                    m.class.as_ref().map(|c| format!(" class {c}")).unwrap_or_default()
                );
                for (kind, pdos) in [("RxPDO", &m.rx_pdos), ("TxPDO", &m.tx_pdos)] {
                    for p in pdos {
                        outln!("         {kind} {:#06x} {:?} ({} bits)", p.index, p.name, p.bit_len());
                    }
                }
                if let Some(n) = m.dictionary.as_ref().map(|d| d.objects.len()).filter(|&n| n > 0) {
                    outln!("         {n} objects");
                }
                for c in &m.init_cmds {
                    outln!("         {}", init_cmd_text(c));
                }
                for c in &m.soe_init_cmds {
                    outln!("         {}", soe_init_cmd_text(c));
                }
            }
        }
        for c in &d.init_cmds {
            outln!("  {}", init_cmd_text(c));
        }
        for c in &d.soe_init_cmds {
            outln!("  {}", soe_init_cmd_text(c));
        }
    }
    Ok(ExitCode::SUCCESS)
}

/// "INIT PS 0x8000:03 ← 0x5552… (Name …)"; a slot-dependent index marked "+slot".
fn init_cmd_text(c: &ferrocat_esi::InitCmd) -> String {
    let hex: String = c.data.iter().map(|b| format!("{b:02x}")).collect();
    let slot = if c.index_depends == ferrocat_esi::Depend::None { "" } else { " +slot" };
    let ca = if c.complete_access { " (complete access)" } else { "" };
    format!("INIT {} {:#06x}:{:#04x}{slot} ← {hex}{ca} {:?}", c.transitions.join(","), c.index, c.subindex, c.comment)
}

/// "SoE PS P-0-0001 drive 0 ← fa00 (value) "Gain"".
fn soe_init_cmd_text(c: &ferrocat_esi::SoeInitCmd) -> String {
    let hex: String = c.data.iter().map(|b| format!("{b:02x}")).collect();
    let elements = ferrocat_wire::soe::Elements::NAMES
        .iter()
        .filter(|(_, e)| c.elements.0 & e.0 != 0)
        .map(|(n, _)| *n)
        .collect::<Vec<_>>()
        .join(",");
    format!("SoE {} {} drive {} ← {hex} ({elements}) {:?}", c.transitions.join(","), c.idn, c.drive, c.comment)
}

fn soe_init_cmd_json(c: &ferrocat_esi::SoeInitCmd) -> serde_json::Value {
    json!({"transitions": c.transitions, "idn": c.idn.to_string(), "drive": c.drive, "elements": c.elements.0,
        "data": c.data, "timeout_ms": c.timeout_ms, "comment": c.comment})
}

fn init_cmd_json(c: &ferrocat_esi::InitCmd) -> serde_json::Value {
    json!({"transitions": c.transitions, "index": c.index, "depends_on_slot": c.index_depends != ferrocat_esi::Depend::None,
        "subindex": c.subindex, "data": c.data, "complete_access": c.complete_access, "comment": c.comment})
}

/// The modules that fit `d`'s slots: by ident, or by class; all of the file's where a slot
/// names neither.
fn modules_of<'a>(file: &'a EsiFile, d: &Device) -> Vec<&'a ferrocat_esi::ModuleDesc> {
    let Some(slots) = &d.slots else { return Vec::new() };
    file.modules.iter().filter(|m| slots.slots.iter().any(|s| s.fits(m))).collect()
}
