//! Built-in devices, described as an ESI file would describe them. Identities and layouts are
//! the facts SOEM printed for the real terminals (../shared/captures/*.txt).
use ferrocat_esi::{Device, FmmuKind, PdoDesc, PdoEntryDesc, SmDesc, SmKind};

pub const NAMES: &[&str] = &["EK1100", "EL1004", "EL2004"];

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
        _ => return None,
    }
    Some(d)
}
