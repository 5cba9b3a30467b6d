//! Park et al. 2020, Table 1: the master–reference and master–last-slave synchronisation
//! errors (GMEAN: the mean of each round's mean; MRMS: the mean of each round's RMS) for 2 and
//! 6 slaves, 1 ms cycle, a sample every 2 ms after a settling time.
use crate::LabError;
use ferrocat_master::sync::{Correction, Coupling};
use ferrocat_segment::HostModel;
use rayon::prelude::*;
use serde::Serialize;

use crate::stats::Moments;
use ferrocat_segment::SegmentConfig;

/// The methods whose master clock this experiment compares with the slaves' (the
/// reference-follows-master methods, and none at all).
pub const METHODS: [&str; 10] = crate::concat_names(["none", "conventional", "park2020"], crate::CALIBRATED);

#[derive(Debug, Clone)]
pub struct Options {
    pub slaves: Vec<usize>,
    pub methods: Vec<String>,
    pub rounds: u32,
    pub settle_s: f64,
    pub samples: u64,
    pub cycle_ns: u64,
    /// A sample every this many cycles (the paper: every 2 ms at 1 ms).
    pub sample_every: u64,
    pub seed: u64,
    pub host: HostModel,
    /// A segment of one's own instead of the line of `slaves` EK1100s (`slaves` then only
    /// labels the rows).
    pub segment: Option<SegmentConfig>,
    /// ferrocat's methods calibrate their stamps' asymmetry through the host's GPIO into the
    /// reference's LATCH0 input where the host model has one (`crate::calibration`).
    pub gpio_calibration: bool,
    /// The GPI measurement whose view of the errors the `gpi_*` figures give (§IV-B).
    pub gpi: crate::gpi::GpiSetup,
}

impl Options {
    /// As published: 100 000 samples after 5 minutes, 10 rounds.
    pub fn full(host: HostModel) -> Self {
        Options {
            slaves: vec![2, 6],
            methods: crate::ERROR_METHODS.iter().map(|s| s.to_string()).collect(),
            rounds: 10,
            settle_s: 300.0,
            samples: 100_000,
            cycle_ns: 1_000_000,
            sample_every: 2,
            seed: 1,
            host,
            segment: None,
            gpio_calibration: true,
            gpi: crate::gpi::GpiSetup::park2020(),
        }
    }

    /// Under a minute: 5 s of settling, 5 000 samples, 3 rounds.
    pub fn quick(host: HostModel) -> Self {
        Options { rounds: 3, settle_s: 5.0, samples: 5_000, ..Options::full(host) }
    }
}

#[derive(Debug, Clone, Serialize, PartialEq)]
pub struct Row {
    pub slaves: usize,
    pub method: String,
    pub host: String,
    pub ref_gmean_us: f64,
    pub ref_mrms_us: f64,
    pub last_gmean_us: f64,
    pub last_mrms_us: f64,
    /// Median over rounds of the time from the start of cyclic operation until every slave
    /// stays within 100 ns of the reference and the master within 1 µs (None: not locked in
    /// some round).
    pub lock_ms: Option<f64>,
    /// Median over rounds of how long the DC initialisation's static drift compensation took
    /// before cyclic operation (it stops once every |0x092C| has converged).
    pub init_ms: f64,
    /// The same errors as Park's GPI measurement (§IV-B) would have reported them
    /// (`crate::gpi`): latencies drawn per sample, their estimated means subtracted.
    pub gpi_ref_gmean_us: f64,
    pub gpi_ref_mrms_us: f64,
    pub gpi_last_gmean_us: f64,
    pub gpi_last_mrms_us: f64,
    pub rounds: u32,
    pub frames_lost: u64,
    /// The mean over rounds of the master − reference error the GPIO calibration found and
    /// took out (None: not calibrated).
    pub calibration_us: Option<f64>,
    /// The first round's samples (µs), master − reference and master − last slave, for the
    /// figures (Park 2020, Figures 8–11).
    #[serde(skip)]
    pub ref_samples_us: Vec<f32>,
    #[serde(skip)]
    pub last_samples_us: Vec<f32>,
}

