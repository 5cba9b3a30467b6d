//! `ferrocat lab …`: the papers' experiments in virtual time.
use std::io::IsTerminal;
use std::path::Path;
use std::process::ExitCode;

use ferrocat_lab::park2020::{self, Options, Row, PAPER};
use ferrocat_lab::scenario::Plan;

use crate::outln;
use crate::report::write as write_report;

/// A one-line counter on stderr, when it is a terminal.
fn progress(unit: &'static str) -> impl Fn(usize, usize) + Sync {
    let tty = std::io::stderr().is_terminal();
    move |done, total| {
        if tty {
            eprint!("\r  {done}/{total} {unit}");
            if done == total {
                eprintln!();
            }
        }
    }
}

pub fn host(name: &str) -> anyhow::Result<ferrocat_segment::HostModel> {
    use ferrocat_segment::HostModel;
    HostModel::preset(name)
        .ok_or_else(|| anyhow::anyhow!("unknown host model {name:?} (known: {})", HostModel::PRESETS.join(", ")))
}

/// An experiment as planned from its scenario and flags: run, print, and write `out`.
pub fn run(plan: Plan, json: bool, out: Option<&Path>) -> anyhow::Result<ExitCode> {
    if let Some(dir) = out {
        crate::report::check_out_dir(dir)?;
    }
    let code = match plan {
        Plan::Park2020(o) => park2020(o, json, out),
        Plan::Chen2016(o) => chen2016(o, json, out),
        Plan::Paprocki2022(o) => paprocki2022(o, json, out),
        Plan::Robustness(o) => robustness(o, json, out),
    }?;
    if let Some(dir) = out {
        crate::report::announce(dir)?;
    }
    Ok(code)
}

/// The experiment's set-up model fitted afresh from the presets, every step printed.
pub fn fit(plan: Plan, json: bool) -> anyhow::Result<ExitCode> {
    match plan {
        Plan::Park2020(o) => {
            let steps = park2020::fit(&o, park2020::SetupModel::current(), 8)?;
            if json {
                outln!("{}", serde_json::json!({ "experiment": "park2020", "seed": o.seed, "steps": steps }));
                return Ok(ExitCode::SUCCESS);
            }
            outln!(
                "Park 2020 set-up model fitted on Table 1's 2-slave rows (GPI view), {} rounds of {} samples after {} s, seed {}",
                o.rounds,
                o.samples,
                o.settle_s,
                o.seed
            );
            outln!(
                "{:>4} {:>12} {:>12} {:>14}   {:>17} {:>17} {:>17}",
                "step",
                "send µs",
                "receive µs",
                "GPI spread µs",
                "conv GMEAN err µs",
                "park GMEAN err µs",
                "conv spread err µs"
            );
            for (k, s) in steps.iter().enumerate() {
                outln!(
                    "{k:>4} {:>12.3} {:>12.3} {:>14.3}   {:>+17.3} {:>+17.3} {:>+17.3}",
                    s.model.send_mean_ns / 1e3,
                    s.model.recv_mean_ns / 1e3,
                    s.model.gpi_master_detect_sd_ns / 1e3,
                    s.conventional_gmean_error_us,
                    s.park2020_gmean_error_us,
                    s.conventional_spread_error_us
                );
            }
            Ok(ExitCode::SUCCESS)
        }
        Plan::Chen2016(o) => {
            use ferrocat_lab::chen2016::{self as chen, SetupModel};
            let steps = chen::fit(o.seed, SetupModel::current(), 6)?;
            if json {
                outln!("{}", serde_json::json!({ "experiment": "chen2016", "seed": o.seed, "steps": steps }));
                return Ok(ExitCode::SUCCESS);
            }
            outln!(
                "Chen 2016 set-up model fitted on Table 2's 500 µs latest frame (56.00 µs), medians of {} seeds from {}, {} cycles per run",
                chen::MODEL_SEEDS,
                o.seed,
                chen::MODEL_CYCLES
            );
            outln!("{:>4} {:>22} {:>22}", "step", "late wake-up up to µs", "latest frame error µs");
            for (k, s) in steps.iter().enumerate() {
                outln!("{k:>4} {:>22.2} {:>+22.2}", s.model.wake_outlier_ns / 1e3, s.late_500us_error_us);
            }
            Ok(ExitCode::SUCCESS)
        }
        Plan::Paprocki2022(_) | Plan::Robustness(_) => {
            anyhow::bail!("--fit: only park2020 and chen2016 have set-up models fitted on their papers' tables")
        }
    }
}

