//! The master in virtual time against the in-process segment.
use ferrocat_esc::DigitalIo;
use ferrocat_master::Master;
use ferrocat_segment::SegmentConfig;
use ferrocat_segment::{HostModel, VirtualIo};
use ferrocat_wire::register::AlState;

fn master(toml: &str, host: HostModel) -> Master<VirtualIo> {
    let cfg: SegmentConfig = toml::from_str(toml).unwrap();
    Master::new(VirtualIo::new(cfg.build().unwrap(), host, 1))
}

/// An EK1100 and an EL2004 on an ideal host, scanned.
fn coupler_and_output_scanned() -> Master<VirtualIo> {
    let mut m =
        master("seed = 1\n[[device]]\nbuiltin = 'EK1100'\n[[device]]\nbuiltin = 'EL2004'\n", HostModel::ideal());
    m.states().scan().unwrap();
    m
}

fn real_io_segment() -> String {
    let e = ferrocat_testdata::shared("captures/eeprom");
    format!(
        "seed = 4\n[[device]]\neeprom = '{0}/ek1100.hex'\n[[device]]\neeprom = '{0}/el2004.bin'\n[[device]]\neeprom = '{0}/el2004.bin'\n",
        e.display()
    )
}

#[test]
fn needs_shared_ek1100_and_two_el2004_to_op_with_outputs() {
    let mut m = master(&real_io_segment(), HostModel::pc_rt());
    m.states().bring_up().unwrap();
    let names: Vec<_> = m.slaves().iter().map(|s| s.name()).collect();
    assert_eq!(names, ["EK1100", "EL2004", "EL2004"]);
    assert_eq!(
        m.slaves().iter().map(|s| s.dc().delay_ns).collect::<Vec<_>>(),
        [0, 145, 300],
        "SOEM on the real hardware: 0, 144, 299"
    );
    assert_eq!(m.slaves().iter().map(|s| s.ports().parent).collect::<Vec<_>>(), [None, Some(0), Some(1)]);
    assert_eq!(
        m.slaves().iter().map(|s| s.ports().active_text()).collect::<Vec<_>>(),
        ["1.1.0.0", "1.1.0.0", "1.0.0.0"]
    );
    assert!(m.slaves().iter().all(|s| s.status().state() == AlState::Op));
    assert_eq!(m.image().expected_wkc(), 4);
    // Outputs by entry name: channel 1 of the first terminal, channel 4 of the second.
    let a = m.image().output(1, "Output").unwrap();
    m.cyclic().set(a, 1);
    let b = m.slaves()[2].mapping().outputs[3].clone();
    let hb = ferrocat_master::Handle { bit: b.image_bit, bits: b.bits };
    m.cyclic().set(hb, 1);
    for _ in 0..10 {
        let now = ferrocat_master::io::Io::now_ns(m.cyclic().io_mut());
        ferrocat_master::io::Io::sleep_until(m.cyclic().io_mut(), now + 1_000_000);
        assert_eq!(m.cyclic().cycle().unwrap(), 4);
    }
    let outs: Vec<Vec<u8>> = m.io().seg.nodes[1..]
        .iter()
        .map(|n| n.esc.app().as_any().downcast_ref::<DigitalIo>().unwrap().outputs.clone())
        .collect();
    assert_eq!(outs, [vec![0x01], vec![0x08]]);
    assert_eq!(m.diagnosis().cycle_stats().wkc_errors, 0);
    // A group of two goes back to SAFEOP and returns to OP; the coupler stays in OP.
    m.states().request_state_group(&[1, 2], AlState::SafeOp).unwrap();
    assert_eq!(
        m.slaves().iter().map(|s| s.status().state()).collect::<Vec<_>>(),
        [AlState::Op, AlState::SafeOp, AlState::SafeOp]
    );
    m.states().request_state_group(&[1, 2], AlState::Op).unwrap();
    assert!(m.slaves().iter().all(|s| s.status().state() == AlState::Op));
}

