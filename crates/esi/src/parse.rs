//! Reading the XML: small helpers that turn a missing or malformed element into an error that
//! points at it.
use roxmltree::{Document, Node};

use crate::dictionary_xml::parse_dictionary;
use crate::*;

pub(crate) type R<T> = Result<T, EsiError>;

thread_local! {
    /// What the file under parse does that vendors' tools accept but ETG.2000 does not. The
    /// readers are free functions over nodes; the one parse running on this thread collects
    /// here and [`parse_file`] hands them to the caller.
    static WARNINGS: std::cell::RefCell<Vec<EsiError>> = const { std::cell::RefCell::new(Vec::new()) };
}

/// Notes a deviation the reader accepted, at `node`.
pub(crate) fn warn(node: Node<'_, '_>, message: impl Into<String>) {
    let w = err(node, message);
    WARNINGS.with(|ws| ws.borrow_mut().push(w));
}

pub(crate) fn err(node: Node<'_, '_>, message: impl Into<String>) -> EsiError {
    let p = node.document().text_pos_at(node.range().start);
    EsiError { line: p.row, column: p.col, message: message.into() }
}

pub(crate) fn line_of(node: Node<'_, '_>) -> u32 {
    node.document().text_pos_at(node.range().start).row
}

pub(crate) fn children<'a, 'i>(node: Node<'a, 'i>, name: &'static str) -> impl Iterator<Item = Node<'a, 'i>> {
    node.children().filter(move |c| c.is_element() && c.tag_name().name() == name)
}

pub(crate) fn child<'a, 'i>(node: Node<'a, 'i>, name: &'static str) -> Option<Node<'a, 'i>> {
    children(node, name).next()
}

pub(crate) fn text<'a>(node: Node<'a, '_>) -> &'a str {
    node.text().unwrap_or("").trim()
}

pub(crate) fn child_text(node: Node<'_, '_>, name: &'static str) -> Option<String> {
    child(node, name).map(|c| text(c).to_string())
}

/// ETG.2000's HexDecValue: `#x` and hex digits, or decimal digits (with a sign where a field
/// takes negative values).
fn canonical_number(s: &str) -> bool {
    match s.strip_prefix("#x") {
        Some(h) => !h.is_empty() && h.bytes().all(|b| b.is_ascii_hexdigit()),
        None => {
            let d = s.strip_prefix('-').unwrap_or(s);
            !d.is_empty() && d.bytes().all(|b| b.is_ascii_digit())
        }
    }
}

/// A number that must fit `T`; `what` names it in the error. `0x…`, `#X…`, a `+` sign and
/// surrounding whitespace, which vendors' tools accept, are read with a warning.
pub(crate) fn number<T: TryFrom<i64>>(node: Node<'_, '_>, s: &str, what: &str) -> R<T> {
    let v = parse_number(s).ok_or_else(|| err(node, format!("{what}: '{}' is not a number", s.trim())))?;
    if !canonical_number(s) {
        warn(node, format!("{what}: '{s}' is not ETG.2000's form (#x… or decimal): read as {v}"));
    }
    T::try_from(v).map_err(|_| err(node, format!("{what}: {v} is out of range")))
}

pub(crate) fn attr_number<T: TryFrom<i64>>(node: Node<'_, '_>, attr: &str) -> R<Option<T>> {
    node.attribute(attr)
        .map(|s| number(node, s, &format!("attribute {attr} of <{}>", node.tag_name().name())))
        .transpose()
}

pub(crate) fn child_number<T: TryFrom<i64>>(node: Node<'_, '_>, name: &'static str) -> R<Option<T>> {
    child(node, name).map(|c| number(c, c.text().unwrap_or(""), &format!("<{name}>"))).transpose()
}

pub(crate) fn req_child_number<T: TryFrom<i64>>(node: Node<'_, '_>, name: &'static str) -> R<T> {
    child_number(node, name)?.ok_or_else(|| err(node, format!("<{}> lacks <{name}>", node.tag_name().name())))
}

