//! Every frame of every real capture in ../shared/captures decodes and re-encodes byte for byte.
use ferrocat_capture::{for_each_packet, LINKTYPE_ETHERNET};
use ferrocat_wire::{DatagramHeader, Frame, FrameWriter};

#[test]
fn needs_shared_every_capture_frame_round_trips() {
    let files = ferrocat_testdata::shared_files("captures", ".pcapng");
    assert!(files.len() >= 18, "expected the 18 shared captures, found {}", files.len());
    let (mut all_frames, mut all_datagrams) = (0, 0);
    for path in files {
        let bytes = std::fs::read(&path).unwrap();
        let (mut frames, mut datagrams, mut other, mut non_dlpdu) = (0usize, 0usize, 0usize, 0usize);
        for_each_packet(&bytes, |p| {
            assert_eq!(p.link_type, LINKTYPE_ETHERNET);
            assert!(!p.is_truncated(), "{}: frame {} truncated by snaplen", path.display(), p.number);
            // Runts too short for an Ethernet header (there are some) cannot be EtherCAT.
            if ferrocat_wire::EthernetRepr::parse(&p.data).is_err() {
                other += 1;
                return Ok(());
            }
            let frame = match Frame::parse(&p.data) {
                Ok(Some(f)) => f,
                Ok(None) => {
                    other += 1;
                    return Ok(());
                }
                Err(e) => panic!("{} frame {}: {e}", path.display(), p.number),
            };
            // Re-encode from the plain representations, not by copying the PDU.
            let reprs: Vec<(DatagramHeader, &[u8], u16)> =
                frame.pdu.datagrams().map(|d| (*d.header(), d.data(), d.wkc())).collect();
            let mut out = vec![0u8; p.data.len() + 64];
            let mut w = FrameWriter::with_encapsulation(&mut out, &frame.ethernet, &frame.encapsulation).unwrap();
            for (h, data, wkc) in &reprs {
                w.push(h, data, *wkc).unwrap();
            }
            if frame.pdu.header.frame_type != ferrocat_wire::frame::TYPE_DLPDU {
                // TwinCAT sends a few frames of other EtherCAT types (7, over UDP): opaque bodies.
                w.push_body(frame.pdu.body()).unwrap();
                non_dlpdu += 1;
            }
            let n = w.finish_exact(frame.pdu.header, frame.trailer).unwrap();
            assert_eq!(&out[..n], &p.data[..], "{} frame {} re-encodes differently", path.display(), p.number);
            frames += 1;
            datagrams += reprs.len();
            Ok(())
        })
        .unwrap();
        println!(
            "{:45} {frames:6} EtherCAT frames ({non_dlpdu} not DLPDU) {datagrams:7} datagrams {other:6} other frames",
            path.file_name().unwrap().to_string_lossy()
        );
        assert!(frames > 0, "{}: no EtherCAT frames", path.display());
        all_frames += frames;
        all_datagrams += datagrams;
    }
    println!("total: {all_frames} frames, {all_datagrams} datagrams");
}
