//! The master's side of the control socket.
//!
//! Threads of their own accept the clients and read their requests; each request reaches the
//! cyclic loop through a bounded queue that the loop empties without waiting
//! ([`Server::serve`], once a cycle), and its reply goes back through a channel of one place
//! that the loop fills without waiting. So a client that hangs, floods or dies costs the loop
//! a `try_recv` and nothing more; the work it asks for is the master's acyclic side's
//! ([`Acyclic::serve_requests`](ferrocat_master::part::Acyclic::serve_requests)), in the cycle's spare time.
use std::collections::HashMap;
use std::io::{BufRead, BufReader, Read, Write};
use std::os::unix::fs::PermissionsExt;
use std::os::unix::net::{UnixListener, UnixStream};
use std::path::PathBuf;
use std::sync::atomic::{AtomicBool, AtomicUsize, Ordering};
use std::sync::mpsc::{self, Receiver, SyncSender, TryRecvError, TrySendError};
use std::sync::Arc;
use std::time::Duration;

use ferrocat_master::io::Io;
use ferrocat_master::{AlState, Answer, Health, Master, MasterError, RequestError, RequestId, SlaveError};

use crate::gateway::{Gateway, GatewayOptions};
use crate::master_od::{Facts, SlaveFacts};
use crate::protocol::{
    self, ErrorKind, ErrorReply, Event, Events, Hello, PdoEntry, Pdos, Reply, Request, SlaveInfo, Stats, MAX_LINE,
};

/// Requests on their way to the loop at most (beyond, a client is told the master is busy).
const QUEUE: usize = 64;
/// Clients connected at once at most.
const MAX_CLIENTS: usize = 16;
/// Requests the loop takes from the queue per call.
const TAKEN_PER_CALL: usize = 16;
/// How long a client's thread waits for the loop's reply: longer than any request's own
/// limit (the state timeout, 10 s by default).
const REPLY_WAIT: Duration = Duration::from_secs(25);
/// The same for a file by FoE, which makes progress a packet a cycle (the master ends one
/// that makes none for its mailbox timeout).
const FILE_WAIT: Duration = Duration::from_secs(3600);
/// How long a write to a client may block its thread (a client that does not read).
const WRITE_TIMEOUT: Duration = Duration::from_secs(5);
/// Events kept for `events` requests.
const EVENTS_KEPT: usize = 1024;

/// How the control socket is made.
#[derive(Debug, Clone)]
pub struct ServerOptions {
    /// The socket's path (its directory is made, mode 0755, where missing).
    pub path: PathBuf,
    /// The socket file's mode. Default 0o660: the owner and the group.
    pub mode: u32,
    /// The group that owns the socket file (`None`: the process's).
    pub group: Option<String>,
    /// Take register writes. Default off: a register write can take a slave off the bus.
    pub register_writes: bool,
    /// What the master says to each client first.
    pub hello: Hello,
}

/// What goes back to a client's thread: a reply made by the loop, or a request's answer as
/// the master gave it (the thread makes it a reply: a file's hex text is not the loop's work).
pub(crate) enum Back {
    Ready(Reply),
    Answer(ferrocat_master::Result<Answer>),
    Facts(Box<Facts>),
}

/// A request as it reaches the loop: the protocol's, or the master's where the client's
/// thread made it already (a file by FoE, its parts gathered).
pub(crate) enum Asked {
    Protocol(Request),
    Ready(ferrocat_master::Request),
    /// What the master's object dictionary is built from (the mailbox gateway's, the
    /// `master_od` request's).
    Facts,
}

pub(crate) struct Job {
    id: u64,
    asked: Asked,
    reply: SyncSender<Back>,
}

/// A running master's control socket (removed when dropped).
pub struct Server {
    jobs: Receiver<Job>,
    pending: HashMap<RequestId, SyncSender<Back>>,
    path: PathBuf,
    register_writes: bool,
    stop: Arc<AtomicBool>,
    /// The last events, and the number the next will have.
    events: std::collections::VecDeque<Event>,
    next_event: u64,
    /// A reload asked for and not yet done: the reply's number and channel.
    reload: Option<(u64, SyncSender<Back>)>,
    /// The queue's sending side, for the mailbox gateway.
    tx: SyncSender<Job>,
    gateway: Option<Gateway>,
    /// Per slave: times it stopped answering, times it left OP (the dictionary's counters).
    lost: HashMap<u16, u32>,
    left_op: HashMap<u16, u32>,
    started: std::time::Instant,
}

