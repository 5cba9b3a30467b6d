//! Chen et al. 2016, Table 2: with the master following the reference clock (or not), the
//! jitter of the reference's timestamps against the master's cycle grid (min, max, width as a
//! share of the cycle) and the process-data cycles that DC-synchronous slaves lost or consumed
//! twice, for 500, 250, 100 and 50 µs cycles.
use crate::LabError;
use ferrocat_esc::{SyncApp, SyncMode};
use ferrocat_master::sync::{ClockSync, Coupling, Ferrocat, Nominal};
use ferrocat_master::{DcConfig, Master};
use ferrocat_segment::SegmentConfig;
use ferrocat_segment::{HostModel, VirtualIo};
use rayon::prelude::*;
use serde::Serialize;

pub const METHODS: [&str; 4] = ["none", "chen2016", "pi", "ferrocat"];

#[derive(Debug, Clone)]
pub struct Options {
    pub cycles_us: Vec<u64>,
    pub methods: Vec<String>,
    pub seconds: f64,
    pub seed: u64,
    pub host: HostModel,
    /// The reference's crystal error (the master's clock is exact).
    pub reference_ppm: f64,
    /// A segment of one's own instead of a coupler and two DC-synchronous outputs (its
    /// slaves with `app = "dc"` and process-data outputs are the ones whose lost and repeated
    /// cycles count; its reference's crystal is its own, `reference_ppm` applies only without).
    pub segment: Option<SegmentConfig>,
}

impl Options {
    pub fn full(host: HostModel) -> Self {
        Options {
            cycles_us: vec![500, 250, 100, 50],
            methods: METHODS.iter().map(|s| s.to_string()).collect(),
            seconds: 60.0,
            seed: 1,
            host,
            reference_ppm: 40.0,
            segment: None,
        }
    }
    pub fn quick(host: HostModel) -> Self {
        Options { seconds: 10.0, ..Options::full(host) }
    }
}

#[derive(Debug, Clone, Serialize, PartialEq)]
pub struct Row {
    pub cycle_us: u64,
    pub method: String,
    pub host: String,
    pub jitter_min_us: f64,
    pub jitter_max_us: f64,
    /// (max − min) / cycle, in per cent, as the paper gives it.
    pub jitter_width_pct: f64,
    /// Standard deviation of the jitter (µs): the width is two extremes, single host outliers
    /// that land on one method's frame and not another's; the spread of all cycles is not.
    pub jitter_sd_us: f64,
    pub cycles: u64,
    /// Over the DC-synchronous slaves: cycles whose data was overwritten before use, and
    /// cycles whose data was used twice.
    pub lost: u64,
    pub repeated: u64,
    pub loss_rate: f64,
    pub frames_lost: u64,
    /// Up to 2 000 points of (master cycle, reference jitter µs, master period µs) over the
    /// measured part of the run (Chen 2016, Figure 12).
    #[serde(skip)]
    pub trace: Vec<(u64, f64, f64)>,
}

impl Row {
    /// The row's figures as every table prints them: jitter min, max (µs), width (%), sd (µs),
    /// cycles, lost, repeated.
    pub fn figures(&self) -> [String; 7] {
        [
            format!("{:.2}", self.jitter_min_us),
            format!("{:.2}", self.jitter_max_us),
            format!("{:.1}", self.jitter_width_pct),
            format!("{:.2}", self.jitter_sd_us),
            self.cycles.to_string(),
            self.lost.to_string(),
            self.repeated.to_string(),
        ]
    }
}

/// Table 2 as published: cycle µs, jitter min, max (µs), width (%), loss rate.
pub const PAPER: [(u64, f64, f64, f64, f64); 3] =
    [(500, 26.36, -56.0, 16.5, 0.0), (250, 15.12, -66.96, 32.8, 0.0), (100, 14.48, -49.96, 64.4, 0.0)];

/// What a table was measured on, the same for every run of it.
#[derive(Debug, Clone, Serialize, PartialEq)]
pub struct Setup {
    /// The reference clock's crystal error at the start of the runs (ppm; the master's clock
    /// is exact): the scenario's `reference_ppm` on the experiment's own segment, whatever a
    /// segment file gave it otherwise.
    pub reference_ppm: f64,
    /// The slaves (positions) whose lost and repeated cycles the table counts: DC-synchronous
    /// (`app = "dc"`) with process-data outputs. One without outputs gets SYNC0 but has
    /// nothing to lose or repeat.
    pub counted_slaves: Vec<u16>,
}

