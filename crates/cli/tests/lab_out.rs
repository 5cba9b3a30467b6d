//! `ferrocat lab … --out DIR`: each experiment writes its CSV, its figures as SVG and PNG and a
//! Markdown report with the table.
use std::path::Path;
use std::process::Command;

mod figures;

/// Runs the experiment; it must say where it wrote what.
fn run(args: &[&str]) {
    let out = Command::new(env!("CARGO_BIN_EXE_ferrocat")).args(args).output().unwrap();
    let err = String::from_utf8_lossy(&out.stderr);
    assert!(out.status.success(), "{args:?}: {err}");
    let dir = args.last().unwrap();
    assert!(err.contains(&format!(" files to {dir}: ")), "{args:?} does not say where it wrote: {err}");
}

fn has(dir: &Path, file: &str, needle: &str) {
    let p = dir.join(file);
    let text = std::fs::read_to_string(&p).unwrap_or_else(|e| panic!("{}: {e}", p.display()));
    assert!(text.contains(needle), "{} lacks {needle:?}", p.display());
}

#[test]
fn every_experiment_writes_csv_figures_and_a_report() {
    let dir = std::env::temp_dir().join(format!("ferrocat-lab-out-{}", std::process::id()));
    let d = |s: &str| dir.join(s).to_str().unwrap().to_string();
    run(&["lab", "park2020", "--quick", "--slaves", "2", "--rounds", "1", "--out", &d("park")]);
    let park = dir.join("park");
    has(&park, "park2020.md", "| 2 | conventional |");
    has(&park, "park2020.md", "| 2 slaves, park2020, ref GMEAN | fit |");
    has(&park, "park2020.csv", "slaves,method");
    for f in ["fig8-2slaves-park2020.svg", "fig9-2slaves-ferrocat.svg", "fig10-2slaves-conventional.svg"] {
        has(&park, f, "<svg");
    }
    has(&park, "fig11-2slaves-ferrocat.svg", "RMS");
    for f in ["fig8-2slaves-ferrocat.png", "fig11-2slaves-park2020.png"] {
        figures::assert_chart_png(&park.join(f));
    }
    run(&["lab", "chen2016", "--quick", "--cycle-us", "500", "--out", &d("chen")]);
    let chen = dir.join("chen");
    has(&chen, "chen2016.md", "| 500 | chen2016 |");
    has(&chen, "chen2016.md", "| 500 µs, latest frame | fit |");
    has(&chen, "chen2016.csv", "500,pi,");
    has(&chen, "fig12-jitter-500us.svg", "<svg");
    has(&chen, "fig12-period-500us.svg", "chen2016");
    figures::assert_chart_png(&chen.join("fig12-jitter-500us.png"));
    run(&["lab", "paprocki2022", "--out", &d("pap")]);
    has(&dir.join("pap"), "paprocki2022.md", "| 1000 | ferrocat |");
    has(&dir.join("pap"), "paprocki2022.md", "Not held against the paper's Table 2");
    run(&["lab", "paprocki2022", "--quick", "--uncompensated-drive-delay", "--out", &d("pap-paper")]);
    has(&dir.join("pap-paper"), "paprocki2022.md", "| 1000 µs, mean | prediction |");
    has(&dir.join("pap"), "paprocki2022.csv", "cycle_us,method");
    has(&dir.join("pap"), "table2-sync0-1000us.svg", "ferrocat");
    figures::assert_chart_png(&dir.join("pap").join("table2-sync0-500us.png"));
    run(&["lab", "robustness", "--out", &d("rob")]);
    has(&dir.join("rob"), "robustness.md", "| drift-step-50ppm | ferrocat |");
    for sc in ["control", "loss-1pct", "drift-step-50ppm", "overrun-3-cycles"] {
        figures::assert_chart_png(&dir.join("rob").join(format!("robustness-{sc}.png")));
    }
    let _ = std::fs::remove_dir_all(&dir);
}

/// `lab robustness` prints a table that splits into its 16 columns on white space, header and
/// rows alike, and the control rows (no disturbance) show no recovery or relock time.
#[test]
fn the_robustness_table_splits_into_columns() {
    let out = Command::new(env!("CARGO_BIN_EXE_ferrocat")).args(["lab", "robustness"]).output().unwrap();
    assert!(out.status.success(), "{}", String::from_utf8_lossy(&out.stderr));
    let text = String::from_utf8_lossy(&out.stdout);
    let rows: Vec<Vec<&str>> = text.lines().skip(1).map(|l| l.split_whitespace().collect()).collect();
    assert!(rows.len() > 8, "{text}");
    assert!(rows.iter().all(|r| r.len() == 16), "{text}");
    let col = |name: &str| rows[0].iter().position(|h| *h == name).unwrap_or_else(|| panic!("no {name}: {text}"));
    let (recovery, relock) = (col("recovery_ms"), col("relock_ms"));
    for r in rows.iter().skip(1) {
        let control = r[0] == "control";
        assert_eq!(control, r[recovery] == "—", "{r:?}");
        assert!(!control || r[relock] == "—", "{r:?}");
    }
}

