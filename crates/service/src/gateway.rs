//! The mailbox gateway (ETG.8200): mailbox messages over UDP from engineering tools, passed
//! to the slaves' mailboxes by the running master, and the master's own object dictionary
//! (ETG.1510, [`crate::master_od`]) at station address 0.
//!
//! A datagram is an EtherCAT header (length of what follows in bits 0–10, type 5 "mailbox" in
//! bits 12–15) and one mailbox message whose header's address is the slave's station address
//! (0: the master). The gateway's thread parses it, checks the sender against the allow-list
//! and its rate, and asks the cyclic loop through the control socket's queue, as a client
//! does: the loop never waits on the gateway, and a flood costs it a `try_recv` per cycle.
use std::collections::HashMap;
use std::net::{IpAddr, SocketAddr, UdpSocket};
use std::sync::atomic::{AtomicBool, AtomicU64, Ordering};
use std::sync::mpsc::SyncSender;
use std::sync::Arc;
use std::time::{Duration, Instant};

use ferrocat_master::wire::coe::{self, AbortCode, CoeHeader, CoeService, InfoHeader, InfoOpcode, Sdo};
use ferrocat_master::wire::mailbox::{MailboxErrorCode, MailboxHeader, MailboxType, HEADER_LEN};
use ferrocat_master::{Answer, MasterError, SlaveError};

use crate::master_od::{self, Facts, Live};
use crate::server::{ask, ask_facts, Job};

/// The standard port, 0x88A4.
pub const PORT: u16 = 34980;
/// The EtherCAT header's type for mailbox messages.
const MAILBOX_FRAME: u16 = 5;
/// The type `pyetg1510` sends on Linux: its ctypes header puts the 4-bit type in a byte that
/// CPython's non-MSVC bit-field layout (with `_pack_`) drops, up to 3.13 at least. Taken, with
/// a warning (docs/service.md, "Mailbox gateway").
const ZERO_TYPE: u16 = 0;
/// The mailbox the master offers at station address 0, in bytes with its header: a reply
/// longer than this goes in segments (an SDO upload) or fragments (SDO information).
pub const MASTER_MAILBOX: usize = 1024;
/// The longest datagram taken: the EtherCAT header's length field holds 11 bits.
const MAX_DATAGRAM: usize = 2 + 2047;
/// Clients whose segmented uploads are remembered at once.
const TRANSFERS: usize = 64;
/// How long the loop's facts are reused before they are asked for again.
const FACTS_FOR: Duration = Duration::from_millis(100);

/// How the gateway is set up.
#[derive(Debug, Clone)]
pub struct GatewayOptions {
    /// Where it listens (loopback by default: `127.0.0.1:34980`).
    pub bind: SocketAddr,
    /// The senders taken besides loopback (an empty list: loopback only).
    pub allow: Vec<IpAddr>,
    /// Requests a sender may make a second, on average; beyond, it is answered "not enough
    /// resources" (mailbox error 0x07) without reaching the master.
    pub rate_per_s: u32,
    /// Requests a sender may make at once beyond its rate.
    pub burst: u32,
}

impl Default for GatewayOptions {
    fn default() -> Self {
        GatewayOptions {
            bind: SocketAddr::from(([127, 0, 0, 1], PORT)),
            allow: Vec::new(),
            rate_per_s: 500,
            burst: 100,
        }
    }
}

/// What the gateway did: counts since it started.
#[derive(Debug, Default)]
pub struct GatewayStats {
    /// Datagrams received.
    pub received: AtomicU64,
    /// Datagrams dropped as malformed (no reply).
    pub malformed: AtomicU64,
    /// Datagrams dropped because their sender is not allowed (no reply).
    pub refused: AtomicU64,
    /// Requests answered "not enough resources" for their sender's rate.
    pub rate_limited: AtomicU64,
    /// Requests taken although their EtherCAT header's type or CoE service was 0 (the
    /// `pyetg1510` client on Linux), each read as what its content says.
    pub lenient: AtomicU64,
    /// Replies sent (an answer, an abort or a mailbox error).
    pub replies: AtomicU64,
    /// Requests passed to a slave.
    pub forwarded: AtomicU64,
}

