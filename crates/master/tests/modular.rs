//! Modular devices end to end in virtual time: the simulator plugs an ESI device's modules into
//! its slots (PDOs at each slot's indices, 0xF050), the master configures and checks them
//! (0xF030), and a device told other modules refuses SAFEOP with AL status code 0x0070.
use ferrocat_master::Master;
use ferrocat_segment::{DeviceToml, HostModel, Number, SegmentConfig, VirtualIo};
use ferrocat_wire::register::AlState;

const FILE: &str = concat!(env!("CARGO_MANIFEST_DIR"), "/../esi/tests/data/ferrocat_modular.xml");

fn drive(modules: Option<&[&str]>) -> Master<VirtualIo> {
    let dev = DeviceToml {
        esi: Some(FILE.into()),
        product: Some(Number::Text("#x00010002".into())),
        modules: modules.map(|m| m.iter().map(|s| Number::Text(s.to_string())).collect()),
        ..Default::default()
    };
    let cfg = SegmentConfig { devices: vec![dev], ..SegmentConfig::default() };
    Master::new(VirtualIo::new(cfg.build().unwrap(), HostModel::ideal(), 1))
}

fn indices(entries: &[ferrocat_master::Mapped]) -> Vec<u16> {
    entries.iter().filter(|e| e.index != 0).map(|e| e.index).collect()
}

#[test]
fn the_default_modules_map_one_csp_axis_per_slot_and_reach_op() {
    let mut m = drive(None);
    m.states().scan().unwrap();
    m.states().configure().unwrap();
    assert_eq!(m.config().detected_modules(0).unwrap(), [0x9010, 0x9010]);
    // 0xF000: the index distance between modules and how many the slots take at most.
    assert_eq!(m.acyclic().coe().sdo_read(0, 0xF000, 1).unwrap(), 0x800u16.to_le_bytes());
    assert_eq!(m.acyclic().coe().sdo_read(0, 0xF000, 2).unwrap(), 2u16.to_le_bytes());
    // Axis 1's objects 0x800 above axis 0's (CiA402's multi-axis layout).
    assert_eq!(indices(&m.slaves()[0].mapping().outputs), [0x6040, 0x607A, 0x6840, 0x687A]);
    assert_eq!(indices(&m.slaves()[0].mapping().inputs), [0x6041, 0x6064, 0x6841, 0x6864]);
    m.config().configure_modules(0, &[0x9010, 0x9010]).unwrap();
    m.states().start().unwrap();
    assert_eq!(m.slaves()[0].status().state(), AlState::Op);
}

#[test]
fn chosen_modules_are_plugged_in_order() {
    let mut m = drive(Some(&["#x9010", "#x9020"]));
    m.states().scan().unwrap();
    m.states().configure().unwrap();
    assert_eq!(m.config().detected_modules(0).unwrap(), [0x9010, 0x9020]);
    assert_eq!(indices(&m.slaves()[0].mapping().outputs), [0x6040, 0x607A, 0x6840, 0x68FF]);
    assert_eq!(indices(&m.slaves()[0].mapping().inputs), [0x6041, 0x6064, 0x6841, 0x686C]);
}

#[test]
fn other_modules_configured_are_an_error_naming_the_slot_and_the_slave_refuses_safeop() {
    let mut m = drive(None);
    m.states().scan().unwrap();
    m.states().configure().unwrap();
    let e = m.config().configure_modules(0, &[0x9010, 0x9020]).unwrap_err().to_string();
    assert!(e.contains("slot 1: module 0x00009020 configured, 0x00009010 detected"), "{e}");
    // Told so, the slave keeps to PREOP.
    let e = m.states().request_state(0, AlState::SafeOp).unwrap_err().to_string();
    assert!(e.contains("0x0070"), "{e}");
    // Told the right modules, it goes on.
    m.config().configure_modules(0, &[0x9010, 0x9010]).unwrap();
}

#[test]
fn a_slot_that_refuses_a_module_or_a_count_out_of_range_is_a_build_error() {
    let build = |modules: &[&str]| {
        let dev = DeviceToml {
            esi: Some(FILE.into()),
            product: Some(Number::Text("#x00010002".into())),
            modules: Some(modules.iter().map(|s| Number::Text(s.to_string())).collect()),
            ..Default::default()
        };
        SegmentConfig { devices: vec![dev], ..SegmentConfig::default() }.build().unwrap_err().to_string()
    };
    let e = build(&["#x9010"]);
    assert!(e.contains("takes 2 to 2 modules, 1 given"), "{e}");
    let e = build(&["#x9010", "#x0801"]);
    assert!(e.contains("slot 1 (Axis): module FC-DO4 (0x00000801) does not fit it"), "{e}");
}

/// The simulated drive behind slave 0.
fn sim(m: &Master<VirtualIo>) -> &ferrocat_esc::Cia402Drive {
    m.io().seg.nodes[0].esc.app().as_any().downcast_ref().unwrap()
}

