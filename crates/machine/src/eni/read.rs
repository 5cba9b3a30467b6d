//! Reading an ENI document into an [`Eni`]: one function an element, each error and warning
//! pointing at the element it is about.
use roxmltree::{Document, Node};

use ferrocat_wire::register::AlState;
use ferrocat_wire::Command;

use super::*;
use crate::compare::Identity;

type R<T> = Result<T, EniError>;

/// The most data a datagram can carry in one frame: 1 500 bytes of payload less the EtherCAT
/// header (2), the datagram header (10) and the working counter (2).
const MAX_DATAGRAM_DATA: usize = 1486;

/// Reads the document, collecting warnings.
pub(super) fn read(text: &str) -> R<Eni> {
    let opts = roxmltree::ParsingOptions { allow_dtd: true, ..Default::default() };
    let doc = Document::parse_with_options(text, opts).map_err(|e| {
        use roxmltree::Error as E;
        // A document that ends too soon (a truncated file) at its end, not at line 1, column 1.
        let (line, column, why) = match e {
            E::UnexpectedEndOfStream | E::UnclosedRootNode | E::NoRootNode => {
                let (line, column) = ferrocat_esi::end_of_text(text);
                (line, column, " (the text ends here: a truncated file?)")
            }
            _ => (e.pos().row, e.pos().col, ""),
        };
        EniError { place: Place { line, column }, message: format!("malformed XML: {e}{why}") }
    })?;
    let root = doc.root_element();
    if root.tag_name().name() != "EtherCATConfig" {
        return Err(err(root, format!("root element is <{}>, expected <EtherCATConfig>", root.tag_name().name())));
    }
    let config = child(root, "Config").ok_or_else(|| err(root, "no <Config>"))?;
    let mut r = Reader { warnings: Vec::new() };
    let master = match child(config, "Master") {
        Some(m) => r.master(m)?,
        None => MasterConfig::default(),
    };
    let mut slaves = Vec::new();
    for s in children(config, "Slave") {
        if slaves.len() == u16::MAX as usize {
            return Err(err(s, "more than 65 535 slaves"));
        }
        slaves.push(r.slave(s)?);
    }
    let process_image = match child(config, "ProcessImage") {
        Some(p) => ProcessImage { inputs: r.area(p, "Inputs")?, outputs: r.area(p, "Outputs")? },
        None => ProcessImage::default(),
    };
    let mut cyclic = Vec::new();
    for c in children(config, "Cyclic") {
        cyclic.push(r.cyclic(c, &process_image)?);
    }
    r.warnings.sort_by_key(|w| w.place);
    Ok(Eni { master, slaves, cyclic, process_image, warnings: r.warnings })
}

fn place(node: Node<'_, '_>) -> Place {
    let p = node.document().text_pos_at(node.range().start);
    Place { line: p.row, column: p.col }
}

fn err(node: Node<'_, '_>, message: impl Into<String>) -> EniError {
    EniError { place: place(node), message: message.into() }
}

fn children<'a, 'i>(node: Node<'a, 'i>, name: &'static str) -> impl Iterator<Item = Node<'a, 'i>> {
    node.children().filter(move |c| c.is_element() && c.tag_name().name() == name)
}

fn child<'a, 'i>(node: Node<'a, 'i>, name: &'static str) -> Option<Node<'a, 'i>> {
    children(node, name).next()
}

/// The element's text as written (CDATA included).
fn raw_text<'a>(node: Node<'a, '_>) -> &'a str {
    node.text().unwrap_or("")
}

struct Reader {
    warnings: Vec<Warning>,
}

impl Reader {
    fn warn(&mut self, node: Node<'_, '_>, message: impl Into<String>) {
        self.warnings.push(Warning { place: place(node), message: message.into() });
    }

    /// Text with white space around it removed (names and comments, CDATA included).
    fn text(&mut self, node: Node<'_, '_>) -> String {
        raw_text(node).trim().to_string()
    }

