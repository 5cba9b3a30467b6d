//! A slave with two output SyncManagers (our `ferrocat_two_output_sms.xml`, laid out as
//! Beckhoff's EK1960 TwinSAFE controllers are: SM2 and SM6, SM4 and SM5 listed but off): the
//! master configures both, each with an FMMU of its own, and an output of the second reaches
//! the slave's memory at that SyncManager. With SM6 left off the device refused SAFEOP with
//! 0x001D.
use ferrocat_master::Master;
use ferrocat_segment::{DeviceToml, HostModel, Number, SegmentConfig, VirtualIo};
use ferrocat_wire::register::AlState;
use ferrocat_wire::{Address, Command};

const FILE: &str = concat!(env!("CARGO_MANIFEST_DIR"), "/../esi/tests/data/ferrocat_two_output_sms.xml");

#[test]
fn both_output_sync_managers_are_configured_and_the_second_carries_its_outputs() {
    let dev =
        DeviceToml { esi: Some(FILE.into()), product: Some(Number::Text("#x00010004".into())), ..Default::default() };
    let cfg = SegmentConfig { devices: vec![dev], ..SegmentConfig::default() };
    let mut m = Master::new(VirtualIo::new(cfg.build().unwrap(), HostModel::ideal(), 1));
    m.states().scan().unwrap();
    m.states().configure().unwrap();
    let mapping = m.slaves()[0].mapping();
    let sms: Vec<(u8, u16, u32, u32)> = mapping.output_sms().iter().map(|s| (s.0, s.1.start, s.2, s.3)).collect();
    // SM2's two bytes, then SM6's four on a byte of their own; SM4 (off, nothing assigned) not.
    assert_eq!(sms, [(2, 0x1100, 0, 2), (6, 0x1FF4, 2, 4)]);
    assert_eq!(mapping.output_bits(), 48);
    assert_eq!(mapping.input_sms().iter().map(|s| (s.0, s.3)).collect::<Vec<_>>(), [(3, 2)]);
    m.states().start().unwrap();
    assert_eq!(m.slaves()[0].status().state(), AlState::Op);

    let word = m.image().output(0, "Standard word").unwrap();
    let bit2 = m.image().output(0, "Standard output 2").unwrap();
    m.cyclic().set(word, 0xABCDEF);
    m.cyclic().set(bit2, 1);
    for _ in 0..3 {
        assert_eq!(m.cyclic().cycle().unwrap(), m.image().expected_wkc());
    }
    // SM6's buffer in the slave: bit 1 of its first byte, then the 24-bit word.
    let mut d = [0u8; 4];
    let station = m.slaves()[0].station();
    m.cyclic().datagram(Command::FPRD, Address::Device { adp: station, ado: 0x1FF4 }, &mut d).unwrap();
    assert_eq!(d, [0b10, 0xEF, 0xCD, 0xAB]);
}
