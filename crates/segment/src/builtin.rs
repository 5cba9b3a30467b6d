//! Built-in devices, described as an ESI file would describe them. Identities and layouts are
//! the facts SOEM printed for the real terminals (../shared/captures/*.txt).
use ferrocat_esi::{Device, FmmuKind, PdoDesc, PdoEntryDesc, SmDesc, SmKind};

pub const NAMES: &[&str] = &["EK1100", "EL1004", "EL2004", "SERVO"];

fn bits(index: u16, n: u8, sm: u8, name: &str) -> Vec<PdoDesc> {
    (0..n)
        .map(|k| PdoDesc {
            index: index + k as u16,
            name: format!("Channel {}", k + 1),
            sm: Some(sm),
            fixed: true,
            mandatory: true,
            entries: vec![PdoEntryDesc {
                index: if index >= 0x1A00 { 0x6000 } else { 0x7000 } + 0x10 * k as u16,
                subindex: 1,
                bit_len: 1,
                name: name.into(),
                data_type: "BOOL".into(),
            }],
        })
        .collect()
}

pub fn device(name: &str) -> Option<Device> {
    let mut d =
        Device { type_name: name.into(), physics: "KK".into(), group_type: "DigIO".into(), ..Default::default() };
    match name {
        "EK1100" => {
            d.name = "EK1100 EtherCAT Coupler (2A E-Bus)".into();
            d.product_code = 0x044C_2C52;
            d.revision = 0x0012_0000;
            d.physics = "YKY".into();
            d.group_type = "SystemBk".into();
            d.ebus_current_ma = -2000;
            d.eeprom = Some(ferrocat_esi::EepromDesc {
                byte_size: Some(2048),
                config_data: vec![0x00, 0x0D],
                bootstrap: vec![],
            });
        }
        "EL2004" => {
            d.name = "EL2004 4Ch. Dig. Output 24V, 0.5A".into();
            d.product_code = 0x07D4_3052;
            d.revision = 0x0010_0000;
            d.ebus_current_ma = 100;
            d.fmmus = vec![FmmuKind::Outputs];
            d.sync_managers =
                vec![SmDesc { kind: SmKind::Outputs, start: 0x0F00, default_size: None, control: 0x44, enable: true }];
            d.rx_pdos = bits(0x1600, 4, 0, "Output");
            d.eeprom = Some(ferrocat_esi::EepromDesc {
                byte_size: Some(2048),
                config_data: vec![0x04, 0x01],
                bootstrap: vec![],
            });
        }
        "EL1004" => {
            d.name = "EL1004 4Ch. Dig. Input 24V, 3ms".into();
            d.product_code = 0x03EC_3052;
            d.revision = 0x0010_0000;
            d.ebus_current_ma = 90;
            d.fmmus = vec![FmmuKind::Inputs];
            d.sync_managers =
                vec![SmDesc { kind: SmKind::Inputs, start: 0x1000, default_size: None, control: 0x00, enable: true }];
            d.tx_pdos = bits(0x1A00, 4, 0, "Input");
            d.eeprom = Some(ferrocat_esi::EepromDesc {
                byte_size: Some(2048),
                config_data: vec![0x04, 0x01],
                bootstrap: vec![],
            });
        }
        "SERVO" => return Some(servo()),
        _ => return None,
    }
    Some(d)
}

/// A CiA402 servo drive of our own (not a vendor's product): the profile's objects in two fixed
/// PDOs, enough for CSP, CSV and CST without remapping. Vendor 0 is ETG's "no vendor".
fn servo() -> Device {
    let entry = |index: u16, bit_len: u8, name: &str, data_type: &str| PdoEntryDesc {
        index,
        subindex: 0,
        bit_len,
        name: name.into(),
        data_type: data_type.into(),
    };
    let pdo = |index: u16, sm: u8, entries: Vec<PdoEntryDesc>| PdoDesc {
        index,
        name: if sm == 2 { "Outputs" } else { "Inputs" }.into(),
        sm: Some(sm),
        fixed: false,
        mandatory: true,
        entries,
    };
    Device {
        type_name: "SERVO".into(),
        name: "ferrocat simulated CiA402 servo drive".into(),
        product_code: 0x0000_0402,
        revision: 0x0001_0000,
        physics: "YY".into(),
        group_type: "Drive".into(),
        profile_no: Some(402),
        fmmus: vec![FmmuKind::Outputs, FmmuKind::Inputs, FmmuKind::MailboxState],
        sync_managers: vec![
            SmDesc { kind: SmKind::MailboxOut, start: 0x1000, default_size: Some(128), control: 0x26, enable: true },
            SmDesc { kind: SmKind::MailboxIn, start: 0x1080, default_size: Some(128), control: 0x22, enable: true },
            SmDesc { kind: SmKind::Outputs, start: 0x1100, default_size: None, control: 0x24, enable: true },
            SmDesc { kind: SmKind::Inputs, start: 0x1180, default_size: None, control: 0x20, enable: true },
        ],
        rx_pdos: vec![pdo(
            0x1600,
            2,
            vec![
                entry(0x6040, 16, "Controlword", "UINT"),
                entry(0x607A, 32, "Target position", "DINT"),
                entry(0x60FF, 32, "Target velocity", "DINT"),
                entry(0x6071, 16, "Target torque", "INT"),
                entry(0x6060, 8, "Modes of operation", "SINT"),
                entry(0, 8, "", ""),
            ],
        )],
        tx_pdos: vec![pdo(
            0x1A00,
            3,
            vec![
                entry(0x6041, 16, "Statusword", "UINT"),
                entry(0x6064, 32, "Position actual value", "DINT"),
                entry(0x606C, 32, "Velocity actual value", "DINT"),
                entry(0x6077, 16, "Torque actual value", "INT"),
                entry(0x60F4, 32, "Following error actual value", "DINT"),
                entry(0x6061, 8, "Modes of operation display", "SINT"),
                entry(0, 8, "", ""),
            ],
        )],
        mailbox: Some(ferrocat_esi::MailboxDesc {
            coe: Some(ferrocat_esi::CoeDesc {
                sdo_info: true,
                pdo_assign: true,
                pdo_config: true,
                pdo_upload: false,
                complete_access: true,
            }),
            ..Default::default()
        }),
        dc_op_modes: vec![
            ferrocat_esi::DcOpModeDesc {
                name: "SM".into(),
                description: "SM-synchronous".into(),
                ..Default::default()
            },
            ferrocat_esi::DcOpModeDesc {
                name: "DC".into(),
                description: "DC-synchronous (SYNC0)".into(),
                assign_activate: 0x0300,
                cycle_time_sync0_ns: 1_000_000,
                ..Default::default()
            },
        ],
        // SPI PDI to a microcontroller, no device emulation: the firmware runs the AL.
        eeprom: Some(ferrocat_esi::EepromDesc {
            byte_size: Some(2048),
            config_data: vec![0x05, 0x0C],
            bootstrap: vec![],
        }),
        ..Default::default()
    }
}
