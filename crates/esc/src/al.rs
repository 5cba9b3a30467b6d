//! The AL state machine (esc-spec §5.1, after SOES's `ESC_state`): valid and invalid
//! transitions, error indication and acknowledge.
use ferrocat_wire::register::{AlState, AlStatus, AlStatusCode};

#[derive(Debug, Clone, PartialEq, Eq)]
pub struct AlMachine {
    pub state: AlState,
    pub error: bool,
    pub code: AlStatusCode,
    /// AL status as the hardware copied it from AL control under device emulation, bits the
    /// state machine has no name for included; `None` while the state machine sets it.
    pub copied: Option<u16>,
}

impl Default for AlMachine {
    fn default() -> Self {
        AlMachine { state: AlState::Init, error: false, code: AlStatusCode::NO_ERROR, copied: None }
    }
}

fn valid(from: AlState, to: AlState) -> bool {
    use AlState::*;
    matches!(
        (from, to),
        (_, Init)
            | (Init, PreOp)
            | (Init, Bootstrap)
            | (PreOp, SafeOp)
            | (SafeOp, Op)
            | (Op, SafeOp)
            | (Op, PreOp)
            | (SafeOp, PreOp)
    )
}

impl AlMachine {
    pub fn status(&self) -> AlStatus {
        self.copied.map_or(AlStatus::new(self.state, self.error), AlStatus)
    }

    /// Device emulation: the ESC copies AL control into AL status as it is written, the
    /// error-indication bit included (real EK1100, EL1004 and EL2004 read back 0x0011 after a
    /// write of 0x0011: `soem-sdinfo-ek1100-el1004.pcapng` frames 132–133, 204–205). The
    /// status code is the PDI's to write and stays as it is. The state that gates mailbox and
    /// process data follows the copied state bits where they name one.
    pub fn copy_control(&mut self, control: u16) {
        self.copied = Some(control);
        self.error = control & AlStatus::ERROR != 0;
        if let Some(s) = AlState::from_bits((control & 0x0F) as u8) {
            self.state = s;
        }
    }

    /// Sets an error from the application side (e.g. a watchdog): state and code.
    pub fn fail(&mut self, state: AlState, code: AlStatusCode) {
        self.copied = None;
        self.state = state;
        self.error = true;
        self.code = code;
    }

    /// Handles a write of AL control. `check` runs the checks of an upward transition and may
    /// refuse it with a status code.
    pub fn request(&mut self, control: u16, check: &mut dyn FnMut(AlState, AlState) -> Result<(), AlStatusCode>) {
        self.copied = None;
        let ack = control & AlStatus::ERROR != 0;
        let bits = (control & 0x0F) as u8;
        if self.error && !ack && bits != AlState::Init as u8 {
            // An unacknowledged error blocks every request but one to INIT.
            return;
        }
        if ack || bits == AlState::Init as u8 {
            self.error = false;
            self.code = AlStatusCode::NO_ERROR;
        }
        let Some(to) = AlState::from_bits(bits) else {
            let state = if self.state == AlState::Op { AlState::SafeOp } else { self.state };
            self.fail(state, AlStatusCode::UNKNOWN_STATE);
            return;
        };
        if to == self.state {
            return;
        }
        if !valid(self.state, to) {
            // Invalid requests from OP to BOOT fall back to SAFEOP; the others keep the state.
            let state = if self.state == AlState::Op { AlState::SafeOp } else { self.state };
            self.fail(state, AlStatusCode::INVALID_STATE_CHANGE);
            return;
        }
        match check(self.state, to) {
            Ok(()) => self.state = to,
            Err(code) => {
                let state = self.state;
                self.fail(state, code);
            }
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn ok(_: AlState, _: AlState) -> Result<(), AlStatusCode> {
        Ok(())
    }

    #[test]
    fn transitions() {
        let mut m = AlMachine::default();
        m.request(8, &mut ok); // INIT -> OP is invalid
        assert_eq!((m.state, m.error, m.code), (AlState::Init, true, AlStatusCode::INVALID_STATE_CHANGE));
        m.request(2, &mut ok); // blocked until acknowledged
        assert_eq!(m.state, AlState::Init);
        m.request(0x12, &mut ok); // ack + PREOP
        assert_eq!((m.state, m.error), (AlState::PreOp, false));
        m.request(4, &mut |_, _| Err(AlStatusCode::INVALID_OUTPUT_CONFIG));
        assert_eq!((m.state, m.error, m.code), (AlState::PreOp, true, AlStatusCode::INVALID_OUTPUT_CONFIG));
        m.request(0x14, &mut ok);
        m.request(8, &mut ok);
        assert_eq!(m.status(), AlStatus(8));
        m.request(3, &mut ok); // OP -> BOOT
        assert_eq!((m.state, m.code), (AlState::SafeOp, AlStatusCode::INVALID_STATE_CHANGE));
        m.request(5, &mut ok); // unknown state, blocked by error? No: error set, not acked.
        assert_eq!(m.code, AlStatusCode::INVALID_STATE_CHANGE);
        m.request(0x15, &mut ok); // ack + unknown state
        assert_eq!((m.state, m.code), (AlState::SafeOp, AlStatusCode::UNKNOWN_STATE));
        m.request(1, &mut ok); // INIT always possible
        assert_eq!((m.state, m.error), (AlState::Init, false));
    }
}
