//! Errors carry their context as values: the slave, what it lacks or did, the position asked
//! for, why DC cannot run; and their text reads as before.
use ferrocat_master::{DcConfig, DcError, Master, MasterError, SlaveError, SlaveRef};
use ferrocat_segment::{HostModel, SegmentConfig, VirtualIo};

fn scanned(toml: &str) -> Master<VirtualIo> {
    let cfg: SegmentConfig = toml::from_str(toml).unwrap();
    let mut m = Master::new(VirtualIo::new(cfg.build().unwrap(), HostModel::ideal(), 1));
    m.states().scan().unwrap();
    m
}

#[test]
fn errors_name_the_slave_and_what_as_values() {
    let mut m = scanned("seed = 1\n[[device]]\nbuiltin = 'EK1100'\n[[device]]\nbuiltin = 'EL2004'\n");
    // An SDO of a terminal without a mailbox.
    let e = m.acyclic().coe().sdo_read(1, 0x1008, 0).unwrap_err();
    match &e {
        MasterError::Slave { slave: SlaveRef { position: 1, name }, error: SlaveError::NoMailbox } => {
            assert_eq!(name, "EL2004")
        }
        other => panic!("{other:?}"),
    }
    assert_eq!(e.to_string(), "slave 1 (EL2004): has no mailbox");
    // A position past the last slave.
    let e = m.slaves().at(5).unwrap_err();
    assert!(matches!(e, MasterError::NoSuchSlave { position: 5, count: 2 }), "{e:?}");
    assert_eq!(e.to_string(), "no slave at position 5 (positions count from 0: 0 to 1)");
    // An entry the slave does not have.
    let e = m.states().configure().and_then(|_| m.image().output(1, "no such entry")).unwrap_err();
    assert!(matches!(&e, MasterError::Slave { error: SlaveError::NoOutput(n), .. } if n == "no such entry"), "{e:?}");
}

#[test]
fn dc_on_a_segment_without_clocks_says_why() {
    // An EL2004's ESC latches receive times but keeps no system time: no reference.
    let mut m = scanned("seed = 1\n[[device]]\nbuiltin = 'EL2004'\n");
    let e = m.dc().init_dc(&DcConfig::default()).unwrap_err();
    assert!(matches!(e, MasterError::Dc(DcError::NoSystemTime)), "{e:?}");
    assert_eq!(e.to_string(), "no slave has a DC system time (receive times only)");
}

#[test]
fn an_image_with_more_data_than_the_eeprom_is_refused_before_any_write() {
    let mut m = scanned("seed = 1\n[[device]]\nbuiltin = 'EK1100'\n");
    let mut img = m.slaves()[0].sii().to_image();
    let size = m.slaves()[0].sii().header.eeprom_size_bytes();
    img.resize(size + 2, 0xFF);
    img[size] = 0;
    match m.acyclic().sii().write(0, &img).unwrap_err() {
        MasterError::Slave { error: SlaveError::EepromTooSmall { image, eeprom }, .. } => {
            assert_eq!((image, eeprom), (size + 1, size))
        }
        other => panic!("{other:?}"),
    }
    // Padding (0xFF) past the end is no data: the image is written up to the EEPROM's end.
    img[size] = 0xFF;
    m.acyclic().sii().write(0, &img).unwrap();
}

#[test]
fn diagnosis_stays_within_its_deadline() {
    let mut m = scanned("seed = 1\n[[device]]\nbuiltin = 'EK1100'\n[[device]]\nbuiltin = 'SERVO'\n");
    m.states().configure().unwrap();
    let now = m.cyclic().now_ns();
    // Less than a round trip (at least 50 µs) left: nothing sent.
    assert_eq!(m.diagnosis().diagnose(now + 40_000, 1_000_000).unwrap(), 0);
    // Time enough: the counters (due at once) and one mailbox.
    assert_eq!(m.diagnosis().diagnose(now + 10_000_000, 1_000_000).unwrap(), 2);
    let s = m.diagnosis().diagnosis_stats();
    assert_eq!((s.counter_reads, s.mailbox_polls), (1, 1));
    assert!(m.diagnosis().error_counters()[0].is_some() && m.diagnosis().error_counters()[1].is_none());
}