#[test]
fn needs_shared_drive_sdo_of_every_kind_and_remapping() {
    let esi = ferrocat_testdata::shared("esi/Nanotec_C5-E-2-21.xml");
    let toml = format!("seed = 2\n[[device]]\nesi = '{}'\nproduct = 0x4F\n[[device]]\nbuiltin = 'EK1100'\n[[device]]\nbuiltin = 'EL1004'\n", esi.display());
    let mut m = master(&toml, HostModel::pc_rt());
    m.states().scan().unwrap();
    assert_eq!(m.slaves()[0].name(), "C5-E-2-21");
    m.states().configure().unwrap();
    // Expedited, normal (a name of more than 4 bytes), segmented (≈1 KiB), complete access.
    assert_eq!(m.acyclic().coe().sdo_read(0, 0x1018, 1).unwrap(), 0x26Cu32.to_le_bytes());
    let name = m.acyclic().coe().sdo_read(0, 0x1008, 0).unwrap();
    assert!(name.len() > 4, "{name:?}");
    let big = m.acyclic().coe().sdo_upload(0, 0x2701, 0, true).unwrap();
    assert!(big.len() > 1000);
    // A long string into the drive's customer storage (segmented download), and back
    // (segmented upload).
    let text = "ferrocat writes a long string through a 128-byte mailbox, segment by segment. ".repeat(12);
    let mut pattern = big.clone();
    pattern[2..2 + text.len()].copy_from_slice(text.as_bytes());
    m.acyclic().coe().sdo_download(0, 0x2701, 0, true, &pattern).unwrap();
    let back = m.acyclic().coe().sdo_upload(0, 0x2701, 0, true).unwrap();
    assert_eq!(&back[2..2 + text.len()], text.as_bytes());
    assert_eq!(back, pattern);
    assert_eq!(m.acyclic().coe().sdo_upload(0, 0x1C12, 0, true).unwrap()[..4], [1, 0, 0x00, 0x16]);
    m.acyclic().coe().sdo_write(0, 0x6060, 0, &[8]).unwrap();
    assert_eq!(m.acyclic().coe().sdo_read(0, 0x6060, 0).unwrap(), [8]);
    // Aborts by name.
    let e = m.acyclic().coe().sdo_read(0, 0x1234, 0).unwrap_err().to_string();
    assert!(e.contains("does not exist"), "{e}");
    // SDO information.
    let list = m.acyclic().coe().od_list(0).unwrap();
    assert!(list.len() > 150 && list.contains(&0x6040));
    assert_eq!(m.acyclic().coe().object_info(0, 0x1018).unwrap().max_subindex, 4);
    // Remapping: 0x1601 (target position, profile velocity) instead of 0x1600.
    let before = m.image().byte_counts().0;
    m.config().remap(0, true, &[0x1601]).unwrap();
    assert_ne!(m.image().byte_counts().0, before);
    assert_eq!(m.slaves()[0].mapping().outputs.iter().map(|e| e.index).collect::<Vec<_>>(), [0x607A, 0x6081]);
    m.states().start().unwrap();
    let target = m.slaves()[0].mapping().outputs[0].clone();
    m.cyclic().set(ferrocat_master::Handle { bit: target.image_bit, bits: target.bits }, 4242);
    for _ in 0..5 {
        let now = ferrocat_master::io::Io::now_ns(m.cyclic().io_mut());
        ferrocat_master::io::Io::sleep_until(m.cyclic().io_mut(), now + 1_000_000);
        m.cyclic().cycle().unwrap();
    }
    assert_eq!(
        m.acyclic().coe().sdo_read(0, 0x607A, 0).unwrap(),
        4242i32.to_le_bytes(),
        "the output reached the drive's object"
    );
}

#[test]
fn needs_shared_emergencies_reach_the_application() {
    use ferrocat_master::MasterEvent;
    let esi = ferrocat_testdata::shared("esi/Nanotec_C5-E-2-21.xml");
    let toml = format!("seed = 2\n[[device]]\nesi = '{}'\nproduct = 0x4F\n", esi.display());
    let mut m = master(&toml, HostModel::pc_rt());
    m.states().scan().unwrap();
    m.states().configure().unwrap();
    assert_eq!(m.acyclic().poll_mailboxes().unwrap(), 0, "nothing waiting");
    let e = ferrocat_wire::coe::Emergency { error_code: 0x8611, error_register: 0x20, data: [1, 2, 3, 4, 5] };
    // The Nanotec is a CiA402 drive: its CoE device queues the message.
    let dev = m.cyclic().io_mut().seg.nodes[0]
        .esc
        .app_mut()
        .as_any_mut()
        .downcast_mut::<ferrocat_esc::Cia402Drive>()
        .unwrap();
    dev.coe.emergency(e);
    // The ESC delivers it to SM1 with the next frame; the application's poll finds it.
    m.acyclic().poll_mailboxes().unwrap();
    m.acyclic().poll_mailboxes().unwrap();
    let got: Vec<_> = m
        .diagnosis()
        .events()
        .iter()
        .filter(|e| matches!(e, MasterEvent::Emergency { .. }))
        .map(|e| e.to_string())
        .collect();
    assert_eq!(
        got,
        ["slave 0 (C5-E-2-21): emergency 0x8611 (following error), error register 0x20, data [01, 02, 03, 04, 05]"]
    );
    // And an SDO still works afterwards.
    assert_eq!(m.acyclic().coe().sdo_read(0, 0x1018, 2).unwrap(), 0x4Fu32.to_le_bytes());
}

