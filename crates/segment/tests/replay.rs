//! Replaying the master side of every real capture against a segment of the devices it came
//! from, as far as the shared EEPROM dumps describe them: the working counters the real
//! hardware gave, and identical data for reads of identity, SII and configuration registers.
//! A report lists every mismatch with its reason.
use std::collections::{BTreeMap, BTreeSet};

use ferrocat_segment::{Segment, SegmentConfig};
use ferrocat_wire::register::SyncManager;
use ferrocat_wire::{Address, Command, Frame};

struct Packet {
    t_ns: u64,
    data: Vec<u8>,
}

fn packets(path: &std::path::Path) -> Vec<Packet> {
    let bytes = std::fs::read(path).unwrap();
    let mut v = Vec::new();
    ferrocat_capture::for_each_packet(&bytes, |p| {
        if matches!(Frame::parse(&p.data), Ok(Some(f)) if f.pdu.datagram_count() > 0) {
            v.push(Packet { t_ns: p.timestamp.as_nanos() as u64, data: p.data.to_vec() });
        }
        Ok(())
    })
    .unwrap();
    v
}

fn shape(f: &[u8]) -> Vec<(u8, u8, u16)> {
    let f = Frame::parse(f).unwrap().unwrap();
    f.pdu.datagrams().map(|d| (d.header().command.0, d.header().index, d.header().len)).collect()
}

/// Request/response pairs: a frame and the next one with the same datagram shape (commands,
/// indices, lengths) within the next four — a master with two frames in flight has them
/// interleaved (TwinCAT's SM1 write in twincat-akd-nc-mode, frames 3337 and 3339, around a
/// read of 0x080D). A frame whose match is identical to it was lost and sent again: the
/// second is the request.
fn pairs(p: &[Packet]) -> Vec<(usize, usize)> {
    let shapes: Vec<_> = p.iter().map(|x| shape(&x.data)).collect();
    let mut used = vec![false; p.len()];
    let mut v = Vec::new();
    for i in 0..p.len() {
        if used[i] {
            continue;
        }
        let Some(j) = (i + 1..(i + 5).min(p.len())).find(|&j| !used[j] && shapes[j] == shapes[i]) else { continue };
        if p[j].data != p[i].data {
            v.push((i, j));
            used[i] = true;
            used[j] = true;
        }
    }
    v
}

/// Product codes by slave position, from the SII reads in the capture (word 0x0A), keyed by
/// the address the master sent: a position (AP commands, the first slave 0) or a station
/// address (FP commands, assigned in position order). A response's position address comes back
/// incremented by every slave, so the request's is used.
fn identities(p: &[Packet], pairs: &[(usize, usize)]) -> (usize, BTreeMap<usize, u32>) {
    let mut count = 0;
    let mut pending: BTreeMap<(bool, u16), u32> = BTreeMap::new();
    let (mut by_position, mut by_station) = (BTreeMap::new(), BTreeMap::new());
    for &(req, resp) in pairs {
        let sent = Frame::parse(&p[req].data).unwrap().unwrap();
        let f = Frame::parse(&p[resp].data).unwrap().unwrap();
        for (q, d) in sent.pdu.datagrams().zip(f.pdu.datagrams()) {
            let h = d.header();
            let (Address::Device { ado, .. }, Address::Device { adp: key, .. }) = (h.address, q.header().address)
            else {
                continue;
            };
            let positional = matches!(h.command, Command::APWR | Command::APRD);
            let key = if positional { 0u16.wrapping_sub(key) } else { key };
            match (h.command, ado) {
                // Every slave answers a broadcast read of its basic registers once.
                (Command::BRD, 0x0000..=0x01FF) if count == 0 => count = d.wkc() as usize,
                (Command::APWR | Command::FPWR, 0x0502) if d.data().len() >= 6 => {
                    pending.insert((positional, key), u32::from_le_bytes(d.data()[2..6].try_into().unwrap()));
                }
                (Command::APRD | Command::FPRD, 0x0508) if d.wkc() == 1 => {
                    let Some(&a) = pending.get(&(positional, key)) else { continue };
                    if a <= 0x0A && (0x0A - a) as usize * 2 + 4 <= d.data().len() {
                        let off = (0x0A - a) as usize * 2;
                        let id = u32::from_le_bytes(d.data()[off..off + 4].try_into().unwrap());
                        if positional { &mut by_position } else { &mut by_station }.insert(key, id);
                    }
                }
                _ => {}
            }
        }
    }
    let ids: BTreeMap<usize, u32> = if by_position.is_empty() {
        by_station.into_values().enumerate().collect()
    } else {
        by_position.into_iter().map(|(pos, id)| (pos as usize, id)).collect()
    };
    let highest = ids.keys().next_back().map_or(0, |&k| k + 1);
    (count.max(highest), ids)
}

