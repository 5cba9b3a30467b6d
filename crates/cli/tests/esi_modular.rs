//! `ferrocat esi` on a modular device: slots, the modules that fit, and the warnings of a file
//! vendors' tools accept.
use std::process::Command;

const FILE: &str = concat!(env!("CARGO_MANIFEST_DIR"), "/../esi/tests/data/ferrocat_modular.xml");

#[test]
fn esi_lists_slots_and_modules_and_warns_with_line_and_column() {
    let out =
        Command::new(env!("CARGO_BIN_EXE_ferrocat")).args(["esi", FILE, "--device", "1", "--json"]).output().unwrap();
    assert!(out.status.success(), "{}", String::from_utf8_lossy(&out.stderr));
    let v: serde_json::Value = serde_json::from_slice(&out.stdout).unwrap();
    assert_eq!(v["slots"]["slot_index_increment"], 0x800);
    assert_eq!(v["slots"]["slots"][0]["min_instances"], 2);
    assert_eq!(v["slots"]["slots"][0]["default_module"], 0x9010);
    let types: Vec<&str> = v["modules"].as_array().unwrap().iter().map(|m| m["type"].as_str().unwrap()).collect();
    assert_eq!(types, ["FC-AXIS-CSP", "FC-AXIS-CSV"], "only the modules that fit the drive's slots");
    let stderr = String::from_utf8_lossy(&out.stderr);
    assert!(
        stderr.contains("warning: ") && stderr.contains("odd length 1") && stderr.contains(", column "),
        "{stderr}"
    );
    assert_eq!(v["warnings"].as_array().unwrap().len(), 1);
    let out = Command::new(env!("CARGO_BIN_EXE_ferrocat")).args(["esi", FILE, "--device", "0"]).output().unwrap();
    let text = String::from_utf8_lossy(&out.stdout);
    assert!(text.contains("SLOT \"Terminal\" ×1–8: 0x00000801 (default), 0x00000802, 0x00000803"), "{text}");
    assert_eq!(text.matches("  MODULE ").count(), 3, "{text}");
}

#[test]
fn device_args_choose_the_modules_of_a_modular_device() {
    let run = |device: &str| {
        Command::new(env!("CARGO_BIN_EXE_ferrocat"))
            .args(["run", "--device", device, "--seconds", "0.1", "--json"])
            .output()
            .unwrap()
    };
    let out = run(&format!("{FILE}:#x00010002:#x9010,#x9020"));
    assert!(out.status.success(), "{}", String::from_utf8_lossy(&out.stderr));
    let v: serde_json::Value = serde_json::from_slice(&out.stdout).unwrap();
    assert_eq!(v["wkc_errors"], 0, "{v}");
    let out = run(&format!("{FILE}:#x00010002:#x9010,#x0801"));
    assert!(!out.status.success());
    let err = String::from_utf8_lossy(&out.stderr);
    assert!(err.contains("slot 1 (Axis): module FC-DO4 (0x00000801) does not fit it"), "{err}");
    let out = run(&format!("{FILE}:#x00010002:#x9010,banana"));
    assert!(String::from_utf8_lossy(&out.stderr).contains("'banana' in '#x9010,banana' is not a module ident"));
}
