//! A servo drive's SoE service channel (ETG.1000.6 §5.8): IDNs with their elements (name,
//! attribute, unit, minimum, maximum, value, default) per drive, read and written through the
//! mailbox, both ways in fragments where a mailbox is too short. Write protection follows the
//! attribute and the AL state (communication phases 2, 3, 4 are PREOP, SAFEOP, OP); values
//! of fixed length are checked against their minimum and maximum.
use std::collections::BTreeMap;

use ferrocat_wire::register::AlState;
use ferrocat_wire::soe::{
    self, emit_list, opcode, Attribute, DataType, Elements, Idn, SoeError, SoeHeader, ValueLength,
};

/// One IDN of a drive.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct IdnEntry {
    pub name: String,
    pub attribute: Attribute,
    pub unit: Option<String>,
    pub min: Option<Vec<u8>>,
    pub max: Option<Vec<u8>>,
    /// A fixed-length value's bytes, or a list's items.
    pub value: Vec<u8>,
    /// A list's maximum length, bytes.
    pub max_len: u16,
    pub default: Option<Vec<u8>>,
}

impl IdnEntry {
    fn fixed(name: &str, data_type: DataType, value: &[u8]) -> Self {
        IdnEntry {
            name: name.into(),
            attribute: Attribute::new(ValueLength::Fixed(value.len() as u8), data_type, 0),
            unit: None,
            min: None,
            max: None,
            value: value.to_vec(),
            max_len: 0,
            default: None,
        }
    }

    fn list(name: &str, item_len: u8, data_type: DataType, items: &[u8], max_len: u16) -> Self {
        IdnEntry {
            name: name.into(),
            attribute: Attribute::new(ValueLength::List(item_len), data_type, 0),
            unit: None,
            min: None,
            max: None,
            value: items.to_vec(),
            max_len,
            default: None,
        }
    }

    fn protected(mut self, phases: &[u8]) -> Self {
        self.attribute = self.attribute.with_write_protection(phases);
        self
    }

    fn unit(mut self, unit: &str) -> Self {
        self.unit = Some(unit.into());
        self
    }

    /// Element 7 as it goes on the wire: a list with its lengths.
    fn value_on_wire(&self) -> Vec<u8> {
        match self.attribute.length() {
            ValueLength::Fixed(_) => self.value.clone(),
            ValueLength::List(_) => list(&self.value, self.max_len),
        }
    }
}

fn list(items: &[u8], max: u16) -> Vec<u8> {
    let mut v = vec![0u8; 4 + items.len()];
    let n = emit_list(items, max, &mut v).unwrap_or(0);
    v.truncate(n);
    v
}

fn idns(list: &[Idn]) -> Vec<u8> {
    list.iter().flat_map(|i| i.0.to_le_bytes()).collect()
}

/// The SoE side of a drive: its IDNs per drive (axis), and a write in fragments under way.
#[derive(Debug, Clone, Default)]
pub struct SoeServer {
    pub drives: Vec<BTreeMap<Idn, IdnEntry>>,
    /// A write's fragments so far: drive, elements, the data.
    partial: Option<(u8, Elements, Vec<u8>)>,
    pub reads: u64,
    pub writes: u64,
}

