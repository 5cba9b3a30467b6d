#![no_main]
//! Any bytes as a shared process image file (docs/service.md): attached as a client does, and
//! where it attaches, read, and every output variable written.
use libfuzzer_sys::fuzz_target;

fuzz_target!(|data: &[u8]| {
    let path = std::env::temp_dir().join(format!("ferrocat-fuzz-image-{}", std::process::id()));
    if std::fs::write(&path, data).is_err() {
        return;
    }
    if let Ok(mut c) = ferrocat_service::ImageClient::attach(&path) {
        let _ = c.read();
        let outputs: Vec<String> = c.variables().iter().filter(|v| v.output).map(|v| v.name.clone()).collect();
        for name in outputs {
            let _ = c.write(&[(name.as_str(), 1)]);
        }
    }
    let _ = std::fs::remove_file(&path);
});
