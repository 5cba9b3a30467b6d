//! `ferrocat demo`: drives brought to OP with distributed clocks and moved together, once per
//! clock-sync method and cycle time; tables on stdout, CSV and plots (SVG, PNG) in a folder.
use std::path::{Path, PathBuf};
use std::process::ExitCode;

use ferrocat_lab::demo::{run, run_with, Options, Row, TracePoint};

use crate::plots::{line_chart, Series};

use crate::outln;

pub struct DemoArgs {
    pub drives: usize,
    pub drive: Option<String>,
    pub cycles_us: Vec<u64>,
    pub methods: Vec<String>,
    pub host: String,
    pub seed: Option<u64>,
    pub json: bool,
    pub out: PathBuf,
    /// A real network (or a served one) instead of the embedded virtual segment.
    pub iface: Option<String>,
    pub force: bool,
    pub no_gpio_calibration: bool,
}

pub fn demo(a: DemoArgs) -> anyhow::Result<ExitCode> {
    let mut o = Options::new(crate::lab::host(&a.host)?);
    crate::report::check_out_dir(&a.out)?;
    anyhow::ensure!((1..=16).contains(&a.drives), "--drives must be between 1 and 16");
    o.drives = a.drives;
    if let Some(d) = a.drive {
        o.drive = d;
    }
    if let Some(s) = a.seed {
        o.seed = s;
    }
    o.gpio_calibration = !a.no_gpio_calibration;
    if !a.cycles_us.is_empty() {
        o.cycles_us = a.cycles_us;
    }
    if !a.methods.is_empty() {
        for m in &a.methods {
            anyhow::ensure!(
                ferrocat_lab::METHODS.contains(&m.as_str()),
                "unknown method {m:?} (known: {})",
                ferrocat_lab::METHODS.join(", ")
            );
        }
        o.methods = a.methods;
    }
    let rows = match &a.iface {
        None => run(&o)?,
        Some(iface) => {
            let target = crate::target::Target::on_iface(iface, a.force);
            crate::target::go_real_time();
            run_with(&o, &mut || target.master().map_err(|e| ferrocat_lab::LabError::Open(format!("{e:#}").into())))?
        }
    };
    write_outputs(&a.out, &o, &rows)?;
    if a.json {
        let v = serde_json::json!({ "demo": { "drives": o.drives, "drive": o.drive, "host": o.host.name,
            "seed": o.seed, "out": a.out, "iface": a.iface }, "methods": rows });
        outln!("{v}");
        return Ok(ExitCode::SUCCESS);
    }
    let r0 = &rows[0];
    let mut modes: Vec<String> = r0.axes.iter().map(|x| x.mode.to_uppercase()).collect();
    modes.dedup();
    modes.sort();
    modes.dedup();
    let modes = modes.join("/");
    match &a.iface {
        None => outln!(
            "ferrocat demo — {} × {} behind EK1100, EL2004, EL1004 ({} axes); host {}, seed {}; every axis moves out and back together ({:.2} s, {modes})",
            o.drives,
            o.drive,
            r0.axes.len(),
            o.host.name,
            o.seed,
            r0.move_s
        ),
        Some(i) => outln!(
            "ferrocat demo on {i} — {} drives, {} axes; every axis moves out and back together ({:.2} s, {modes}); — marks what only a simulator can measure",
            r0.drives,
            r0.axes.len(),
            r0.move_s
        ),
    }
    outln!(
        "Columns: err or phase, ns; Δ mean, sd, min, max: SYNC0 Δ, the second drive's SYNC0 minus the first's, ns \
         (Paprocki 2022 Table 2); spread: the largest spread of all drives' SYNC0 instants; late: set-points that \
         reached a drive after its SYNC0; repeated: SYNC0s at which a drive had no new set-point and took the last \
         again; max FE: the largest following error of any axis, encoder increments; enabled: axes in operation \
         enabled at the end, of all; app mean/max: the application layer's time from SYNC0 to set-point, µs \
         (Paprocki 2022 Tables 3–4)."
    );
    // Two measures, one per coupling: a method whose reference follows the master is judged by
    // the clock error; one whose master follows the reference by its phase on the reference's
    // cycle, which is no error.
    for (title, label, phased) in [
        ("The reference follows the master — err: master clock − reference clock", "err", false),
        ("The master follows the reference — phase: the reference's time at the master's cycle start, off its cycle grid", "phase", true),
    ] {
        let group: Vec<&ferrocat_lab::demo::Row> = rows.iter().filter(|r| r.phase_mean_ns.is_some() == phased).collect();
        if group.is_empty() || (phased && group.iter().all(|r| r.phase_mean_ns.is_none())) {
            continue;
        }
        outln!("{title}:");
        outln!(
            "{:>6}  {:<12} {:>10} {:>10} {:>10}   {:>7} {:>6} {:>6} {:>6} {:>7}   {:>5} {:>8}   {:>12} {:>7} {:>14}",
            "cycle",
            "method",
            format!("{label} mean"),
            format!("{label} rms"),
            format!("{label} max"),
            "Δ mean",
            "Δ sd",
            "Δ min",
            "Δ max",
            "spread",
            "late",
            "repeated",
            "max FE",
            "enabled",
            "app mean/max"
        );
        for r in group {
            let (mean, rms, max) = if phased {
                (r.phase_mean_ns, r.phase_rms_ns, r.phase_max_ns)
            } else {
                (r.error_mean_ns, r.error_rms_ns, r.error_max_ns)
            };
            outln!(
                "{:>4}µs  {:<12} {:>10} {:>10} {:>10}   {:>7} {:>6} {:>6} {:>6} {:>7}   {:>5} {:>8}   {:>12} {:>5}/{} {:>15}",
                r.cycle_us,
                r.method,
                ns(mean),
                ns(rms),
                ns(max),
                opt(r.sync0_mean_ns, 1),
                opt(r.sync0_sd_ns, 1),
                opt(r.sync0_min_ns.map(|v| v as f64), 0),
                opt(r.sync0_max_ns.map(|v| v as f64), 0),
                r.sync0_spread_max_ns.map_or("—".into(), |v| format!("{v}ns")),
                opt(r.late_setpoints.map(|v| v as f64), 0),
                opt(r.repeated_setpoints.map(|v| v as f64), 0),
                opt(r.max_following_error, 0),
                r.axes.iter().filter(|x| x.enabled).count(),
                r.axes.len(),
                match (r.processing_mean_us, r.processing_max_us) {
                    (Some(m), Some(x)) => format!("{m:.1}/{x:.1}"),
                    _ => "—".into(),
                }
            );
        }
    }
    let calibrated: Vec<String> =
        rows.iter().filter_map(|r| r.calibration_ns.map(|c| format!("{}µs {} {c}ns", r.cycle_us, r.method))).collect();
    if !calibrated.is_empty() {
        outln!(
            "Stamps' asymmetry measured through the host's GPIO into the reference's LATCH0 and taken out: {}",
            calibrated.join(", ")
        );
    }
    let labels: Vec<String> = r0.axes.iter().map(axis_label).collect();
    outln!(
        "Following error per axis (increments, largest |demand − actual|; csv: the move's set-point − the shaft's travel, or the image's position): {}",
        labels.join("  ")
    );
    for r in &rows {
        let fe: Vec<String> = r.axes.iter().map(|x| opt(x.following_error, 0)).collect();
        outln!("{:>4}µs  {:<12} {}", r.cycle_us, r.method, fe.join("  "));
    }
    for r in rows.iter().filter(|r| r.late_setpoints.unwrap_or(0) + r.repeated_setpoints.unwrap_or(0) > 0) {
        outln!(
            "{:>4}µs  {:<12} late at drive:SYNC0 {} — repeated at {}",
            r.cycle_us,
            r.method,
            list(&r.late_cycles),
            list(&r.repeated_cycles)
        );
    }
    for r in rows.iter().filter(|r| r.left_op > 0) {
        outln!(
            "{:>4}µs  {:<12} drives left OP {} times (a sync error: three cycles without set-points), each brought back",
            r.cycle_us,
            r.method,
            r.left_op
        );
    }
    outln!("Plots and CSV in {}", a.out.display());
    Ok(ExitCode::SUCCESS)
}