/// Table 1 as published (µs): slaves, method, ref GMEAN, ref MRMS, last GMEAN, last MRMS.
pub const PAPER: [(usize, &str, f64, f64, f64, f64); 4] = [
    (2, "conventional", 10.58, 11.23, 10.57, 11.24),
    (2, "park2020", 1.06, 4.19, 1.08, 4.24),
    (6, "conventional", 11.67, 12.29, 11.74, 12.35),
    (6, "park2020", -1.71, 4.55, -1.59, 4.59),
];

#[derive(Debug, Clone, Default)]
struct Round {
    reference: Moments,
    last: Moments,
    gpi_reference: Moments,
    gpi_last: Moments,
    lock_ms: Option<f64>,
    init_ms: f64,
    lost: u64,
    calibration_ns: Option<i64>,
    /// Every sample (µs), kept for the first round only.
    samples: Option<(Vec<f32>, Vec<f32>)>,
}

fn round(opts: &Options, slaves: usize, method: &str, seed: u64, keep: bool) -> crate::Result<Round> {
    let cfg = opts.segment.clone().unwrap_or_else(|| crate::line(slaves));
    let (mut m, mut sync, dc_report) =
        crate::segment(&cfg, opts.host, seed, method, opts.cycle_ns, Coupling::ReferenceFollowsMaster)?;
    let dc = crate::dc_slaves(&m)?;
    let mut st = m.clock().sync_state()?;
    let settle = (opts.settle_s * 1e9 / opts.cycle_ns as f64) as u64;
    let total = settle + opts.samples * opts.sample_every;
    let mut next = m.cyclic().now_ns();
    let mut r = Round::default();
    if keep {
        r.samples = Some((Vec::with_capacity(opts.samples as usize), Vec::with_capacity(opts.samples as usize)));
    }
    let mut last_violation: Option<u64> = None;
    let reference = dc[0];
    // One GPI rig per slave measured, as in the paper's set-up.
    let mut gpi_ref = crate::gpi::Gpi::new(opts.gpi, seed);
    let mut gpi_last = crate::gpi::Gpi::new(opts.gpi, seed ^ 0x1A57);
    let mut c = Correction::default();
    let pulses = crate::calibration_pulses(settle);
    let mut calibration =
        if opts.gpio_calibration && pulses > 0 { crate::calibration(&mut m, method, reference, pulses) } else { None };
    // The reference, every follower, the last slave last: the lock needs them all.
    let mut sampler = crate::sampler::Sampler::new(&m, &dc, seed);
    let mut take = |samples: Vec<crate::sampler::Sample>, r: &mut Round| {
        for s in samples {
            let (e_ref, e_last) = (s.errors_ns[0], s.errors_ns[s.errors_ns.len() - 1]);
            if !crate::sampler::locked(&s.errors_ns) {
                last_violation = Some(s.tag);
            }
            if s.tag >= settle {
                r.reference.push(e_ref as f64);
                r.last.push(e_last as f64);
                r.gpi_reference.push(gpi_ref.measure(e_ref as f64));
                r.gpi_last.push(gpi_last.measure(e_last as f64));
                if let Some((a, b)) = r.samples.as_mut() {
                    a.push(e_ref as f32 / 1e3);
                    b.push(e_last as f32 / 1e3);
                }
            }
        }
    };
    // Every method's cyclic phase meets the same host, whatever its bring-up did.
    m.cyclic().io_mut().start_cycles(opts.cycle_ns);
    for k in 0..total {
        // A master that follows the reference times its next cycle by it.
        next = crate::next_wake(next, opts.cycle_ns, &c);
        m.cyclic().sleep_until(next);
        if k % opts.sample_every == 0 {
            sampler.arm(&mut m, next, opts.cycle_ns, k);
        }
        c = m.clock().sync_step(sync.as_mut(), &mut st)?;
        if let Some(cal) = calibration.as_mut().filter(|_| crate::calibration_cycle(k, settle)) {
            r.calibration_ns = r.calibration_ns.or(cal.pulse(&mut m, sync.as_mut())?);
        }
        take(sampler.after_cycle(&mut m, sync.as_ref()), &mut r);
    }
    take(sampler.rest(&mut m, sync.as_ref()), &mut r);
    // Locked if the last violation is in the first 90 % of the run.
    r.lock_ms = match last_violation {
        None => Some(0.0),
        Some(v) if v < total * 9 / 10 => Some((v + opts.sample_every) as f64 * opts.cycle_ns as f64 / 1e6),
        Some(_) => None,
    };
    r.lost = st.lost;
    r.init_ms = dc_report.static_ns as f64 / 1e6;
    Ok(r)
}