/// What a capture shows of each slave's own device, by position: the SII words it read and the
/// bytes of the ESC's identity registers (0x0000–0x0009) it read.
#[derive(Default, Debug)]
struct Evidence {
    sii: BTreeMap<usize, BTreeMap<u16, u16>>,
    identity: BTreeMap<usize, [Option<u8>; 10]>,
}

/// The slave a datagram addresses, as a position: position addressing directly, station
/// addresses through the capture's own assignment (APWR of 0x0010) or, where the capture
/// starts with them assigned, in ascending order.
fn position_of(cmd: Command, adp: u16, stations: &BTreeMap<u16, usize>) -> Option<usize> {
    match cmd {
        Command::APRD | Command::APWR | Command::APRW => Some(0u16.wrapping_sub(adp) as usize),
        Command::FPRD | Command::FPWR | Command::FPRW => stations.get(&adp).copied(),
        _ => None,
    }
}

fn evidence(p: &[Packet], pairs: &[(usize, usize)]) -> Evidence {
    let mut stations: BTreeMap<u16, usize> = BTreeMap::new();
    for &(req, _) in pairs {
        let f = Frame::parse(&p[req].data).unwrap().unwrap();
        for d in f.pdu.datagrams() {
            if let (Command::APWR, Address::Device { adp, ado: 0x0010 }) = (d.header().command, d.header().address) {
                if d.data().len() >= 2 {
                    stations.insert(u16::from_le_bytes([d.data()[0], d.data()[1]]), 0u16.wrapping_sub(adp) as usize);
                }
            }
        }
    }
    if stations.is_empty() {
        stations = addressing(p, pairs).1.into_iter().enumerate().map(|(k, a)| (a, k)).collect();
    }
    let mut e = Evidence::default();
    let mut pending: BTreeMap<usize, u32> = BTreeMap::new();
    for &(req, resp) in pairs {
        let sent = Frame::parse(&p[req].data).unwrap().unwrap();
        let back = Frame::parse(&p[resp].data).unwrap().unwrap();
        for (q, a) in sent.pdu.datagrams().zip(back.pdu.datagrams()) {
            let h = q.header();
            let Address::Device { adp, ado } = h.address else { continue };
            let Some(pos) = position_of(h.command, adp, &stations) else { continue };
            let at = |reg: u16, data: &[u8]| -> Option<u8> {
                reg.checked_sub(ado).map(usize::from).and_then(|i| data.get(i).copied())
            };
            let address = |data: &[u8]| -> Option<u32> {
                Some(u32::from_le_bytes([at(0x0504, data)?, at(0x0505, data)?, at(0x0506, data)?, at(0x0507, data)?]))
            };
            if h.command.writes() && a.wkc() > 0 {
                if let Some(w) = address(q.data()) {
                    pending.insert(pos, w);
                }
            }
            if !h.command.reads() || a.wkc() != 1 {
                continue;
            }
            let data = a.data();
            let id = e.identity.entry(pos).or_insert([None; 10]);
            for (r, slot) in id.iter_mut().enumerate() {
                if slot.is_none() {
                    *slot = at(r as u16, data);
                }
            }
            let busy = at(0x0503, data).is_some_and(|b| b & 0x80 != 0);
            let word = address(data).or(pending.get(&pos).copied());
            if let (false, Some(word), Some(_)) = (busy, word, at(0x0508, data)) {
                let words = e.sii.entry(pos).or_default();
                for k in 0..4u16 {
                    if let (Some(lo), Some(hi)) = (at(0x0508 + 2 * k, data), at(0x0509 + 2 * k, data)) {
                        words.entry(word as u16 + k).or_insert(u16::from_le_bytes([lo, hi]));
                    }
                }
            }
        }
    }
    e
}

/// The EEPROM dump a device's TOML names, if it names one.
fn eeprom_of(src: &str) -> Option<std::path::PathBuf> {
    let rest = src.strip_prefix("eeprom = '")?;
    Some(rest[..rest.find('\'')?].into())
}

/// The stand-in's image with the words the capture read of the real device put over it at
/// their addresses (the configuration area's checksum, word 7, computed again where the
/// capture did not read it), and how many were used. Where the words read of the category
/// area do not make a readable image with the stand-in's (a category read only in part over
/// one of another length), only the header's (0x00–0x3F) are used.
fn overlay_sii(base: &std::path::Path, read: &BTreeMap<u16, u16>) -> (Vec<u8>, usize) {
    let stand_in = ferrocat_segment::files::read_eeprom_dump(base).unwrap();
    let put = |words: &mut dyn Iterator<Item = (&u16, &u16)>| {
        let mut img = stand_in.clone();
        let mut n = 0;
        for (&w, &v) in words {
            let at = 2 * w as usize;
            if img.len() < at + 2 {
                img.resize((at + 2).next_multiple_of(0x80), 0xFF);
            }
            img[at..at + 2].copy_from_slice(&v.to_le_bytes());
            n += 1;
        }
        if (0..7).any(|w| read.contains_key(&w)) && !read.contains_key(&7) {
            img[14] = ferrocat_wire::sii::header_crc(&img);
        }
        (img, n)
    };
    let all = put(&mut read.iter());
    if ferrocat_wire::sii::SiiInfo::from_image(&all.0).is_ok() {
        return all;
    }
    put(&mut read.range(..0x40))
}