fn park2020(o: Options, json: bool, out: Option<&Path>) -> anyhow::Result<ExitCode> {
    let host = o.host;
    let rows = park2020::run(&o, &progress("rounds"))?;
    if let Some(dir) = out {
        write_report(dir, "park2020.csv", &crate::report::csv_of(&rows))?;
        park_figures(dir, &rows)?;
        let mut md = format!(
            "# Park 2020, Table 1\n\nHost `{}`, seed {}, {} rounds, {} samples every {} ms after {} s of settling; \
             error = master − slave clock (true times from the simulator), µs.\n\n\
             | slaves | method | ref GMEAN | ref MRMS | last GMEAN | last MRMS | lock ms | init ms | GPIO calibration | GPI ref GMEAN/MRMS | GPI last GMEAN/MRMS | paper ref GMEAN/MRMS |\n|---|---|---|---|---|---|---|---|---|---|---|---|\n",
            host.name, o.seed, o.rounds, o.samples, o.sample_every * o.cycle_ns / 1_000_000, o.settle_s
        );
        for r in &rows {
            let paper = PAPER
                .iter()
                .find(|p| p.0 == r.slaves && p.1 == r.method)
                .map(|p| format!("{:.2} / {:.2}", p.2, p.3))
                .unwrap_or_else(|| "—".into());
            let lock = r.lock_ms.map(|l| format!("{l:.0}")).unwrap_or_else(|| "never".into());
            let cal = r.calibration_us.map(|c| format!("{c:+.3}")).unwrap_or_else(|| "—".into());
            md.push_str(&format!(
                "| {} | {} | {:.3} | {:.3} | {:.3} | {:.3} | {lock} | {:.0} | {cal} | {:.3} / {:.3} | {:.3} / {:.3} | {paper} |\n",
                r.slaves,
                r.method,
                r.ref_gmean_us,
                r.ref_mrms_us,
                r.last_gmean_us,
                r.last_mrms_us,
                r.init_ms,
                r.gpi_ref_gmean_us,
                r.gpi_ref_mrms_us,
                r.gpi_last_gmean_us,
                r.gpi_last_mrms_us
            ));
        }
        md.push_str(
            "\nFigures (first round): `fig8-*` and `fig9-*` histograms of the master–reference and \
             master–last-slave errors, `fig10-*` and `fig11-*` their mean and RMS up to each sample; CSV in \
             `park2020.csv`.\n",
        );
        if park2020::paper_setup(&o).is_ok() {
            md.push_str(&figures_md("Table 1 against the set-up model (GPI view)", &park2020::compare(&rows)));
        }
        write_report(dir, "park2020.md", &md)?;
    }
    if json {
        let (model, figures) = match park2020::paper_setup(&o) {
            Ok(m) => (Some(m), Some(park2020::compare(&rows))),
            Err(_) => (None, None),
        };
        let v = serde_json::json!({ "experiment": "park2020", "seed": o.seed, "rounds": o.rounds,
            "settle_s": o.settle_s, "samples": o.samples, "rows": rows,
            "setup_model": model, "paper_comparison": figures });
        outln!("{v}");
        return Ok(ExitCode::SUCCESS);
    }
    outln!(
        "Park 2020 Table 1 — host {}, seed {}, {} rounds, {} samples every {} ms after {} s; error = master − slave, µs",
        host.name,
        o.seed,
        o.rounds,
        o.samples,
        o.sample_every * o.cycle_ns / 1_000_000,
        o.settle_s
    );
    outln!(
        "{:>6}  {:<13} {:>9} {:>9} {:>9} {:>9} {:>10} {:>8}   paper: {:>7} {:>7} {:>7} {:>7}",
        "slaves",
        "method",
        "ref GMEAN",
        "ref MRMS",
        "lastGMEAN",
        "last MRMS",
        "lock ms",
        "init ms",
        "rGMEAN",
        "rMRMS",
        "lGMEAN",
        "lMRMS"
    );
    for r in &rows {
        let paper = PAPER
            .iter()
            .find(|p| p.0 == r.slaves && p.1 == r.method)
            .map(|p| format!("{:>7.2} {:>7.2} {:>7.2} {:>7.2}", p.2, p.3, p.4, p.5))
            .unwrap_or_else(|| format!("{:>7} {:>7} {:>7} {:>7}", "—", "—", "—", "—"));
        let lock = r.lock_ms.map(|l| format!("{l:.0}")).unwrap_or_else(|| "never".into());
        outln!(
            "{:>6}  {:<13} {:>9.3} {:>9.3} {:>9.3} {:>9.3} {:>10} {:>8.0}   paper: {paper}",
            r.slaves,
            r.method,
            r.ref_gmean_us,
            r.ref_mrms_us,
            r.last_gmean_us,
            r.last_mrms_us,
            lock,
            r.init_ms
        );
    }
    let calibrated: Vec<String> = rows
        .iter()
        .filter_map(|r| r.calibration_us.map(|c| format!("{} slaves {} {c:+.3}", r.slaves, r.method)))
        .collect();
    if !calibrated.is_empty() {
        outln!(
            "Calibrated through the host's GPIO into the reference's LATCH0 (master − reference error found and taken out, µs): {}",
            calibrated.join(", ")
        );
    }
    outln!("{PARK_LEGEND}");
    outln!(
        "As Park's GPI measurement (§IV-B) would have reported the same runs (latencies drawn per sample, their means"
    );
    outln!("estimated from 1 000 measurements and subtracted; docs/lab.md), µs:");
    outln!(
        "{:>6}  {:<13} {:>9} {:>9} {:>9} {:>9}",
        "slaves",
        "method",
        "ref GMEAN",
        "ref MRMS",
        "lastGMEAN",
        "last MRMS"
    );
    for r in &rows {
        outln!(
            "{:>6}  {:<13} {:>9.3} {:>9.3} {:>9.3} {:>9.3}",
            r.slaves,
            r.method,
            r.gpi_ref_gmean_us,
            r.gpi_ref_mrms_us,
            r.gpi_last_gmean_us,
            r.gpi_last_mrms_us
        );
    }
    match park2020::paper_setup(&o) {
        Ok(model) => {
            let m = model;
            outln!(
                "Table 1 against the set-up model (send path {:.2} µs, receive path {:.2} µs, GPI detection spread {:.2} µs; \
                 docs/lab.md), as the GPI measurement reports it:",
                m.send_mean_ns / 1e3,
                m.recv_mean_ns / 1e3,
                m.gpi_master_detect_sd_ns / 1e3
            );
            print_figures(&park2020::compare(&rows), "µs");
        }
        Err(why) => outln!("Table 1 is compared only on the paper's set-up model: {why}."),
    }
    Ok(ExitCode::SUCCESS)
}