impl std::fmt::Debug for Server {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("Server").field("path", &self.path).field("pending", &self.pending.len()).finish()
    }
}

impl Server {
    /// Makes the socket and starts accepting clients. A file already at the path is removed
    /// first: the caller holds the target's lock ([`crate::MasterLock`]), so no master serves
    /// it.
    pub fn start(o: ServerOptions) -> std::io::Result<Server> {
        if let Some(dir) = o.path.parent() {
            std::fs::create_dir_all(dir)?;
        }
        match std::fs::remove_file(&o.path) {
            Ok(()) => {}
            Err(e) if e.kind() == std::io::ErrorKind::NotFound => {}
            Err(e) => return Err(e),
        }
        let listener = UnixListener::bind(&o.path)?;
        std::fs::set_permissions(&o.path, std::fs::Permissions::from_mode(o.mode))?;
        if let Some(group) = &o.group {
            chown_group(&o.path, group)?;
        }
        let (tx, jobs) = mpsc::sync_channel(QUEUE);
        let gateway_tx = tx.clone();
        let stop = Arc::new(AtomicBool::new(false));
        let clients = Arc::new(AtomicUsize::new(0));
        let hello = o.hello.clone();
        let stop_accept = Arc::clone(&stop);
        std::thread::Builder::new().name(String::from("ferrocat-control")).spawn(move || {
            ordinary_thread();
            for stream in listener.incoming() {
                if stop_accept.load(Ordering::Relaxed) {
                    break;
                }
                let Ok(stream) = stream else { continue };
                if clients.fetch_add(1, Ordering::SeqCst) >= MAX_CLIENTS {
                    clients.fetch_sub(1, Ordering::SeqCst);
                    let e = ErrorReply::new(ErrorKind::Busy, format!("{MAX_CLIENTS} clients are connected already"));
                    let _ = write_line(&stream, &Reply { id: 0, ok: None, error: Some(e) });
                    continue;
                }
                let (tx, hello, clients) = (tx.clone(), hello.clone(), Arc::clone(&clients));
                let spawned = std::thread::Builder::new().name(String::from("ferrocat-client")).spawn(move || {
                    ordinary_thread();
                    client(stream, &hello, &tx);
                    clients.fetch_sub(1, Ordering::SeqCst);
                });
                if spawned.is_err() {
                    tracing::warn!("control socket: no thread for a client");
                }
            }
        })?;
        tracing::info!("control socket {}", o.path.display());
        Ok(Server {
            jobs,
            pending: HashMap::new(),
            path: o.path,
            register_writes: o.register_writes,
            stop,
            events: std::collections::VecDeque::with_capacity(EVENTS_KEPT),
            next_event: 0,
            reload: None,
            tx: gateway_tx,
            gateway: None,
            lost: HashMap::new(),
            left_op: HashMap::new(),
            started: std::time::Instant::now(),
        })
    }

    /// Starts the mailbox gateway (ETG.8200) beside the socket: its requests take the same
    /// queue as the socket's.
    pub fn start_gateway(&mut self, o: GatewayOptions) -> std::io::Result<std::net::SocketAddr> {
        let g = Gateway::start(o, self.tx.clone())?;
        let at = g.local_addr();
        self.gateway = Some(g);
        Ok(at)
    }

    /// The mailbox gateway's counts, if it runs.
    pub fn gateway_stats(&self) -> Option<serde_json::Value> {
        self.gateway.as_ref().map(|g| g.stats().to_json())
    }

    /// The socket's path.
    pub fn path(&self) -> &std::path::Path {
        &self.path
    }

    /// Whether a client asked for a reload that the application has not done yet
    /// ([`Server::reloaded`] answers it).
    pub fn reload_asked(&self) -> bool {
        self.reload.is_some()
    }

    /// Answers the reload asked for: what it did, or why it did nothing.
    pub fn reloaded(&mut self, result: &Result<String, String>) {
        if let Some((id, reply)) = self.reload.take() {
            let r = match result {
                Ok(said) => Reply { id, ok: Some(serde_json::json!({ "said": said })), error: None },
                Err(e) => Reply { id, ok: None, error: Some(ErrorReply::new(ErrorKind::Refused, e.clone())) },
            };
            let _ = reply.try_send(Back::Ready(r));
        }
    }

