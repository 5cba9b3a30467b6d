//! The acyclic side of a running master: requests from the application or from other
//! processes (SDO transfers, SDO information, registers, AL states), each taken one datagram
//! at a time in a cycle's spare time, so that none of them makes a cycle late. Requests wait
//! in a queue and are served one after the other; their answers wait until taken.
use ferrocat_wire::mailbox::MailboxType;
use ferrocat_wire::register::{addr, AlState, AlStatus, AlStatusCode};
use ferrocat_wire::{Address, Command};

use crate::acyclic_state::{Active, InfoWanted, Job};
pub use crate::acyclic_state::{AcyclicStats, Answer, Request, RequestId, QUEUE_LIMIT, REGISTER_MAX, STARVED_CALLS};
use crate::coe;
use crate::error::{MasterError, RequestError, Result, SlaveError, StateCause};
use crate::foe_transfer::{FoePeer, FoeStep, FoeTransfer};
use crate::io::Io;
use crate::mailbox::Polled;
use crate::master::Master;
use crate::sdo_transfer::{InfoTransfer, Peer, SdoTransfer, Step};
use crate::soe_transfer::{SoeStep, SoeTransfer};

/// Datagrams a call of [`Acyclic::serve_requests`](crate::part::Acyclic::serve_requests) sends at most.
const DATAGRAMS_PER_CALL: u32 = 4;
/// A datagram is started only where this, or the last cyclic round trip, is left before the
/// deadline (it is waited for until the deadline at most): a segment whose round trip is a
/// large part of the cycle is still served.
const MIN_STEP_NS: u64 = 50_000;

impl<I: Io> Master<I> {
    /// Takes the next queued request that can start now: a mailbox request waits while
    /// diagnosis awaits a reply of the same slave. Returns whether one is being served.
    fn start_next(&mut self) -> bool {
        let busy = self.diagnosis.sync_pending.map(|(p, _, _)| p);
        let Some(k) = self.acyclic.queue.iter().position(|(_, r)| !(r.uses_mailbox() && busy == Some(r.position())))
        else {
            return false;
        };
        let Some((id, request)) = self.acyclic.queue.remove(k) else { return false };
        let now = self.engine.io.now_ns();
        match self.job_of(&request) {
            Ok(job) => {
                self.acyclic.active = Some(Active { id, position: request.position(), job, since_ns: now });
                true
            }
            Err(e) => {
                self.acyclic.answer(id, Err(e));
                self.start_next()
            }
        }
    }

