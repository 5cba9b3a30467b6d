//! `ferrocat.Master`: the master in-process, on a raw interface, over UDP or on a virtual
//! segment in virtual time. Every call that waits on the wire releases the GIL.
use std::sync::{Arc, Mutex, MutexGuard};
use std::time::Duration;

use ferrocat_io::Io;
use ferrocat_master::cia402::{self, Goal, Mode, Output};
use ferrocat_master::io::{RawIo, UdpIo};
use ferrocat_master::sync::{ClockSync, Coupling, Sync0Plan, SyncMethod};
use ferrocat_master::{AlState, Answer, DcConfig, Handle, Request, SyncState};
use ferrocat_segment::{HostModel, VirtualIo};
use pyo3::prelude::*;
use pyo3::types::{PyBytes, PyDict};

use crate::error;
use crate::slave::{Slave, Variable};
use crate::world::{Link, World};

type Inner = ferrocat_master::Master<World>;

/// What the Python master keeps between calls.
pub struct State {
    pub m: Inner,
    /// The clock-sync method and its state, with DC.
    pub sync: Option<(Box<dyn ClockSync>, SyncState)>,
    /// The cycle, ns (0 before `bring_up`).
    pub cycle_ns: u64,
    /// The next cycle's planned start, the world's clock.
    pub next_ns: u64,
    /// The CiA402 axes the cycle drives.
    pub axes: Vec<cia402::Axis>,
    /// Cycles started later than planned (the one before ran past its period).
    pub overruns: u64,
}

/// An EtherCAT master. Make one with `Master.open(iface)`, `Master.udp(addr)` or
/// `Master.virtual(segment)`.
#[pyclass(module = "ferrocat")]
pub struct Master {
    state: Arc<Mutex<State>>,
    /// The segment's lock (`RUNDIR/TARGET.lock`, as `ferrocat run` takes it): one master per
    /// segment. `None` on a virtual segment, or where no lock could be made (warned of).
    _lock: Option<ferrocat_service::MasterLock>,
    /// The cyclic loop's thread, while it runs (`start`).
    running: Mutex<Option<crate::running::Running>>,
}

impl Master {
    fn of(world: World, lock: Option<ferrocat_service::MasterLock>) -> Self {
        let state = State { m: Inner::new(world), sync: None, cycle_ns: 0, next_ns: 0, axes: Vec::new(), overruns: 0 };
        Master { state: Arc::new(Mutex::new(state)), _lock: lock, running: Mutex::new(None) }
    }
    /// An error unless `bring_up` has set a cycle and the loop is not running (which runs
    /// the cycles itself).
    pub fn cycling(&self) -> PyResult<()> {
        self.not_running("run cycles")?;
        if self.lock().cycle_ns == 0 {
            return Err(error::text("no cycle yet: call bring_up(cycle_us=…) first"));
        }
        Ok(())
    }
    /// An error while the loop runs: `what` would take the master from it.
    pub fn not_running(&self, what: &str) -> PyResult<()> {
        if self.running.lock().unwrap_or_else(|p| p.into_inner()).is_some() {
            return Err(error::text(format!("the cyclic loop is running (start()): stop() it to {what}")));
        }
        Ok(())
    }

    /// An acyclic service: through the running loop, between its cycles, or directly.
    fn service(&self, py: Python<'_>, request: Request) -> PyResult<Answer> {
        if !matches!(request, Request::State { .. }) {
            let s = self.lock();
            let position = request.position();
            let slave = s.m.slaves().at(position).map_err(error::master)?;
            if slave.status().state() == AlState::Init {
                return Err(error::text(format!(
                    "slave {position} ({}) is in INIT, where it has no mailbox: configure() or bring_up() first",
                    slave.name()
                )));
            }
        }
        let requests = self.running.lock().unwrap_or_else(|p| p.into_inner()).as_ref().map(|r| r.requests.clone());
        let Some(requests) = requests else {
            return detached(py, self, move |s| direct(s, request));
        };
        let (tx, rx) = std::sync::mpsc::sync_channel(1);
        requests.try_send((request, tx)).map_err(|e| match e {
            std::sync::mpsc::TrySendError::Full(_) => {
                error::text(format!("{} requests wait already: try again when one is answered", crate::running::QUEUE))
            }
            std::sync::mpsc::TrySendError::Disconnected(_) => error::text("the cyclic loop has stopped"),
        })?;
        // The master answers every request (an error after the mailbox timeout at most); the
        // wait's own limit only guards against a loop that stopped meanwhile.
        py.detach(move || rx.recv_timeout(Duration::from_secs(60)))
            .map_err(|_| error::text("no answer from the cyclic loop in 60 s"))?
            .map_err(error::master)
    }

