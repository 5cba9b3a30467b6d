//! An FoE file server (ETG.1000.6 §5.7) for devices whose SII names FoE among their mailbox
//! protocols: files written by the master are kept by name and can be read back; a transfer
//! runs one packet per mailbox exchange, each acknowledged.
use std::collections::BTreeMap;

use ferrocat_wire::foe::{max_data_len, Foe, FoeErrorCode};

/// Most bytes all files together may hold: a master writing without end gets "disk full"
/// rather than the simulator's memory.
pub const CAPACITY_BYTES: usize = 64 << 20;

#[derive(Debug, Clone)]
enum Transfer {
    /// Receiving `name`; `next` is the packet number expected, `busy_left` how many more
    /// times its first data packet is answered busy.
    Write { name: Vec<u8>, data: Vec<u8>, next: u32, busy_left: u32 },
    /// Sending `data`; `packet` was the last one sent and `sent` bytes have gone, `last` whether
    /// that packet ended the file.
    Read { data: Vec<u8>, sent: usize, packet: u32, last: bool },
}

#[derive(Debug, Clone, Default)]
pub struct FoeServer {
    /// The files, by name (bytes as the master sent them).
    pub files: BTreeMap<Vec<u8>, Vec<u8>>,
    /// The password read and write requests must carry (0: any).
    pub password: u32,
    transfer: Option<Transfer>,
    /// How many times the first data packet of each write is answered busy (a device
    /// erasing its flash before it takes the file); the master sends the packet again.
    pub busy_per_write: u32,
    /// Files received whole, files sent whole, busy replies sent.
    pub writes: u64,
    pub reads: u64,
    pub busy_sent: u64,
}

/// An FoE reply's service data.
fn emit(msg: Foe<'_>) -> Vec<u8> {
    let mut v = vec![0u8; msg.len()];
    let n = msg.emit(&mut v).unwrap_or(0);
    v.truncate(n);
    v
}

fn error(code: FoeErrorCode) -> Vec<u8> {
    emit(Foe::Error { code, text: code.name().unwrap_or("").as_bytes() })
}

impl FoeServer {
    /// A server with no files whose requests must carry `password` (0: any).
    pub fn with_password(password: u32) -> Self {
        FoeServer { password, ..FoeServer::default() }
    }

    fn stored_bytes(&self) -> usize {
        self.files.values().map(Vec::len).sum()
    }

    /// Answers one request. `out_len` and `in_len` are the receive (SM0) and send (SM1)
    /// mailboxes' lengths: a packet from the master shorter than the first allows ends a file,
    /// and packets to it are as long as the second allows. Empty: no reply (the master's last
    /// acknowledge, or its own error).
    pub fn handle(&mut self, request: &[u8], out_len: usize, in_len: usize) -> Vec<u8> {
        let Ok(msg) = Foe::parse(request) else {
            self.transfer = None;
            return error(FoeErrorCode::ILLEGAL);
        };
        match (msg, self.transfer.take()) {
            (Foe::WriteRequest { password, file_name }, _) => {
                if self.password != 0 && password != self.password {
                    return error(FoeErrorCode::ACCESS_DENIED);
                }
                let busy_left = self.busy_per_write;
                self.transfer =
                    Some(Transfer::Write { name: file_name.to_vec(), data: Vec::new(), next: 1, busy_left });
                emit(Foe::Ack { packet: 0 })
            }
            (Foe::ReadRequest { password, file_name }, _) => {
                if self.password != 0 && password != self.password {
                    return error(FoeErrorCode::ACCESS_DENIED);
                }
                let Some(data) = self.files.get(file_name).cloned() else {
                    return error(FoeErrorCode::NOT_FOUND);
                };
                self.next_packet(data, 0, 0, in_len)
            }
            (Foe::Data { packet, data }, Some(Transfer::Write { name, data: mut file, next, busy_left })) => {
                let max = max_data_len(out_len);
                if packet != next {
                    return error(FoeErrorCode::PACKET_NUMBER_WRONG);
                }
                if busy_left > 0 {
                    // Not taken: the master sends this packet again (ETG.1000.6 §5.7).
                    self.transfer = Some(Transfer::Write { name, data: file, next, busy_left: busy_left - 1 });
                    self.busy_sent += 1;
                    let entire = self.busy_per_write.min(u16::MAX as u32) as u16;
                    let done = (self.busy_per_write.saturating_sub(busy_left) + 1).min(entire as u32) as u16;
                    return emit(Foe::Busy { done, entire });
                }
                if data.len() > max {
                    return error(FoeErrorCode::ILLEGAL);
                }
                let replaced = self.files.get(&name).map_or(0, Vec::len);
                if self.stored_bytes() - replaced + file.len() + data.len() > CAPACITY_BYTES {
                    return error(FoeErrorCode::DISK_FULL);
                }
                file.extend_from_slice(data);
                if data.len() < max {
                    self.files.insert(name, file);
                    self.writes += 1;
                } else {
                    self.transfer =
                        Some(Transfer::Write { name, data: file, next: next.wrapping_add(1), busy_left: 0 });
                }
                emit(Foe::Ack { packet })
            }
            (Foe::Ack { packet: acked }, Some(Transfer::Read { data, sent, packet, last })) => {
                if acked != packet {
                    return error(FoeErrorCode::PACKET_NUMBER_WRONG);
                }
                if last {
                    self.reads += 1;
                    return Vec::new();
                }
                self.next_packet(data, sent, packet, in_len)
            }
            // The master gave up: so does the transfer, without a reply.
            (Foe::Error { .. }, _) => Vec::new(),
            // Data, acknowledges or busy outside a transfer of their kind.
            _ => error(FoeErrorCode::ILLEGAL),
        }
    }