#[test]
fn inputs_come_back_and_esi_describes_a_bare_slave() {
    // EL1004 inputs set on the simulated terminal arrive in the image, by entry name.
    let mut m = master(
        "seed = 5\n[[device]]\nbuiltin = 'EK1100'\n[[device]]\nbuiltin = 'EL1004'\n[[device]]\nbuiltin = 'EL2004'\n",
        HostModel::pc_rt(),
    );
    m.states().bring_up().unwrap();
    let io = m.cyclic().io_mut().seg.nodes[1].esc.app_mut().as_any_mut().downcast_mut::<DigitalIo>().unwrap();
    io.inputs = vec![0b0101];
    for _ in 0..3 {
        m.cyclic().cycle().unwrap();
    }
    let bits: Vec<u64> = m.slaves()[1]
        .mapping()
        .inputs
        .iter()
        .map(|e| m.image().get(ferrocat_master::Handle { bit: e.image_bit, bits: e.bits }))
        .collect();
    assert_eq!(bits, [1, 0, 1, 0]);
    assert_eq!(m.image().get(m.image().input(1, "Input").unwrap()), 1);
}

/// An ESI for a 2-channel output terminal; `pdos` says whether it describes its PDOs.
fn terminal_esi(pdos: bool) -> String {
    let pdo = if pdos {
        "<RxPdo Fixed=\"1\" Sm=\"0\"><Index>#x1600</Index><Name>Ch1</Name><Entry><Index>#x7000</Index><SubIndex>1</SubIndex><BitLen>1</BitLen><Name>Out 1</Name><DataType>BOOL</DataType></Entry></RxPdo>\
         <RxPdo Fixed=\"1\" Sm=\"0\"><Index>#x1601</Index><Name>Ch2</Name><Entry><Index>#x7010</Index><SubIndex>1</SubIndex><BitLen>1</BitLen><Name>Out 2</Name><DataType>BOOL</DataType></Entry></RxPdo>"
    } else {
        ""
    };
    format!(
        "<EtherCATInfo><Vendor><Id>#x2</Id><Name>Test</Name></Vendor><Descriptions><Devices><Device Physics=\"KK\">\
         <Type ProductCode=\"#x12345678\" RevisionNo=\"#x1\">XT0002</Type><Name>Two outputs</Name>\
         <Fmmu>Outputs</Fmmu><Sm StartAddress=\"#xF00\" ControlByte=\"#x44\" Enable=\"1\">Outputs</Sm>{pdo}\
         <Eeprom><ByteSize>2048</ByteSize><ConfigData>0401</ConfigData></Eeprom></Device></Devices></Descriptions></EtherCATInfo>"
    )
}

#[test]
fn esi_describes_a_slave_whose_sii_does_not() {
    let dir = std::env::temp_dir();
    let (bare, full) = (
        dir.join(format!("ferrocat-bare-{}.xml", std::process::id())),
        dir.join(format!("ferrocat-full-{}.xml", std::process::id())),
    );
    std::fs::write(&bare, terminal_esi(false)).unwrap();
    std::fs::write(&full, terminal_esi(true)).unwrap();
    let toml = format!(
        "seed = 1\n[[device]]\nbuiltin = 'EK1100'\n[[device]]\nesi = '{}'\nproduct = 0x12345678\n",
        bare.display()
    );
    let mut m = master(&toml, HostModel::ideal());
    m.states().bring_up().unwrap();
    assert!(m.slaves()[1].mapping().outputs.is_empty(), "the SII alone says nothing");
    // The same bring-up with the ESI: two outputs, in OP, reaching the terminal.
    let mut m = master(&toml, HostModel::ideal());
    let f = ferrocat_esi::EsiFile::parse(&std::fs::read_to_string(&full).unwrap()).unwrap();
    for d in f.devices {
        m.config().add_esi(f.vendor_id, d);
    }
    m.states().bring_up().unwrap();
    std::fs::remove_file(&bare).ok();
    std::fs::remove_file(&full).ok();
    assert_eq!(m.slaves()[1].mapping().outputs.iter().map(|e| e.name.as_str()).collect::<Vec<_>>(), ["Out 1", "Out 2"]);
    let h = m.image().output(1, "Out 2").unwrap();
    m.cyclic().set(h, 1);
    m.cyclic().cycle().unwrap();
    let io = m.io().seg.nodes[1].esc.app().as_any().downcast_ref::<DigitalIo>().unwrap();
    assert_eq!(io.outputs, [0b10]);
}