/// The IDNs of the simulated drive: the telegram configuration (S-0-0015, S-0-0016 the AT's,
/// S-0-0024 the MDT's), the list of every IDN (S-0-0017), the firmware version (S-0-0030),
/// the cycle time (S-0-0001), the position command and feedback (S-0-0047, S-0-0051), the
/// control and status words (S-0-0134, S-0-0135) and one product parameter (P-0-0001, a gain
/// from 0 to 1000). Names, units and write protection as IEC 61800-7-204 gives them; the
/// values are ours.
pub fn standard_idns(firmware: &str) -> BTreeMap<Idn, IdnEntry> {
    let in_phase_2 = [3, 4];
    let read_only = [2, 3, 4];
    let mut m = BTreeMap::new();
    let at = [Idn(135), Idn(51)];
    let mdt = [Idn(134), Idn(47)];
    m.insert(
        Idn(1),
        IdnEntry::fixed("NC cycle time (TNcyc)", DataType::Unsigned, &1000u16.to_le_bytes())
            .unit("us")
            .protected(&in_phase_2),
    );
    m.insert(
        Idn::TELEGRAM_TYPE,
        IdnEntry::fixed("Telegram type", DataType::Unsigned, &7u16.to_le_bytes()).protected(&in_phase_2),
    );
    m.insert(
        Idn::AT_CONFIG,
        IdnEntry::list("Configuration list of AT", 2, DataType::Idn, &idns(&at), 32).protected(&in_phase_2),
    );
    m.insert(
        Idn::MDT_CONFIG,
        IdnEntry::list("Configuration list of MDT", 2, DataType::Idn, &idns(&mdt), 32).protected(&in_phase_2),
    );
    m.insert(
        Idn::FIRMWARE_VERSION,
        IdnEntry::list("Manufacturer version", 1, DataType::Text, firmware.as_bytes(), 64).protected(&read_only),
    );
    m.insert(Idn(47), IdnEntry::fixed("Position command value", DataType::Signed, &0i32.to_le_bytes()).unit("incr"));
    m.insert(
        Idn(51),
        IdnEntry::fixed("Position feedback value 1", DataType::Signed, &0i32.to_le_bytes())
            .unit("incr")
            .protected(&read_only),
    );
    m.insert(Idn(134), IdnEntry::fixed("Master control word", DataType::Binary, &0u16.to_le_bytes()));
    m.insert(
        Idn(135),
        IdnEntry::fixed("Drive status word", DataType::Binary, &0u16.to_le_bytes()).protected(&read_only),
    );
    let mut gain = IdnEntry::fixed("Gain", DataType::Unsigned, &100u16.to_le_bytes()).unit("%");
    gain.min = Some(0u16.to_le_bytes().to_vec());
    gain.max = Some(1000u16.to_le_bytes().to_vec());
    gain.default = Some(100u16.to_le_bytes().to_vec());
    m.insert(Idn(0x8001), gain);
    let all: Vec<Idn> =
        m.keys().copied().chain([Idn::ALL_IDNS]).collect::<std::collections::BTreeSet<_>>().into_iter().collect();
    let n = all.len() as u16 * 2;
    m.insert(
        Idn::ALL_IDNS,
        IdnEntry::list("IDN-list of all operation data", 2, DataType::Idn, &idns(&all), n).protected(&read_only),
    );
    m
}

impl SoeServer {
    /// The bytes of the telegram every drive's configuration list names: the MDT's (S-0-0024,
    /// the outputs) or the AT's (S-0-0016, the inputs), drive after drive, each IDN as long as
    /// its attribute says. A list naming an IDN the drive lacks or one of variable length
    /// cannot be mapped: `None`.
    pub fn telegram_bytes(&self, outputs: bool) -> Option<u16> {
        let list_idn = if outputs { Idn::MDT_CONFIG } else { Idn::AT_CONFIG };
        let mut bytes = 0u32;
        for drive in &self.drives {
            let Some(list) = drive.get(&list_idn) else { continue };
            for item in list.value.chunks_exact(2) {
                let idn = Idn(u16::from_le_bytes([item[0], item[1]]));
                match drive.get(&idn)?.attribute.length() {
                    ValueLength::Fixed(n) => bytes += n as u32,
                    ValueLength::List(_) => return None,
                }
            }
        }
        u16::try_from(bytes).ok()
    }

    /// One drive with [`standard_idns`].
    pub fn one_drive(firmware: &str) -> Self {
        Self::drives(1, firmware)
    }

    /// `count` drives (axes 0 to `count` − 1), each with [`standard_idns`].
    pub fn drives(count: u8, firmware: &str) -> Self {
        SoeServer { drives: (0..count).map(|_| standard_idns(firmware)).collect(), ..SoeServer::default() }
    }

