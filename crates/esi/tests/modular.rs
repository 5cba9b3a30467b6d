//! Modular devices in ESI: slots, modules and the index arithmetic of `DependOnSlot`, on the
//! project's own test file and on a vendor's.
use ferrocat_esi::{Depend, EsiFile};

fn own() -> EsiFile {
    let xml = include_str!("data/ferrocat_modular.xml");
    EsiFile::parse(xml).unwrap()
}

#[test]
fn slots_and_modules_of_a_modular_io_head_and_a_two_axis_drive() {
    let f = own();
    assert_eq!(f.modules.len(), 5);
    let head = &f.devices[0];
    let slots = head.slots.as_ref().expect("the I/O head has slots");
    assert_eq!((slots.slot_index_increment, slots.slot_pdo_increment), (0x10, 1));
    assert_eq!(slots.slots.len(), 1);
    let s = &slots.slots[0];
    assert_eq!((s.min_instances, s.max_instances, s.name.as_str()), (1, 8, "Terminal"));
    assert_eq!(s.module_idents, [0x801, 0x802, 0x803]);
    assert_eq!(s.default_module, Some(0x801));
    let drive = &f.devices[1];
    let axes = drive.slots.as_ref().unwrap();
    assert_eq!((axes.slot_index_increment, axes.slot_pdo_increment), (0x800, 0x10));
    assert_eq!(axes.slots[0].default_module, Some(0x9010));
    let csv = f.module(0x9020).unwrap();
    assert_eq!((csv.type_name.as_str(), csv.class.as_deref()), ("FC-AXIS-CSV", Some("Axis")));
    assert_eq!(csv.rx_pdos[0].index_depends, Depend::Slot);
    assert_eq!(csv.rx_pdos[0].entries[1].index_depends, Depend::Slot);
}

#[test]
fn a_module_in_slot_n_moves_its_indices_by_n_increments() {
    let f = own();
    let axes = f.devices[1].slots.as_ref().unwrap();
    let csp = f.module(0x9010).unwrap();
    // Axis 0 as written; axis 1 at 0x6000 + 0x800 (CiA402's second axis), PDOs 0x10 on.
    let (rx0, tx0) = csp.pdos_in_slot(axes, 0, 0);
    assert_eq!(rx0[0].index, 0x1600);
    assert_eq!(rx0[0].entries.iter().map(|e| e.index).collect::<Vec<_>>(), [0x6040, 0x607A]);
    assert_eq!(tx0[0].entries[1].index, 0x6064);
    let (rx1, tx1) = csp.pdos_in_slot(axes, 1, 0);
    assert_eq!((rx1[0].index, tx1[0].index), (0x1610, 0x1A10));
    assert_eq!(rx1[0].entries.iter().map(|e| e.index).collect::<Vec<_>>(), [0x6840, 0x687A]);
    assert_eq!(tx1[0].entries.iter().map(|e| e.index).collect::<Vec<_>>(), [0x6841, 0x6864]);
    assert!(rx1[0].entries.iter().all(|e| e.index_depends == Depend::None), "resolved");
    // A padding entry (index 0, no DependOnSlot) stays 0 in any slot.
    let head = f.devices[0].slots.as_ref().unwrap();
    let (rx, _) = f.module(0x801).unwrap().pdos_in_slot(head, 3, 0);
    assert_eq!((rx[0].index, rx[0].entries[0].index, rx[0].entries[1].index), (0x1603, 0x7030, 0));
}

#[test]
fn an_odd_length_default_is_read_with_a_warning_naming_line_and_column() {
    let f = own();
    let obj = f.devices[0].dictionary.as_ref().unwrap().objects.iter().find(|o| o.index == 0xF000).unwrap();
    assert_eq!(obj.default_data.as_deref(), Some(&[0x02][..]));
    assert_eq!(f.warnings.len(), 1, "{:?}", f.warnings);
    let w = f.warnings[0].to_string();
    let line =
        include_str!("data/ferrocat_modular.xml").lines().position(|l| l.contains("<DefaultData>2")).unwrap() + 1;
    assert!(w.starts_with(&format!("line {line}, column ")), "{w}");
    assert!(w.contains("odd length 1") && w.contains("read as '02'"), "{w}");
    // A second parse starts with no warnings of the first.
    assert_eq!(EsiFile::parse(include_str!("data/ferrocat_modular.xml")).unwrap().warnings.len(), 1);
}