impl GatewayStats {
    /// The counts as JSON, for the control socket's statistics.
    pub fn to_json(&self) -> serde_json::Value {
        let l = |a: &AtomicU64| a.load(Ordering::Relaxed);
        serde_json::json!({
            "received": l(&self.received), "malformed": l(&self.malformed), "refused": l(&self.refused),
            "rate_limited": l(&self.rate_limited), "lenient": l(&self.lenient), "replies": l(&self.replies), "forwarded": l(&self.forwarded),
        })
    }
}

/// A request as the gateway reads it.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct GatewayRequest {
    /// The mailbox header (its address: the slave's station address, 0 the master).
    pub header: MailboxHeader,
    /// The message after the mailbox header.
    pub payload: Vec<u8>,
    /// The EtherCAT header's type was 0, not 5.
    pub zero_type: bool,
}

/// Why a datagram is dropped.
#[derive(Debug, Clone, PartialEq, Eq, thiserror::Error)]
pub enum Malformed {
    /// Shorter than an EtherCAT header and a mailbox header.
    #[error("{0} bytes: shorter than an EtherCAT and a mailbox header (8)")]
    Short(usize),
    /// The EtherCAT header's type is not 5 (mailbox), nor 0.
    #[error("EtherCAT header type {0}, not 5 (mailbox)")]
    NotMailbox(u16),
    /// The EtherCAT header's length is not what follows it.
    #[error("EtherCAT header length {header}, {actual} bytes follow")]
    Length {
        /// The header's length.
        header: usize,
        /// The bytes after it.
        actual: usize,
    },
    /// The mailbox header's length runs past the datagram.
    #[error("mailbox length {0} runs past the datagram")]
    MailboxLength(usize),
}

/// Reads a datagram (ETG.8200).
pub fn parse(datagram: &[u8]) -> Result<GatewayRequest, Malformed> {
    if datagram.len() < 2 + HEADER_LEN {
        return Err(Malformed::Short(datagram.len()));
    }
    let word = u16::from_le_bytes([datagram[0], datagram[1]]);
    if word >> 12 != MAILBOX_FRAME && word >> 12 != ZERO_TYPE {
        return Err(Malformed::NotMailbox(word >> 12));
    }
    let length = usize::from(word & 0x07FF);
    if length != datagram.len() - 2 {
        return Err(Malformed::Length { header: length, actual: datagram.len() - 2 });
    }
    let mbx = &datagram[2..];
    let header = MailboxHeader::parse(mbx).map_err(|_| Malformed::Short(datagram.len()))?;
    let end = HEADER_LEN + usize::from(header.length);
    if end > mbx.len() {
        return Err(Malformed::MailboxLength(usize::from(header.length)));
    }
    Ok(GatewayRequest { header, payload: mbx[HEADER_LEN..end].to_vec(), zero_type: word >> 12 == ZERO_TYPE })
}

/// A reply datagram: `payload` as a message of `mailbox_type` from `address`, under `counter`.
pub fn frame(address: u16, mailbox_type: MailboxType, counter: u8, payload: &[u8]) -> Vec<u8> {
    let len = HEADER_LEN + payload.len();
    let mut out = Vec::with_capacity(2 + len);
    out.extend_from_slice(&((MAILBOX_FRAME << 12) | (len as u16 & 0x07FF)).to_le_bytes());
    let mut h = MailboxHeader::new(mailbox_type, payload.len() as u16, counter);
    h.address = address;
    out.extend_from_slice(&h.to_bytes());
    out.extend_from_slice(payload);
    out
}

/// A mailbox error reply's payload.
fn mailbox_error(code: MailboxErrorCode) -> (MailboxType, Vec<u8>) {
    (MailboxType::ERR, code.to_bytes().to_vec())
}