    fn job_of(&mut self, request: &Request) -> Result<Job> {
        let position = request.position();
        let job = match request.clone() {
            Request::SdoRead { index, subindex, complete_access, .. } => {
                Job::Sdo(SdoTransfer::upload(self.peer_of(position)?, index, subindex, complete_access), None)
            }
            Request::SdoWrite { index, subindex, complete_access, data, .. } => {
                Job::Sdo(SdoTransfer::download(self.peer_of(position)?, index, subindex, complete_access, data), None)
            }
            Request::OdList { .. } => {
                Job::Info(InfoTransfer::new(self.peer_of(position)?, coe::od_list_request())?, InfoWanted::List, None)
            }
            Request::ObjectInfo { index, .. } => {
                let t = InfoTransfer::new(self.peer_of(position)?, coe::object_request(index))?;
                Job::Info(t, InfoWanted::Object, None)
            }
            Request::EntryInfo { index, subindex, .. } => {
                let t = InfoTransfer::new(self.peer_of(position)?, coe::entry_request(index, subindex))?;
                Job::Info(t, InfoWanted::Entry, None)
            }
            Request::FoeRead { file, password, max_bytes, .. } => {
                Job::Foe(FoeTransfer::read(self.foe_peer_of(position)?, &file, password, max_bytes), None, None, false)
            }
            Request::FoeWrite { file, password, data, .. } => {
                Job::Foe(FoeTransfer::write(self.foe_peer_of(position)?, &file, password, data)?, None, None, true)
            }
            Request::RegisterRead { register, len, .. } => {
                self.slave(position)?;
                Job::RegisterRead { register, len }
            }
            Request::RegisterWrite { register, data, .. } => {
                self.slave(position)?;
                Job::RegisterWrite { register, data }
            }
            Request::SoeRead { drive, idn, elements, .. } => {
                let peer = self.acyclic().soe().peer(position)?;
                Job::Soe(SoeTransfer::read(peer, drive, idn, elements)?, None, false)
            }
            Request::SoeWrite { drive, idn, elements, data, .. } => {
                let peer = self.acyclic().soe().peer(position)?;
                Job::Soe(SoeTransfer::write(peer, drive, idn, elements, &data)?, None, true)
            }
            // Empty data awaiting a reply: nothing written, the slave's next message awaited.
            Request::Mailbox { mailbox_type, data, reply: true, .. } if data.is_empty() => {
                self.mailboxes().mailbox_of(position, mailbox_type)?;
                Job::Mailbox(mailbox_type, None, true)
            }
            Request::Mailbox { mailbox_type, data, reply, .. } => {
                Job::Mailbox(mailbox_type, Some(self.mailboxes().message(position, mailbox_type, &data)?), reply)
            }
            Request::State { state, .. } => {
                self.slave(position)?;
                // Supervision keeps the slave where it was asked to be, not in OP.
                self.slaves[position as usize].state = state;
                Job::State { state, written: false }
            }
        };
        // A mailbox conversation starts with its first message, under the next counter.
        Ok(match job {
            Job::Sdo(mut t, _) => {
                let first = t.start()?;
                Job::Sdo(t, Some(self.mailboxes().message(position, MailboxType::COE, &first)?))
            }
            Job::Info(mut t, wanted, _) => {
                let first = t.start()?;
                Job::Info(t, wanted, Some(self.mailboxes().message(position, MailboxType::COE, &first)?))
            }
            Job::Foe(mut t, _, _, writes) => {
                let first = t.start()?;
                Job::Foe(t, Some(self.mailboxes().message(position, MailboxType::FOE, &first)?), None, writes)
            }
            Job::Soe(mut t, _, writes) => {
                let first = t.next_message().unwrap_or_default();
                Job::Soe(t, Some(self.mailboxes().message(position, MailboxType::SOE, &first)?), writes)
            }
            other => other,
        })
    }

    /// Where a starved request's one datagram may wait until: a sixteenth of the period before
    /// the next cycle (the wake-up target plus the nominal period), when that is past
    /// `deadline_ns` and the requests found no room for [`STARVED_CALLS`] calls in a row.
    fn relief_deadline_ns(&mut self, deadline_ns: u64) -> Option<u64> {
        let period = self.cyc.stats.nominal_period_ns;
        let start = self.engine.io.wake_target_ns()?;
        let r = (start + period).checked_sub(period / 16)?;
        (self.acyclic.starved_calls >= STARVED_CALLS && period > 0 && r > deadline_ns).then_some(r)
    }

    /// A call without room: counted, and the request being served answered with
    /// [`RequestError::NoRoom`] once it has waited the mailbox timeout (the state timeout for a
    /// state request) without a datagram.
    fn starved(&mut self, deadline_ns: u64, step_ns: u64) {
        self.acyclic.starved_calls = self.acyclic.starved_calls.saturating_add(1);
        self.acyclic.stats.starved += 1;
        let now = self.engine.io.now_ns();
        let Some(a) = self.acyclic.active.as_ref() else { return };
        let limit_ns = match a.job {
            Job::State { .. } => self.settings.state_timeout_ns,
            _ => self.settings.mailbox_timeout_ns,
        };
        let waited_ns = now.saturating_sub(a.since_ns);
        if waited_ns > limit_ns {
            let id = a.id;
            self.acyclic.active = None;
            let e = RequestError::NoRoom {
                waited_ms: waited_ns / 1_000_000,
                round_trip_us: step_ns / 1000,
                spare_us: deadline_ns.saturating_sub(now) / 1000,
            };
            self.acyclic.answer(id, Err(e.into()));
        }
    }

