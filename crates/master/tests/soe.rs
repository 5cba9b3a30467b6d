//! The SoE client against the simulated drive of our `ferrocat_soe_drive.xml` (a mailbox of
//! 40 bytes each way, so that values of a few dozen bytes come and go in fragments), in
//! virtual time: every element, fragments both ways, write protection by state, limits, the
//! drive's errors by code, and devices that speak no SoE.
use ferrocat_master::wire::soe::{DataType, Elements, Idn, SoeError, ValueLength};
use ferrocat_master::{AlState, Master, MasterError, SlaveError};
use ferrocat_segment::{HostModel, SegmentConfig, VirtualIo};

fn drive() -> Master<VirtualIo> {
    let esi = concat!(env!("CARGO_MANIFEST_DIR"), "/../esi/tests/data/ferrocat_soe_drive.xml");
    let cfg =
        SegmentConfig::from_device_args(&["EK1100".into(), "EL2004".into(), format!("{esi}:FC-SOE-DRIVE")]).unwrap();
    let mut m = Master::new(VirtualIo::new(cfg.build().unwrap(), HostModel::pc_rt(), 3));
    m.states().scan().unwrap();
    m.states().configure().unwrap();
    m
}

fn soe_error(r: Result<impl std::fmt::Debug, MasterError>) -> SoeError {
    match r {
        Err(MasterError::Slave { error: SlaveError::Soe { error, .. }, .. }) => error,
        other => panic!("not an SoE error: {other:?}"),
    }
}

#[test]
fn every_element_of_an_idn_is_read_and_a_long_value_comes_in_fragments() {
    let mut m = drive();
    // 44 bytes with the list's lengths: two fragments of a 40-byte mailbox.
    let v = m.acyclic().soe().value(2, 0, Idn::FIRMWARE_VERSION).unwrap();
    let (text, max) = ferrocat_master::wire::soe::list_items(&v).unwrap();
    assert_eq!(text, b"ferrocat SoE drive (ferrocat simulation)");
    assert_eq!(max, 64);
    let d = m.acyclic().soe().describe(2, 0, Idn::product(0, 1).unwrap()).unwrap();
    assert_eq!(d.name.as_deref(), Some("Gain"));
    assert_eq!(d.unit.as_deref(), Some("%"));
    assert_eq!((d.attribute.length(), d.attribute.data_type()), (ValueLength::Fixed(2), DataType::Unsigned));
    assert_eq!((d.min, d.max, d.value), (Some(vec![0, 0]), Some(vec![0xE8, 0x03]), vec![100, 0]));
    // Several elements in one reply, in the order of their bits: attribute, then value.
    let both = m.acyclic().soe().read(2, 0, Idn(1), Elements(Elements::ATTRIBUTE.0 | Elements::VALUE.0)).unwrap();
    assert_eq!(&both[4..], &1000u16.to_le_bytes());
    let all = m.acyclic().soe().idn_list(2, 0, Idn::ALL_IDNS).unwrap();
    for idn in [Idn(1), Idn::AT_CONFIG, Idn::MDT_CONFIG, Idn::FIRMWARE_VERSION, Idn(0x8001)] {
        assert!(all.contains(&idn), "{idn} in S-0-0017: {all:?}");
    }
    assert_eq!(m.acyclic().soe().idn_list(2, 0, Idn::AT_CONFIG).unwrap(), [Idn(135), Idn(51)]);
}

#[test]
fn writes_are_checked_as_the_drive_checks_them_and_long_ones_go_in_fragments() {
    let mut m = drive();
    let gain = Idn::product(0, 1).unwrap();
    m.acyclic().soe().write(2, 0, gain, Elements::VALUE, &500u16.to_le_bytes()).unwrap();
    assert_eq!(m.acyclic().soe().value(2, 0, gain).unwrap(), 500u16.to_le_bytes());
    let too_big = m.acyclic().soe().write(2, 0, gain, Elements::VALUE, &1001u16.to_le_bytes());
    assert_eq!(soe_error(too_big), SoeError::VALUE_ABOVE_MAX);
    assert_eq!(soe_error(m.acyclic().soe().write(2, 0, gain, Elements::NAME, b"x")), SoeError::NAME_READ_ONLY);
    // 16 IDNs (36 bytes with the lengths) in two fragments, in PREOP where S-0-0016 is writable.
    let list: Vec<Idn> = (0..16).map(|k| Idn(40 + k)).collect();
    let mut data = vec![32, 0, 32, 0];
    data.extend(list.iter().flat_map(|i| i.0.to_le_bytes()));
    m.acyclic().soe().write(2, 0, Idn::AT_CONFIG, Elements::VALUE, &data).unwrap();
    assert_eq!(m.acyclic().soe().idn_list(2, 0, Idn::AT_CONFIG).unwrap(), list);
    // In SAFEOP the telegram's configuration is protected.
    m.states().request_state(2, AlState::SafeOp).unwrap();
    let protected = m.acyclic().soe().write(2, 0, Idn::AT_CONFIG, Elements::VALUE, &data);
    assert_eq!(soe_error(protected), SoeError::VALUE_WRITE_PROTECTED_NOW);
    let read_only = m.acyclic().soe().write(2, 0, Idn::FIRMWARE_VERSION, Elements::VALUE, &[0, 0, 0, 0]);
    assert_eq!(soe_error(read_only), SoeError::VALUE_READ_ONLY);
}