    pub fn lock(&self) -> MutexGuard<'_, State> {
        self.state.lock().unwrap_or_else(|p| p.into_inner())
    }
}

pub fn al_state(name: &str) -> PyResult<AlState> {
    Ok(match name.to_ascii_lowercase().as_str() {
        "init" => AlState::Init,
        "preop" | "pre-op" => AlState::PreOp,
        "boot" | "bootstrap" => AlState::Bootstrap,
        "safeop" | "safe-op" => AlState::SafeOp,
        "op" => AlState::Op,
        _ => return Err(error::text(format!("state '{name}': give init, preop, bootstrap, safeop or op"))),
    })
}

impl State {
    /// One cycle: the axes' commands, the frame (with the clock sync's datagrams under DC),
    /// then a sleep to the next cycle's start on the master's clock. Returns the working
    /// counter.
    pub fn step(&mut self) -> ferrocat_master::Result<u16> {
        let wkc = self.exchange()?;
        let next = self.next_ns;
        self.m.cyclic().sleep_until(next);
        Ok(wkc)
    }

    /// A cycle without its sleep: `next_ns` is where the next one starts.
    pub fn exchange(&mut self) -> ferrocat_master::Result<u16> {
        let m = &mut self.m;
        for a in self.axes.iter_mut() {
            a.update(m);
        }
        let (wkc, period) = match self.sync.as_mut() {
            Some((method, st)) => {
                let (wkc, c) = m.cyclic().cycle_sync(method.as_mut(), st)?;
                (wkc, c.next_period_ns.unwrap_or(self.cycle_ns))
            }
            None => (m.cyclic().cycle()?, self.cycle_ns),
        };
        self.next_ns += period;
        let now = m.cyclic().now_ns();
        if now > self.next_ns {
            // A whole cycle or more behind: the missed ones are skipped, on the same grid.
            self.overruns += 1;
            self.next_ns += (now - self.next_ns) / period.max(1) * period;
        }
        Ok(wkc)
    }

    fn handle(&self, position: u16, name: &str, output: bool) -> ferrocat_master::Result<Handle> {
        let image = self.m.image();
        if output {
            image.output(position, name)
        } else {
            image.input(position, name).or_else(|_| image.output(position, name))
        }
    }
}

/// Runs `f` on the master's state with the GIL released: other Python threads go on while
/// the master waits on the wire.
pub fn detached<R: Send>(
    py: Python<'_>,
    master: &Master,
    f: impl FnOnce(&mut State) -> ferrocat_master::Result<R> + Send,
) -> PyResult<R> {
    py.detach(|| f(&mut master.lock())).map_err(error::master)
}

#[pymethods]
impl Master {
    /// A master on a network interface (a raw socket: root, or CAP_NET_RAW). `io` is how
    /// frames move, as `ferrocat run --io` takes it: `auto` (io_uring where the kernel allows
    /// it, else socket calls), `uring`, `socket`, or `ring` (a packet ring spun on for
    /// `spin_us` before a receive sleeps: for a core of the master's own).
    #[staticmethod]
    #[pyo3(signature = (iface, io = "auto", spin_us = 50))]
    fn open(py: Python<'_>, iface: &str, io: &str, spin_us: u64) -> PyResult<Self> {
        use ferrocat_master::io::LinkPath;
        let path = match io {
            "auto" => LinkPath::Auto,
            "uring" => LinkPath::Uring,
            "socket" => LinkPath::Socket,
            "ring" => LinkPath::Ring { spin_ns: spin_us.saturating_mul(1000) },
            other => return Err(error::text(format!("io '{other}': give auto, uring, socket or ring"))),
        };
        let lock = take_segment(py, iface)?;
        let io = RawIo::open_with(iface, path).map_err(|e| error::text(format!("{iface}: {e}")))?;
        Ok(Self::of(World::new(Link::Raw(io)), lock))
    }

