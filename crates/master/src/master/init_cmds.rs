//! The CoE init commands of a slave's ESI description (`<InitCmd>`, ETG.2000), sent at the state
//! transitions they name, as a configuration tool's master does: "IP" and "PS" while the slave
//! is in PREOP, before the process data are read and SAFEOP is asked; "SO" in SAFEOP, before OP.
use crate::error::{MasterError, Result};
use crate::io::Io;
use crate::master::Master;

impl<I: Io> Master<I> {
    /// The ESI description the master holds for slave `position` (`Master::esi`): vendor and
    /// product code match, the slave's own revision first, else the newest.
    pub fn esi_description(&self, position: u16) -> Option<&ferrocat_esi::Device> {
        let s = self.slaves.get(position as usize)?;
        self.esi
            .iter()
            .filter(|(v, d)| *v == s.identity.vendor_id && d.product_code == s.identity.product_code)
            .max_by_key(|(_, d)| (d.revision == s.identity.revision, d.revision))
            .map(|(_, d)| d)
    }

    /// Sends slave `position` the init commands its ESI description gives for `transition`
    /// ("IP", "PS", "SO", …), in the file's order: each an SDO download (complete access where
    /// it says so). Returns how many it sent; an abort is an error naming the command.
    pub fn run_init_commands(&mut self, position: u16, transition: &str) -> Result<usize> {
        let cmds: Vec<ferrocat_esi::InitCmd> = match self.esi_description(position) {
            Some(d) => d.init_cmds.iter().filter(|c| c.transitions.iter().any(|t| t == transition)).cloned().collect(),
            None => return Ok(0),
        };
        for c in &cmds {
            self.coe().sdo_download(position, c.index, c.subindex, c.complete_access, &c.data).map_err(|e| {
                let name = self.slaves[position as usize].name.clone();
                MasterError::of(
                    position,
                    &name,
                    crate::error::SlaveError::ConfigSdo {
                        origin: crate::error::SdoSource::EsiInitCommand {
                            transition: transition.to_string(),
                            line: c.line,
                        },
                        index: c.index,
                        subindex: c.subindex,
                        comment: c.comment.clone(),
                        error: Box::new(e),
                    },
                )
            })?;
            tracing::debug!(position, transition, index = c.index, subindex = c.subindex, "init command sent");
        }
        Ok(cmds.len())
    }
}
