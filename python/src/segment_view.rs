//! `Master.segment`: the faults and counters of the virtual segment a master runs on.
use pyo3::prelude::*;
use pyo3::types::PyDict;

use crate::error;
use crate::master::Master;

/// The virtual segment of a `Master.virtual`: faults scheduled on the segment's clock, its
/// counters, and what only a simulator knows (each clock's true time).
#[pyclass(module = "ferrocat")]
pub struct SegmentView {
    master: Py<Master>,
}

impl SegmentView {
    pub fn new(master: Py<Master>) -> Self {
        SegmentView { master }
    }
    fn with<R>(&self, py: Python<'_>, f: impl FnOnce(&mut ferrocat_segment::VirtualIo) -> PyResult<R>) -> PyResult<R> {
        let m = self.master.borrow(py);
        let mut s = m.lock();
        let v = s.m.cyclic().io_mut().virtual_io().ok_or_else(|| error::text("not a virtual segment"))?;
        f(v)
    }
}

#[pymethods]
impl SegmentView {
    /// As `Segment.fault`: `kind` at `at_s` seconds of segment time from now.
    #[pyo3(signature = (kind, node, at_s = 0.0, port = 0, code = 0x2310, delta_ppb = 0))]
    #[allow(clippy::too_many_arguments)]
    fn fault(
        &self,
        py: Python<'_>,
        kind: &str,
        node: usize,
        at_s: f64,
        port: u8,
        code: u16,
        delta_ppb: i64,
    ) -> PyResult<()> {
        self.with(py, |v| crate::segment::schedule(&mut v.seg, kind, node, at_s, port, code, delta_ppb))
    }

    /// The chance, 0 to 1, that the segment loses a frame.
    #[getter]
    fn get_loss_probability(&self, py: Python<'_>) -> PyResult<f64> {
        self.with(py, |v| Ok(v.seg.loss_probability))
    }
    #[setter]
    fn set_loss_probability(&self, py: Python<'_>, p: f64) -> PyResult<()> {
        self.with(py, |v| crate::segment::set_loss(&mut v.seg, p))
    }

    /// The segment's counters: frames, returned, lost, corrupted, its time.
    fn stats<'py>(&self, py: Python<'py>) -> PyResult<Bound<'py, PyDict>> {
        self.with(py, |v| crate::segment::stats(py, &v.seg))
    }

    /// The device at `node`'s AL state as the simulated ESC holds it (`op`, `safeop` …).
    fn device_state(&self, py: Python<'_>, node: usize) -> PyResult<String> {
        self.with(py, |v| {
            let n = v.seg.nodes.get(node).ok_or_else(|| error::text(format!("no device {node}")))?;
            Ok(n.esc.al_status().state().map_or_else(|| String::from("unknown"), |s| s.name().to_ascii_lowercase()))
        })
    }

    /// The true offset, ns, of the master's clock from the reference's system time now: what
    /// the simulator knows and the master can only estimate. `None` before DC.
    fn true_offset_ns(&self, py: Python<'_>) -> PyResult<Option<i64>> {
        let m = self.master.borrow(py);
        let mut s = m.lock();
        // Before DC the master's clock is not the segment's system time.
        if s.sync.is_none() {
            return Ok(None);
        }
        let now = s.m.cyclic().now_ns();
        let master_time = s.m.clock().master_system_time_at(now);
        let v = s.m.cyclic().io_mut().virtual_io().ok_or_else(|| error::text("not a virtual segment"))?;
        let reference = v.seg.nodes.iter().find(|n| n.esc.has_system_time()).and_then(|n| n.esc.dc.as_ref());
        Ok(reference.map(|dc| master_time.wrapping_sub(dc.system_at(now)) as i64))
    }
}
