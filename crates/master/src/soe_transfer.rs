//! An SoE read or write as steps without I/O (ETG.1000.6 §5.8): the messages to write (a
//! write's fragments, each but the last unanswered) and the replies taken (a read's fragments
//! joined). The blocking SoE client ([`crate::Soe`]) and the acyclic side of a running master
//! drive the same steps.
use std::collections::VecDeque;

use ferrocat_wire::soe::{self, opcode, Elements, Idn, SoeError, SoeHeader};

use crate::error::{MasterError, Result, SlaveError};

/// Fragments a transfer may have, whichever way: past this a drive's reply is an error
/// rather than a loop (a drive's list of every IDN, S-0-0017, is a few KB).
const MAX_FRAGMENTS: usize = 4096;

/// What a transfer wants after a reply.
#[derive(Debug)]
pub(crate) enum SoeStep {
    /// Another reply (the next fragment).
    Await,
    /// The transfer is over: the data read (empty after a write).
    Done(Vec<u8>),
}

/// The slave of a transfer, for its errors, and its mailboxes' lengths.
#[derive(Debug, Clone)]
pub(crate) struct SoePeer {
    pub position: u16,
    pub name: String,
    /// The receive mailbox's length (the master's messages).
    pub out_len: usize,
}

/// A read or write of an IDN's elements.
#[derive(Debug)]
pub(crate) struct SoeTransfer {
    peer: SoePeer,
    drive: u8,
    idn: Idn,
    /// The messages still to write; a write's replies come after its last.
    to_send: VecDeque<Vec<u8>>,
    reply_opcode: u8,
    got: Vec<u8>,
    fragments: usize,
}

impl SoeTransfer {
    pub fn read(peer: SoePeer, drive: u8, idn: Idn, elements: Elements) -> Result<Self> {
        let h =
            SoeHeader { opcode: opcode::READ_REQUEST, incomplete: false, error: false, drive, elements, idn: idn.0 };
        let mut req = vec![0u8; soe::HEADER_LEN];
        h.emit(&mut req)?;
        Ok(SoeTransfer {
            peer,
            drive,
            idn,
            to_send: VecDeque::from([req]),
            reply_opcode: opcode::READ_RESPONSE,
            got: Vec::new(),
            fragments: 0,
        })
    }

    /// `data` to `elements`, in fragments where it does not fit the receive mailbox (each but
    /// the last marked incomplete, counting the fragments left; the drive answers the last).
    pub fn write(peer: SoePeer, drive: u8, idn: Idn, elements: Elements, data: &[u8]) -> Result<Self> {
        let per = soe::max_fragment_len(peer.out_len);
        let parts: Vec<&[u8]> = if data.is_empty() { vec![&[][..]] } else { data.chunks(per.max(1)).collect() };
        if per == 0 || parts.len() > MAX_FRAGMENTS {
            return Err(MasterError::of(
                peer.position,
                &peer.name,
                SlaveError::RequestTooLong { len: data.len(), mailbox: peer.out_len },
            ));
        }
        let mut to_send = VecDeque::with_capacity(parts.len());
        for (k, part) in parts.iter().enumerate() {
            let left = parts.len() - 1 - k;
            let h = SoeHeader {
                opcode: opcode::WRITE_REQUEST,
                incomplete: left > 0,
                error: false,
                drive,
                elements,
                idn: if left > 0 { left as u16 } else { idn.0 },
            };
            let mut msg = vec![0u8; soe::HEADER_LEN + part.len()];
            h.emit(&mut msg)?;
            msg[soe::HEADER_LEN..].copy_from_slice(part);
            to_send.push_back(msg);
        }
        Ok(SoeTransfer {
            peer,
            drive,
            idn,
            to_send,
            reply_opcode: opcode::WRITE_RESPONSE,
            got: Vec::new(),
            fragments: 0,
        })
    }

    /// The next message to write, if any is left (the drive replies after the last).
    pub fn next_message(&mut self) -> Option<Vec<u8>> {
        self.to_send.pop_front()
    }

    fn fail(&self, error: SlaveError) -> MasterError {
        MasterError::of(self.peer.position, &self.peer.name, error)
    }