    /// Keeps `events` (taken from the master at `at_s`, seconds since the loop started) for
    /// `events` requests: the last 1 024.
    pub fn note_events(&mut self, events: &[ferrocat_master::MasterEvent], at_s: f64) {
        use ferrocat_master::MasterEvent as E;
        for e in events {
            let (kind, position) = match e {
                E::LeftOp { position, .. } => {
                    *self.left_op.entry(*position).or_default() += 1;
                    ("left_op", Some(*position))
                }
                E::Lost { position, .. } => {
                    *self.lost.entry(*position).or_default() += 1;
                    ("lost", Some(*position))
                }
                E::Recovered { position, .. } => ("recovered", Some(*position)),
                E::Emergency { position, .. } => ("emergency", Some(*position)),
                E::Soe { position, .. } => ("soe", Some(*position)),
                E::SyncError { position, .. } => ("sync_error", Some(*position)),
                E::InputsInvalid { position, .. } => ("inputs_invalid", Some(*position)),
                E::InputsStale { position, .. } => ("inputs_stale", Some(*position)),
                E::ErrorCounters { position, .. } => ("error_counters", Some(*position)),
                E::InitCommandSkipped { position, .. } => ("init_command_skipped", Some(*position)),
                E::SoeInitCommandSkipped { position, .. } => ("soe_init_command_skipped", Some(*position)),
                E::InitCommandsNotSent { position, .. } => ("init_commands_not_sent", Some(*position)),
                E::Ring { .. } => ("ring", None),
            };
            if self.events.len() == EVENTS_KEPT {
                self.events.pop_front();
            }
            let seq = self.next_event;
            self.next_event += 1;
            self.events.push_back(Event { seq, kind: kind.to_string(), position, text: e.to_string(), at_s });
        }
    }

    /// Once a cycle, in its spare time: takes the requests that came (without waiting), serves
    /// them before `deadline_ns` (the master's clock; [`Acyclic::serve_requests`](ferrocat_master::part::Acyclic::serve_requests)) and hands
    /// the answers back. `extra` adds to a statistics reply what the application knows (the
    /// clock sync's lock, diagnosis), called only when one is asked for. Returns the datagrams sent;
    /// only the link's errors are errors.
    pub fn serve<I: Io>(
        &mut self,
        m: &mut Master<I>,
        deadline_ns: u64,
        extra: &dyn Fn(&mut Master<I>) -> serde_json::Value,
    ) -> ferrocat_master::Result<u32> {
        for _ in 0..TAKEN_PER_CALL {
            match self.jobs.try_recv() {
                Ok(job) => self.take(m, job, extra),
                Err(TryRecvError::Empty | TryRecvError::Disconnected) => break,
            }
        }
        let sent = if self.pending.is_empty() { 0 } else { m.acyclic().serve_requests(deadline_ns)? };
        for (id, answer) in m.acyclic().take_answers() {
            if let Some(reply) = self.pending.remove(&id) {
                // A channel of one place, this reply's own: never full, and a client gone
                // makes it fail, which nobody needs to hear.
                let _ = reply.try_send(Back::Answer(answer));
            }
        }
        Ok(sent)
    }