/// What Table 1's columns mean.
const PARK_LEGEND: &str = "ref: master − reference clock; last: master − last slave; GMEAN: the mean of the \
rounds' mean errors; MRMS: the mean of the rounds' RMS errors (Park 2020's Table 1); lock ms: from the start \
of cyclic operation until every slave stays within 100 ns of the reference and the master within 1 µs; \
init ms: the DC initialisation's static drift compensation; paper: rGMEAN, rMRMS, lGMEAN, lMRMS the same \
columns as Park 2020 published them.";

/// A paper's figures beside the set-up model's as a Markdown section, for `--out` reports.
fn figures_md(title: &str, figures: &[ferrocat_lab::fit::Figure]) -> String {
    let mut md = format!(
        "\n## {title}\n\n| figure | part | paper | model | error | error % | band | within |\n|---|---|---|---|---|---|---|---|\n"
    );
    for f in figures {
        let part = f.part.as_str();
        let pct = f.error_pct.map(|p| format!("{p:+.1}")).unwrap_or_else(|| "—".into());
        md.push_str(&format!(
            "| {} | {part} | {:.2} {u} | {:.2} {u} | {:+.2} {u} | {pct} | ±{:.2} {u} | {} |\n",
            f.name,
            f.paper,
            f.model,
            f.error,
            f.tolerance,
            if f.within { "yes" } else { "**no**" },
            u = f.unit
        ));
    }
    md
}