/// An SDO abort as a CoE message.
fn abort(index: u16, subindex: u8, code: AbortCode) -> (MailboxType, Vec<u8>) {
    coe_message(&Sdo::Abort { index, subindex, code })
}

fn coe_message(sdo: &Sdo<'_>) -> (MailboxType, Vec<u8>) {
    let mut out = vec![0u8; coe::HEADER_LEN + coe::SDO_HEADER_LEN + MASTER_MAILBOX];
    let _ = CoeHeader::new(sdo.service()).emit(&mut out);
    let n = sdo.emit(&mut out[coe::HEADER_LEN..]).unwrap_or(0);
    out.truncate(coe::HEADER_LEN + n);
    (MailboxType::COE, out)
}

/// A running gateway (stopped when dropped).
pub struct Gateway {
    stop: Arc<AtomicBool>,
    stats: Arc<GatewayStats>,
    local: SocketAddr,
    thread: Option<std::thread::JoinHandle<()>>,
}

impl std::fmt::Debug for Gateway {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("Gateway").field("local", &self.local).finish()
    }
}

impl Gateway {
    pub(crate) fn start(o: GatewayOptions, jobs: SyncSender<Job>) -> std::io::Result<Gateway> {
        let socket = UdpSocket::bind(o.bind)?;
        socket.set_read_timeout(Some(Duration::from_millis(200)))?;
        let local = socket.local_addr()?;
        let stop = Arc::new(AtomicBool::new(false));
        let stats = Arc::new(GatewayStats::default());
        let (stop2, stats2) = (Arc::clone(&stop), Arc::clone(&stats));
        let thread = std::thread::Builder::new().name(String::from("ferrocat-gateway")).spawn(move || {
            crate::server::ordinary_thread();
            let mut g = Serving {
                o,
                jobs,
                stats: stats2,
                facts: None,
                master: MasterCoe::default(),
                buckets: HashMap::new(),
                warned: Vec::new(),
            };
            g.run(&socket, &stop2);
        })?;
        tracing::info!("mailbox gateway on udp {local}");
        Ok(Gateway { stop, stats, local, thread: Some(thread) })
    }

    /// Where it listens.
    pub fn local_addr(&self) -> SocketAddr {
        self.local
    }

    /// Its counts.
    pub fn stats(&self) -> &GatewayStats {
        &self.stats
    }
}

impl Drop for Gateway {
    fn drop(&mut self) {
        self.stop.store(true, Ordering::Relaxed);
        if let Some(t) = self.thread.take() {
            let _ = t.join();
        }
    }
}

/// A sender's allowance: tokens, and when they were last topped up.
struct Bucket {
    tokens: f64,
    at: Instant,
}

/// A segmented upload under way: the data, what was sent, the next toggle.
struct Transfer {
    data: Vec<u8>,
    sent: usize,
    toggle: bool,
}

struct Serving {
    o: GatewayOptions,
    jobs: SyncSender<Job>,
    stats: Arc<GatewayStats>,
    facts: Option<(Instant, Arc<Facts>)>,
    master: MasterCoe,
    buckets: HashMap<IpAddr, Bucket>,
    /// Senders told of their lenient requests.
    warned: Vec<IpAddr>,
}

