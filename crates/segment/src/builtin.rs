//! Built-in devices, described as an ESI file would describe them. Identities and layouts are
//! the facts SOEM printed for the real terminals and read from the real LAN9252 board
//! (../shared/captures/); the servo is our own.
use ferrocat_esi::{Device, FmmuKind, PdoDesc, PdoEntryDesc, SmDesc, SmKind};

pub const NAMES: &[&str] = &["EK1100", "EL1004", "EL2004", "SERVO", "LAN9252-EVB"];

/// The vendor ID a built-in device carries in its SII.
/// The built-in device's name as `NAMES` spells it, whatever the case of `name`.
pub fn canonical(name: &str) -> Option<&'static str> {
    NAMES.iter().copied().find(|n| n.eq_ignore_ascii_case(name))
}

pub fn vendor_id(name: &str) -> u32 {
    match name {
        // ETG's "no vendor" for our own servo; Microchip's for its evaluation board.
        "SERVO" => 0,
        "LAN9252-EVB" => 0x0000_0009,
        _ => 0x0000_0002, // Beckhoff
    }
}

/// How long a built-in device's firmware takes (µs): to act on AL control, and to answer a
/// mailbox request; `None` where the device has no firmware of its own to describe (the
/// segment's defaults then: 1 ms, and at once). The EVB-LAN9252's sample firmware, from SOEM's
/// capture of the real board (soem-single-lan9252): INIT→PREOP and PREOP→SAFEOP shown
/// 15.85–17.85 ms after the writes, all six mailbox replies 37.94–38.66 ms after the requests
/// (the middles; docs/esc-model.md).
pub fn firmware_times_us(name: &str) -> Option<(f64, f64)> {
    match name {
        "LAN9252-EVB" => Some((16_850.0, 38_300.0)),
        _ => None,
    }
}

/// An EEPROM of `bytes` whose SII word 0 (PDI control, ESC configuration) is `word0`.
fn eeprom(bytes: u32, word0: [u8; 2]) -> Option<ferrocat_esi::EepromDesc> {
    Some(ferrocat_esi::EepromDesc { byte_size: Some(bytes), config_data: word0.to_vec(), bootstrap: vec![] })
}

/// SM0/SM1 as 128-byte mailboxes at 0x1000/0x1080, SM2 outputs and SM3 inputs at the given
/// start, control byte and default length.
fn mailbox_and_process_data_sms(outputs: (u16, u8, Option<u16>), inputs: (u16, u8, Option<u16>)) -> Vec<SmDesc> {
    let sm = |kind, start, default_size, control| SmDesc { kind, start, default_size, control, enable: true };
    vec![
        sm(SmKind::MailboxOut, 0x1000, Some(128), 0x26),
        sm(SmKind::MailboxIn, 0x1080, Some(128), 0x22),
        sm(SmKind::Outputs, outputs.0, outputs.2, outputs.1),
        sm(SmKind::Inputs, inputs.0, inputs.2, inputs.1),
    ]
}

/// A CoE-only mailbox with SDO information and complete access; `pdo_config`: PDO assignment
/// and mapping writable.
fn coe_mailbox(pdo_config: bool) -> Option<ferrocat_esi::MailboxDesc> {
    let coe = ferrocat_esi::CoeDesc {
        sdo_info: true,
        pdo_assign: pdo_config,
        pdo_config,
        pdo_upload: false,
        complete_access: true,
    };
    Some(ferrocat_esi::MailboxDesc { coe: Some(coe), ..Default::default() })
}