/// A paper's figures beside the set-up model's, and which miss their bands.
fn print_figures(figures: &[ferrocat_lab::fit::Figure], unit: &str) {
    outln!("{}", ferrocat_lab::fit::Figure::header(unit));
    for f in figures {
        outln!("{}", f.line());
    }
    outln!(
        "part: fit (a figure the set-up model was fitted on) or prediction (one it was not); band: how far the \
         model's figure may lie from the paper's and still be within (docs/lab.md)"
    );
    let misses = ferrocat_lab::fit::misses(figures);
    outln!(
        "{} of {} figures within their bands{}",
        figures.len() - misses.len(),
        figures.len(),
        if misses.is_empty() { String::new() } else { format!("; missing: {}", misses.join("; ")) }
    );
}

/// Park 2020 Figures 8–11 for the first round of every (slaves, method).
fn park_figures(dir: &Path, rows: &[Row]) -> anyhow::Result<()> {
    use crate::plots::{histogram, line_chart, running_mean_rms, Series};
    for r in rows {
        for (fig, whom, samples) in [(8, "reference", &r.ref_samples_us), (9, "last slave", &r.last_samples_us)] {
            // Whole ns, as measured (the f32 µs carry a little rounding).
            let v: Vec<f64> = samples.iter().map(|&x| (x as f64 * 1e3).round() / 1e3).collect();
            if v.is_empty() {
                continue;
            }
            let (lo, hi) = v.iter().fold((f64::INFINITY, f64::NEG_INFINITY), |(a, b), &x| (a.min(x), b.max(x)));
            let tag = format!("{}slaves-{}", r.slaves, r.method);
            line_chart(
                &dir.join(format!("fig{fig}-{tag}")),
                &format!("Master–{whom} error, {} slaves, {} ({} samples)", r.slaves, r.method, v.len()),
                "error (µs)",
                "share of samples (%)",
                &[Series::new(r.method.clone(), histogram(&v, lo, hi, 100, 1e-3))],
            )?;
            let (mean, rms) = running_mean_rms(&v, 2000);
            line_chart(
                &dir.join(format!("fig{}-{tag}", fig + 2)),
                &format!(
                    "Mean and RMS of the master–{whom} error up to each sample, {} slaves, {}",
                    r.slaves, r.method
                ),
                "sample",
                "µs",
                &[Series::new("mean", mean), Series::new("RMS", rms)],
            )?;
        }
    }
    Ok(())
}