fn source(product: Option<u32>) -> (String, Option<&'static str>) {
    let eeprom = ferrocat_testdata::shared("captures/eeprom");
    let e = |f: &str| format!("eeprom = '{}/{f}'", eeprom.display());
    match product {
        Some(0x044C_2C52) => (e("ek1100.hex"), None),
        Some(0x07D4_3052) => (e("el2004.bin"), None),
        Some(0x0B0C_3052) => (e("el2828.hex"), None),
        // On the IP core the segment knows the AKD carries (its identity picks it). Its
        // firmware's mailbox response time: soem-sdinfo-akd's 35 requests were each answered
        // between SOEM's last empty and first full poll of SM1 (0.56–2.86 ms after the
        // request); the uniform range of greatest likelihood for those intervals.
        // Its AL control: INIT→PREOP shown 3.58–5.63 ms after SOEM's write (AL status polls).
        Some(0x0041_4B44) => {
            (e("akd.hex") + "\nmailbox_response_us = 565\nmailbox_response_max_us = 2230\nal_response_us = 4600", None)
        }
        // The real EL2889 has a system time (replay-dc: the FRMWs of 0x0910 count it), the
        // EL2828 whose dump stands in has receive times only: its SYNC unit is turned on.
        Some(0x0B49_3052) => (
            e("el2828.hex") + "\nsync_unit = true",
            Some("EL2889: no EEPROM dump or ESI in shared data (EL2828 with its SYNC unit on stands in)"),
        ),
        // The real EK1914 is an ET1100 (features 0x00FC, 8 FMMUs and SyncManagers) with receive
        // times but no system time (its FRMWs and BWRs of 0x0910–0x09A4 count 0): units off.
        Some(0x077A_2C52) => (
            e("ek1100.hex") + "\nsync_unit = false\nlatch_unit = false",
            Some("EK1914: no EEPROM dump or ESI in shared data (EK1100 with its SYNC and latch units off stands in)"),
        ),
        Some(0x0BBC_3052) => (e("el2828.hex"), Some("EL3004: no EEPROM dump or ESI in shared data (EL2828 stands in)")),
        // The built-in board carries its sample firmware's times as this capture shows them
        // (`builtin::firmware_times_us`).
        Some(0x9252) => (
            "builtin = 'LAN9252-EVB'".into(),
            Some("EVB-LAN9252: no EEPROM dump in shared data (the built-in description, from this capture, stands in)"),
        ),
        Some(0x03EC_3052) => (e("el2004.bin"), Some("EL1004: no EEPROM dump in shared data (EL2004 stands in)")),
        _ => (e("ek1100.hex"), Some("device unknown from the capture (EK1100 stands in)")),
    }
}

/// Registers whose read data must be identical: identity and features, station address and
/// alias, DL control and status, PDI control, SII data, FMMU and SyncManager configuration
/// (not the SM status bytes).
fn compared(ado: u16, i: usize) -> bool {
    let a = ado as usize + i;
    matches!(a, 0x0000..=0x000B | 0x0010..=0x0013 | 0x0100..=0x0103 | 0x0110..=0x0111 | 0x0140..=0x0141 | 0x0508..=0x050F | 0x0600..=0x06FF)
        || ((0x0800..=0x087F).contains(&a) && (a - 0x0800) % 8 < 5)
}

/// Whether the capture assigns station addresses, and the configured addresses it uses.
fn addressing(p: &[Packet], pairs: &[(usize, usize)]) -> (bool, Vec<u16>) {
    let mut assigns = false;
    let mut fixed = std::collections::BTreeSet::new();
    for &(req, _) in pairs {
        let f = Frame::parse(&p[req].data).unwrap().unwrap();
        for d in f.pdu.datagrams() {
            let h = d.header();
            if let Address::Device { adp, ado } = h.address {
                match h.command {
                    Command::APWR | Command::BWR if (0x0010..=0x0011).contains(&ado) => assigns = true,
                    Command::FPRD | Command::FPWR | Command::FPRW | Command::FRMW => {
                        fixed.insert(adp);
                    }
                    _ => {}
                }
            }
        }
    }
    (assigns, fixed.into_iter().collect())
}

