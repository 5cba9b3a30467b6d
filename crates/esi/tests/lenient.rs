//! Vendors' files that their own tools accept are read, each deviation from ETG.2000 a warning
//! with its line and column, and nothing read wrong: the project's own file with one of each
//! (crates/esi/tests/data/ferrocat_lenient.xml).
use ferrocat_esi::{EsiFile, FmmuKind, SmKind};

const XML: &str = include_str!("data/ferrocat_lenient.xml");

#[test]
fn every_deviation_is_read_as_vendors_tools_read_it_with_a_warning_in_file_order() {
    let f = EsiFile::parse(XML).unwrap();
    let w: Vec<(u32, String)> = f.warnings.iter().map(|w| (w.line, w.message.clone())).collect();
    for (line, message) in &w {
        println!("{line}: {message}");
    }
    let expect: [(u32, &str); 15] = [
        (9, "'0x00010003' is not ETG.2000's form"),
        (11, "<Fmmu>outputs</Fmmu>: read as Outputs"),
        (12, "<Sm>mboxout</Sm>: read as MBoxOut"),
        (12, "'#X1000' is not ETG.2000's form"),
        (16, "Fixed=\"True\" of <RxPdo>: xs:boolean is lower case; read as true"),
        (16, "Mandatory=\"yes\" of <RxPdo>: not a boolean; read as false"),
        (16, "' #x1600 ' is not ETG.2000's form"),
        (17, "entry 0x7000 has no <DataType>"),
        (19, "PDO 0x1600 (Outputs again) is there already: the first kept"),
        (22, "<TxPdo> has no <Name>"),
        (30, "data type UDINT is defined again"),
        (35, "hex data of odd length 1 ('7')"),
        (37, "object 0x2000 (Setting again) is defined again: the first kept"),
        (45, "FC-LENIENT-COPY has no <Name>"),
        (45, "repeats product code 0x10003 revision 0x1 of FC-LENIENT (line 8)"),
    ];
    assert_eq!(w.len(), expect.len(), "{w:#?}");
    let mut sorted = w.clone();
    sorted.sort_by_key(|(l, _)| *l);
    assert_eq!(w, sorted, "in file order");
    for (line, fragment) in expect {
        assert!(w.iter().any(|(l, m)| *l == line && m.contains(fragment)), "line {line}: {fragment}\n{w:#?}");
    }
    // What was read.
    let d = &f.devices[0];
    assert_eq!((d.product_code, d.type_name.as_str()), (0x10003, "FC-LENIENT"));
    assert_eq!(d.fmmus[0], FmmuKind::Outputs);
    assert_eq!((d.sync_managers[0].kind, d.sync_managers[0].start), (SmKind::MailboxOut, 0x1000));
    assert!(d.sync_managers[0].enable, "Enable=\"true\"");
    assert_eq!(d.rx_pdos.len(), 1, "the repeated 0x1600 is not read twice");
    let rx = &d.rx_pdos[0];
    assert_eq!((rx.index, rx.fixed, rx.mandatory, rx.entries[0].index), (0x1600, true, false, 0x7000));
    let dict = d.dictionary.as_ref().unwrap();
    let setting = dict.object(0x2000).unwrap();
    assert_eq!((setting.name.as_str(), setting.default_data.as_deref()), ("Setting", Some(&[7u8][..])));
    assert_eq!(dict.objects.iter().filter(|o| o.index == 0x2000).count(), 1);
    // Both devices kept; the copy too builds an SII.
    assert_eq!(f.devices.len(), 2);
    d.to_sii(f.vendor_id).unwrap();
}

#[test]
fn a_file_as_etg2000_writes_it_gives_no_warning() {
    // The modular test file has one deviation only (its odd-length DefaultData).
    let f = EsiFile::parse(include_str!("data/ferrocat_modular.xml")).unwrap();
    assert_eq!(f.warnings.len(), 1, "{:?}", f.warnings);
    let fixed = include_str!("data/ferrocat_modular.xml")
        .replace("<DefaultData>2</DefaultData>", "<DefaultData>02</DefaultData>");
    assert!(EsiFile::parse(&fixed).unwrap().warnings.is_empty());
}
