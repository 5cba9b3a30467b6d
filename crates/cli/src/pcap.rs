//! `ferrocat pcap`: datagrams of a capture, as text or JSON lines.
use std::path::Path;
use std::process::ExitCode;

use anyhow::Context;
use ferrocat_capture::{for_each_packet, LINKTYPE_ETHERNET};
use ferrocat_wire::{Address, EthernetRepr, Frame};
use serde_json::json;

use crate::outln;

pub fn run(path: &Path, json: bool) -> anyhow::Result<ExitCode> {
    let bytes = ferrocat_segment::files::read_capture(path).with_context(|| format!("reading {}", path.display()))?;
    let mut bad = 0usize;
    for_each_packet(&bytes, |p| {
        // Frames of other link types, runts without an Ethernet header and non-EtherCAT
        // traffic are skipped: they are not EtherCAT.
        if p.link_type != LINKTYPE_ETHERNET || EthernetRepr::parse(&p.data).is_err() {
            return Ok(());
        }
        let frame = match Frame::parse(&p.data) {
            Ok(Some(f)) => f,
            Ok(None) => return Ok(()),
            Err(e) => {
                let cut = if p.is_truncated() { " (frame truncated by the capture's snap length)" } else { "" };
                eprintln!("{}: frame {}: {e}{cut}", path.display(), p.number);
                bad += 1;
                return Ok(());
            }
        };
        for (i, d) in frame.pdu.datagrams().enumerate() {
            let h = d.header();
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
                    "wkc": d.wkc(),
                    "data": hex(d.data()),
                });
                match h.address {
                    Address::Device { adp, ado } => {
                        o["adp"] = adp.into();
                        o["ado"] = ado.into();
                    }
                    Address::Logical(a) => o["logical"] = a.into(),
                }
                outln!("{o}");
            } else {
                let addr = match h.address {
                    Address::Device { adp, ado } => format!("adp={adp:#06x} ado={ado:#06x}"),
                    Address::Logical(a) => format!("logical={a:#010x}"),
                };
                outln!(
                    "frame {:6} #{i} {:5} idx={:#04x} {addr:30} len={:4} C={} M={} irq={:#06x} wkc={}",
                    p.number,
                    h.command.to_string(),
                    h.index,
                    h.len,
                    h.circulating as u8,
                    h.more as u8,
                    h.irq,
                    d.wkc()
                );
            }
        }
        Ok(())
    })
    .with_context(|| format!("reading {}", path.display()))?;
    if bad > 0 {
        eprintln!("{}: {bad} EtherCAT frame(s) could not be decoded", path.display());
        return Ok(ExitCode::FAILURE);
    }
    Ok(ExitCode::SUCCESS)
}

pub(crate) fn hex(b: &[u8]) -> String {
    b.iter().map(|x| format!("{x:02x}")).collect()
}
