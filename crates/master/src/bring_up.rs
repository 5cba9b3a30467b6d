//! The whole bring-up, and its last step: PREOP → SAFEOP → OP with process data exchanged
//! meanwhile. It sits above the cyclic exchange (`process`), which the master's own modules
//! do not call.
use ferrocat_wire::register::{addr, AlState};
use ferrocat_wire::{Address, Command};

use crate::error::Result;
use crate::io::Io;
use crate::master::Master;

impl<I: Io> Master<I> {}

impl<'a, I: Io> crate::master::part::States<'a, I> {
    /// PREOP → SAFEOP → OP for every slave, exchanging process data meanwhile (slaves with an
    /// SM watchdog want outputs before OP).
    pub fn start(&mut self) -> Result<()> {
        self.m.states().request_state_all(AlState::SafeOp)?;
        for k in 0..self.m.slaves.len() as u16 {
            self.m.run_init_commands(k, "SO")?;
        }
        self.m.cyclic().cycle()?;
        self.m.engine.one(
            Command::BWR,
            Address::Device { adp: 0, ado: addr::AL_CONTROL },
            &mut [AlState::Op as u8, 0],
        )?;
        let deadline = self.m.engine.io.now_ns() + self.m.settings.state_timeout_ns;
        loop {
            let now = self.m.engine.io.now_ns();
            self.m.cyclic().cycle()?;
            let mut d = [0u8; 2];
            let wkc = self.m.engine.one(Command::BRD, Address::Device { adp: 0, ado: addr::AL_STATUS }, &mut d)?;
            if wkc as usize == self.m.slaves.len() && d[0] & 0x1F == AlState::Op as u8 {
                // BRD ORs every slave's state: all OP and no error flag.
                break;
            }
            if d[0] & 0x10 != 0 || now > deadline {
                for k in 0..self.m.slaves.len() as u16 {
                    self.m.wait_state(k, AlState::Op)?;
                }
                break;
            }
            self.m.engine.io.sleep_until(now + 1_000_000);
        }
        for s in self.m.slaves.iter_mut() {
            s.state = AlState::Op;
        }
        tracing::info!("every slave in OP");
        Ok(())
    }

    /// Scan, configure, start: the whole bring-up.
    pub fn bring_up(&mut self) -> Result<()> {
        self.scan()?;
        self.m.states().configure()?;
        self.m.states().start()
    }
}