    /// A number: decimal, or hex as `#x…` (the schema's HexDecValue); `0x…`, `#X…`, a `+` and
    /// white space around it are read with a warning. Negative values of unsigned fields wrap
    /// (`-1` as 0xFFFF), with a warning.
    fn number<T: TryFrom<i64>>(&mut self, node: Node<'_, '_>, what: &str) -> R<T> {
        let raw = raw_text(node);
        let s = raw.trim();
        let v = ferrocat_esi::parse_number(s.strip_prefix('+').unwrap_or(s))
            .ok_or_else(|| err(node, format!("{what}: '{s}' is not a number")))?;
        let canonical = s == raw
            && match s.strip_prefix("#x") {
                Some(h) => !h.is_empty() && h.bytes().all(|b| b.is_ascii_hexdigit()),
                None => {
                    let d = s.strip_prefix('-').unwrap_or(s);
                    !d.is_empty() && d.bytes().all(|b| b.is_ascii_digit())
                }
            };
        if !canonical {
            self.warn(node, format!("{what}: '{}' read as {v}", raw.escape_debug()));
        }
        if let Ok(t) = T::try_from(v) {
            return Ok(t);
        }
        // A negative number for an unsigned field of 16 or 32 bits: its two's complement.
        for bits in [16u32, 32] {
            let wrapped = v + (1i64 << bits);
            if v < 0 && wrapped >= 0 {
                if let Ok(t) = T::try_from(wrapped) {
                    if T::try_from((1i64 << bits) - 1).is_ok() && T::try_from(1i64 << bits).is_err() {
                        self.warn(node, format!("{what}: {v} read as {wrapped:#x}"));
                        return Ok(t);
                    }
                }
            }
        }
        Err(err(node, format!("{what}: {v} is out of range")))
    }

    fn child_number<T: TryFrom<i64>>(&mut self, node: Node<'_, '_>, name: &'static str) -> R<Option<T>> {
        match child(node, name) {
            Some(c) => self.number(c, name).map(Some),
            None => Ok(None),
        }
    }

    fn req_number<T: TryFrom<i64>>(&mut self, node: Node<'_, '_>, name: &'static str) -> R<T> {
        let c = child(node, name).ok_or_else(|| err(node, format!("<{}> has no <{name}>", node.tag_name().name())))?;
        self.number(c, name)
    }

    fn child_text(&mut self, node: Node<'_, '_>, name: &'static str) -> Option<String> {
        child(node, name).map(|c| self.text(c))
    }

    /// `true`/`false`/`1`/`0`; another case is read with a warning, anything else is an error.
    fn boolean(&mut self, node: Node<'_, '_>, s: &str, what: &str) -> R<bool> {
        match s.trim() {
            "true" | "1" => Ok(true),
            "false" | "0" => Ok(false),
            t if t.eq_ignore_ascii_case("true") || t.eq_ignore_ascii_case("false") => {
                self.warn(node, format!("{what}: '{t}' read as {}", t.to_ascii_lowercase()));
                Ok(t.eq_ignore_ascii_case("true"))
            }
            t => Err(err(node, format!("{what}: '{t}' is not a boolean"))),
        }
    }

    fn child_bool(&mut self, node: Node<'_, '_>, name: &'static str) -> R<Option<bool>> {
        match child(node, name) {
            Some(c) => {
                let t = raw_text(c).to_string();
                self.boolean(c, &t, name).map(Some)
            }
            None => Ok(None),
        }
    }

    fn attr_bool(&mut self, node: Node<'_, '_>, name: &str) -> R<bool> {
        match node.attribute(name) {
            Some(v) => self.boolean(node, v, name),
            None => Ok(false),
        }
    }