/// `--json` carries the paper's figures beside the set-up model's; `--fit` prints the fit, and
/// only where the experiment has a fitted model.
#[test]
fn the_papers_figures_and_the_fit_are_in_json() {
    let json = |args: &[&str]| -> serde_json::Value {
        let out = Command::new(env!("CARGO_BIN_EXE_ferrocat")).args(args).output().unwrap();
        assert!(out.status.success(), "{args:?}: {}", String::from_utf8_lossy(&out.stderr));
        serde_json::from_slice(&out.stdout).unwrap()
    };
    let v = json(&["lab", "park2020", "--quick", "--slaves", "2", "--rounds", "1", "--json"]);
    let figures = v["paper_comparison"].as_array().unwrap();
    // The 2-slave rows of conventional and park2020, four figures each, all fitted.
    assert_eq!(figures.len(), 8, "{v}");
    assert!(figures.iter().all(|f| f["part"] == "fit" && f["within"].is_boolean()), "{v}");
    assert!(v["setup_model"]["send_mean_ns"].as_f64().is_some_and(|x| x > 0.0), "{v}");
    // On another host there is no model to compare with.
    let v = json(&["lab", "park2020", "--quick", "--slaves", "2", "--rounds", "1", "--host", "pc-rt", "--json"]);
    assert!(v["paper_comparison"].is_null() && v["setup_model"].is_null(), "{v}");
    // The preset is the fit's fixed point: one step.
    let v = json(&["lab", "park2020", "--quick", "--fit", "--json"]);
    assert_eq!(v["steps"].as_array().map(Vec::len), Some(1), "{v}");
    let out = Command::new(env!("CARGO_BIN_EXE_ferrocat")).args(["lab", "robustness", "--fit"]).output().unwrap();
    let err = String::from_utf8_lossy(&out.stderr);
    assert!(!out.status.success() && err.contains("unexpected argument '--fit'"), "{err}");
}

/// The reports read as what they are: a compensated Paprocki run is not set beside the
/// paper's uncompensated figures, Park's columns are explained, every table has a header, and
/// no source path reaches the user.
#[test]
fn the_reports_say_what_their_figures_are() {
    let text = |args: &[&str]| {
        let out = Command::new(env!("CARGO_BIN_EXE_ferrocat")).args(args).output().unwrap();
        assert!(out.status.success(), "{args:?}: {}", String::from_utf8_lossy(&out.stderr));
        String::from_utf8_lossy(&out.stdout).into_owned()
    };
    let pap = text(&["lab", "paprocki2022", "--quick"]);
    assert!(!pap.contains("MISSES") && pap.contains("Not held against the paper's Table 2"), "{pap}");
    let paper = text(&["lab", "paprocki2022", "--quick", "--uncompensated-drive-delay"]);
    assert!(paper.contains("figures within their bands"), "{paper}");
    let park = text(&["lab", "park2020", "--quick", "--slaves", "2", "--rounds", "1"]);
    assert!(park.contains("GMEAN: the mean of the rounds' mean errors") && park.contains("MRMS: the mean"), "{park}");
    let lines: Vec<&str> = park.lines().collect();
    let gpi = lines.iter().position(|l| l.starts_with("estimated from 1 000 measurements")).unwrap();
    assert!(lines[gpi + 1].split_whitespace().take(2).eq(["slaves", "method"]), "the GPI table's header: {park}");
    assert!(!park.contains("crates/") && !park.contains(".rs"), "{park}");
}

/// Each experiment takes its own flags: another's is refused by name, and `lab run` takes its
/// scenario once, as its argument.
#[test]
fn an_experiment_refuses_another_experiments_flags() {
    for (args, flag) in [
        (&["lab", "park2020", "--uncompensated-drive-delay"][..], "--uncompensated-drive-delay"),
        (&["lab", "paprocki2022", "--rounds", "2"], "--rounds"),
        (&["lab", "chen2016", "--no-gpio-calibration"], "--no-gpio-calibration"),
        (&["lab", "run", "scenarios/park2020.toml", "--scenario", "x.toml"], "--scenario"),
    ] {
        let out = Command::new(env!("CARGO_BIN_EXE_ferrocat")).args(args).output().unwrap();
        let err = String::from_utf8_lossy(&out.stderr);
        assert!(!out.status.success() && err.contains(&format!("unexpected argument '{flag}'")), "{args:?}: {err}");
    }
    let out = Command::new(env!("CARGO_BIN_EXE_ferrocat")).args(["lab", "park2020", "--help"]).output().unwrap();
    let help = String::from_utf8_lossy(&out.stdout);
    assert!(
        !help.contains("chen2016") && !help.contains("paprocki2022:") && !help.contains("--uncompensated"),
        "{help}"
    );
}