#[test]
fn aliases_are_honoured_and_wkc_errors_name_the_slave() {
    let mut m = master(
        "seed = 1\n[[device]]\nbuiltin = 'EK1100'\n[[device]]\nbuiltin = 'EL2004'\nstation_alias = 0x0777\n",
        HostModel::ideal(),
    );
    m.states().scan().unwrap();
    assert_eq!((m.slaves()[0].alias(), m.slaves()[1].alias()), (0, 0x0777));
    let mut d = [0u8; 2];
    let fprd_alias = ferrocat_wire::Address::Device { adp: 0x0777, ado: 0x0010 };
    assert_eq!(
        m.cyclic().datagram(ferrocat_wire::Command::FPRD, fprd_alias, &mut d).unwrap(),
        0,
        "alias not yet enabled"
    );
    assert_eq!(m.states().enable_alias(1).unwrap(), 0x0777);
    assert_eq!(
        m.cyclic()
            .datagram(ferrocat_wire::Command::FPRD, ferrocat_wire::Address::Device { adp: 0x0777, ado: 0x0010 }, &mut d)
            .unwrap(),
        1
    );
    assert_eq!(u16::from_le_bytes(d), 0x1002, "the alias reaches the slave with station address 0x1002");
    assert!(m.states().enable_alias(0).unwrap_err().to_string().contains("no station alias"));
    let e = m
        .cyclic()
        .expect_datagram(
            ferrocat_wire::Command::FPRD,
            ferrocat_wire::Address::Device { adp: 0x4242, ado: 0x0130 },
            &mut d,
            1,
        )
        .unwrap_err()
        .to_string();
    assert!(e.contains("FPRD 0x4242:0x0130") && e.contains("station address or alias 0x4242"), "{e}");
    let e = m
        .cyclic()
        .expect_datagram(ferrocat_wire::Command::BRD, ferrocat_wire::Address::Device { adp: 0, ado: 0x0130 }, &mut d, 5)
        .unwrap_err()
        .to_string();
    assert!(e.contains("2 of 5 expected answers"), "{e}");
}

#[test]
fn sii_write_programs_only_changed_words_and_reads_back() {
    let mut m = coupler_and_output_scanned();
    let mut info = m.slaves()[1].sii().clone();
    assert_eq!(info.header.station_alias, 0);
    info.header.station_alias = 0x0321;
    let mut image = info.to_image();
    let e = m.acyclic().sii().write(1, &image).unwrap_err().to_string();
    assert!(e.contains("header CRC"), "a stale CRC is refused: {e}");
    image[14] = ferrocat_wire::sii::header_crc(&image);
    // The alias word and the header CRC word differ; nothing else.
    assert_eq!(m.acyclic().sii().write(1, &image).unwrap(), 2);
    assert_eq!(m.slaves()[1].sii().header.station_alias, 0x0321);
    m.states().scan().unwrap();
    assert_eq!(m.slaves()[1].sii().header.station_alias, 0x0321, "what a new scan reads from the EEPROM");
    assert_eq!(m.slaves()[1].name(), "EL2004");
    assert_eq!(m.acyclic().sii().write(1, &image).unwrap(), 0, "the same image again writes nothing");
}

/// IgH's `ethercat alias`: the alias goes into EEPROM word 4 with the checksum, and the ESC
/// takes it at its next power-on (not before, and not at a reload).
#[test]
fn an_alias_written_to_the_eeprom_is_taken_at_the_next_power_on() {
    let mut m = coupler_and_output_scanned();
    assert_eq!(m.acyclic().sii().set_alias(1, 0x0BAD).unwrap(), 2, "words 4 and 7");
    m.states().scan().unwrap();
    assert_eq!(m.slaves()[1].alias(), 0, "the register keeps its power-on value");
    assert!(m.slaves()[1].esc().eeprom_problem().is_none());
    let t = m.cyclic().now_ns();
    m.cyclic().io_mut().seg.schedule(t + 1_000_000, ferrocat_segment::Event::PowerOff { node: 1 });
    m.cyclic().io_mut().seg.schedule(t + 2_000_000, ferrocat_segment::Event::PowerOn { node: 1 });
    m.cyclic().sleep_until(t + 3_000_000);
    m.states().scan().unwrap();
    assert_eq!(m.slaves()[1].alias(), 0x0BAD);
    assert_eq!(m.states().enable_alias(1).unwrap(), 0x0BAD);
    m.states().bring_up().unwrap();
}