    fn take<I: Io>(&mut self, m: &mut Master<I>, job: Job, extra: &dyn Fn(&mut Master<I>) -> serde_json::Value) {
        let reply = |r: Result<serde_json::Value, ErrorReply>| match r {
            Ok(v) => Reply { id: job.id, ok: Some(v), error: None },
            Err(e) => Reply { id: job.id, ok: None, error: Some(e) },
        };
        let bad = |message: String| Err(ErrorReply::new(ErrorKind::BadRequest, message));
        let request = match job.asked {
            Asked::Ready(ready) => ready,
            Asked::Facts => {
                let _ = job.reply.try_send(Back::Facts(Box::new(self.facts(m))));
                return;
            }
            Asked::Protocol(Request::MasterOd { from }) => {
                // As many objects as fit three quarters of a reply's line; `next` the rest's.
                let od = crate::master_od::dictionary(&self.facts(m));
                let (mut objects, mut bytes, mut next) = (Vec::new(), 0, None);
                for o in od.into_iter().filter(|o| o.index >= from) {
                    bytes += serde_json::to_vec(&o).map_or(0, |v| v.len() + 1);
                    if bytes > MAX_LINE * 3 / 4 && !objects.is_empty() {
                        next = Some(o.index);
                        break;
                    }
                    objects.push(o);
                }
                let r = serde_json::json!({ "objects": objects, "next": next });
                let _ = job.reply.try_send(Back::Ready(reply(Ok(r))));
                return;
            }
            Asked::Protocol(Request::Slaves) => {
                let _ = job.reply.try_send(Back::Ready(reply(Ok(serde_json::json!({ "slaves": slave_list(m) })))));
                return;
            }
            Asked::Protocol(Request::Stats) => {
                let _ = job.reply.try_send(Back::Ready(reply(Ok({
                    let mut extra = extra(m);
                    if let (Some(g), Some(o)) = (self.gateway_stats(), extra.as_object_mut()) {
                        o.insert(String::from("gateway"), g);
                    }
                    stats(m, extra)
                }))));
                return;
            }
            Asked::Protocol(Request::Reload) => {
                if self.reload.is_some() {
                    let _ = job
                        .reply
                        .try_send(Back::Ready(reply(Err(ErrorReply::new(ErrorKind::Busy, "a reload is under way")))));
                } else {
                    self.reload = Some((job.id, job.reply));
                }
                return;
            }
            Asked::Protocol(Request::Events { since }) => {
                // As many as fit a reply's line (three quarters of it), oldest first; `next`
                // is where the following ask starts.
                let first = self.events.front().map_or(self.next_event, |e| e.seq);
                let (mut events, mut bytes) = (Vec::new(), 0);
                for e in self.events.iter().filter(|e| e.seq >= since) {
                    bytes += serde_json::to_vec(e).map_or(0, |v| v.len() + 1);
                    if bytes > MAX_LINE * 3 / 4 {
                        break;
                    }
                    events.push(e.clone());
                }
                let next = events.last().map_or(self.next_event, |e| e.seq + 1);
                let batch = Events { next, missed: first.saturating_sub(since), events };
                let _ = job.reply.try_send(Back::Ready(reply(Ok(serde_json::to_value(batch).unwrap_or_default()))));
                return;
            }
            Asked::Protocol(Request::SiiRead { position, offset }) => {
                let r = match m.slaves().at(position) {
                    Ok(s) => {
                        let image = s.sii().to_image();
                        let from = offset.min(image.len());
                        let to = (from + protocol::SII_PART).min(image.len());
                        Ok(serde_json::json!({
                            "total": image.len(), "offset": from, "data": protocol::hex(&image[from..to]),
                        }))
                    }
                    Err(e) => Err(error_of(&e)),
                };
                let _ = job.reply.try_send(Back::Ready(reply(r)));
                return;
            }
            Asked::Protocol(Request::Pdos { position }) => {
                let r = match m.slaves().at(position) {
                    Ok(s) => Ok(serde_json::to_value(pdos_of(s)).unwrap_or_default()),
                    Err(e) => Err(error_of(&e)),
                };
                let _ = job.reply.try_send(Back::Ready(reply(r)));
                return;
            }
            Asked::Protocol(Request::RegisterWrite { .. }) if !self.register_writes => {
                let e = ErrorReply::new(
                    ErrorKind::Refused,
                    "register writes are off: start the master with --allow-register-writes",
                );
                let _ = job.reply.try_send(Back::Ready(reply(Err(e))));
                return;
            }
            Asked::Protocol(r) => match master_request(r) {
                Ok(r) => r,
                Err(message) => {
                    let _ = job.reply.try_send(Back::Ready(reply(bad(message))));
                    return;
                }
            },
        };
        let id = m.acyclic().submit(request);
        self.pending.insert(id, job.reply);
    }
}

impl Drop for Server {
    fn drop(&mut self) {
        self.stop.store(true, Ordering::Relaxed);
        // Wakes the accepting thread, which then ends.
        let _ = UnixStream::connect(&self.path);
        let _ = std::fs::remove_file(&self.path);
    }
}

/// The process data `slave` maps, as the protocol gives it.
pub fn pdos_of(slave: &ferrocat_master::Slave) -> Pdos {
    let entries = |list: &[ferrocat_master::Mapped]| {
        list.iter()
            .map(|e| PdoEntry {
                index: e.index,
                subindex: e.subindex,
                bits: e.bits,
                name: e.name.clone(),
                image_bit: e.image_bit,
            })
            .collect()
    };
    let map = slave.mapping();
    Pdos { position: slave.position(), outputs: entries(&map.outputs), inputs: entries(&map.inputs) }
}