/// An EoE message read whole from a mailbox: its counter byte and service data.
fn eoe_message(data: &[u8], wkc: u16) -> Option<Vec<u8>> {
    let h = ferrocat_wire::mailbox::MailboxHeader::parse(data).ok()?;
    let end = 6 + h.length as usize;
    (wkc > 0 && h.mailbox_type == ferrocat_wire::mailbox::MailboxType::EOE && end <= data.len())
        .then(|| data[5..end].to_vec())
}

/// The state bits of the first AL status the capture reads from `station`.
fn first_al_status(p: &[Packet], pairs: &[(usize, usize)], station: u16) -> Option<u8> {
    pairs.iter().find_map(|&(_, resp)| {
        let f = Frame::parse(&p[resp].data).ok()??;
        f.pdu.datagrams().find_map(|d| match (d.header().command, d.header().address) {
            (Command::FPRD, Address::Device { adp, ado: 0x0130 }) if adp == station && d.wkc() == 1 => {
                d.data().first().map(|b| b & 0x0F)
            }
            _ => None,
        })
    })
}

fn setup_frame(cmd: Command, address: Address, data: &[u8]) -> Vec<u8> {
    use ferrocat_wire::ethernet::{EthernetRepr, BROADCAST};
    use ferrocat_wire::{DatagramHeader, FrameWriter};
    let eth = EthernetRepr { dst: BROADCAST, src: [0x02; 6], vlan_tci: None, ethertype: 0 };
    let mut buf = vec![0u8; 128];
    let mut w = FrameWriter::new(&mut buf, &eth).unwrap();
    w.push(&DatagramHeader::new(cmd, 0, address, data.len() as u16), data, 0).unwrap();
    let n = w.finish().unwrap();
    buf.truncate(n);
    buf
}

#[derive(Default)]
struct Report {
    datagrams: usize,
    wkc_same: usize,
    compared_reads: usize,
    data_same: usize,
    /// Datagrams after the capture wrote the ECAT event mask, and those whose IRQ field
    /// came back as the real one.
    irq_compared: usize,
    irq_same: usize,
    /// Reads of a mailbox SyncManager's status, and those equal in bits 0, 1 and 3.
    mbx_status_compared: usize,
    mbx_status_same: usize,
    /// The EoE messages the real slaves sent (read from their mailboxes, a message read
    /// twice counted once), and ours, in order.
    eoe_real: Vec<Vec<u8>>,
    eoe_ours: Vec<Vec<u8>>,
    reasons: BTreeMap<String, usize>,
    examples: Vec<String>,
    /// Every byte of every response: compared, exempt, and differing by register (or area).
    bytes: usize,
    bytes_exempt: usize,
    byte_diffs: BTreeMap<String, (usize, String)>,
}

/// Bytes whose value comes from time or physics, not from the ESC's logic: they are left out
/// of the byte agreement (docs/esc-model.md, "Data-level replay", gives the frames that show
/// each).
fn exempt(reg: u16) -> Option<&'static str> {
    match reg {
        0x0900..=0x091F => Some("DC receive times, system time, processing-unit receive time: the real clocks"),
        0x092C..=0x092F => Some("DC system time difference: the real crystals"),
        _ => None,
    }
}

/// Why an IRQ field differs. `dl_unknown`: the capture has not yet read every slave's DL
/// status, so the real ESCs' DL status events may have been cleared before it began.
fn irq_reason(ours: u16, real: u16, dl_unknown: bool, standins: &[(u16, &str)]) -> &'static str {
    let dl = ferrocat_wire::register::ecat_event::DL_STATUS;
    if ours ^ real == dl && ours & dl != 0 && dl_unknown {
        "DL status event: the real ESC's was read before the capture began (an earlier session)"
    } else if ours ^ real == dl && real & dl != 0 {
        "DL status event: the real ESCs' DL status changed with no master write before it (not replayed)"
    } else if !standins.is_empty() {
        "the segment includes stand-ins"
    } else {
        "not explained"
    }
}

/// Why a mailbox SyncManager's status byte differs (bits 0, 1, 3).
fn mailbox_status_reason(ours: u8, real: u8, standin: bool, drawn: bool) -> &'static str {
    let full = SyncManager::STATUS_MAILBOX_FULL;
    if standin {
        "a stand-in device"
    } else if drawn && (ours ^ real) & full != 0 {
        "the firmware's response time: ours is drawn from the real one's range, not the real draw"
    } else if ours & full != 0 && real & full == 0 {
        "the real firmware had not answered yet; ours answers at once"
    } else if ours & 0x0B == SyncManager::STATUS_INT_READ && real == 0x80 {
        "the real firmware was writing its reply (write buffer open)"
    } else {
        "not explained"
    }
}