impl Serving {
    fn run(&mut self, socket: &UdpSocket, stop: &AtomicBool) {
        let mut buf = vec![0u8; MAX_DATAGRAM + 1];
        while !stop.load(Ordering::Relaxed) {
            let Ok((n, from)) = socket.recv_from(&mut buf) else { continue };
            self.stats.received.fetch_add(1, Ordering::Relaxed);
            if !self.allowed(from.ip()) {
                self.stats.refused.fetch_add(1, Ordering::Relaxed);
                continue;
            }
            let request = match parse(&buf[..n.min(MAX_DATAGRAM + 1)]) {
                Ok(r) => r,
                Err(e) => {
                    self.stats.malformed.fetch_add(1, Ordering::Relaxed);
                    tracing::debug!("mailbox gateway: dropped a datagram from {from}: {e}");
                    continue;
                }
            };
            let h = request.header;
            if request.zero_type {
                self.lenient(from, "EtherCAT header type 0 read as 5 (mailbox)");
            }
            let replies = if self.within_rate(from.ip()) {
                self.answer(&request, from)
            } else {
                self.stats.rate_limited.fetch_add(1, Ordering::Relaxed);
                vec![mailbox_error(MailboxErrorCode::NO_MORE_MEMORY)]
            };
            for (t, payload) in replies {
                if socket.send_to(&frame(h.address, t, h.counter, &payload), from).is_ok() {
                    self.stats.replies.fetch_add(1, Ordering::Relaxed);
                }
            }
        }
    }

    /// Counts a request taken leniently, and says so once per sender.
    fn lenient(&mut self, from: SocketAddr, what: &str) {
        if self.stats.lenient.fetch_add(1, Ordering::Relaxed) == 0 || !self.warned.contains(&from.ip()) {
            if self.warned.len() < 1024 {
                self.warned.push(from.ip());
            }
            tracing::warn!("mailbox gateway: {from}: {what} (pyetg1510 on Linux sends so)");
        }
    }

    fn allowed(&self, ip: IpAddr) -> bool {
        ip.is_loopback() || self.o.allow.contains(&ip)
    }

    fn within_rate(&mut self, ip: IpAddr) -> bool {
        let now = Instant::now();
        if self.buckets.len() > 1024 {
            self.buckets.retain(|_, b| now.duration_since(b.at) < Duration::from_secs(10));
        }
        let (rate, burst) = (f64::from(self.o.rate_per_s), f64::from(self.o.burst.max(1)));
        let b = self.buckets.entry(ip).or_insert(Bucket { tokens: burst, at: now });
        b.tokens = (b.tokens + now.duration_since(b.at).as_secs_f64() * rate).min(burst);
        b.at = now;
        if b.tokens >= 1.0 {
            b.tokens -= 1.0;
            true
        } else {
            false
        }
    }

    /// The loop's facts, asked again after [`FACTS_FOR`].
    fn facts(&mut self) -> Option<Arc<Facts>> {
        if let Some((at, f)) = &self.facts {
            if at.elapsed() < FACTS_FOR {
                return Some(Arc::clone(f));
            }
        }
        let f = Arc::new(ask_facts(&self.jobs)?);
        self.facts = Some((Instant::now(), Arc::clone(&f)));
        Some(f)
    }

    /// The replies to one request (several for SDO information's fragments).
    fn answer(&mut self, r: &GatewayRequest, from: SocketAddr) -> Vec<(MailboxType, Vec<u8>)> {
        let Some(facts) = self.facts() else { return vec![mailbox_error(MailboxErrorCode::NO_MORE_MEMORY)] };
        if r.header.address == 0 {
            if r.header.mailbox_type != MailboxType::COE {
                return vec![mailbox_error(MailboxErrorCode::UNSUPPORTED_PROTOCOL)];
            }
            let jobs = self.jobs.clone();
            let mut live = |position| live_registers(&jobs, position);
            let before = self.master.lenient;
            let replies = self.master.answer(&facts, &r.payload, from, &mut live);
            if self.master.lenient > before {
                self.lenient(from, "CoE service 0 read from the command that follows");
            }
            return replies;
        }
        let Some(s) = facts.slaves.iter().find(|s| s.station == r.header.address) else {
            return vec![mailbox_error(MailboxErrorCode::SYNTAX)];
        };
        self.forward(s.position, r)
    }

