//! Modular devices (ETG.5001): the master tells the slave which modules it expects (0xF030)
//! and checks them against those the slave detected (0xF050) before SAFEOP.
use crate::error::{MasterError, ModuleError, Result, SlaveError};
use crate::io::Io;
use crate::master::Master;

/// Configured module ident list.
const CONFIGURED: u16 = 0xF030;
/// Detected module ident list.
const DETECTED: u16 = 0xF050;

impl<I: Io> Master<I> {}

impl<'a, I: Io> crate::master::part::Config<'a, I> {
    /// The modules slave `position` (in PREOP) carries, slot by slot, from its 0xF050.
    pub fn detected_modules(&mut self, position: u16) -> Result<Vec<u32>> {
        let n = *self.m.acyclic().coe().sdo_read(position, DETECTED, 0)?.first().unwrap_or(&0);
        (1..=n)
            .map(|k| {
                let v = self.m.acyclic().coe().sdo_read(position, DETECTED, k)?;
                let b: [u8; 4] = v.get(..4).and_then(|b| b.try_into().ok()).ok_or_else(|| {
                    let name = self.m.slaves[position as usize].name.clone();
                    MasterError::of(
                        position,
                        &name,
                        SlaveError::Modules(ModuleError::DetectedEntry { subindex: k, len: v.len() }),
                    )
                })?;
                Ok(u32::from_le_bytes(b))
            })
            .collect()
    }

    /// Configures the modules slave `position` (in PREOP) is to carry, slot by slot: writes
    /// them to 0xF030 and checks them against 0xF050. The error names the first slot that
    /// differs, with the module configured and the one detected; a slave told modules it
    /// does not carry refuses SAFEOP (AL status code 0x0070).
    pub fn configure_modules(&mut self, position: u16, idents: &[u32]) -> Result<()> {
        let name = self.m.slave(position)?.name.clone();
        let count = u8::try_from(idents.len())
            .map_err(|_| MasterError::of(position, &name, SlaveError::Modules(ModuleError::TooMany(idents.len()))))?;
        self.m.acyclic().coe().sdo_write(position, CONFIGURED, 0, &[0])?;
        for (k, ident) in idents.iter().enumerate() {
            self.m.acyclic().coe().sdo_write(position, CONFIGURED, k as u8 + 1, &ident.to_le_bytes())?;
        }
        self.m.acyclic().coe().sdo_write(position, CONFIGURED, 0, &[count])?;
        let detected = self.m.config().detected_modules(position)?;
        let slots = idents.len().max(detected.len());
        if let Some(slot) = (0..slots).find(|&k| idents.get(k) != detected.get(k)) {
            return Err(MasterError::of(
                position,
                &name,
                SlaveError::Modules(ModuleError::Mismatch {
                    slot,
                    configured: idents.get(slot).copied(),
                    detected: detected.get(slot).copied(),
                    detected_count: detected.len(),
                }),
            ));
        }
        tracing::info!(position, modules = idents.len(), "modules configured");
        Ok(())
    }
}
