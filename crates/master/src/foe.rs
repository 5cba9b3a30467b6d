//! The FoE client: files to and from a slave's mailbox (firmware, parameter sets), packet by
//! packet, each acknowledged (ETG.1000.6 §5.7).
use ferrocat_wire::mailbox::MailboxType;
use ferrocat_wire::register::AlState;

use crate::error::{MasterError, Result};
use crate::foe_transfer::{FoePeer, FoeStep, FoeTransfer};
use crate::io::Io;
use crate::mailbox::Mailboxes;
use crate::master::Master;
use crate::slave::MailboxConfig;

impl<I: Io> Master<I> {}

/// The FoE client of one master (see [`Acyclic::foe`](crate::part::Acyclic::foe)): it borrows the master's engine and
/// slave list for as long as it is used.
pub struct Foe<'a, I: Io> {
    pub(crate) mbx: Mailboxes<'a, I>,
}

impl<I: Io> Master<I> {}

impl<I: Io> Foe<'_, I> {
    /// Who `position` is, for a transfer's messages and errors.
    fn peer(&self, position: u16) -> Result<FoePeer> {
        let (_, name, m) = self.mbx.mailbox_of(position, MailboxType::FOE)?;
        Ok(FoePeer { position, name, out_len: m.out.1 as usize, in_len: m.inp.1 as usize })
    }

    /// Each message of `t`'s written into SM0 and its reply read from SM1, until it is over.
    fn drive(&mut self, position: u16, mut t: FoeTransfer) -> Result<Vec<u8>> {
        let mut msg = t.start()?;
        loop {
            self.mbx.write(position, MailboxType::FOE, &msg)?;
            let reply = self.mbx.read(position, MailboxType::FOE)?;
            match t.on_reply(&reply)? {
                FoeStep::Send(next) => msg = next,
                FoeStep::Finish(last, result) => {
                    self.mbx.write(position, MailboxType::FOE, &last)?;
                    return result;
                }
                FoeStep::Done(data) => return Ok(data),
            }
        }
    }

    /// Writes `data` as file `file` to the slave at `position` (in a state with a mailbox:
    /// PREOP and above, or BOOT for firmware — see [`States::enter_bootstrap`](crate::part::States::enter_bootstrap)).
    pub fn write(&mut self, position: u16, file: &str, password: u32, data: &[u8]) -> Result<()> {
        let t = FoeTransfer::write(self.peer(position)?, file, password, data.to_vec())?;
        self.drive(position, t).map(drop)
    }

    /// Reads file `file` from the slave at `position`. `max_bytes` bounds what is kept: a
    /// slave sending more is an error (the transfer is aborted), not a truncated file.
    pub fn read(&mut self, position: u16, file: &str, password: u32, max_bytes: usize) -> Result<Vec<u8>> {
        let t = FoeTransfer::read(self.peer(position)?, file, password, max_bytes);
        self.drive(position, t)
    }
}

impl<'a, I: Io> crate::master::part::States<'a, I> {
    /// Puts the slave at `position` into BOOT, where a bootloader takes firmware by FoE: INIT,
    /// the SII's bootstrap mailbox written to SM0 and SM1, then BOOT. Its mailbox functions use
    /// the bootstrap mailbox until [`leave_bootstrap`](Self::leave_bootstrap).
    pub fn enter_bootstrap(&mut self, position: u16) -> Result<()> {
        let (boot, name) = {
            let s = self.m.slave(position)?;
            (MailboxConfig::bootstrap(&s.sii.header), s.name.clone())
        };
        let boot =
            boot.ok_or_else(|| MasterError::of(position, &name, crate::error::SlaveError::NoBootstrapMailbox))?;
        self.m.states().request_state(position, AlState::Init)?;
        self.m.slaves[position as usize].mailbox = Some(boot);
        let entered = self
            .m
            .write_mailbox_config(position)
            .and_then(|_| self.m.states().request_state(position, AlState::Bootstrap));
        if entered.is_err() {
            self.m.slaves[position as usize].mailbox =
                MailboxConfig::standard(&self.m.slaves[position as usize].sii.header);
        }
        entered
    }

    /// Back from BOOT to INIT, the standard mailbox written to SM0 and SM1 again (a new
    /// firmware starts there, and PREOP can be requested at once).
    pub fn leave_bootstrap(&mut self, position: u16) -> Result<()> {
        let left = self.m.states().request_state(position, AlState::Init);
        let s = &mut self.m.slaves[position as usize];
        s.mailbox = MailboxConfig::standard(&s.sii.header);
        left?;
        self.m.write_mailbox_config(position)
    }
}

impl<'a, I: Io> crate::master::part::Acyclic<'a, I> {
    /// The FoE client: files to and from a slave (see also [`States::enter_bootstrap`](crate::part::States::enter_bootstrap)).
    pub fn foe(self) -> Foe<'a, I> {
        Foe { mbx: self.m.mailboxes() }
    }
}
