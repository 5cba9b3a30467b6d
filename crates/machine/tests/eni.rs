//! ENI files: the two TwinCAT exports in `../shared/eni` read as they are, the project's own
//! test file with every tolerated departure, and bad files refused with their place.
use ferrocat_machine::eni::{Eni, Target, Transition};
use ferrocat_wire::register::AlState;
use ferrocat_wire::sii::SiiInfo;
use ferrocat_wire::Command;

fn shared_eni(name: &str) -> Eni {
    let path = ferrocat_testdata::shared(&format!("eni/{name}"));
    Eni::parse(&std::fs::read(&path).unwrap()).unwrap_or_else(|e| panic!("{}: {e}", path.display()))
}

const LENIENT: &[u8] = include_bytes!("data/ferrocat_lenient.eni.xml");

#[test]
fn needs_shared_twincat_s_coupler_and_terminals() {
    let e = shared_eni("mega_master_eni.xml");
    let names: Vec<String> = e.slaves.iter().map(|s| s.type_name()).collect();
    assert_eq!(names, ["EK1100", "EL2008", "EL4002", "EL1809"]);
    let ek = &e.slaves[0];
    assert_eq!((ek.identity.vendor_id, ek.identity.product_code, ek.identity.revision), (2, 72100946, 0x0012_0000));
    assert_eq!((ek.station, ek.auto_inc), (Some(1001), Some(0)));
    assert_eq!(e.slaves[3].auto_inc, Some(65533));
    // The EL2008's eight bits in the output image, the EL1809's sixteen in the input image.
    let el2008 = &e.slaves[1].process_data;
    assert_eq!(el2008.send.map(|r| (r.start, r.length)), Some((344, 8)));
    assert_eq!(e.slaves[3].process_data.recv.map(|r| (r.start, r.length)), Some((448, 16)));
    assert_eq!(el2008.rx_pdos.len(), 8);
    // Init commands per transition: the EK1100's first is a broadcast or its address.
    assert_eq!(ek.init_cmds.len(), 26);
    assert!(ek.init_cmds.iter().all(|c| !c.transitions.is_empty()));
    // One frame: the mailbox state bits, the outputs (LWR, two slaves), the inputs (LRD, one),
    // and every slave's AL status.
    let cmds = &e.cyclic[0].frames[0].cmds;
    type Seen = (Command, Target, u16, Option<u16>, Option<u32>);
    let seen: Vec<Seen> = cmds.iter().map(|c| (c.command, c.target, c.data_length, c.cnt, c.input_offs)).collect();
    assert_eq!(
        seen,
        [
            (Command::LRD, Target::Logical(0x0900_0000), 1, None, Some(16)),
            (Command::LWR, Target::Logical(0x0100_0000), 5, Some(2), Some(29)),
            (Command::LRD, Target::Logical(0x0100_0800), 2, Some(1), Some(46)),
            (Command::BRD, Target::Device { adp: 0, ado: 0x0130 }, 2, Some(4), Some(60)),
        ]
    );
    assert_eq!(cmds[1].states, [AlState::SafeOp, AlState::Op]);
    // The image mirrors the frame: a datagram's header, then its data, then its working
    // counter, so each datagram starts 12 bytes past the last one's data.
    for w in cmds.windows(2) {
        assert_eq!(w[1].input_offs.unwrap(), w[0].input_offs.unwrap() + 10 + w[0].data_length as u32 + 2);
    }
    // TwinCAT's own InfoData lie past the 1 536 bytes it sizes the image at: kept, each warned.
    assert_eq!(e.process_image.inputs.byte_size, 1536);
    assert!(e.warnings.len() == 12 && e.warnings.iter().all(|w| w.message.contains("InfoData")), "{:?}", e.warnings);
    assert!(Eni::parse_strict(&std::fs::read(ferrocat_testdata::shared("eni/mega_master_eni.xml")).unwrap()).is_err());
}