/// An xs:boolean attribute (absent: false). `True`, `TRUE` and the like, which vendors' tools
/// accept, are read with a warning; anything else is read as false, with a warning.
pub(crate) fn flag(node: Node<'_, '_>, attr: &str) -> bool {
    let Some(raw) = node.attribute(attr) else { return false };
    match raw.trim() {
        "1" | "true" => true,
        "0" | "false" => false,
        other => {
            let v = match other.to_ascii_lowercase().as_str() {
                "1" | "true" => Some(true),
                "0" | "false" => Some(false),
                _ => None,
            };
            let read = v.unwrap_or(false);
            let why = if v.is_some() { "xs:boolean is lower case" } else { "not a boolean" };
            warn(node, format!("attribute {attr}=\"{raw}\" of <{}>: {why}; read as {read}", node.tag_name().name()));
            read
        }
    }
}

/// An attribute that files write as a number or as a boolean (`<Sm Enable="1">` or `"true"`).
pub(crate) fn number_or_flag(node: Node<'_, '_>, attr: &str) -> R<bool> {
    match node.attribute(attr).map(str::trim) {
        Some(s) if parse_number(s).is_some() => Ok(attr_number::<i64>(node, attr)?.unwrap_or(0) != 0),
        _ => Ok(flag(node, attr)),
    }
}

/// An element's text that should be one of `known` (case and all): matched regardless of case,
/// with a warning where only the case differs; `None` (with a warning) where nothing matches.
pub(crate) fn keyword<'k>(node: Node<'_, '_>, known: &[&'k str]) -> Option<&'k str> {
    let t = text(node);
    if let Some(k) = known.iter().find(|k| **k == t) {
        return Some(k);
    }
    let what = node.tag_name().name();
    match known.iter().find(|k| k.eq_ignore_ascii_case(t)) {
        Some(k) => {
            warn(node, format!("<{what}>{t}</{what}>: read as {k} (the schema's spelling)"));
            Some(k)
        }
        None => {
            warn(node, format!("<{what}>{t}</{what}>: not one of {}", known.join(", ")));
            None
        }
    }
}

/// Hex text (e.g. `<ConfigData>05060B0E</ConfigData>`) as bytes. An odd number of digits,
/// which vendors' tools read as a value missing its leading zero (`<DefaultData>2`), is read
/// so, with a warning.
pub(crate) fn hex_bytes(node: Node<'_, '_>, s: &str) -> R<Vec<u8>> {
    match ferrocat_wire::hex::decode(s) {
        Err(ferrocat_wire::hex::HexError::OddLength(n)) => {
            warn(node, format!("hex data of odd length {n} ('{s}'): read as '0{s}'"));
            ferrocat_wire::hex::decode(&format!("0{s}")).map_err(|e| err(node, e.to_string()))
        }
        r => r.map_err(|e| err(node, e.to_string())),
    }
}

/// The English `<Name>` (LcId 1033), else the first one.
pub(crate) fn name_of(node: Node<'_, '_>) -> String {
    let first = children(node, "Name").next();
    children(node, "Name")
        .find(|n| n.attribute("LcId") == Some("1033"))
        .or(first)
        .map(|n| text(n).to_string())
        .unwrap_or_default()
}

pub(crate) fn parse_file(xml: &str) -> R<EsiFile> {
    WARNINGS.with(|ws| ws.borrow_mut().clear());
    let mut file = parse_document(xml)?;
    file.warnings = WARNINGS.with(|ws| std::mem::take(&mut *ws.borrow_mut()));
    // In file order, whatever order the readers met them in.
    file.warnings.sort_by_key(|w| (w.line, w.column));
    Ok(file)
}

