//! Device applications: what runs behind the ESC's process data interface (PDI).
use std::any::Any;
use std::fmt::Debug;

use ferrocat_wire::register::{AlState, AlStatusCode, SyncManager};

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
    /// The SyncManager whose control byte says "ECAT writes, buffered" (outputs) or "ECAT
    /// reads, buffered" (inputs), among the first `count`.
    pub fn process_data_sm(&self, outputs: bool, count: u8) -> Option<(u8, SyncManager)> {
        (0..count)
            .map(|n| (n, self.sm(n)))
            .find(|(_, s)| s.enabled() && !s.is_mailbox() && s.length > 0 && s.ecat_writes() == outputs)
    }
}

pub trait Application: Debug + Send {
    /// Checks of an upward AL transition beyond the ESC's own SyncManager checks.
    fn check_transition(&mut self, _pdi: &mut Pdi<'_>, _from: AlState, _to: AlState) -> Result<(), AlStatusCode> {
        Ok(())
    }
    /// A buffered output SyncManager received a complete buffer.
    fn outputs_written(&mut self, _pdi: &mut Pdi<'_>, _sm: u8) {}
    /// The SYNC0 signal fired at system time `sys_ns`.
    fn sync0(&mut self, _pdi: &mut Pdi<'_>, _sys_ns: u64) {}
    /// A complete mailbox request arrived in SM0; the reply (if any) goes to SM1.
    fn mailbox(&mut self, _pdi: &mut Pdi<'_>, _request: &[u8]) -> Option<Vec<u8>> {
        None
    }
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
    /// Values presented to the master.
    pub inputs: Vec<u8>,
    pub sm_count: u8,
}

impl DigitalIo {
    pub fn new(sm_count: u8) -> Self {
        DigitalIo { sm_count, ..Default::default() }
    }

    fn publish_inputs(&self, pdi: &mut Pdi<'_>) {
        if let Some((_, sm)) = pdi.process_data_sm(false, self.sm_count) {
            let n = (sm.length as usize).min(self.inputs.len());
            let data = self.inputs[..n].to_vec();
            pdi.write(sm.start, &data);
        }
    }
}

impl Application for DigitalIo {
    fn check_transition(&mut self, pdi: &mut Pdi<'_>, _from: AlState, to: AlState) -> Result<(), AlStatusCode> {
        if to == AlState::SafeOp {
            self.publish_inputs(pdi);
        }
        Ok(())
    }
    fn outputs_written(&mut self, pdi: &mut Pdi<'_>, sm: u8) {
        let s = pdi.sm(sm);
        self.outputs = pdi.read(s.start, s.length as usize).to_vec();
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