#[test]
fn needs_shared_twincat_s_four_drives_and_an_imu() {
    let e = shared_eni("test_eni.xml");
    assert!(e.warnings.is_empty(), "{:?}", e.warnings);
    assert_eq!(e.slaves.len(), 5);
    let wheel = &e.slaves[1];
    assert_eq!(wheel.name, "WheelRearLeft");
    let mbx = wheel.mailbox.as_ref().unwrap();
    assert_eq!((mbx.send, mbx.recv, mbx.profile_no), ((6144, 140), (6400, 140), Some(402)));
    assert_eq!(mbx.coe_init_cmds.len(), 12);
    let first = &mbx.coe_init_cmds[0];
    assert_eq!((first.index, first.subindex, first.data.as_slice()), (0x1C12, 0, &[0u8][..]));
    assert_eq!(first.transitions, [Transition::parse("PS").unwrap()]);
    let dc = wheel.dc.unwrap();
    assert!(dc.reference_clock && dc.cycle_time0_ns == 10_000_000);
    assert!(!e.slaves[2].dc.unwrap().reference_clock);
    assert_eq!(e.cyclic[0].cycle_time_us, Some(10_000));
    // The reference clock's time distributed by ARMW at its auto-increment address.
    let armw = &e.cyclic[0].frames[0].cmds[1];
    assert_eq!((armw.command, armw.target), (Command::ARMW, Target::Device { adp: 0xFFFF, ado: 0x0910 }));
    // Every ENI slave as a device: its SII carries the identity and the mailbox.
    for s in &e.slaves {
        let sii = s.to_device().to_sii(s.identity.vendor_id).unwrap();
        let info = SiiInfo::from_image(&sii).unwrap();
        assert_eq!((info.header.vendor_id, info.header.product_code), (s.identity.vendor_id, s.identity.product_code));
        assert_eq!(info.header.revision, s.identity.revision);
        if let Some(m) = &s.mailbox {
            assert_eq!((info.header.mailbox_rx_offset, info.header.mailbox_rx_size), m.send);
        }
    }
}

#[test]
fn every_tolerated_departure_is_read_with_a_warning_and_strict_refuses() {
    let e = Eni::parse(LENIENT).unwrap();
    let lines: Vec<(u32, &str)> = e.warnings.iter().map(|w| (w.place.line, w.message.as_str())).collect();
    let has = |line: u32, text: &str| lines.iter().any(|(l, m)| *l == line && m.contains(text));
    assert!(has(1, "not UTF-8: read as windows-1252"), "{lines:?}");
    assert!(has(60, "AutoIncAddr: -1 read as 0xffff"), "{lines:?}");
    assert!(has(64, "ProductCode: '0x7d83052' read as 131608658"), "{lines:?}");
    assert!(has(66, "RevisionNo: ' 1179648 ' read as 1179648"), "{lines:?}");
    assert!(has(82, "Fixed: 'True' read as true"), "{lines:?}");
    assert!(has(118, "transition 'XY'"), "{lines:?}");
    assert!(has(124, "odd number of hex digits"), "{lines:?}");
    assert!(lines.iter().any(|(_, m)| m.contains("ReferenceClock: 'TRUE'")), "{lines:?}");
    assert!(lines.iter().any(|(_, m)| m.contains("ShiftTime: '+250000' read as 250000")), "{lines:?}");
    assert!(lines.iter().any(|(_, m)| m.contains("state 'RUNNING'")), "{lines:?}");
    assert_eq!(e.warnings.len(), 10, "{lines:?}");
    // Read as the messages say.
    let el2008 = &e.slaves[1];
    assert_eq!(
        (el2008.auto_inc, el2008.identity.product_code, el2008.identity.revision),
        (Some(0xFFFF), 0x07D8_3052, 0x0012_0000)
    );
    assert!(el2008.process_data.rx_pdos[0].fixed);
    assert_eq!(el2008.init_cmds[2].transitions, [Transition::parse("PI").unwrap()]);
    assert_eq!(el2008.init_cmds[2].data, [0, 0]);
    let v = el2008.init_cmds[2].validate.as_ref().unwrap();
    assert_eq!((v.data.as_slice(), v.mask.as_deref(), v.timeout_ms), (&[1u8, 0][..], Some(&[0x0F, 0][..]), Some(5000)));
    let drive = &e.slaves[2];
    assert_eq!(drive.name, "Drive \u{b5}");
    assert_eq!(drive.identity.vendor_id, 0xA8F);
    assert_eq!(drive.dc.unwrap().shift_time_ns, 250_000);
    assert!(drive.dc.unwrap().reference_clock);
    assert_eq!(drive.previous_port, Some(('B', 1001)));
    assert_eq!(drive.mailbox.as_ref().unwrap().poll_time_ms, Some(20));
    assert_eq!(e.cyclic[0].frames[0].cmds[1].states, [AlState::PreOp, AlState::SafeOp, AlState::Op]);
    assert_eq!(e.master.destination, Some([0xFF; 6]));
    assert_eq!(e.master.mailbox_states, Some((0x0900_0000, 1)));
    // Strict: the first departure is the error.
    let err = Eni::parse_strict(LENIENT).unwrap_err();
    assert_eq!(err.place.line, 1);
    assert!(err.to_string().contains("refused: strict"), "{err}");
}

/// A good file's text with `from` replaced by `to`: the first time, or every time where `from`
/// is a tag name's end (`Sm3>`, opening and closing).
fn broken(from: &str, to: &str) -> Vec<u8> {
    let text = encoding_free(LENIENT);
    assert!(text.contains(from), "{from}");
    if from.starts_with('<') { text.replacen(from, to, 1) } else { text.replace(from, to) }.into_bytes()
}

/// The test file as UTF-8 (its one non-ASCII byte replaced), for editing.
fn encoding_free(bytes: &[u8]) -> String {
    bytes.iter().map(|&b| if b < 0x80 { b as char } else { 'u' }).collect::<String>().replace("ISO-8859-1", "UTF-8")
}