/// Where an XML reader's error lies in `text` (line, column, from 1), and what it says. A
/// document that ends too soon (a truncated file) is placed at its end.
fn xml_error(text: &str, e: &roxmltree::Error) -> (u32, u32, String) {
    use roxmltree::Error as E;
    match e {
        E::UnexpectedEndOfStream | E::UnclosedRootNode | E::NoRootNode => {
            let (line, column) = crate::end_of_text(text);
            (line, column, format!("malformed XML: {e} (the text ends here: a truncated file?)"))
        }
        _ => (e.pos().row, e.pos().col, format!("malformed XML: {e}")),
    }
}

fn parse_document(xml: &str) -> R<EsiFile> {
    let opts = roxmltree::ParsingOptions { allow_dtd: true, ..Default::default() };
    let doc = Document::parse_with_options(xml, opts).map_err(|e| {
        let (line, column, message) = xml_error(xml, &e);
        EsiError { line, column, message }
    })?;
    let root = doc.root_element();
    match root.tag_name().name() {
        "EtherCATInfo" => parse_info(root),
        // IgH's `ethercat xml`: an <EtherCATInfo> a slave, in one list.
        "EtherCATInfoList" => parse_list(root),
        // A module file (ETG.2000's EtherCATModule schema): modules of modular devices whose
        // own files name them in their slots, kept apart by some vendors.
        "EtherCATModule" => parse_module_file(root),
        other => Err(err(
            root,
            format!("root element is <{other}>, expected <EtherCATInfo>, <EtherCATInfoList> or <EtherCATModule>"),
        )),
    }
}

/// An `<EtherCATInfoList>` as one file: its infos' devices and modules in order, all of one
/// vendor (a description of several vendors' devices is refused: each device here has its
/// file's vendor).
fn parse_list(root: Node<'_, '_>) -> R<EsiFile> {
    let mut infos = children(root, "EtherCATInfo");
    let first = infos.next().ok_or_else(|| err(root, "an <EtherCATInfoList> without an <EtherCATInfo>"))?;
    let mut file = parse_info(first)?;
    for info in infos {
        let more = parse_info(info)?;
        if more.vendor_id != file.vendor_id {
            return Err(err(
                info,
                format!(
                    "vendor {:#x} here, {:#x} in the list's first <EtherCATInfo>: give each vendor's devices a file of their own",
                    more.vendor_id, file.vendor_id
                ),
            ));
        }
        for dev in more.devices {
            if let Some(o) =
                file.devices.iter().find(|o| (o.product_code, o.revision) == (dev.product_code, dev.revision))
            {
                // The same device once a slave: the first kept, as for a file that repeats one.
                if *o == (Device { line: o.line, ..dev.clone() }) {
                    continue;
                }
            }
            file.devices.push(dev);
        }
        file.modules.extend(more.modules);
        file.passive.extend(more.passive);
    }
    Ok(file)
}

fn parse_info(root: Node<'_, '_>) -> R<EsiFile> {
    let vendor = child(root, "Vendor").ok_or_else(|| err(root, "no <Vendor>"))?;
    let vendor_id = req_child_number::<i64>(vendor, "Id")?;
    // Vendor IDs are 32-bit; some files write them as negative decimals.
    let vendor_id = if vendor_id < 0 {
        vendor_id as i32 as u32
    } else {
        u32::try_from(vendor_id).map_err(|_| err(vendor, "vendor Id out of range"))?
    };
    let descriptions = child(root, "Descriptions");
    let devices_node =
        descriptions.and_then(|d| child(d, "Devices")).ok_or_else(|| err(root, "no <Descriptions><Devices>"))?;
    let mut devices: Vec<Device> = Vec::new();
    let mut passive = Vec::new();
    for d in children(devices_node, "Device") {
        // Neither product code nor revision: a passive device (no ESC), as Beckhoff's end
        // terminals are written; one with a revision and no product code is an error below.
        if let Some(ty) =
            child(d, "Type").filter(|t| t.attribute("ProductCode").is_none() && t.attribute("RevisionNo").is_none())
        {
            passive.push(PassiveDevice { line: line_of(d), type_name: text(ty).to_string(), name: name_of(d) });
            continue;
        }
        let dev = parse_device(d)?;
        if let Some(first) = devices.iter().find(|o| (o.product_code, o.revision) == (dev.product_code, dev.revision)) {
            warn(
                d,
                format!(
                    "device {} repeats product code {:#x} revision {:#x} of {} (line {}): both kept, the first is the one FILE:PRODUCT picks",
                    dev.type_name, dev.product_code, dev.revision, first.type_name, first.line
                ),
            );
        }
        devices.push(dev);
    }
    let modules = parse_modules(descriptions.and_then(|d| child(d, "Modules")))?;
    Ok(EsiFile { vendor_id, vendor_name: name_of(vendor), devices, modules, warnings: Vec::new(), passive })
}

