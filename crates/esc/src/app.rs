//! Device applications: what runs behind the ESC's process data interface (PDI).
use std::any::Any;
use std::fmt::Debug;

use ferrocat_wire::register::{AlState, AlStatusCode, SyncManager};

use crate::sync_monitor::SmSyncMonitor;

/// The application's view of the ESC: its memory and SyncManager configuration.
#[derive(Debug)]
pub struct Pdi<'a> {
    pub(crate) mem: &'a mut [u8],
    pub(crate) now_ns: u64,
}

impl Pdi<'_> {
    pub fn now_ns(&self) -> u64 {
        self.now_ns
    }
    pub fn read(&self, addr: u16, len: usize) -> &[u8] {
        let a = addr as usize;
        self.mem.get(a..a + len).unwrap_or(&[])
    }
    pub fn write(&mut self, addr: u16, data: &[u8]) {
        let a = addr as usize;
        if let Some(d) = self.mem.get_mut(a..a + data.len()) {
            d.copy_from_slice(data);
        }
    }
    pub fn sm(&self, n: u8) -> SyncManager {
        let a = ferrocat_wire::register::addr::sm(n) as usize;
        SyncManager::parse(&self.mem[a..a + 8]).unwrap_or_default()
    }
    /// Length of the send mailbox (SM1), which bounds what one reply can carry.
    pub fn process_mailbox_len(&self) -> usize {
        self.sm(1).length as usize
    }
    /// The SyncManager of the outputs ("ECAT writes") or the inputs ("ECAT reads") among the
    /// first `count`: a buffered one, or from SM2 on one in mailbox mode (one buffer, as the
    /// AX2000's ESI has its inputs), SM0 and SM1 being a mailbox device's mailbox (ETG.1000.4).
    pub fn process_data_sm(&self, outputs: bool, count: u8) -> Option<(u8, SyncManager)> {
        (0..count)
            .map(|n| (n, self.sm(n)))
            .find(|(n, s)| s.enabled() && (*n >= 2 || !s.is_mailbox()) && s.length > 0 && s.ecat_writes() == outputs)
    }
}

