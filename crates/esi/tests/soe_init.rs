//! SoE init commands (`<Mailbox><SoE><InitCmd>`): read with every element our test drive's file
//! gives; those a master cannot send as written left out with a warning naming their line; a
//! malformed one an error.
use ferrocat_esi::EsiFile;
use ferrocat_wire::soe::{Elements, Idn};

#[test]
fn the_test_drives_commands_are_read_in_file_order_with_every_element() {
    let f = EsiFile::parse(include_str!("data/ferrocat_soe_drive.xml")).unwrap();
    assert!(f.warnings.is_empty(), "{:?}", f.warnings);
    let plain = f.devices.iter().find(|d| d.type_name == "FC-SOE-DRIVE").unwrap();
    assert!(plain.soe_init_cmds.is_empty());
    let d = f.devices.iter().find(|d| d.type_name == "FC-SOE-DRIVE-INIT").unwrap();
    let got: Vec<(&str, Idn, &[u8], &str)> =
        d.soe_init_cmds.iter().map(|c| (c.transitions[0].as_str(), c.idn, &c.data[..], c.comment.as_str())).collect();
    let gain = Idn::product(0, 1).unwrap();
    assert_eq!(
        got,
        [
            ("IP", Idn(1), &500u16.to_le_bytes()[..], "NC cycle time"),
            ("PS", gain, &250u16.to_le_bytes()[..], "Gain"),
            ("PS", Idn(999), &10u16.to_le_bytes()[..], "Brake delay (later revisions)"),
            ("SO", gain, &300u16.to_le_bytes()[..], "Gain in OP"),
        ]
    );
    let c = &d.soe_init_cmds[1];
    assert_eq!((c.drive, c.elements, c.timeout_ms), (0, Elements::VALUE, Some(500)));
    assert_eq!(d.soe_init_cmds[0].timeout_ms, None);
    assert!(d.soe_init_cmds.windows(2).all(|w| w[0].line < w[1].line));
}

fn device(cmds: &str) -> String {
    format!(
        r##"<?xml version="1.0"?>
<EtherCATInfo>
  <Vendor><Id>#x0F3C</Id><Name>ferrocat tests</Name></Vendor>
  <Descriptions><Devices><Device>
    <Type ProductCode="#x1" RevisionNo="#x1">T</Type><Name>T</Name>
    <Mailbox><SoE>
{cmds}
    </SoE></Mailbox>
  </Device></Devices></Descriptions>
</EtherCATInfo>"##
    )
}

#[test]
fn a_command_the_master_cannot_send_as_written_is_left_out_with_a_warning() {
    let xml = device(
        "<InitCmd><Transition>PS</Transition><IDN>#xFFFFFFFF</IDN><Data>00</Data></InitCmd>
<InitCmd><Transition>PS</Transition><IDN>65584</IDN><Data>00</Data></InitCmd>
<InitCmd><Transition>PS</Transition><OpCode>1</OpCode><IDN>30</IDN></InitCmd>
<InitCmd><Transition>PS</Transition><DriveNo>2</DriveNo><IDN>47</IDN><Elements>0</Elements><Data>01000000</Data></InitCmd>",
    );
    let f = EsiFile::parse(&xml).unwrap();
    let w: Vec<(u32, &str)> = f.warnings.iter().map(|w| (w.line, w.message.as_str())).collect();
    assert_eq!(w.len(), 4, "{w:#?}");
    assert!(w[0].0 == 7 && w[0].1.contains("IDN 0xffffffff is not a 16-bit IDN: left out"), "{w:#?}");
    assert!(w[1].0 == 8 && w[1].1.contains("IDN 0x00010030 is not a 16-bit IDN"), "{w:#?}");
    assert!(w[2].0 == 9 && w[2].1.contains("opcode 1 is not a write request (3): left out"), "{w:#?}");
    assert!(w[3].0 == 10 && w[3].1.contains("<Elements> 0 names no element"), "{w:#?}");
    let cmds = &f.devices[0].soe_init_cmds;
    assert_eq!(cmds.len(), 1, "{cmds:?}");
    assert_eq!((cmds[0].drive, cmds[0].idn, cmds[0].elements), (2, Idn(47), Elements::VALUE));
}

#[test]
fn an_enis_wrapped_form_is_read_with_a_warning() {
    let xml = device("<InitCmds><InitCmd><Transition>SO</Transition><IDN>47</IDN></InitCmd></InitCmds>");
    let f = EsiFile::parse(&xml).unwrap();
    assert_eq!(f.warnings.len(), 1, "{:?}", f.warnings);
    assert!(f.warnings[0].message.contains("an ENI's form"), "{:?}", f.warnings);
    assert_eq!(f.devices[0].soe_init_cmds[0].idn, Idn(47));
}

#[test]
fn a_malformed_command_is_an_error_naming_its_line() {
    for (cmd, message) in [
        ("<InitCmd><IDN>47</IDN></InitCmd>", "SoE <InitCmd> lacks <Transition>"),
        ("<InitCmd><Transition>PS</Transition></InitCmd>", "SoE <InitCmd> lacks <IDN>"),
        (
            "<InitCmd><Transition>PS</Transition><DriveNo>8</DriveNo><IDN>47</IDN></InitCmd>",
            "<DriveNo> 8 is not a drive 0–7",
        ),
        ("<InitCmd><Transition>PS</Transition><IDN>47</IDN><Data>zz</Data></InitCmd>", ""),
    ] {
        let e = EsiFile::parse(&device(cmd)).unwrap_err();
        assert_eq!(e.line, 7, "{cmd}: {e}");
        assert!(e.message.contains(message), "{cmd}: {e}");
    }
}
