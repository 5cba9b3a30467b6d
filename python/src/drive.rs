//! `ferrocat.Axis`: a CiA402 axis that the master's cycles drive (enable, disable, move in
//! cyclic synchronous position).
use ferrocat_master::cia402::Goal;
use pyo3::prelude::*;
use pyo3::types::PyDict;

use crate::error;
use crate::master::{detached, Master};

/// A CiA402 axis of a drive, from `Master.axis(position)`. Every master cycle walks it
/// towards its goal (the CiA402 state machine) and writes its target.
#[pyclass(module = "ferrocat")]
pub struct Axis {
    master: Py<Master>,
    index: usize,
    /// The drive's position on the segment.
    #[pyo3(get)]
    position: u16,
    /// The axis of the drive, from 0.
    #[pyo3(get)]
    axis: u8,
}

impl Axis {
    pub fn new(master: Py<Master>, index: usize, position: u16, axis: u8) -> Self {
        Axis { master, index, position, axis }
    }

    /// Cycles until the axis reaches `goal`, at most `timeout_s` of the master's clock.
    fn reach(&self, py: Python<'_>, goal: Goal, timeout_s: f64) -> PyResult<u64> {
        let m = self.master.borrow(py);
        m.cycling()?;
        let index = self.index;
        let (cycles, reached) = detached(py, &m, move |s| {
            s.axes[index].set_goal(goal);
            if goal == Goal::OperationEnabled {
                // Stand where the drive stands, so that enabling moves nothing.
                let here = s.axes[index].feedback(&s.m).position.unwrap_or(0);
                crate::master::write_position(s, index, here);
            }
            let end = s.m.cyclic().now_ns() + (timeout_s.max(0.0) * 1e9) as u64;
            let mut k = 0;
            loop {
                let a = &s.axes[index];
                let done = match goal {
                    Goal::OperationEnabled => a.feedback(&s.m).ready,
                    _ => a.state() == Some(ferrocat_master::cia402::State::SwitchOnDisabled),
                };
                if done || s.m.cyclic().now_ns() >= end {
                    return Ok((k, done));
                }
                s.step()?;
                k += 1;
            }
        })?;
        if !reached {
            let state =
                m.lock().axes[index].state().map_or_else(|| String::from("no statusword"), |s| format!("{s:?}"));
            return Err(error::text(format!(
                "slave {} axis {}: not {} after {timeout_s} s ({cycles} cycles); the drive is in {state}",
                self.position,
                self.axis,
                goal.name()
            )));
        }
        Ok(cycles)
    }
}

#[pymethods]
impl Axis {
    /// Enables operation (shutdown, switch on, enable operation) within `timeout_s`, the
    /// target held at the actual position. Returns the cycles it took.
    #[pyo3(signature = (timeout_s = 2.0))]
    fn enable(&self, py: Python<'_>, timeout_s: f64) -> PyResult<u64> {
        self.reach(py, Goal::OperationEnabled, timeout_s)
    }

    /// Disables the drive (to SWITCH ON DISABLED) within `timeout_s`.
    #[pyo3(signature = (timeout_s = 2.0))]
    fn disable(&self, py: Python<'_>, timeout_s: f64) -> PyResult<u64> {
        self.reach(py, Goal::Disabled, timeout_s)
    }

    /// Moves to `target` (increments) along a cosine profile over `seconds`, one set-point a
    /// cycle, then holds it for `settle_cycles`. Returns the actual position at the end.
    #[pyo3(signature = (target, seconds = 1.0, settle_cycles = 10))]
    fn move_to(&self, py: Python<'_>, target: i32, seconds: f64, settle_cycles: u64) -> PyResult<i32> {
        let m = self.master.borrow(py);
        m.cycling()?;
        let index = self.index;
        detached(py, &m, move |s| {
            let from = s.axes[index].feedback(&s.m).position.unwrap_or(0);
            let steps = ((seconds.max(0.0) * 1e9) as u64 / s.cycle_ns.max(1)).max(1);
            let span = target.wrapping_sub(from) as f64;
            for k in 0..=steps + settle_cycles {
                // Cosine from 0 to 1: no step in velocity at either end.
                let x = (k.min(steps) as f64 / steps as f64 * std::f64::consts::PI).cos();
                let at = from.wrapping_add((span * (1.0 - x) / 2.0).round() as i32);
                crate::master::write_position(s, index, at);
                s.step()?;
            }
            Ok(s.axes[index].feedback(&s.m).position.unwrap_or(from))
        })
    }

    /// Writes a target position for the next cycles (cyclic synchronous position).
    #[setter]
    fn set_target(&self, py: Python<'_>, position: i32) {
        let m = self.master.borrow(py);
        crate::master::write_position(&mut m.lock(), self.index, position);
    }

    /// What the drive reports now: statusword, mode, ready (operation enabled in its mode),
    /// position, velocity, torque, following error (each `None` where not mapped).
    fn feedback<'py>(&self, py: Python<'py>) -> PyResult<Bound<'py, PyDict>> {
        let m = self.master.borrow(py);
        let s = m.lock();
        let f = s.axes[self.index].feedback(&s.m);
        let d = PyDict::new(py);
        d.set_item("statusword", f.statusword)?;
        d.set_item("mode", f.mode.map(|m| m.code()))?;
        d.set_item("ready", f.ready)?;
        d.set_item("position", f.position)?;
        d.set_item("velocity", f.velocity)?;
        d.set_item("torque", f.torque)?;
        d.set_item("following_error", f.following_error)?;
        Ok(d)
    }

    /// The actual position, increments (`None` where not mapped).
    #[getter]
    fn actual_position(&self, py: Python<'_>) -> Option<i32> {
        let m = self.master.borrow(py);
        let s = m.lock();
        s.axes[self.index].feedback(&s.m).position
    }

    /// The CiA402 state from the last statusword (`OperationEnabled`, `Fault` …).
    #[getter]
    fn state(&self, py: Python<'_>) -> Option<String> {
        let m = self.master.borrow(py);
        let s = m.lock();
        s.axes[self.index].state().map(|st| format!("{st:?}"))
    }
}
