//! `ferrocat.Segment`: a virtual EtherCAT segment built in-process, to hand to a master in
//! virtual time (`Master.virtual`) or to serve on an interface for any master.
use std::sync::atomic::{AtomicBool, Ordering};
use std::sync::{Arc, Mutex};
use std::thread::JoinHandle;

use ferrocat_segment::{Event, Segment as Seg, SegmentConfig};
use ferrocat_sim::serve::ServeStats;
use pyo3::prelude::*;
use pyo3::types::PyDict;

use crate::error;

/// A virtual segment: devices in a line, their clocks, wire timing and faults. Deterministic
/// by seed: the same seed gives the same frames and clocks on any machine.
#[pyclass(module = "ferrocat")]
pub struct Segment {
    seg: Mutex<Option<Seg>>,
    serving: Mutex<Option<Serving>>,
}

struct Serving {
    stop: Arc<AtomicBool>,
    thread: JoinHandle<(Seg, std::io::Result<ServeStats>)>,
}

impl Segment {
    fn wrap(seg: Seg) -> Self {
        Segment { seg: Mutex::new(Some(seg)), serving: Mutex::new(None) }
    }
    /// The segment, taken out for a master in virtual time.
    pub fn take(&self) -> PyResult<Seg> {
        self.seg.lock().unwrap_or_else(|p| p.into_inner()).take().ok_or_else(gone)
    }
    fn with<R>(&self, f: impl FnOnce(&mut Seg) -> PyResult<R>) -> PyResult<R> {
        let mut g = self.seg.lock().unwrap_or_else(|p| p.into_inner());
        f(g.as_mut().ok_or_else(gone)?)
    }
}

fn gone() -> PyErr {
    error::text("this segment is in use: a master took it (Master.virtual) or it is being served")
}

fn build(cfg: SegmentConfig, seed: Option<u64>) -> PyResult<Seg> {
    let mut cfg = cfg;
    if let Some(s) = seed {
        cfg.seed = s;
    }
    cfg.build().map_err(error::other)
}

#[pymethods]
impl Segment {
    /// A line of devices, each as `ferrocat run --device` takes it: a built-in name (`EK1100`,
    /// `EL2004`, `SERVO` …), an EEPROM dump, `ESI.xml:PRODUCT` or `ESI.xml:PRODUCT:MODULE,…`.
    #[new]
    #[pyo3(signature = (devices, seed = None))]
    fn new(devices: Vec<String>, seed: Option<u64>) -> PyResult<Self> {
        if devices.is_empty() {
            return Err(error::text("a segment needs at least one device"));
        }
        let cfg = SegmentConfig::from_device_args(&devices).map_err(error::other)?;
        Ok(Self::wrap(build(cfg, seed)?))
    }

    /// A segment file (TOML, docs/segment-model.md).
    #[staticmethod]
    #[pyo3(signature = (path, seed = None))]
    fn from_file(path: std::path::PathBuf, seed: Option<u64>) -> PyResult<Self> {
        let cfg = SegmentConfig::from_file(&path).map_err(error::other)?;
        Ok(Self::wrap(build(cfg, seed)?))
    }

    /// The network an ENI file (ETG.2100) describes, each slave simulated from the file.
    #[staticmethod]
    #[pyo3(signature = (path, seed = None))]
    fn from_eni(path: std::path::PathBuf, seed: Option<u64>) -> PyResult<Self> {
        let cfg = SegmentConfig::from_eni(&path).map_err(error::other)?;
        Ok(Self::wrap(build(cfg, seed)?))
    }

    /// The machine a ferrocat machine description (TOML, docs/machine.md) describes: each
    /// slave's `device`, in order.
    #[staticmethod]
    #[pyo3(signature = (path, seed = None))]
    fn from_machine(path: std::path::PathBuf, seed: Option<u64>) -> PyResult<Self> {
        let cfg = SegmentConfig::from_machine(&path).map_err(error::other)?;
        Ok(Self::wrap(build(cfg, seed)?))
    }

    /// The devices' names, in line order.
    #[getter]
    fn devices(&self) -> PyResult<Vec<String>> {
        self.with(|s| Ok(s.nodes.iter().map(|n| n.name.clone()).collect()))
    }

    /// The chance, 0 to 1, that the segment loses a frame (drawn from the seed).
    #[getter]
    fn get_loss_probability(&self) -> PyResult<f64> {
        self.with(|s| Ok(s.loss_probability))
    }
    #[setter]
    fn set_loss_probability(&self, p: f64) -> PyResult<()> {
        self.with(|s| set_loss(s, p))
    }

    /// Schedules a fault `at_s` seconds of segment time from now (0: before the next frame).
    /// `kind` is one of `link_down`, `link_up` (with `port`), `power_off`, `power_on`,
    /// `drive_fault` (with `code`, a CiA402 drive's own fault), `al_error` (with `code`, its
    /// application's local error: SAFEOP with the error bit) and `drift_step` (with
    /// `delta_ppb`). `node` counts devices from 0 in line order.
    #[pyo3(signature = (kind, node, at_s = 0.0, port = 0, code = 0x2310, delta_ppb = 0))]
    fn fault(&self, kind: &str, node: usize, at_s: f64, port: u8, code: u16, delta_ppb: i64) -> PyResult<()> {
        self.with(|s| schedule(s, kind, node, at_s, port, code, delta_ppb))
    }

