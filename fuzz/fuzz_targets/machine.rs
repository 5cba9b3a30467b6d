#![no_main]
//! Any text as a machine description: an error or a description, never a panic; whatever reads
//! writes out as TOML that reads back the same (but for the lines its init commands stood on).
use ferrocat_machine::Machine;
use libfuzzer_sys::fuzz_target;

fuzz_target!(|data: &[u8]| {
    let Ok(text) = std::str::from_utf8(data) else { return };
    if let Ok(m) = Machine::parse(text) {
        let again = Machine::parse(&m.to_toml()).expect("a written description reads back");
        // An init command's line is where it stands in its file, which the written file moves.
        let lines_off = |mut m: Machine| {
            m.slaves.iter_mut().flat_map(|s| s.init.iter_mut()).for_each(|c| c.line = 0);
            m
        };
        assert_eq!(lines_off(again), lines_off(m));
    }
});