    /// A master speaking EtherCAT over UDP to `addr` (`HOST:PORT`, e.g. a `ferrocat sim --udp`).
    #[staticmethod]
    fn udp(py: Python<'_>, addr: &str) -> PyResult<Self> {
        let lock = take_segment(py, &format!("udp-{addr}"))?;
        let io = UdpIo::open(addr).map_err(|e| error::text(format!("{addr}: {e}")))?;
        Ok(Self::of(World::new(Link::Udp(io)), lock))
    }

    /// A master on `segment` in virtual time: every cycle, sleep and timeout is the segment's
    /// clock, so a run is as fast as the machine computes it and the same for the same seed.
    /// `host` is the model of the master's host (`pc-rt`, `pc-stock`, `ideal`, `nic-hwts`,
    /// `beaglebone-rt`, `rtx-10us`). The segment is the master's from here.
    #[staticmethod]
    #[pyo3(signature = (segment, host = "pc-rt", seed = 0))]
    fn r#virtual(segment: &crate::segment::Segment, host: &str, seed: u64) -> PyResult<Self> {
        let model = HostModel::preset(host).ok_or_else(|| {
            error::text(format!("unknown host model '{host}' (known: {})", HostModel::PRESETS.join(", ")))
        })?;
        let seg = segment.take()?;
        Ok(Self::of(World::new(Link::Virtual(Box::new(VirtualIo::new(seg, model, seed)))), None))
    }

    /// Counts and reads every slave (INIT): identity, EEPROM, mailbox, DC, ports.
    fn scan(&self, py: Python<'_>) -> PyResult<Vec<Slave>> {
        self.not_running("scan")?;
        detached(py, self, |s| s.m.states().scan())?;
        Ok(self.slaves())
    }

    /// The slaves the last scan found.
    #[getter]
    fn slaves(&self) -> Vec<Slave> {
        let s = self.lock();
        s.m.slaves().iter().map(Slave::from).collect()
    }

    /// Takes every slave to PREOP with its mailbox set up and its process data mapped (from
    /// CoE, the SII or ESI), scanning first unless done: SDO, SDO information and FoE work
    /// from here. Returns the slaves.
    fn configure(&self, py: Python<'_>) -> PyResult<Vec<Slave>> {
        self.not_running("configure")?;
        detached(py, self, |s| {
            if s.m.slaves().is_empty() {
                s.m.states().scan()?;
            }
            s.m.states().configure()
        })?;
        Ok(self.slaves())
    }

    /// Brings every slave to OP with cycles of `cycle_us`: scan (unless done), process data
    /// mapped from CoE, the SII or ESI, then with `dc` the distributed clocks and the clock-sync
    /// method `sync` (SYNC0 placed half a cycle from the frame's passage). `csp` lists CiA402
    /// drives to map for cyclic synchronous position first. Returns the slaves.
    #[pyo3(signature = (cycle_us = 1000, dc = false, sync = "ferrocat", csp = Vec::new()))]
    fn bring_up(&self, py: Python<'_>, cycle_us: u64, dc: bool, sync: &str, csp: Vec<u16>) -> PyResult<Vec<Slave>> {
        if !(50..=1_000_000).contains(&cycle_us) {
            return Err(error::text(format!("cycle_us {cycle_us}: give 50 to 1 000 000")));
        }
        let method = if dc {
            Some(SyncMethod::preset(sync, Coupling::ReferenceFollowsMaster).ok_or_else(|| {
                error::text(format!("sync '{sync}': not a method ({})", SyncMethod::PRESETS.join(", ")))
            })?)
        } else {
            None
        };
        let cycle_ns = cycle_us * 1000;
        self.not_running("bring the segment up again")?;
        detached(py, self, move |s| {
            if s.m.slaves().is_empty() {
                s.m.states().scan()?;
            }
            s.m.states().configure()?;
            for &p in &csp {
                cia402::map_for_csp(&mut s.m, p)?;
            }
            // A frame a little later than the round trip is not lost; one later than the
            // cycle's spare half is.
            let round_trip_ns = s.m.dc().median_round_trip_ns(16)?.max(0) as u64;
            let timeout_ns =
                (cycle_ns * 3 / 4).min(1_000_000).max(round_trip_ns + cycle_ns.saturating_sub(round_trip_ns) / 2);
            s.m.config().settings_mut().cyclic_timeout_ns = timeout_ns;
            let mut grid_ns = None;
            if let Some(method) = &method {
                let plan = Sync0Plan::new(method, cycle_ns, round_trip_ns, None);
                let cfg = DcConfig {
                    sync0_cycle_ns: cycle_ns.min(u32::MAX as u64) as u32,
                    sync0_shift_ns: plan.shift_ns as i32,
                    ..Default::default()
                };
                let (sync, report, st) = s.m.clock().start_clock_sync(&cfg, method, cycle_ns)?;
                s.sync = Some((sync, st));
                grid_ns = report.sync0_start.map(|t| t.wrapping_sub(plan.shift_ns));
            }
            s.m.states().start()?;
            s.m.cyclic().set_period_ns(cycle_ns);
            s.cycle_ns = cycle_ns;
            s.next_ns = match grid_ns {
                Some(grid) => s.m.clock().next_on_grid_ns(grid, cycle_ns),
                None => s.m.cyclic().now_ns(),
            };
            s.m.cyclic().sleep_until(s.next_ns);
            Ok(())
        })?;
        Ok(self.slaves())
    }

    /// Requests `state` (`init`, `preop`, `bootstrap`, `safeop`, `op`) of one slave, or of
    /// all with `position=None`, and waits until it is reached.
    #[pyo3(signature = (state, position = None))]
    fn request_state(&self, py: Python<'_>, state: &str, position: Option<u16>) -> PyResult<()> {
        let st = al_state(state)?;
        match position {
            Some(position) => self.service(py, Request::State { position, state: st }).map(|_| ()),
            None => {
                self.not_running("request a state of every slave (give a position)")?;
                detached(py, self, move |s| s.m.states().request_state_all(st))
            }
        }
    }

    /// Steps every slave down to INIT (PREOP first where it is higher) and ends the cycles.
    fn shut_down(&self, py: Python<'_>) -> PyResult<()> {
        self.not_running("shut down")?;
        detached(py, self, |s| {
            s.cycle_ns = 0;
            s.sync = None;
            s.axes.clear();
            s.m.states().shut_down()
        })
    }

    /// One cycle: outputs out, inputs in (and the clock sync's datagrams with DC), then a
    /// sleep to the next cycle's start. Returns the working counter.
    fn cycle(&self, py: Python<'_>) -> PyResult<u16> {
        self.cycling()?;
        detached(py, self, |s| s.step())
    }

    /// One cycle without the sleep after it (outputs out, inputs in), for an application that
    /// keeps its own time, as pysoem's `send_processdata` and `receive_processdata`. Returns
    /// the working counter.
    fn exchange(&self, py: Python<'_>) -> PyResult<u16> {
        self.cycling()?;
        detached(py, self, |s| s.exchange())
    }

    /// `cycles` cycles in a row, in Rust, the GIL released. Returns the cycles whose working
    /// counter was short.
    fn run(&self, py: Python<'_>, cycles: u64) -> PyResult<u64> {
        self.cycling()?;
        detached(py, self, move |s| {
            let want = s.m.image().expected_wkc();
            let mut short = 0;
            for _ in 0..cycles {
                short += u64::from(s.step()? != want);
            }
            Ok(short)
        })
    }

    /// The working counter a whole cycle comes back with.
    #[getter]
    fn expected_wkc(&self) -> u16 {
        self.lock().m.image().expected_wkc()
    }

    /// The master's clock, ns (virtual time on a virtual segment; CLOCK_MONOTONIC otherwise).
    #[getter]
    fn now_ns(&self) -> u64 {
        self.lock().m.cyclic().now_ns()
    }

    /// Every mapped entry of every slave.
    fn variables(&self) -> Vec<Variable> {
        let s = self.lock();
        s.m.slaves().iter().flat_map(Variable::all_of).collect()
    }

    /// The value of the entry `name` of slave `position` from the image (an input, else an
    /// output). `signed` reads it as a two's-complement number of its width.
    #[pyo3(signature = (position, name, signed = false))]
    fn get(&self, position: u16, name: &str, signed: bool) -> PyResult<i128> {
        let s = self.lock();
        let h = s.handle(position, name, false).map_err(error::master)?;
        let raw = s.m.image().get(h);
        Ok(if signed && h.bits < 64 && h.bits > 0 && raw >> (h.bits - 1) & 1 == 1 {
            raw as i128 - (1i128 << h.bits)
        } else if signed && h.bits == 64 {
            raw as i64 as i128
        } else {
            raw as i128
        })
    }

    /// Sets the output entry `name` of slave `position` for the next cycles; a negative value
    /// is written in two's complement of the entry's width.
    fn set(&self, position: u16, name: &str, value: i128) -> PyResult<()> {
        let mut s = self.lock();
        let h = s.handle(position, name, true).map_err(error::master)?;
        let bits = u32::from(h.bits.max(1));
        let (lo, hi) = (-(1i128 << (bits - 1)), (1i128 << bits) - 1);
        if value < lo || value > hi {
            return Err(error::text(format!("{value} does not fit '{name}' of slave {position} ({bits} bits)")));
        }
        let raw = if value < 0 { (value + (1i128 << bits)) as u64 } else { value as u64 };
        s.m.cyclic().set(h, raw);
        Ok(())
    }

    /// The whole process image as of the last cycle (outputs, then inputs), as bytes:
    /// `memoryview(m.image())` or `numpy.frombuffer(m.image(), dtype=numpy.uint8)`.
    fn image<'py>(&self, py: Python<'py>) -> Bound<'py, PyBytes> {
        PyBytes::new(py, self.lock().m.image().bytes())
    }

    /// Bytes of outputs and of inputs in the image.
    #[getter]
    fn image_sizes(&self) -> (u32, u32) {
        self.lock().m.image().byte_counts()
    }

    /// SDO upload of `index:subindex` from slave `position` (the whole object from
    /// `subindex` on with `complete`).
    #[pyo3(signature = (position, index, subindex = 0, complete = false))]
    fn sdo_read<'py>(
        &self,
        py: Python<'py>,
        position: u16,
        index: u16,
        subindex: u8,
        complete: bool,
    ) -> PyResult<Bound<'py, PyBytes>> {
        match self.service(py, Request::SdoRead { position, index, subindex, complete_access: complete })? {
            Answer::Data(v) => Ok(PyBytes::new(py, &v)),
            other => Err(unexpected(other)),
        }
    }

    /// SDO download of `data` to `index:subindex` of slave `position`.
    #[pyo3(signature = (position, index, subindex, data, complete = false))]
    fn sdo_write(
        &self,
        py: Python<'_>,
        position: u16,
        index: u16,
        subindex: u8,
        data: Vec<u8>,
        complete: bool,
    ) -> PyResult<()> {
        self.service(py, Request::SdoWrite { position, index, subindex, complete_access: complete, data })?;
        Ok(())
    }

    /// SDO information: every object's index in slave `position`'s dictionary.
    fn od_list(&self, py: Python<'_>, position: u16) -> PyResult<Vec<u16>> {
        match self.service(py, Request::OdList { position })? {
            Answer::List(v) => Ok(v),
            other => Err(unexpected(other)),
        }
    }

    /// SDO information: an object's description (name, object code, data type, subindices).
    fn object_info<'py>(&self, py: Python<'py>, position: u16, index: u16) -> PyResult<Bound<'py, PyDict>> {
        let Answer::Object(o) = self.service(py, Request::ObjectInfo { position, index })? else {
            return Err(error::text("an answer of another kind"));
        };
        let d = PyDict::new(py);
        d.set_item("index", o.index)?;
        d.set_item("name", o.name)?;
        d.set_item("data_type", o.data_type)?;
        d.set_item("max_subindex", o.max_subindex)?;
        d.set_item("object_code", o.object_code)?;
        Ok(d)
    }

    /// SDO information: an entry's description (name, data type, bits, access).
    fn entry_info<'py>(
        &self,
        py: Python<'py>,
        position: u16,
        index: u16,
        subindex: u8,
    ) -> PyResult<Bound<'py, PyDict>> {
        let Answer::Entry(e) = self.service(py, Request::EntryInfo { position, index, subindex })? else {
            return Err(error::text("an answer of another kind"));
        };
        let d = PyDict::new(py);
        d.set_item("index", index)?;
        d.set_item("subindex", e.subindex)?;
        d.set_item("name", e.name)?;
        d.set_item("data_type", e.data_type)?;
        d.set_item("bits", e.bit_length)?;
        d.set_item("access", e.access)?;
        Ok(d)
    }

    /// Slave `position`'s EEPROM (SII) as read at the scan, as bytes (word N at byte 2N).
    fn sii_read<'py>(&self, py: Python<'py>, position: u16) -> PyResult<Bound<'py, PyBytes>> {
        let s = self.lock();
        let img = s.m.slaves().at(position).map_err(error::master)?.sii().to_image();
        Ok(PyBytes::new(py, &img))
    }

    /// The clock sync with DC: method, lock state (`unlocked`, `locking`, `locked`), the
    /// filtered offset to the reference (ns), frames lost; `None` without DC.
    fn clock_sync<'py>(&self, py: Python<'py>) -> PyResult<Option<Bound<'py, PyDict>>> {
        let s = self.lock();
        let Some((method, st)) = s.sync.as_ref() else { return Ok(None) };
        let d = PyDict::new(py);
        d.set_item("method", method.name())?;
        d.set_item("lock", st.lock.state().name())?;
        d.set_item("offset_ns", st.lock.offset_ns())?;
        d.set_item("lost", st.lost)?;
        Ok(Some(d))
    }

    /// Counters of the cycles: cycles, working-counter errors, frames lost, overruns, the
    /// last round trip (ns).
    fn stats<'py>(&self, py: Python<'py>) -> PyResult<Bound<'py, PyDict>> {
        let mut s = self.lock();
        let st = s.m.diagnosis().cycle_stats();
        let d = PyDict::new(py);
        d.set_item("cycles", st.cycles)?;
        d.set_item("wkc_errors", st.wkc_errors)?;
        d.set_item("last_wkc", st.last_wkc)?;
        d.set_item("lost_frames", st.lost_frames)?;
        d.set_item("last_round_trip_ns", st.last_round_trip_ns)?;
        d.set_item("max_round_trip_ns", st.max_round_trip_ns)?;
        d.set_item("overruns", s.overruns)?;
        Ok(d)
    }

    /// The master's events since the last call, in words (a slave left OP, an emergency …).
    fn events(&self) -> Vec<String> {
        self.lock().m.diagnosis().take_events().iter().map(|e| e.to_string()).collect()
    }

    /// On a virtual segment, its faults and counters (`None` on a real link).
    #[getter]
    fn segment(slf: Py<Self>, py: Python<'_>) -> Option<crate::segment_view::SegmentView> {
        let virtual_world = slf.borrow(py).lock().m.io().virtual_ref().is_some();
        virtual_world.then(|| crate::segment_view::SegmentView::new(slf))
    }

    /// The CiA402 axis `axis` of the drive at `position`, driven by every later cycle, in
    /// cyclic synchronous position mode. Call it after `bring_up`.
    #[pyo3(signature = (position, axis = 0))]
    fn axis(slf: Py<Self>, py: Python<'_>, position: u16, axis: u8) -> PyResult<crate::drive::Axis> {
        let index = {
            let m = slf.borrow(py);
            detached(py, &m, move |s| {
                let mut a = cia402::Axis::on_axis(&s.m, position, axis)?;
                a.set_mode(&mut s.m, Mode::CyclicSyncPosition)?;
                a.set_goal(Goal::Disabled);
                s.axes.push(a);
                Ok(s.axes.len() - 1)
            })?
        };
        Ok(crate::drive::Axis::new(slf, index, position, axis))
    }

    /// Runs the cycles in a Rust thread of their own from here, on the master's real clock
    /// (not on a virtual segment: there `run(cycles)` is faster than real time). Python
    /// reads and writes the image (`get`, `set`, `image`) and asks for SDO, SDO information
    /// and a slave's state between cycles meanwhile. `priority`: SCHED_FIFO priority for the
    /// loop's thread, memory locked too (needs CAP_SYS_NICE and CAP_IPC_LOCK); `cpu` pins it.
    #[pyo3(signature = (priority = None, cpu = None))]
    fn start(&self, priority: Option<i32>, cpu: Option<usize>) -> PyResult<()> {
        self.cycling()?;
        if self.lock().m.io().virtual_ref().is_some() {
            return Err(error::text(
                "a master on a virtual segment has no real clock to cycle on: call run(cycles), or serve the segment (Segment.serve) and open its interface",
            ));
        }
        if let Some(p) = priority {
            if !(1..=99).contains(&p) {
                return Err(error::text(format!("priority {p}: give 1 to 99 (SCHED_FIFO)")));
            }
        }
        let r = crate::running::start(Arc::clone(&self.state), priority, cpu).map_err(error::other)?;
        *self.running.lock().unwrap_or_else(|p| p.into_inner()) = Some(r);
        Ok(())
    }

    /// Stops the loop started by `start()` (after its current cycle) and returns its figures,
    /// as `loop_stats()`. The loop's error, if it ended on one, is raised.
    fn stop<'py>(&self, py: Python<'py>) -> PyResult<Bound<'py, PyDict>> {
        let Some(mut r) = self.running.lock().unwrap_or_else(|p| p.into_inner()).take() else {
            return Err(error::text("the cyclic loop is not running"));
        };
        r.stop.store(true, std::sync::atomic::Ordering::Relaxed);
        if let Some(thread) = r.thread.take() {
            py.detach(|| thread.join()).map_err(|_| error::text("the cyclic loop's thread panicked"))?;
        }
        let st = r.stats.lock().unwrap_or_else(|p| p.into_inner()).clone();
        if let Some(e) = &st.error {
            return Err(error::text(format!("the cyclic loop ended: {e}")));
        }
        loop_stats_dict(py, &st)
    }

    /// The running loop's figures: cycles, cycles with a short working counter, overruns,
    /// wake-up lateness (p50, p99, max over the last 100 000 cycles, µs), its scheduling, and
    /// the error it ended on; `None` when no loop runs.
    fn loop_stats<'py>(&self, py: Python<'py>) -> PyResult<Option<Bound<'py, PyDict>>> {
        let stats = self.running.lock().unwrap_or_else(|p| p.into_inner()).as_ref().map(|r| Arc::clone(&r.stats));
        let Some(stats) = stats else { return Ok(None) };
        let st = stats.lock().unwrap_or_else(|p| p.into_inner()).clone();
        Ok(Some(loop_stats_dict(py, &st)?))
    }

    /// The loop runs (`start()` called, `stop()` not yet, and it has not ended on an error).
    #[getter]
    fn running(&self) -> bool {
        self.running
            .lock()
            .unwrap_or_else(|p| p.into_inner())
            .as_ref()
            .is_some_and(|r| r.thread.as_ref().is_some_and(|t| !t.is_finished()))
    }

    fn __repr__(&self) -> String {
        let s = self.lock();
        format!("Master({:?}, {} slaves)", s.m.io(), s.m.slaves().len())
    }
}

