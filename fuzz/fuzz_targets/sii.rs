#![no_main]
//! Any bytes as an EEPROM dump: dump decoding, the zero-copy view and the owned description.
use ferrocat_wire::sii::{dump::parse_dump, Pdos, SiiImage, SiiInfo};
use libfuzzer_sys::fuzz_target;

fuzz_target!(|data: &[u8]| {
    let Ok((img, _)) = parse_dump(data) else { return };
    if let Ok(view) = SiiImage::parse(&img) {
        let _ = view.check_crc();
        let _ = view.strings().map(|s| s.iter().count());
        let _ = view.general();
        for c in view.categories().flatten() {
            for p in Pdos::new(c.data) {
                let _ = p;
            }
        }
    }
    if let Ok(info) = SiiInfo::from_image(&img) {
        let again = info.to_image();
        let body = again.len() - 2;
        assert_eq!(&img[..body], &again[..body]);
        let _ = info.name();
    }
});