#[test]
fn bad_files_are_refused_with_their_place() {
    let cases: &[(&str, &str, &str)] = &[
        ("<Cmd>12</Cmd>", "<Cmd>99</Cmd>", "command 99 is no EtherCAT command"),
        ("<DataLength>13</DataLength>", "<DataLength>1487</DataLength>", "more than a datagram carries"),
        (
            "<InputOffs>41</InputOffs>",
            "<InputOffs>60</InputOffs>",
            "InputOffs 60: the datagram's 14 bytes end past the image's 64 bytes",
        ),
        ("<VendorId>2</VendorId>", "<VendorId>two</VendorId>", "VendorId: 'two' is not a number"),
        ("<VendorId>2</VendorId>", "", "<Info> has no <VendorId>"),
        ("<ProductCode>72100946</ProductCode>", "<ProductCode>4294967296</ProductCode>", "out of range"),
        ("<Data>e903</Data>", "<Data>e9g3</Data>", "is not hex data"),
        // A character of more than one byte where a digit should be (found by the fuzzer: it
        // split the text inside the character and panicked).
        ("<DataMask>0f00</DataMask>", "<DataMask>0f\u{2014}0</DataMask>", "DataMask: '0f\u{2014}0' is not hex data"),
        ("<Data>e903</Data>", "<Data>+e903</Data>", "is not hex data"),
        (
            "<Destination>ffffffffffff</Destination>",
            "<Destination>ffff</Destination>",
            "a MAC address has 6 bytes, not 2",
        ),
        ("<DataMask>0f00</DataMask>", "<DataMask>0f</DataMask>", "validates 2 bytes (mask 1)"),
        ("Sm3>", "Sm16>", "an ESC has SyncManagers 0 to 15"),
        ("<ReferenceClock>TRUE</ReferenceClock>", "<ReferenceClock>yes</ReferenceClock>", "'yes' is not a boolean"),
        ("<EtherCATConfig Version=\"1.3\">", "<EtherCATInfo>", "malformed XML"),
    ];
    for (from, to, want) in cases {
        match Eni::parse(&broken(from, to)) {
            Ok(_) => panic!("{from} -> {to}: read"),
            Err(e) => {
                assert!(e.to_string().contains(want), "{from} -> {to}: {e}");
                assert!(e.place.line > 1 || want.contains("malformed"), "{from} -> {to}: {e}");
            }
        }
    }
    let root = Eni::parse(b"<EtherCATInfo/>").unwrap_err();
    assert_eq!(root.to_string(), "line 1, column 1: root element is <EtherCATInfo>, expected <EtherCATConfig>");
    let not_text = Eni::parse(b"<EtherCATConfig>\xff</EtherCATConfig>").unwrap_err();
    assert!(not_text.message.contains("not UTF-8"), "{not_text}");
    // A file cut short: placed at its end, not at line 1, column 1.
    let cut = Eni::parse(b"<EtherCATConfig>\n  <Config>\n    <Slave").unwrap_err();
    assert_eq!((cut.place.line, cut.place.column), (3, 11), "{cut}");
    assert!(cut.message.contains("a truncated file?"), "{cut}");
}

/// A drive's SoE init commands (`<Mailbox><SoE><InitCmds>`): each write read with its drive,
/// IDN, elements, data and timeout; one on an IDN beyond 16 bits and one that is no write left
/// out with a warning naming it.
#[test]
fn a_drive_s_soe_init_commands_are_read() {
    let e = Eni::parse(include_bytes!("data/ferrocat_soe.eni.xml")).unwrap();
    let mbx = e.slaves[2].mailbox.as_ref().unwrap();
    assert_eq!(mbx.protocols, ["CoE", "SoE"]);
    let cmds: Vec<_> = mbx
        .soe_init_cmds
        .iter()
        .map(|c| (c.transitions.clone(), c.drive, c.idn, c.elements, c.data.clone(), c.timeout_ms, c.fixed))
        .collect();
    let (ip, ps) = (Transition::parse("IP").unwrap(), Transition::parse("PS").unwrap());
    assert_eq!(
        cmds,
        [
            (vec![ip], 0, 1, 0x40, vec![0xF4, 0x01], Some(0), false),
            (vec![ps], 0, 0x8001, 0x40, vec![0xFA, 0x00], Some(500), true),
        ]
    );
    assert_eq!(mbx.soe_init_cmds[1].comment, "Gain");
    let soe: Vec<&str> = e.warnings.iter().map(|w| w.message.as_str()).filter(|m| m.contains("SoE")).collect();
    assert_eq!(
        soe,
        [
            "SoE init command: IDN -1 does not fit SoE's 16 bits: left out",
            "SoE init command for S-0-0030: opcode 1 is not a write request (3): left out"
        ]
    );
}
