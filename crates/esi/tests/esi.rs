use ferrocat_esi::{EsiFile, SmKind};
use ferrocat_wire::sii::{SiiImage, SiiInfo, SmEntry};

fn load(name: &str) -> EsiFile {
    let path = ferrocat_testdata::shared(&format!("esi/{name}"));
    let xml = std::fs::read_to_string(&path).unwrap();
    EsiFile::parse(&xml).unwrap_or_else(|e| panic!("{}: {e}", path.display()))
}

#[test]
fn needs_shared_all_three_esi_files_parse() {
    for (name, vendor, min_devices) in
        [("Beckhoff_EK11xx.xml", 2, 20), ("Nanotec_C5-E-2-21.xml", 0x26C, 1), ("Weidmueller_UR20_FBC.xml", 0x230, 1)]
    {
        let f = load(name);
        assert_eq!(f.vendor_id, vendor, "{name}");
        assert!(f.devices.len() >= min_devices, "{name}: {} devices", f.devices.len());
        for d in &f.devices {
            assert!(!d.type_name.is_empty() && !d.name.is_empty(), "{name} line {}", d.line);
            // Every device's SII image builds and reads back.
            let img = d.to_sii(f.vendor_id).unwrap();
            let info = SiiInfo::from_image(&img).unwrap();
            assert_eq!(info.header.product_code, d.product_code);
            SiiImage::parse(&img).unwrap().check_crc().unwrap();
        }
        println!("{name}: vendor {:#x}, {} devices", f.vendor_id, f.devices.len());
    }
}

#[test]
fn needs_shared_nanotec_drive_description() {
    let f = load("Nanotec_C5-E-2-21.xml");
    let d = f.device(0x4F, None).expect("C5-E-2-21");
    assert_eq!(d.type_name, "C5-E-2-21");
    assert_eq!(d.revision, 0x08A5_0000);
    assert_eq!(d.profile_no, Some(402));
    assert_eq!(d.sync_managers.len(), 4);
    assert_eq!(d.sync_managers[0].kind, SmKind::MailboxOut);
    assert_eq!((d.sync_managers[2].start, d.sync_managers[2].control), (0x1100, 0x24));
    assert_eq!(d.rx_pdos[0].index, 0x1600);
    assert_eq!(d.rx_pdos[0].entries[0].index, 0x6040);
    assert_eq!(d.tx_pdos[1].entries[0].index, 0x6064);
    assert_eq!(d.dc_op_modes[1].assign_activate, 0x0330);
    assert_eq!(d.dc_op_modes[1].cycle_time_sync0_ns, 1_000_000);
    assert_eq!(d.dc_op_modes[1].shift_time_sync0_ns, 250_000);
    let dict = d.dictionary.as_ref().expect("object dictionary");
    assert!(dict.objects.len() > 150, "{} objects", dict.objects.len());
    let identity = dict.object(0x1018).expect("0x1018");
    assert!(identity.subs.len() >= 4, "{:?}", identity.subs);
    let cw = dict.object(0x6040).expect("controlword");
    assert_eq!(cw.bit_size, 16);
    assert!(cw.access.write);
    // 0x1003 is an array: subindex 0 plus its elements.
    let errs = dict.object(0x1003).expect("0x1003");
    assert!(errs.subs.len() > 2 && errs.subs[1].subindex == 1, "{:?}", errs.subs);
}

