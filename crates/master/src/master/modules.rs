//! Modular devices (ETG.5001): the master tells the slave which modules it expects (0xF030)
//! and checks them against those the slave detected (0xF050) before SAFEOP.
use crate::error::{MasterError, Result};
use crate::io::Io;
use crate::master::Master;

/// Configured module ident list.
const CONFIGURED: u16 = 0xF030;
/// Detected module ident list.
const DETECTED: u16 = 0xF050;

impl<I: Io> Master<I> {
    /// The modules slave `position` (in PREOP) carries, slot by slot, from its 0xF050.
    pub fn detected_modules(&mut self, position: u16) -> Result<Vec<u32>> {
        let n = *self.coe().sdo_read(position, DETECTED, 0)?.first().unwrap_or(&0);
        (1..=n)
            .map(|k| {
                let v = self.coe().sdo_read(position, DETECTED, k)?;
                let b: [u8; 4] = v.get(..4).and_then(|b| b.try_into().ok()).ok_or_else(|| {
                    let name = self.slaves[position as usize].name.clone();
                    MasterError::slave(position, &name, format!("0xF050:{k:02x} is {} bytes, not 4", v.len()))
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
        let name = self.slave(position)?.name.clone();
        let count = u8::try_from(idents.len())
            .map_err(|_| MasterError::slave(position, &name, format!("{} modules: 0xF030 holds 255", idents.len())))?;
        self.coe().sdo_write(position, CONFIGURED, 0, &[0])?;
        for (k, ident) in idents.iter().enumerate() {
            self.coe().sdo_write(position, CONFIGURED, k as u8 + 1, &ident.to_le_bytes())?;
        }
        self.coe().sdo_write(position, CONFIGURED, 0, &[count])?;
        let detected = self.detected_modules(position)?;
        let slots = idents.len().max(detected.len());
        let shown = |v: Option<&u32>| v.map_or("none".to_string(), |m| format!("{m:#010x}"));
        if let Some(slot) = (0..slots).find(|&k| idents.get(k) != detected.get(k)) {
            return Err(MasterError::slave(
                position,
                &name,
                format!(
                    "slot {slot}: module {} configured, {} detected (0xF050 lists {} modules)",
                    shown(idents.get(slot)),
                    shown(detected.get(slot)),
                    detected.len()
                ),
            ));
        }
        tracing::info!(position, modules = idents.len(), "modules configured");
        Ok(())
    }
}