    /// The messages (service data after the mailbox header) answering `request`, in order;
    /// none while a write's fragments are still coming. `in_len` is the send mailbox's size.
    pub fn handle(&mut self, request: &[u8], in_len: usize, state: AlState) -> Vec<Vec<u8>> {
        let Ok(h) = SoeHeader::parse(request) else { return Vec::new() };
        let body = &request[soe::HEADER_LEN..];
        match h.opcode {
            opcode::READ_REQUEST => {
                self.reads += 1;
                match self.read(h, state) {
                    Ok(data) => fragments(h, opcode::READ_RESPONSE, &data, soe::max_fragment_len(in_len)),
                    Err(e) => vec![error_reply(h, opcode::READ_RESPONSE, e)],
                }
            }
            opcode::WRITE_REQUEST => {
                let (drive, elements) = (h.drive, h.elements);
                let mut data = match self.partial.take() {
                    Some((d, e, so_far)) if d == drive && e == elements => so_far,
                    _ => Vec::new(),
                };
                data.extend_from_slice(body);
                if h.incomplete {
                    self.partial = Some((drive, elements, data));
                    return Vec::new();
                }
                self.writes += 1;
                let reply = match self.write(h, &data, state) {
                    Ok(()) => {
                        let r = SoeHeader { opcode: opcode::WRITE_RESPONSE, incomplete: false, error: false, ..h };
                        let mut v = vec![0u8; soe::HEADER_LEN];
                        let _ = r.emit(&mut v);
                        v
                    }
                    Err(e) => error_reply(h, opcode::WRITE_RESPONSE, e),
                };
                vec![reply]
            }
            _ => Vec::new(),
        }
    }

    fn entry(&self, h: SoeHeader) -> Result<&IdnEntry, SoeError> {
        let drive = self.drives.get(h.drive as usize).ok_or(SoeError::INVALID_DRIVE)?;
        drive.get(&Idn(h.idn)).ok_or(SoeError::NO_IDN)
    }

    fn read(&self, h: SoeHeader, _state: AlState) -> Result<Vec<u8>, SoeError> {
        let e = self.entry(h)?;
        if h.elements.0 == 0 {
            return Err(SoeError::NO_ELEMENT);
        }
        let mut out = Vec::new();
        let want = |x: Elements| h.elements.contains(x);
        if want(Elements::DATA_STATE) {
            out.extend_from_slice(&0u16.to_le_bytes());
        }
        if want(Elements::NAME) {
            out.extend(list(e.name.as_bytes(), e.name.len() as u16));
        }
        if want(Elements::ATTRIBUTE) {
            out.extend_from_slice(&e.attribute.0.to_le_bytes());
        }
        if want(Elements::UNIT) {
            let u = e.unit.as_ref().ok_or(SoeError::NO_UNIT)?;
            out.extend(list(u.as_bytes(), u.len() as u16));
        }
        if want(Elements::MIN) {
            out.extend_from_slice(e.min.as_ref().ok_or(SoeError::NO_MIN)?);
        }
        if want(Elements::MAX) {
            out.extend_from_slice(e.max.as_ref().ok_or(SoeError::NO_MAX)?);
        }
        if want(Elements::VALUE) {
            out.extend(e.value_on_wire());
        }
        if want(Elements::DEFAULT) {
            out.extend_from_slice(e.default.as_ref().ok_or(SoeError::NO_DEFAULT)?);
        }
        Ok(out)
    }