/// The stand-in a datagram reaches, if any (a broadcast: all of them).
fn standin_reached(cmd: Command, adp: u16, standins: &[(u16, &str)]) -> Option<String> {
    let broadcast = matches!(
        cmd,
        Command::BRD
            | Command::BWR
            | Command::BRW
            | Command::LRD
            | Command::LWR
            | Command::LRW
            | Command::ARMW
            | Command::FRMW
    );
    if broadcast && !standins.is_empty() {
        return Some(format!(
            "the segment includes stand-ins ({})",
            standins.iter().map(|s| s.1).collect::<Vec<_>>().join("; ")
        ));
    }
    standins
        .iter()
        .find(|(pos, _)| *pos == adp || 0x1000 + *pos == adp || 0x1001 + *pos == adp || 0u16.wrapping_sub(*pos) == adp)
        .map(|(_, why)| why.to_string())
}

fn reason(cmd: Command, adp: u16, ado: u16, standins: &[(u16, &str)], what: &str) -> String {
    let standin = standin_reached(cmd, adp, standins);
    if let Some(why) = standin {
        return format!("{what}: {why}");
    }
    let r = match ado {
        0x0000..=0x000B => "ESC identity registers: the simulated ESC (ET1100/ET1200 as the captures show them) is not this unit's silicon revision",
        0x0100..=0x0103 => "DL control's reset value: the real ESC, an IP core, is not the ET1100 modelled",
        0x0140..=0x0141 => "PDI control: the real ESC, an IP core, has its PDI fixed at synthesis, not as SII word 0 gives it",
        0x0120..=0x0121 => "AL control: the real firmware read it at another moment than the modelled 1 ms",
        0x0130..=0x0135 => "AL status: the simulated slave changes state at another moment than the real one",
        0x0502 => "SII interface, 0x0502 bit 4 (reserved in the datasheet): the real ET1200s of the EL2828, EL1004 and EL3004 read it set, the EL2004's clear; the EL1004's and EL3004's clear later in their sessions, the EL2828's not after the same EEPROM hand-over to the PDI; not modelled (no source says what it means)",
        0x0500..=0x050F => "SII interface: busy timing differs (700 µs per read, 3 ms per write here; a PDI-emulated EEPROM answers sooner)",
        0x0800..=0x087F => "mailbox SyncManager status: the firmware's response time (drawn from the real one's range, not the real draw)",
        0x0900..=0x09FF => "DC registers: times are the simulation's",
        0x0F00..=0x1FFF => "mailbox/process RAM: the simulated slave's reply was ready at another moment than the real one's",
        0x0300..=0x0313 => "error counters: the real segment saw link errors",
        _ => "not explained",
    };
    if matches!(cmd, Command::LRD | Command::LWR | Command::LRW) {
        return format!("{what}: process data before the slaves were in the same state");
    }
    format!("{what}: {r}")
}