/// The segment of `target` for this master, as every ferrocat command takes it: a master
/// running there is an error that says how to reach it; a lock that cannot be made is warned
/// of (Python's `warnings`), and the master goes on without it.
fn take_segment(py: Python<'_>, target: &str) -> PyResult<Option<ferrocat_service::MasterLock>> {
    match ferrocat_service::MasterLock::take(target) {
        Ok(Ok(lock)) => Ok(Some(lock)),
        Ok(Err(held)) => Err(error::text(format!(
            "a master runs on {target} already ({}; socket {}): ferrocat.Client reaches it there, and this master needs the segment to itself: stop that master first",
            held.pid.map_or(String::from("its process unknown"), |p| format!("process {p}")),
            ferrocat_service::find_socket(target).display()
        ))),
        Err(e) => {
            let message = format!(
                "no lock for {target} ({}: {e}): a second master on it would not be refused",
                ferrocat_service::lock_path(target).display()
            );
            let warn = py.import("warnings")?.getattr("warn")?;
            warn.call1((message,))?;
            Ok(None)
        }
    }
}

fn loop_stats_dict<'py>(py: Python<'py>, st: &crate::running::LoopStats) -> PyResult<Bound<'py, PyDict>> {
    let d = PyDict::new(py);
    d.set_item("cycles", st.cycles)?;
    d.set_item("short_wkc", st.short_wkc)?;
    d.set_item("overruns", st.overruns)?;
    let us: Vec<Option<f64>> =
        st.wake_percentiles_ns(&[50.0, 99.0, 100.0]).into_iter().map(|v| v.map(|v| v as f64 / 1e3)).collect();
    d.set_item("wake_late_p50_us", us[0])?;
    d.set_item("wake_late_p99_us", us[1])?;
    d.set_item("wake_late_max_us", us[2])?;
    d.set_item("scheduling", &st.real_time)?;
    d.set_item("error", st.error.clone())?;
    Ok(d)
}

