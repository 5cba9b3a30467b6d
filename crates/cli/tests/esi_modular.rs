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

/// `--strict` refuses what vendors' tools accept, naming every deviation; without it the file
/// is read. Devices are chosen by type name as well as by product code.
#[test]
fn esi_strict_refuses_deviations_and_devices_go_by_type_name() {
    let lenient = concat!(env!("CARGO_MANIFEST_DIR"), "/../esi/tests/data/ferrocat_lenient.xml");
    let esi = |args: &[&str]| Command::new(env!("CARGO_BIN_EXE_ferrocat")).arg("esi").args(args).output().unwrap();
    let out = esi(&[lenient, "--strict"]);
    let stderr = String::from_utf8_lossy(&out.stderr);
    assert!(!out.status.success(), "{stderr}");
    assert_eq!(stderr.matches("error: ").count(), 16, "15 deviations and the verdict:\n{stderr}");
    assert!(stderr.contains("15 deviations from ETG.2000") && stderr.contains("line 16, column 9"), "{stderr}");
    let out = esi(&[lenient]);
    assert!(out.status.success(), "{}", String::from_utf8_lossy(&out.stderr));
    assert_eq!(String::from_utf8_lossy(&out.stderr).matches("warning: ").count(), 15);
    // By type name, any case, in `ferrocat esi` and in --device.
    let out = esi(&[FILE, "--device", "fc-2axis", "--json"]);
    let v: serde_json::Value = serde_json::from_slice(&out.stdout).unwrap();
    assert_eq!(v["product_code"], 0x10002, "{v}");
    let out = Command::new(env!("CARGO_BIN_EXE_ferrocat"))
        .args(["run", "--device", &format!("{FILE}:FC-2AXIS"), "--seconds", "0.1", "--json"])
        .output()
        .unwrap();
    assert!(out.status.success(), "{}", String::from_utf8_lossy(&out.stderr));
    let out = Command::new(env!("CARGO_BIN_EXE_ferrocat"))
        .args(["run", "--device", &format!("{FILE}:FC-3AXIS"), "--seconds", "0.1"])
        .output()
        .unwrap();
    let stderr = String::from_utf8_lossy(&out.stderr);
    assert!(
        !out.status.success()
            && stderr.contains("no device of type FC-3AXIS (the file has: FC-IOHEAD 0x10001, FC-2AXIS 0x10002)"),
        "{stderr}"
    );
}

/// Modules in a file of their own (`<EtherCATModule>`, ISO-8859-1) beside the device's: `esi`
/// lists the device's modules from it and reads the module file itself; `run` plugs the default
/// and chosen modules from it and reaches OP with their process data; without the module file
/// the error says where the module was looked for.
#[test]
fn modules_in_a_module_file_beside_the_device_file_are_plugged() {
    let dir = concat!(env!("CARGO_MANIFEST_DIR"), "/../esi/tests/data/module_file");
    let device = format!("{dir}/ferrocat_iohead.xml");
    let ferrocat = |args: &[&str]| Command::new(env!("CARGO_BIN_EXE_ferrocat")).args(args).output().unwrap();
    let out = ferrocat(&["esi", &device, "--device", "FC-IOHEAD-M", "--json"]);
    assert!(out.status.success(), "{}", String::from_utf8_lossy(&out.stderr));
    let v: serde_json::Value = serde_json::from_slice(&out.stdout).unwrap();
    let types: Vec<&str> = v["modules"].as_array().unwrap().iter().map(|m| m["type"].as_str().unwrap()).collect();
    assert_eq!(types, ["FC-DO4", "FC-DI8", "FC-AI2"]);
    assert!(String::from_utf8_lossy(&out.stderr).contains("modules also from "), "the module file is named");
    let out = ferrocat(&["esi", &format!("{dir}/ferrocat_iohead_modules.xml"), "--json"]);
    assert!(out.status.success(), "{}", String::from_utf8_lossy(&out.stderr));
    let v: serde_json::Value = serde_json::from_slice(&out.stdout).unwrap();
    assert_eq!((v["vendor_id"].as_u64(), v["modules"].as_array().map(Vec::len)), (Some(0xF3C), Some(3)), "{v}");

    for spec in [format!("{device}:FC-IOHEAD-M"), format!("{device}:FC-IOHEAD-M:#x802,#x801,#x803")] {
        let out = ferrocat(&["run", "--device", &spec, "--seconds", "0.1", "--json", "--no-control"]);
        assert!(out.status.success(), "{spec}: {}", String::from_utf8_lossy(&out.stderr));
        let v: serde_json::Value = serde_json::from_slice(&out.stdout).unwrap();
        assert_eq!((v["slaves"]["in_op_at_end"].as_u64(), v["wkc_errors"].as_u64()), (Some(1), Some(0)), "{spec}: {v}");
    }
    // The inputs of the chosen modules are in the image: AI1 of the analog module in slot 2.
    let out = ferrocat(&[
        "run",
        "--device",
        &format!("{device}:FC-IOHEAD-M:#x802,#x801,#x803"),
        "--seconds",
        "0.1",
        "--no-control",
        "--show",
        "0:AI1",
    ]);
    let said = String::from_utf8_lossy(&out.stdout);
    assert!(out.status.success() && said.contains("0:AI1 = "), "{said}{}", String::from_utf8_lossy(&out.stderr));

    let alone = std::env::temp_dir().join(format!("ferrocat-module-file-{}", std::process::id()));
    std::fs::create_dir_all(&alone).unwrap();
    std::fs::copy(&device, alone.join("ferrocat_iohead.xml")).unwrap();
    let out = ferrocat(&[
        "run",
        "--device",
        &format!("{}:FC-IOHEAD-M", alone.join("ferrocat_iohead.xml").display()),
        "--seconds",
        "0.1",
    ]);
    std::fs::remove_dir_all(&alone).ok();
    let err = String::from_utf8_lossy(&out.stderr);
    assert!(
        !out.status.success()
            && err.contains("no module with ident 0x00000801 in the file or an <EtherCATModule> file beside it"),
        "{err}"
    );
}