    /// Who `position` is, for an FoE transfer.
    fn foe_peer_of(&mut self, position: u16) -> Result<FoePeer> {
        let (_, name, m) = self.mailboxes().mailbox_of(position, MailboxType::FOE)?;
        Ok(FoePeer { position, name, out_len: m.out.1 as usize, in_len: m.inp.1 as usize })
    }

    /// Who `position` is, for a CoE conversation.
    fn peer_of(&mut self, position: u16) -> Result<Peer> {
        let (_, name, m) = self.mailboxes().mailbox_of(position, MailboxType::COE)?;
        Ok(Peer { position, name, mailbox_len: m.out.1 as usize })
    }

    /// One datagram of the request being served. A datagram lost or the link failing leaves
    /// the request to the next call (a lost datagram's outcome is unknown: a register or a
    /// state is written again, a mailbox message again under its counter, which a slave takes
    /// once) until it has made no progress for its timeout, and is returned; any other error
    /// is the request's answer.
    fn request_step(&mut self) -> Result<()> {
        let Some(mut a) = self.acyclic.active.take() else { return Ok(()) };
        let now = self.engine.io.now_ns();
        let limit_ns = match a.job {
            Job::State { .. } => self.settings.state_timeout_ns,
            _ => self.settings.mailbox_timeout_ns,
        };
        match self.step_of(&mut a, now, limit_ns) {
            Ok(Some(answer)) => self.acyclic.answer(a.id, answer),
            Ok(None) => self.acyclic.active = Some(a),
            Err(e @ MasterError::Timeout { .. }) if now.saturating_sub(a.since_ns) > limit_ns => {
                let waited_ms = now.saturating_sub(a.since_ns) / 1_000_000;
                self.acyclic.answer(a.id, Err(RequestError::TimedOut { waited_ms }.into()));
                return Err(e);
            }
            Err(e @ (MasterError::Timeout { .. } | MasterError::Io(_))) => {
                self.acyclic.active = Some(a);
                return Err(e);
            }
            Err(e) => self.acyclic.answer(a.id, Err(e)),
        }
        Ok(())
    }