    fn write(&mut self, h: SoeHeader, data: &[u8], state: AlState) -> Result<(), SoeError> {
        let e = self.entry(h)?;
        // Only the value is written here; the other elements are the drive's.
        if h.elements != Elements::VALUE {
            return Err(match h.elements {
                Elements::NAME => SoeError::NAME_READ_ONLY,
                Elements::ATTRIBUTE => SoeError::ATTRIBUTE_READ_ONLY,
                Elements::DEFAULT => SoeError(0x8004),
                Elements(0) => SoeError::NO_ELEMENT,
                _ => SoeError::GENERAL,
            });
        }
        let phase = match state {
            AlState::PreOp => 2,
            AlState::SafeOp => 3,
            AlState::Op => 4,
            _ => 0,
        };
        let a = e.attribute;
        if (2..=4).all(|p| a.write_protected_in(p)) {
            return Err(SoeError::VALUE_READ_ONLY);
        }
        if a.write_protected_in(phase) {
            return Err(SoeError::VALUE_WRITE_PROTECTED_NOW);
        }
        let value = match a.length() {
            ValueLength::Fixed(n) => {
                if data.len() < n as usize {
                    return Err(SoeError::VALUE_TOO_SHORT);
                }
                if data.len() > n as usize {
                    return Err(SoeError::VALUE_TOO_LONG);
                }
                let number = |b: &[u8]| -> i128 {
                    let mut w = [0u8; 8];
                    w[..b.len().min(8)].copy_from_slice(&b[..b.len().min(8)]);
                    let u = u64::from_le_bytes(w);
                    if a.data_type() == DataType::Signed && b.len() < 8 {
                        let shift = 64 - 8 * b.len() as u32;
                        (((u << shift) as i64) >> shift) as i128
                    } else if a.data_type() == DataType::Signed {
                        u as i64 as i128
                    } else {
                        u as i128
                    }
                };
                if matches!(a.data_type(), DataType::Unsigned | DataType::Signed) {
                    if e.min.as_ref().is_some_and(|m| number(data) < number(m)) {
                        return Err(SoeError::VALUE_BELOW_MIN);
                    }
                    if e.max.as_ref().is_some_and(|m| number(data) > number(m)) {
                        return Err(SoeError::VALUE_ABOVE_MAX);
                    }
                }
                data.to_vec()
            }
            ValueLength::List(item) => {
                let (items, _) = soe::list_items(data).map_err(|_| SoeError::VALUE_TOO_SHORT)?;
                if items.len() > e.max_len as usize {
                    return Err(SoeError::VALUE_TOO_LONG);
                }
                if items.len() % item as usize != 0 {
                    return Err(SoeError::VALUE_INVALID);
                }
                items.to_vec()
            }
        };
        if let Some(e) = self.drives.get_mut(h.drive as usize).and_then(|d| d.get_mut(&Idn(h.idn))) {
            e.value = value;
        }
        Ok(())
    }
}

fn error_reply(h: SoeHeader, op: u8, e: SoeError) -> Vec<u8> {
    let r = SoeHeader { opcode: op, incomplete: false, error: true, ..h };
    let mut v = vec![0u8; soe::HEADER_LEN + 2];
    let _ = r.emit(&mut v);
    v[soe::HEADER_LEN..].copy_from_slice(&e.0.to_le_bytes());
    v
}

/// A response of `op` carrying `data`, split into fragments of at most `per` bytes: each but
/// the last marked incomplete with the fragments still to come in its IDN field.
fn fragments(h: SoeHeader, op: u8, data: &[u8], per: usize) -> Vec<Vec<u8>> {
    let per = per.max(1);
    let parts: Vec<&[u8]> = if data.is_empty() { vec![&[][..]] } else { data.chunks(per).collect() };
    let n = parts.len();
    parts
        .iter()
        .enumerate()
        .map(|(k, part)| {
            let left = n - 1 - k;
            let r = SoeHeader {
                opcode: op,
                incomplete: left > 0,
                error: false,
                idn: if left > 0 { left as u16 } else { h.idn },
                ..h
            };
            let mut v = vec![0u8; soe::HEADER_LEN + part.len()];
            let _ = r.emit(&mut v);
            v[soe::HEADER_LEN..].copy_from_slice(part);
            v
        })
        .collect()
}

#[cfg(test)]
mod tests {
    use super::*;

    fn req(op: u8, incomplete: bool, elements: Elements, idn: u16, data: &[u8]) -> Vec<u8> {
        let h = SoeHeader { opcode: op, incomplete, error: false, drive: 0, elements, idn };
        let mut v = vec![0u8; 4 + data.len()];
        h.emit(&mut v).unwrap();
        v[4..].copy_from_slice(data);
        v
    }

    #[test]
    fn a_read_longer_than_the_mailbox_comes_in_fragments_counting_down() {
        let mut s = SoeServer::one_drive("ferrocat SoE drive 1.0");
        // A 16-byte mailbox: 6 header + 4 SoE header leaves 6 bytes a fragment.
        let r = s.handle(&req(opcode::READ_REQUEST, false, Elements::VALUE, 30, &[]), 16, AlState::PreOp);
        let text = b"ferrocat SoE drive 1.0";
        assert_eq!(r.len(), (4 + text.len()).div_ceil(6));
        let mut joined = Vec::new();
        for (k, m) in r.iter().enumerate() {
            let h = SoeHeader::parse(m).unwrap();
            let left = r.len() - 1 - k;
            assert_eq!((h.incomplete, h.idn), if left > 0 { (true, left as u16) } else { (false, 30) });
            joined.extend_from_slice(&m[4..]);
        }
        assert_eq!(soe::list_items(&joined).unwrap(), (&text[..], 64));
    }

