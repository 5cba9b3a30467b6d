//! `ferrocat.Client`: a client of a running `ferrocat run` — its control socket (slaves,
//! statistics, events, SDO, SDO information, registers, FoE, states) and its shared process
//! image (variables by name, read and written between the master's cycles).
use std::path::PathBuf;
use std::sync::Mutex;

use ferrocat_service::{Client as Socket, ImageClient};
use pyo3::prelude::*;
use pyo3::types::{PyBytes, PyDict};

use crate::error;

/// A running master, reached through its control socket and shared image.
#[pyclass(module = "ferrocat")]
pub struct Client {
    socket: Mutex<Socket>,
    image: Mutex<Option<ImageClient>>,
}

fn json<'py>(py: Python<'py>, v: &serde_json::Value) -> PyResult<Bound<'py, PyAny>> {
    let loads = py.import("json")?.getattr("loads")?;
    loads.call1((v.to_string(),))
}

impl Client {
    fn call<R>(
        &self,
        py: Python<'_>,
        f: impl FnOnce(&mut Socket) -> Result<R, ferrocat_service::ClientError> + Send,
    ) -> PyResult<R>
    where
        R: Send,
    {
        py.detach(|| f(&mut self.socket.lock().unwrap_or_else(|p| p.into_inner()))).map_err(error::other)
    }
    fn image<R>(&self, f: impl FnOnce(&mut ImageClient) -> PyResult<R>) -> PyResult<R> {
        let mut g = self.image.lock().unwrap_or_else(|p| p.into_inner());
        let img = g.as_mut().ok_or_else(|| {
            error::text("this master shares no process image (it runs without a control socket's image)")
        })?;
        f(img)
    }
}

#[pymethods]
impl Client {
    /// Connects to the master running on `target` (an interface name, as `ferrocat run
    /// --iface` was given, or `udp-ADDR:PORT`), or on the control socket `socket` (a path).
    /// Its shared image, beside the socket, is attached where there is one.
    #[new]
    #[pyo3(signature = (target = None, socket = None))]
    fn new(py: Python<'_>, target: Option<String>, socket: Option<PathBuf>) -> PyResult<Self> {
        let path = match (socket, target) {
            (Some(p), None) => p,
            (None, Some(t)) => ferrocat_service::find_socket(&t),
            _ => return Err(error::text("give a target (an interface name) or a socket path, not both")),
        };
        let sock = py.detach(|| Socket::connect(&path)).map_err(error::other)?;
        let image = ImageClient::attach(path.with_extension("image")).ok();
        Ok(Client { socket: Mutex::new(sock), image: Mutex::new(image) })
    }