pub trait Application: Debug + Send {
    /// Checks of an upward AL transition beyond the ESC's own SyncManager checks.
    fn check_transition(&mut self, _pdi: &mut Pdi<'_>, _from: AlState, _to: AlState) -> Result<(), AlStatusCode> {
        Ok(())
    }
    /// A frame is about to be processed in SAFEOP or OP: inputs the application samples
    /// continuously go to the input buffer now.
    fn sample_inputs(&mut self, _pdi: &mut Pdi<'_>) {}
    /// The AL state changed (device emulation or not).
    fn state_changed(&mut self, _pdi: &mut Pdi<'_>, _state: AlState) {}
    /// A buffered output SyncManager received a complete buffer.
    fn outputs_written(&mut self, _pdi: &mut Pdi<'_>, _sm: u8) {}
    /// The SYNC0 signal fired at system time `sys_ns`.
    fn sync0(&mut self, _pdi: &mut Pdi<'_>, _sys_ns: u64) {}
    /// A local error the application found since it was last asked, which takes the slave from
    /// OP to SAFEOP with this status code (the SM-synchronisation supervision's 0x001A).
    fn take_fault(&mut self) -> Option<AlStatusCode> {
        None
    }
    /// The process data watchdog expired under device emulation: outputs to their safe state.
    fn watchdog_expired(&mut self) {}
    /// A complete mailbox request arrived in SM0; the reply goes to SM1. `None`: a protocol
    /// the application does not serve (the ESC answers "unsupported protocol"); an empty reply:
    /// handled, nothing to send.
    fn mailbox(&mut self, _pdi: &mut Pdi<'_>, _request: &[u8]) -> Option<Vec<u8>> {
        None
    }
    /// A message the application wants to send unasked (SDO-information fragments,
    /// emergencies); the ESC delivers it when the send mailbox is free.
    fn pending_mailbox(&mut self) -> Option<Vec<u8>> {
        None
    }
    /// Process-image bytes the application expects in process-data SyncManager `sm` (of
    /// outputs or inputs), when it decides them (PDO mapping through CoE) rather than the SII.
    fn process_data_bytes(&self, _sm: u8, _outputs: bool) -> Option<u16> {
        None
    }
    /// True time of the application's next own event (a free-running timer), if any.
    fn next_event_ns(&self) -> Option<u64> {
        None
    }
    /// The application's own event at `pdi.now_ns()`.
    fn tick(&mut self, _pdi: &mut Pdi<'_>) {}
    fn as_any(&self) -> &dyn Any;
    fn as_any_mut(&mut self) -> &mut dyn Any;
}

/// A device without an application (couplers, junctions).
#[derive(Debug, Default)]
pub struct NoApplication;

impl Application for NoApplication {
    fn as_any(&self) -> &dyn Any {
        self
    }
    fn as_any_mut(&mut self) -> &mut dyn Any {
        self
    }
}

/// A digital I/O terminal: output buffers are latched to its outputs; its inputs are copied to
/// the input SyncManager's buffer.
#[derive(Debug, Default, Clone)]
pub struct DigitalIo {
    /// The last complete output buffer.
    pub outputs: Vec<u8>,
    /// How many complete output buffers arrived.
    pub output_updates: u64,
    /// Values presented to the master (published with the next frame after a change).
    pub inputs: Vec<u8>,
    pub sm_count: u8,
    published: Vec<u8>,
}

impl DigitalIo {
    pub fn new(sm_count: u8) -> Self {
        DigitalIo { sm_count, ..Default::default() }
    }

    fn publish_inputs(&self, pdi: &mut Pdi<'_>) {
        if self.inputs.is_empty() {
            return; // an output terminal: nothing to publish, no SyncManager to look up
        }
        if let Some((_, sm)) = pdi.process_data_sm(false, self.sm_count) {
            let n = (sm.length as usize).min(self.inputs.len());
            pdi.write(sm.start, &self.inputs[..n]);
        }
    }
}

impl Application for DigitalIo {
    fn sample_inputs(&mut self, pdi: &mut Pdi<'_>) {
        // Two empty Vecs (an output terminal, or inputs never set) compare through memcmp on
        // dangling pointers, which cost ≈ 77 ns on the benchmark machine (glibc's AVX-512
        // memcmp; half of every ESC visit): lengths first, bytes only when there are some.
        let changed =
            self.inputs.len() != self.published.len() || (!self.inputs.is_empty() && self.inputs != self.published);
        if changed {
            self.publish_inputs(pdi);
            self.published.clear();
            self.published.extend_from_slice(&self.inputs);
        }
    }
    fn check_transition(&mut self, pdi: &mut Pdi<'_>, _from: AlState, to: AlState) -> Result<(), AlStatusCode> {
        if to == AlState::SafeOp {
            self.publish_inputs(pdi);
        }
        Ok(())
    }
    fn watchdog_expired(&mut self) {
        self.outputs.fill(0);
    }
    fn outputs_written(&mut self, pdi: &mut Pdi<'_>, sm: u8) {
        let s = pdi.sm(sm);
        // Reuse the buffer: a steady cycle allocates nothing.
        self.outputs.clear();
        self.outputs.extend_from_slice(pdi.read(s.start, s.length as usize));
        self.output_updates += 1;
        self.publish_inputs(pdi);
    }
    fn as_any(&self) -> &dyn Any {
        self
    }
    fn as_any_mut(&mut self) -> &mut dyn Any {
        self
    }
}

/// How an application is synchronised to the master (ETG.1020; Chen 2016 §2).
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum SyncMode {
    /// On the device's own timer: `period_ns` of its crystal.
    FreeRun { period_ns: u64 },
    /// On every complete output buffer (SM2 event).
    SmSynchronous,
    /// On every SYNC0 pulse.
    DcSynchronous,
}

/// An I/O application that consumes its output buffer in one of the synchronisation modes and
/// counts the process-data cycles it lost (overwritten before it consumed them) and repeated
/// (consumed twice): the packet loss Chen et al. 2016 (Table 2) measure.
#[derive(Debug, Clone)]
pub struct SyncApp {
    pub mode: SyncMode,
    pub io: DigitalIo,
    /// The device crystal's error, which a free-running timer follows.
    pub drift_ppb: i64,
    written: u64,
    consumed_seq: u64,
    pub consumed: u64,
    pub lost: u64,
    pub repeated: u64,
    /// DC-synchronous mode: the SM-synchronisation supervision (off unless set).
    pub monitor: SmSyncMonitor,
    running: bool,
    timer_t0: u64,
    timer_k: u64,
}

impl SyncApp {
    /// Starts the counts afresh (at the start of a measurement).
    pub fn reset_counts(&mut self) {
        self.consumed = 0;
        self.lost = 0;
        self.repeated = 0;
    }

    pub fn new(mode: SyncMode, sm_count: u8, drift_ppb: i64) -> Self {
        SyncApp {
            mode,
            io: DigitalIo::new(sm_count),
            drift_ppb,
            written: 0,
            consumed_seq: 0,
            consumed: 0,
            lost: 0,
            repeated: 0,
            monitor: SmSyncMonitor::default(),
            running: false,
            timer_t0: 0,
            timer_k: 0,
        }
    }

    fn consume(&mut self, pdi: &mut Pdi<'_>) {
        if !self.running || self.written == 0 {
            return;
        }
        if self.consumed > 0 {
            if self.written == self.consumed_seq {
                self.repeated += 1;
            } else {
                self.lost += self.written - self.consumed_seq - 1;
            }
        }
        self.consumed_seq = self.written;
        self.consumed += 1;
        if let Some((_, sm)) = pdi.process_data_sm(true, self.io.sm_count) {
            self.io.outputs.clear();
            self.io.outputs.extend_from_slice(pdi.read(sm.start, sm.length as usize));
        }
    }
}

impl Application for SyncApp {
    fn watchdog_expired(&mut self) {
        self.io.watchdog_expired();
    }
    fn check_transition(&mut self, pdi: &mut Pdi<'_>, from: AlState, to: AlState) -> Result<(), AlStatusCode> {
        if to == AlState::Op && self.mode == SyncMode::DcSynchronous {
            // DC-synchronous operation needs the SYNC unit running with SYNC0.
            let act = pdi.read(0x0981, 1).first().copied().unwrap_or(0);
            if act & 0x03 != 0x03 {
                return Err(AlStatusCode::INVALID_DC_SYNC_CONFIG);
            }
        }
        self.io.check_transition(pdi, from, to)
    }
    fn state_changed(&mut self, pdi: &mut Pdi<'_>, state: AlState) {
        let was = self.running;
        self.running = state == AlState::Op;
        if self.running && !was {
            self.timer_t0 = pdi.now_ns();
            self.timer_k = 0;
        }
        if self.running && !was {
            self.monitor.restart();
        }
    }
    fn sample_inputs(&mut self, pdi: &mut Pdi<'_>) {
        self.io.sample_inputs(pdi);
    }
    fn outputs_written(&mut self, pdi: &mut Pdi<'_>, sm: u8) {
        self.written += 1;
        self.io.output_updates += 1;
        if self.running {
            let supervised = self.mode == SyncMode::DcSynchronous && self.monitor.on;
            let cycle = supervised.then(|| u32::from_le_bytes(pdi.read(0x09A0, 4).try_into().unwrap_or([0; 4])) as u64);
            self.monitor.outputs(pdi.now_ns(), cycle);
        }
        if self.mode == SyncMode::SmSynchronous {
            self.consume(pdi);
        }
        let _ = sm;
    }
    fn sync0(&mut self, pdi: &mut Pdi<'_>, _sys_ns: u64) {
        if self.mode == SyncMode::DcSynchronous {
            self.consume(pdi);
            if self.running {
                self.monitor.pulse(pdi.now_ns());
            }
        }
    }
    fn take_fault(&mut self) -> Option<AlStatusCode> {
        self.monitor.take_fault()
    }
    fn next_event_ns(&self) -> Option<u64> {
        match self.mode {
            SyncMode::FreeRun { period_ns } if self.running => {
                // The timer counts periods of the device's crystal.
                let k = self.timer_k as u128 + 1;
                Some(
                    self.timer_t0
                        + (k * period_ns as u128 * 1_000_000_000 / (1_000_000_000 + self.drift_ppb) as u128) as u64,
                )
            }
            _ => None,
        }
    }
    fn tick(&mut self, pdi: &mut Pdi<'_>) {
        self.timer_k += 1;
        self.consume(pdi);
    }
    fn as_any(&self) -> &dyn Any {
        self
    }
    fn as_any_mut(&mut self) -> &mut dyn Any {
        self
    }
}
