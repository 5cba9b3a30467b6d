#![no_main]
//! Any bytes as an ENI file: an error or a description, never a panic; every slave it reads
//! builds an SII image that reads back with the slave's identity, and compares equal to itself.
use ferrocat_machine::eni::Eni;
use libfuzzer_sys::fuzz_target;

fuzz_target!(|data: &[u8]| {
    let Ok(eni) = Eni::parse(data) else { return };
    for s in &eni.slaves {
        if let Ok(img) = s.to_device().to_sii(s.identity.vendor_id) {
            let info = ferrocat_wire::sii::SiiInfo::from_image(&img).expect("built images read back");
            assert_eq!(info.header.product_code, s.identity.product_code);
        }
    }
    let expected = eni.expected();
    let found: Vec<ferrocat_machine::Found> = expected
        .iter()
        .map(|e| ferrocat_machine::Found { position: e.position, name: e.name.clone(), identity: e.identity, alias: 0 })
        .collect();
    assert!(ferrocat_machine::compare(&expected, &found).is_empty());
});