    /// A request to a slave: passed through the master's acyclic side, its reply back.
    fn forward(&mut self, position: u16, r: &GatewayRequest) -> Vec<(MailboxType, Vec<u8>)> {
        let t = r.header.mailbox_type;
        // An EoE fragment (frame type 0) or time stamp (1) has no reply.
        let reply = !(t == MailboxType::EOE && r.payload.first().is_some_and(|b| b & 0x0F <= 1));
        self.stats.forwarded.fetch_add(1, Ordering::Relaxed);
        let request = ferrocat_master::Request::Mailbox { position, mailbox_type: t, data: r.payload.clone(), reply };
        let mut out = Vec::new();
        let mut answer = ask(&self.jobs, request);
        loop {
            match answer {
                Some(Ok(Answer::Mailbox(payload))) => {
                    // SDO information, or an SoE reply (its header's incomplete bit 3), in
                    // fragments: each is a message of its own from the slave.
                    let more = (t == MailboxType::COE && info_fragments_follow(&payload))
                        || (t == MailboxType::SOE && payload.first().is_some_and(|b| b & 0x08 != 0));
                    if !payload.is_empty() {
                        out.push((t, payload));
                    }
                    if !more || out.len() > 4096 {
                        return out;
                    }
                    let next =
                        ferrocat_master::Request::Mailbox { position, mailbox_type: t, data: Vec::new(), reply: true };
                    answer = ask(&self.jobs, next);
                }
                Some(Ok(_)) => return out,
                Some(Err(e)) => {
                    out.push(error_reply(t, &r.payload, &e));
                    return out;
                }
                None => {
                    out.push(mailbox_error(MailboxErrorCode::NO_MORE_MEMORY));
                    return out;
                }
            }
        }
    }
}

/// The master's own dictionary at station address 0: CoE requests answered from the loop's
/// facts, segmented uploads remembered per sender. `live` reads a slave's registers for its
/// diagnosis object (the gateway asks the loop; [`Live::default`] leaves them 0).
#[derive(Default)]
pub struct MasterCoe {
    transfers: HashMap<SocketAddr, Transfer>,
    /// Requests whose CoE service was 0, read from what followed.
    pub lenient: u64,
}

impl MasterCoe {
    /// The replies to `payload` (a CoE message after its mailbox header) from `from`.
    pub fn answer(
        &mut self,
        facts: &Facts,
        payload: &[u8],
        from: SocketAddr,
        live: &mut dyn FnMut(u16) -> Live,
    ) -> Vec<(MailboxType, Vec<u8>)> {
        let Ok(h) = CoeHeader::parse(payload) else { return vec![mailbox_error(MailboxErrorCode::SIZE_TOO_SHORT)] };
        let body = &payload[coe::HEADER_LEN..];
        let service = match h.service {
            // CoE service 0 (reserved) is what pyetg1510 on Linux sends, its 4-bit field lost
            // as the EtherCAT header's type is: an SDO information opcode is below 8, an SDO
            // command's specifier in bits 5–7 makes it 0x20 or more.
            CoeService(0) => {
                self.lenient += 1;
                match body.first() {
                    Some(&b) if b & 0x7F < 0x08 => CoeService::SDO_INFORMATION,
                    _ => CoeService::SDO_REQUEST,
                }
            }
            s => s,
        };
        match service {
            CoeService::SDO_REQUEST => vec![self.sdo(facts, body, from, live)],
            CoeService::SDO_INFORMATION => master_info(facts, body),
            _ => vec![mailbox_error(MailboxErrorCode::SERVICE_NOT_SUPPORTED)],
        }
    }