    /// [`request_step`](Self::request_step)'s datagram: the request's answer once it has one.
    fn step_of(&mut self, a: &mut Active, now: u64, limit_ns: u64) -> Result<Option<Result<Answer>>> {
        let station = self.slave(a.position)?.station;
        let device = |ado| Address::Device { adp: station, ado };
        // A write's next fragment, once the one before was taken (no reply comes between).
        let mut soe_next = None;
        let done = match &mut a.job {
            Job::Sdo(_, Some(msg))
            | Job::Info(_, _, Some(msg))
            | Job::Foe(_, Some(msg), _, _)
            | Job::Soe(_, Some(msg), _)
            | Job::Mailbox(_, Some(msg), _) => {
                // Written again under the same counter until the slave takes it.
                let mut mbx = self.mailboxes();
                if mbx.try_write(a.position, msg)? {
                    a.since_ns = now;
                    match &mut a.job {
                        // An FoE transfer's last message: over once written.
                        Job::Foe(_, _, end @ Some(_), writes) => {
                            let end = end.take().unwrap_or_else(|| Ok(Vec::new()));
                            let writes = *writes;
                            Some(end.map(|d| if writes { Answer::Written } else { Answer::Data(d) }))
                        }
                        Job::Soe(t, m, _) => {
                            *m = None;
                            soe_next = t.next_message();
                            None
                        }
                        Job::Mailbox(_, _, false) => Some(Ok(Answer::Mailbox(Vec::new()))),
                        Job::Mailbox(_, m, true) => {
                            *m = None;
                            None
                        }
                        Job::Sdo(_, m) | Job::Info(_, _, m) | Job::Foe(_, m, _, _) => {
                            *m = None;
                            None
                        }
                        _ => None,
                    }
                } else if now.saturating_sub(a.since_ns) > limit_ns {
                    return Err(MasterError::of(a.position, &mbx.name_of(a.position), SlaveError::MailboxFull));
                } else {
                    None
                }
            }
            Job::Sdo(..) | Job::Info(..) | Job::Foe(..) | Job::Soe(..) | Job::Mailbox(..) => {
                self.await_reply(a, now, limit_ns)?
            }
            Job::RegisterRead { register, len } => {
                let mut b = vec![0u8; *len as usize];
                let wkc = self.engine.one(Command::FPRD, device(*register), &mut b)?;
                Some(self.wkc_checked(a.position, wkc).map(|()| Answer::Data(b)))
            }
            Job::RegisterWrite { register, data } => {
                let wkc = self.engine.one(Command::FPWR, device(*register), data)?;
                Some(self.wkc_checked(a.position, wkc).map(|()| Answer::Written))
            }
            Job::State { state, written: w @ false } => {
                let wkc = self.engine.one(Command::FPWR, device(addr::AL_CONTROL), &mut [*state as u8, 0])?;
                *w = wkc == 1;
                None
            }
            Job::State { state, written: true } => {
                let mut d = [0u8; 6];
                self.engine.one(Command::FPRD, device(addr::AL_STATUS), &mut d)?;
                let status = AlStatus(u16::from_le_bytes([d[0], d[1]]));
                let code = AlStatusCode(u16::from_le_bytes([d[4], d[5]]));
                let error = self.slaves[a.position as usize].esc().al_error(status, code);
                let failed = |cause| MasterError::State {
                    position: a.position,
                    name: self.slaves[a.position as usize].name.clone(),
                    requested: *state,
                    stayed: status.state(),
                    code,
                    cause,
                };
                if status.state() == Some(*state) && !error {
                    Some(Ok(Answer::State(*state)))
                } else if error {
                    Some(Err(failed(StateCause::Error)))
                } else if now.saturating_sub(a.since_ns) > limit_ns {
                    Some(Err(failed(StateCause::Timeout)))
                } else {
                    None
                }
            }
        };
        if let (Some(next), Job::Soe(_, slot, _)) = (soe_next, &mut a.job) {
            *slot = Some(self.mailboxes().message(a.position, MailboxType::SOE, &next)?);
        }
        Ok(done)
    }

    /// One poll of the slave's send mailbox for the awaited reply.
    fn await_reply(&mut self, a: &mut Active, now: u64, limit_ns: u64) -> Result<Option<Result<Answer>>> {
        let protocol = match a.job {
            Job::Foe(..) => MailboxType::FOE,
            Job::Soe(..) => MailboxType::SOE,
            Job::Mailbox(t, ..) => t,
            _ => MailboxType::COE,
        };
        let polled = self.mailboxes().poll(a.position);
        let reply = match polled {
            Ok(Polled::Message(t, payload)) if t == protocol => payload,
            Ok(_) => {
                if now.saturating_sub(a.since_ns) > limit_ns {
                    let name = self.slaves[a.position as usize].name.clone();
                    return Ok(Some(Err(MasterError::of(a.position, &name, SlaveError::NoReply))));
                }
                return Ok(None);
            }
            Err(e @ MasterError::Slave { .. }) => return Ok(Some(Err(e))),
            Err(e) => return Err(e),
        };
        a.since_ns = now;
        let next = match &mut a.job {
            Job::Sdo(t, _) => match t.on_reply(&reply) {
                Ok(Step::Done(data)) => return Ok(Some(Ok(written_or(Answer::Data(data), t)))),
                Ok(Step::Send(next)) => Some(next),
                Ok(Step::Await) => None,
                Err(e) => return Ok(Some(Err(e))),
            },
            Job::Info(t, wanted, _) => match t.on_reply(&reply) {
                Ok(Step::Done(parts)) => {
                    let peer = t.peer().clone();
                    return Ok(Some(match wanted {
                        InfoWanted::List => coe::od_list_of(&parts).map(Answer::List),
                        InfoWanted::Object => coe::object_info_of(&peer, &parts).map(Answer::Object),
                        InfoWanted::Entry => coe::entry_info_of(&peer, &parts).map(Answer::Entry),
                    }));
                }
                Ok(_) => None,
                Err(e) => return Ok(Some(Err(e))),
            },
            Job::Foe(t, _, end, writes) => match t.on_reply(&reply) {
                Ok(FoeStep::Done(data)) => {
                    return Ok(Some(Ok(if *writes { Answer::Written } else { Answer::Data(data) })));
                }
                Ok(FoeStep::Send(next)) => Some(next),
                // The last message is written at the next call, then the transfer answered.
                Ok(FoeStep::Finish(last, result)) => {
                    *end = Some(result);
                    Some(last)
                }
                Err(e) => return Ok(Some(Err(e))),
            },
            Job::Soe(t, _, writes) => match t.on_reply(&reply) {
                Ok(SoeStep::Done(data)) => {
                    return Ok(Some(Ok(if *writes { Answer::Written } else { Answer::Data(data) })));
                }
                Ok(SoeStep::Await) => None,
                Err(e) => return Ok(Some(Err(e))),
            },
            Job::Mailbox(..) => return Ok(Some(Ok(Answer::Mailbox(reply)))),
            _ => None,
        };
        if let Some(payload) = next {
            let m = self.mailboxes().message(a.position, protocol, &payload)?;
            match &mut a.job {
                Job::Sdo(_, slot) | Job::Info(_, _, slot) | Job::Foe(_, slot, _, _) => *slot = Some(m),
                _ => {}
            }
        }
        Ok(None)
    }