fn replay(path: &std::path::Path) -> (Report, Vec<String>) {
    let p = packets(path);
    let pairs = pairs(&p);
    let (count, ids) = identities(&p, &pairs);
    let fp = addressing(&p, &pairs).1.len();
    let count = count.max(fp);
    let mut toml = String::from("seed = 1\ndrift_spread_ppm = 0\n");
    let mut standins = Vec::new();
    let mut notes = Vec::new();
    // Whether some slave's firmware draws its mailbox response times.
    let mut drawn = false;
    let ev = evidence(&p, &pairs);
    let mut overlays = Vec::new();
    for k in 0..count.max(1) {
        let product = ids.get(&k).copied();
        let (mut src, why) = source(product);
        drawn |= src.contains("mailbox_response_max_us");
        if let Some(w) = why {
            // What the capture shows of the device itself goes over the stand-in: the SII
            // words it read, and the ESC identity bytes it read.
            let (mut words, mut id_bytes) = (0, 0);
            if let (Some(read), Some(base)) = (ev.sii.get(&k), eeprom_of(&src)) {
                let path = std::env::temp_dir().join(format!(
                    "ferrocat-replay-{}-{}-{k}.bin",
                    std::process::id(),
                    path.file_stem().unwrap().to_string_lossy()
                ));
                let (img, used) = overlay_sii(&base, read);
                std::fs::write(&path, img).unwrap();
                src = src.replacen(&format!("'{}'", base.display()), &format!("'{}'", path.display()), 1);
                words = used;
                overlays.push(path);
            }
            if let Some(id) = ev.identity.get(&k).filter(|id| id.iter().any(Option::is_some)) {
                let hex: Vec<String> = id.iter().map(|b| b.map_or("..".into(), |b| format!("{b:02x}"))).collect();
                src += &format!("\nesc_identity = '{}'", hex.join(" "));
                id_bytes = id.iter().flatten().count();
            }
            standins.push((k as u16, w));
            notes.push(format!(
                "slave {k}: {w}; over it {words} of the {} SII words and {id_bytes} of the 10 ESC identity bytes the capture read",
                ev.sii.get(&k).map_or(0, BTreeMap::len)
            ));
        }
        toml += &format!("[[device]]\n{src}\n");
    }
    let cfg: SegmentConfig = toml::from_str(&toml).unwrap();
    let mut seg: Segment = cfg.build().unwrap();
    for path in overlays {
        std::fs::remove_file(path).ok();
    }
    // A capture that starts after the master configured the slaves never assigns station
    // addresses: give them the ones it uses, in ascending order.
    let (assigns, fixed) = addressing(&p, &pairs);
    if !assigns && !fixed.is_empty() {
        notes.push(format!(
            "the capture starts with the slaves already configured: station addresses {fixed:?} pre-assigned, their AL state before the capture is unknown"
        ));
        let mut t = 0;
        for (k, a) in fixed.iter().enumerate().take(seg.nodes.len()) {
            let mut f = setup_frame(Command::APWR, Address::position(k as u16, 0x0010), &a.to_le_bytes());
            t = seg.exchange(&mut f, t).unwrap_or(t) + 1000;
            // Its AL state as the capture first reads it, requested before the replay starts.
            if let Some(state) = first_al_status(&p, &pairs, *a) {
                let mut f = setup_frame(Command::FPWR, Address::Device { adp: *a, ado: 0x0120 }, &[state, 0]);
                t = seg.exchange(&mut f, t).unwrap_or(t) + 1000;
                notes.push(format!("station {a}: AL state {state:#04x} as the capture first reads it"));
            }
        }
    }
    let mut r = Report::default();
    // Until the capture writes the ECAT event mask the real one is unknown (it survives from
    // an earlier session), so IRQ fields are compared only after that write.
    let mut mask_known = false;
    // Slaves whose DL status the capture has read (by station, by position, or all at once).
    let (mut dl_fp, mut dl_ap, mut dl_all) = (BTreeSet::new(), BTreeSet::new(), false);
    let mut mailbox_sms: Vec<u16> = Vec::new();
    let t0 = p.first().map(|x| x.t_ns).unwrap_or(0);
    // A capture whose every answer came back at least 1 µs after its request has the wire's
    // times, and is replayed at its own spacing (shifted by 1 ms); TwinCAT's Windows captures
    // stamp batches of frames alike (answers "0 ns" after their requests), and are replayed
    // 1 ms after each answer at the earliest.
    let wire_timed = pairs.iter().all(|&(q, r)| p[r].t_ns >= p[q].t_ns + 1_000);
    if !wire_timed {
        notes
            .push("answers stamped as early as their requests: replayed 1 ms after each answer at the earliest".into());
    }
    let mut last_t = 0;
    for &(req, resp) in &pairs {
        let captured = p[req].t_ns - t0 + 1_000_000;
        let t = if wire_timed { captured.max(last_t + 1_000) } else { captured.max(last_t + 1_000_000) };
        let mut frame = p[req].data.clone();
        let back = seg.exchange(&mut frame, t);
        last_t = back.unwrap_or(t);
        let real = Frame::parse(&p[resp].data).unwrap().unwrap();
        let ours = Frame::parse(&frame).unwrap().unwrap();
        let sent = Frame::parse(&p[req].data).unwrap().unwrap();
        for ((a, b), q) in real.pdu.datagrams().zip(ours.pdu.datagrams()).zip(sent.pdu.datagrams()) {
            r.datagrams += 1;
            // The address as sent: position addressing comes back incremented by every slave.
            let h = q.header();
            let (adp, ado) = match h.address {
                Address::Device { adp, ado } => (adp, ado),
                Address::Logical(_) => (0xFFFF, 0),
            };
            if mask_known && back.is_some() {
                r.irq_compared += 1;
                if a.header().irq == b.header().irq {
                    r.irq_same += 1;
                } else {
                    let (ours, real) = (b.header().irq, a.header().irq);
                    let dl_unknown = !dl_all && dl_fp.len() < count && dl_ap.len() < count;
                    let why = format!(
                        "IRQ {ours:#06x} vs real {real:#06x}: {}",
                        irq_reason(ours, real, dl_unknown, &standins)
                    );
                    *r.reasons.entry(why.clone()).or_default() += 1;
                    if r.examples.len() < 8 && why.contains("not explained") {
                        r.examples.push(format!(
                            "frame {}: {} adp {adp:#06x} ado {ado:#06x}: {why}",
                            req + 1,
                            h.command
                        ));
                    }
                }
            }
            let span = ado as u32..ado as u32 + a.data().len() as u32;
            if h.command.writes() && !h.command.is_logical() && span.contains(&0x0200) {
                mask_known |= a.wkc() > 0;
            }
            if h.command.reads()
                && !h.command.is_logical()
                && a.wkc() > 0
                && (span.contains(&0x0110) || span.contains(&0x0111))
            {
                match h.command {
                    Command::BRD | Command::BRW => dl_all |= a.wkc() as usize >= count,
                    Command::FPRD | Command::FPRW => {
                        dl_fp.insert(adp);
                    }
                    _ => {
                        dl_ap.insert(adp);
                    }
                }
            }
            // SyncManagers the capture configures in mailbox mode (control byte, mode bits 10).
            if h.command.writes() && !h.command.is_logical() && a.wkc() > 0 {
                for (i, v) in a.data().iter().enumerate() {
                    let x = ado as usize + i;
                    if (0x0800..0x0840).contains(&x) && (x - 0x0800) % 8 == 4 && v & 0b11 == 0b10 {
                        mailbox_sms.push(x as u16 + 1);
                    }
                }
            }
            if h.command.reads() && !h.command.is_logical() && a.wkc() > 0 && a.wkc() == b.wkc() {
                for i in 0..a.data().len() {
                    if mailbox_sms.contains(&(ado.wrapping_add(i as u16))) {
                        r.mbx_status_compared += 1;
                        let (ours, real) = (b.data()[i], a.data()[i]);
                        if (ours ^ real) & 0x0B == 0 {
                            r.mbx_status_same += 1;
                        } else {
                            let standin = standin_reached(h.command, adp, &standins).is_some();
                            let why = format!(
                                "mailbox SM status {ours:#04x} vs real {real:#04x}: {}",
                                mailbox_status_reason(ours, real, standin, drawn)
                            );
                            *r.reasons.entry(why).or_default() += 1;
                        }
                    }
                }
            }
            if h.command.reads() && !h.command.is_logical() && ado >= 0x1000 {
                for (data, wkc, list) in [(a.data(), a.wkc(), &mut r.eoe_real), (b.data(), b.wkc(), &mut r.eoe_ours)] {
                    if let Some(m) = eoe_message(data, wkc) {
                        if list.last() != Some(&m) {
                            list.push(m);
                        }
                    }
                }
            }
            // Every byte of the response: its data and its working counter.
            let exempt_bytes = if h.command.is_logical() {
                0
            } else {
                (0..a.data().len()).filter(|&i| exempt(ado.wrapping_add(i as u16)).is_some()).count()
            };
            r.bytes += a.data().len() + 2 - exempt_bytes;
            r.bytes_exempt += exempt_bytes;
            let differ = |r: &mut Report, n: usize, why: String, example: String| {
                let e = r.byte_diffs.entry(why).or_insert((0, example));
                e.0 += n;
            };
            if a.wkc() != b.wkc() || back.is_none() {
                let why = reason(h.command, adp, ado, &standins, "working counter");
                differ(&mut r, 2, why, format!("frame {}: WKC {} vs real {}", req + 1, b.wkc(), a.wkc()));
            }
            for i in 0..a.data().len().min(b.data().len()) {
                let reg = ado.wrapping_add(i as u16);
                if a.data()[i] == b.data()[i] || (!h.command.is_logical() && exempt(reg).is_some()) {
                    continue;
                }
                let why = reason(h.command, adp, reg, &standins, "data");
                let ex = format!(
                    "frame {}: {} adp {adp:#06x} ado {ado:#06x} byte {i}: ours {:02x?} real {:02x?}",
                    req + 1,
                    h.command,
                    &b.data()[..b.data().len().min(16)],
                    &a.data()[..a.data().len().min(16)]
                );
                differ(&mut r, 1, why, ex);
            }
            if a.wkc() == b.wkc() && back.is_some() {
                r.wkc_same += 1;
            } else {
                let why = reason(h.command, adp, ado, &standins, &format!("WKC {} vs real {}", b.wkc(), a.wkc()));
                *r.reasons.entry(why.clone()).or_default() += 1;
                if r.examples.len() < 8 && why.contains("not explained") {
                    r.examples.push(format!("frame {}: {} adp {adp:#06x} ado {ado:#06x}: {why}", req + 1, h.command));
                }
            }
            if h.command.reads() && !h.command.is_logical() && a.wkc() > 0 && a.wkc() == b.wkc() {
                let idx: Vec<usize> = (0..a.data().len()).filter(|&i| compared(ado, i)).collect();
                if !idx.is_empty() {
                    r.compared_reads += 1;
                    if idx.iter().all(|&i| a.data()[i] == b.data()[i]) {
                        r.data_same += 1;
                    } else {
                        let why = reason(h.command, adp, ado, &standins, "data");
                        let why = if why.contains("not explained") {
                            format!("data of {ado:#06x} differs: not explained")
                        } else {
                            why
                        };
                        *r.reasons.entry(why.clone()).or_default() += 1;
                        if r.examples.len() < 8 && why.contains("not explained") {
                            r.examples.push(format!(
                                "frame {}: {} adp {adp:#06x} ado {ado:#06x}: ours {:02x?} real {:02x?}",
                                req + 1,
                                h.command,
                                b.data(),
                                a.data()
                            ));
                        }
                    }
                }
            }
        }
    }
    (r, notes)
}

