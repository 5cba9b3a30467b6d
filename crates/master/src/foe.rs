//! The FoE client: files to and from a slave's mailbox (firmware, parameter sets), packet by
//! packet, each acknowledged (ETG.1000.6 §5.7).
use ferrocat_wire::foe::{self as wire, max_data_len};
use ferrocat_wire::mailbox::MailboxType;
use ferrocat_wire::register::AlState;

use crate::error::{FoeError, MasterError, Result, SlaveError};
use crate::io::Io;
use crate::mailbox::Mailboxes;
use crate::master::Master;
use crate::slave::MailboxConfig;

/// How often a slave may answer "busy" to one packet before the transfer is given up (each
/// busy costs a mailbox round trip; firmware erasing its flash says so for seconds).
const MAX_BUSY: u32 = 100_000;

impl<I: Io> Master<I> {
    /// Puts the slave at `position` into BOOT, where a bootloader takes firmware by FoE: INIT,
    /// the SII's bootstrap mailbox written to SM0 and SM1, then BOOT. Its mailbox functions use
    /// the bootstrap mailbox until [`leave_bootstrap`](Self::leave_bootstrap).
    pub fn enter_bootstrap(&mut self, position: u16) -> Result<()> {
        let (boot, name) = {
            let s = self.slave(position)?;
            (MailboxConfig::bootstrap(&s.sii.header), s.name.clone())
        };
        let boot =
            boot.ok_or_else(|| MasterError::of(position, &name, crate::error::SlaveError::NoBootstrapMailbox))?;
        self.request_state(position, AlState::Init)?;
        self.slaves[position as usize].mailbox = Some(boot);
        let entered =
            self.write_mailbox_config(position).and_then(|_| self.request_state(position, AlState::Bootstrap));
        if entered.is_err() {
            self.slaves[position as usize].mailbox =
                MailboxConfig::standard(&self.slaves[position as usize].sii.header);
        }
        entered
    }

    /// Back from BOOT to INIT, the standard mailbox written to SM0 and SM1 again (a new
    /// firmware starts there, and PREOP can be requested at once).
    pub fn leave_bootstrap(&mut self, position: u16) -> Result<()> {
        let left = self.request_state(position, AlState::Init);
        let s = &mut self.slaves[position as usize];
        s.mailbox = MailboxConfig::standard(&s.sii.header);
        left?;
        self.write_mailbox_config(position)
    }
}

/// The FoE client of one master (see [`Master::foe`](crate::Master::foe)): it borrows the master's engine and
/// slave list for as long as it is used.
pub struct Foe<'a, I: Io> {
    pub(crate) mbx: Mailboxes<'a, I>,
}

impl<I: Io> Master<I> {
    /// The FoE client: files to and from a slave (see also [`Master::enter_bootstrap`]).
    pub fn foe(&mut self) -> Foe<'_, I> {
        Foe { mbx: self.mailboxes() }
    }
}