#[test]
fn needs_shared_weidmueller_slots_and_modules() {
    let path = ferrocat_testdata::shared("esi/Weidmueller_UR20_FBC.xml");
    let f = EsiFile::parse(&std::fs::read_to_string(path).unwrap()).unwrap();
    let slots = f.devices[0].slots.as_ref().expect("the UR20 coupler has slots");
    assert_eq!((slots.slot_index_increment, slots.slot_pdo_increment), (16, 1));
    assert_eq!((slots.slots[0].min_instances, slots.slots[0].max_instances), (1, 64));
    assert_eq!(slots.slots[0].module_classes.len(), 8);
    assert_eq!(f.modules.len(), 2);
    let m = &f.modules[0];
    assert_eq!((m.ident, m.type_name.as_str()), (0x001F_7E40, "UR20-4DI-4DO-PN-FSOE-V2"));
    // In the third slot its output PDO and entries move by 2 and 2 × 16.
    let (rx, _) = m.pdos_in_slot(slots, 2, 0);
    assert_eq!(rx[0].index, 0x1602);
    assert_eq!(rx[0].entries[0].index, 0x7020);
    // Its init commands (PS: name and module id at 0x8000 + 16 per slot) and its objects move
    // the same way; the coupler's own command stays at 0xF810.
    assert_eq!(m.init_cmds.len(), 2);
    assert_eq!(
        (m.init_cmds[1].index, m.init_cmds[1].subindex, &m.init_cmds[1].data[..]),
        (0x8000, 0x0A, &[0x00, 0x1F, 0x7E, 0x40][..])
    );
    assert_eq!(m.init_cmds[1].transitions, ["PS"]);
    let cmds = m.init_cmds_in_slot(slots, 2, 0);
    assert_eq!((cmds[0].index, cmds[1].index), (0x8020, 0x8020));
    assert_eq!(m.dictionary.as_ref().unwrap().objects.len(), 11);
    let coupler = &f.devices[0];
    assert_eq!(coupler.init_cmds.iter().map(|c| (c.index, c.subindex)).collect::<Vec<_>>(), [(0xF810, 1)]);
    let plugged = coupler.plugged(&f.modules, &[0x001F_7E40, 0x0020_6E40]).unwrap();
    let at: Vec<u16> = plugged.init_cmds.iter().map(|c| c.index).collect();
    assert_eq!(at, [0xF810, 0x8000, 0x8000, 0x8010, 0x8010]);
    let dict = plugged.dictionary.as_ref().unwrap();
    for (slot, module) in [(0u16, &f.modules[0]), (1, &f.modules[1])] {
        for o in &module.dictionary.as_ref().unwrap().objects {
            let at = if o.index_depends == Depend::Slot { o.index + 16 * slot } else { o.index };
            assert!(dict.object(at).is_some(), "slot {slot}: object {:#06x} at {at:#06x}", o.index);
        }
    }
}

/// A drive whose axes are optional slots (MinInstances 0, one per axis, each naming a default)
/// has every default plugged, in slot order; a slot that needs a module and names none has no
/// default set.
#[test]
fn optional_slots_with_a_default_module_get_it() {
    let xml = include_str!("data/ferrocat_modular.xml").replace(
        r#"<Slot MinInstances="2" MaxInstances="2">
            <Name>Axis</Name>
            <ModuleIdent Default="1">#x00009010</ModuleIdent>
            <ModuleIdent>#x00009020</ModuleIdent>
          </Slot>"#,
        r#"<Slot MinInstances="0" MaxInstances="1"><Name>Axis A</Name>
            <ModuleIdent Default="1">#x00009010</ModuleIdent><ModuleIdent>#x00009020</ModuleIdent></Slot>
          <Slot MinInstances="0" MaxInstances="1"><Name>Axis B</Name>
            <ModuleIdent>#x00009010</ModuleIdent><ModuleIdent Default="1">#x00009020</ModuleIdent></Slot>"#,
    );
    let f = EsiFile::parse(&xml).unwrap();
    let drive = f.devices.iter().find(|d| d.type_name == "FC-2AXIS").unwrap();
    assert_eq!(drive.slots.as_ref().unwrap().slots.len(), 2, "the replacement took");
    let defaults = drive.default_modules().unwrap();
    assert_eq!(defaults, [0x9010, 0x9020]);
    let plugged = drive.plugged(&f.modules, &defaults).unwrap();
    let rx: Vec<u16> = plugged.rx_pdos.iter().map(|p| p.index).collect();
    assert_eq!(rx, [0x1600, 0x1611], "axis B's CSV PDO at slot 1's PDO index");
    // The I/O head's slot needs a module and has a default; without it, no default set.
    let head =
        xml.replace(r#"<ModuleIdent Default="1">#x00000801</ModuleIdent>"#, "<ModuleIdent>#x00000801</ModuleIdent>");
    let f = EsiFile::parse(&head).unwrap();
    assert_eq!(f.devices[0].default_modules(), None);
}
