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
        Some(0x03EC_3052) => (
            "builtin = 'EL1004'".into(),
            Some("EL1004: no EEPROM dump in shared data (built-in description stands in)"),
        ),
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
        0x0500..=0x050F => "SII interface: busy timing differs (700 µs per read here; a Windows capture's times are not the wire's)",
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
    for k in 0..count.max(1) {
        let product = ids.get(&k).copied();
        let (src, why) = source(product);
        drawn |= src.contains("mailbox_response_max_us");
        if let Some(w) = why {
            standins.push((k as u16, w));
            notes.push(format!("slave {k}: {w}"));
        }
        toml += &format!("[[device]]\n{src}\n");
    }
    let cfg: SegmentConfig = toml::from_str(&toml).unwrap();
    let mut seg: Segment = cfg.build().unwrap();
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

#[test]
fn needs_shared_replay_every_capture() {
    let mut failures = Vec::new();
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
    }
    assert!(failures.is_empty(), "{failures:#?}");
}