    /// Sends the packet after `packet`, from byte `sent` of `data`.
    fn next_packet(&mut self, data: Vec<u8>, sent: usize, packet: u32, in_len: usize) -> Vec<u8> {
        let max = max_data_len(in_len);
        if max == 0 {
            return error(FoeErrorCode::PROGRAM_ERROR);
        }
        let end = (sent + max).min(data.len());
        let packet = packet.wrapping_add(1);
        // A packet shorter than the mailbox allows (an empty one after a full last) ends it.
        let last = end - sent < max;
        let reply = emit(Foe::Data { packet, data: &data[sent..end] });
        self.transfer = Some(Transfer::Read { data, sent: end, packet, last });
        reply
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn req(msg: Foe<'_>) -> Vec<u8> {
        emit(msg)
    }

    fn parse(reply: &[u8]) -> Foe<'_> {
        Foe::parse(reply).unwrap()
    }

    /// A 24-byte mailbox carries 12 bytes of file data per packet.
    const MBX: usize = 24;

    #[test]
    fn a_file_written_in_packets_reads_back_the_same() {
        let mut s = FoeServer::default();
        let file: Vec<u8> = (0..30).collect();
        assert_eq!(
            parse(&s.handle(&req(Foe::WriteRequest { password: 0, file_name: b"f" }), MBX, MBX)),
            Foe::Ack { packet: 0 }
        );
        for (k, chunk) in file.chunks(12).enumerate() {
            let p = k as u32 + 1;
            assert_eq!(parse(&s.handle(&req(Foe::Data { packet: p, data: chunk }), MBX, MBX)), Foe::Ack { packet: p });
        }
        assert_eq!(s.files.get(&b"f"[..]), Some(&file));
        let mut got = Vec::new();
        let mut reply = s.handle(&req(Foe::ReadRequest { password: 0, file_name: b"f" }), MBX, MBX);
        loop {
            let Foe::Data { packet, data } = parse(&reply) else { panic!("{:?}", parse(&reply)) };
            got.extend_from_slice(data);
            let short = data.len() < 12;
            reply = s.handle(&req(Foe::Ack { packet }), MBX, MBX);
            if short {
                assert!(reply.is_empty(), "nothing after the last acknowledge");
                break;
            }
        }
        assert_eq!(got, file);
        assert_eq!((s.writes, s.reads), (1, 1));
    }

    #[test]
    fn a_file_that_fills_its_last_packet_ends_with_an_empty_one() {
        let mut s = FoeServer::default();
        s.files.insert(b"x".to_vec(), vec![7; 24]);
        let r = s.handle(&req(Foe::ReadRequest { password: 0, file_name: b"x" }), MBX, MBX);
        assert!(matches!(parse(&r), Foe::Data { packet: 1, data } if data.len() == 12));
        let r = s.handle(&req(Foe::Ack { packet: 1 }), MBX, MBX);
        assert!(matches!(parse(&r), Foe::Data { packet: 2, data } if data.len() == 12));
        let r = s.handle(&req(Foe::Ack { packet: 2 }), MBX, MBX);
        assert_eq!(parse(&r), Foe::Data { packet: 3, data: &[] });
        assert!(s.handle(&req(Foe::Ack { packet: 3 }), MBX, MBX).is_empty());
        // Writing: a full packet does not end the file, the empty one does.
        s.handle(&req(Foe::WriteRequest { password: 0, file_name: b"y" }), MBX, MBX);
        s.handle(&req(Foe::Data { packet: 1, data: &[1; 12] }), MBX, MBX);
        assert!(!s.files.contains_key(&b"y"[..]));
        s.handle(&req(Foe::Data { packet: 2, data: &[] }), MBX, MBX);
        assert_eq!(s.files.get(&b"y"[..]), Some(&vec![1; 12]));
    }