/// A service done on the master directly (no loop runs).
fn direct(s: &mut State, request: Request) -> ferrocat_master::Result<Answer> {
    Ok(match request {
        Request::SdoRead { position, index, subindex, complete_access } => {
            Answer::Data(s.m.acyclic().coe().sdo_upload(position, index, subindex, complete_access)?)
        }
        Request::SdoWrite { position, index, subindex, complete_access, data } => {
            s.m.acyclic().coe().sdo_download(position, index, subindex, complete_access, &data)?;
            Answer::Written
        }
        Request::OdList { position } => Answer::List(s.m.acyclic().coe().od_list(position)?),
        Request::ObjectInfo { position, index } => Answer::Object(s.m.acyclic().coe().object_info(position, index)?),
        Request::EntryInfo { position, index, subindex } => {
            Answer::Entry(s.m.acyclic().coe().entry_info(position, index, subindex)?)
        }
        Request::State { position, state } => {
            s.m.states().request_state(position, state)?;
            Answer::State(state)
        }
        other => {
            return Err(ferrocat_master::MasterError::Io(std::io::Error::other(format!(
                "{other:?}: not offered by the Python master"
            ))))
        }
    })
}

fn unexpected(a: Answer) -> PyErr {
    error::text(format!("an answer of another kind: {a:?}"))
}

/// The output a CiA402 axis gets, for `drive.rs`.
pub fn write_position(s: &mut State, index: usize, position: i32) {
    let a = &s.axes[index];
    a.write(&mut s.m, Output::Position(position));
}

#[allow(dead_code)]
fn assert_send() {
    fn is_send<T: Send>() {}
    is_send::<State>();
    let _ = <World as Io>::is_virtual;
}