#[test]
fn the_drive_s_refusals_and_devices_without_soe_are_errors_that_say_so() {
    let mut m = drive();
    let e = m.acyclic().soe().value(2, 0, Idn(999)).unwrap_err();
    assert!(e.to_string().contains("SoE S-0-0999 (drive 0): SoE error 0x1001 (no IDN)"), "{e}");
    assert_eq!(soe_error(m.acyclic().soe().value(2, 1, Idn(1))), SoeError::INVALID_DRIVE);
    assert_eq!(soe_error(m.acyclic().soe().read(2, 0, Idn::TELEGRAM_TYPE, Elements::UNIT)), SoeError::NO_UNIT);
    // The coupler has no mailbox; the EL2004 no SoE.
    let e = m.acyclic().soe().value(0, 0, Idn(1)).unwrap_err();
    assert!(matches!(e, MasterError::Slave { error: SlaveError::NoMailbox, .. }), "{e}");
    let e = m.acyclic().soe().value(1, 0, Idn(1)).unwrap_err();
    assert!(matches!(e, MasterError::Slave { error: SlaveError::NoMailbox | SlaveError::Unsupported(_), .. }), "{e}");
    // The mailbox works on after each refusal.
    assert_eq!(m.acyclic().soe().value(2, 0, Idn::TELEGRAM_TYPE).unwrap(), 7u16.to_le_bytes());
}

/// SoE as a running master's acyclic side serves it: submitted, one datagram at a time in the
/// cycles' spare time, beside cycles whose working counters stay whole and the diagnosis's
/// work. (In virtual time the drive's fragments come at once; that the diagnosis's mailbox
/// polls leave a request's replies alone shows live, in `cli/tests/soe_live.rs`.)
#[test]
fn soe_is_served_beside_the_cycle_in_fragments() {
    use ferrocat_master::{Answer, Request};
    const CYCLE_NS: u64 = 1_000_000;
    let mut m = drive();
    m.states().start().unwrap();
    let serve = |m: &mut Master<VirtualIo>, request: Request| {
        let id = m.acyclic().submit(request);
        let mut next = m.cyclic().now_ns();
        for _ in 0..500 {
            next += CYCLE_NS;
            assert_eq!(m.cyclic().cycle().unwrap(), m.image().expected_wkc(), "a whole cycle beside SoE");
            m.acyclic().serve_requests(next - CYCLE_NS / 4).unwrap();
            // Diagnosis in the spare time polls the mailboxes that no request holds.
            m.diagnosis().diagnose(next - CYCLE_NS / 4, 100 * CYCLE_NS).unwrap();
            if let Some((_, a)) = m.acyclic().take_answers().into_iter().find(|(k, _)| *k == id) {
                return a;
            }
            m.cyclic().sleep_until(next);
        }
        panic!("not answered in 500 cycles");
    };
    let a = serve(
        &mut m,
        Request::SoeRead { position: 2, drive: 0, idn: Idn::FIRMWARE_VERSION, elements: Elements::VALUE },
    );
    let Answer::Data(v) = a.unwrap() else { panic!("not data") };
    assert_eq!(ferrocat_master::wire::soe::list_items(&v).unwrap().0, b"ferrocat SoE drive (ferrocat simulation)");
    // A 36-byte list in two fragments, in SAFEOP (started): protected there.
    let mut data = vec![32, 0, 32, 0];
    data.extend((0..16u16).flat_map(|k| (40 + k).to_le_bytes()));
    let a = serve(
        &mut m,
        Request::SoeWrite { position: 2, drive: 0, idn: Idn::AT_CONFIG, elements: Elements::VALUE, data },
    );
    assert_eq!(soe_error(a), SoeError::VALUE_WRITE_PROTECTED_NOW);
    let gain = Idn::product(0, 1).unwrap();
    let a = serve(
        &mut m,
        Request::SoeWrite { position: 2, drive: 0, idn: gain, elements: Elements::VALUE, data: vec![7, 0] },
    );
    assert_eq!(a.unwrap(), Answer::Written);
    let a = serve(&mut m, Request::SoeRead { position: 2, drive: 0, idn: gain, elements: Elements::VALUE });
    assert_eq!(a.unwrap(), Answer::Data(vec![7, 0]));
}