/// The segment brought up and configured, with the slaves that take SYNC0 and those that count.
fn prepare(o: &Options) -> crate::Result<(Master<VirtualIo>, Vec<u16>, Setup)> {
    let toml = format!(
        "seed = {}\ndrift_spread_ppm = 50.0\n[[device]]\nbuiltin = 'EK1100'\ndrift_ppm = {}\n\
         [[device]]\nbuiltin = 'EL2004'\napp = 'dc'\n[[device]]\nbuiltin = 'EL2004'\napp = 'dc'\n",
        o.seed, o.reference_ppm
    );
    let cfg: SegmentConfig = match &o.segment {
        Some(c) => SegmentConfig { seed: o.seed, ..c.clone() },
        None => toml::from_str(&toml)?,
    };
    let mut m = Master::new(VirtualIo::new(cfg.build()?, o.host, o.seed));
    m.states().scan()?;
    m.states().configure()?;
    let dc_synchronous = |k: usize| {
        crate::node_of(&m, k)
            .and_then(|n| m.io().seg.nodes[n].esc.app().as_any().downcast_ref::<SyncApp>())
            .is_some_and(|a| a.mode == SyncMode::DcSynchronous)
    };
    let synced: Vec<u16> = (0..m.slaves().len()).filter(|&k| dc_synchronous(k)).map(|k| k as u16).collect();
    if synced.is_empty() {
        return Err(LabError::NoDcSynchronousSlave);
    }
    let counted_slaves: Vec<u16> =
        synced.iter().copied().filter(|&k| m.slaves()[k as usize].mapping().output_bits() > 0).collect();
    if counted_slaves.is_empty() {
        return Err(LabError::NoSynchronousOutputs(synced));
    }
    let reference = crate::dc_slaves(&m)?[0];
    let reference_ppm = crate::node_of(&m, reference)
        .and_then(|n| m.io().seg.nodes[n].esc.dc.as_ref())
        .map_or(0.0, |dc| dc.drift_ppb as f64 / 1000.0);
    Ok((m, synced, Setup { reference_ppm, counted_slaves }))
}

/// The table's [`Setup`], without running it.
pub fn setup(o: &Options) -> crate::Result<Setup> {
    Ok(prepare(o)?.2)
}