    fn wkc_checked(&self, position: u16, wkc: u16) -> Result<()> {
        if wkc == 1 {
            return Ok(());
        }
        let name = self.slaves.get(position as usize).map(|s| s.name.clone()).unwrap_or_default();
        Err(MasterError::of(position, &name, SlaveError::NotAnswering))
    }
}

/// A download's answer is that it was written; an upload's, its data.
fn written_or(answer: Answer, t: &SdoTransfer) -> Answer {
    if t.is_download() {
        Answer::Written
    } else {
        answer
    }
}

fn register_check(register: u16, len: usize) -> Option<RequestError> {
    if !(1..=REGISTER_MAX).contains(&len) {
        return Some(RequestError::RegisterLength { len, max: REGISTER_MAX });
    }
    (register as usize + len > 0x1_0000).then_some(RequestError::RegisterRange { register, len })
}

impl<'a, I: Io> crate::master::part::Acyclic<'a, I> {
    /// Queues `request` for the acyclic side ([`Acyclic::serve_requests`](crate::part::Acyclic::serve_requests)); its answer comes
    /// under the number returned ([`Acyclic::take_answers`](crate::part::Acyclic::take_answers)). A request that cannot be taken
    /// (the queue full, a register range too long) is answered at once with the error.
    pub fn submit(&mut self, request: Request) -> RequestId {
        let a = &mut self.m.acyclic;
        let id = RequestId(a.next_id);
        a.next_id += 1;
        a.stats.submitted += 1;
        let refused = match &request {
            _ if a.queue.len() + usize::from(a.active.is_some()) >= QUEUE_LIMIT => {
                Some(RequestError::QueueFull { limit: QUEUE_LIMIT })
            }
            Request::RegisterRead { register, len, .. } => register_check(*register, *len as usize),
            Request::RegisterWrite { register, data, .. } => register_check(*register, data.len()),
            Request::State { state: AlState::Bootstrap, .. } => Some(RequestError::State(AlState::Bootstrap)),
            _ => None,
        };
        match refused {
            Some(e) => a.answer(id, Err(e.into())),
            None => a.queue.push_back((id, request)),
        }
        id
    }

