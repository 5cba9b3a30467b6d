//! docs/results.md is what the code produces now: the headline experiments in their quick
//! variants on seed 1 (`ferrocat lab park2020|chen2016|paprocki2022|robustness --quick`,
//! `ferrocat demo`) and the papers' figures beside the set-up models, rendered as tables. The simulations are deterministic, so a figure that
//! changes without the file fails this test; `scripts/results.sh` writes the file anew
//! (`FERROCAT_WRITE_RESULTS=1`).
use std::fmt::Write as _;
use std::process::Command;

use serde_json::Value;

fn run(args: &[&str]) -> Value {
    // One folder, whatever the arguments hold (a scenario's path has slashes: joined as they
    // were, the folder removed below was a subfolder of one left behind).
    let name: String =
        args.join("-").chars().map(|c| if c.is_ascii_alphanumeric() || c == '-' { c } else { '_' }).collect();
    let out_dir = std::env::temp_dir().join(format!("ferrocat-results-{}-{name}", std::process::id()));
    let out = Command::new(env!("CARGO_BIN_EXE_ferrocat"))
        .args(args)
        .args(["--json", "--out"])
        .arg(&out_dir)
        .output()
        .unwrap();
    let _ = std::fs::remove_dir_all(&out_dir);
    assert!(out.status.success(), "ferrocat {args:?}: {}", String::from_utf8_lossy(&out.stderr));
    serde_json::from_slice(&out.stdout).unwrap()
}

/// A figure with `decimals` places, "—" where the experiment gives none.
fn f(v: &Value, decimals: usize) -> String {
    match v.as_f64() {
        // A value that rounds to zero is 0, whichever side it came from.
        Some(x) => {
            let s = format!("{x:.decimals$}");
            if s.trim_start_matches('-').chars().all(|c| c == '0' || c == '.') {
                s.trim_start_matches('-').to_string()
            } else {
                s
            }
        }
        None => "—".into(),
    }
}

fn rows(v: &Value) -> &Vec<Value> {
    v["rows"].as_array().unwrap()
}

fn table(out: &mut String, header: &[&str], lines: impl Iterator<Item = Vec<String>>) {
    let _ = writeln!(out, "| {} |", header.join(" | "));
    let _ = writeln!(out, "|{}", "---|".repeat(header.len()));
    for l in lines {
        let _ = writeln!(out, "| {} |", l.join(" | "));
    }
    out.push('\n');
}