/// A protocol request as the master's (the slave list and statistics are the loop's own: an
/// error), or what is wrong with its values.
pub fn master_request(r: Request) -> Result<ferrocat_master::Request, String> {
    use ferrocat_master::Request as M;
    Ok(match r {
        Request::SdoRead { position, index, subindex, complete_access } => {
            M::SdoRead { position, index, subindex, complete_access }
        }
        Request::SdoWrite { position, index, subindex, complete_access, data } => {
            M::SdoWrite { position, index, subindex, complete_access, data: protocol::unhex(&data)? }
        }
        Request::OdList { position } => M::OdList { position },
        Request::ObjectInfo { position, index } => M::ObjectInfo { position, index },
        Request::EntryInfo { position, index, subindex } => M::EntryInfo { position, index, subindex },
        Request::RegisterRead { position, register, len } => M::RegisterRead { position, register, len },
        Request::RegisterWrite { position, register, data } => {
            M::RegisterWrite { position, register, data: protocol::unhex(&data)? }
        }
        Request::State { position, state } => M::State { position, state: state_named(&state)? },
        Request::FoeRead { position, file, password, max_bytes, .. } => {
            M::FoeRead { position, file, password, max_bytes: max_bytes.min(protocol::MAX_FOE_FILE) }
        }
        Request::FoeWrite { position, file, password, data, .. } => {
            M::FoeWrite { position, file, password, data: protocol::unhex(&data)? }
        }
        Request::SoeRead { position, drive, idn, elements } => M::SoeRead {
            position,
            drive,
            idn: ferrocat_master::wire::soe::Idn(idn),
            elements: ferrocat_master::wire::soe::Elements(elements),
        },
        Request::SoeWrite { position, drive, idn, elements, data } => M::SoeWrite {
            position,
            drive,
            idn: ferrocat_master::wire::soe::Idn(idn),
            elements: ferrocat_master::wire::soe::Elements(elements),
            data: protocol::unhex(&data)?,
        },
        Request::Slaves
        | Request::Stats
        | Request::Events { .. }
        | Request::Pdos { .. }
        | Request::SiiRead { .. }
        | Request::MasterOd { .. }
        | Request::Reload => return Err(String::from("answered by the loop")),
    })
}

/// INIT, PREOP, SAFEOP or OP, any case.
fn state_named(name: &str) -> Result<AlState, String> {
    match name.to_ascii_uppercase().as_str() {
        "INIT" => Ok(AlState::Init),
        "PREOP" | "PRE-OP" => Ok(AlState::PreOp),
        "SAFEOP" | "SAFE-OP" => Ok(AlState::SafeOp),
        "OP" => Ok(AlState::Op),
        _ => Err(format!("state '{name}': give INIT, PREOP, SAFEOP or OP")),
    }
}

fn slave_list<I: Io>(m: &Master<I>) -> Vec<SlaveInfo> {
    m.slaves()
        .iter()
        .map(|s| {
            let id = s.identity();
            SlaveInfo {
                position: s.position(),
                station: s.station(),
                alias: s.alias(),
                name: s.name().to_string(),
                vendor_id: id.vendor_id,
                product_code: id.product_code,
                revision: id.revision,
                serial: id.serial,
                state: s.status().state().name().to_string(),
                health: String::from(match s.status().health() {
                    Health::Operational => "operational",
                    Health::Lost => "lost",
                    Health::Recovering => "recovering",
                }),
                coe: s.mailbox().is_some_and(|mb| mb.has_coe()),
            }
        })
        .collect()
}

fn stats<I: Io>(m: &mut Master<I>, extra: serde_json::Value) -> serde_json::Value {
    let c = m.diagnosis().cycle_stats();
    let a = m.acyclic().acyclic_stats();
    let s = Stats {
        cycles: c.cycles,
        wkc_errors: c.wkc_errors,
        expected_wkc: m.image().expected_wkc(),
        last_wkc: c.last_wkc,
        last_round_trip_ns: c.last_round_trip_ns,
        requests_answered: a.answered,
        requests_failed: a.failed,
        extra,
    };
    serde_json::to_value(s).unwrap_or_default()
}

/// The master's answer as the protocol's reply.
fn reply_of(id: u64, answer: ferrocat_master::Result<Answer>) -> Reply {
    let ok = match answer {
        Ok(Answer::Data(d)) => serde_json::json!({ "data": protocol::hex(&d) }),
        Ok(Answer::Written) => serde_json::json!({}),
        Ok(Answer::List(l)) => serde_json::json!({ "indices": l }),
        Ok(Answer::Object(o)) => serde_json::json!({
            "index": o.index, "data_type": o.data_type, "max_subindex": o.max_subindex,
            "object_code": o.object_code, "name": o.name,
        }),
        Ok(Answer::Entry(e)) => serde_json::json!({
            "subindex": e.subindex, "data_type": e.data_type, "bit_length": e.bit_length,
            "access": e.access, "name": e.name,
        }),
        Ok(Answer::State(s)) => serde_json::json!({ "state": s.name() }),
        Ok(Answer::Mailbox(d)) => serde_json::json!({ "data": protocol::hex(&d) }),
        Err(e) => return Reply { id, ok: None, error: Some(error_of(&e)) },
    };
    Reply { id, ok: Some(ok), error: None }
}

