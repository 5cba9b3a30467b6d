//! EoE between the master's client and the simulated drive's endpoint, in virtual time: IP
//! parameters, frames in fragments both ways, ping, and frames met during other exchanges.
use ferrocat_esc::{Cia402Drive, EoeServer};
use ferrocat_master::{EoePing, Master};
use ferrocat_segment::SegmentConfig;
use ferrocat_segment::{HostModel, VirtualIo};
use ferrocat_wire::eoe::IpParameters;
use ferrocat_wire::ethernet::{EthernetRepr, BROADCAST};
use ferrocat_wire::inet::{ArpRepr, ARP_REPLY, ARP_REQUEST, ETHERTYPE_ARP};

const DRIVE: u16 = 1;
const DRIVE_MAC: [u8; 6] = [0x02, 0x00, 0x00, 0x00, 0x03, 0xE9];
const DRIVE_IP: [u8; 4] = [192, 168, 7, 2];
const MASTER_MAC: [u8; 6] = [0x02, 0x00, 0x00, 0x00, 0x00, 0x01];
const MASTER_IP: [u8; 4] = [192, 168, 7, 1];

/// EK1100 and the built-in servo (whose SII names EoE, 128-byte mailboxes), in PREOP.
fn master() -> Master<VirtualIo> {
    let toml = "seed = 5\n[[device]]\nbuiltin = 'EK1100'\n[[device]]\nbuiltin = 'SERVO'\n";
    let cfg: SegmentConfig = toml::from_str(toml).unwrap();
    let mut m = Master::new(VirtualIo::new(cfg.build().unwrap(), HostModel::pc_rt(), 5));
    m.states().scan().unwrap();
    m.states().configure().unwrap();
    m
}

fn endpoint(m: &Master<VirtualIo>) -> &EoeServer {
    let app = m.io().seg.nodes[DRIVE as usize].esc.app();
    app.as_any().downcast_ref::<Cia402Drive>().unwrap().coe.eoe.as_ref().expect("the drive serves EoE")
}

fn addressed(m: &mut Master<VirtualIo>) {
    let params = IpParameters {
        mac: Some(DRIVE_MAC),
        ip: Some(DRIVE_IP),
        subnet_mask: Some([255, 255, 255, 0]),
        gateway: Some(MASTER_IP),
        dns_name: Some(IpParameters::dns_name_field(b"axis-1").unwrap()),
        ..Default::default()
    };
    m.acyclic().eoe().set_ip(DRIVE, &params).unwrap();
}

fn ping() -> EoePing {
    EoePing { from_mac: MASTER_MAC, from_ip: MASTER_IP, to_mac: DRIVE_MAC, to_ip: DRIVE_IP }
}

fn arp_request(target_ip: [u8; 4]) -> Vec<u8> {
    let mut f = vec![0u8; 42];
    EthernetRepr { dst: BROADCAST, src: MASTER_MAC, vlan_tci: None, ethertype: ETHERTYPE_ARP }.emit(&mut f).unwrap();
    ArpRepr { operation: ARP_REQUEST, sender_mac: MASTER_MAC, sender_ip: MASTER_IP, target_mac: [0; 6], target_ip }
        .emit(&mut f[14..])
        .unwrap();
    f
}

#[test]
fn set_ip_is_read_back_and_announced() {
    let mut m = master();
    addressed(&mut m);
    let p = m.acyclic().eoe().get_ip(DRIVE).unwrap();
    assert_eq!(
        (p.mac, p.ip, p.subnet_mask, p.gateway),
        (Some(DRIVE_MAC), Some(DRIVE_IP), Some([255, 255, 255, 0]), Some(MASTER_IP))
    );
    assert_eq!(p.dns_name_bytes(), Some(&b"axis-1"[..]));
    assert_eq!(p.dns_server, None);
    // The announcement came before the Get IP response; it waited in the inbox (a timeout of
    // any size: it is there at once).
    let f = m.acyclic().eoe().receive(DRIVE, u64::MAX).unwrap().expect("an ARP announcement");
    let (eth, n) = EthernetRepr::parse(&f).unwrap();
    assert_eq!((eth.dst, eth.src, eth.ethertype), (BROADCAST, DRIVE_MAC, ETHERTYPE_ARP));
    let a = ArpRepr::parse(&f[n..]).unwrap();
    assert_eq!((a.operation, a.sender_ip, a.target_ip, a.target_mac), (ARP_REQUEST, DRIVE_IP, DRIVE_IP, [0; 6]));
    assert_eq!(m.acyclic().eoe().receive(DRIVE, 1_000_000).unwrap(), None);
}