    /// What the master said on connecting: service, protocol, pid, target, cycle_us, slaves.
    fn hello<'py>(&self, py: Python<'py>) -> PyResult<Bound<'py, PyDict>> {
        let s = self.socket.lock().unwrap_or_else(|p| p.into_inner());
        let h = s.hello();
        let d = PyDict::new(py);
        d.set_item("service", &h.service)?;
        d.set_item("protocol", h.protocol)?;
        d.set_item("pid", h.pid)?;
        d.set_item("target", &h.target)?;
        d.set_item("cycle_us", h.cycle_us)?;
        d.set_item("slaves", h.slaves)?;
        Ok(d)
    }

    /// The master's slave table, as `ferrocat slaves --json` gives it.
    fn slaves<'py>(&self, py: Python<'py>) -> PyResult<Bound<'py, PyAny>> {
        let v = self.call(py, |s| s.slaves())?;
        json(py, &serde_json::to_value(v).map_err(error::other)?)
    }

    /// The master's statistics (cycles, working counters, clock sync, diagnosis), as
    /// `ferrocat stats --json` gives them.
    fn stats<'py>(&self, py: Python<'py>) -> PyResult<Bound<'py, PyAny>> {
        let v = self.call(py, |s| s.stats())?;
        json(py, &serde_json::to_value(v).map_err(error::other)?)
    }

    /// The master's events from sequence number `since` on.
    #[pyo3(signature = (since = 0))]
    fn events<'py>(&self, py: Python<'py>, since: u64) -> PyResult<Bound<'py, PyAny>> {
        let v = self.call(py, move |s| s.events(since))?;
        json(py, &serde_json::to_value(v).map_err(error::other)?)
    }

    /// SDO upload of `index:subindex` from slave `position`, between the master's cycles.
    #[pyo3(signature = (position, index, subindex = 0))]
    fn sdo_read<'py>(&self, py: Python<'py>, position: u16, index: u16, subindex: u8) -> PyResult<Bound<'py, PyBytes>> {
        let v = self.call(py, move |s| s.sdo_read(position, index, subindex))?;
        Ok(PyBytes::new(py, &v))
    }

    /// SDO download of `data` to `index:subindex` of slave `position`.
    fn sdo_write(&self, py: Python<'_>, position: u16, index: u16, subindex: u8, data: Vec<u8>) -> PyResult<()> {
        self.call(py, move |s| s.sdo_download(position, index, subindex, false, &data))
    }

    /// SDO information: every object's index in slave `position`'s dictionary.
    fn od_list(&self, py: Python<'_>, position: u16) -> PyResult<Vec<u16>> {
        self.call(py, move |s| s.od_list(position))
    }

    /// Slave `position`'s EEPROM as the master read it.
    fn sii_read<'py>(&self, py: Python<'py>, position: u16) -> PyResult<Bound<'py, PyBytes>> {
        let v = self.call(py, move |s| s.sii_read(position))?;
        Ok(PyBytes::new(py, &v))
    }

    /// `len` bytes of ESC registers from `register` of slave `position`.
    fn register_read<'py>(
        &self,
        py: Python<'py>,
        position: u16,
        register: u16,
        len: u16,
    ) -> PyResult<Bound<'py, PyBytes>> {
        let v = self.call(py, move |s| s.register_read(position, register, len))?;
        Ok(PyBytes::new(py, &v))
    }

    /// File `file` of slave `position` by FoE (at most `max_bytes`).
    #[pyo3(signature = (position, file, password = 0, max_bytes = 1 << 20))]
    fn foe_read<'py>(
        &self,
        py: Python<'py>,
        position: u16,
        file: String,
        password: u32,
        max_bytes: usize,
    ) -> PyResult<Bound<'py, PyBytes>> {
        let v = self.call(py, move |s| s.foe_read(position, &file, password, max_bytes))?;
        Ok(PyBytes::new(py, &v))
    }

    /// `data` to slave `position` as file `file` by FoE.
    #[pyo3(signature = (position, file, data, password = 0))]
    fn foe_write(&self, py: Python<'_>, position: u16, file: String, data: Vec<u8>, password: u32) -> PyResult<()> {
        self.call(py, move |s| s.foe_write(position, &file, password, &data))
    }

    /// Slave `position` to `state` (INIT, PREOP, SAFEOP, OP); returns the state reached.
    fn request_state(&self, py: Python<'_>, position: u16, state: String) -> PyResult<String> {
        self.call(py, move |s| s.request_state(position, &state))
    }

    /// The shared image's variables' names (`POS:ENTRY`, or an ENI's variable names).
    fn variables(&self) -> PyResult<Vec<String>> {
        self.image(|i| Ok(i.variables().iter().map(|v| v.name.clone()).collect()))
    }

    /// The values of `names` (all variables without) as the master's last cycle left them,
    /// with `cycle`, `wkc` and `expected_wkc` of that cycle.
    #[pyo3(signature = (names = None))]
    fn read<'py>(&self, py: Python<'py>, names: Option<Vec<String>>) -> PyResult<Bound<'py, PyDict>> {
        self.image(|i| {
            let snap = i.read().map_err(error::other)?;
            let d = PyDict::new(py);
            let vars: Vec<_> = match &names {
                Some(n) => n.iter().map(|n| i.variable(n).cloned().map_err(error::other)).collect::<PyResult<_>>()?,
                None => i.variables().to_vec(),
            };
            for v in &vars {
                d.set_item(&v.name, snap.get(v))?;
            }
            let out = PyDict::new(py);
            out.set_item("cycle", snap.cycle)?;
            out.set_item("wkc", snap.wkc)?;
            out.set_item("expected_wkc", snap.expected_wkc)?;
            out.set_item("running", snap.running)?;
            out.set_item("values", d)?;
            Ok(out)
        })
    }

    /// Writes output variables, all in one cycle or none (a dict of name → value). Returns
    /// the write's sequence number.
    fn write(&self, values: std::collections::HashMap<String, u64>) -> PyResult<u64> {
        self.image(|i| {
            let pairs: Vec<(&str, u64)> = values.iter().map(|(k, v)| (k.as_str(), *v)).collect();
            i.write(&pairs).map_err(error::other)
        })
    }
}