fn error_of(e: &MasterError) -> ErrorReply {
    let kind = match e {
        MasterError::Abort { .. } => ErrorKind::Abort,
        MasterError::NoSuchSlave { .. } => ErrorKind::NoSuchSlave,
        MasterError::State { .. } => ErrorKind::State,
        MasterError::Timeout { .. } => ErrorKind::Timeout,
        MasterError::Slave { error: SlaveError::NoReply | SlaveError::MailboxFull, .. } => ErrorKind::Timeout,
        MasterError::Request(RequestError::QueueFull { .. }) => ErrorKind::Busy,
        MasterError::Request(RequestError::TimedOut { .. }) => ErrorKind::Timeout,
        MasterError::Request(_) => ErrorKind::BadRequest,
        MasterError::Io(_) => ErrorKind::Master,
        _ => ErrorKind::Slave,
    };
    let abort_code = match e {
        MasterError::Abort { code, .. } => Some(code.0),
        _ => None,
    };
    ErrorReply { kind, message: e.to_string(), abort_code }
}

/// Makes the calling thread an ordinary one: a thread inherits the real-time policy and the CPU
/// of the thread that made it, and the socket's threads, made by a master already on SCHED_FIFO
/// and its own CPU, would compete with its cyclic loop at the loop's priority.
pub(crate) fn ordinary_thread() {
    // SAFETY: plain system calls on the calling thread (0), with values they take.
    unsafe {
        let param = libc::sched_param { sched_priority: 0 };
        libc::sched_setscheduler(0, libc::SCHED_OTHER, &param);
        let mut any: libc::cpu_set_t = std::mem::zeroed();
        let cpus = libc::sysconf(libc::_SC_NPROCESSORS_CONF).clamp(1, 1024) as usize;
        for cpu in 0..cpus {
            libc::CPU_SET(cpu, &mut any);
        }
        libc::sched_setaffinity(0, std::mem::size_of::<libc::cpu_set_t>(), &any);
    }
}

/// One client's connection: the hello, then a request and its reply at a time.
fn client(stream: UnixStream, hello: &Hello, jobs: &SyncSender<Job>) {
    let _ = stream.set_write_timeout(Some(WRITE_TIMEOUT));
    if write_line(&stream, &serde_json::json!({ "hello": hello })).is_err() {
        return;
    }
    let Ok(read) = stream.try_clone() else { return };
    let mut reader = BufReader::new(read);
    let mut files = Files::default();
    loop {
        let mut line = Vec::new();
        match (&mut reader).take(MAX_LINE as u64 + 1).read_until(b'\n', &mut line) {
            Ok(0) | Err(_) => return,
            Ok(_) => {}
        }
        if line.last() != Some(&b'\n') {
            let e = ErrorReply::new(ErrorKind::BadRequest, format!("a line longer than {MAX_LINE} bytes: closed"));
            let _ = write_line(&stream, &Reply { id: 0, ok: None, error: Some(e) });
            return;
        }
        let reply = match protocol::parse_request(&line) {
            Err(reply) => reply,
            Ok(env) => files.handle(env, jobs),
        };
        if write_line(&stream, &reply).is_err() {
            return;
        }
    }
}

/// A connection's files by FoE: the parts of one being written, and the one read last, whose
/// parts are handed out from there. They are the client's thread's, never the loop's.
#[derive(Default)]
struct Files {
    writing: Option<(u16, String, u32, Vec<u8>)>,
    read: Option<(u16, String, Vec<u8>)>,
}