fn render() -> String {
    let mut out = String::from(
        "# Current results\n\n\
         Written by `scripts/results.sh`; `crates/cli/tests/results_current.rs` fails when the code \
         gives other figures than these. Every run is deterministic: seed 1, the quick variants. \
         docs/lab.md explains the experiments and docs/clock-sync.md and docs/cia402.md the methods; \
         the papers' own figures stand beside ours there.\n\n",
    );
    let park = run(&["lab", "park2020", "--quick"]);
    let _ = writeln!(
        out,
        "## Park 2020, Table 1 — `ferrocat lab park2020 --quick`\n\nHost {}, {} rounds of {} samples after {} s settling. \
         GMEAN and MRMS of master − slave clock (µs), as the simulator's truth; GPI: as Park's \
         GPIO set-up would have measured it.\n",
        rows(&park)[0]["host"].as_str().unwrap_or("?"),
        park["rounds"],
        park["samples"],
        park["settle_s"]
    );
    table(
        &mut out,
        &[
            "slaves",
            "method",
            "ref GMEAN",
            "ref MRMS",
            "last GMEAN",
            "last MRMS",
            "GPI ref GMEAN",
            "GPI last GMEAN",
            "init ms",
        ],
        rows(&park).iter().map(|r| {
            vec![
                r["slaves"].to_string(),
                r["method"].as_str().unwrap_or("?").into(),
                f(&r["ref_gmean_us"], 2),
                f(&r["ref_mrms_us"], 2),
                f(&r["last_gmean_us"], 2),
                f(&r["last_mrms_us"], 2),
                f(&r["gpi_ref_gmean_us"], 2),
                f(&r["gpi_last_gmean_us"], 2),
                f(&r["init_ms"], 1),
            ]
        }),
    );
    let chen = run(&["lab", "chen2016", "--quick"]);
    let _ = writeln!(
        out,
        "## Chen 2016, Table 2 — `ferrocat lab chen2016 --quick`\n\nHost {}, {} s per row, reference crystal {} ppm. \
         Jitter of the SYNC0-to-frame interval (µs; width as % of the cycle) and process data \
         lost (a cycle whose outputs the slaves' SYNC0 did not find new).\n",
        rows(&chen)[0]["host"].as_str().unwrap_or("?"),
        chen["seconds"],
        chen["reference_ppm"]
    );
    table(
        &mut out,
        &["cycle µs", "method", "jitter min", "jitter max", "width %", "sd", "lost", "repeated", "loss rate"],
        rows(&chen).iter().map(|r| {
            vec![
                r["cycle_us"].to_string(),
                r["method"].as_str().unwrap_or("?").into(),
                f(&r["jitter_min_us"], 2),
                f(&r["jitter_max_us"], 2),
                f(&r["jitter_width_pct"], 1),
                f(&r["jitter_sd_us"], 2),
                r["lost"].to_string(),
                r["repeated"].to_string(),
                f(&r["loss_rate"], 5),
            ]
        }),
    );
    let pap = run(&["lab", "paprocki2022", "--quick"]);
    let _ = writeln!(
        out,
        "## Paprocki 2022, Table 2 — `ferrocat lab paprocki2022 --quick`\n\nHost {}. Second slave's SYNC0 minus the first's (ns).\n",
        rows(&pap)[0]["host"].as_str().unwrap_or("?")
    );
    table(
        &mut out,
        &["cycle µs", "method", "mean", "sd", "min", "max", "samples"],
        rows(&pap).iter().map(|r| {
            vec![
                r["cycle_us"].to_string(),
                r["method"].as_str().unwrap_or("?").into(),
                f(&r["mean_ns"], 1),
                f(&r["sd_ns"], 1),
                r["min_ns"].to_string(),
                r["max_ns"].to_string(),
                r["samples"].to_string(),
            ]
        }),
    );
    let unc = concat!(env!("CARGO_MANIFEST_DIR"), "/../../scenarios/paprocki2022-uncompensated.toml");
    let pap_model = run(&["lab", "run", unc]);
    let _ = writeln!(
        out,
        "## The papers' figures beside the set-up models

Every published figure beside the model's: Park's Table 1 \
         (`lab park2020 --quick`, GPI view; fitted on the 2-slave rows), Chen's Table 2 (`lab chen2016 --quick`, \
         chen2016, medians of 5 seeds of 120 000 cycles; fitted on the 500 µs latest frame), Paprocki's Table 2 \
         (`lab run scenarios/paprocki2022-uncompensated.toml`, the `none` rows; nothing fitted). Bands: fitted \
         ±20 % or ±0.3 µs, predicted ±30 % or ±0.5 µs, Paprocki's ns ±30 % alone (docs/lab.md).\n"
    );
    table(
        &mut out,
        &["paper", "figure", "part", "paper's", "model", "error", "band", "within"],
        [("Park 2020", &park), ("Chen 2016", &chen), ("Paprocki 2022", &pap_model)].into_iter().flat_map(
            |(paper, v)| {
                v["paper_comparison"].as_array().cloned().unwrap_or_default().into_iter().map(move |c| {
                    let unit = c["unit"].as_str().unwrap_or("").to_string();
                    vec![
                        paper.to_string(),
                        c["name"].as_str().unwrap_or("?").into(),
                        c["part"].as_str().unwrap_or("?").into(),
                        format!("{} {unit}", f(&c["paper"], 2)),
                        format!("{} {unit}", f(&c["model"], 2)),
                        format!("{} {unit}", f(&c["error"], 2)),
                        format!("±{} {unit}", f(&c["tolerance"], 2)),
                        if c["within"] == true { "yes".into() } else { "**no**".into() },
                    ]
                })
            },
        ),
    );
    let rob = run(&["lab", "robustness", "--quick"]);
    let _ = writeln!(
        out,
        "## Robustness — `ferrocat lab robustness --quick`\n\nHost {}; each disturbance once after {} s settling, {} s observed after. \
         Master − reference (ns): mean before, peak excursion, recovery into the band (ms), mean after.\n",
        rows(&rob)[0]["host"].as_str().unwrap_or("?"),
        rob["settle_s"],
        rob["after_s"]
    );
    table(
        &mut out,
        &["scenario", "method", "before mean", "band", "peak", "recovery ms", "after mean", "frames lost"],
        rows(&rob).iter().map(|r| {
            vec![
                r["scenario"].as_str().unwrap_or("?").into(),
                r["method"].as_str().unwrap_or("?").into(),
                f(&r["before_mean_ns"], 0),
                f(&r["band_ns"], 0),
                f(&r["peak_ns"], 0),
                f(&r["recovery_ms"], 0),
                f(&r["after_mean_ns"], 0),
                r["frames_lost"].to_string(),
            ]
        }),
    );
    let demo = run(&["demo"]);
    let d = &demo["demo"];
    let _ = writeln!(
        out,
        "## The CiA402 demo — `ferrocat demo`\n\n{} × {} behind EK1100, EL2004, EL1004; host {}. Err: master − reference \
         clock where the reference follows the master; phase: the reference's time at the master's \
         cycle start, off its grid, where the master follows (ns). SYNC0 Δ: second drive minus first (ns).\n",
        d["drives"],
        d["drive"].as_str().unwrap_or("?"),
        d["host"].as_str().unwrap_or("?")
    );
    table(
        &mut out,
        &[
            "cycle µs",
            "method",
            "err or phase mean",
            "rms",
            "SYNC0 Δ mean",
            "spread",
            "late",
            "repeated",
            "max FE",
            "enabled",
        ],
        demo["methods"].as_array().unwrap().iter().map(|r| {
            let phased = r["error_mean_ns"].is_null();
            let (mean, rms) = if phased {
                (&r["phase_mean_ns"], &r["phase_rms_ns"])
            } else {
                (&r["error_mean_ns"], &r["error_rms_ns"])
            };
            let enabled = r["axes"].as_array().map_or(0, |a| a.iter().filter(|x| x["enabled"] == true).count());
            vec![
                r["cycle_us"].to_string(),
                format!("{}{}", r["method"].as_str().unwrap_or("?"), if phased { " (phase)" } else { "" }),
                f(mean, 0),
                f(rms, 0),
                f(&r["sync0_mean_ns"], 1),
                r["sync0_spread_max_ns"].to_string(),
                r["late_setpoints"].to_string(),
                r["repeated_setpoints"].to_string(),
                f(&r["max_following_error"], 0),
                format!("{enabled}/{}", r["axes"].as_array().map_or(0, Vec::len)),
            ]
        }),
    );
    out.truncate(out.trim_end().len());
    out.push('\n');
    out
}

#[test]
fn docs_results_md_is_current() {
    let text = render();
    let path = concat!(env!("CARGO_MANIFEST_DIR"), "/../../docs/results.md");
    if std::env::var_os("FERROCAT_WRITE_RESULTS").is_some() {
        std::fs::write(path, &text).unwrap();
        println!("wrote {path}");
        return;
    }
    let committed = std::fs::read_to_string(path).unwrap_or_default();
    if committed != text {
        let line = committed
            .lines()
            .zip(text.lines())
            .position(|(a, b)| a != b)
            .unwrap_or(committed.lines().count().min(text.lines().count()));
        panic!(
            "docs/results.md is not what the code gives now (first difference at line {}):\n  committed: {:?}\n  now:       {:?}\nrun scripts/results.sh and commit the file with the change that moved the figures",
            line + 1,
            committed.lines().nth(line).unwrap_or(""),
            text.lines().nth(line).unwrap_or("")
        );
    }
}