/// An `<EtherCATModule>` file: its vendor (where it names one; 0 where not) and modules, no
/// devices.
fn parse_module_file(root: Node<'_, '_>) -> R<EsiFile> {
    let vendor = child(root, "Vendor");
    let vendor_id = match vendor {
        Some(v) => {
            let id = req_child_number::<i64>(v, "Id")?;
            if id < 0 {
                id as i32 as u32
            } else {
                u32::try_from(id).map_err(|_| err(v, "vendor Id out of range"))?
            }
        }
        None => 0,
    };
    let modules = parse_modules(child(root, "Modules"))?;
    if modules.is_empty() {
        warn(root, "an <EtherCATModule> file without a <Modules><Module>".to_string());
    }
    Ok(EsiFile {
        vendor_id,
        vendor_name: vendor.map(name_of).unwrap_or_default(),
        devices: Vec::new(),
        modules,
        warnings: Vec::new(),
        passive: Vec::new(),
    })
}

/// The `<Module>`s of a `<Modules>`, the first of an ident kept (a repeat is a warning).
fn parse_modules(list: Option<Node<'_, '_>>) -> R<Vec<ModuleDesc>> {
    let mut modules: Vec<ModuleDesc> = Vec::new();
    for m in list.into_iter().flat_map(|m| children(m, "Module")) {
        let module = parse_module(m)?;
        if let Some(first) = modules.iter().find(|o| o.ident == module.ident) {
            warn(
                m,
                format!(
                    "module {} repeats ident {:#010x} of {} (line {}): the first is the one plugged",
                    module.type_name, module.ident, first.type_name, first.line
                ),
            );
        }
        modules.push(module);
    }
    Ok(modules)
}