/// "slave 4" for a one-axis drive's axis, "slave 4 axis 1 (csv)" past the first, the mode where
/// it is not CSP.
fn axis_label(x: &ferrocat_lab::demo::AxisRow) -> String {
    let mut s = format!("slave {}", x.slave);
    if x.axis > 0 {
        s += &format!(" axis {}", x.axis);
    }
    if x.mode != "csp" {
        s += &format!(" ({})", x.mode);
    }
    s
}

/// A figure, or "—" where it was not measured.
fn opt(v: Option<f64>, precision: usize) -> String {
    v.map_or("—".into(), |v| format!("{v:.precision$}"))
}

fn ns(v: Option<f64>) -> String {
    v.map_or("—".into(), |v| format!("{v:.0}ns"))
}

fn list(v: &[String]) -> String {
    if v.is_empty() {
        "none".into()
    } else {
        v.join(" ")
    }
}

fn write_outputs(dir: &Path, o: &Options, rows: &[Row]) -> anyhow::Result<()> {
    crate::report::make_dir(dir)?;
    crate::report::write(dir, "demo.csv", &crate::report::csv_of(rows))?;
    for &c in &o.cycles_us {
        let of_cycle: Vec<&Row> = rows.iter().filter(|r| r.cycle_us == c).collect();
        if let Some(r) = of_cycle.iter().find(|r| r.method == "ferrocat").or(of_cycle.first()) {
            let mut series = Vec::new();
            for (i, x) in r.axes.iter().enumerate() {
                let pts = |f: &dyn Fn(&TracePoint) -> f64| r.trace.iter().map(|p| (p.t_s, f(p))).collect();
                series.push(Series::new(format!("{} set-point", axis_label(x)), pts(&|p| p.setpoint_rev[i])));
                let mut actual = Series::new(format!("{} actual", axis_label(x)), pts(&|p| p.actual_rev[i]));
                actual.wide = true;
                series.push(actual);
            }
            line_chart(
                &dir.join(format!("positions-{c}us")),
                &format!("Positions, {c} µs, {}: set-point and actual", r.method),
                "time (s)",
                "rev",
                &series,
            )?;
        }
        let per_method = |f: &dyn Fn(&TracePoint) -> f64| -> Vec<Series> {
            of_cycle
                .iter()
                .map(|r| Series::new(r.method.clone(), r.trace.iter().map(|p| (p.t_s, f(p))).collect()))
                .collect()
        };
        line_chart(
            &dir.join(format!("following-error-{c}us")),
            &format!("Following error of axis 1, {c} µs"),
            "time (s)",
            "increments",
            &per_method(&|p| p.following_error.first().copied().unwrap_or(f64::NAN)),
        )?;
        // The two measures apart, as in the table: the clock error of the methods whose
        // reference follows the master; the phase of those whose master follows the reference,
        // a panel each (their traces lie on one another).
        let split = |phased: bool| -> Vec<Series> {
            of_cycle
                .iter()
                .filter(|r| {
                    r.phase_mean_ns.is_some() == phased && (r.phase_mean_ns.is_some() || r.error_mean_ns.is_some())
                })
                .map(|r| Series::new(r.method.clone(), r.trace.iter().map(|p| (p.t_s, p.error_ns)).collect()))
                .collect()
        };
        let errors = split(false);
        if !errors.is_empty() {
            line_chart(
                &dir.join(format!("clock-error-{c}us")),
                &format!("Master clock − reference clock, {c} µs (the reference follows the master)"),
                "time (s)",
                "ns",
                &errors,
            )?;
        }
        let phases = split(true);
        if !phases.is_empty() {
            crate::plots::panel_chart(
                &dir.join(format!("phase-{c}us")),
                &format!("The reference's time at the master's cycle start, off its grid, {c} µs"),
                "time (s)",
                "ns",
                &phases,
            )?;
        }
    }
    Ok(())
}
