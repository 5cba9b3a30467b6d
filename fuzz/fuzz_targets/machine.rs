#![no_main]
//! Any text as a machine description: an error or a description, never a panic; whatever reads
//! writes out as TOML that reads back the same.
use ferrocat_machine::Machine;
use libfuzzer_sys::fuzz_target;

fuzz_target!(|data: &[u8]| {
    let Ok(text) = std::str::from_utf8(data) else { return };
    if let Ok(m) = Machine::parse(text) {
        let again = Machine::parse(&m.to_toml()).expect("a written description reads back");
        assert_eq!(again, m);
    }
});