fn parse_device(d: Node<'_, '_>) -> R<Device> {
    let ty = child(d, "Type").ok_or_else(|| err(d, "<Device> lacks <Type>"))?;
    let product_code = attr_number::<i64>(ty, "ProductCode")?.ok_or_else(|| err(ty, "<Type> lacks ProductCode"))?;
    let revision = attr_number::<i64>(ty, "RevisionNo")?.unwrap_or(0);
    let as_u32 = |v: i64, what: &str| -> R<u32> {
        if v < 0 {
            Ok(v as i32 as u32)
        } else {
            u32::try_from(v).map_err(|_| err(ty, format!("{what} {v} out of range")))
        }
    };
    if child(d, "Name").is_none() {
        warn(d, format!("device {} has no <Name>: named by its type", text(ty)));
    }
    let mut dev = Device {
        line: line_of(d),
        type_name: text(ty).to_string(),
        name: name_of(d),
        product_code: as_u32(product_code, "ProductCode")?,
        revision: as_u32(revision, "RevisionNo")?,
        physics: d.attribute("Physics").unwrap_or("").to_string(),
        group_type: child_text(d, "GroupType").unwrap_or_default(),
        ..Default::default()
    };
    if let Some(profile) = child(d, "Profile") {
        dev.profile_no = child_number(profile, "ProfileNo")?;
        if let Some(dict) = child(profile, "Dictionary") {
            dev.dictionary = Some(parse_dictionary(dict)?);
        }
    }
    for f in children(d, "Fmmu") {
        dev.fmmus.push(match keyword(f, &["Outputs", "Inputs", "MBoxState"]) {
            Some("Outputs") => FmmuKind::Outputs,
            Some("Inputs") => FmmuKind::Inputs,
            Some(_) => FmmuKind::MailboxState,
            None => FmmuKind::Other(text(f).to_string()),
        });
    }
    for (n, sm) in children(d, "Sm").enumerate() {
        let control: u8 = attr_number(sm, "ControlByte")?.unwrap_or(0);
        let enabled = number_or_flag(sm, "Enable")?;
        dev.sync_managers.push(SmDesc {
            kind: match text(sm) {
                // An unnamed SyncManager that is enabled takes its kind from its control byte
                // (bits 0–1 the mode, 2–3 the direction: ESC datasheet section II, 0x0804):
                // IgH's `ethercat xml` writes its slaves' SyncManagers without their kind. One
                // not enabled is one the device does not use.
                "" if enabled && control != 0 => {
                    let writes = (control >> 2) & 3 == 1;
                    let mailbox = control & 3 == 2 && n < 2;
                    let kind = match (mailbox, writes) {
                        (true, true) => SmKind::MailboxOut,
                        (true, false) => SmKind::MailboxIn,
                        (false, true) => SmKind::Outputs,
                        (false, false) => SmKind::Inputs,
                    };
                    warn(sm, format!("<Sm> {n} names no kind: taken as {kind:?} from its control byte {control:#04x}"));
                    kind
                }
                "" => SmKind::Unused,
                _ => match keyword(sm, &["MBoxOut", "MBoxIn", "Outputs", "Inputs"]) {
                    Some("MBoxOut") => SmKind::MailboxOut,
                    Some("MBoxIn") => SmKind::MailboxIn,
                    Some("Outputs") => SmKind::Outputs,
                    Some("Inputs") => SmKind::Inputs,
                    _ => SmKind::Unused,
                },
            },
            start: attr_number(sm, "StartAddress")?.ok_or_else(|| err(sm, "<Sm> lacks StartAddress"))?,
            default_size: attr_number(sm, "DefaultSize")?,
            control,
            enable: enabled,
        });
    }
    for p in children(d, "RxPdo") {
        push_pdo(&mut dev.rx_pdos, p)?;
    }
    for p in children(d, "TxPdo") {
        push_pdo(&mut dev.tx_pdos, p)?;
    }
    if let Some(m) = child(d, "Mailbox") {
        dev.mailbox = Some(MailboxDesc {
            coe: child(m, "CoE").map(|c| CoeDesc {
                sdo_info: flag(c, "SdoInfo"),
                pdo_assign: flag(c, "PdoAssign"),
                pdo_config: flag(c, "PdoConfig"),
                pdo_upload: flag(c, "PdoUpload"),
                complete_access: flag(c, "CompleteAccess"),
            }),
            foe: child(m, "FoE").is_some(),
            eoe: child(m, "EoE").is_some(),
            soe: child(m, "SoE").is_some(),
            aoe: child(m, "AoE").is_some(),
            voe: child(m, "VoE").is_some(),
        });
    }
    dev.init_cmds = init_cmds(d)?;
    dev.soe_init_cmds = crate::soe_init::soe_init_cmds(d)?;
    if let Some(dc) = child(d, "Dc") {
        for m in children(dc, "OpMode") {
            let cyc = |name| -> R<(u32, Option<i16>)> {
                match child(m, name) {
                    Some(c) => Ok((number(c, text(c), name)?, attr_number(c, "Factor")?)),
                    None => Ok((0, None)),
                }
            };
            let (cycle_time_sync0_ns, cycle_time_sync0_factor) = cyc("CycleTimeSync0")?;
            let (cycle_time_sync1_ns, cycle_time_sync1_factor) = cyc("CycleTimeSync1")?;
            dev.dc_op_modes.push(DcOpModeDesc {
                name: child_text(m, "Name").unwrap_or_default(),
                description: child_text(m, "Desc").unwrap_or_default(),
                assign_activate: child_number(m, "AssignActivate")?.unwrap_or(0),
                cycle_time_sync0_ns,
                cycle_time_sync0_factor,
                shift_time_sync0_ns: child_number(m, "ShiftTimeSync0")?.unwrap_or(0),
                cycle_time_sync1_ns,
                cycle_time_sync1_factor,
                shift_time_sync1_ns: child_number(m, "ShiftTimeSync1")?.unwrap_or(0),
            });
        }
    }
    if let Some(e) = child(d, "Eeprom") {
        let hex = |name| -> R<Vec<u8>> {
            match child(e, name) {
                Some(c) => hex_bytes(c, text(c)),
                None => Ok(Vec::new()),
            }
        };
        dev.eeprom = Some(EepromDesc {
            byte_size: child_number(e, "ByteSize")?,
            config_data: hex("ConfigData")?,
            bootstrap: hex("BootStrap")?,
        });
    }
    if let Some(slots) = child(d, "Slots") {
        dev.slots = Some(parse_slots(slots)?);
    }
    if let Some(el) = child(d, "Info").and_then(|i| child(i, "Electrical")) {
        dev.ebus_current_ma = child_number(el, "EBusCurrent")?.unwrap_or(0);
    }
    Ok(dev)
}

