//! `ferrocat run --dc` runs a clock-sync method and reports its lock state, on the embedded
//! virtual segment.
use std::process::Command;

fn run(args: &[&str]) -> serde_json::Value {
    let out = Command::new(env!("CARGO_BIN_EXE_ferrocat"))
        .args(["run", "--device", "EK1100", "--device", "EL2004", "--device", "EL1004", "--dc", "--json"])
        .args(args)
        .output()
        .unwrap();
    assert!(out.status.success(), "{}", String::from_utf8_lossy(&out.stderr));
    serde_json::from_slice(&out.stdout).unwrap_or_else(|e| panic!("{e}: {}", String::from_utf8_lossy(&out.stdout)))
}

#[test]
fn run_dc_runs_ferrocat_by_default_and_reports_it_locked() {
    let r = run(&["--seconds", "2"]);
    println!("{r}");
    assert_eq!(r["clock_sync"]["method"], "ferrocat");
    assert_eq!(r["clock_sync"]["lock"], "locked");
    assert!(r["clock_sync"]["offset_ns"].as_i64().unwrap().abs() <= 1_000, "{r}");
    assert_eq!(r["cycles"], 2000);
}

#[test]
fn run_dc_takes_a_named_method_and_says_when_it_does_not_lock() {
    let r = run(&["--seconds", "1", "--sync", "conventional"]);
    println!("{r}");
    assert_eq!(r["clock_sync"]["method"], "conventional");
    assert_eq!(r["clock_sync"]["lock"], "locking");
    let r = run(&["--seconds", "0.5", "--sync", "chen2016"]);
    assert_eq!(r["clock_sync"]["lock"], "unlocked", "chen2016 keeps no estimate to compare: {r}");
    let out = Command::new(env!("CARGO_BIN_EXE_ferrocat"))
        .args(["run", "--device", "EK1100", "--dc", "--sync", "ptp"])
        .output()
        .unwrap();
    assert!(!out.status.success());
    assert!(String::from_utf8_lossy(&out.stderr).contains("ferrocat-mfr"), "the error lists the presets");
}

#[test]
fn run_without_dc_has_no_clock_sync() {
    let out = Command::new(env!("CARGO_BIN_EXE_ferrocat"))
        .args(["run", "--device", "EK1100", "--device", "EL2004", "--seconds", "0.2", "--json"])
        .output()
        .unwrap();
    assert!(out.status.success());
    let r: serde_json::Value = serde_json::from_slice(&out.stdout).unwrap();
    assert_eq!(r["clock_sync"], serde_json::Value::Null);
    // The loop's quality, as cyclictest reports it: one wake-up per cycle, one period fewer.
    let cycles = r["cycles"].as_u64().unwrap();
    for (key, n) in [("wake_latency", cycles), ("period_jitter", cycles - 1)] {
        let h = &r[key];
        assert_eq!(h["count"], n, "{key}: {h}");
        let buckets: u64 = h["histogram"].as_array().unwrap().iter().map(|b| b[1].as_u64().unwrap()).sum();
        assert_eq!(buckets, n, "{key}: {h}");
        let (p50, p99, max) =
            (h["p50_us"].as_f64().unwrap(), h["p99_us"].as_f64().unwrap(), h["max_us"].as_f64().unwrap());
        assert!(p50 <= p99 && p99 <= max, "{key}: {h}");
    }
    assert!(r["overruns"].is_u64());
    let out = Command::new(env!("CARGO_BIN_EXE_ferrocat"))
        .args(["run", "--device", "EK1100", "--sync", "pi"])
        .output()
        .unwrap();
    assert!(!out.status.success(), "--sync needs --dc");
}
