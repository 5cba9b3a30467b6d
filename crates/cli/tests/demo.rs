//! `ferrocat demo --json`, as the README runs it: every method at 1 ms and 250 µs, the figures
//! the issue names, and the plots written.
mod figures;

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
    assert_eq!(methods.len(), 14, "7 methods × 2 cycle times");
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
        // One measure per coupling, never both: a clock error, or a phase on the reference's
        // cycle where the master follows it.
        let mfr = ["none", "chen2016", "pi", "ferrocat-mfr"].contains(&m["method"].as_str().unwrap());
        assert_eq!((m["error_mean_ns"].is_null(), m["phase_mean_ns"].is_null()), (mfr, !mfr), "{m}");
    }
    for f in ["demo.csv", "positions-1000us.svg", "following-error-250us.svg", "clock-error-1000us.svg"] {
        let p = out_dir.join(f);
        let len = std::fs::metadata(&p).map(|m| m.len()).unwrap_or(0);
        assert!(len > 500, "{} is {len} bytes", p.display());
    }
    figures::assert_chart_png(&out_dir.join("clock-error-1000us.png"));
    let _ = std::fs::remove_dir_all(&out_dir);
    // The text has the two measures under their own headings.
    let text = Command::new(env!("CARGO_BIN_EXE_ferrocat")).args(["demo", "--cycle-us", "1000"]).output().unwrap();
    let text = String::from_utf8_lossy(&text.stdout).to_string();
    let (err_part, rest) = text.split_once("The master follows the reference").expect("two tables");
    let phase_part = rest.split("Following error").next().unwrap();
    assert!(err_part.contains("err mean") && err_part.contains("\n1000µs  ferrocat "), "{text}");
    assert!(phase_part.contains("phase mean") && phase_part.contains("\n1000µs  ferrocat-mfr "), "{text}");
    assert!(!err_part.contains("ferrocat-mfr") && !phase_part.contains("\n1000µs  ferrocat "), "{text}");
    // Bad input is one clear line, not a panic.
    let bad = Command::new(env!("CARGO_BIN_EXE_ferrocat")).args(["demo", "--method", "magic"]).output().unwrap();
    assert!(!bad.status.success());
    let msg = String::from_utf8_lossy(&bad.stderr);
    assert!(msg.contains("unknown method \"magic\""), "{msg}");
}
