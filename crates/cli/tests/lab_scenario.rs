//! `ferrocat lab run SCENARIO.toml` and `--scenario`: the shipped scenarios, a segment of one's
//! own, the command line over a file, and bad files.
use std::process::Command;

fn ferrocat(args: &[&str]) -> std::process::Output {
    Command::new(env!("CARGO_BIN_EXE_ferrocat"))
        .current_dir(concat!(env!("CARGO_MANIFEST_DIR"), "/../.."))
        // One core: the live tests running beside this one need the other.
        .env("RAYON_NUM_THREADS", "1")
        .args(args)
        .output()
        .unwrap()
}

#[test]
fn a_scenario_with_a_tree_segment_runs_and_the_flags_override_it() {
    let out = ferrocat(&[
        "lab",
        "run",
        "scenarios/park2020-tree.toml",
        "--quick",
        "--rounds",
        "1",
        "--seed",
        "3",
        "--method",
        "conventional",
        "--method",
        "ferrocat",
        "--json",
    ]);
    assert!(out.status.success(), "{}", String::from_utf8_lossy(&out.stderr));
    let v: serde_json::Value = serde_json::from_slice(&out.stdout).unwrap();
    assert_eq!((v["seed"].as_u64(), v["rounds"].as_u64()), (Some(3), Some(1)), "{v}");
    let rows = v["rows"].as_array().unwrap();
    assert_eq!(rows.len(), 2, "{v}");
    // The tree of scenarios/segments/tree.toml: six devices, its host pc-rt.
    assert!(rows.iter().all(|r| r["slaves"] == 6 && r["host"] == "pc-rt"), "{v}");
    let gmean = |m: &str| rows.iter().find(|r| r["method"] == m).unwrap()["last_gmean_us"].as_f64().unwrap();
    // Behind a 100BASE-TX branch and at a 32-bit DC, ferrocat still beats conventional.
    assert!(gmean("ferrocat").abs() < gmean("conventional").abs() / 4.0, "{v}");
}

#[test]
fn robustness_writes_its_report() {
    let dir = std::env::temp_dir().join(format!("ferrocat-robust-{}", std::process::id()));
    let out = ferrocat(&[
        "lab",
        "robustness",
        "--scenario",
        "scenarios/robustness.toml",
        "--method",
        "ferrocat",
        "--out",
        dir.to_str().unwrap(),
    ]);
    assert!(out.status.success(), "{}", String::from_utf8_lossy(&out.stderr));
    let md = std::fs::read_to_string(dir.join("robustness.md")).unwrap();
    assert!(md.contains("| drift-step-50ppm | ferrocat |"), "{md}");
    assert!(std::fs::read_to_string(dir.join("robustness.csv")).unwrap().starts_with("scenario,method"));
    let _ = std::fs::remove_dir_all(&dir);
}

#[test]
fn bad_scenarios_are_named_with_their_key() {
    let dir = std::env::temp_dir().join(format!("ferrocat-scen-{}", std::process::id()));
    std::fs::create_dir_all(&dir).unwrap();
    for (text, needle) in [
        ("experiment = 'park2020'\nsamples = 'many'\n", "samples"),
        ("experiment = 'chen2016'\nslaves = [2]\n", "`slaves`: does not apply to chen2016"),
        ("experiment = 'park2020'\nsegment = 'missing.toml'\n", "missing.toml"),
        ("experiment = 'park2020'\n[oops\n", "line 2"),
    ] {
        let f = dir.join("s.toml");
        std::fs::write(&f, text).unwrap();
        let out = ferrocat(&["lab", "run", f.to_str().unwrap()]);
        let err = String::from_utf8_lossy(&out.stderr);
        assert_eq!(out.status.code(), Some(1), "{text}: {err}");
        assert!(err.contains("s.toml") && err.contains(needle), "{text}: {err}");
    }
    // `--quick` replaces the durations, but a bad one in the file is still an error.
    let f = dir.join("s.toml");
    std::fs::write(&f, "experiment = 'park2020'\nsettle_s = nan\n").unwrap();
    let out = ferrocat(&["lab", "run", f.to_str().unwrap(), "--quick"]);
    let err = String::from_utf8_lossy(&out.stderr);
    assert_eq!(out.status.code(), Some(1), "{err}");
    assert!(err.contains("`settle_s`: NaN is not between 0 and 86400 s"), "{err}");
    // Another experiment's flag: chen2016 has none named so; `lab run` takes every flag and the
    // scenario's check names the one that does not apply.
    let out = ferrocat(&["lab", "chen2016", "--rounds", "2"]);
    assert!(String::from_utf8_lossy(&out.stderr).contains("unexpected argument '--rounds'"));
    std::fs::write(&f, "experiment = 'chen2016'\n").unwrap();
    let out = ferrocat(&["lab", "run", f.to_str().unwrap(), "--rounds", "2"]);
    let err = String::from_utf8_lossy(&out.stderr);
    assert!(err.contains("--rounds: does not apply to chen2016"), "{err}");
    let _ = std::fs::remove_dir_all(&dir);
}

/// The shipped ring scenario against the same segment as a line: ferrocat's GPIO calibration
/// finds the same stamp asymmetry on both (the master measured how much shorter the ring's
/// loop is; without that, 0.22 µs more on the ring), and its error stays a few ns.
#[test]
fn a_ring_measures_as_its_line_does() {
    let line = std::env::temp_dir().join(format!("ferrocat-line-{}.toml", std::process::id()));
    let ring =
        std::fs::read_to_string(concat!(env!("CARGO_MANIFEST_DIR"), "/../../scenarios/segments/ring.toml")).unwrap();
    std::fs::write(&line, ring.split("\n[secondary]").next().unwrap()).unwrap();
    let run = |segment: Option<&str>| -> serde_json::Value {
        let mut args = vec![
            "lab",
            "run",
            "scenarios/park2020-ring.toml",
            "--quick",
            "--rounds",
            "1",
            "--method",
            "ferrocat",
            "--json",
        ];
        if let Some(s) = segment {
            args.extend(["--segment", s]);
        }
        let out = ferrocat(&args);
        assert!(out.status.success(), "{}", String::from_utf8_lossy(&out.stderr));
        let v: serde_json::Value = serde_json::from_slice(&out.stdout).unwrap();
        v["rows"][0].clone()
    };
    let (r, l) = (run(None), run(Some(line.to_str().unwrap())));
    std::fs::remove_file(&line).ok();
    println!("ring {r}\nline {l}");
    let f = |v: &serde_json::Value, k: &str| v[k].as_f64().unwrap();
    assert!((f(&r, "calibration_us") - f(&l, "calibration_us")).abs() < 0.02, "ring {r}\nline {l}");
    assert!(f(&r, "ref_gmean_us").abs() < 0.01 && f(&r, "ref_mrms_us") < 0.02, "{r}");
}