/// Whether an `<Index>` moves with the slot (`DependOnSlot`, `DependOnSlotGroup`).
pub(crate) fn depends(parent: Node<'_, '_>) -> Depend {
    match child(parent, "Index") {
        Some(i) if flag(i, "DependOnSlot") => Depend::Slot,
        Some(i) if flag(i, "DependOnSlotGroup") => Depend::SlotGroup,
        _ => Depend::None,
    }
}

fn parse_slots(s: Node<'_, '_>) -> R<Slots> {
    let mut out = Slots {
        slot_index_increment: attr_number(s, "SlotIndexIncrement")?.unwrap_or(0),
        slot_pdo_increment: attr_number(s, "SlotPdoIncrement")?.unwrap_or(0),
        slot_group_index_increment: attr_number(s, "SlotGroupIndexIncrement")?.unwrap_or(0),
        slot_group_pdo_increment: attr_number(s, "SlotGroupPdoIncrement")?.unwrap_or(0),
        slots: Vec::new(),
    };
    for slot in children(s, "Slot") {
        let mut d = SlotDesc {
            line: line_of(slot),
            name: name_of(slot),
            min_instances: attr_number(slot, "MinInstances")?.unwrap_or(1),
            max_instances: attr_number(slot, "MaxInstances")?.unwrap_or(1),
            slot_group: attr_number(slot, "SlotGroup")?,
            ..Default::default()
        };
        for m in children(slot, "ModuleIdent") {
            let ident = number::<i64>(m, text(m), "<ModuleIdent>")? as u32;
            if flag(m, "Default") {
                d.default_module = Some(ident);
            }
            d.module_idents.push(ident);
        }
        for c in children(slot, "ModuleClass") {
            if let Some(class) = child_text(c, "Class") {
                d.module_classes.push(class);
            }
        }
        if d.max_instances < d.min_instances {
            return Err(err(slot, format!("MaxInstances {} below MinInstances {}", d.max_instances, d.min_instances)));
        }
        out.slots.push(d);
    }
    Ok(out)
}