/// An EEPROM whose configuration area fails its checksum (an alias written without it): the
/// ESC runs unconfigured and stays in INIT, and the master says so at once, by name.
#[test]
fn a_slave_whose_eeprom_checksum_is_wrong_is_named_at_once() {
    let m = coupler_and_output_scanned();
    let mut image = m.slaves()[1].sii().to_image();
    image[8] ^= 0x01;
    let path = std::env::temp_dir().join(format!("ferrocat-badcrc-{}.bin", std::process::id()));
    std::fs::write(&path, &image).unwrap();
    let mut m = master(
        &format!("seed = 1\n[[device]]\nbuiltin = 'EK1100'\n[[device]]\neeprom = '{}'\n", path.display()),
        HostModel::ideal(),
    );
    std::fs::remove_file(&path).unwrap();
    m.states().scan().unwrap();
    let problem = m.slaves()[1].esc().eeprom_problem().expect("an unconfigured ESC");
    assert!(problem.contains("checksum"), "{problem}");
    assert_eq!(m.slaves()[1].esc().eeprom_status & 0x1800, 0x1800, "checksum error, not loaded");
    assert!(m.slaves()[0].esc().eeprom_problem().is_none());
    let t0 = m.cyclic().now_ns();
    let e = m.states().bring_up().unwrap_err().to_string();
    println!("{e}");
    assert!(e.contains("slave 1 (EL2004)") && e.contains("checksum"), "{e}");
    assert!(m.cyclic().now_ns() - t0 < m.config().settings().state_timeout_ns / 10, "not after the state timeout");
}

/// The virtual host's NIC sends one frame at a time: of two frames handed over 1 µs apart, the
/// second leaves after the first. A NIC's transmit stamp shows the wait; the kernel's software
/// stamp, taken at the hand-over, does not — as on real hardware.
#[test]
fn back_to_back_frames_queue_at_the_nic_and_only_its_stamps_see_it() {
    use ferrocat_master::io::Io;
    use ferrocat_segment::{Latency, Stamps};
    use ferrocat_wire::ethernet::{EthernetRepr, BROADCAST};
    use ferrocat_wire::{Address, Command, DatagramHeader, FrameWriter};
    let eth = EthernetRepr { dst: BROADCAST, src: [0x10; 6], vlan_tci: None, ethertype: 0 };
    let mut frame = vec![0u8; 1514];
    let mut w = FrameWriter::new(&mut frame, &eth).unwrap();
    w.push(&DatagramHeader::new(Command::BRD, 1, Address::Device { adp: 0, ado: 0 }, 100), &[0; 100], 0).unwrap();
    let n = w.finish().unwrap();
    frame.truncate(n);
    let wire_ns = (8 + n as u64 + 4 + 12) * 80;
    for stamps in
        [Stamps::Hardware, Stamps::Software { tx_early: Latency::fixed(500.0), rx_late: Latency::fixed(500.0) }]
    {
        let host = HostModel {
            name: "test",
            send: Latency::fixed(1_000.0),
            recv: Latency::fixed(1_000.0),
            wake: Latency::ZERO,
            stamps,
            timer_resolution_ns: 0,
            gpio: None,
        };
        let cfg = SegmentConfig::from_device_args(&["EK1100".into(), "EL2004".into()]).unwrap();
        let mut io = VirtualIo::new(cfg.build().unwrap(), host, 1);
        io.send(&frame).unwrap();
        let tx1 = io.last_tx_ns().unwrap();
        io.send(&frame).unwrap();
        let tx2 = io.last_tx_ns().unwrap();
        let mut buf = [0u8; 1536];
        let (_, rx1) = io.recv(&mut buf, u64::MAX).unwrap().unwrap();
        let (_, rx2) = io.recv(&mut buf, u64::MAX).unwrap().unwrap();
        assert_eq!(rx2 - rx1, wire_ns, "{stamps:?}: the replies come back a frame apart");
        match stamps {
            Stamps::Hardware => assert_eq!(tx2 - tx1, wire_ns, "the NIC stamps the real departure"),
            _ => assert_eq!(tx2 - tx1, 1_000, "the kernel stamps the hand-over"),
        }
    }
}
