//! ESI init commands on a device whose file has no dictionary (our `ferrocat_init_commands.xml`:
//! a CoE terminal whose init commands write its channel settings, 0x8000): the simulated device
//! takes the objects its own file's commands write, so the master's commands reach them and the
//! terminal reaches OP; told by a file of another revision to write an object it lacks, the
//! master leaves that one out with a warning and goes on.
use ferrocat_esi::EsiFile;
use ferrocat_master::{Master, MasterEvent};
use ferrocat_segment::{DeviceToml, HostModel, Number, SegmentConfig, VirtualIo};
use ferrocat_wire::register::AlState;

const FILE: &str = concat!(env!("CARGO_MANIFEST_DIR"), "/../esi/tests/data/ferrocat_init_commands.xml");

fn terminal() -> Master<VirtualIo> {
    let dev =
        DeviceToml { esi: Some(FILE.into()), product: Some(Number::Text("#x00010005".into())), ..Default::default() };
    let cfg = SegmentConfig { devices: vec![dev], ..SegmentConfig::default() };
    Master::new(VirtualIo::new(cfg.build().unwrap(), HostModel::ideal(), 1))
}

fn description() -> (u32, ferrocat_esi::Device) {
    let file = EsiFile::parse(&std::fs::read_to_string(FILE).unwrap()).unwrap();
    (file.vendor_id, file.devices[0].clone())
}

#[test]
fn the_objects_a_file_s_init_commands_write_are_there_and_take_the_commands() {
    // Without the description nothing is sent: the objects are there, zero.
    let mut m = terminal();
    m.states().scan().unwrap();
    m.states().configure().unwrap();
    assert_eq!(m.acyclic().coe().sdo_read(0, 0x8000, 21).unwrap(), [0, 0]);
    // With it, both commands are sent in PREOP and the terminal goes on to OP.
    let mut m = terminal();
    let (vendor, dev) = description();
    m.config().add_esi(vendor, dev);
    m.states().scan().unwrap();
    m.states().configure().unwrap();
    assert_eq!(m.acyclic().coe().sdo_read(0, 0x8000, 6).unwrap(), [1]);
    assert_eq!(m.acyclic().coe().sdo_read(0, 0x8000, 21).unwrap(), [0x0A, 0]);
    m.states().start().unwrap();
    assert_eq!(m.slaves()[0].status().state(), AlState::Op);
    assert!(!m.diagnosis().take_events().iter().any(|e| matches!(e, MasterEvent::InitCommandSkipped { .. })));
}

#[test]
fn a_command_on_an_object_the_device_lacks_is_left_out_with_a_warning() {
    let mut m = terminal();
    let (vendor, mut dev) = description();
    // Another revision's command: a second channel this terminal does not have.
    let mut second = dev.init_cmds[1].clone();
    (second.index, second.comment) = (0x8010, "Filter settings channel 2".into());
    dev.init_cmds.push(second);
    m.config().add_esi(vendor, dev);
    m.states().scan().unwrap();
    m.states().configure().unwrap();
    let events = m.diagnosis().take_events();
    let skipped: Vec<String> =
        events.iter().filter(|e| matches!(e, MasterEvent::InitCommandSkipped { .. })).map(|e| e.to_string()).collect();
    assert_eq!(skipped.len(), 1, "{events:?}");
    assert!(
        skipped[0].contains("ESI init command PS 0x8010:15 (\"Filter settings channel 2\", line ")
            && skipped[0].contains("not sent: "),
        "{skipped:?}"
    );
    // The commands the terminal has are sent all the same.
    assert_eq!(m.acyclic().coe().sdo_read(0, 0x8000, 21).unwrap(), [0x0A, 0]);
    m.states().start().unwrap();
    assert_eq!(m.slaves()[0].status().state(), AlState::Op);
}
