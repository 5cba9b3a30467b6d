//! Round trips of every plain representation, and no panic on arbitrary input.
use ferrocat_wire::coe::{self, AbortCode, CoeService, Emergency, InfoHeader, InfoOpcode, Sdo, SdoInfo};
use ferrocat_wire::mailbox::{Mailbox, MailboxHeader, MailboxType};
use ferrocat_wire::register::{Fmmu, SyncManager, SystemTimeDifference};
use ferrocat_wire::sii::{CategoryRepr, DcOpMode, General, Pdo, PdoEntry, SiiHeader, SiiImage, SiiInfo, SmEntry};
use ferrocat_wire::{Address, Command, DatagramHeader, EthernetRepr, Frame, FrameWriter};
use proptest::prelude::*;

fn header() -> impl Strategy<Value = DatagramHeader> {
    (0u8..=15, any::<u8>(), any::<u32>(), 0u16..=64, 0u8..8, any::<bool>(), any::<u16>()).prop_map(
        |(cmd, index, raw, len, reserved, circulating, irq)| {
            let command = Command(cmd);
            DatagramHeader {
                command,
                index,
                address: Address::from_raw(command, raw),
                len,
                reserved,
                circulating,
                more: false,
                irq,
            }
        },
    )
}

proptest! {
    #[test]
    fn frames_round_trip(
        dgs in proptest::collection::vec((header(), any::<u16>(), any::<u8>()), 1..8),
        vlan in proptest::option::of(any::<u16>()),
        src in any::<[u8; 6]>(),
    ) {
        let eth = EthernetRepr { dst: [0xFF; 6], src, vlan_tci: vlan, ethertype: 0 };
        let mut buf = [0u8; 1600];
        let mut w = FrameWriter::new(&mut buf, &eth).unwrap();
        for (h, wkc, fill) in &dgs {
            w.push_chained(h, &vec![*fill; h.len as usize], *wkc).unwrap();
        }
        let n = w.finish().unwrap();
        prop_assert!(n >= 60);
        let f = Frame::parse(&buf[..n]).unwrap().unwrap();
        prop_assert_eq!(f.ethernet.vlan_tci, vlan);
        let got: Vec<_> = f.pdu.datagrams().collect();
        prop_assert_eq!(got.len(), dgs.len());
        for (i, (d, (h, wkc, fill))) in got.iter().zip(&dgs).enumerate() {
            let want = DatagramHeader { more: i + 1 < dgs.len(), ..*h };
            prop_assert_eq!(*d.header(), want);
            prop_assert_eq!(d.wkc(), *wkc);
            prop_assert!(d.data().iter().all(|b| b == fill));
        }
        let mut again = [0u8; 1600];
        let m = f.emit(&mut again).unwrap();
        prop_assert_eq!(&again[..m], &buf[..n]);
    }

    #[test]
    fn frame_parser_never_panics(bytes in proptest::collection::vec(any::<u8>(), 0..200), ecat in any::<bool>()) {
        let mut b = bytes;
        if ecat && b.len() > 14 {
            b[12] = 0x88;
            b[13] = 0xA4;
        }
        if let Ok(Some(f)) = Frame::parse(&b) {
            let n = f.pdu.datagrams().count();
            prop_assert_eq!(n, f.pdu.datagram_count());
            let mut out = vec![0u8; b.len()];
            prop_assert_eq!(f.emit(&mut out).unwrap(), b.len());
            prop_assert_eq!(out, b);
        }
    }

    #[test]
    fn registers_round_trip(b16 in any::<[u8; 16]>(), v in any::<i64>()) {
        let f = Fmmu::parse(&b16).unwrap();
        prop_assert_eq!(Fmmu::parse(&f.to_bytes()).unwrap(), f);
        let s = SyncManager::parse(&b16[..8]).unwrap();
        prop_assert_eq!(s.to_bytes(), <[u8; 8]>::try_from(&b16[..8]).unwrap());
        let d = SystemTimeDifference::from_ns(v);
        prop_assert_eq!(d.as_ns(), v.clamp(-0x7FFF_FFFF, 0x7FFF_FFFF));
    }

    #[test]
    fn mailbox_and_coe_parsers_never_panic(bytes in proptest::collection::vec(any::<u8>(), 0..80)) {
        if let Ok(m) = Mailbox::parse(&bytes) {
            prop_assert_eq!(MailboxHeader::parse(&m.header.to_bytes()).unwrap(), m.header);
            if let Ok((h, msg)) = coe::parse(m.payload) {
                let mut out = [0u8; 128];
                match msg {
                    coe::CoeMessage::Sdo(s) => {
                        let n = s.emit(&mut out).unwrap();
                        prop_assert_eq!(Sdo::parse(h.service, &out[..n]).unwrap(), s);
                    }
                    coe::CoeMessage::Information(i) => {
                        let n = i.emit(&mut out).unwrap();
                        prop_assert_eq!(SdoInfo::parse(&out[..n]).unwrap(), i);
                    }
                    coe::CoeMessage::Emergency(e) => prop_assert_eq!(Emergency::parse(&e.to_bytes()).unwrap(), e),
                    coe::CoeMessage::Other(_) => {}
                }
            }
        }
    }

    #[test]
    fn sdo_round_trips(
        index in any::<u16>(), sub in any::<u8>(), ca in any::<bool>(), size in 1u8..=4, four in any::<[u8; 4]>(),
        data in proptest::collection::vec(any::<u8>(), 0..40), toggle in any::<bool>(), last in any::<bool>(),
        code in any::<u32>(), unused in 0u8..=7,
    ) {
        let mut seg = data.clone();
        seg.resize(seg.len().max(7), 0);
        let unused = if seg.len() == 7 { unused } else { 0 };
        let frames = [
            Sdo::DownloadExpeditedRequest { index, subindex: sub, complete_access: ca, size: Some(size), data: four },
            Sdo::UploadExpeditedResponse { index, subindex: sub, complete_access: ca, size: None, data: four },
            Sdo::DownloadNormalRequest { index, subindex: sub, complete_access: ca, complete_size: code, data: &data },
            Sdo::UploadNormalResponse { index, subindex: sub, complete_access: ca, complete_size: code, data: &data },
            Sdo::UploadRequest { index, subindex: sub, complete_access: ca, reserved: four },
            Sdo::DownloadResponse { index, subindex: sub, complete_access: ca, reserved: four },
            Sdo::DownloadSegmentRequest { toggle, last, unused, segment: &seg },
            Sdo::UploadSegmentResponse { toggle, last, unused, segment: &seg },
            Sdo::Abort { index, subindex: sub, code: AbortCode(code) },
        ];
        for s in frames {
            let mut mbx = [0u8; 80];
            let n = s.emit(&mut mbx[8..]).unwrap();
            MailboxHeader::new(MailboxType::COE, (2 + n) as u16, 1).emit(&mut mbx).unwrap();
            coe::CoeHeader::new(s.service()).emit(&mut mbx[6..]).unwrap();
            let m = Mailbox::parse(&mbx).unwrap();
            let (h, msg) = coe::parse(m.payload).unwrap();
            prop_assert_eq!(h.service, s.service());
            prop_assert_eq!(msg, coe::CoeMessage::Sdo(s));
        }
        let info = SdoInfo::EntryDescriptionResponse {
            header: InfoHeader { opcode: InfoOpcode::GET_ENTRY_DESCRIPTION_RESPONSE, incomplete: toggle, reserved: 0, fragments_left: index },
            index, subindex: sub, value_info: size, data_type: 7, bit_length: 32, object_access: 7, rest: &data,
        };
        let mut out = [0u8; 80];
        let n = info.emit(&mut out).unwrap();
        prop_assert_eq!(SdoInfo::parse(&out[..n]).unwrap(), info);
        let _ = CoeService::SDO_INFORMATION;
    }

    #[test]
    fn sii_descriptions_round_trip(
        ids in any::<[u32; 4]>(),
        strings in proptest::collection::vec("[ -~]{0,20}", 0..6),
        ebus in any::<i16>(),
        sms in proptest::collection::vec(any::<[u8; 8]>(), 0..5),
        pdos in proptest::collection::vec((any::<u16>(), proptest::collection::vec(any::<[u8; 8]>(), 0..4)), 0..4),
        dc in proptest::collection::vec(any::<[u8; 24]>(), 0..3),
        fmmus in proptest::collection::vec(0u8..=3, 0..5),
    ) {
        let mut info = SiiInfo {
            header: SiiHeader { vendor_id: ids[0], product_code: ids[1], revision: ids[2], serial: ids[3], ..Default::default() }.with_checksum(),
            categories: vec![],
        };
        for s in &strings {
            info.intern(s);
        }
        info.push(CategoryRepr::General(General { current_on_ebus_ma: ebus, name_idx: 1, ..Default::default() }));
        info.push(CategoryRepr::Fmmu(fmmus));
        info.push(CategoryRepr::SyncManagers(sms.iter().map(|b| SmEntry::parse(b).unwrap()).collect()));
        info.push(CategoryRepr::TxPdos(pdos.iter().map(|(i, es)| Pdo {
            index: *i, sync_manager: 3, synchronization: 0, name_idx: 0, flags: 0,
            entries: es.iter().map(|b| PdoEntry::parse(b).unwrap()).collect(),
        }).collect()));
        info.push(CategoryRepr::Dc(dc.iter().map(|b| DcOpMode::parse(b).unwrap()).collect()));
        let img = info.to_image();
        SiiImage::parse(&img).unwrap().check_crc().unwrap();
        let back = SiiInfo::from_image(&img).unwrap();
        prop_assert_eq!(back.header, info.header);
        let reprs = |i: &SiiInfo| i.categories.iter().map(|c| c.repr.clone()).collect::<Vec<_>>();
        prop_assert_eq!(reprs(&back), reprs(&info));
        prop_assert_eq!(back.to_image(), img);
    }

    #[test]
    fn sii_parsers_never_panic(bytes in proptest::collection::vec(any::<u8>(), 0..400)) {
        if let Ok(info) = SiiInfo::from_image(&bytes) {
            // Everything before the end marker re-encodes identically (the input may lack one).
            let img = info.to_image();
            let body = img.len() - 2;
            prop_assert_eq!(&bytes[..body], &img[..body]);
        }
        if let Ok(img) = SiiImage::parse(&bytes) {
            let _ = img.strings();
            let _ = img.general();
            for c in img.categories() {
                let _ = c;
            }
        }
        let _ = ferrocat_wire::sii::dump::parse_dump(&bytes);
    }
}

