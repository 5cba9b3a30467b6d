#![no_main]
//! Any text as an ESI file, each device in it put on a segment as `ferrocat sim --config`
//! would (its SII image, object dictionary, application), and our master brought against it:
//! scan, configure (PDO mapping read over CoE), distributed clocks, OP, then the object
//! dictionary listed and every object read. Building may fail with an error and the master may
//! give up with one; neither may panic or hang.
use ferrocat_esi::EsiFile;
use ferrocat_master::{DcConfig, Master};
use ferrocat_segment::SegmentConfig;
use ferrocat_segment::{HostModel, VirtualIo};
use libfuzzer_sys::fuzz_target;

fuzz_target!(|data: &[u8]| {
    let Ok(text) = std::str::from_utf8(data) else { return };
    let Ok(f) = EsiFile::parse(text) else { return };
    let path = std::env::temp_dir().join(format!("ferrocat-fuzz-device-{}.xml", std::process::id()));
    std::fs::write(&path, text).expect("temporary ESI file");
    for d in f.devices.iter().take(3) {
        let toml = format!(
            "[[device]]\nbuiltin = 'EK1100'\n[[device]]\nesi = '{}'\nproduct = {}\nrevision = {}\n",
            path.display(),
            d.product_code,
            d.revision
        );
        let cfg: SegmentConfig = toml::from_str(&toml).expect("the fuzz segment file parses");
        let Ok(seg) = cfg.build() else { continue };
        exercise(seg);
    }
    let _ = std::fs::remove_file(&path);
});

fn exercise(seg: ferrocat_segment::Segment) {
    let mut m = Master::new(VirtualIo::new(seg, HostModel::ideal(), 1));
    if m.states().scan().is_err() || m.states().configure().is_err() {
        return;
    }
    let dc = DcConfig { max_frames: 300, ..DcConfig::default() };
    let _ = m.dc().init_dc(&dc);
    let _ = m.states().start();
    if let Ok(list) = m.acyclic().coe().od_list(1) {
        for index in list.into_iter().take(64) {
            if let Ok(info) = m.acyclic().coe().object_info(1, index) {
                for sub in 0..=info.max_subindex.min(8) {
                    let _ = m.acyclic().coe().entry_info(1, index, sub);
                    let _ = m.acyclic().coe().sdo_read(1, index, sub);
                }
            }
        }
    }
}