/// Every (slaves, method) row; round `i` of every method uses seed `seed + i`, so the
/// comparison is paired. `progress(done, total)` is called as rounds finish.
pub fn run(opts: &Options, progress: &(dyn Fn(usize, usize) + Sync)) -> crate::Result<Vec<Row>> {
    let jobs: Vec<(usize, String, u32)> = opts
        .slaves
        .iter()
        .flat_map(|&n| opts.methods.iter().flat_map(move |m| (0..opts.rounds).map(move |i| (n, m.clone(), i))))
        .collect();
    let done = std::sync::atomic::AtomicUsize::new(0);
    let results: Vec<crate::Result<Round>> = jobs
        .par_iter()
        .map(|(n, method, i)| {
            let r = round(opts, *n, method, opts.seed.wrapping_add(*i as u64), *i == 0);
            progress(done.fetch_add(1, std::sync::atomic::Ordering::Relaxed) + 1, jobs.len());
            r
        })
        .collect();
    // The jobs run in the rows' order: the first failure is the first row's.
    let results: Vec<Round> = jobs
        .iter()
        .zip(results)
        .map(|((n, method, i), r)| r.map_err(|e| e.in_run(format!("{n} slaves, {method}, round {i}"))))
        .collect::<crate::Result<_>>()?;
    let mut rows = Vec::new();
    for &n in &opts.slaves {
        for method in &opts.methods {
            let mut rs = Vec::new();
            for (job, r) in jobs.iter().zip(&results) {
                if job.0 == n && &job.1 == method {
                    rs.push(r);
                }
            }
            let k = rs.len() as f64;
            let avg = |f: &dyn Fn(&Round) -> f64| rs.iter().map(|r| f(r)).sum::<f64>() / k / 1e3;
            let locks: Option<Vec<f64>> = rs.iter().map(|r| r.lock_ms).collect();
            let (ref_samples_us, last_samples_us) = rs.iter().find_map(|r| r.samples.clone()).unwrap_or_default();
            rows.push(Row {
                slaves: n,
                method: method.clone(),
                host: opts.host.name.to_string(),
                ref_gmean_us: avg(&|r| r.reference.mean()),
                ref_mrms_us: avg(&|r| r.reference.rms()),
                last_gmean_us: avg(&|r| r.last.mean()),
                last_mrms_us: avg(&|r| r.last.rms()),
                lock_ms: locks.map(|l| crate::stats::median(&l)),
                init_ms: crate::stats::median(&rs.iter().map(|r| r.init_ms).collect::<Vec<_>>()),
                gpi_ref_gmean_us: avg(&|r| r.gpi_reference.mean()),
                gpi_ref_mrms_us: avg(&|r| r.gpi_reference.rms()),
                gpi_last_gmean_us: avg(&|r| r.gpi_last.mean()),
                gpi_last_mrms_us: avg(&|r| r.gpi_last.rms()),
                rounds: rs.len() as u32,
                frames_lost: rs.iter().map(|r| r.lost).sum(),
                calibration_us: rs
                    .iter()
                    .map(|r| r.calibration_ns.map(|e| e as f64 / 1e3))
                    .sum::<Option<f64>>()
                    .map(|s| s / k),
                ref_samples_us,
                last_samples_us,
            });
        }
    }
    Ok(rows)
}

