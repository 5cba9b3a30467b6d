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
