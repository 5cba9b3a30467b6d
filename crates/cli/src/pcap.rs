//! `ferrocat pcap`: datagrams of a capture, as text or JSON lines.
use std::path::Path;
use std::process::ExitCode;

use anyhow::Context;
use ferrocat_capture::{for_each_packet, LINKTYPE_ETHERNET};
use ferrocat_wire::{Address, DatagramHeader, EthernetRepr, Frame};
use serde_json::json;

use crate::outln;

/// One datagram as the capture holds it: its data, and its working counter unless the
/// capture's snap length cut the datagram short.
struct Shown<'a> {
    header: DatagramHeader,
    data: &'a [u8],
    wkc: Option<u16>,
}

pub fn run(path: &Path, json: bool) -> anyhow::Result<ExitCode> {
    // Refused on its first bytes: an endless or huge file that is no capture is not read.
    let first = ferrocat_segment::files::first_bytes(path, 4).with_context(|| format!("reading {}", path.display()))?;
    if !ferrocat_capture::begins_like_a_capture(&first) {
        anyhow::bail!("{}: not a pcap or pcapng capture (it begins with {first:02x?})", path.display());
    }
    let bytes = ferrocat_segment::files::read_capture(path).with_context(|| format!("reading {}", path.display()))?;
    let (mut bad, mut cut) = (0usize, 0usize);
    for_each_packet(&bytes, |p| {
        // Frames of other link types, runts without an Ethernet header and non-EtherCAT
        // traffic are skipped: they are not EtherCAT.
        if p.link_type != LINKTYPE_ETHERNET || EthernetRepr::parse(&p.data).is_err() {
            return Ok(());
        }
        let shown: Vec<Shown<'_>> = match Frame::parse(&p.data) {
            Ok(Some(f)) => {
                f.pdu.datagrams().map(|d| Shown { header: *d.header(), data: d.data(), wkc: Some(d.wkc()) }).collect()
            }
            Ok(None) => return Ok(()),
            Err(_) if p.is_truncated() => {
                cut += 1;
                match cut_datagrams(&p.data) {
                    Some(v) => v,
                    None => return Ok(()),
                }
            }
            Err(e) => {
                eprintln!("{}: frame {}: {e}", path.display(), p.number);
                bad += 1;
                return Ok(());
            }
        };
        for (i, d) in shown.iter().enumerate() {
            let h = &d.header;
            if json {
                let mut o = json!({
                    "frame": p.number,
                    "datagram": i,
                    "time_ns": p.timestamp.as_nanos() as u64,
                    "cmd": h.command.0,
                    "cmd_name": h.command.name(),
                    "idx": h.index,
                    "len": h.len,
                    "circulating": h.circulating,
                    "more": h.more,
                    "irq": h.irq,
                    "wkc": d.wkc,
                    "data": hex(d.data),
                });
                match h.address {
                    Address::Device { adp, ado } => {
                        o["adp"] = adp.into();
                        o["ado"] = ado.into();
                    }
                    Address::Logical(a) => o["logical"] = a.into(),
                }
                if d.wkc.is_none() {
                    o["truncated"] = true.into();
                }
                outln!("{o}");
            } else {
                let addr = match h.address {
                    Address::Device { adp, ado } => format!("adp={adp:#06x} ado={ado:#06x}"),
                    Address::Logical(a) => format!("logical={a:#010x}"),
                };
                let wkc = match d.wkc {
                    Some(w) => w.to_string(),
                    None => format!("? (truncated: {} of {} data bytes captured)", d.data.len(), h.len),
                };
                outln!(
                    "frame {:6} #{i} {:5} idx={:#04x} {addr:30} len={:4} C={} M={} irq={:#06x} wkc={wkc}",
                    p.number,
                    h.command.to_string(),
                    h.index,
                    h.len,
                    h.circulating as u8,
                    h.more as u8,
                    h.irq,
                );
            }
        }
        Ok(())
    })
    .with_context(|| format!("reading {}", path.display()))?;
    if cut > 0 {
        eprintln!(
            "{}: {cut} EtherCAT frame(s) cut short by the capture's snap length: their last datagram is marked truncated",
            path.display()
        );
    }
    if bad > 0 {
        eprintln!("{}: {bad} EtherCAT frame(s) could not be decoded", path.display());
        return Ok(ExitCode::FAILURE);
    }
    Ok(ExitCode::SUCCESS)
}

/// The datagrams of an EtherCAT frame (Ethernet encapsulation) that a snap length cut: each
/// whole one, then the one the cut fell in with the data bytes that were captured and no
/// working counter. `None` when not even the first datagram's header survived.
fn cut_datagrams(buf: &[u8]) -> Option<Vec<Shown<'_>>> {
    let (eth, off) = EthernetRepr::parse(buf).ok()?;
    if eth.ethertype != ferrocat_wire::ethernet::ETHERTYPE_ETHERCAT {
        return None;
    }
    let mut at = off + 2;
    let mut out = Vec::new();
    while let Ok(header) = DatagramHeader::parse(buf.get(at..)?) {
        let start = at + 10;
        let end = start + header.len as usize;
        let data = &buf[start.min(buf.len())..end.min(buf.len())];
        let wkc = buf.get(end..end + 2).map(|w| u16::from_le_bytes([w[0], w[1]]));
        let more = header.more;
        out.push(Shown { header, data, wkc });
        if wkc.is_none() || !more {
            break;
        }
        at = end + 2;
    }
    (!out.is_empty()).then_some(out)
}

pub(crate) fn hex(b: &[u8]) -> String {
    b.iter().map(|x| format!("{x:02x}")).collect()
}