    fn sdo(
        &mut self,
        facts: &Facts,
        body: &[u8],
        from: SocketAddr,
        live: &mut dyn FnMut(u16) -> Live,
    ) -> (MailboxType, Vec<u8>) {
        let Ok(sdo) = Sdo::parse(CoeService::SDO_REQUEST, body) else {
            return abort(0, 0, AbortCode::INVALID_COMMAND);
        };
        match sdo {
            Sdo::UploadRequest { index, subindex, complete_access, .. } => {
                let l = master_od::diagnosis_slave(facts, index).map(&mut *live).unwrap_or_default();
                let Some(object) = master_od::object(facts, index, &l) else {
                    return abort(index, subindex, AbortCode::NO_OBJECT);
                };
                let data = match object.upload(subindex, complete_access) {
                    Ok(d) => d,
                    Err(code) => return abort(index, subindex, code),
                };
                self.transfers.remove(&from);
                upload_response(index, subindex, complete_access, data, |rest| {
                    if self.transfers.len() >= TRANSFERS {
                        self.transfers.clear();
                    }
                    self.transfers.insert(from, rest);
                })
            }
            Sdo::UploadSegmentRequest { toggle, .. } => {
                let Some(t) = self.transfers.get_mut(&from) else { return abort(0, 0, AbortCode::INVALID_COMMAND) };
                if toggle != t.toggle {
                    self.transfers.remove(&from);
                    return abort(0, 0, AbortCode::TOGGLE_BIT);
                }
                let room = MASTER_MAILBOX - HEADER_LEN - coe::HEADER_LEN - 1;
                let end = (t.sent + room).min(t.data.len());
                let part = t.data[t.sent..end].to_vec();
                let last = end == t.data.len();
                t.sent = end;
                t.toggle = !t.toggle;
                let unused = if part.len() < 7 { 7 - part.len() as u8 } else { 0 };
                let mut segment = part;
                segment.resize(segment.len().max(7), 0);
                if last {
                    self.transfers.remove(&from);
                }
                coe_message(&Sdo::UploadSegmentResponse { toggle, last, unused, segment: &segment })
            }
            Sdo::DownloadExpeditedRequest { index, subindex, .. }
            | Sdo::DownloadNormalRequest { index, subindex, .. } => {
                let known = master_od::dictionary(facts).iter().any(|o| o.index == index);
                abort(index, subindex, if known { AbortCode::READ_ONLY } else { AbortCode::NO_OBJECT })
            }
            Sdo::Abort { .. } => {
                self.transfers.remove(&from);
                (MailboxType::COE, Vec::new())
            }
            _ => abort(0, 0, AbortCode::INVALID_COMMAND),
        }
    }
}

/// A slave's registers for its diagnosis object, read through the loop's acyclic side.
fn live_registers(jobs: &SyncSender<Job>, position: u16) -> Live {
    let (register, len) = master_od::LIVE;
    match ask(jobs, ferrocat_master::Request::RegisterRead { position, register, len }) {
        Some(Ok(Answer::Data(d))) => Live { registers: Some(d) },
        _ => Live::default(),
    }
}

/// An upload's first response: expedited up to 4 bytes, normal where it fits the mailbox,
/// else its first part with the rest handed to `keep` for the segments.
fn upload_response(
    index: u16,
    subindex: u8,
    complete_access: bool,
    data: Vec<u8>,
    keep: impl FnOnce(Transfer),
) -> (MailboxType, Vec<u8>) {
    if data.len() <= 4 && !data.is_empty() {
        let mut four = [0u8; 4];
        four[..data.len()].copy_from_slice(&data);
        let size = Some(data.len() as u8);
        return coe_message(&Sdo::UploadExpeditedResponse { index, subindex, complete_access, size, data: four });
    }
    let room = MASTER_MAILBOX - HEADER_LEN - coe::HEADER_LEN - coe::SDO_HEADER_LEN;
    let complete_size = data.len() as u32;
    let first = data.len().min(room);
    let response = coe_message(&Sdo::UploadNormalResponse {
        index,
        subindex,
        complete_access,
        complete_size,
        data: &data[..first],
    });
    if first < data.len() {
        keep(Transfer { data, sent: first, toggle: false });
    }
    response
}