/// `Request::Mailbox` passes a message through as the mailbox gateway does: an SoE read of a
/// long value written once, then each further fragment the drive sends awaited without a write
/// (empty data); the fragments joined are the value the SoE client reads.
#[test]
fn a_passed_through_read_comes_in_fragments_each_awaited_without_a_write() {
    use ferrocat_master::wire::mailbox::MailboxType;
    use ferrocat_master::{Answer, Request};
    const CYCLE_NS: u64 = 1_000_000;
    let mut m = drive();
    let want = m.acyclic().soe().read(2, 0, Idn::FIRMWARE_VERSION, Elements::VALUE).unwrap();
    m.states().start().unwrap();
    let serve = |m: &mut Master<VirtualIo>, data: Vec<u8>| {
        let id =
            m.acyclic().submit(Request::Mailbox { position: 2, mailbox_type: MailboxType::SOE, data, reply: true });
        let mut next = m.cyclic().now_ns();
        for _ in 0..500 {
            next += CYCLE_NS;
            m.cyclic().cycle().unwrap();
            m.acyclic().serve_requests(next - CYCLE_NS / 4).unwrap();
            if let Some((_, a)) = m.acyclic().take_answers().into_iter().find(|(k, _)| *k == id) {
                let Ok(Answer::Mailbox(reply)) = a else { panic!("{a:?}") };
                return reply;
            }
            m.cyclic().sleep_until(next);
        }
        panic!("not answered in 500 cycles");
    };
    // Read request (opcode 1), the value element (0x40), S-0-0030.
    let [i0, i1] = Idn::FIRMWARE_VERSION.0.to_le_bytes();
    let mut replies = vec![serve(&mut m, vec![0x01, 0x40, i0, i1])];
    // The incomplete bit (3) of the SoE header: more fragments follow.
    while replies.last().unwrap()[0] & 0x08 != 0 {
        replies.push(serve(&mut m, Vec::new()));
    }
    assert!(replies.len() > 1, "a 40-byte mailbox gives the value in fragments");
    let data: Vec<u8> = replies.iter().flat_map(|r| r[4..].to_vec()).collect();
    assert_eq!(data, want);
}

/// The drive of `FC-SOE-DRIVE-INIT`, its ESI description in the master or not.
fn drive_with_init_commands(description: Option<ferrocat_esi::Device>) -> Master<VirtualIo> {
    let esi = concat!(env!("CARGO_MANIFEST_DIR"), "/../esi/tests/data/ferrocat_soe_drive.xml");
    let cfg = SegmentConfig::from_device_args(&[format!("{esi}:FC-SOE-DRIVE-INIT")]).unwrap();
    let mut m = Master::new(VirtualIo::new(cfg.build().unwrap(), HostModel::pc_rt(), 3));
    if let Some(d) = description {
        m.config().add_esi(0x0F3C, d);
    }
    m.states().scan().unwrap();
    m
}

fn init_description() -> ferrocat_esi::Device {
    let path = concat!(env!("CARGO_MANIFEST_DIR"), "/../esi/tests/data/ferrocat_soe_drive.xml");
    let file = ferrocat_esi::EsiFile::parse(&std::fs::read_to_string(path).unwrap()).unwrap();
    file.devices.into_iter().find(|d| d.type_name == "FC-SOE-DRIVE-INIT").unwrap()
}