fn run_one(o: &Options, cycle_us: u64, name: &str) -> crate::Result<(Setup, Row)> {
    let cycle_ns = cycle_us * 1000;
    let (mut m, synced, setup) = prepare(o)?;
    // SYNC0 half a cycle after the reference's cycle grid (Chen §6: "half the cycle time").
    m.dc().init_dc(&DcConfig {
        sync0_cycle_ns: cycle_ns as u32,
        sync0_shift_ns: (cycle_ns / 2) as i32,
        sync0_slaves: Some(synced),
        start_delay_ns: 20_000_000,
        ..DcConfig::default()
    })?;
    m.states().start()?;
    let mut sync: Box<dyn ClockSync> = if name == "ferrocat" {
        // ferrocat knows the SYNC0 its frames serve, and holds a frame back after a late one.
        let mut f = Ferrocat::new(Coupling::MasterFollowsReference, cycle_ns).with_flywheel();
        f.set_sync0_phase_ns(Some(cycle_ns / 2));
        Box::new(f)
    } else {
        crate::method(name, &mut m, cycle_ns, Coupling::MasterFollowsReference)?
    };
    let mut st = m.clock().sync_state()?;
    // Common start for every method, Chen's compensation of the initial offset and the
    // propagation delay at t1 (§3, §5.3: T_m(i) = T_s + T_p·i "after compensation for the
    // propagation delay and initial offset"): a probe frame measures where the reference's
    // cycle grid lies against the master's send, and the first frame is sent so that it
    // passes the reference at the start of a reference cycle. (Timing the wake-up rather
    // than the passage put every frame a lead — 27 µs on rtx-10us — into the cycle, and
    // chen2016 lost data at 100 µs where the paper lost none.)
    // Every method's cyclic phase meets the same host, whatever its bring-up did.
    m.cyclic().io_mut().start_cycles(cycle_ns);
    let mut probe = Nominal { cycle_ns };
    let sent = m.cyclic().now_ns();
    m.clock().sync_step(&mut probe, &mut st)?;
    let r0 = st.reference_ns.unwrap_or(0);
    // The reference read r0 one lead after `sent`; a send at sent + d passes at r0 + d.
    let mut next = sent + 2 * cycle_ns - r0 % cycle_ns;
    m.cyclic().sleep_until(next);
    for a in apps(&mut m, &setup.counted_slaves) {
        a.reset_counts();
    }
    let total = (o.seconds * 1e9 / cycle_ns as f64) as u64;
    let (mut jmin, mut jmax) = (i64::MAX, i64::MIN);
    // Exact sums for the spread: Σj cannot overflow i128 (fewer than 2⁶⁴ terms of |j| ≤ 2⁶³);
    // Σj² saturates (j² alone is below 2¹²⁶, but a segment of one's own may give wild j).
    let (mut jn, mut jsum, mut jsq) = (0i128, 0i128, 0i128);
    let mut first: Option<(u64, u64)> = None;
    let mut trace = Vec::new();
    let trace_every = (total - total / 10).div_ceil(2000).max(1);
    // Slots of the master's grid so far: a period of two cycles (a frame held back) skips one.
    let mut slot = 0u64;
    for k in 0..total {
        // One frame per cycle: the process data with the sync datagrams behind it.
        let (_, c) = m.cyclic().cycle_sync(sync.as_mut(), &mut st)?;
        let period = c.next_period_ns.unwrap_or(cycle_ns);
        if let (Some(t), true) = (st.reference_ns, k >= total / 10) {
            let (k0, t0) = *first.get_or_insert((slot, t));
            // Chen's jitter: the reference's time against the master's grid T_s + i·T_p.
            let j = t.wrapping_sub(t0) as i64 - ((slot - k0) * cycle_ns) as i64;
            jmin = jmin.min(j);
            jmax = jmax.max(j);
            jn += 1;
            jsum += j as i128;
            jsq = jsq.saturating_add((j as i128) * (j as i128));
            if (k - total / 10) % trace_every == 0 {
                trace.push((slot - k0, j as f64 / 1e3, period as f64 / 1e3));
            }
        }
        slot += ((period + cycle_ns / 2) / cycle_ns).max(1);
        next += period;
        m.cyclic().sleep_until(next);
    }
    let (lost, repeated) =
        apps(&mut m, &setup.counted_slaves).iter().fold((0, 0), |(l, r), a| (l + a.lost, r + a.repeated));
    let cycles = total;
    let row = Row {
        cycle_us,
        method: name.to_string(),
        host: o.host.name.to_string(),
        jitter_min_us: jmin as f64 / 1e3,
        jitter_max_us: jmax as f64 / 1e3,
        jitter_width_pct: (jmax - jmin) as f64 / cycle_ns as f64 * 100.0,
        jitter_sd_us: spread_ns(jn, jsum, jsq) / 1e3,
        cycles,
        lost,
        repeated,
        loss_rate: lost as f64 / (setup.counted_slaves.len() as u64 * cycles).max(1) as f64,
        frames_lost: st.lost + m.diagnosis().cycle_stats().lost_frames,
        trace,
    };
    Ok((setup, row))
}

/// Population standard deviation (ns) from exact sums: n·Σj² − (Σj)² is the exact n²·variance.
fn spread_ns(n: i128, sum: i128, sq: i128) -> f64 {
    if n == 0 {
        return 0.0;
    }
    // n·Σj² passes i128 only for runs far beyond any lab's (10¹³ cycles of ±10⁹ ns): saturate.
    let var_n2 = n.saturating_mul(sq).saturating_sub(sum.saturating_mul(sum)).max(0);
    (var_n2 as f64).sqrt() / n as f64
}

/// The applications of the slaves at `positions`.
fn apps<'m>(m: &'m mut Master<VirtualIo>, positions: &[u16]) -> Vec<&'m mut SyncApp> {
    let nodes: Vec<usize> = positions.iter().filter_map(|&k| crate::node_of(m, k as usize)).collect();
    m.cyclic()
        .io_mut()
        .seg
        .nodes
        .iter_mut()
        .enumerate()
        .filter(|(n, _)| nodes.contains(n))
        .filter_map(|(_, n)| n.esc.app_mut().as_any_mut().downcast_mut::<SyncApp>())
        .collect()
}

/// A table: its set-up and a row per (cycle, method).
#[derive(Debug, Clone)]
pub struct Table {
    pub setup: Setup,
    pub rows: Vec<Row>,
}