fn chen2016(o: ferrocat_lab::chen2016::Options, json: bool, out: Option<&Path>) -> anyhow::Result<ExitCode> {
    use ferrocat_lab::chen2016::{run, Table, PAPER};
    let host = o.host;
    let Table { setup, rows } = run(&o, &progress("runs"))?;
    let model = match ferrocat_lab::chen2016::paper_setup(&o) {
        Ok(m) => Ok((m, ferrocat_lab::chen2016::model_rows(o.host, o.seed)?)),
        Err(why) => Err(why),
    };
    if let Some(dir) = out {
        let figures = model.as_ref().ok().map(|(_, m)| ferrocat_lab::chen2016::compare(m));
        chen_outputs(dir, &o, &setup, &rows, figures.as_deref())?;
    }
    if json {
        let (setup_model, model_rows, figures) = match &model {
            Ok((m, rows)) => (Some(m), Some(rows), Some(ferrocat_lab::chen2016::compare(rows))),
            Err(_) => (None, None, None),
        };
        let v = serde_json::json!({ "experiment": "chen2016", "seed": o.seed, "seconds": o.seconds,
            "reference_ppm": setup.reference_ppm, "counted_slaves": setup.counted_slaves, "rows": rows,
            "setup_model": setup_model, "model_rows": model_rows, "paper_comparison": figures });
        outln!("{v}");
        return Ok(ExitCode::SUCCESS);
    }
    outln!(
        "Chen 2016 Table 2 — host {}, seed {}, {} s per run, reference crystal {:+} ppm; jitter of the reference's time against the master's grid;",
        host.name, o.seed, o.seconds, setup.reference_ppm
    );
    outln!(
        "lost and repeated: the cycles of the DC-synchronous slaves with outputs, at positions {:?}",
        setup.counted_slaves
    );
    outln!(
        "{:>6}  {:<9} {:>10} {:>10} {:>8} {:>7} {:>9} {:>6} {:>8}   paper: {:>7} {:>7} {:>6} {:>5}",
        "cycle",
        "method",
        "min µs",
        "max µs",
        "width %",
        "sd µs",
        "cycles",
        "lost",
        "repeated",
        "min",
        "max",
        "width",
        "loss"
    );
    for r in &rows {
        let paper = PAPER
            .iter()
            .find(|p| p.0 == r.cycle_us && r.method == "chen2016")
            .map(|p| format!("{:>7.2} {:>7.2} {:>6.1} {:>5}", p.1, p.2, p.3, p.4))
            .unwrap_or_default();
        // The header's column widths, from min µs to repeated.
        let cells: Vec<String> =
            r.figures().iter().zip([10, 10, 8, 7, 9, 6, 8]).map(|(f, w)| format!("{f:>w$}")).collect();
        outln!(
            "{:>4}µs  {:<9} {}   {}{paper}",
            r.cycle_us,
            r.method,
            cells.join(" "),
            if paper.is_empty() { "" } else { "paper: " }
        );
    }
    match model {
        Ok((m, model_rows)) => {
            outln!(
                "Table 2 against the set-up model (late wake-ups up to {:.2} µs; chen2016, medians of {} seeds from {}, {} cycles \
                 per run; docs/lab.md).",
                m.wake_outlier_ns / 1e3,
                ferrocat_lab::chen2016::MODEL_SEEDS,
                o.seed,
                ferrocat_lab::chen2016::MODEL_CYCLES
            );
            outln!(
                "The paper's jitter is grid − reference, its Min. the largest value, Max. the smallest; here reference − grid:"
            );
            print_figures(&ferrocat_lab::chen2016::compare(&model_rows), "");
        }
        Err(why) => outln!("Table 2 is compared only on the paper's set-up model: {why}."),
    }
    Ok(ExitCode::SUCCESS)
}

/// Chen 2016: CSV, Figure 12 (the reference's jitter and the master's period per cycle, every
/// method) and a Markdown report.
fn chen_outputs(
    dir: &Path,
    o: &ferrocat_lab::chen2016::Options,
    setup: &ferrocat_lab::chen2016::Setup,
    rows: &[ferrocat_lab::chen2016::Row],
    figures: Option<&[ferrocat_lab::fit::Figure]>,
) -> anyhow::Result<()> {
    use crate::plots::{panel_chart, Series};
    crate::report::make_dir(dir)?;
    let mut md = format!(
        "# Chen 2016, Table 2\n\nHost `{}`, seed {}, {} s per run, reference crystal {:+} ppm; lost and repeated \
         cycles of the DC-synchronous slaves with outputs, at positions {:?}.\n\n\
         | cycle µs | method | jitter min µs | max µs | width % | sd µs | cycles | lost | repeated | paper (chen2016) |\n|---|---|---|---|---|---|---|---|---|---|\n",
        o.host.name, o.seed, o.seconds, setup.reference_ppm, setup.counted_slaves
    );
    for r in rows {
        let paper = ferrocat_lab::chen2016::PAPER
            .iter()
            .find(|p| p.0 == r.cycle_us && r.method == "chen2016")
            .map(|p| format!("{:.2} / {:.2} µs, {:.1} %, loss {}", p.1, p.2, p.3, p.4))
            .unwrap_or_else(|| "—".into());
        md.push_str(&format!("| {} | {} | {} | {paper} |\n", r.cycle_us, r.method, r.figures().join(" | ")));
    }
    write_report(dir, "chen2016.csv", &crate::report::csv_of(rows))?;
    for &c in &o.cycles_us {
        let of: Vec<_> = rows.iter().filter(|r| r.cycle_us == c).collect();
        let series = |f: &dyn Fn(&(u64, f64, f64)) -> f64| -> Vec<Series> {
            of.iter()
                .map(|r| Series::new(r.method.clone(), r.trace.iter().map(|p| (p.0 as f64, f(p))).collect()))
                .collect()
        };
        // A panel per method: in one chart their traces overlap and hide one another.
        panel_chart(
            &dir.join(format!("fig12-jitter-{c}us")),
            &format!("Reference time against the master's grid, {c} µs cycle"),
            "master cycle",
            "µs",
            &series(&|p| p.1),
        )?;
        panel_chart(
            &dir.join(format!("fig12-period-{c}us")),
            &format!("The master's cycle period, {c} µs nominal"),
            "master cycle",
            "µs",
            &series(&|p| p.2),
        )?;
    }
    md.push_str("\nFigure 12: `fig12-jitter-*` (the reference's timestamps against the master's cycle grid) and `fig12-period-*` (the master's period, its speed relative to the reference); CSV in `chen2016.csv`.\n");
    if let Some(f) = figures {
        md.push_str(&figures_md(
            "Table 2 against the set-up model (chen2016, medians of 5 seeds; reference − grid: the paper's Min. is the earliest frame and its Max. the latest, signs reversed)",
            f,
        ));
    }
    write_report(dir, "chen2016.md", &md)
}

