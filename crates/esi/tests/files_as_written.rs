//! ESI files as vendors' tools write them and ETG.2000 leaves open: an 8-bit encoding the
//! declaration names, passive devices without a product code, and IgH's `<EtherCATInfoList>`.
//! The files are made here, byte for byte, so that each class has a file of the project's own.
use ferrocat_esi::{text, EsiFile};

/// One `<EtherCATInfo>` of vendor `vendor` with the devices given (`<Device>` elements).
fn info(vendor: u32, devices: &str) -> String {
    format!("<EtherCATInfo><Vendor><Id>{vendor}</Id><Name>V</Name></Vendor><Descriptions><Devices>{devices}</Devices></Descriptions></EtherCATInfo>")
}

const COUPLER: &str = "<Device><Type ProductCode=\"#x10\" RevisionNo=\"#x1\">C10</Type><Name>Koppler</Name></Device>";

#[test]
fn a_file_in_the_encoding_its_declaration_names_reads_as_that_encoding() {
    // ISO-8859-1, as most of Beckhoff's files: "für" with ü as the one byte 0xFC.
    let mut bytes = b"<?xml version=\"1.0\" encoding=\"ISO-8859-1\"?>".to_vec();
    bytes.extend(
        info(2, "<Device><Type ProductCode=\"#x20\" RevisionNo=\"#x1\">T20</Type><Name>Klemme f\u{0}r</Name></Device>")
            .bytes(),
    );
    let at = bytes.iter().position(|&b| b == 0).unwrap();
    bytes[at] = 0xFC;
    assert!(std::str::from_utf8(&bytes).is_err(), "not UTF-8");
    let (xml, _) = text::decode(&bytes).unwrap();
    let f = EsiFile::parse(&xml).unwrap();
    assert_eq!(f.devices[0].name, "Klemme für");
    // UTF-16 with its byte-order mark.
    let wide: Vec<u8> =
        [0xFF, 0xFE].into_iter().chain(info(2, COUPLER).encode_utf16().flat_map(u16::to_le_bytes)).collect();
    assert_eq!(EsiFile::parse(&text::decode(&wide).unwrap().0).unwrap().devices[0].type_name, "C10");
    // An encoding nobody knows is said, not guessed.
    let e = text::decode(b"<?xml version=\"1.0\" encoding=\"x-none\"?><a>\xFC</a>").unwrap_err();
    assert!(e.contains("'x-none'"), "{e}");
}

#[test]
fn passive_devices_are_listed_and_not_described() {
    let xml = info(2, &format!("<Device Physics=\"K\"><Type>P9010</Type><Name>End terminal</Name></Device>{COUPLER}"));
    let f = EsiFile::parse(&xml).unwrap();
    assert_eq!(f.devices.iter().map(|d| d.type_name.as_str()).collect::<Vec<_>>(), ["C10"]);
    assert_eq!(
        (f.passive.len(), f.passive[0].type_name.as_str(), f.passive[0].name.as_str()),
        (1, "P9010", "End terminal")
    );
}

#[test]
fn an_ethercat_info_list_reads_as_one_file_of_its_vendor() {
    // IgH's `ethercat xml`: one info a slave, the same device twice.
    let two = "<Device><Type ProductCode=\"#x20\" RevisionNo=\"#x1\">T20</Type><Name>I/O</Name></Device>";
    let xml = format!("<EtherCATInfoList>{}{}{}</EtherCATInfoList>", info(7, COUPLER), info(7, two), info(7, two));
    let f = EsiFile::parse(&xml).unwrap();
    assert_eq!(f.vendor_id, 7);
    assert_eq!(f.devices.iter().map(|d| d.type_name.as_str()).collect::<Vec<_>>(), ["C10", "T20"], "the repeat once");
    // Two vendors in one list: said where the second begins.
    let xml = format!("<EtherCATInfoList>{}\n{}</EtherCATInfoList>", info(7, COUPLER), info(9, two));
    let e = EsiFile::parse(&xml).unwrap_err();
    assert_eq!(e.line, 2, "{e}");
    assert!(e.message.contains("vendor 0x9 here, 0x7 in the list's first"), "{e}");
    let e = EsiFile::parse("<EtherCATInfoList></EtherCATInfoList>").unwrap_err();
    assert!(e.message.contains("without an <EtherCATInfo>"), "{e}");
}