/// Two axes on one slave are two state machines: the driver finds both, enabling the second
/// leaves the first disabled, and a fault on the second (its error code at 0x683F) leaves the
/// first alone.
#[test]
fn each_axis_of_a_two_axis_drive_runs_its_own_state_machine() {
    use ferrocat_master::cia402::{drive_to_goal, Axis, Goal};
    use ferrocat_wire::cia402::{error_code, State};
    let mut m = drive(None);
    m.states().scan().unwrap();
    m.states().configure().unwrap();
    m.states().start().unwrap();
    let mut axes = Axis::all(&m, 0).unwrap();
    assert_eq!(axes.iter().map(|a| (a.axis, a.index(0x6040))).collect::<Vec<_>>(), [(0, 0x6040), (1, 0x6840)]);
    assert_eq!(sim(&m).axes().len(), 2);
    axes[1].set_goal(Goal::OperationEnabled);
    drive_to_goal(&mut m, &mut axes[1..], 1_000_000, 200).unwrap();
    let s = sim(&m);
    assert_eq!((s.axes()[0].state(), s.axes()[1].state()), (State::SwitchOnDisabled, State::OperationEnabled));
    m.cyclic().cycle().unwrap();
    assert_eq!(axes[0].update(&mut m), Some(State::SwitchOnDisabled));
    m.cyclic().io_mut().seg.nodes[0]
        .esc
        .app_mut()
        .as_any_mut()
        .downcast_mut::<ferrocat_esc::Cia402Drive>()
        .unwrap()
        .inject_axis_fault(1, error_code::OVERCURRENT);
    for _ in 0..20 {
        m.cyclic().cycle().unwrap();
    }
    assert_eq!(axes[1].update(&mut m), Some(State::Fault));
    assert_eq!(axes[0].update(&mut m), Some(State::SwitchOnDisabled));
    let code = |m: &mut Master<VirtualIo>, index| {
        u16::from_le_bytes(m.acyclic().coe().sdo_read(0, index, 0).unwrap()[..2].try_into().unwrap())
    };
    assert_eq!((code(&mut m, 0x603F), code(&mut m, 0x683F)), (0, error_code::OVERCURRENT));
    // Past the last axis a drive may have, the driver says so.
    let e = Axis::on_axis(&m, 0, 8).unwrap_err().to_string();
    assert!(e.contains("at most 8"), "{e}");
}

/// A module's objects sit at its slot's indices in the simulated device, and with the ESI
/// description in `Master::esi` the master sends its init commands (each at its slot's index)
/// in PREOP before SAFEOP; one on an object the device lacks is left out with a warning, one
/// the device refuses otherwise is an error naming the command.
#[test]
fn module_objects_and_init_commands_follow_the_slot() {
    use ferrocat_esi::EsiFile;
    let file = EsiFile::parse(&std::fs::read_to_string(FILE).unwrap()).unwrap();
    let dev = file.devices.iter().find(|d| d.product_code == 0x10002).unwrap();
    let plugged = dev.plugged(&file.modules, &[0x9010, 0x9010]).unwrap();
    let cmds: Vec<(u16, &str)> = plugged.init_cmds.iter().map(|c| (c.index, c.comment.as_str())).collect();
    assert_eq!(
        cmds,
        [
            (0x6060, "Modes of operation: CSP"),
            (0x2000, "Gear ratio"),
            (0x6860, "Modes of operation: CSP"),
            (0x2800, "Gear ratio")
        ]
    );
    let read_u32 = |m: &mut Master<VirtualIo>, index| {
        let v = m.acyclic().coe().sdo_read(0, index, 0).unwrap();
        let mut b = [0u8; 4];
        b[..v.len().min(4)].copy_from_slice(&v[..v.len().min(4)]);
        u32::from_le_bytes(b)
    };
    // Without the description: the module objects with their defaults, nothing sent.
    let mut m = drive(None);
    m.states().scan().unwrap();
    m.states().configure().unwrap();
    assert_eq!((read_u32(&mut m, 0x2000), read_u32(&mut m, 0x2800)), (1, 1));
    assert_eq!((read_u32(&mut m, 0x6060), read_u32(&mut m, 0x6860)), (0, 0));
    // With it: every command at its slot's index.
    let mut m = drive(None);
    m.config().add_esi(file.vendor_id, plugged.clone());
    m.states().scan().unwrap();
    m.states().configure().unwrap();
    assert_eq!((read_u32(&mut m, 0x2000), read_u32(&mut m, 0x2800)), (10, 10));
    assert_eq!((read_u32(&mut m, 0x6060), read_u32(&mut m, 0x6860)), (8, 8));
    m.states().start().unwrap();
    // A command to an object the device lacks (the file describes a family; this device has
    // no 0x2F00): left out with a warning, the others sent, the slave configured.
    let mut absent = plugged.clone();
    absent.init_cmds[3].index = 0x2F00;
    let mut m = drive(None);
    m.config().add_esi(file.vendor_id, absent);
    m.states().scan().unwrap();
    m.states().configure().unwrap();
    let skipped: Vec<String> = m
        .diagnosis()
        .take_events()
        .iter()
        .filter(|e| matches!(e, ferrocat_master::MasterEvent::InitCommandSkipped { .. }))
        .map(|e| e.to_string())
        .collect();
    assert_eq!(skipped.len(), 1, "{skipped:?}");
    assert!(skipped[0].contains("ESI init command PS 0x2f00:00 (\"Gear ratio\", line "), "{skipped:?}");
    assert!(skipped[0].contains("not sent"), "{skipped:?}");
    assert_eq!((read_u32(&mut m, 0x2000), read_u32(&mut m, 0x6860)), (10, 8));
    // A command the device refuses for another reason (a read-only object) is an error
    // naming it.
    let mut refused = plugged;
    (refused.init_cmds[3].index, refused.init_cmds[3].subindex) = (0x1018, 1);
    let mut m = drive(None);
    m.config().add_esi(file.vendor_id, refused);
    m.states().scan().unwrap();
    let e = m.states().configure().unwrap_err().to_string();
    assert!(e.contains("ESI init command PS 0x1018:0x01 (\"Gear ratio\", line "), "{e}");
}