/// Reasons that come from the moment a real firmware or EEPROM acted, which a model draws or
/// fits but cannot know for one capture.
const TIMED: [&str; 4] = ["response time", "busy timing", "at another moment", "ready at another moment"];

#[test]
fn needs_shared_replay_every_capture() {
    let mut failures = Vec::new();
    let mut summary = Vec::new();
    for path in ferrocat_testdata::shared_files("captures", ".pcapng") {
        let name = path.file_name().unwrap().to_string_lossy().to_string();
        let (r, notes) = replay(&path);
        let wkc = 100.0 * r.wkc_same as f64 / r.datagrams.max(1) as f64;
        let data = 100.0 * r.data_same as f64 / r.compared_reads.max(1) as f64;
        println!(
            "{name}: {} datagrams, WKC as real {wkc:.2} %, identity/SII/config reads identical {}/{} ({data:.1} %), \
             IRQ as real {}/{} after the event mask was written, mailbox SM status as real {}/{}",
            r.datagrams,
            r.data_same,
            r.compared_reads,
            r.irq_same,
            r.irq_compared,
            r.mbx_status_same,
            r.mbx_status_compared
        );
        if !r.eoe_real.is_empty() {
            let same = r.eoe_real.iter().zip(&r.eoe_ours).filter(|(a, b)| a == b).count();
            println!(
                "    EoE messages as real (mailbox counter and service data): {same}/{} (ours: {})",
                r.eoe_real.len(),
                r.eoe_ours.len()
            );
            if same != r.eoe_real.len() || r.eoe_ours.len() != r.eoe_real.len() {
                for (k, (a, b)) in r.eoe_real.iter().zip(&r.eoe_ours).enumerate().filter(|(_, (a, b))| a != b) {
                    println!("    EoE message {k}: ours {b:02x?}\n        real {a:02x?}");
                }
                failures.push(format!("{name}: EoE messages differ from the real device's"));
            }
        }
        for n in &notes {
            println!("    {n}");
        }
        let differing: usize = r.byte_diffs.values().map(|v| v.0).sum();
        let agree = 100.0 * (r.bytes - differing) as f64 / r.bytes.max(1) as f64;
        println!(
            "    bytes: {} compared (data and working counters), {} exempt; {agree:.2} % as real ({differing} differ)",
            r.bytes, r.bytes_exempt
        );
        for (why, (n, ex)) in &r.byte_diffs {
            println!("    {n:6} byte(s): {why}\n           e.g. {ex}");
        }
        for (why, n) in &r.reasons {
            println!("    {n:6} × {why}");
        }
        for e in &r.examples {
            println!("    e.g. {e}");
        }
        // Every capture's working counters, stand-ins included (they are given what their
        // captures show of the real devices' ESCs); captures whose devices the shared data fully
        // describes must also have every mismatch explained.
        if r.datagrams > 0 && wkc < 99.0 {
            failures.push(format!("{name}: WKC as real on {wkc:.2} % of datagrams"));
        }
        if notes.is_empty() && r.datagrams > 0 {
            let unexplained: usize =
                r.reasons.iter().filter(|(k, _)| k.contains("not explained")).map(|(_, v)| v).sum();
            if unexplained > 0 {
                failures.push(format!("{name}: {unexplained} unexplained mismatches"));
            }
        }
        // Every byte that differs has a named reason; in a capture of devices the shared data
        // describes whole (no stand-in), only the moments real firmware and EEPROMs took may
        // differ: every other non-exempt byte is as real.
        for (why, (n, ex)) in &r.byte_diffs {
            if why.contains("not explained") {
                failures.push(format!("{name}: {n} byte(s) differ for no named reason, e.g. {ex}"));
            } else if !notes.iter().any(|n| n.contains("stands in")) && !TIMED.iter().any(|t| why.contains(t)) {
                failures
                    .push(format!("{name}: {n} byte(s) differ on devices the shared data describes: {why}; e.g. {ex}"));
            }
        }
        summary.push(format!(
            "| {name} | {} | {wkc:.2} % | {} | {} | {:.2} % |",
            r.datagrams,
            r.bytes,
            r.bytes_exempt,
            100.0 * (r.bytes - r.byte_diffs.values().map(|v| v.0).sum::<usize>()) as f64 / r.bytes.max(1) as f64
        ));
    }
    println!(
        "\n| capture | datagrams | WKC as real | bytes compared | exempt | bytes as real |\n|---|---|---|---|---|---|"
    );
    for line in &summary {
        println!("{line}");
    }
    assert!(failures.is_empty(), "{failures:#?}");
}