/// Park 2020's set-up as the lab models it: the BeagleBone's host paths and the GPI
/// measurement's spread are the three parameters fitted on the paper's 2-slave rows
/// ([`fit`]); everything else is named in docs/lab.md with its source.
#[derive(Debug, Clone, Copy, PartialEq, Serialize)]
pub struct SetupModel {
    /// The master's clock read (IgH's application time, which the FPWR to 0x0910 carries) to
    /// the frame's first bit on the wire, mean, ns.
    pub send_mean_ns: f64,
    /// The frame's last bit in to the master's clock read that ends eq. 3's round trip, mean, ns.
    pub recv_mean_ns: f64,
    /// The spread of the master's GPI detection latency (edge to interrupt), ns.
    pub gpi_master_detect_sd_ns: f64,
}

impl SetupModel {
    /// The model the `beaglebone-rt` host and [`crate::gpi::GpiSetup::park2020`] hold.
    pub fn current() -> Self {
        let (h, g) = (HostModel::beaglebone_rt(), crate::gpi::GpiSetup::park2020());
        SetupModel {
            send_mean_ns: h.send.mean_ns,
            recv_mean_ns: h.recv.mean_ns,
            gpi_master_detect_sd_ns: g.master_detect.sd_ns,
        }
    }

    /// `base` with this model's paths: each path's spread and floor keep their distance below
    /// the mean.
    pub fn host(&self, base: HostModel) -> HostModel {
        let mut h = base;
        for (l, mean) in [(&mut h.send, self.send_mean_ns), (&mut h.recv, self.recv_mean_ns)] {
            l.min_ns = (l.min_ns + mean - l.mean_ns).max(0.0);
            l.mean_ns = mean;
        }
        h
    }

    pub fn gpi(&self, base: crate::gpi::GpiSetup) -> crate::gpi::GpiSetup {
        crate::gpi::GpiSetup {
            master_detect: crate::gpi::Latency { sd_ns: self.gpi_master_detect_sd_ns, ..base.master_detect },
            ..base
        }
    }
}

/// The set-up model `o` runs on, if it is the paper's set-up: Table 1 compares with it only
/// there (the BeagleBone's host model, the line of slaves, a 1 ms cycle sampled every 2 ms).
pub fn paper_setup(o: &Options) -> Result<SetupModel, String> {
    let model = SetupModel::current();
    if o.host != model.host(HostModel::beaglebone_rt()) {
        return Err(format!("the host is {}, not the fitted beaglebone-rt", o.host.name));
    }
    if o.gpi != model.gpi(crate::gpi::GpiSetup::park2020()) {
        return Err("the GPI measurement is not the fitted one".into());
    }
    if o.segment.is_some() {
        return Err("a segment file replaces the paper's line of slaves".into());
    }
    if (o.cycle_ns, o.sample_every) != (1_000_000, 2) {
        return Err("the cycle is not the paper's 1 ms, sampled every 2 ms".into());
    }
    Ok(model)
}

/// The spread a row's GMEAN and MRMS leave: √(MRMS² − GMEAN²).
pub fn spread(gmean: f64, mrms: f64) -> f64 {
    (mrms * mrms - gmean * gmean).max(0.0).sqrt()
}

/// One step of [`fit`]: the model, and the errors against the paper's 2-slave rows it left (µs).
#[derive(Debug, Clone, Copy, PartialEq, Serialize)]
pub struct FitStep {
    pub model: SetupModel,
    pub conventional_gmean_error_us: f64,
    pub park2020_gmean_error_us: f64,
    pub conventional_spread_error_us: f64,
}