impl Files {
    /// `env`'s reply: a file's part kept or handed out here, anything else from the loop.
    fn handle(&mut self, env: protocol::Envelope, jobs: &SyncSender<Job>) -> Reply {
        let id = env.id;
        let ok = |v: serde_json::Value| Reply { id, ok: Some(v), error: None };
        let bad =
            |message: String| Reply { id, ok: None, error: Some(ErrorReply::new(ErrorKind::BadRequest, message)) };
        match env.request {
            Request::FoeWrite { position, file, password, data, more } => {
                let part = match protocol::unhex(&data) {
                    Ok(p) => p,
                    Err(e) => return bad(format!("data {e}")),
                };
                let same = self.writing.as_ref().is_some_and(|w| (w.0, &w.1, w.2) == (position, &file, password));
                if !same {
                    self.writing = Some((position, file.clone(), password, Vec::new()));
                }
                let Some(w) = self.writing.as_mut() else { return bad(String::from("no file")) };
                if w.3.len() + part.len() > protocol::MAX_FOE_FILE {
                    self.writing = None;
                    return bad(format!("a file of more than {} bytes", protocol::MAX_FOE_FILE));
                }
                w.3.extend_from_slice(&part);
                if more {
                    return ok(serde_json::json!({ "buffered": w.3.len() }));
                }
                let (position, file, password, data) = self.writing.take().unwrap_or_default();
                let ready = ferrocat_master::Request::FoeWrite { position, file, password, data };
                forward(jobs, id, Asked::Ready(ready), true)
            }
            Request::FoeRead { position, file, offset, .. } if offset > 0 => match &self.read {
                Some((p, f, data)) if (*p, f) == (position, &file) => ok(part_of(data, offset)),
                _ => bad(format!(
                    "offset {offset}: read '{file}' of slave {position} from offset 0 first, on this connection"
                )),
            },
            Request::FoeRead { position, file, password, max_bytes, .. } => {
                let max_bytes = max_bytes.min(protocol::MAX_FOE_FILE);
                let ready = ferrocat_master::Request::FoeRead { position, file: file.clone(), password, max_bytes };
                match forward_answer(jobs, id, Asked::Ready(ready), true) {
                    Ok(Ok(Answer::Data(data))) => {
                        let r = ok(part_of(&data, 0));
                        self.read = Some((position, file, data));
                        r
                    }
                    Ok(answer) => reply_of(id, answer),
                    Err(r) => r,
                }
            }
            request => forward(jobs, id, Asked::Protocol(request), false),
        }
    }
}

/// A file's part from `offset`, as a reply's result.
fn part_of(data: &[u8], offset: usize) -> serde_json::Value {
    let from = offset.min(data.len());
    let to = (from + protocol::MAX_DATA).min(data.len());
    serde_json::json!({ "total": data.len(), "offset": from, "data": protocol::hex(&data[from..to]) })
}

/// Sends a request to the loop and waits for its reply.
fn forward(jobs: &SyncSender<Job>, id: u64, asked: Asked, long: bool) -> Reply {
    match forward_answer(jobs, id, asked, long) {
        Ok(answer) => reply_of(id, answer),
        Err(r) => r,
    }
}

/// Sends a request to the loop: the master's answer, or the reply that ends it here (made by
/// the loop, or saying why none came). A file by FoE (`long`) may take minutes (a packet a
/// cycle and the slave busy); anything else is answered within the loop's own limits.
fn forward_answer(
    jobs: &SyncSender<Job>,
    id: u64,
    asked: Asked,
    long: bool,
) -> Result<ferrocat_master::Result<Answer>, Reply> {
    let (tx, rx) = mpsc::sync_channel(1);
    let error = |kind, message: &str| Reply { id, ok: None, error: Some(ErrorReply::new(kind, message)) };
    let wait = if long { FILE_WAIT } else { REPLY_WAIT };
    match jobs.try_send(Job { id, asked, reply: tx }) {
        Ok(()) => match rx.recv_timeout(wait) {
            Ok(Back::Ready(r)) => Err(r),
            Ok(Back::Answer(a)) => Ok(a),
            Ok(Back::Facts(_)) => Err(error(ErrorKind::Master, "an answer of the wrong kind")),
            Err(mpsc::RecvTimeoutError::Disconnected) => Err(error(ErrorKind::Master, "the master has stopped")),
            Err(mpsc::RecvTimeoutError::Timeout) => {
                Err(error(ErrorKind::Master, "no answer from the cyclic loop (stopped, or stalled)"))
            }
        },
        Err(TrySendError::Full(_)) => Err(error(ErrorKind::Busy, "the master's request queue is full: try again")),
        Err(TrySendError::Disconnected(_)) => Err(error(ErrorKind::Master, "the master has stopped")),
    }
}

fn write_line(mut stream: &UnixStream, v: &impl serde::Serialize) -> std::io::Result<()> {
    let mut line = serde_json::to_vec(v).map_err(std::io::Error::other)?;
    line.push(b'\n');
    stream.write_all(&line)
}