#[test]
fn needs_shared_nanotec_sii_round_trips_identity_sm_pdo_dc() {
    let f = load("Nanotec_C5-E-2-21.xml");
    let d = f.device(0x4F, None).unwrap();
    let img = d.to_sii(f.vendor_id).unwrap();
    assert_eq!(img.len(), 16384, "EEPROM ByteSize from the ESI");
    let sii = SiiInfo::from_image(&img).unwrap();
    let h = &sii.header;
    assert_eq!((h.vendor_id, h.product_code, h.revision), (0x26C, 0x4F, 0x08A5_0000));
    assert_eq!(
        (h.mailbox_rx_offset, h.mailbox_rx_size, h.mailbox_tx_offset, h.mailbox_tx_size),
        (0x1000, 128, 0x1080, 128)
    );
    assert_eq!(h.pdi_control, 0x0605, "ConfigData word 0");
    assert_eq!(sii.name().as_deref(), Some(d.name.as_str()));
    // SyncManagers.
    let sms = sii.sync_managers();
    assert_eq!(sms.len(), d.sync_managers.len());
    for (s, e) in sms.iter().zip(&d.sync_managers) {
        assert_eq!(
            (s.start, s.length, s.control, s.enable != 0),
            (e.start, e.default_size.unwrap_or(0), e.control, e.enable)
        );
    }
    assert_eq!(sms.iter().map(|s| s.sm_type).collect::<Vec<_>>(), [SmEntry::TYPE_MBX_OUT, SmEntry::TYPE_MBX_IN, 3, 4]);
    // PDOs with their entries and names.
    for (sii_pdos, esi_pdos) in [(sii.rx_pdos(), &d.rx_pdos), (sii.tx_pdos(), &d.tx_pdos)] {
        assert_eq!(sii_pdos.len(), esi_pdos.len());
        for (s, e) in sii_pdos.iter().zip(esi_pdos) {
            assert_eq!(s.index, e.index);
            assert_eq!(s.sync_manager, e.sm.unwrap_or(0xFF));
            assert_eq!(sii.string(s.name_idx).as_deref(), Some(e.name.as_str()));
            let got: Vec<_> = s.entries.iter().map(|x| (x.index, x.subindex, x.bit_len)).collect();
            let want: Vec<_> = e.entries.iter().map(|x| (x.index, x.subindex, x.bit_len)).collect();
            assert_eq!(got, want);
        }
    }
    // DC op-modes.
    let dc = sii.dc_op_modes();
    assert_eq!(dc.len(), 2);
    assert_eq!((dc[1].assign_activate, dc[1].cycle_time0, dc[1].shift_time0), (0x0330, 1_000_000, 250_000));
    assert_eq!(sii.string(dc[1].name_idx).as_deref(), Some("DC"));
    // And the owned description re-encodes to the same image.
    assert_eq!(sii.to_image_sized(img.len()).unwrap(), img);
}

/// A file cut short (as `head -c` leaves one) is placed at its end, where the reader had said
/// line 1, column 1.
#[test]
fn a_truncated_file_is_placed_at_its_end() {
    let whole = "<?xml version=\"1.0\"?>\n<EtherCATInfo>\n  <Vendor>\n    <Id>2</Id>\n  </Vendor>\n  <Descriptions attr=\"x\">\n</EtherCATInfo>\n";
    for (cut, line, column) in [(61, 4, 14), (70, 5, 8), (84, 6, 10)] {
        let e = EsiFile::parse(&whole[..cut]).unwrap_err();
        assert_eq!((e.line, e.column), (line, column), "cut at {cut}: {e}");
        assert!(e.message.contains("a truncated file?"), "cut at {cut}: {e}");
    }
}

#[test]
fn malformed_xml_names_line_and_column() {
    let e = EsiFile::parse("<EtherCATInfo>\n  <Vendor><Id>2</Id>\n</EtherCATInfo>").unwrap_err();
    assert_eq!(e.line, 3, "{e}");
    assert!(e.column > 0 && e.message.contains("malformed XML"), "{e}");

    let e = EsiFile::parse("<EtherCATInfo><Vendor><Id>two</Id></Vendor></EtherCATInfo>").unwrap_err();
    assert!(e.message.contains("'two' is not a number"), "{e}");

    let xml = "<EtherCATInfo><Vendor><Id>2</Id></Vendor><Descriptions><Devices>\n<Device>\n <Type RevisionNo=\"1\">X</Type>\n</Device></Devices></Descriptions></EtherCATInfo>";
    let e = EsiFile::parse(xml).unwrap_err();
    assert_eq!((e.line, e.message.as_str()), (3, "<Type> lacks ProductCode"));

    let xml = "<EtherCATInfo><Vendor><Id>2</Id></Vendor><Descriptions><Devices><Device><Type ProductCode=\"#x1\">X</Type>\n<Sm StartAddress=\"#x100000\">Outputs</Sm></Device></Devices></Descriptions></EtherCATInfo>";
    let e = EsiFile::parse(xml).unwrap_err();
    assert_eq!(e.line, 2);
    assert!(e.message.contains("out of range"), "{e}");

    // A multi-byte character in hex data (a find of the `device` fuzz target: a parser that
    // slices the text by bytes panics inside the character).
    let xml = "<EtherCATInfo><Vendor><Id>2</Id></Vendor><Descriptions><Devices><Device><Type ProductCode=\"#x1\">X</Type>\n<Eeprom><ConfigData>080\u{113}ments0</ConfigData></Eeprom></Device></Devices></Descriptions></EtherCATInfo>";
    let e = EsiFile::parse(xml).unwrap_err();
    assert_eq!((e.line, e.message.as_str()), (2, "'\u{113}' at character 3 is not a hex digit"), "{e}");

    assert!(EsiFile::parse("").is_err());
    assert!(EsiFile::parse("<Other/>").unwrap_err().message.contains("expected <EtherCATInfo>"));
}
