#![no_main]
//! Any bytes as a pcap or pcapng file. The first byte may put a valid file header in front
//! (pcapng section + interface blocks, or a pcap header), so that packet records get fuzzed.
use std::time::Duration;

use ferrocat_capture::{CaptureWriter, Format};
use libfuzzer_sys::fuzz_target;

fuzz_target!(|data: &[u8]| {
    let Some((&sel, rest)) = data.split_first() else { return };
    let mut file = match sel % 3 {
        0 => Vec::new(),
        1 => CaptureWriter::new(Vec::new(), Format::PcapNg).unwrap().into_inner(),
        _ => CaptureWriter::new(Vec::new(), Format::Pcap).unwrap().into_inner(),
    };
    file.extend_from_slice(rest);
    let _ = ferrocat_capture::for_each_packet(&file, |p| {
        let _ = ferrocat_wire::Frame::parse(&p.data);
        Ok(())
    });
    let _ = Duration::ZERO;
});