#[test]
fn pings_of_every_size_come_back_whole() {
    let mut m = master();
    addressed(&mut m);
    // Up to a full 1 514-byte Ethernet frame: 16 fragments of 96 bytes through the 128-byte
    // mailbox each way.
    for (seq, len) in [0usize, 1, 56, 95, 96, 97, 1000, 1472].into_iter().enumerate() {
        let rtt = m.acyclic().eoe().ping(DRIVE, &ping(), seq as u16, len, u64::MAX).unwrap();
        assert!(rtt.is_some_and(|t| t > 0), "{len} bytes: {rtt:?}");
    }
    let e = endpoint(&m);
    assert_eq!((e.frames_in, e.frames_out, e.fragment_errors), (8, 9, 0));
    // Another address is not answered: no reply within the timeout.
    let lost = EoePing { to_ip: [192, 168, 7, 3], ..ping() };
    assert_eq!(m.acyclic().eoe().ping(DRIVE, &lost, 99, 8, 20_000_000).unwrap(), None);
    // More than 63 × 32 bytes has no EoE form.
    let err = m.acyclic().eoe().send(DRIVE, &[0u8; 2017]).unwrap_err().to_string();
    assert!(err.contains("2017-byte frame") && err.contains("SERVO"), "{err}");
}

#[test]
fn a_frame_that_arrives_during_an_sdo_transfer_is_kept() {
    let mut m = master();
    addressed(&mut m);
    assert!(m.acyclic().eoe().receive(DRIVE, 1_000_000).unwrap().is_some(), "the announcement");
    m.acyclic().eoe().send(DRIVE, &arp_request(DRIVE_IP)).unwrap();
    // The ARP reply is in the send mailbox before the SDO response: the SDO read meets it.
    let v = m.acyclic().coe().sdo_read(DRIVE, 0x1000, 0).unwrap();
    assert_eq!(v.len(), 4);
    let f = m.acyclic().eoe().receive(DRIVE, 0).unwrap().expect("the ARP reply, kept");
    let a = ArpRepr::parse(&f[14..]).unwrap();
    assert_eq!((a.operation, a.sender_mac, a.target_ip), (ARP_REPLY, DRIVE_MAC, MASTER_IP));
    assert_eq!(m.acyclic().eoe().link(DRIVE).unwrap().dropped, 0);
}

#[test]
fn a_slave_without_eoe_is_refused_before_anything_is_sent() {
    let mut m = master();
    let e = m.acyclic().eoe().get_ip(0).unwrap_err().to_string();
    assert!(e.contains("EK1100") && e.contains("mailbox"), "{e}");
}

#[test]
fn the_pump_moves_frames_between_cycles_in_op_without_waiting() {
    let mut m = master();
    addressed(&mut m);
    m.states().start().unwrap();
    m.cyclic().set_period_ns(1_000_000);
    let p = ping();
    let data = [0x5Au8; 600];
    // Three echo requests of 642 bytes queued at once: 7 fragments each through the 128-byte
    // mailbox, one written per cycle.
    for seq in 0..3 {
        assert!(m.acyclic().eoe().queue(DRIVE, &p.echo_request(seq, &data).unwrap()).unwrap());
    }
    // Meanwhile a blocking send would interleave its fragments with the queue's.
    let e = m.acyclic().eoe().send(DRIVE, &p.echo_request(9, &data).unwrap()).unwrap_err().to_string();
    assert!(e.contains("still going out"), "{e}");
    let mut echoes = Vec::new();
    let mut cycles = 0;
    while echoes.len() < 3 && cycles < 200 {
        m.cyclic().cycle().unwrap();
        cycles += 1;
        // The drive's ARP announcement (42 bytes) waited in its mailbox: not an echo.
        if let Some(f) = m.acyclic().eoe().pump(DRIVE).unwrap().filter(|f| f.len() > 42) {
            echoes.push(f);
        }
    }
    for (seq, f) in echoes.iter().enumerate() {
        assert!(p.is_echo_reply(f, seq as u16, &data), "reply {seq}");
    }
    assert_eq!(echoes.len(), 3, "after {cycles} cycles");
    // Every cycle kept the whole working counter: the pump's frames are its own.
    assert_eq!(m.diagnosis().cycle_stats().wkc_errors, 0);
    println!("three 642-byte echoes there and back in {cycles} cycles of 1 ms");
}
