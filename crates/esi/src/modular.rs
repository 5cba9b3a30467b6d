//! The Modular Device Profile in ESI (ETG.2000 §"Slots", ETG.5001): a device whose process
//! data and objects come per slot from the modules plugged into it. A module's PDO and object
//! indices marked `DependOnSlot` (or `DependOnSlotGroup`) move by the slot's (or its group's)
//! increment for each slot before it.
use crate::{Dictionary, InitCmd, Object, PdoDesc, PdoEntryDesc};

/// Whether an index moves with the slot a module sits in.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
pub enum Depend {
    /// A fixed index.
    #[default]
    None,
    /// `DependOnSlot`: plus the slot number times the slot increment.
    Slot,
    /// `DependOnSlotGroup`: plus the slot group number times the group increment.
    SlotGroup,
}

/// A device's `<Slots>`: where modules plug in, and how their indices move.
#[derive(Debug, Clone, PartialEq, Eq, Default)]
pub struct Slots {
    /// Object index increment per slot (`SlotIndexIncrement`, e.g. 0x10 or 0x800).
    pub slot_index_increment: u16,
    /// PDO index increment per slot (`SlotPdoIncrement`).
    pub slot_pdo_increment: u16,
    /// Object index increment per slot group (`SlotGroupIndexIncrement`).
    pub slot_group_index_increment: u16,
    /// PDO index increment per slot group (`SlotGroupPdoIncrement`).
    pub slot_group_pdo_increment: u16,
    /// The slots in order; a slot with `max_instances` above 1 stands for that many.
    pub slots: Vec<SlotDesc>,
}

/// One `<Slot>` of a modular device.
#[derive(Debug, Clone, PartialEq, Eq, Default)]
pub struct SlotDesc {
    /// Line of the `<Slot>` element.
    pub line: u32,
    /// Its name.
    pub name: String,
    /// How many instances of this slot the device has at least.
    pub min_instances: u16,
    /// How many at most.
    pub max_instances: u16,
    /// The slot group it belongs to (`SlotGroup` attribute), if any.
    pub slot_group: Option<u16>,
    /// The modules that fit, by ident (`<ModuleIdent>`).
    pub module_idents: Vec<u32>,
    /// The module plugged by default (`<ModuleIdent Default="1">`), if any.
    pub default_module: Option<u32>,
    /// The module classes that fit (`<ModuleClass><Class>`).
    pub module_classes: Vec<String>,
}

impl SlotDesc {
    /// Whether `module` may be plugged here: the slot names its ident or its class, or names
    /// neither (any module).
    pub fn fits(&self, module: &ModuleDesc) -> bool {
        self.module_idents.contains(&module.ident)
            || module.class.as_ref().is_some_and(|c| self.module_classes.contains(c))
            || (self.module_idents.is_empty() && self.module_classes.is_empty())
    }
}

/// One `<Module>` of a file's `<Modules>`.
#[derive(Debug, Clone, PartialEq, Eq, Default)]
pub struct ModuleDesc {
    /// Line of the `<Module>` element.
    pub line: u32,
    /// Its ident (`<Type ModuleIdent>`), what 0xF030 and 0xF050 list.
    pub ident: u32,
    /// The `<Type>` text.
    pub type_name: String,
    /// The English `<Name>`, or the first.
    pub name: String,
    /// Its class (`ModuleClass`), if given.
    pub class: Option<String>,
    /// Its PDOs, indices as written (see [`ModuleDesc::pdos_in_slot`]).
    pub rx_pdos: Vec<PdoDesc>,
    /// Its input PDOs.
    pub tx_pdos: Vec<PdoDesc>,
    /// Its objects (`<Profile><Dictionary>`), indices as written.
    pub dictionary: Option<Dictionary>,
    /// Its CoE init commands, indices as written.
    pub init_cmds: Vec<InitCmd>,
    /// Its SoE init commands (an IDN does not move with the slot).
    pub soe_init_cmds: Vec<crate::SoeInitCmd>,
}

impl ModuleDesc {
    /// The module's output and input PDOs as plugged into slot `slot` (from 0) of group
    /// `group`, their indices moved by `slots`' increments where they depend on it.
    pub fn pdos_in_slot(&self, slots: &Slots, slot: u16, group: u16) -> (Vec<PdoDesc>, Vec<PdoDesc>) {
        let moved = |pdos: &[PdoDesc]| pdos.iter().map(|p| moved_pdo(p, slots, slot, group)).collect();
        (moved(&self.rx_pdos), moved(&self.tx_pdos))
    }
}

impl ModuleDesc {
    /// The module's objects as plugged into slot `slot` of group `group` (see
    /// [`ModuleDesc::pdos_in_slot`]; objects move by the index increments).
    pub fn objects_in_slot(&self, slots: &Slots, slot: u16, group: u16) -> Vec<Object> {
        let objects = self.dictionary.as_ref().map_or(&[][..], |d| &d.objects[..]);
        objects
            .iter()
            .map(|o| Object {
                index: shift(
                    o.index,
                    o.index_depends,
                    slots.slot_index_increment,
                    slots.slot_group_index_increment,
                    slot,
                    group,
                ),
                index_depends: Depend::None,
                ..o.clone()
            })
            .collect()
    }

    /// The module's init commands as plugged into slot `slot` of group `group`.
    pub fn init_cmds_in_slot(&self, slots: &Slots, slot: u16, group: u16) -> Vec<InitCmd> {
        self.init_cmds
            .iter()
            .map(|c| InitCmd {
                index: shift(
                    c.index,
                    c.index_depends,
                    slots.slot_index_increment,
                    slots.slot_group_index_increment,
                    slot,
                    group,
                ),
                index_depends: Depend::None,
                ..c.clone()
            })
            .collect()
    }
}

fn shift(index: u16, depend: Depend, slot_step: u16, group_step: u16, slot: u16, group: u16) -> u16 {
    match depend {
        Depend::None => index,
        Depend::Slot => index.wrapping_add(slot_step.wrapping_mul(slot)),
        Depend::SlotGroup => index.wrapping_add(group_step.wrapping_mul(group)),
    }
}

fn moved_pdo(p: &PdoDesc, s: &Slots, slot: u16, group: u16) -> PdoDesc {
    PdoDesc {
        index: shift(p.index, p.index_depends, s.slot_pdo_increment, s.slot_group_pdo_increment, slot, group),
        index_depends: Depend::None,
        entries: p
            .entries
            .iter()
            .map(|e| PdoEntryDesc {
                index: shift(
                    e.index,
                    e.index_depends,
                    s.slot_index_increment,
                    s.slot_group_index_increment,
                    slot,
                    group,
                ),
                index_depends: Depend::None,
                ..e.clone()
            })
            .collect(),
        ..p.clone()
    }
}