impl<I: Io> Foe<'_, I> {
    fn error(&self, position: u16, error: SlaveError) -> MasterError {
        MasterError::of(position, &self.mbx.name_of(position), error)
    }

    fn file_error(&self, position: u16, file: &str, error: FoeError) -> MasterError {
        self.error(position, SlaveError::Foe { file: file.into(), error })
    }

    fn exchange(&mut self, position: u16, msg: wire::Foe<'_>) -> Result<Vec<u8>> {
        let mut b = vec![0u8; msg.len()];
        msg.emit(&mut b)?;
        self.mbx.write(position, MailboxType::FOE, &b)?;
        self.mbx.read(position, MailboxType::FOE)
    }

    /// What an FoE reply that is not the one expected means, as an error.
    fn unexpected(&self, position: u16, file: &str, reply: &[u8], expected: &str) -> MasterError {
        let error = match wire::Foe::parse(reply) {
            Ok(wire::Foe::Error { code, text }) => {
                let text = String::from_utf8_lossy(text);
                let text = text.trim_end_matches('\0');
                let text = (!text.is_empty() && Some(text) != code.name()).then(|| text.to_string());
                FoeError::Refused { code, text }
            }
            Ok(other) => FoeError::Unexpected { reply: format!("{other:?}"), expected: expected.into() },
            Err(e) => FoeError::Undecodable(e),
        };
        self.file_error(position, file, error)
    }

    /// Writes `data` as file `file` to the slave at `position` (in a state with a mailbox:
    /// PREOP and above, or BOOT for firmware — see [`Master::enter_bootstrap`]).
    pub fn write(&mut self, position: u16, file: &str, password: u32, data: &[u8]) -> Result<()> {
        let (_, _, m) = self.mbx.mailbox_of(position, MailboxType::FOE)?;
        let max = max_data_len(m.out.1 as usize);
        if max == 0 {
            return Err(self.error(position, SlaveError::FoeMailboxTooSmall(m.out.1)));
        }
        let reply = self.exchange(position, wire::Foe::WriteRequest { password, file_name: file.as_bytes() })?;
        if wire::Foe::parse(&reply).ok() != Some(wire::Foe::Ack { packet: 0 }) {
            return Err(self.unexpected(position, file, &reply, "the acknowledge of packet 0"));
        }
        // Full packets, then a short one (empty where the file fills the last).
        let mut sent = 0;
        let mut packet = 0u32;
        loop {
            let chunk = &data[sent..(sent + max).min(data.len())];
            packet = packet.wrapping_add(1);
            let mut busy = 0;
            let mut reply = self.exchange(position, wire::Foe::Data { packet, data: chunk })?;
            // Busy: the same packet again once the slave is ready.
            while let Ok(wire::Foe::Busy { .. }) = wire::Foe::parse(&reply) {
                busy += 1;
                if busy > MAX_BUSY {
                    return Err(self.file_error(position, file, FoeError::Busy { times: MAX_BUSY, packet }));
                }
                reply = self.exchange(position, wire::Foe::Data { packet, data: chunk })?;
            }
            if wire::Foe::parse(&reply).ok() != Some(wire::Foe::Ack { packet }) {
                return Err(self.unexpected(position, file, &reply, &format!("the acknowledge of packet {packet}")));
            }
            sent += chunk.len();
            if chunk.len() < max {
                return Ok(());
            }
        }
    }

    /// Reads file `file` from the slave at `position`. `max_bytes` bounds what is kept: a
    /// slave sending more is an error (the transfer is aborted), not a truncated file.
    pub fn read(&mut self, position: u16, file: &str, password: u32, max_bytes: usize) -> Result<Vec<u8>> {
        let (_, _, m) = self.mbx.mailbox_of(position, MailboxType::FOE)?;
        let max = max_data_len(m.inp.1 as usize);
        let mut data = Vec::new();
        let mut expect = 1u32;
        let mut reply = self.exchange(position, wire::Foe::ReadRequest { password, file_name: file.as_bytes() })?;
        loop {
            let (packet, chunk) = match wire::Foe::parse(&reply) {
                Ok(wire::Foe::Data { packet, data }) if packet == expect => (packet, data),
                _ => return Err(self.unexpected(position, file, &reply, &format!("data packet {expect}"))),
            };
            if data.len() + chunk.len() > max_bytes {
                // Tell the slave to stop; its answer (none) is not awaited.
                let abort = wire::Foe::Error { code: wire::FoeErrorCode::DISK_FULL, text: b"" };
                let mut b = vec![0u8; abort.len()];
                abort.emit(&mut b)?;
                self.mbx.write(position, MailboxType::FOE, &b)?;
                return Err(self.file_error(position, file, FoeError::TooLong(max_bytes)));
            }
            data.extend_from_slice(chunk);
            let last = chunk.len() < max;
            let ack = wire::Foe::Ack { packet };
            if last {
                let mut b = vec![0u8; ack.len()];
                ack.emit(&mut b)?;
                self.mbx.write(position, MailboxType::FOE, &b)?;
                return Ok(data);
            }
            expect = expect.wrapping_add(1);
            reply = self.exchange(position, ack)?;
        }
    }
}
