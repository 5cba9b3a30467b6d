//! `ferrocat sii`: decode an EEPROM image.
use std::path::Path;
use std::process::ExitCode;

use anyhow::Context;
use ferrocat_wire::sii::dump::parse_dump;
use ferrocat_wire::sii::{category, fmmu_usage, mailbox_protocol, CategoryRepr, Pdo, SiiImage, SiiInfo};
use serde_json::{json, Value};

use crate::outln;
use crate::pcap::hex;

/// Reads an EEPROM image file in any supported dump format.
pub fn load(path: &Path) -> anyhow::Result<Vec<u8>> {
    let raw = ferrocat_segment::files::read_eeprom_dump(path).with_context(|| format!("reading {}", path.display()))?;
    let (bytes, _) = parse_dump(&raw).with_context(|| format!("{}: not a readable EEPROM dump", path.display()))?;
    Ok(bytes)
}

fn protocols(mask: u16) -> String {
    let names = [
        (mailbox_protocol::AOE, "AoE"),
        (mailbox_protocol::EOE, "EoE"),
        (mailbox_protocol::COE, "CoE"),
        (mailbox_protocol::FOE, "FoE"),
        (mailbox_protocol::SOE, "SoE"),
        (mailbox_protocol::VOE, "VoE"),
    ];
    let v: Vec<_> = names.iter().filter(|(b, _)| mask & b != 0).map(|(_, n)| *n).collect();
    if v.is_empty() {
        "none".into()
    } else {
        v.join(" ")
    }
}

fn fmmu_name(u: u8) -> &'static str {
    match u {
        fmmu_usage::OUTPUTS => "Outputs",
        fmmu_usage::INPUTS => "Inputs",
        fmmu_usage::SM_STATUS => "MBoxState",
        _ => "unused",
    }
}

fn sm_type_name(t: u8) -> &'static str {
    match t {
        1 => "MBoxOut",
        2 => "MBoxIn",
        3 => "Outputs",
        4 => "Inputs",
        _ => "unused",
    }
}

fn pdos_json(info: &SiiInfo, pdos: &[Pdo]) -> Value {
    pdos.iter()
        .map(|p| {
            json!({
                "index": p.index, "name": info.string(p.name_idx), "sm": p.sync_manager, "flags": p.flags,
                "bit_len": p.bit_len(),
                "entries": p.entries.iter().map(|e| json!({
                    "index": e.index, "subindex": e.subindex, "name": info.string(e.name_idx),
                    "data_type": e.data_type, "bit_len": e.bit_len, "flags": e.flags,
                })).collect::<Vec<_>>(),
            })
        })
        .collect()
}

