//! A device's or module's SoE init commands (`<Mailbox><SoE><InitCmd>`, ETG.2000): IDN writes
//! a master sends at state transitions. Their elements are an ENI's SoE init command's
//! (ETG.2100): `Transition`, `Comment`, `Timeout`, `OpCode`, `DriveNo`, `IDN`, `Elements`,
//! `Attribute`, `Data`.
use ferrocat_wire::soe::{opcode, Elements, Idn};
use roxmltree::Node;

use crate::parse::{child, child_number, child_text, children, err, hex_bytes, line_of, number, text, warn, R};
use crate::SoeInitCmd;

/// The SoE init commands of `owner` (a `<Device>` or `<Module>`), in the file's order. A
/// command the master cannot send as written (an IDN beyond 16 bits, an opcode other than a
/// write) is left out with a warning naming it.
pub(crate) fn soe_init_cmds(owner: Node<'_, '_>) -> R<Vec<SoeInitCmd>> {
    let Some(soe) = child(owner, "Mailbox").and_then(|m| child(m, "SoE")) else { return Ok(Vec::new()) };
    // An ENI wraps them in <InitCmds>; an ESI written so is read too.
    let wrapped = child(soe, "InitCmds");
    if let Some(w) = wrapped {
        warn(w, "<SoE><InitCmds> is an ENI's form (ETG.2100); an ESI has <SoE><InitCmd>: read");
    }
    let mut out = Vec::new();
    for c in children(soe, "InitCmd").chain(wrapped.into_iter().flat_map(|w| children(w, "InitCmd"))) {
        if let Some(cmd) = soe_init_cmd(c)? {
            out.push(cmd);
        }
    }
    Ok(out)
}

fn soe_init_cmd(c: Node<'_, '_>) -> R<Option<SoeInitCmd>> {
    let transitions: Vec<String> = children(c, "Transition").map(|t| text(t).to_string()).collect();
    if transitions.is_empty() {
        return Err(err(c, "SoE <InitCmd> lacks <Transition>"));
    }
    let idn_node = child(c, "IDN").ok_or_else(|| err(c, "SoE <InitCmd> lacks <IDN>"))?;
    // The schema's IDN is an xs:int: SERCOS III's extended IDNs (structure instance and element
    // above bit 15) and the -1 (#xFFFFFFFF) some files write have no place in SoE's 16 bits.
    let raw: i64 = number(idn_node, text(idn_node), "<IDN>")?;
    let Ok(idn) = u16::try_from(raw) else {
        let shown = match u32::try_from(raw).or(i32::try_from(raw).map(|v| v as u32)) {
            Ok(v) => format!("{v:#010x}"),
            Err(_) => raw.to_string(),
        };
        warn(idn_node, format!("SoE init command: IDN {shown} is not a 16-bit IDN: left out"));
        return Ok(None);
    };
    if let Some(op) = child_number::<u8>(c, "OpCode")? {
        if op != opcode::WRITE_REQUEST {
            warn(
                c,
                format!(
                    "SoE init command for {}: opcode {op} is not a write request ({}): left out",
                    Idn(idn),
                    opcode::WRITE_REQUEST
                ),
            );
            return Ok(None);
        }
    }
    let drive = child_number::<u8>(c, "DriveNo")?.unwrap_or(0);
    if drive > 7 {
        return Err(err(c, format!("SoE <InitCmd>: <DriveNo> {drive} is not a drive 0–7")));
    }
    let elements = match child_number::<u8>(c, "Elements")? {
        None => Elements::VALUE,
        Some(0) => {
            warn(c, format!("SoE init command for {}: <Elements> 0 names no element: the value written", Idn(idn)));
            Elements::VALUE
        }
        Some(e) => Elements(e),
    };
    Ok(Some(SoeInitCmd {
        line: line_of(c),
        transitions,
        drive,
        idn: Idn(idn),
        elements,
        data: match child(c, "Data") {
            Some(d) => hex_bytes(d, text(d))?,
            None => Vec::new(),
        },
        timeout_ms: child_number(c, "Timeout")?,
        comment: child_text(c, "Comment").unwrap_or_default(),
    }))
}