    /// Hex bytes (`0400`); odd length is read with a leading zero and a warning.
    fn hex(&mut self, node: Node<'_, '_>, what: &str) -> R<Vec<u8>> {
        let s: String = raw_text(node).split_whitespace().collect();
        // Digits are ASCII: anything else is no hex data, and byte pairs below need ASCII.
        if !s.bytes().all(|b| b.is_ascii_hexdigit()) {
            return Err(err(node, format!("{what}: '{s}' is not hex data")));
        }
        let s = if s.len() % 2 == 1 {
            self.warn(node, format!("{what}: odd number of hex digits, read with a leading 0"));
            format!("0{s}")
        } else {
            s
        };
        let bytes = (0..s.len())
            .step_by(2)
            .map(|i| u8::from_str_radix(&s[i..i + 2], 16))
            .collect::<Result<Vec<u8>, _>>()
            .map_err(|_| err(node, format!("{what}: '{s}' is not hex data")))?;
        if bytes.len() > MAX_DATAGRAM_DATA {
            return Err(err(
                node,
                format!("{what}: {} bytes, more than a datagram carries ({MAX_DATAGRAM_DATA})", bytes.len()),
            ));
        }
        Ok(bytes)
    }

    fn mac(&mut self, node: Node<'_, '_>) -> R<[u8; 6]> {
        let b = self.hex(node, node.tag_name().name())?;
        b.try_into().map_err(|b: Vec<u8>| err(node, format!("a MAC address has 6 bytes, not {}", b.len())))
    }

    fn master(&mut self, m: Node<'_, '_>) -> R<MasterConfig> {
        let mut out = MasterConfig::default();
        if let Some(info) = child(m, "Info") {
            out.name = self.child_text(info, "Name").unwrap_or_default();
            out.destination = child(info, "Destination").map(|d| self.mac(d)).transpose()?;
            out.source = child(info, "Source").map(|d| self.mac(d)).transpose()?;
        }
        if let Some(ms) = child(m, "MailboxStates") {
            out.mailbox_states = Some((self.req_number(ms, "StartAddr")?, self.req_number(ms, "Count")?));
        }
        out.init_cmds = self.init_cmds(m)?;
        Ok(out)
    }

    fn slave(&mut self, s: Node<'_, '_>) -> R<Slave> {
        let info = child(s, "Info").ok_or_else(|| err(s, "<Slave> has no <Info>"))?;
        let identity = Identity {
            vendor_id: self.req_u32(info, "VendorId")?,
            product_code: self.req_u32(info, "ProductCode")?,
            revision: self.child_u32(info, "RevisionNo")?.unwrap_or(0),
            serial: self.child_u32(info, "SerialNo")?.unwrap_or(0),
        };
        let process_data = match child(s, "ProcessData") {
            Some(p) => self.process_data(p)?,
            None => ProcessData::default(),
        };
        let mailbox = child(s, "Mailbox").map(|m| self.mailbox(m)).transpose()?;
        let previous_port = match children(s, "PreviousPort").find(|p| p.attribute("Selected") == Some("true")) {
            Some(p) => {
                let port = self.child_text(p, "Port").and_then(|t| t.chars().next()).unwrap_or('?');
                Some((port, self.req_number(p, "PhysAddr")?))
            }
            None => None,
        };
        let dc = match child(s, "DC") {
            Some(d) => Some(Dc {
                reference_clock: self.child_bool(d, "ReferenceClock")?.unwrap_or(false),
                cycle_time0_ns: self.child_number(d, "CycleTime0")?.unwrap_or(0),
                cycle_time1_ns: self.child_number(d, "CycleTime1")?.unwrap_or(0),
                shift_time_ns: self.child_number(d, "ShiftTime")?.unwrap_or(0),
            }),
            None => None,
        };
        Ok(Slave {
            place: place(s),
            name: self.child_text(info, "Name").unwrap_or_default(),
            identity,
            station: self.child_number(info, "PhysAddr")?,
            auto_inc: self.child_number(info, "AutoIncAddr")?,
            physics: self.child_text(info, "Physics"),
            product_revision: self.child_text(info, "ProductRevision"),
            process_data,
            mailbox,
            init_cmds: self.init_cmds(s)?,
            previous_port,
            dc,
        })
    }

    /// A 32-bit identity field: some tools write vendor IDs above 2³¹ as negative decimals.
    fn child_u32(&mut self, node: Node<'_, '_>, name: &'static str) -> R<Option<u32>> {
        self.child_number::<u32>(node, name)
    }