    /// Counters of the segment: frames, returned, lost, corrupted.
    fn stats<'py>(&self, py: Python<'py>) -> PyResult<Bound<'py, PyDict>> {
        self.with(|s| stats(py, s))
    }

    /// Serves the segment on a network interface (a raw socket: root or CAP_NET_RAW), in a
    /// thread of its own, until `stop()`. Any master may then use the interface's peer.
    fn serve(&self, iface: &str) -> PyResult<()> {
        let mut serving = self.serving.lock().unwrap_or_else(|p| p.into_inner());
        if serving.is_some() {
            return Err(error::text("this segment is being served already"));
        }
        let sock = ferrocat_sim::serve::RawSocket::open(iface)
            .map_err(|e| error::text(format!("serving interface {iface}: {e}")))?;
        let mut seg = self.take()?;
        let stop = Arc::new(AtomicBool::new(false));
        let flag = Arc::clone(&stop);
        let thread = std::thread::Builder::new()
            .name(format!("ferrocat-sim {iface}"))
            .spawn(move || {
                let r = ferrocat_sim::serve::serve_raw(&mut seg, &sock, None, &flag, false, &mut []);
                (seg, r)
            })
            .map_err(error::other)?;
        *serving = Some(Serving { stop, thread });
        Ok(())
    }

    /// Ends `serve()`: the segment is this object's again. Returns the serving counters
    /// (frames in and out, malformed, taken late, the devices' sync errors).
    fn stop<'py>(&self, py: Python<'py>) -> PyResult<Bound<'py, PyDict>> {
        let Some(s) = self.serving.lock().unwrap_or_else(|p| p.into_inner()).take() else {
            return Err(error::text("this segment is not being served"));
        };
        s.stop.store(true, Ordering::Relaxed);
        let (seg, result) = py.detach(|| s.thread.join()).map_err(|_| error::text("the serving thread panicked"))?;
        *self.seg.lock().unwrap_or_else(|p| p.into_inner()) = Some(seg);
        let st = result.map_err(|e| error::text(format!("serving: {e}")))?;
        let d = PyDict::new(py);
        d.set_item("frames_in", st.frames_in)?;
        d.set_item("frames_out", st.frames_out)?;
        d.set_item("not_ethercat", st.not_ethercat)?;
        d.set_item("malformed", st.malformed)?;
        d.set_item("taken_late", st.taken_late)?;
        d.set_item("sync_errors", st.sync_errors.len())?;
        Ok(d)
    }

    fn __repr__(&self) -> String {
        match self.seg.lock().unwrap_or_else(|p| p.into_inner()).as_ref() {
            Some(s) => {
                format!("Segment([{}])", s.nodes.iter().map(|n| format!("'{}'", n.name)).collect::<Vec<_>>().join(", "))
            }
            None => String::from("Segment(<in use>)"),
        }
    }
}

pub fn set_loss(s: &mut Seg, p: f64) -> PyResult<()> {
    if !(0.0..=1.0).contains(&p) {
        return Err(error::text(format!("loss probability {p}: give 0 to 1")));
    }
    s.loss_probability = p;
    Ok(())
}

pub fn schedule(s: &mut Seg, kind: &str, node: usize, at_s: f64, port: u8, code: u16, delta_ppb: i64) -> PyResult<()> {
    if node >= s.nodes.len() {
        return Err(error::text(format!(
            "no device {node}: the segment has {} (0 to {})",
            s.nodes.len(),
            s.nodes.len().saturating_sub(1)
        )));
    }
    if port > 3 {
        return Err(error::text(format!("port {port}: an ESC has ports 0 to 3")));
    }
    if !(0.0..=1e6).contains(&at_s) {
        return Err(error::text(format!("at_s {at_s}: give 0 to 1e6 seconds from now")));
    }
    let event = match kind {
        "link_down" => Event::LinkDown { node, port },
        "link_up" => Event::LinkUp { node, port },
        "power_off" => Event::PowerOff { node },
        "power_on" => Event::PowerOn { node },
        "drive_fault" => Event::DriveFault { node, code },
        "al_error" => Event::AlError { node, code },
        "drift_step" => Event::DriftStep { node, delta_ppb },
        other => {
            return Err(error::text(format!(
                "unknown fault '{other}': give link_down, link_up, power_off, power_on, drive_fault, al_error or drift_step"
            )))
        }
    };
    let at = s.now_ns() + (at_s * 1e9) as u64;
    s.schedule(at, event);
    Ok(())
}

pub fn stats<'py>(py: Python<'py>, s: &Seg) -> PyResult<Bound<'py, PyDict>> {
    let d = PyDict::new(py);
    d.set_item("frames", s.stats.frames)?;
    d.set_item("returned", s.stats.returned)?;
    d.set_item("lost", s.stats.lost)?;
    d.set_item("corrupted", s.stats.corrupted)?;
    d.set_item("time_s", s.now_ns() as f64 * 1e-9)?;
    Ok(d)
}