    /// [`Config::set_process_data_watchdog`](crate::part::Config::set_process_data_watchdog) while cyclic: the two register writes (divider
    /// and time) are requests, served in the cycles' spare time; their numbers. The master
    /// writes the watchdog again whenever it configures the slave, as it does the other's.
    pub fn submit_process_data_watchdog(&mut self, position: u16, time_ns: u64) -> Result<[RequestId; 2]> {
        use crate::master::{WATCHDOG_DIVIDER, WATCHDOG_STEP_NS};
        self.m.slave(position)?;
        let steps = u16::try_from(time_ns.div_ceil(WATCHDOG_STEP_NS))
            .map_err(|_| crate::error::ConfigError::WatchdogTooLong(time_ns))?;
        self.m.slaves[position as usize].pd_watchdog_steps = Some(steps);
        let write = |register, data: [u8; 2]| Request::RegisterWrite { position, register, data: data.to_vec() };
        Ok([
            self.m.acyclic().submit(write(addr::WATCHDOG_DIVIDER, WATCHDOG_DIVIDER.to_le_bytes())),
            self.m.acyclic().submit(write(addr::WATCHDOG_TIME_PROCESS_DATA, steps.to_le_bytes())),
        ])
    }

    /// The answers given since the last call, each under its request's number.
    pub fn take_answers(&mut self) -> Vec<(RequestId, Result<Answer>)> {
        std::mem::take(&mut self.m.acyclic.answers)
    }

    /// Requests waiting or being served.
    pub fn requests_pending(&self) -> usize {
        self.m.acyclic.queue.len() + usize::from(self.m.acyclic.active.is_some())
    }

    /// What the acyclic side did so far.
    pub fn acyclic_stats(&self) -> AcyclicStats {
        self.m.acyclic.stats
    }

    /// Serves the queued requests before `deadline_ns` (the master's clock): at most 4
    /// datagrams, each only where a round trip (the last cyclic one, at least 50 µs) is
    /// left, and waited for until the deadline at most, not sent again. A mailbox message not
    /// yet taken is written again at the next call under the same counter (a slave drops a
    /// repeated one, ETG.1000.4); a reply not yet there is polled for again. A request is
    /// answered with an error when it has made no progress for the mailbox timeout (the state
    /// timeout for a state request); a datagram given up leaves its request for the next call,
    /// until it has gone unanswered that long ([`RequestError::TimedOut`]). Errors of a request
    /// are its answer; only the link's errors are returned. Returns the datagrams sent.
    pub fn serve_requests(&mut self, deadline_ns: u64) -> Result<u32> {
        let step_ns = self.m.cyc.stats.last_round_trip_ns.max(MIN_STEP_NS);
        let (timeout, retries) = (self.m.engine.timeout_ns, self.m.engine.retries);
        let mut sent = 0;
        let mut result = Ok(0);
        let mut no_room = false;
        while sent < DATAGRAMS_PER_CALL {
            if self.m.acyclic.active.is_none() && !self.m.start_next() {
                break;
            }
            let now = self.m.engine.io.now_ns();
            let mut until_ns = deadline_ns;
            if now + step_ns > deadline_ns {
                // A round trip as long as most of the cycle would otherwise starve the requests
                // for good: after a run of calls without room, one datagram in the last part.
                match self.m.relief_deadline_ns(deadline_ns) {
                    Some(r) if sent == 0 && now + step_ns <= r => {
                        until_ns = r;
                        self.m.acyclic.stats.relieved += 1;
                    }
                    _ => {
                        no_room = sent == 0;
                        break;
                    }
                }
            }
            (self.m.engine.timeout_ns, self.m.engine.retries) = (until_ns - now, 0);
            self.m.engine.wait_until_ns = Some(until_ns);
            sent += 1;
            self.m.acyclic.stats.datagrams += 1;
            match self.m.request_step() {
                Ok(()) => result = Ok(sent),
                Err(MasterError::Timeout { .. }) => {
                    self.m.acyclic.stats.given_up += 1;
                    result = Ok(sent);
                    break;
                }
                // The link's (a request's own errors are its answer, given in the step).
                Err(e) => {
                    result = Err(e);
                    break;
                }
            }
            if until_ns != deadline_ns {
                break;
            }
        }
        (self.m.engine.timeout_ns, self.m.engine.retries) = (timeout, retries);
        self.m.engine.wait_until_ns = None;
        if no_room {
            self.m.starved(deadline_ns, step_ns);
        } else if sent > 0 {
            self.m.acyclic.starved_calls = 0;
        }
        result
    }
}
