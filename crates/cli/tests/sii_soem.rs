//! The real EEPROM images of EK1100 and EL2004 decode to what SOEM's slaveinfo printed on the
//! real hardware (../shared/captures/soem-sdinfo-2-el2004.txt).
use std::collections::BTreeMap;

use ferrocat_wire::sii::dump::parse_dump;
use ferrocat_wire::sii::SiiInfo;

/// One "Slave:N" block of the printout: its lines, trimmed.
fn soem_slaves(text: &str) -> Vec<Vec<String>> {
    let mut slaves: Vec<Vec<String>> = Vec::new();
    for line in text.lines() {
        let l = line.trim();
        if l.starts_with("Slave:") {
            slaves.push(Vec::new());
        } else if let Some(s) = slaves.last_mut() {
            if !l.is_empty() && !l.starts_with("End ") {
                s.push(l.to_string());
            }
        }
    }
    slaves
}

fn field<'a>(lines: &'a [String], prefix: &str) -> &'a str {
    lines.iter().find_map(|l| l.strip_prefix(prefix)).unwrap_or_else(|| panic!("no '{prefix}' in {lines:?}")).trim()
}

/// What slaveinfo would print for this image, computed the way SOEM computes it from the SII.
fn expected_lines(sii: &SiiInfo) -> BTreeMap<&'static str, String> {
    let h = &sii.header;
    let g = sii.general().expect("general category");
    let mut m = BTreeMap::new();
    // SOEM names a slave by the first string of the strings category.
    m.insert("Name:", sii.string(1).unwrap());
    m.insert("Man:", format!("{:08x} ID: {:08x} Rev: {:08x}", h.vendor_id, h.product_code, h.revision));
    let bits = |pdos: &[ferrocat_wire::sii::Pdo]| -> u32 {
        pdos.iter().filter(|p| p.sync_manager < 8).map(|p| p.bit_len()).sum()
    };
    m.insert("Output size:", format!("{}bits", bits(sii.rx_pdos())));
    m.insert("Input size:", format!("{}bits", bits(sii.tx_pdos())));
    let f: Vec<u8> = (0..4).map(|i| sii.fmmus().get(i).copied().filter(|&u| u != 0xFF).unwrap_or(0)).collect();
    m.insert("FMMUfunc", format!("0:{} 1:{} 2:{} 3:{}", f[0], f[1], f[2], f[3]));
    m.insert(
        "MBX length wr:",
        format!("{} rd: {} MBX protocols : {:02x}", h.mailbox_rx_size, h.mailbox_tx_size, h.mailbox_protocols),
    );
    m.insert(
        "CoE details:",
        format!(
            "{:02x} FoE details: {:02x} EoE details: {:02x} SoE details: {:02x}",
            g.coe_details, g.foe_details, g.eoe_details, g.soe_channels
        ),
    );
    m.insert("Ebus current:", format!("{}[mA]", g.current_on_ebus_ma));
    m
}

/// SM lines: SOEM sizes a process-data SM from the PDOs assigned to it when the SII says 0.
fn expected_sm_lines(sii: &SiiInfo) -> Vec<String> {
    sii.sync_managers()
        .iter()
        .enumerate()
        .filter(|(_, s)| s.start > 0)
        .map(|(i, s)| {
            let pdo_bits: u32 = sii
                .rx_pdos()
                .iter()
                .chain(sii.tx_pdos())
                .filter(|p| p.sync_manager as usize == i)
                .map(|p| p.bit_len())
                .sum();
            let len = if s.length > 0 { s.length as u32 } else { pdo_bits.div_ceil(8) };
            let flags = s.control as u32 | (s.enable as u32) << 16;
            format!("SM{i} A:{:04x} L:{len:4} F:{flags:08x} Type:{}", s.start, s.sm_type)
        })
        .collect()
}

#[test]
fn needs_shared_ek1100_and_el2004_match_soem_slaveinfo() {
    let text = std::fs::read_to_string(ferrocat_testdata::shared("captures/soem-sdinfo-2-el2004.txt")).unwrap();
    let slaves = soem_slaves(&text);
    assert_eq!(slaves.len(), 3);
    let mut checked = 0;
    for lines in &slaves {
        let file = match field(lines, "Name:") {
            "EK1100" => "ek1100.hex",
            "EL2004" => "el2004.bin",
            other => panic!("unexpected slave {other}"),
        };
        let raw = std::fs::read(ferrocat_testdata::shared(&format!("captures/eeprom/{file}"))).unwrap();
        let (img, _) = parse_dump(&raw).unwrap();
        let sii = SiiInfo::from_image(&img).unwrap();
        for (prefix, want) in expected_lines(&sii) {
            assert_eq!(field(lines, prefix), want, "{file}: '{prefix}'");
        }
        let soem_sm: Vec<&String> = lines.iter().filter(|l| l.starts_with("SM")).collect();
        assert_eq!(soem_sm.iter().map(|s| s.as_str()).collect::<Vec<_>>(), expected_sm_lines(&sii), "{file}: SM lines");
        // The FMMU SOEM configured maps the outputs SM with exactly the outputs' bits.
        if let Some(fmmu) = lines.iter().find(|l| l.starts_with("FMMU0 ")) {
            let v: BTreeMap<&str, &str> = fmmu.split_whitespace().skip(1).filter_map(|kv| kv.split_once(':')).collect();
            let out_sm = sii.sync_managers().iter().find(|s| s.sm_type == 3).unwrap();
            assert_eq!(u16::from_str_radix(v["Ps"], 16).unwrap(), out_sm.start, "{file}: FMMU physical start");
            let bits: u32 = sii.rx_pdos().iter().map(|p| p.bit_len()).sum();
            let (lsb, leb): (u32, u32) = (v["Lsb"].parse().unwrap(), v["Leb"].parse().unwrap());
            assert_eq!(leb - lsb + 1, bits, "{file}: FMMU bit span");
            assert_eq!(v["Ty"], "02", "{file}: outputs FMMU writes");
        }
        checked += 1;
    }
    assert_eq!(checked, 3);
}

#[test]
fn needs_shared_every_eeprom_image_parses_and_re_encodes() {
    for path in ferrocat_testdata::shared_files("captures/eeprom", "") {
        let raw = std::fs::read(&path).unwrap();
        let (img, _) = parse_dump(&raw).unwrap();
        let sii = SiiInfo::from_image(&img).unwrap_or_else(|e| panic!("{}: {e}", path.display()));
        assert!(sii.general().is_some() && sii.name().is_some(), "{}", path.display());
        ferrocat_wire::sii::SiiImage::parse(&img).unwrap().check_crc().unwrap();
        // Up to and including the end marker the image re-encodes byte for byte.
        let again = sii.to_image();
        assert_eq!(&img[..again.len()], &again[..], "{}", path.display());
        println!("{:28} {:5} bytes  {:?}", path.file_name().unwrap().to_string_lossy(), img.len(), sii.name().unwrap());
    }
}