/// Gives the socket file to `group`.
fn chown_group(path: &std::path::Path, group: &str) -> std::io::Result<()> {
    use std::os::unix::ffi::OsStrExt;
    let name = std::ffi::CString::new(group).map_err(|_| std::io::Error::other("a group name with NUL"))?;
    // SAFETY: getgrnam reads a NUL-terminated name; the record it returns is read at once.
    let gid = unsafe {
        let g = libc::getgrnam(name.as_ptr());
        if g.is_null() {
            return Err(std::io::Error::other(format!("no group '{group}'")));
        }
        (*g).gr_gid
    };
    let p = std::ffi::CString::new(path.as_os_str().as_bytes()).map_err(std::io::Error::other)?;
    // SAFETY: a NUL-terminated path; -1 leaves the owner as it is.
    if unsafe { libc::chown(p.as_ptr(), u32::MAX, gid) } != 0 {
        return Err(std::io::Error::last_os_error());
    }
    Ok(())
}

/// Asks the loop for `request` on a thread that is not the loop's (the mailbox gateway's):
/// its answer, or `None` where the queue was full or no answer came in time.
pub(crate) fn ask(
    jobs: &SyncSender<Job>,
    request: ferrocat_master::Request,
) -> Option<ferrocat_master::Result<Answer>> {
    forward_answer(jobs, 0, Asked::Ready(request), false).ok()
}

/// Asks the loop for the facts the master's object dictionary is built from.
pub(crate) fn ask_facts(jobs: &SyncSender<Job>) -> Option<Facts> {
    let (tx, rx) = mpsc::sync_channel(1);
    jobs.try_send(Job { id: 0, asked: Asked::Facts, reply: tx }).ok()?;
    match rx.recv_timeout(REPLY_WAIT) {
        Ok(Back::Facts(f)) => Some(*f),
        _ => None,
    }
}

impl Server {
    /// What the master's object dictionary is built from, taken in the loop: the slave table,
    /// the counters, the events kept.
    fn facts<I: Io>(&self, m: &mut Master<I>) -> Facts {
        let slaves: Vec<SlaveFacts> = m
            .slaves()
            .iter()
            .map(|s| {
                let id = s.identity();
                let ports = s.ports();
                let mut neighbours = [0u16; 4];
                if let Some(parent) = ports.parent.and_then(|p| m.slaves().get(p as usize)) {
                    neighbours[usize::from(ports.entry & 3)] = parent.station();
                }
                for child in m.slaves().iter().filter(|c| c.ports().parent == Some(s.position())) {
                    neighbours[usize::from(child.ports().parent_port & 3)] = child.station();
                }
                let sii = s.sii();
                let type_name = sii.general().and_then(|g| sii.string(g.order_idx)).unwrap_or_else(|| s.name().into());
                SlaveFacts {
                    position: s.position(),
                    station: s.station(),
                    type_name,
                    name: s.name().to_string(),
                    identity: [id.vendor_id, id.product_code, id.revision, id.serial],
                    mailbox_out: s.mailbox().map_or(0, |mb| mb.out.1),
                    mailbox_in: s.mailbox().map_or(0, |mb| mb.inp.1),
                    protocols: s.mailbox().map_or(0, |mb| mb.protocols),
                    port_descriptor: ports.descriptor,
                    active: ports.active,
                    dl_status: ports.dl_status.0,
                    neighbours,
                    requested_state: s.status().state() as u8,
                    lost_count: self.lost.get(&s.position()).copied().unwrap_or(0),
                    left_op_count: self.left_op.get(&s.position()).copied().unwrap_or(0),
                }
            })
            .collect();
        let c = m.diagnosis().cycle_stats();
        let f = m.cyclic().frame_stats();
        let severity = |kind: &str| match kind {
            "recovered" => 0,
            "left_op" | "lost" | "sync_error" | "emergency" => 2,
            _ => 1,
        };
        let started = self.started;
        Facts {
            slaves,
            cycles: c.cycles,
            wkc_errors: c.wkc_errors,
            cyclic_lost: c.lost_frames,
            frames_lost: f.lost,
            frames_sent: f.frames_sent,
            uptime_ns: started.elapsed().as_nanos() as u64,
            events: self.events.iter().map(|e| ((e.at_s * 1e9) as u64, severity(&e.kind), e.text.clone())).collect(),
            events_dropped: self.events.front().map_or(0, |e| e.seq),
        }
    }
}
