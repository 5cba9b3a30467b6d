//! SII images from device descriptions (ETG.2010 categories, esc-spec §5.4).
use ferrocat_wire::sii::{
    fmmu_usage, mailbox_protocol, CategoryRepr, DcOpMode, General, Pdo, PdoEntry, SiiHeader, SiiInfo, SmEntry,
};

use crate::{Device, FmmuKind, PdoDesc, SmKind};

/// CoE data type index (CiA 301 / ETG.1000.6 Table 64) of an ESI type name; 0 if unknown.
pub fn coe_data_type(name: &str) -> u8 {
    match name {
        "BOOL" | "BIT" => 0x01,
        "SINT" => 0x02,
        "INT" => 0x03,
        "DINT" => 0x04,
        "USINT" | "BYTE" => 0x05,
        "UINT" | "WORD" => 0x06,
        "UDINT" | "DWORD" => 0x07,
        "REAL" => 0x08,
        "LREAL" => 0x11,
        "LINT" => 0x15,
        "ULINT" | "LWORD" => 0x1B,
        "BIT1" => 0x30,
        "BIT2" => 0x31,
        "BIT3" => 0x32,
        "BIT4" => 0x33,
        "BIT5" => 0x34,
        "BIT6" => 0x35,
        "BIT7" => 0x36,
        "BIT8" => 0x37,
        n if n.starts_with("STRING") => 0x09,
        _ => 0,
    }
}

/// Port type nibble (ETG.2010 general category) of a Physics character.
fn port_type(c: char) -> u16 {
    match c {
        'Y' => 1, // MII / 100BASE-TX
        'K' => 3, // E-Bus
        'H' => 4, // fast hot-connect MII
        _ => 0,
    }
}

fn word(bytes: &[u8], i: usize) -> Option<u16> {
    Some(u16::from_le_bytes([*bytes.get(2 * i)?, *bytes.get(2 * i + 1)?]))
}

/// EEPROM bytes: the ESI's ByteSize, else the smallest power of two (≥ 2 KiB) that holds the image.
pub(crate) fn eeprom_size(dev: &Device, info: &SiiInfo) -> usize {
    let needed = info.to_image().len();
    match dev.eeprom.as_ref().and_then(|e| e.byte_size) {
        Some(n) if n as usize >= needed => n as usize,
        _ => needed.next_power_of_two().max(2048),
    }
}

fn pdos(list: &[PdoDesc], info: &mut SiiInfo) -> Vec<Pdo> {
    list.iter()
        .map(|p| Pdo {
            index: p.index,
            // 0xFF: not assigned to a SyncManager by default (SOEM skips such PDOs).
            sync_manager: p.sm.unwrap_or(0xFF),
            synchronization: 0,
            name_idx: info.intern(&p.name),
            flags: (p.mandatory as u16) | if p.fixed { 0x0010 } else { 0 },
            entries: p
                .entries
                .iter()
                .map(|e| PdoEntry {
                    index: e.index,
                    subindex: e.subindex,
                    name_idx: info.intern(&e.name),
                    data_type: coe_data_type(&e.data_type),
                    bit_len: e.bit_len,
                    flags: 0,
                })
                .collect(),
        })
        .collect()
}