    fn req_u32(&mut self, node: Node<'_, '_>, name: &'static str) -> R<u32> {
        self.req_number::<u32>(node, name)
    }

    fn process_data(&mut self, p: Node<'_, '_>) -> R<ProcessData> {
        let mut out = ProcessData::default();
        let range = |r: &mut Self, n: Option<Node<'_, '_>>| -> R<Option<BitRange>> {
            match n {
                Some(n) => {
                    Ok(Some(BitRange { start: r.req_number(n, "BitStart")?, length: r.req_number(n, "BitLength")? }))
                }
                None => Ok(None),
            }
        };
        out.send = range(self, child(p, "Send"))?;
        out.recv = range(self, child(p, "Recv"))?;
        for c in p.children().filter(|c| c.is_element()) {
            let tag = c.tag_name().name();
            let Some(number) = tag.strip_prefix("Sm").and_then(|n| n.parse::<u8>().ok()) else { continue };
            if number > 15 {
                return Err(err(c, format!("<{tag}>: an ESC has SyncManagers 0 to 15")));
            }
            let mut pdos = Vec::new();
            for pd in children(c, "Pdo") {
                pdos.push(self.number(pd, "Pdo")?);
            }
            out.sms.push(ProcessSm {
                number,
                kind: self.child_text(c, "Type").unwrap_or_default(),
                start: self.req_number(c, "StartAddress")?,
                control: self.child_number(c, "ControlByte")?.unwrap_or(0),
                enable: self.child_number::<u8>(c, "Enable")?.unwrap_or(0) != 0,
                default_size: self.child_number(c, "DefaultSize")?,
                pdos,
            });
        }
        for (tag, list) in [("RxPdo", &mut out.rx_pdos), ("TxPdo", &mut out.tx_pdos)] {
            for pd in children(p, tag) {
                list.push(self.pdo(pd)?);
            }
        }
        Ok(out)
    }

    fn pdo(&mut self, p: Node<'_, '_>) -> R<Pdo> {
        let sm = match p.attribute("Sm") {
            Some(v) => Some(
                ferrocat_esi::parse_number(v)
                    .and_then(|n| u8::try_from(n).ok())
                    .ok_or_else(|| err(p, format!("Sm=\"{v}\" is no SyncManager number")))?,
            ),
            None => None,
        };
        let mut entries = Vec::new();
        for e in children(p, "Entry") {
            entries.push(PdoEntry {
                index: self.req_number(e, "Index")?,
                subindex: self.child_number(e, "SubIndex")?.unwrap_or(0),
                bits: self.req_number(e, "BitLen")?,
                name: self.child_text(e, "Name").unwrap_or_default(),
                data_type: self.child_text(e, "DataType"),
            });
        }
        Ok(Pdo {
            index: self.req_number(p, "Index")?,
            name: self.child_text(p, "Name").unwrap_or_default(),
            sm,
            fixed: self.attr_bool(p, "Fixed")?,
            entries,
        })
    }