    /// A reply of the drive's: an error reply is its error code, a fragment is kept.
    pub fn on_reply(&mut self, payload: &[u8]) -> Result<SoeStep> {
        let h = SoeHeader::parse(payload).map_err(|e| self.fail(SlaveError::MalformedReply(e)))?;
        let want = self.reply_opcode;
        if h.opcode != want {
            return Err(self.fail(SlaveError::UnexpectedReply(format!("SoE opcode {} where {want} was due", h.opcode))));
        }
        let body = &payload[soe::HEADER_LEN..];
        let (idn, drive) = (self.idn, self.drive);
        if h.error {
            let code = body.get(..2).map_or(SoeError::GENERAL.0, |b| u16::from_le_bytes([b[0], b[1]]));
            return Err(self.fail(SlaveError::Soe { idn, drive, error: SoeError(code) }));
        }
        self.fragments += 1;
        if self.fragments > MAX_FRAGMENTS {
            return Err(
                self.fail(SlaveError::UnexpectedReply(format!("SoE {idn}: more than {MAX_FRAGMENTS} fragments")))
            );
        }
        self.got.extend_from_slice(body);
        if h.incomplete {
            return Ok(SoeStep::Await);
        }
        if h.idn != idn.0 || h.drive != drive {
            return Err(self.fail(SlaveError::UnexpectedReply(format!(
                "SoE reply for {} of drive {} where {idn} of drive {drive} was asked",
                Idn(h.idn),
                h.drive
            ))));
        }
        Ok(SoeStep::Done(std::mem::take(&mut self.got)))
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn peer(out_len: usize) -> SoePeer {
        SoePeer { position: 1, name: "drive".into(), out_len }
    }

    #[test]
    fn a_write_longer_than_the_mailbox_goes_in_fragments_counting_down() {
        // 40-byte mailbox: 30 bytes of data a fragment; 70 bytes make three.
        let mut t = SoeTransfer::write(peer(40), 0, Idn(16), Elements::VALUE, &[7u8; 70]).unwrap();
        let msgs: Vec<Vec<u8>> = std::iter::from_fn(|| t.next_message()).collect();
        let heads: Vec<(bool, u16, usize)> = msgs
            .iter()
            .map(|m| {
                let h = SoeHeader::parse(m).unwrap();
                (h.incomplete, h.idn, m.len() - soe::HEADER_LEN)
            })
            .collect();
        assert_eq!(heads, [(true, 2, 30), (true, 1, 30), (false, 16, 10)]);
        assert!(SoeTransfer::write(peer(10), 0, Idn(16), Elements::VALUE, &[1]).is_err(), "no room for data");
    }

    #[test]
    fn a_read_joins_its_fragments_and_an_error_reply_is_the_drive_s_code() {
        let mut t = SoeTransfer::read(peer(40), 0, Idn(30), Elements::VALUE).unwrap();
        assert!(t.next_message().is_some() && t.next_message().is_none());
        let frag = |incomplete, idn: u16, data: &[u8]| {
            let mut v = vec![0u8; 4];
            SoeHeader {
                opcode: opcode::READ_RESPONSE,
                incomplete,
                error: false,
                drive: 0,
                elements: Elements::VALUE,
                idn,
            }
            .emit(&mut v)
            .unwrap();
            v.extend_from_slice(data);
            v
        };
        assert!(matches!(t.on_reply(&frag(true, 1, b"ab")).unwrap(), SoeStep::Await));
        assert!(matches!(t.on_reply(&frag(false, 30, b"cd")).unwrap(), SoeStep::Done(d) if d == b"abcd"));
        let mut t = SoeTransfer::read(peer(40), 0, Idn(30), Elements::VALUE).unwrap();
        let mut e = vec![0u8; 4];
        SoeHeader {
            opcode: opcode::READ_RESPONSE,
            incomplete: false,
            error: true,
            drive: 0,
            elements: Elements::VALUE,
            idn: 30,
        }
        .emit(&mut e)
        .unwrap();
        e.extend_from_slice(&0x1001u16.to_le_bytes());
        let err = t.on_reply(&e).unwrap_err();
        assert!(
            matches!(err, MasterError::Slave { error: SlaveError::Soe { error: SoeError(0x1001), .. }, .. }),
            "{err}"
        );
        // A reply for another IDN is not this one's.
        let mut t = SoeTransfer::read(peer(40), 0, Idn(30), Elements::VALUE).unwrap();
        assert!(t.on_reply(&frag(false, 31, b"x")).is_err());
    }
}