pub fn run(path: &Path, json: bool) -> anyhow::Result<ExitCode> {
    let bytes = load(path)?;
    let info = SiiInfo::from_image(&bytes).with_context(|| format!("{}: malformed SII image", path.display()))?;
    let crc = SiiImage::parse(&bytes)?.check_crc();
    let h = &info.header;
    let g = info.general();
    if json {
        let o = json!({
            "file": path.display().to_string(),
            "size": bytes.len(),
            "vendor_id": h.vendor_id, "product_code": h.product_code, "revision": h.revision, "serial": h.serial,
            "name": info.name(),
            "crc_ok": crc.is_ok(), "checksum": h.checksum,
            "pdi_control": h.pdi_control, "pdi_config": h.pdi_config, "sync_impulse_len": h.sync_impulse_len,
            "station_alias": h.station_alias,
            "mailbox": { "rx_offset": h.mailbox_rx_offset, "rx_size": h.mailbox_rx_size,
                         "tx_offset": h.mailbox_tx_offset, "tx_size": h.mailbox_tx_size, "protocols": h.mailbox_protocols },
            "bootstrap": { "rx_offset": h.bootstrap_rx_offset, "rx_size": h.bootstrap_rx_size,
                           "tx_offset": h.bootstrap_tx_offset, "tx_size": h.bootstrap_tx_size },
            "eeprom_size_bytes": h.eeprom_size_bytes(), "version": h.version,
            "strings": info.strings().iter().map(|s| s.iter().map(|&b| b as char).collect::<String>()).collect::<Vec<_>>(),
            "general": g.map(|g| json!({
                "group": info.string(g.group_idx), "order": info.string(g.order_idx), "name": info.string(g.name_idx),
                "coe_details": g.coe_details, "foe_details": g.foe_details, "eoe_details": g.eoe_details,
                "soe_channels": g.soe_channels, "ds402_channels": g.ds402_channels, "flags": g.flags,
                "ebus_current_ma": g.current_on_ebus_ma, "physical_ports": g.physical_ports,
            })),
            "fmmus": info.fmmus().iter().map(|&u| fmmu_name(u)).collect::<Vec<_>>(),
            "sync_managers": info.sync_managers().iter().map(|s| json!({
                "start": s.start, "length": s.length, "control": s.control, "status": s.status,
                "enable": s.enable, "type": s.sm_type,
            })).collect::<Vec<_>>(),
            "tx_pdos": pdos_json(&info, info.tx_pdos()),
            "rx_pdos": pdos_json(&info, info.rx_pdos()),
            "dc_op_modes": info.dc_op_modes().iter().map(|m| json!({
                "name": info.string(m.name_idx), "description": info.string(m.desc_idx),
                "assign_activate": m.assign_activate, "cycle_time0": m.cycle_time0, "shift_time0": m.shift_time0,
                "shift_time1": m.shift_time1, "sync0_cycle_factor": m.sync0_cycle_factor,
                "sync1_cycle_factor": m.sync1_cycle_factor,
            })).collect::<Vec<_>>(),
            "other_categories": info.categories.iter().filter_map(|c| match &c.repr {
                CategoryRepr::Other { kind, data } => Some(json!({"type": kind, "data": hex(data)})),
                _ => None,
            }).collect::<Vec<_>>(),
        });
        outln!("{o:#}");
        return Ok(ExitCode::SUCCESS);
    }
    outln!("{}: {} bytes", path.display(), bytes.len());
    outln!("Name:       {}", info.name().unwrap_or_default());
    outln!(
        "Identity:   vendor {:#010x} product {:#010x} revision {:#010x} serial {:#010x}",
        h.vendor_id,
        h.product_code,
        h.revision,
        h.serial
    );
    match &crc {
        Ok(()) => outln!("Header CRC: {:#04x} ok", h.checksum & 0xFF),
        Err(e) => outln!("Header CRC: {e}"),
    }
    outln!(
        "PDI:        control {:#06x} config {:#06x} config2 {:#06x}; SYNC pulse {} ns; alias {}",
        h.pdi_control,
        h.pdi_config,
        h.pdi_config2,
        h.sync_impulse_len as u32 * 10,
        h.station_alias
    );
    outln!(
        "Mailbox:    out {:#06x}/{} in {:#06x}/{} protocols {}",
        h.mailbox_rx_offset,
        h.mailbox_rx_size,
        h.mailbox_tx_offset,
        h.mailbox_tx_size,
        protocols(h.mailbox_protocols)
    );
    outln!(
        "Bootstrap:  out {:#06x}/{} in {:#06x}/{}",
        h.bootstrap_rx_offset,
        h.bootstrap_rx_size,
        h.bootstrap_tx_offset,
        h.bootstrap_tx_size
    );
    outln!("EEPROM:     {} bytes, SII version {}", h.eeprom_size_bytes(), h.version);
    if let Some(g) = g {
        outln!(
            "General:    group {:?} order {:?}; CoE details {:#04x} FoE {:#04x} EoE {:#04x}; E-Bus current {}; ports {:#06x}",
            info.string(g.group_idx).unwrap_or_default(),
            info.string(g.order_idx).unwrap_or_default(),
            g.coe_details,
            g.foe_details,
            g.eoe_details,
            match g.current_on_ebus_ma {
                // A negative figure is what the device feeds into the E-Bus (a coupler's supply).
                ma if ma < 0 => format!("{ma} mA (it supplies {} mA to the E-Bus)", -(ma as i32)),
                ma => format!("{ma} mA (it draws from the E-Bus)"),
            },
            g.physical_ports
        );
    }
    for (i, u) in info.fmmus().iter().enumerate() {
        outln!("FMMU{i}:      {}", fmmu_name(*u));
    }
    for (i, s) in info.sync_managers().iter().enumerate() {
        outln!(
            "SM{i}:        start {:#06x} length {:4} control {:#04x} enable {:#04x} {}",
            s.start,
            s.length,
            s.control,
            s.enable,
            sm_type_name(s.sm_type)
        );
    }
    for (kind, pdos) in [("TxPDO", info.tx_pdos()), ("RxPDO", info.rx_pdos())] {
        for p in pdos {
            outln!(
                "{kind}      {:#06x} {:?} SM{} ({} bits)",
                p.index,
                info.string(p.name_idx).unwrap_or_default(),
                p.sync_manager,
                p.bit_len()
            );
            for e in &p.entries {
                outln!(
                    "              {:#06x}:{:#04x} {:2} bits type {:#04x} {:?}",
                    e.index,
                    e.subindex,
                    e.bit_len,
                    e.data_type,
                    info.string(e.name_idx).unwrap_or_default()
                );
            }
        }
    }
    for m in info.dc_op_modes() {
        outln!(
            "DC op-mode: {:?} AssignActivate {:#06x} SYNC0 cycle {} ns shift {} ns; SYNC1 shift {} ns",
            info.string(m.name_idx).unwrap_or_default(),
            m.assign_activate,
            m.cycle_time0,
            m.shift_time0,
            m.shift_time1
        );
    }
    for c in &info.categories {
        if let CategoryRepr::Other { kind, data } = &c.repr {
            outln!("Category:   {} ({kind}), {} bytes kept raw", category::name(*kind), data.len());
        }
    }
    Ok(ExitCode::SUCCESS)
}