fn bits(index: u16, n: u8, sm: u8, name: &str) -> Vec<PdoDesc> {
    (0..n)
        .map(|k| PdoDesc {
            index_depends: Default::default(),
            index: index + k as u16,
            name: format!("Channel {}", k + 1),
            sm: Some(sm),
            fixed: true,
            mandatory: true,
            entries: vec![PdoEntryDesc {
                index_depends: Default::default(),
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
            d.eeprom = eeprom(2048, [0x00, 0x0D]);
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
            d.eeprom = eeprom(2048, [0x04, 0x01]);
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
            d.eeprom = eeprom(2048, [0x04, 0x01]);
        }
        "SERVO" => return Some(servo()),
        "LAN9252-EVB" => return Some(lan9252_evb()),
        _ => return None,
    }
    Some(d)
}

/// A CiA402 servo drive of our own (not a vendor's product): the profile's objects in two fixed
/// PDOs, enough for CSP, CSV and CST without remapping. Vendor 0 is ETG's "no vendor".
fn servo() -> Device {
    let entry = |index: u16, bit_len: u8, name: &str, data_type: &str| PdoEntryDesc {
        index_depends: Default::default(),
        index,
        subindex: 0,
        bit_len,
        name: name.into(),
        data_type: data_type.into(),
    };
    let pdo = |index: u16, sm: u8, entries: Vec<PdoEntryDesc>| PdoDesc {
        index_depends: Default::default(),
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
        sync_managers: mailbox_and_process_data_sms((0x1100, 0x24, None), (0x1180, 0x20, None)),
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
        // Drives take their firmware and parameter files by FoE.
        mailbox: coe_mailbox(true).map(|m| ferrocat_esi::MailboxDesc { foe: true, eoe: true, ..m }),
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
        eeprom: eeprom(2048, [0x05, 0x0C]),
        ..Default::default()
    }
}

/// Microchip's EVB-LAN9252 board running its EtherCAT sample firmware (SSC), as the real one
/// showed itself to SOEM (../shared/captures/soem-single-lan9252.pcapng and
/// soem-sdinfo-2-lan9252.txt): identity, name, SyncManagers, FMMUs, mailbox and CoE details
/// from its SII reads, PDI control 0x0E89 from its 0x0140 read, and the PDO assignment and
/// mapping from its complete-access SDO answers (0x1C12 = 0x1601, 0x1C13 = 0x1A00 + 0x1A02).
/// The entry names and the EEPROM's size are ours (the capture reads neither): eight output bits,
/// eight input bits, and an analog input laid out as Beckhoff's (underrange, overrange, two
/// 2-bit limits, TxPDO state and toggle, a 16-bit value).
fn lan9252_evb() -> Device {
    let entry = |index: u16, subindex: u8, bit_len: u8, name: String, data_type: &str| PdoEntryDesc {
        index_depends: Default::default(),
        index,
        subindex,
        bit_len,
        name,
        data_type: data_type.into(),
    };
    let pad = |bits: u8| entry(0, 0, bits, String::new(), "");
    let bits8 = |index: u16, what: &str| {
        let mut v: Vec<PdoEntryDesc> = (1..=8).map(|k| entry(index, k, 1, format!("{what} {k}"), "BOOL")).collect();
        v.push(pad(8));
        v
    };
    let pdo = |index: u16, name: &str, sm: u8, entries: Vec<PdoEntryDesc>| PdoDesc {
        index_depends: Default::default(),
        index,
        name: name.into(),
        sm: Some(sm),
        fixed: true,
        mandatory: true,
        entries,
    };
    Device {
        type_name: "LAN9252-EVB-HBI".into(),
        name: "LAN9252-EVB-HBI".into(),
        product_code: 0x0000_9252,
        revision: 0x0000_0001,
        physics: "YY".into(),
        group_type: "EVB".into(),
        fmmus: vec![FmmuKind::Outputs, FmmuKind::Inputs, FmmuKind::MailboxState],
        sync_managers: mailbox_and_process_data_sms((0x1100, 0x64, Some(2)), (0x1400, 0x20, Some(6))),
        rx_pdos: vec![pdo(0x1601, "Outputs", 2, bits8(0x7010, "Output"))],
        tx_pdos: vec![
            pdo(0x1A00, "Inputs", 3, bits8(0x6000, "Input")),
            pdo(
                0x1A02,
                "Analog input",
                3,
                vec![
                    entry(0x6020, 0x01, 1, "Underrange".into(), "BOOL"),
                    entry(0x6020, 0x02, 1, "Overrange".into(), "BOOL"),
                    entry(0x6020, 0x03, 2, "Limit 1".into(), "BIT2"),
                    entry(0x6020, 0x05, 2, "Limit 2".into(), "BIT2"),
                    pad(8),
                    entry(0x1802, 0x07, 1, "TxPDO State".into(), "BOOL"),
                    entry(0x1802, 0x09, 1, "TxPDO Toggle".into(), "BOOL"),
                    entry(0x6020, 0x11, 16, "Analog input".into(), "INT"),
                ],
            ),
        ],
        mailbox: coe_mailbox(false),
        // Word 0: PDI control 0x89 (HBI), ESC configuration 0x0E (enhanced link detection, SYNC
        // and latch units; no device emulation: the firmware runs the AL).
        eeprom: eeprom(4096, [0x89, 0x0E]),
        ..Default::default()
    }
}