/// Why a compensated Paprocki run is not held against the paper's figures.
const PAPER_SETUP_NOTE: &str = "Not held against the paper's Table 2: this run compensates the second drive's \
propagation delay, and the paper's set-up does not (its ≈ 0.8 µs constant). \
`--uncompensated-drive-delay` (or `lab run scenarios/paprocki2022-uncompensated.toml`) runs the paper's set-up \
and compares every figure.";

fn paprocki2022(o: ferrocat_lab::paprocki2022::Options, json: bool, out: Option<&Path>) -> anyhow::Result<ExitCode> {
    use ferrocat_lab::paprocki2022::{run, PAPER};
    let host = o.host;
    let rows = run(&o)?;
    // The paper's drives leave the second one's delay uncompensated; a compensated run is
    // another set-up, and its rows beside the paper's figures would only read as misses.
    let compared = if o.drive_delay_compensated { None } else { ferrocat_lab::paprocki2022::compared_method(&rows) };
    if let Some(dir) = out {
        let mut md = format!(
            "# Paprocki 2022, Table 2\n\nHost `{}`, seed {}, {} SYNC0 pulses after {} s; second slave's SYNC0 minus the \
             first's (true times), ns.\n\n| cycle µs | method | mean | max | min | sd | paper mean / max / min / sd |\n|---|---|---|---|---|---|---|\n",
            host.name, o.seed, o.samples, o.settle_s
        );
        for r in &rows {
            let p = PAPER
                .iter()
                .find(|p| p.0 == r.cycle_us)
                .map(|p| format!("{} / {} / {} / {}", p.1, p.2, p.3, p.4))
                .unwrap_or_else(|| "—".into());
            md.push_str(&format!(
                "| {} | {} | {:.1} | {} | {} | {:.1} | {p} |\n",
                r.cycle_us, r.method, r.mean_ns, r.max_ns, r.min_ns, r.sd_ns
            ));
        }
        match compared {
            Some(m) => {
                let title = format!("Table 2 beside this run's {m} rows");
                md.push_str(&figures_md(&title, &ferrocat_lab::paprocki2022::compare(&rows, m)));
            }
            None => md.push_str(&format!("\n{PAPER_SETUP_NOTE}\n")),
        }
        write_report(dir, "paprocki2022.md", &md)?;
        write_report(dir, "paprocki2022.csv", &crate::report::csv_of(&rows))?;
        // The distribution of the difference, a panel per method (their spreads differ by an
        // order of magnitude).
        for &c in &o.cycles_us {
            let series: Vec<crate::plots::Series> = rows
                .iter()
                .filter(|r| r.cycle_us == c && !r.diffs_ns.0.is_empty())
                .map(|r| {
                    let v: Vec<f64> = r.diffs_ns.0.iter().map(|&(_, d)| d).collect();
                    let (lo, hi) = v.iter().fold((f64::INFINITY, f64::NEG_INFINITY), |(a, b), &x| (a.min(x), b.max(x)));
                    crate::plots::Series::new(r.method.clone(), crate::plots::histogram(&v, lo, hi, 60, 1.0))
                })
                .collect();
            crate::plots::panel_chart(
                &dir.join(format!("table2-sync0-{c}us")),
                &format!("Second slave's SYNC0 minus the first's, {c} µs cycle"),
                "ns",
                "% of pulses",
                &series,
            )?;
        }
    }
    if json {
        let figures = compared.map(|m| ferrocat_lab::paprocki2022::compare(&rows, m));
        let v = serde_json::json!({ "experiment": "paprocki2022", "seed": o.seed, "settle_s": o.settle_s, "rows": rows,
            "compared_method": compared, "paper_comparison": figures });
        outln!("{v}");
        return Ok(ExitCode::SUCCESS);
    }
    outln!(
        "Paprocki 2022 Table 2 — host {}, seed {}, {} SYNC0 pulses after {} s; second slave's SYNC0 minus the first's, ns",
        host.name, o.seed, o.samples, o.settle_s
    );
    outln!(
        "{:>6}  {:<13} {:>8} {:>6} {:>6} {:>6}   paper: {:>6} {:>6} {:>6} {:>6}",
        "cycle",
        "method",
        "mean",
        "max",
        "min",
        "sd",
        "mean",
        "max",
        "min",
        "sd"
    );
    for r in &rows {
        let p = PAPER
            .iter()
            .find(|p| p.0 == r.cycle_us)
            .map(|p| format!("{:>6.1} {:>6.1} {:>6.1} {:>6.3}", p.1, p.2, p.3, p.4))
            .unwrap_or_default();
        outln!(
            "{:>4}µs  {:<13} {:>8.1} {:>6} {:>6} {:>6.1}   paper: {p}",
            r.cycle_us,
            r.method,
            r.mean_ns,
            r.max_ns,
            r.min_ns,
            r.sd_ns
        );
    }
    match compared {
        Some(m) => {
            outln!("Table 2 beside this run's {m} rows (the paper's set-up: the second drive's delay uncompensated; nothing fitted; docs/lab.md):");
            print_figures(&ferrocat_lab::paprocki2022::compare(&rows, m), "ns");
        }
        None => outln!("{PAPER_SETUP_NOTE}"),
    }
    Ok(ExitCode::SUCCESS)
}