/// The ESI's SoE init commands go at their transitions (IP and PS in PREOP, SO in SAFEOP), one
/// on an IDN the drive lacks is left out with an event naming it, one the drive refuses is an
/// error naming it; the application's own command on an absent IDN stays an error.
#[test]
fn esi_soe_init_commands_are_sent_at_their_transitions() {
    let gain = Idn::product(0, 1).unwrap();
    let u16_of = |v: Vec<u8>| u16::from_le_bytes([v[0], v[1]]);
    // Without the description: the drive's own values.
    let mut m = drive_with_init_commands(None);
    m.states().configure().unwrap();
    assert_eq!(u16_of(m.acyclic().soe().value(0, 0, gain).unwrap()), 100);
    // With it: IP and PS in PREOP, the absent S-0-0999 skipped, SO on the way to OP.
    let mut m = drive_with_init_commands(Some(init_description()));
    m.states().configure().unwrap();
    assert_eq!(u16_of(m.acyclic().soe().value(0, 0, Idn(1)).unwrap()), 500);
    assert_eq!(u16_of(m.acyclic().soe().value(0, 0, gain).unwrap()), 250);
    let skipped: Vec<String> = m
        .diagnosis()
        .take_events()
        .iter()
        .filter(|e| matches!(e, ferrocat_master::MasterEvent::SoeInitCommandSkipped { .. }))
        .map(|e| e.to_string())
        .collect();
    assert_eq!(skipped.len(), 1, "{skipped:?}");
    assert!(
        skipped[0].contains(
            "ESI SoE init command PS S-0-0999 drive 0 (\"Brake delay (later revisions)\", line 83) not sent: SoE error 0x1001"
        ),
        "{skipped:?}"
    );
    m.states().start().unwrap();
    assert_eq!(u16_of(m.acyclic().soe().value(0, 0, gain).unwrap()), 300);
    // A value the drive refuses: an error naming the command.
    let mut refused = init_description();
    refused.soe_init_cmds[1].data = 1001u16.to_le_bytes().to_vec();
    let mut m = drive_with_init_commands(Some(refused));
    let e = m.states().configure().unwrap_err();
    let MasterError::Slave { error: SlaveError::ConfigIdn { error, .. }, .. } = &e else { panic!("{e:?}") };
    assert!(
        matches!(**error, MasterError::Slave { error: SlaveError::Soe { error: SoeError::VALUE_ABOVE_MAX, .. }, .. }),
        "{e:?}"
    );
    assert!(e.to_string().contains("ESI SoE init command PS P-0-0001 drive 0 (\"Gain\", line 73): "), "{e}");
    // The application's own command on an absent IDN is its mistake: an error.
    let mut m = drive_with_init_commands(None);
    let mut own = init_description().soe_init_cmds[2].clone();
    own.line = 12;
    m.config().setup_mut(0).unwrap().soe_init_cmds.push(own);
    let e = m.states().configure().unwrap_err().to_string();
    assert!(e.contains("SoE init command PS S-0-0999 drive 0 (\"Brake delay (later revisions)\", line 12): "), "{e}");
    assert!(!e.contains("ESI"), "{e}");
}

/// A drive that speaks SoE alone (`FC-SOE-ONLY`, whose file gives no PDOs): the master maps its
/// telegrams as S-0-0024 (the MDT, outputs) and S-0-0016 (the AT, inputs) name them, and the
/// simulated drive checks its SyncManagers against the same lists: a list changed in PREOP
/// changes both, and the slave reaches OP with whole working counters.
#[test]
fn a_drive_that_speaks_soe_alone_maps_its_telegram_configuration() {
    let esi = concat!(env!("CARGO_MANIFEST_DIR"), "/../esi/tests/data/ferrocat_soe_drive.xml");
    let build = || {
        let cfg = SegmentConfig::from_device_args(&["EK1100".into(), format!("{esi}:FC-SOE-ONLY")]).unwrap();
        let mut m = Master::new(VirtualIo::new(cfg.build().unwrap(), HostModel::pc_rt(), 3));
        m.states().scan().unwrap();
        m
    };
    let entries = |m: &Master<VirtualIo>, outputs: bool| -> Vec<(u16, u8, String)> {
        let map = m.slaves()[1].mapping();
        let list = if outputs { &map.outputs } else { &map.inputs };
        list.iter().map(|e| (e.index, e.bits, e.name.clone())).collect()
    };
    let mut m = build();
    m.states().configure().unwrap();
    assert_eq!(
        entries(&m, true),
        [
            (134, 16, "S-0-0134 Master control word".to_string()),
            (47, 32, "S-0-0047 Position command value".to_string())
        ]
    );
    assert_eq!(entries(&m, false).iter().map(|e| (e.0, e.1)).collect::<Vec<_>>(), [(135, 16), (51, 32)]);
    m.states().start().unwrap();
    for _ in 0..20 {
        m.cyclic().cycle().unwrap();
    }
    assert_eq!(m.diagnosis().cycle_stats().wkc_errors, 0);
    // The AT with the position command beside the feedback: ten bytes of inputs on both sides.
    let mut m = build();
    let mut list = vec![6, 0, 32, 0];
    list.extend([135u16, 51, 47].iter().flat_map(|i| i.to_le_bytes()));
    // Written as a configuration tool's startup list writes it: an init command at IP, before
    // the mapping is read.
    m.config().setup_mut(1).unwrap().soe_init_cmds.push(ferrocat_esi::SoeInitCmd {
        line: 1,
        transitions: vec!["IP".into()],
        drive: 0,
        idn: Idn::AT_CONFIG,
        elements: Elements::VALUE,
        data: list,
        timeout_ms: None,
        comment: "AT with the position command".into(),
    });
    m.states().configure().unwrap();
    assert_eq!(entries(&m, false).iter().map(|e| e.0).collect::<Vec<_>>(), [135, 51, 47]);
    m.states().start().unwrap();
    for _ in 0..20 {
        m.cyclic().cycle().unwrap();
    }
    assert_eq!(m.diagnosis().cycle_stats().wkc_errors, 0);
    // CoE is not its protocol: the master says so before it asks.
    let e = m.acyclic().coe().sdo_read(1, 0x1000, 0).unwrap_err().to_string();
    assert_eq!(e, "slave 1 (FC-SOE-ONLY): does not support CoE");
}