    #[test]
    fn a_busy_server_takes_the_first_packet_when_it_comes_again() {
        let mut s = FoeServer { busy_per_write: 2, ..FoeServer::default() };
        s.handle(&req(Foe::WriteRequest { password: 0, file_name: b"fw" }), MBX, MBX);
        let first = req(Foe::Data { packet: 1, data: &[9; 12] });
        assert_eq!(parse(&s.handle(&first, MBX, MBX)), Foe::Busy { done: 1, entire: 2 });
        assert_eq!(parse(&s.handle(&first, MBX, MBX)), Foe::Busy { done: 2, entire: 2 });
        assert_eq!(parse(&s.handle(&first, MBX, MBX)), Foe::Ack { packet: 1 });
        // Only the first packet: the rest is acknowledged at once.
        assert_eq!(parse(&s.handle(&req(Foe::Data { packet: 2, data: &[8] }), MBX, MBX)), Foe::Ack { packet: 2 });
        assert_eq!(s.files.get(&b"fw"[..]), Some(&[[9; 12].as_slice(), &[8]].concat()));
        // A packet number skipped while busy is still wrong.
        s.handle(&req(Foe::WriteRequest { password: 0, file_name: b"g" }), MBX, MBX);
        let skipped = s.handle(&req(Foe::Data { packet: 2, data: &[] }), MBX, MBX);
        assert!(matches!(parse(&skipped), Foe::Error { code: FoeErrorCode::PACKET_NUMBER_WRONG, .. }));
        assert_eq!((s.writes, s.busy_sent), (1, 2));
    }

    #[test]
    fn errors_name_what_went_wrong() {
        let mut s = FoeServer::with_password(0x1234);
        let code = |r: Vec<u8>| match Foe::parse(&r).unwrap() {
            Foe::Error { code, .. } => code,
            other => panic!("{other:?}"),
        };
        assert_eq!(
            code(s.handle(&req(Foe::ReadRequest { password: 0x1234, file_name: b"none" }), MBX, MBX)),
            FoeErrorCode::NOT_FOUND
        );
        assert_eq!(
            code(s.handle(&req(Foe::WriteRequest { password: 1, file_name: b"f" }), MBX, MBX)),
            FoeErrorCode::ACCESS_DENIED
        );
        s.handle(&req(Foe::WriteRequest { password: 0x1234, file_name: b"f" }), MBX, MBX);
        assert_eq!(
            code(s.handle(&req(Foe::Data { packet: 2, data: &[] }), MBX, MBX)),
            FoeErrorCode::PACKET_NUMBER_WRONG
        );
        // The transfer ended with that error: data now is outside any.
        assert_eq!(code(s.handle(&req(Foe::Data { packet: 1, data: &[] }), MBX, MBX)), FoeErrorCode::ILLEGAL);
        s.handle(&req(Foe::WriteRequest { password: 0x1234, file_name: b"f" }), MBX, MBX);
        assert_eq!(code(s.handle(&req(Foe::Data { packet: 1, data: &[0; 13] }), MBX, MBX)), FoeErrorCode::ILLEGAL);
        assert_eq!(code(s.handle(&[3, 0], MBX, MBX)), FoeErrorCode::ILLEGAL);
        assert!(s.files.is_empty());
    }

    #[test]
    fn a_master_writing_without_end_fills_the_disk_not_the_memory() {
        let mut s = FoeServer::default();
        let big = 1 << 16;
        s.handle(&req(Foe::WriteRequest { password: 0, file_name: b"big" }), big, big);
        let chunk = vec![0u8; max_data_len(big)];
        let mut p = 1;
        let last = loop {
            let r = s.handle(&req(Foe::Data { packet: p, data: &chunk }), big, big);
            if !matches!(parse(&r), Foe::Ack { .. }) {
                break r;
            }
            p += 1;
        };
        assert!(matches!(parse(&last), Foe::Error { code: FoeErrorCode::DISK_FULL, .. }));
        assert!((p as usize) * chunk.len() > CAPACITY_BYTES - chunk.len());
    }
}
