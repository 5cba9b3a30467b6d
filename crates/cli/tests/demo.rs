//! `ferrocat demo --json`, as the README runs it: every method at 1 ms and 250 µs, the figures
//! the issue names, and the plots written.
mod common;
mod figures;

use std::process::Command;

use common::{ReportingSim, VethPair};

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

/// The demo on a real interface: `ferrocat sim` serves two drives over a veth pair, the master
/// runs in real time; only what a master can see is reported (the SYNC0 columns stay empty).
#[test]
fn the_demo_runs_on_a_served_network() {
    let net = VethPair::new("dm");
    // A stall of this shared machine of three cycles would be a sync error of the drives
    // (docs/esc-model.md), which this test is not about: their supervision is off.
    let toml = "[[device]]\nbuiltin = 'EK1100'\n[[device]]\nbuiltin = 'SERVO'\nsync_error_limit = 0\n\
                [[device]]\nbuiltin = 'SERVO'\nsync_error_limit = 0\n";
    let sim = ReportingSim::start(&net, "dm", toml, &[]);
    let out_dir = std::env::temp_dir().join(format!("ferrocat-demo-live-{}", std::process::id()));
    let out = VethPair::cmd(&net.master_ns, env!("CARGO_BIN_EXE_ferrocat"))
        .args(["demo", "--iface", &net.master_if, "--cycle-us", "1000", "--method", "ferrocat", "--json", "--out"])
        .arg(&out_dir)
        .output()
        .unwrap();
    sim.report();
    let _ = std::fs::remove_dir_all(&out_dir);
    assert!(out.status.success(), "{}", String::from_utf8_lossy(&out.stderr));
    let v: serde_json::Value = serde_json::from_slice(&out.stdout).unwrap();
    let r = &v["methods"][0];
    println!("live demo: {r}");
    assert_eq!(r["drives"], 2, "{r}");
    assert_eq!(r["host"], "real");
    // Both drives were enabled before the move (the run fails otherwise); how many stay so and
    // how many set-points come late depends on this machine's latencies, which is the point.
    assert!(r["drives_enabled"].as_u64().is_some_and(|n| n <= 2), "{r}");
    // Read from the drives: 0x60F4 through the image, 0x1C32:0B/0C by SDO.
    assert!(r["max_following_error"].as_f64().is_some(), "{r}");
    assert!(r["late_setpoints"].as_u64().is_some() && r["repeated_setpoints"].as_u64().is_some(), "{r}");
    // Only the simulator in-process knows the SYNC0 instants and the true clocks.
    assert!(r["sync0_spread_max_ns"].is_null() && r["error_mean_ns"].is_null(), "{r}");
}