fn robustness(o: ferrocat_lab::robustness::Options, json: bool, out: Option<&Path>) -> anyhow::Result<ExitCode> {
    use ferrocat_lab::robustness::run;
    let host = o.host;
    let rows = run(&o)?;
    if let Some(dir) = out {
        write_report(dir, "robustness.csv", &crate::report::csv_of(&rows))?;
        let mut md = format!(
            "# Robustness\n\nHost `{}`, seed {}, {} slaves, {} µs cycle; one disturbance after {} s of settling, {} s \
             measured after it; error = master − reference (true times), ns. Band: the mean before ± max(4 sd, 100 ns). \
             vs control: paired with the same method undisturbed (scenario control, the same realisation until the \
             disturbance), until the error stayed within the band's half-width of the control's for good, and the \
             largest distance from it. Relock: until every slave stays within 100 ns of the reference and the master within 1 µs \
             (unlocked: not locked before the disturbance). Made up: lost frames ferrocat replaced at once. Probes: \
             ferrocat's extra reads of the reference after the disturbance.\n\n\
             | disturbance | method | mean before | sd | band | peak | recovery ms | vs control ms | peak vs control | \
             relock ms | outside % | mean after | RMS after | frames lost | made up | probes |\n\
             |---|---|---|---|---|---|---|---|---|---|---|---|---|---|---|---|\n",
            host.name, o.seed, o.slaves, o.cycle_ns / 1000, o.settle_s, o.after_s
        );
        for r in &rows {
            md.push_str(&format!("| {} |\n", robustness_cells(r).join(" | ")));
        }
        write_report(dir, "robustness.md", &md)?;
        // Each disturbance's error around it, a panel per method.
        let mut scenarios: Vec<&str> = rows.iter().map(|r| r.scenario.as_str()).collect();
        scenarios.dedup();
        for sc in scenarios {
            let series: Vec<crate::plots::Series> = rows
                .iter()
                .filter(|r| r.scenario == sc)
                .map(|r| crate::plots::Series::new(r.method.clone(), r.trace.0.clone()))
                .collect();
            crate::plots::panel_chart(
                &dir.join(format!("robustness-{sc}")),
                &format!("Master − reference around the disturbance: {sc}"),
                "ms from the disturbance",
                "ns",
                &series,
            )?;
        }
    }
    if json {
        let v = serde_json::json!({ "experiment": "robustness", "seed": o.seed, "settle_s": o.settle_s,
            "after_s": o.after_s, "rows": rows });
        outln!("{v}");
        return Ok(ExitCode::SUCCESS);
    }
    outln!(
        "Robustness — host {}, seed {}, {} slaves, {} µs; one disturbance after {} s, {} s measured; error = master − reference, ns",
        host.name, o.seed, o.slaves, o.cycle_ns / 1000, o.settle_s, o.after_s
    );
    // One token per header, so that the table splits into columns on white space; each column
    // as wide as its header or the widest value it usually holds.
    let head = [
        "scenario",
        "method",
        "before_ns",
        "sd_ns",
        "band_ns",
        "peak_ns",
        "recovery_ms",
        "vs_ctrl_ms",
        "peak_vs_ctrl_ns",
        "relock_ms",
        "outside_pct",
        "after_ns",
        "after_rms_ns",
        "lost",
        "made_up",
        "probes",
    ];
    let min: [usize; 16] = [18, 13, 9, 7, 7, 9, 11, 8, 9, 9, 9, 9, 9, 5, 7, 7];
    let line = |cells: &[String]| -> String {
        let pad = |(k, c): (usize, &String)| {
            let w = min[k].max(head[k].len());
            if k < 2 {
                format!("{c:<w$}")
            } else {
                format!("{c:>w$}")
            }
        };
        cells.iter().enumerate().map(pad).collect::<Vec<_>>().join(" ")
    };
    outln!("{}", line(&head.map(String::from)));
    for r in &rows {
        outln!("{}", line(&robustness_cells(r)));
    }
    Ok(ExitCode::SUCCESS)
}