fn parse_module(m: Node<'_, '_>) -> R<ModuleDesc> {
    let ty = child(m, "Type").ok_or_else(|| err(m, "<Module> lacks <Type>"))?;
    let ident = attr_number::<i64>(ty, "ModuleIdent")?.ok_or_else(|| err(ty, "<Type> lacks ModuleIdent"))?;
    let mut module = ModuleDesc {
        line: line_of(m),
        ident: ident as u32,
        type_name: text(ty).to_string(),
        name: name_of(m),
        class: ty.attribute("ModuleClass").map(str::to_string),
        ..Default::default()
    };
    for p in children(m, "RxPdo") {
        push_pdo(&mut module.rx_pdos, p)?;
    }
    for p in children(m, "TxPdo") {
        push_pdo(&mut module.tx_pdos, p)?;
    }
    module.init_cmds = init_cmds(m)?;
    module.soe_init_cmds = crate::soe_init::soe_init_cmds(m)?;
    if let Some(dict) = child(m, "Profile").and_then(|p| child(p, "Dictionary")) {
        module.dictionary = Some(parse_dictionary(dict)?);
    }
    Ok(module)
}

/// The `<Mailbox><CoE><InitCmd>`s of a device or module.
fn init_cmds(owner: Node<'_, '_>) -> R<Vec<InitCmd>> {
    let Some(coe) = child(owner, "Mailbox").and_then(|m| child(m, "CoE")) else { return Ok(Vec::new()) };
    children(coe, "InitCmd")
        .map(|c| {
            let index = child(c, "Index").ok_or_else(|| err(c, "<InitCmd> lacks <Index>"))?;
            let transitions: Vec<String> = children(c, "Transition").map(|t| text(t).to_string()).collect();
            if transitions.is_empty() {
                return Err(err(c, "<InitCmd> lacks <Transition>"));
            }
            Ok(InitCmd {
                line: line_of(c),
                transitions,
                index: number(index, index.text().unwrap_or(""), "<InitCmd><Index>")?,
                index_depends: depends(c),
                subindex: child_number(c, "SubIndex")?.unwrap_or(0),
                data: match child(c, "Data") {
                    Some(d) => hex_bytes(d, text(d))?,
                    None => Vec::new(),
                },
                complete_access: flag(c, "CompleteAccess"),
                comment: child_text(c, "Comment").unwrap_or_default(),
            })
        })
        .collect()
}

/// Adds the PDO at `p`, unless one with its index is there already (a warning; the first kept).
fn push_pdo(pdos: &mut Vec<PdoDesc>, p: Node<'_, '_>) -> R<()> {
    let pdo = parse_pdo(p)?;
    if pdos.iter().any(|o| o.index == pdo.index) {
        warn(p, format!("PDO {:#06x} ({}) is there already: the first kept", pdo.index, pdo.name));
    } else {
        pdos.push(pdo);
    }
    Ok(())
}

fn parse_pdo(p: Node<'_, '_>) -> R<PdoDesc> {
    if child(p, "Name").is_none() {
        warn(p, format!("<{}> has no <Name>", p.tag_name().name()));
    }
    let mut pdo = PdoDesc {
        index: req_child_number(p, "Index")?,
        index_depends: depends(p),
        name: name_of(p),
        sm: attr_number(p, "Sm")?,
        fixed: flag(p, "Fixed"),
        mandatory: flag(p, "Mandatory"),
        entries: Vec::new(),
    };
    for e in children(p, "Entry") {
        let index: u16 = req_child_number(e, "Index")?;
        if index != 0 && child(e, "DataType").is_none() {
            warn(e, format!("entry {index:#06x} has no <DataType>: read by its <BitLen>"));
        }
        pdo.entries.push(PdoEntryDesc {
            index,
            index_depends: depends(e),
            // Padding entries (index 0) usually omit the subindex.
            subindex: child_number(e, "SubIndex")?.unwrap_or(0),
            bit_len: req_child_number(e, "BitLen")?,
            name: name_of(e),
            data_type: child_text(e, "DataType").unwrap_or_default(),
        });
    }
    Ok(pdo)
}