pub fn run(o: &Options, progress: &(dyn Fn(usize, usize) + Sync)) -> crate::Result<Table> {
    let jobs: Vec<(u64, String)> =
        o.cycles_us.iter().flat_map(|&c| o.methods.iter().map(move |m| (c, m.clone()))).collect();
    let done = std::sync::atomic::AtomicUsize::new(0);
    let runs: Vec<(Setup, Row)> = jobs
        .par_iter()
        .map(|(c, name)| {
            let r = run_one(o, *c, name).map_err(|e| e.in_run(format!("{c} µs, {name}")));
            progress(done.fetch_add(1, std::sync::atomic::Ordering::Relaxed) + 1, jobs.len());
            r
        })
        .collect::<crate::Result<_>>()?;
    // Every run brought the same segment up on the same seed: one set-up for the table.
    let setup = match runs.first() {
        Some((s, _)) => s.clone(),
        None => setup(o)?,
    };
    Ok(Table { setup, rows: runs.into_iter().map(|(_, r)| r).collect() })
}

#[cfg(test)]
mod tests {
    use super::spread_ns;

    #[test]
    fn spread_is_the_population_sd_and_never_overflows() {
        let js = [1i128, 2, 3, 4];
        let (sum, sq) = (js.iter().sum::<i128>(), js.iter().map(|j| j * j).sum::<i128>());
        assert!((spread_ns(4, sum, sq) - 1.25f64.sqrt()).abs() < 1e-12);
        assert_eq!(spread_ns(0, 0, 0), 0.0);
        // Saturated sums give a finite figure, not a panic or a wrapped one.
        assert!(spread_ns(i128::MAX, i128::MAX, i128::MAX).is_finite());
    }
}

/// Chen 2016's set-up as the lab models it (docs/lab.md): the master on RTX with its timer on
/// 10 µs steps (the paper's §5.2) and a PC's real-time latencies, an EK1100 reference 40 ppm fast
/// and two DC-synchronous outputs, SYNC0 half a cycle on. One parameter is fitted on Table 2:
/// how late the master's rare late wake-ups come, on the 500 µs row's latest frame.
#[derive(Debug, Clone, Copy, PartialEq, Serialize)]
pub struct SetupModel {
    /// A late wake-up of the master's timer (0.1 % of cycles) comes up to this much late, ns.
    pub wake_outlier_ns: f64,
}

/// The model's figures are medians over this many seeds (the scenario's and the next ones):
/// the extremes of one run are single draws.
pub const MODEL_SEEDS: u64 = 5;
/// Cycles per run at every cycle time (60 s at 500 µs, 12 s at 100 µs). The paper does not
/// say how long its runs were; its jitter widths in µs shrink with the cycle where runs of
/// equal duration would widen them (more cycles, more late wake-ups), as a capture of a fixed
/// number of frames would not (docs/lab.md gives both readings' figures).
pub const MODEL_CYCLES: u64 = 120_000;

impl SetupModel {
    /// The model the `rtx-10us` host holds.
    pub fn current() -> Self {
        SetupModel { wake_outlier_ns: HostModel::rtx_10us().wake.outlier_ns }
    }

    pub fn host(&self, base: HostModel) -> HostModel {
        let mut h = base;
        h.wake.outlier_ns = self.wake_outlier_ns;
        h
    }
}

/// `chen2016`'s jitter at one of the paper's cycle times: medians over [`MODEL_SEEDS`] runs of
/// [`MODEL_CYCLES`] cycles, with the runs' ranges.
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct ModelRow {
    pub cycle_us: u64,
    /// The earliest frame against the master's grid (reference − grid, µs; negative).
    pub early_us: f64,
    /// The latest (µs).
    pub late_us: f64,
    pub width_pct: f64,
    /// Cycles lost, per million cycles of each counted slave.
    pub loss_ppm: f64,
    pub early_range_us: (f64, f64),
    pub late_range_us: (f64, f64),
}

/// `chen2016` on `host` at the paper's cycle times, seeds `seed` to `seed + MODEL_SEEDS − 1`.
pub fn model_rows(host: HostModel, seed: u64) -> crate::Result<Vec<ModelRow>> {
    let jobs: Vec<(u64, u64)> = PAPER.iter().flat_map(|p| (0..MODEL_SEEDS).map(move |i| (p.0, i))).collect();
    let rows: Vec<Row> = jobs
        .par_iter()
        .map(|&(cycle_us, i)| {
            let o = Options {
                cycles_us: vec![cycle_us],
                methods: vec!["chen2016".into()],
                seconds: (MODEL_CYCLES * cycle_us) as f64 / 1e6,
                seed: seed.wrapping_add(i),
                ..Options::full(host)
            };
            let mut t = run(&o, &|_, _| {})?;
            t.rows.pop().ok_or_else(|| LabError::MissingRow(format!("{cycle_us} µs: no row")))
        })
        .collect::<crate::Result<_>>()?;
    let median = |v: Vec<f64>| crate::stats::median(&v);
    let range = |v: &[f64]| v.iter().fold((f64::INFINITY, f64::NEG_INFINITY), |(a, b), &x| (a.min(x), b.max(x)));
    Ok(PAPER
        .iter()
        .map(|p| {
            let rows: Vec<&Row> = rows.iter().filter(|r| r.cycle_us == p.0).collect();
            let early: Vec<f64> = rows.iter().map(|r| r.jitter_min_us).collect();
            let late: Vec<f64> = rows.iter().map(|r| r.jitter_max_us).collect();
            ModelRow {
                cycle_us: p.0,
                early_range_us: range(&early),
                late_range_us: range(&late),
                early_us: median(early),
                late_us: median(late),
                width_pct: median(rows.iter().map(|r| r.jitter_width_pct).collect()),
                loss_ppm: median(rows.iter().map(|r| r.loss_rate * 1e6).collect()),
            }
        })
        .collect())
}