/// One robustness row's cells, for the terminal and the report alike.
fn robustness_cells(r: &ferrocat_lab::robustness::Row) -> [String; 16] {
    [
        r.scenario.clone(),
        r.method.clone(),
        format!("{:.1}", r.before_mean_ns),
        format!("{:.1}", r.before_sd_ns),
        format!("{:.1}", r.band_ns),
        format!("{:.1}", r.peak_ns),
        match (r.scenario == ferrocat_lab::robustness::CONTROL, r.recovery_ms) {
            (true, _) => "—".into(),
            (false, Some(v)) => format!("{v:.0}"),
            (false, None) => "never".into(),
        },
        match (r.peak_vs_control_ns, r.recovery_vs_control_ms) {
            (None, _) => "—".into(),
            (Some(_), Some(v)) => format!("{v:.0}"),
            (Some(_), None) => "never".into(),
        },
        r.peak_vs_control_ns.map(|v| format!("{v:.1}")).unwrap_or_else(|| "—".into()),
        match (r.locked_before, r.relock_ms) {
            _ if r.scenario == ferrocat_lab::robustness::CONTROL => "—".into(),
            (false, _) => "unlocked".into(),
            (true, Some(v)) => format!("{v:.0}"),
            (true, None) => "never".into(),
        },
        format!("{:.2}", r.outside_pct),
        format!("{:.1}", r.after_mean_ns),
        format!("{:.1}", r.after_rms_ns),
        r.frames_lost.to_string(),
        r.make_ups.to_string(),
        r.probes_after.to_string(),
    ]
}
