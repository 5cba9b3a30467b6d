//! Diagnosis while `run` is cyclic, on the embedded virtual segment: error counters that grow
//! (frames corrupted on the wire) and a drive's emergency (a fault it raises by itself) reach
//! the user, by slave and port, decoded; `--no-diagnosis` sends none of it.
use std::process::Command;

fn run(args: &[&str]) -> (serde_json::Value, String) {
    let toml =
        "seed = 5\ncorruption_probability = 0.002\n[[device]]\nbuiltin = 'EK1100'\n[[device]]\nbuiltin = 'EL2004'\n\
                [[device]]\nbuiltin = 'SERVO'\n[[event]]\nat_ms = 1500\ndrive_fault = { device = 2, code = 0x2310 }\n";
    let path = std::env::temp_dir().join(format!("ferrocat-diagnosis-{}-{}.toml", std::process::id(), args.len()));
    std::fs::write(&path, toml).unwrap();
    let o = Command::new(env!("CARGO_BIN_EXE_ferrocat"))
        .args(["run", "--config", path.to_str().unwrap(), "--seconds", "2.5", "--json", "--counters-period-ms", "500"])
        .args(args)
        .output()
        .unwrap();
    std::fs::remove_file(&path).ok();
    let err = String::from_utf8_lossy(&o.stderr).into_owned();
    assert!(o.status.success(), "{err}");
    (serde_json::from_slice(&o.stdout).unwrap(), err)
}

#[test]
fn error_counters_and_emergencies_reach_the_user_while_cyclic() {
    let (v, err) = run(&[]);
    let d = &v["diagnosis"];
    assert_eq!(d["emergencies"], 1, "{d}");
    assert!(err.contains("slave 2 (SERVO): emergency 0x2310 (continuous over-current)"), "{err}");
    assert!(d["counters_grown"].as_u64().unwrap() > 0, "{d}");
    assert!(err.contains("port 0 invalid frames +"), "{err}");
    // Every slave's port 0 saw corrupted frames, counted by its ESC and read back.
    let counters = d["error_counters"].as_array().unwrap();
    assert_eq!(counters.len(), 3, "{d}");
    assert!(counters.iter().all(|c| c["counters"]["port 0 invalid frames"].as_u64().unwrap() > 0), "{d}");
    // Each slave's counters every 500 ms over 2.5 s, the mailbox between.
    assert!(d["counter_reads"].as_u64().unwrap() >= 3 * 4, "{d}");
    assert!(d["mailbox_polls"].as_u64().unwrap() > 1000, "{d}");
    let (v, err) = run(&["--no-diagnosis"]);
    assert!(v["diagnosis"].is_null(), "{v}");
    assert!(!err.contains("emergency") && !err.contains("invalid frames"), "{err}");
}

#[test]
fn the_sync_error_flag_of_a_drive_with_sync0_is_read_while_cyclic() {
    let path = std::env::temp_dir().join(format!("ferrocat-diagnosis-sync-{}.toml", std::process::id()));
    std::fs::write(&path, "[[device]]\nbuiltin = 'EK1100'\n[[device]]\nbuiltin = 'SERVO'\n").unwrap();
    let o = Command::new(env!("CARGO_BIN_EXE_ferrocat"))
        .args(["run", "--config", path.to_str().unwrap(), "--dc", "--seconds", "1", "--json"])
        .args(["--counters-period-ms", "100"])
        .output()
        .unwrap();
    std::fs::remove_file(&path).ok();
    assert!(o.status.success(), "{}", String::from_utf8_lossy(&o.stderr));
    let v: serde_json::Value = serde_json::from_slice(&o.stdout).unwrap();
    let d = &v["diagnosis"];
    // A round every 100 ms of the one slave with SYNC0, the drive: both its SM parameters' flags,
    // clear throughout.
    assert!(d["sync_flag_reads"].as_u64().unwrap() >= 5, "{d}");
    assert_eq!(d["sync_errors"], 0, "{d}");
    assert_eq!(d["sync_error_flags"], serde_json::json!([{"position": 1, "outputs": false, "inputs": false}]), "{d}");
}

/// A terminal whose inputs carry Beckhoff's TxPDO Toggle (the EL2212's status, one a channel,
/// from its vendor's ESI): the simulated device has no firmware to refresh them, so each toggle
/// stands still, and the run says so once per entry, naming it.
#[test]
fn needs_shared_a_txpdo_toggle_that_stands_still_is_said_once_per_entry() {
    let esi = ferrocat_testdata::shared("esi-corpus/Beckhoff EL2xxx.xml");
    let dev = format!("{}:EL2212", esi.display());
    let o = Command::new(env!("CARGO_BIN_EXE_ferrocat"))
        .args(["run", "--device", "EK1100", "--device", &dev, "--seconds", "0.5", "--json"])
        .args(["--txpdo-stale-ms", "200"])
        .output()
        .unwrap();
    let err = String::from_utf8_lossy(&o.stderr);
    assert!(o.status.success(), "{err}");
    let v: serde_json::Value = serde_json::from_slice(&o.stdout).unwrap();
    let d = &v["diagnosis"];
    assert_eq!(
        (d["txpdo_watched"].as_u64(), d["inputs_stale"].as_u64(), d["inputs_invalid"].as_u64()),
        (Some(2), Some(2), Some(0)),
        "{d}"
    );
    for object in ["0x6000:0x10", "0x6010:0x10"] {
        let said = format!("slave 1 (EL2212): Status__TxPDO Toggle ({object}) unchanged for 200 ms");
        assert_eq!(err.matches(&said).count(), 1, "{object}: {err}");
    }
}