    #[test]
    fn writes_follow_protection_limits_and_lengths() {
        let mut s = SoeServer::one_drive("v1");
        let write = |s: &mut SoeServer, idn: u16, data: &[u8], state| {
            let r = s.handle(&req(opcode::WRITE_REQUEST, false, Elements::VALUE, idn, data), 512, state);
            let h = SoeHeader::parse(&r[0]).unwrap();
            h.error.then(|| SoeError(u16::from_le_bytes([r[0][4], r[0][5]])))
        };
        assert_eq!(write(&mut s, 0x8001, &500u16.to_le_bytes(), AlState::Op), None);
        assert_eq!(write(&mut s, 0x8001, &1001u16.to_le_bytes(), AlState::Op), Some(SoeError::VALUE_ABOVE_MAX));
        assert_eq!(write(&mut s, 0x8001, &[1], AlState::Op), Some(SoeError::VALUE_TOO_SHORT));
        assert_eq!(write(&mut s, 1, &500u16.to_le_bytes(), AlState::SafeOp), Some(SoeError::VALUE_WRITE_PROTECTED_NOW));
        assert_eq!(write(&mut s, 1, &500u16.to_le_bytes(), AlState::PreOp), None);
        assert_eq!(write(&mut s, 51, &1i32.to_le_bytes(), AlState::PreOp), Some(SoeError::VALUE_READ_ONLY));
        assert_eq!(write(&mut s, 0x7777, &[0, 0], AlState::PreOp), Some(SoeError::NO_IDN));
        // A list written in two fragments: the first unanswered.
        let mut l = vec![4, 0, 4, 0];
        l.extend_from_slice(&idns(&[Idn(51), Idn(135)]));
        assert!(s
            .handle(&req(opcode::WRITE_REQUEST, true, Elements::VALUE, 1, &l[..3]), 512, AlState::PreOp)
            .is_empty());
        let r = s.handle(&req(opcode::WRITE_REQUEST, false, Elements::VALUE, 16, &l[3..]), 512, AlState::PreOp);
        assert!(!SoeHeader::parse(&r[0]).unwrap().error);
        assert_eq!(s.drives[0][&Idn::AT_CONFIG].value, idns(&[Idn(51), Idn(135)]));
    }

    #[test]
    fn elements_a_parameter_lacks_are_errors_and_the_list_of_all_names_every_idn() {
        let mut s = SoeServer::one_drive("v1");
        let r = s.handle(&req(opcode::READ_REQUEST, false, Elements::UNIT, 15, &[]), 512, AlState::PreOp);
        assert_eq!(&r[0][4..], &SoeError::NO_UNIT.0.to_le_bytes());
        let r = s.handle(&req(opcode::READ_REQUEST, false, Elements::VALUE, 17, &[]), 512, AlState::PreOp);
        let (items, _) = soe::list_items(&r[0][4..]).unwrap();
        let all: Vec<u16> = items.chunks(2).map(|c| u16::from_le_bytes([c[0], c[1]])).collect();
        assert!(all.contains(&17) && all.contains(&30) && all.contains(&0x8001));
        assert_eq!(all.len(), s.drives[0].len());
    }

    #[test]
    fn the_telegrams_are_as_long_as_the_configuration_lists_name() {
        let mut s = SoeServer::one_drive("x");
        // MDT: control word and position command; AT: status word and position feedback.
        assert_eq!((s.telegram_bytes(true), s.telegram_bytes(false)), (Some(6), Some(6)));
        s.drives[0].get_mut(&Idn::AT_CONFIG).unwrap().value = idns(&[Idn(135), Idn(51), Idn(47)]);
        assert_eq!(s.telegram_bytes(false), Some(10));
        // An IDN the drive lacks, or a list, cannot go in a telegram.
        s.drives[0].get_mut(&Idn::AT_CONFIG).unwrap().value = idns(&[Idn(999)]);
        assert_eq!(s.telegram_bytes(false), None);
        s.drives[0].get_mut(&Idn::AT_CONFIG).unwrap().value = idns(&[Idn::FIRMWARE_VERSION]);
        assert_eq!(s.telegram_bytes(false), None);
    }
}
