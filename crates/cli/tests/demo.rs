//! `ferrocat demo --json`, as the README runs it: every method at 1 ms and 250 µs, the figures
//! the issue names, and the plots written.
use std::process::Command;

#[test]
fn the_demo_prints_every_method_as_json_and_writes_its_plots() {
    let out_dir = std::env::temp_dir().join(format!("ferrocat-demo-{}", std::process::id()));
    let out = Command::new(env!("CARGO_BIN_EXE_ferrocat"))
        .args(["demo", "--json", "--out", out_dir.to_str().unwrap()])
        .output()
        .unwrap();
    assert!(out.status.success(), "{}", String::from_utf8_lossy(&out.stderr));
    let v: serde_json::Value = serde_json::from_slice(&out.stdout).unwrap();
    let methods = v["methods"].as_array().unwrap();
    assert_eq!(methods.len(), 12, "6 methods × 2 cycle times");
    for m in methods {
        for key in [
            "method",
            "cycle_us",
            "sync0_spread_max_ns",
            "late_setpoints",
            "repeated_setpoints",
            "max_following_error",
            "drives_enabled",
        ] {
            assert!(!m[key].is_null(), "{key} missing in {m}");
        }
        assert_eq!(m["drives_enabled"], 2, "{m}");
    }
    for f in ["demo.csv", "positions-1000us.svg", "following-error-250us.svg", "clock-error-1000us.svg"] {
        let p = out_dir.join(f);
        let len = std::fs::metadata(&p).map(|m| m.len()).unwrap_or(0);
        assert!(len > 500, "{} is {len} bytes", p.display());
    }
    let _ = std::fs::remove_dir_all(&out_dir);
    // Bad input is one clear line, not a panic.
    let bad = Command::new(env!("CARGO_BIN_EXE_ferrocat")).args(["demo", "--method", "magic"]).output().unwrap();
    assert!(!bad.status.success());
    let msg = String::from_utf8_lossy(&bad.stderr);
    assert!(msg.contains("unknown method \"magic\""), "{msg}");
}
