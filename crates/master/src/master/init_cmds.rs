//! The CoE and SoE init commands of a slave's ESI description (`<Mailbox><CoE><InitCmd>`,
//! `<Mailbox><SoE><InitCmd>`, ETG.2000) and those the application gives (a machine
//! description's), sent at the state transitions they name, as a configuration tool's master
//! does: "IP" and "PS" while the slave is in PREOP, before the process data are read and SAFEOP
//! is asked; "SO" in SAFEOP, before OP.
use ferrocat_wire::mailbox::MailboxType;
use ferrocat_wire::sii::mailbox_protocol;

use crate::error::{MasterError, Result};
use crate::io::Io;
use crate::master::Master;

impl<I: Io> Master<I> {
    /// The ESI description the master holds for slave `position` (`Master::esi`): vendor and
    /// product code match, the slave's own revision first, else the newest.
    pub(crate) fn esi_description(&self, position: u16) -> Option<&ferrocat_esi::Device> {
        let s = self.slaves.get(position as usize)?;
        self.esi
            .iter()
            .filter(|(v, d)| *v == s.identity.vendor_id && d.product_code == s.identity.product_code)
            .max_by_key(|(_, d)| (d.revision == s.identity.revision, d.revision))
            .map(|(_, d)| d)
    }

    /// Sends slave `position` the init commands for `transition` ("IP", "PS", "SO", …): the CoE
    /// ones, then the SoE ones (each kind its ESI description's in the file's order, then those
    /// the application gave, [`Config::setup_mut`](crate::part::Config::setup_mut)). Returns how
    /// many it sent. The description's commands of a protocol the slave's mailbox lacks are not
    /// sent ([`MasterEvent::InitCommandsNotSent`](crate::event::MasterEvent::InitCommandsNotSent));
    /// the application's are, and fail naming the command.
    pub(crate) fn run_init_commands(&mut self, position: u16, transition: &str) -> Result<usize> {
        let has = |m: &Self, bit| {
            m.slaves.get(position as usize).and_then(|s| s.mailbox()).is_some_and(|mb| mb.has_protocol(bit))
        };
        let (coe, soe) = (has(self, mailbox_protocol::COE), has(self, mailbox_protocol::SOE));
        Ok(self.run_coe_init_commands(position, transition, coe)?
            + self.run_soe_init_commands(position, transition, soe)?)
    }

    /// The event for `count` commands of the description's for `protocol` left out, if any.
    fn not_sent(&mut self, position: u16, transition: &str, protocol: MailboxType, count: usize) {
        if count > 0 {
            let name = self.slaves[position as usize].name.clone();
            let transition = transition.to_string();
            self.skipped(crate::event::MasterEvent::InitCommandsNotSent {
                position,
                name,
                transition,
                protocol,
                count,
            });
        }
    }

    /// The CoE commands for `transition`, each an SDO download (complete access where it says
    /// so). An abort is an error naming the command, but for an ESI command on an object or
    /// subindex the slave lacks: that one is left out with
    /// [`MasterEvent::InitCommandSkipped`](crate::event::MasterEvent::InitCommandSkipped).
    fn run_coe_init_commands(&mut self, position: u16, transition: &str, speaks: bool) -> Result<usize> {
        let wanted = |c: &&ferrocat_esi::InitCmd| c.transitions.iter().any(|t| t == transition);
        let mut cmds: Vec<(ferrocat_esi::InitCmd, bool)> = match self.esi_description(position) {
            Some(d) => d.init_cmds.iter().filter(wanted).map(|c| (c.clone(), true)).collect(),
            None => Vec::new(),
        };
        if !speaks {
            self.not_sent(position, transition, MailboxType::COE, cmds.len());
            cmds.clear();
        }
        if let Some(s) = self.slaves.get(position as usize) {
            cmds.extend(s.setup.init_cmds.iter().filter(wanted).map(|c| (c.clone(), false)));
        }
        let mut sent = 0;
        for (c, from_esi) in &cmds {
            let result = self.acyclic().coe().sdo_download(position, c.index, c.subindex, c.complete_access, &c.data);
            // An ESI's command on an object this slave does not have is left out with a warning:
            // a vendor's file covers a family and its revisions (WAGO's and CODESYS's
            // configurators go on past a start parameter that fails where told to; TwinCAT's
            // ESI commands are the vendor's, not the user's). The application's own commands
            // stay errors.
            if let (true, Err(crate::error::MasterError::Abort { code, .. })) = (*from_esi, &result) {
                if *code == ferrocat_wire::coe::AbortCode::NO_OBJECT
                    || *code == ferrocat_wire::coe::AbortCode::NO_SUBINDEX
                {
                    let name = self.slaves[position as usize].name.clone();
                    let e = crate::event::MasterEvent::InitCommandSkipped {
                        position,
                        name,
                        transition: transition.to_string(),
                        index: c.index,
                        subindex: c.subindex,
                        comment: c.comment.clone(),
                        line: c.line,
                        code: *code,
                    };
                    self.skipped(e);
                    continue;
                }
            }
            result.map_err(|e| {
                let origin = origin(*from_esi, transition, c.line);
                MasterError::of(
                    position,
                    &self.slaves[position as usize].name,
                    crate::error::SlaveError::ConfigSdo {
                        origin,
                        index: c.index,
                        subindex: c.subindex,
                        comment: c.comment.clone(),
                        error: Box::new(e),
                    },
                )
            })?;
            tracing::debug!(position, transition, index = c.index, subindex = c.subindex, "init command sent");
            sent += 1;
        }
        Ok(sent)
    }

