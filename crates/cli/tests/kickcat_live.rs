//! KickCAT's master, unmodified (the `kickcat` package from PyPI, which scripts/test.sh puts in
//! `.venv`), against `ferrocat sim` over a veth pair: a third independent master beside SOEM
//! and ethercrab.
mod common;

use common::{python, Sim, VethPair};

/// EK1100, EL2004, EL1004 and the built-in servo: KickCAT brings all four to OP, its outputs
/// reach the EL2004, and it reads the servo's device name by SDO.
#[test]
fn kickcat_reaches_op_exchanges_process_data_and_reads_an_sdo() {
    let net = VethPair::new("kc");
    let report = std::env::temp_dir().join(format!("ferrocat-kickcat-{}.json", std::process::id()));
    let sim = Sim::start(
        &net,
        &[
            "--device",
            "EK1100",
            "--device",
            "EL2004",
            "--device",
            "EL1004",
            "--device",
            "SERVO",
            "--report",
            report.to_str().unwrap(),
        ],
    );
    let script = concat!(env!("CARGO_MANIFEST_DIR"), "/tests/python/kickcat_master.py");
    let out = VethPair::cmd(&net.master_ns, python().to_str().unwrap())
        .args([script, &net.master_if, "1", "2", "3"])
        .output()
        .unwrap();
    sim.stop();
    let stdout = String::from_utf8_lossy(&out.stdout);
    assert!(out.status.success(), "kickcat: {stdout}{}", String::from_utf8_lossy(&out.stderr));
    // KickCAT prints which interfaces it opened before the script's JSON line.
    let line = stdout.lines().rev().find(|l| l.starts_with('{')).unwrap_or_else(|| panic!("no JSON in {stdout}"));
    let kc: serde_json::Value = serde_json::from_str(line).unwrap();
    println!("KickCAT saw: {kc}");
    assert_eq!(kc["slaves"], serde_json::json!([1001, 1002, 1003, 1004]));
    assert!(kc["states"].as_array().unwrap().iter().all(|s| s == "State.OPERATIONAL"), "{kc}");
    assert_eq!(kc["output_size"][1], 1, "EL2004: one byte of outputs");
    assert_eq!(kc["input_size"][2], 1, "EL1004: one byte of inputs");
    assert!(kc["cycles"].as_u64().unwrap() > 10, "{kc}");
    assert_eq!(kc["device_name"], "ferrocat simulated CiA402 servo drive");
    let rep: serde_json::Value = serde_json::from_str(&std::fs::read_to_string(&report).unwrap()).unwrap();
    std::fs::remove_file(&report).ok();
    let el2004 = &rep["devices"][1];
    assert_eq!(el2004["al_state"], "OP", "{el2004}");
    assert_eq!(el2004["outputs"], serde_json::json!([0x0F]), "KickCAT's outputs on the EL2004: {el2004}");
}
