#![no_main]
//! Any text as an ESI file; whatever parses must build an SII image that reads back.
use ferrocat_esi::EsiFile;
use libfuzzer_sys::fuzz_target;

fuzz_target!(|data: &[u8]| {
    let Ok(text) = std::str::from_utf8(data) else { return };
    if let Ok(f) = EsiFile::parse(text) {
        for d in &f.devices {
            if let Ok(img) = d.to_sii(f.vendor_id) {
                ferrocat_wire::sii::SiiInfo::from_image(&img).expect("built images read back");
            }
        }
    }
});