    /// The SoE commands for `transition`, each a write of its IDN's elements to its drive, the
    /// mailbox wait stretched to the command's `<Timeout>` where that is longer. The drive's
    /// refusal is an error naming the command, but for an ESI command on an IDN the drive lacks
    /// (SoE error 0x1001), left out with
    /// [`MasterEvent::SoeInitCommandSkipped`](crate::event::MasterEvent::SoeInitCommandSkipped)
    /// for the reason the CoE ones are.
    fn run_soe_init_commands(&mut self, position: u16, transition: &str, speaks: bool) -> Result<usize> {
        let wanted = |c: &&ferrocat_esi::SoeInitCmd| c.transitions.iter().any(|t| t == transition);
        let mut cmds: Vec<(ferrocat_esi::SoeInitCmd, bool)> = match self.esi_description(position) {
            Some(d) => d.soe_init_cmds.iter().filter(wanted).map(|c| (c.clone(), true)).collect(),
            None => Vec::new(),
        };
        if !speaks {
            self.not_sent(position, transition, MailboxType::SOE, cmds.len());
            cmds.clear();
        }
        if let Some(s) = self.slaves.get(position as usize) {
            cmds.extend(s.setup.soe_init_cmds.iter().filter(wanted).map(|c| (c.clone(), false)));
        }
        let mut sent = 0;
        for (c, from_esi) in &cmds {
            let result = self.soe_write_waiting(position, (c.drive, c.idn, c.elements), &c.data, c.timeout_ms);
            if let (true, Err(MasterError::Slave { error: crate::error::SlaveError::Soe { error, .. }, .. })) =
                (*from_esi, &result)
            {
                if *error == ferrocat_wire::soe::SoeError::NO_IDN {
                    let e = crate::event::MasterEvent::SoeInitCommandSkipped {
                        position,
                        name: self.slaves[position as usize].name.clone(),
                        transition: transition.to_string(),
                        drive: c.drive,
                        idn: c.idn,
                        comment: c.comment.clone(),
                        line: c.line,
                        error: *error,
                    };
                    self.skipped(e);
                    continue;
                }
            }
            result.map_err(|e| {
                let origin = origin(*from_esi, transition, c.line);
                MasterError::of(
                    position,
                    &self.slaves[position as usize].name,
                    crate::error::SlaveError::ConfigIdn {
                        origin,
                        drive: c.drive,
                        idn: c.idn,
                        comment: c.comment.clone(),
                        error: Box::new(e),
                    },
                )
            })?;
            tracing::debug!(position, transition, idn = %c.idn, drive = c.drive, "SoE init command sent");
            sent += 1;
        }
        Ok(sent)
    }
}

impl<I: Io> Master<I> {
    /// An SoE write of a configuration step (`drive`, `idn`, `elements`), the mailbox wait
    /// stretched to `timeout_ms` where that is longer.
    pub(crate) fn soe_write_waiting(
        &mut self,
        position: u16,
        (drive, idn, elements): (u8, ferrocat_wire::soe::Idn, ferrocat_wire::soe::Elements),
        data: &[u8],
        timeout_ms: Option<u32>,
    ) -> Result<()> {
        let mut soe = self.acyclic().soe();
        if let Some(ms) = timeout_ms {
            soe.mbx.timeout_ns = soe.mbx.timeout_ns.max(ms as u64 * 1_000_000);
        }
        soe.write(position, drive, idn, elements, data)
    }

    /// An ESI command left out: a warning and an event.
    fn skipped(&mut self, e: crate::event::MasterEvent) {
        tracing::warn!("{e}");
        self.events.push(e);
    }
}

/// Whose command failed: the ESI's or the application's, at `transition` from `line`.
fn origin(from_esi: bool, transition: &str, line: u32) -> crate::error::SdoSource {
    let transition = transition.to_string();
    if from_esi {
        crate::error::SdoSource::EsiInitCommand { transition, line }
    } else {
        crate::error::SdoSource::Description { transition, line }
    }
}

impl<'a, I: Io> crate::master::part::Config<'a, I> {
    /// What the application asks of slave `position`'s configuration (a machine
    /// description's init commands and modules), applied whenever the master configures it.
    pub fn setup_mut(self, position: u16) -> Result<&'a mut crate::slave::Setup> {
        self.m.slave(position)?;
        Ok(&mut self.m.slaves[position as usize].setup)
    }
}