/// A two-axis drive that speaks SoE alone: the simulated device has the two drives its init
/// commands address, each takes its own, and the master maps both telegrams, drive after drive
/// (the entry's subindex its drive), to OP with whole working counters.
#[test]
fn a_two_axis_soe_drive_maps_both_telegrams() {
    let esi = concat!(env!("CARGO_MANIFEST_DIR"), "/../esi/tests/data/ferrocat_soe_drive.xml");
    let file = ferrocat_esi::EsiFile::parse(&std::fs::read_to_string(esi).unwrap()).unwrap();
    let two = file.devices.into_iter().find(|d| d.type_name == "FC-SOE-ONLY-2AX").unwrap();
    assert_eq!(two.soe_drives(), 2);
    let cfg = SegmentConfig::from_device_args(&["EK1100".into(), format!("{esi}:FC-SOE-ONLY-2AX")]).unwrap();
    let mut m = Master::new(VirtualIo::new(cfg.build().unwrap(), HostModel::pc_rt(), 3));
    m.config().add_esi(0x0F3C, two);
    m.states().scan().unwrap();
    m.states().configure().unwrap();
    let entries = |m: &Master<VirtualIo>, outputs: bool| -> Vec<(u16, u8, u8)> {
        let map = m.slaves()[1].mapping();
        let list = if outputs { &map.outputs } else { &map.inputs };
        list.iter().map(|e| (e.index, e.subindex, e.bits)).collect()
    };
    assert_eq!(entries(&m, true), [(134, 0, 16), (47, 0, 32), (134, 1, 16), (47, 1, 32)]);
    assert_eq!(entries(&m, false), [(135, 0, 16), (51, 0, 32), (135, 1, 16), (51, 1, 32)]);
    assert_eq!(m.slaves()[1].mapping().inputs[2].name, "drive 1 S-0-0135 Drive status word");
    for drive in [0, 1] {
        assert_eq!(m.acyclic().soe().value(1, drive, Idn(1)).unwrap(), 500u16.to_le_bytes(), "drive {drive}");
    }
    assert_eq!(soe_error(m.acyclic().soe().value(1, 2, Idn(1))), SoeError::INVALID_DRIVE);
    m.states().start().unwrap();
    for _ in 0..20 {
        m.cyclic().cycle().unwrap();
    }
    assert_eq!(m.diagnosis().cycle_stats().wkc_errors, 0);
    assert_eq!(m.slaves()[1].status().state(), AlState::Op);
}