    fn mailbox(&mut self, m: Node<'_, '_>) -> R<Mailbox> {
        let area = |r: &mut Self, n: Node<'_, '_>, name: &'static str| -> R<(u16, u16)> {
            let a = child(n, name).ok_or_else(|| err(n, format!("<{}> has no <{name}>", n.tag_name().name())))?;
            Ok((r.req_number(a, "Start")?, r.req_number(a, "Length")?))
        };
        let bootstrap = match child(m, "BootStrap").or_else(|| child(m, "Bootstrap")) {
            Some(b) => Some((area(self, b, "Send")?, area(self, b, "Recv")?)),
            None => None,
        };
        let protocols = children(m, "Protocol").map(|p| raw_text(p).trim().to_string()).collect();
        let mut coe_init_cmds = Vec::new();
        if let Some(cmds) = child(m, "CoE").and_then(|c| child(c, "InitCmds")) {
            for c in children(cmds, "InitCmd") {
                coe_init_cmds.push(self.coe_init_cmd(c)?);
            }
        }
        let mut soe_init_cmds = Vec::new();
        if let Some(cmds) = child(m, "SoE").and_then(|c| child(c, "InitCmds")) {
            for c in children(cmds, "InitCmd") {
                soe_init_cmds.extend(self.soe_init_cmd(c)?);
            }
        }
        let profile_no = match child(m, "CoE").and_then(|c| child(c, "Profile")).and_then(|p| child(p, "ChannelInfo")) {
            Some(ci) => self.child_number(ci, "ProfileNo")?,
            None => None,
        };
        Ok(Mailbox {
            send: area(self, m, "Send")?,
            recv: area(self, m, "Recv")?,
            poll_time_ms: match child(m, "Recv") {
                Some(r) => self.child_number(r, "PollTime")?,
                None => None,
            },
            bootstrap,
            protocols,
            coe_init_cmds,
            soe_init_cmds,
            profile_no,
        })
    }

    fn transitions(&mut self, c: Node<'_, '_>) -> Vec<Transition> {
        let mut out = Vec::new();
        for t in children(c, "Transition") {
            let s = raw_text(t).trim().to_string();
            match Transition::parse(&s) {
                Some(tr) => out.push(tr),
                None => self.warn(t, format!("transition '{s}' is none of IP, PS, SO, …: left out")),
            }
        }
        out
    }

    fn coe_init_cmd(&mut self, c: Node<'_, '_>) -> R<CoeInitCmd> {
        let data = match child(c, "Data") {
            Some(d) => self.hex(d, "Data")?,
            None => Vec::new(),
        };
        Ok(CoeInitCmd {
            place: place(c),
            transitions: self.transitions(c),
            comment: self.child_text(c, "Comment").unwrap_or_default(),
            ccs: self.child_number(c, "Ccs")?.unwrap_or(1),
            index: self.req_number(c, "Index")?,
            subindex: self.child_number(c, "SubIndex")?.unwrap_or(0),
            complete_access: match c.attribute("CompleteAccess") {
                Some(v) => self.boolean(c, v, "CompleteAccess")?,
                None => false,
            },
            data,
            fixed: self.attr_bool(c, "Fixed")?,
            timeout_ms: self.child_number(c, "Timeout")?,
        })
    }

    /// One SoE init command; one the master cannot send as written (an IDN beyond SoE's 16 bits,
    /// which the schema's `xs:int` allows and files fill with -1; an opcode other than a write
    /// request, 3) is left out with a warning.
    fn soe_init_cmd(&mut self, c: Node<'_, '_>) -> R<Option<SoeInitCmd>> {
        let idn_node = child(c, "IDN").ok_or_else(|| err(c, "SoE <InitCmd> has no <IDN>"))?;
        let idn: i64 = self.number(idn_node, "IDN")?;
        let Ok(idn) = u16::try_from(idn) else {
            self.warn(idn_node, format!("SoE init command: IDN {idn} does not fit SoE's 16 bits: left out"));
            return Ok(None);
        };
        let shown = ferrocat_wire::soe::Idn(idn);
        let op_code: u8 = self.child_number(c, "OpCode")?.unwrap_or(3);
        if op_code != 3 {
            self.warn(
                c,
                format!("SoE init command for {shown}: opcode {op_code} is not a write request (3): left out"),
            );
            return Ok(None);
        }
        let drive: u8 = self.child_number(c, "DriveNo")?.unwrap_or(0);
        if drive > 7 {
            return Err(err(c, format!("SoE init command for {shown}: <DriveNo> {drive} is not a drive 0–7")));
        }
        let elements = match self.child_number::<u8>(c, "Elements")? {
            None => 0x40,
            Some(0) => {
                self.warn(c, format!("SoE init command for {shown}: <Elements> 0 names no element: the value written"));
                0x40
            }
            Some(e) => e,
        };
        let data = match child(c, "Data") {
            Some(d) => self.hex(d, "Data")?,
            None => Vec::new(),
        };
        Ok(Some(SoeInitCmd {
            place: place(c),
            transitions: self.transitions(c),
            comment: self.child_text(c, "Comment").unwrap_or_default(),
            drive,
            idn,
            elements,
            data,
            fixed: self.attr_bool(c, "Fixed")?,
            timeout_ms: self.child_number(c, "Timeout")?,
        }))
    }

    fn init_cmds(&mut self, owner: Node<'_, '_>) -> R<Vec<InitCmd>> {
        let mut out = Vec::new();
        if let Some(cmds) = child(owner, "InitCmds") {
            for c in children(cmds, "InitCmd") {
                out.push(self.init_cmd(c)?);
            }
        }
        Ok(out)
    }

    /// The target and data of a datagram element: `<Adp>`/`<Ado>` or `<Addr>`, and `<Data>` or
    /// `<DataLength>` (zeros).
    fn datagram(&mut self, c: Node<'_, '_>) -> R<(Command, Target, Vec<u8>)> {
        let command = Command(self.req_number(c, "Cmd")?);
        if command.name().is_none() {
            return Err(err(c, format!("command {} is no EtherCAT command", command.0)));
        }
        let target = match child(c, "Addr") {
            Some(a) => Target::Logical(self.number(a, "Addr")?),
            None => Target::Device { adp: self.child_number(c, "Adp")?.unwrap_or(0), ado: self.req_number(c, "Ado")? },
        };
        let data = match (child(c, "Data"), child(c, "DataLength")) {
            (Some(d), _) => self.hex(d, "Data")?,
            (None, Some(l)) => {
                let n: usize = self.number(l, "DataLength")?;
                if n > MAX_DATAGRAM_DATA {
                    return Err(err(l, format!("DataLength {n}: more than a datagram carries ({MAX_DATAGRAM_DATA})")));
                }
                vec![0; n]
            }
            (None, None) => Vec::new(),
        };
        Ok((command, target, data))
    }

    fn init_cmd(&mut self, c: Node<'_, '_>) -> R<InitCmd> {
        let (command, target, data) = self.datagram(c)?;
        let validate = match child(c, "Validate") {
            Some(v) => {
                let d = child(v, "Data").ok_or_else(|| err(v, "<Validate> has no <Data>"))?;
                let vdata = self.hex(d, "Validate Data")?;
                let mask = child(v, "DataMask").map(|m| self.hex(m, "DataMask")).transpose()?;
                if vdata.len() > data.len() || mask.as_ref().is_some_and(|m| m.len() != vdata.len()) {
                    return Err(err(
                        v,
                        format!(
                            "validates {} bytes (mask {}) of a {}-byte datagram",
                            vdata.len(),
                            mask.as_ref().map_or(vdata.len(), Vec::len),
                            data.len()
                        ),
                    ));
                }
                Some(Validate { data: vdata, mask, timeout_ms: self.child_number(v, "Timeout")? })
            }
            None => None,
        };
        Ok(InitCmd {
            place: place(c),
            transitions: self.transitions(c),
            before_slave: self.child_bool(c, "BeforeSlave")?.unwrap_or(false),
            comment: self.child_text(c, "Comment").unwrap_or_default(),
            requires: self.child_text(c, "Requires"),
            command,
            target,
            data,
            cnt: self.child_number(c, "Cnt")?,
            retries: self.child_number(c, "Retries")?.unwrap_or(0),
            timeout_ms: self.child_number(c, "Timeout")?,
            validate,
        })
    }

    fn area(&mut self, p: Node<'_, '_>, name: &'static str) -> R<ImageArea> {
        let Some(a) = child(p, name) else { return Ok(ImageArea::default()) };
        let byte_size: u32 = self.req_number(a, "ByteSize")?;
        let mut variables = Vec::new();
        for v in children(a, "Variable") {
            let var = Variable {
                name: self.child_text(v, "Name").unwrap_or_default(),
                data_type: self.child_text(v, "DataType"),
                bit_size: self.req_number(v, "BitSize")?,
                bit_offs: self.req_number(v, "BitOffs")?,
            };
            // TwinCAT lists its own device's diagnosis (`InfoData.*`) past the image it sizes:
            // kept, as no frame carries it.
            if var.bit_offs as u64 + var.bit_size as u64 > byte_size as u64 * 8 {
                self.warn(
                    v,
                    format!(
                        "variable '{}' (bits {}..{}) lies beyond the {name} image of {byte_size} bytes: kept, no cyclic frame carries it",
                        var.name,
                        var.bit_offs,
                        var.bit_offs as u64 + var.bit_size as u64
                    ),
                );
            }
            variables.push(var);
        }
        Ok(ImageArea { byte_size, variables })
    }

    fn cyclic(&mut self, c: Node<'_, '_>, image: &ProcessImage) -> R<Cyclic> {
        let mut frames = Vec::new();
        for f in children(c, "Frame") {
            let mut cmds = Vec::new();
            let mut bytes = 0usize;
            for d in children(f, "Cmd") {
                let cmd = self.cyclic_cmd(d, image)?;
                bytes += 12 + cmd.data_length as usize;
                if bytes > MAX_DATAGRAM_DATA + 12 {
                    return Err(err(
                        d,
                        format!("the frame's datagrams take {bytes} bytes, more than one frame carries"),
                    ));
                }
                cmds.push(cmd);
            }
            frames.push(CyclicFrame { cmds });
        }
        Ok(Cyclic { cycle_time_us: self.child_number(c, "CycleTime")?, frames })
    }

    fn cyclic_cmd(&mut self, d: Node<'_, '_>, image: &ProcessImage) -> R<CyclicCmd> {
        let (command, target, data) = self.datagram(d)?;
        let mut states = Vec::new();
        for s in children(d, "State") {
            let t = raw_text(s).trim().to_string();
            match t.as_str() {
                "INIT" => states.push(AlState::Init),
                "PREOP" => states.push(AlState::PreOp),
                "BOOT" => states.push(AlState::Bootstrap),
                "SAFEOP" => states.push(AlState::SafeOp),
                "OP" => states.push(AlState::Op),
                _ => self.warn(s, format!("state '{t}' is none of INIT, PREOP, BOOT, SAFEOP, OP: left out")),
            }
        }
        let mut copies = Vec::new();
        if let Some(ci) = child(d, "CopyInfos") {
            for c in children(ci, "CopyInfo") {
                let copy = CopyInfo {
                    src_bit: self.req_number(c, "SrcBitOffs")?,
                    dst_bit: self.req_number(c, "DstBitOffs")?,
                    bits: self.req_number(c, "BitSize")?,
                };
                for (at, area, what) in
                    [(copy.src_bit, &image.inputs, "SrcBitOffs"), (copy.dst_bit, &image.outputs, "DstBitOffs")]
                {
                    if at as u64 + copy.bits as u64 > area.byte_size as u64 * 8 {
                        return Err(err(
                            c,
                            format!("{what} {at}: {} bits end past the image's {} bytes", copy.bits, area.byte_size),
                        ));
                    }
                }
                copies.push(copy);
            }
        }
        let cmd = CyclicCmd {
            place: place(d),
            copies,
            states,
            comment: self.child_text(d, "Comment").unwrap_or_default(),
            command,
            target,
            data_length: data.len() as u16,
            cnt: self.child_number(d, "Cnt")?,
            input_offs: self.child_number(d, "InputOffs")?,
            output_offs: self.child_number(d, "OutputOffs")?,
        };
        // The datagram, header and working counter, must lie within the image it mirrors.
        let span = 10 + cmd.data_length as u64 + 2;
        for (offs, area, what) in
            [(cmd.input_offs, &image.inputs, "InputOffs"), (cmd.output_offs, &image.outputs, "OutputOffs")]
        {
            if let Some(o) = offs {
                if area.byte_size > 0 && o as u64 + span > area.byte_size as u64 {
                    return Err(err(
                        d,
                        format!(
                            "{what} {o}: the datagram's {span} bytes end past the image's {} bytes",
                            area.byte_size
                        ),
                    ));
                }
            }
        }
        Ok(cmd)
    }
}