proptest! {
    /// Any frame cut for any mailbox comes back whole, and a fragment 0 always starts afresh.
    #[test]
    fn eoe_fragments_reassemble(
        frame in proptest::collection::vec(any::<u8>(), 1..=ferrocat_wire::eoe::MAX_FRAME_LEN),
        max_len in 36usize..1500,
        frame_number in 0u8..16,
    ) {
        use ferrocat_wire::eoe::{fragments, Reassembler};
        let mut r = Reassembler::default();
        let parts: Vec<_> = fragments(&frame, max_len, frame_number).unwrap().collect();
        prop_assert!(parts.iter().all(|(_, d)| d.len() + 4 <= max_len));
        let (last, rest) = parts.split_last().unwrap();
        for (h, d) in rest {
            prop_assert_eq!(r.push(h, d), Ok(None));
        }
        let got = r.push(&last.0, last.1).unwrap().unwrap();
        prop_assert_eq!(got.frame, &frame[..]);
    }

    #[test]
    fn eoe_parsers_never_panic(bytes in proptest::collection::vec(any::<u8>(), 0..120), pushes in 1usize..6) {
        use ferrocat_wire::eoe::{EoeHeader, IpParameters, Reassembler};
        let mut r = Reassembler::default();
        for k in 0..pushes {
            let b = &bytes[(k * 7).min(bytes.len())..];
            if let Ok(h) = EoeHeader::parse(b) {
                let _ = r.push(&h, &b[4..]);
                let _ = IpParameters::parse(&b[4..]);
            }
        }
        let _ = ferrocat_wire::inet::ArpRepr::parse(&bytes);
        let _ = ferrocat_wire::inet::IcmpEcho::parse(&bytes);
    }

    #[test]
    fn eoe_ip_parameters_round_trip(
        mac in proptest::option::of(any::<[u8; 6]>()),
        ip in proptest::option::of(any::<[u8; 4]>()),
        mask in proptest::option::of(any::<[u8; 4]>()),
        gw in proptest::option::of(any::<[u8; 4]>()),
        dns in proptest::option::of(any::<[u8; 4]>()),
        name in proptest::option::of(any::<[u8; 32]>()),
    ) {
        use ferrocat_wire::eoe::{IpParameters, IP_PARAMETERS_LEN};
        let p = IpParameters { mac, ip, subnet_mask: mask, gateway: gw, dns_server: dns, dns_name: name };
        let mut b = [0u8; IP_PARAMETERS_LEN];
        p.emit(&mut b).unwrap();
        prop_assert_eq!(IpParameters::parse(&b).unwrap(), p);
    }
}