/// CoE init commands for a drive that speaks SoE alone: the description's are not sent, an
/// event saying how many and why; the application's own is sent and refused, naming it.
#[test]
fn init_commands_of_a_protocol_the_mailbox_lacks() {
    let path = concat!(env!("CARGO_MANIFEST_DIR"), "/../esi/tests/data/ferrocat_soe_drive.xml");
    let file = ferrocat_esi::EsiFile::parse(&std::fs::read_to_string(path).unwrap()).unwrap();
    let mut only = file.devices.into_iter().find(|d| d.type_name == "FC-SOE-ONLY").unwrap();
    let coe_cmd = |transition: &str| ferrocat_esi::InitCmd {
        transitions: vec![transition.into()],
        index: 0x2000,
        data: vec![1],
        comment: "a family's object".into(),
        ..Default::default()
    };
    only.init_cmds = vec![coe_cmd("PS"), coe_cmd("PS"), coe_cmd("SO")];
    let build = |description: ferrocat_esi::Device| {
        let cfg = SegmentConfig::from_device_args(&[format!("{path}:FC-SOE-ONLY")]).unwrap();
        let mut m = Master::new(VirtualIo::new(cfg.build().unwrap(), HostModel::pc_rt(), 3));
        m.config().add_esi(0x0F3C, description);
        m.states().scan().unwrap();
        m
    };
    let mut m = build(only.clone());
    m.states().configure().unwrap();
    m.states().start().unwrap();
    let not_sent: Vec<(String, usize, String)> = m
        .diagnosis()
        .take_events()
        .iter()
        .filter_map(|e| match e {
            ferrocat_master::MasterEvent::InitCommandsNotSent { transition, protocol, count, .. } => {
                Some((transition.clone(), *count, protocol.name().to_string()))
            }
            _ => None,
        })
        .collect();
    assert_eq!(not_sent, [("PS".into(), 2, "CoE".into()), ("SO".into(), 1, "CoE".into())]);
    assert_eq!(m.slaves()[0].status().state(), AlState::Op);
    // The application's own: its mistake, an error naming it.
    let mut m = build(only);
    m.config().setup_mut(0).unwrap().init_cmds.push(coe_cmd("PS"));
    let e = m.states().configure().unwrap_err().to_string();
    assert!(e.contains("does not support CoE"), "{e}");
    assert!(e.contains("0x2000"), "{e}");
}

/// A plan's IDN writes (an ENI's SoE init commands) go to the drive in PREOP, after the scan
/// and before the mapping is read.
#[test]
fn a_plan_s_idn_writes_reach_the_drive() {
    let esi = concat!(env!("CARGO_MANIFEST_DIR"), "/../esi/tests/data/ferrocat_soe_drive.xml");
    let cfg = SegmentConfig::from_device_args(&["EK1100".into(), format!("{esi}:FC-SOE-DRIVE")]).unwrap();
    let mut m = Master::new(VirtualIo::new(cfg.build().unwrap(), HostModel::pc_rt(), 3));
    let write = |idn: Idn, value: u16| ferrocat_master::plan::PlanIdn {
        drive: 0,
        idn,
        elements: Elements::VALUE,
        data: value.to_le_bytes().to_vec(),
        timeout_ms: None,
        comment: String::new(),
    };
    let gain = Idn::product(0, 1).unwrap();
    let plan = ferrocat_master::plan::Plan {
        idns: vec![Vec::new(), vec![write(Idn(1), 500), write(gain, 250)]],
        ..Default::default()
    };
    m.config().set_plan(plan).unwrap();
    m.states().scan().unwrap();
    m.states().configure().unwrap();
    let u16_of = |v: Vec<u8>| u16::from_le_bytes([v[0], v[1]]);
    assert_eq!(u16_of(m.acyclic().soe().value(1, 0, Idn(1)).unwrap()), 500);
    assert_eq!(u16_of(m.acyclic().soe().value(1, 0, gain).unwrap()), 250);
}

/// A mailbox asked for before the slaves are configured (in INIT its SyncManagers are off): an
/// error that says so, not a malformed reply read from plain memory.
#[test]
fn a_mailbox_in_init_is_an_error_that_says_so() {
    let esi = concat!(env!("CARGO_MANIFEST_DIR"), "/../esi/tests/data/ferrocat_soe_drive.xml");
    let cfg = SegmentConfig::from_device_args(&[format!("{esi}:FC-SOE-DRIVE")]).unwrap();
    let mut m = Master::new(VirtualIo::new(cfg.build().unwrap(), HostModel::pc_rt(), 3));
    m.states().scan().unwrap();
    let e = m.acyclic().soe().value(0, 0, Idn::FIRMWARE_VERSION).unwrap_err();
    assert!(matches!(e, MasterError::Slave { error: SlaveError::MailboxInInit, .. }), "{e:?}");
    assert!(e.to_string().contains("mailbox is not set up in INIT"), "{e}");
    m.states().configure().unwrap();
    assert!(m.acyclic().soe().value(0, 0, Idn::FIRMWARE_VERSION).is_ok());
}
