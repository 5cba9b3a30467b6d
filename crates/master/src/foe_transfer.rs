//! An FoE file transfer as steps without I/O (ETG.1000.6 §5.7): each takes the slave's FoE reply
//! and gives the next message, or the transfer's end. The blocking FoE client
//! ([`crate::Foe`]) and the acyclic side of a running master drive the same steps.
use ferrocat_wire::foe::{self as wire, max_data_len};

use crate::error::{FoeError, MasterError, Result, SlaveError};

/// How often a slave may answer "busy" to one packet before the transfer is given up (each
/// busy costs a mailbox round trip; firmware erasing its flash says so for seconds).
pub(crate) const MAX_BUSY: u32 = 100_000;

/// What a transfer wants after a reply.
#[derive(Debug)]
pub(crate) enum FoeStep {
    /// This FoE message next, and its reply.
    Send(Vec<u8>),
    /// This FoE message last (no reply awaited), then the transfer ends with the result.
    Finish(Vec<u8>, Result<Vec<u8>>),
    /// The transfer is over (the data read; empty after a write).
    Done(Vec<u8>),
}

/// The slave and file of a transfer, for its errors.
#[derive(Debug, Clone)]
pub(crate) struct FoePeer {
    pub position: u16,
    pub name: String,
    /// The receive mailbox's length (the master's packets) and the send mailbox's (the
    /// slave's).
    pub out_len: usize,
    pub in_len: usize,
}

#[derive(Debug)]
enum Kind {
    Write { data: Vec<u8>, sent: usize, packet: u32, busy: u32 },
    Read { data: Vec<u8>, expect: u32, max_bytes: usize },
}

/// A file written to, or read from, a slave.
#[derive(Debug)]
pub(crate) struct FoeTransfer {
    peer: FoePeer,
    file: String,
    password: u32,
    kind: Kind,
}

fn emit(msg: wire::Foe<'_>) -> Result<Vec<u8>> {
    let mut b = vec![0u8; msg.len()];
    msg.emit(&mut b)?;
    Ok(b)
}

impl FoeTransfer {
    /// `data` as file `file`: refused where the mailbox carries no data.
    pub fn write(peer: FoePeer, file: &str, password: u32, data: Vec<u8>) -> Result<Self> {
        if max_data_len(peer.out_len) == 0 {
            return Err(MasterError::of(
                peer.position,
                &peer.name,
                SlaveError::FoeMailboxTooSmall(peer.out_len as u16),
            ));
        }
        let kind = Kind::Write { data, sent: 0, packet: 0, busy: 0 };
        Ok(FoeTransfer { peer, file: file.to_string(), password, kind })
    }

    /// File `file`, at most `max_bytes` of it (a slave sending more is an error, the transfer
    /// aborted, not a truncated file).
    pub fn read(peer: FoePeer, file: &str, password: u32, max_bytes: usize) -> Self {
        let kind = Kind::Read { data: Vec::new(), expect: 1, max_bytes };
        FoeTransfer { peer, file: file.to_string(), password, kind }
    }

    /// The first message.
    pub fn start(&mut self) -> Result<Vec<u8>> {
        let file_name = self.file.as_bytes();
        let password = self.password;
        emit(match self.kind {
            Kind::Write { .. } => wire::Foe::WriteRequest { password, file_name },
            Kind::Read { .. } => wire::Foe::ReadRequest { password, file_name },
        })
    }

    fn error(&self, error: FoeError) -> MasterError {
        MasterError::of(self.peer.position, &self.peer.name, SlaveError::Foe { file: self.file.clone(), error })
    }

    /// What a reply that is not the one expected means, as an error.
    fn unexpected(&self, reply: &[u8], expected: &str) -> MasterError {
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
        self.error(error)
    }

    /// The slave's reply (an FoE message): what comes next.
    pub fn on_reply(&mut self, reply: &[u8]) -> Result<FoeStep> {
        let max_out = max_data_len(self.peer.out_len);
        let max_in = max_data_len(self.peer.in_len);
        let parsed = wire::Foe::parse(reply).ok();
        match &mut self.kind {
            Kind::Write { data, sent, packet, busy } => {
                // Busy: the same packet again once the slave is ready.
                if matches!(parsed, Some(wire::Foe::Busy { .. })) && *packet > 0 {
                    *busy += 1;
                    if *busy > MAX_BUSY {
                        let p = *packet;
                        return Err(self.error(FoeError::Busy { times: MAX_BUSY, packet: p }));
                    }
                    let chunk = &data[*sent..(*sent + max_out).min(data.len())];
                    return emit(wire::Foe::Data { packet: *packet, data: chunk }).map(FoeStep::Send);
                }
                if parsed != Some(wire::Foe::Ack { packet: *packet }) {
                    let what = format!("the acknowledge of packet {packet}");
                    return Err(self.unexpected(reply, &what));
                }
                if *packet > 0 {
                    let last = (data.len() - *sent).min(max_out);
                    *sent += last;
                    // A short packet (empty where the file fills the last) ends the file.
                    if last < max_out {
                        return Ok(FoeStep::Done(Vec::new()));
                    }
                }
                *packet = packet.wrapping_add(1);
                *busy = 0;
                let chunk = &data[*sent..(*sent + max_out).min(data.len())];
                emit(wire::Foe::Data { packet: *packet, data: chunk }).map(FoeStep::Send)
            }
            Kind::Read { data, expect, max_bytes } => {
                let (packet, chunk) = match parsed {
                    Some(wire::Foe::Data { packet, data }) if packet == *expect => (packet, data),
                    _ => {
                        let what = format!("data packet {expect}");
                        return Err(self.unexpected(reply, &what));
                    }
                };
                if data.len() + chunk.len() > *max_bytes {
                    // Tell the slave to stop; its answer (none) is not awaited.
                    let max = *max_bytes;
                    let abort = emit(wire::Foe::Error { code: wire::FoeErrorCode::DISK_FULL, text: b"" })?;
                    return Ok(FoeStep::Finish(abort, Err(self.error(FoeError::TooLong(max)))));
                }
                data.extend_from_slice(chunk);
                let ack = emit(wire::Foe::Ack { packet })?;
                if chunk.len() < max_in {
                    return Ok(FoeStep::Finish(ack, Ok(std::mem::take(data))));
                }
                *expect = expect.wrapping_add(1);
                Ok(FoeStep::Send(ack))
            }
        }
    }
}