/// SDO information from the master's dictionary: the reply, in fragments where it is longer
/// than the mailbox (each a datagram of its own).
fn master_info(facts: &Facts, body: &[u8]) -> Vec<(MailboxType, Vec<u8>)> {
    let error = |code: AbortCode| info_messages(0x07, &code.0.to_le_bytes());
    let (Some(&opcode), Some(rest)) = (body.first(), body.get(4..)) else {
        return error(AbortCode::INVALID_COMMAND);
    };
    let od = master_od::dictionary(facts);
    let u16_at = |k: usize| rest.get(k..k + 2).map(|b| u16::from_le_bytes([b[0], b[1]]));
    match opcode & 0x7F {
        0x01 => {
            // List type 0: the count per type; 1: all objects; others (PDO-mappable, backup,
            // settings): none here.
            let list_type = u16_at(0).unwrap_or(1);
            let mut out = list_type.to_le_bytes().to_vec();
            if list_type == 0 {
                for n in [od.len() as u16, 0, 0, 0, 0] {
                    out.extend_from_slice(&n.to_le_bytes());
                }
            } else if list_type == 1 {
                for o in &od {
                    out.extend_from_slice(&o.index.to_le_bytes());
                }
            }
            info_messages(0x02, &out)
        }
        0x03 => {
            let Some(index) = u16_at(0) else { return error(AbortCode::INVALID_COMMAND) };
            let Some(o) = od.iter().find(|o| o.index == index) else { return error(AbortCode::NO_OBJECT) };
            let mut out = index.to_le_bytes().to_vec();
            out.extend_from_slice(&o.data_type().to_le_bytes());
            out.push(o.max_subindex());
            out.push(o.object_code);
            out.extend_from_slice(o.name.as_bytes());
            info_messages(0x04, &out)
        }
        0x05 => {
            let (Some(index), Some(&subindex)) = (u16_at(0), rest.get(2)) else {
                return error(AbortCode::INVALID_COMMAND);
            };
            let Some(o) = od.iter().find(|o| o.index == index) else { return error(AbortCode::NO_OBJECT) };
            let Some(e) = o.entries.iter().find(|e| e.subindex == subindex) else {
                return error(AbortCode::NO_SUBINDEX);
            };
            let mut out = index.to_le_bytes().to_vec();
            // Value info 0: no unit, default, minimum or maximum follow.
            out.extend_from_slice(&[subindex, 0]);
            out.extend_from_slice(&e.data_type.to_le_bytes());
            out.extend_from_slice(&e.bit_length.to_le_bytes());
            out.extend_from_slice(&master_od::READ_ONLY.to_le_bytes());
            out.extend_from_slice(e.name.as_bytes());
            info_messages(0x06, &out)
        }
        _ => error(AbortCode::INVALID_COMMAND),
    }
}

/// SDO information's messages of `opcode` carrying `data`, in fragments that fit the mailbox.
fn info_messages(opcode: u8, data: &[u8]) -> Vec<(MailboxType, Vec<u8>)> {
    let room = MASTER_MAILBOX - HEADER_LEN - coe::HEADER_LEN - 4;
    let parts: Vec<&[u8]> = if data.is_empty() { vec![data] } else { data.chunks(room).collect() };
    let n = parts.len();
    parts
        .into_iter()
        .enumerate()
        .map(|(k, part)| {
            let left = (n - 1 - k) as u16;
            let mut m = vec![0u8; coe::HEADER_LEN];
            let _ = CoeHeader::new(CoeService::SDO_INFORMATION).emit(&mut m);
            let h = InfoHeader { opcode: InfoOpcode(opcode), incomplete: left > 0, reserved: 0, fragments_left: left };
            m.extend_from_slice(&h.to_bytes());
            m.extend_from_slice(part);
            (MailboxType::COE, m)
        })
        .collect()
}

/// Whether a slave's CoE message is SDO information with fragments to follow.
fn info_fragments_follow(payload: &[u8]) -> bool {
    CoeHeader::parse(payload).is_ok_and(|h| h.service == CoeService::SDO_INFORMATION)
        && payload.get(coe::HEADER_LEN).is_some_and(|op| op & 0x80 != 0)
}