/// One step of [`fit`]: the model and the 500 µs row's latest frame against the paper's (µs).
#[derive(Debug, Clone, Copy, PartialEq, Serialize)]
pub struct FitStep {
    pub model: SetupModel,
    pub late_500us_error_us: f64,
}

/// The late wake-ups' size fitted on the 500 µs row's latest frame (the paper's 56.00 µs, in
/// its reading): a late wake-up delays that cycle's frame by as much, so each step moves the
/// parameter by the error; it stops under 0.5 µs (a tenth of the runs' spread), or after `steps`.
pub fn fit(seed: u64, start: SetupModel, steps: usize) -> crate::Result<Vec<FitStep>> {
    let paper_late_us = -PAPER[0].2;
    let mut model = start;
    let mut trace = Vec::new();
    for _ in 0..steps.max(1) {
        let rows = model_rows(model.host(HostModel::rtx_10us()), seed)?;
        let e = rows[0].late_us - paper_late_us;
        trace.push(FitStep { model, late_500us_error_us: e });
        if e.abs() < 0.5 {
            break;
        }
        model = SetupModel { wake_outlier_ns: (model.wake_outlier_ns - e * 1e3).max(0.0) };
    }
    Ok(trace)
}

/// The set-up model `o` runs on, if it is the paper's set-up (the fitted `rtx-10us`, the lab's
/// own segment): Table 2 is compared only there.
pub fn paper_setup(o: &Options) -> Result<SetupModel, String> {
    let model = SetupModel::current();
    if o.host != model.host(HostModel::rtx_10us()) {
        return Err(format!("the host is {}, not the fitted rtx-10us", o.host.name));
    }
    if o.segment.is_some() {
        return Err("a segment file replaces the paper's segment".into());
    }
    if o.reference_ppm != Options::full(o.host).reference_ppm {
        return Err("the reference's crystal is not the model's".into());
    }
    Ok(model)
}

/// Every published figure of Table 2 beside the model's. The paper's jitter is the master's
/// grid less the reference's time, and its "Min." column holds the largest value, "Max." the
/// smallest: width = (Min − Max) / cycle in every row (26.36 + 56.00 = 16.5 % of 500 µs). In the
/// lab's sign (reference − grid, a late frame positive) a row reads early −Min, late −Max. The
/// 500 µs row's latest frame is the fitted figure; the rest are predicted.
pub fn compare(model: &[ModelRow]) -> Vec<crate::fit::Figure> {
    use crate::fit::{Band, Figure, Part};
    let mut out = Vec::new();
    for &(cycle, min, max, width, loss) in &PAPER {
        let Some(m) = model.iter().find(|m| m.cycle_us == cycle) else { continue };
        let part_of = |fitted: bool| if fitted { Part::Fit } else { Part::Prediction };
        let late = part_of(cycle == PAPER[0].0);
        let share = |p: Part| Band { share: Band::for_part(p).share, floor: None };
        let other = Part::Prediction;
        out.push(Figure::new(
            format!("{cycle} µs, earliest frame"),
            "µs",
            other,
            Band::for_part(other),
            -min,
            m.early_us,
        ));
        out.push(Figure::new(format!("{cycle} µs, latest frame"), "µs", late, Band::for_part(late), -max, m.late_us));
        out.push(Figure::new(format!("{cycle} µs, width"), "%", other, share(other), width, m.width_pct));
        // The paper lost nothing: the band is nothing lost.
        out.push(Figure::new(
            format!("{cycle} µs, cycles lost (ppm)"),
            "ppm",
            other,
            Band { share: 0.0, floor: Some(0.0) },
            loss * 1e6,
            m.loss_ppm,
        ));
    }
    out
}