pub(crate) fn sii_info(dev: &Device, vendor_id: u32) -> SiiInfo {
    let mut info = SiiInfo::default();
    let mut h = SiiHeader {
        vendor_id,
        product_code: dev.product_code,
        revision: dev.revision,
        version: 1,
        ..Default::default()
    };
    if let Some(e) = &dev.eeprom {
        let c = &e.config_data;
        h.pdi_control = word(c, 0).unwrap_or(0);
        h.pdi_config = word(c, 1).unwrap_or(0);
        h.sync_impulse_len = word(c, 2).unwrap_or(0);
        h.pdi_config2 = word(c, 3).unwrap_or(0);
        h.station_alias = word(c, 4).unwrap_or(0);
        let b = &e.bootstrap;
        h.bootstrap_rx_offset = word(b, 0).unwrap_or(0);
        h.bootstrap_rx_size = word(b, 1).unwrap_or(0);
        h.bootstrap_tx_offset = word(b, 2).unwrap_or(0);
        h.bootstrap_tx_size = word(b, 3).unwrap_or(0);
        if let Some(n) = e.byte_size {
            // Word 0x3E holds the size in KiBit minus one.
            h.eeprom_size = ((n as u64 * 8 / 1024).max(1) - 1).min(u16::MAX as u64) as u16;
        }
    }
    if dev.eeprom.as_ref().is_none_or(|e| e.config_data.is_empty()) && !dev.dc_op_modes.is_empty() {
        // No ConfigData, but DC operation modes: the ESC configuration byte (0x0141) with the
        // SYNC out and latch units on (bits 2 and 3), without which an ET1100 has no system
        // time. A builder's default where the file is silent, not a vendor's value.
        h.pdi_control = 0x0C00;
    }
    for sm in &dev.sync_managers {
        match sm.kind {
            SmKind::MailboxOut => {
                h.mailbox_rx_offset = sm.start;
                h.mailbox_rx_size = sm.default_size.unwrap_or(0);
            }
            SmKind::MailboxIn => {
                h.mailbox_tx_offset = sm.start;
                h.mailbox_tx_size = sm.default_size.unwrap_or(0);
            }
            _ => {}
        }
    }
    let mut general = General::default();
    if let Some(m) = &dev.mailbox {
        let bit = |on: bool, b: u16| if on { b } else { 0 };
        h.mailbox_protocols = bit(m.aoe, mailbox_protocol::AOE)
            | bit(m.eoe, mailbox_protocol::EOE)
            | bit(m.coe.is_some(), mailbox_protocol::COE)
            | bit(m.foe, mailbox_protocol::FOE)
            | bit(m.soe, mailbox_protocol::SOE)
            | bit(m.voe, mailbox_protocol::VOE);
        if let Some(c) = &m.coe {
            // ETG.2010 CoE details: SDO, SDO info, PDO assign, PDO config, upload, complete access.
            general.coe_details = 0x01
                | (c.sdo_info as u8) << 1
                | (c.pdo_assign as u8) << 2
                | (c.pdo_config as u8) << 3
                | (c.pdo_upload as u8) << 4
                | (c.complete_access as u8) << 5;
        }
        general.foe_details = m.foe as u8;
        general.eoe_details = m.eoe as u8;
    }
    info.header = h.with_checksum();

    // Real images start their strings with the type name (what SOEM shows as the name).
    general.order_idx = info.intern(&dev.type_name);
    general.group_idx = info.intern(&dev.group_type);
    general.group_idx_dup = general.group_idx;
    general.name_idx = info.intern(&dev.name);
    general.current_on_ebus_ma = dev.ebus_current_ma;
    general.physical_ports =
        dev.physics.chars().take(4).enumerate().map(|(i, c)| port_type(c) << (4 * i)).fold(0, |a, b| a | b);
    if dev.profile_no == Some(402) {
        general.ds402_channels = 1;
    }
    info.push(CategoryRepr::General(general));

    if !dev.fmmus.is_empty() {
        info.push(CategoryRepr::Fmmu(
            dev.fmmus
                .iter()
                .map(|f| match f {
                    FmmuKind::Outputs => fmmu_usage::OUTPUTS,
                    FmmuKind::Inputs => fmmu_usage::INPUTS,
                    FmmuKind::MailboxState => fmmu_usage::SM_STATUS,
                    FmmuKind::Other(_) => fmmu_usage::UNUSED,
                })
                .collect(),
        ));
    }
    if !dev.sync_managers.is_empty() {
        info.push(CategoryRepr::SyncManagers(
            dev.sync_managers
                .iter()
                .map(|s| SmEntry {
                    start: s.start,
                    length: s.default_size.unwrap_or(0),
                    control: s.control,
                    status: 0,
                    enable: s.enable as u8,
                    sm_type: match s.kind {
                        SmKind::MailboxOut => SmEntry::TYPE_MBX_OUT,
                        SmKind::MailboxIn => SmEntry::TYPE_MBX_IN,
                        SmKind::Outputs => SmEntry::TYPE_OUTPUTS,
                        SmKind::Inputs => SmEntry::TYPE_INPUTS,
                        SmKind::Unused => 0,
                    },
                })
                .collect(),
        ));
    }
    if !dev.tx_pdos.is_empty() {
        let p = pdos(&dev.tx_pdos, &mut info);
        info.push(CategoryRepr::TxPdos(p));
    }
    if !dev.rx_pdos.is_empty() {
        let p = pdos(&dev.rx_pdos, &mut info);
        info.push(CategoryRepr::RxPdos(p));
    }
    if !dev.dc_op_modes.is_empty() {
        let modes = dev
            .dc_op_modes
            .iter()
            .map(|m| DcOpMode {
                cycle_time0: m.cycle_time_sync0_ns,
                shift_time0: m.shift_time_sync0_ns,
                shift_time1: m.shift_time_sync1_ns,
                sync1_cycle_factor: m.cycle_time_sync1_factor.unwrap_or(0),
                assign_activate: m.assign_activate,
                sync0_cycle_factor: m.cycle_time_sync0_factor.unwrap_or(0),
                name_idx: info.intern(&m.name),
                desc_idx: info.intern(&m.description),
                reserved: [0; 4],
            })
            .collect();
        info.push(CategoryRepr::Dc(modes));
    }
    info
}