/// What the client is told when its request to a slave failed: a slave's own mailbox error
/// as it sent it; for an SDO that got no reply, the SDO abort "protocol timed out"; else the
/// nearest mailbox error (docs/service.md, "Mailbox gateway").
fn error_reply(t: MailboxType, request: &[u8], e: &MasterError) -> (MailboxType, Vec<u8>) {
    let sdo_of = || {
        CoeHeader::parse(request).ok().filter(|h| h.service == CoeService::SDO_REQUEST).and_then(|_| {
            let b = request.get(coe::HEADER_LEN..)?;
            Some((u16::from_le_bytes([*b.get(1)?, *b.get(2)?]), *b.get(3)?))
        })
    };
    match e {
        MasterError::Slave { error: SlaveError::MailboxError(code), .. } => mailbox_error(*code),
        MasterError::Slave { error: SlaveError::Unsupported(_) | SlaveError::NoMailbox, .. } => {
            mailbox_error(MailboxErrorCode::UNSUPPORTED_PROTOCOL)
        }
        MasterError::Slave { error: SlaveError::RequestTooLong { .. }, .. } => {
            mailbox_error(MailboxErrorCode::INVALID_SIZE)
        }
        MasterError::Slave { error: SlaveError::NoReply, .. } if t == MailboxType::COE && sdo_of().is_some() => {
            let (index, subindex) = sdo_of().unwrap_or_default();
            abort(index, subindex, AbortCode::TIMEOUT)
        }
        _ => mailbox_error(MailboxErrorCode::NO_MORE_MEMORY),
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_request_as_igh_s_gateway_carried_it_parses() {
        // An SDO upload of 0x02F9:80 to station 1001, from the etherlab-dev list (2021-04):
        // `10 50 0a 00 e9 03 00 23 00 20 41 80 f9 02 00 00 00 00`.
        let d = [0x10, 0x50, 0x0a, 0x00, 0xe9, 0x03, 0x00, 0x23, 0x00, 0x20, 0x41, 0x80, 0xf9, 0x02, 0, 0, 0, 0];
        let r = parse(&d).unwrap();
        assert_eq!(r.header.address, 1001);
        assert_eq!(r.header.mailbox_type, MailboxType::COE);
        assert_eq!(r.header.counter, 2);
        assert_eq!(r.payload.len(), 10);
        let reply = frame(1001, MailboxType::COE, 1, &[0; 250]);
        assert_eq!(&reply[..2], &[0x00, 0x51], "the EtherCAT header of a 256-byte mailbox message, as IgH's");
    }

    #[test]
    fn malformed_datagrams_are_named() {
        assert_eq!(parse(&[0x10, 0x50]), Err(Malformed::Short(2)));
        let mut d = vec![0x10, 0x10, 0x0a, 0x00, 0xe9, 0x03, 0x00, 0x23];
        d.resize(18, 0);
        assert_eq!(parse(&d), Err(Malformed::NotMailbox(1)));
        d[1] = 0x50;
        d.push(0);
        assert_eq!(parse(&d), Err(Malformed::Length { header: 16, actual: 17 }));
        let mut long = vec![0x08, 0x50, 0xff, 0x00, 0xe9, 0x03, 0x00, 0x23];
        long.resize(10, 0);
        assert_eq!(parse(&long), Err(Malformed::MailboxLength(255)));
    }

    #[test]
    fn info_longer_than_the_mailbox_comes_in_fragments() {
        let data = vec![7u8; 3000];
        let parts = info_messages(0x02, &data);
        assert_eq!(parts.len(), 3);
        assert_eq!(parts[0].1[2], 0x82, "incomplete");
        assert_eq!(u16::from_le_bytes([parts[0].1[4], parts[0].1[5]]), 2);
        assert_eq!(parts[2].1[2], 0x02);
        let total: usize = parts.iter().map(|p| p.1.len() - 6).sum();
        assert_eq!(total, 3000);
        assert!(parts.iter().all(|p| p.1.len() + HEADER_LEN <= MASTER_MAILBOX));
    }
}