/// The set-up model fitted on Table 1's 2-slave rows as the GPI measurement reports them,
/// starting from `start`, on `base`'s run lengths and seed (its slaves, methods, host and GPI
/// replaced). Three figures set the three parameters, each through the mechanism that makes
/// it:
/// - conventional's GMEAN is the send path (the reference takes the application time when
///   the frame passes it);
/// - park2020's GMEAN is half the send path less half the receive path (eq. 3 halves the
///   round trip, whose two host paths differ), so the receive path follows from it;
/// - conventional's spread √(MRMS² − GMEAN²) is almost all the master's GPI detection.
///
/// Each step moves the parameters by those relations' slopes and runs again; it stops when
/// every error is under 20 ns, or after `steps`.
pub fn fit(base: &Options, start: SetupModel, steps: usize) -> crate::Result<Vec<FitStep>> {
    let paper = |method: &str| PAPER.iter().find(|p| p.0 == 2 && p.1 == method).copied();
    let (Some(conv), Some(park)) = (paper("conventional"), paper("park2020")) else {
        return Err(LabError::MissingRow("Table 1 has no 2-slave rows".into()));
    };
    let mut model = start;
    let mut trace = Vec::new();
    for _ in 0..steps.max(1) {
        let o = Options {
            slaves: vec![2],
            methods: vec!["conventional".into(), "park2020".into()],
            host: model.host(HostModel::beaglebone_rt()),
            gpi: model.gpi(crate::gpi::GpiSetup::park2020()),
            segment: None,
            ..base.clone()
        };
        let rows = run(&o, &|_, _| {})?;
        let row =
            |m: &str| rows.iter().find(|r| r.method == m).ok_or_else(|| LabError::MissingRow(format!("no {m} row")));
        let (c, p) = (row("conventional")?, row("park2020")?);
        let e_c = c.gpi_ref_gmean_us - conv.2;
        let e_p = p.gpi_ref_gmean_us - park.2;
        let (s_model, s_paper) = (spread(c.gpi_ref_gmean_us, c.gpi_ref_mrms_us), spread(conv.2, conv.3));
        trace.push(FitStep {
            model,
            conventional_gmean_error_us: e_c,
            park2020_gmean_error_us: e_p,
            conventional_spread_error_us: s_model - s_paper,
        });
        if [e_c, e_p, s_model - s_paper].iter().all(|e| e.abs() < 0.02) {
            break;
        }
        // conventional ≈ send + c₁, park2020 ≈ (send − recv)/2 + c₂.
        let d_send = -e_c * 1e3;
        let d_recv = d_send + 2.0 * e_p * 1e3;
        let sd = model.gpi_master_detect_sd_ns;
        let sd2 = sd * sd + (s_paper * s_paper - s_model * s_model) * 1e6;
        model = SetupModel {
            send_mean_ns: model.send_mean_ns + d_send,
            recv_mean_ns: (model.recv_mean_ns + d_recv).max(0.0),
            gpi_master_detect_sd_ns: sd2.max(0.0).sqrt(),
        };
    }
    Ok(trace)
}

/// Every published figure of Table 1 beside the same figure as the GPI measurement reports it
/// on `rows`: the 2-slave rows are the fitted part, the 6-slave rows the predicted one.
pub fn compare(rows: &[Row]) -> Vec<crate::fit::Figure> {
    use crate::fit::{Band, Figure, Part};
    let mut out = Vec::new();
    for &(n, method, rg, rm, lg, lm) in &PAPER {
        let Some(r) = rows.iter().find(|r| r.slaves == n && r.method == method) else { continue };
        let part = if n == 2 { Part::Fit } else { Part::Prediction };
        let band = Band::for_part(part);
        for (what, paper, model) in [
            ("ref GMEAN", rg, r.gpi_ref_gmean_us),
            ("ref MRMS", rm, r.gpi_ref_mrms_us),
            ("last GMEAN", lg, r.gpi_last_gmean_us),
            ("last MRMS", lm, r.gpi_last_mrms_us),
        ] {
            out.push(Figure::new(format!("{n} slaves, {method}, {what}"), "µs", part, band, paper, model));
        }
    }
    out
}
