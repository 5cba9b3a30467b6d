//! Diagnosis while cyclic: every slave's error counters (0x0300–0x0313) read at a low rate,
//! every CoE or SoE slave's mailbox polled for emergencies (and SoE notifications), and the
//! sync-error flags of the output and input SM parameters (0x1C32:20, 0x1C33:20) of every slave
//! with SYNC0 read, one datagram at a time in a cycle's spare time, so that none of it makes a
//! cycle late.
use ferrocat_wire::coe::{self, CoeHeader, CoeMessage, CoeService, Sdo};
use ferrocat_wire::mailbox::MailboxType;
use ferrocat_wire::register::{addr, ErrorCounters};
use ferrocat_wire::{Address, Command};

use crate::diagnosis_state::DiagnosisStats;
use crate::error::{MasterError, Result};
use crate::io::Io;
use crate::master::Master;
use crate::MasterEvent;

/// A datagram of diagnosis is started only where this, or the last cyclic round trip, is left
/// before the deadline (it is waited for until the deadline at most).
const MIN_STEP_NS: u64 = 50_000;
// The SM parameters' sync-error flags (ETG.1020: 0x1C32:20 and 0x1C33:20, set when the SM-event
// missed counter, subindex 0x0B, reached the limit 0x10F1:02): `SyncSm`.
use crate::diagnosis_state::{SyncFlags, SyncSm};
/// How long a read of the flag waits for its reply before it is given up (the master's clock).
const SYNC_READ_TIMEOUT_NS: u64 = 1_000_000_000;

impl<I: Io> Master<I> {
    fn read_counters_step(&mut self, period_ns: u64) -> Result<()> {
        let k = self.diagnosis.next_counters % self.slaves.len();
        let station = self.slaves[k].station;
        let mut b = [0u8; ErrorCounters::LEN];
        let wkc =
            self.engine.one(Command::FPRD, Address::Device { adp: station, ado: addr::RX_ERROR_COUNTER }, &mut b)?;
        self.diagnosis.stats.counter_reads += 1;
        self.diagnosis.next_counters = k + 1;
        if k + 1 == self.slaves.len() {
            self.diagnosis.round_due_ns = self.engine.io.now_ns() + period_ns;
        }
        if wkc != 1 {
            return Ok(());
        }
        let now = ErrorCounters::parse(&b)?;
        if let Some(before) = self.diagnosis.counters[k] {
            let name = self.slaves[k].name.clone();
            for ((kind, port, total), (_, _, was)) in now.each().zip(before.each()) {
                if total > was {
                    self.diagnosis.stats.counters_grown += 1;
                    let e = MasterEvent::ErrorCounters {
                        position: k as u16,
                        name: name.clone(),
                        kind,
                        port,
                        grown: total - was,
                        total,
                    };
                    self.push_event(e);
                }
            }
        }
        self.diagnosis.counters[k] = Some(now);
        Ok(())
    }

    /// The mailbox's datagram of this call: the awaited flag's reply, a flag's request, or an
    /// emergency poll.
    fn mailbox_step(&mut self, period_ns: u64) -> Result<()> {
        let now = self.engine.io.now_ns();
        if let Some((k, sm, asked_ns)) = self.diagnosis.sync_pending {
            if now.saturating_sub(asked_ns) > SYNC_READ_TIMEOUT_NS {
                self.diagnosis.sync_pending = None;
                self.diagnosis.stats.given_up += 1;
            } else {
                return self.await_sync_flag(k, sm);
            }
        }
        if now >= self.diagnosis.sync_due_ns {
            if let Some((k, sm, round)) = self.next_sync_flag() {
                return self.ask_sync_flag(k, sm, round, period_ns);
            }
        }
        self.poll_mailbox_step()
    }

    /// The next flag to read this round (a slave and which of its two), and how many a round
    /// reads: both flags of each slave with SYNC0 and a CoE mailbox, but those it refused.
    fn next_sync_flag(&self) -> Option<(u16, SyncSm, usize)> {
        let d = &self.diagnosis;
        let flags = d.sync0_slaves.iter().flat_map(|&p| [(p, SyncSm::Outputs), (p, SyncSm::Inputs)]);
        let readable = |f: &(u16, SyncSm)| {
            self.slaves.get(f.0 as usize).is_some_and(|s| s.mailbox().is_some_and(|mb| mb.has_coe()))
                && !d.sync_unreadable.contains(f)
                && !self.acyclic.holds_mailbox(f.0)
        };
        let count = flags.clone().filter(readable).count();
        let (k, sm) = flags.filter(readable).nth(d.next_sync % count.max(1))?;
        Some((k, sm, count))
    }

    /// Writes the request for `position`'s flag of `sm` into its mailbox (one datagram; a full
    /// mailbox is tried again at the next call).
    fn ask_sync_flag(&mut self, position: u16, sm: SyncSm, round: usize, period_ns: u64) -> Result<()> {
        let (index, subindex) = sm.object();
        let mut body = [0u8; 2 + coe::SDO_HEADER_LEN];
        CoeHeader::new(CoeService::SDO_REQUEST).emit(&mut body)?;
        Sdo::UploadRequest { index, subindex, complete_access: false, reserved: [0; 4] }.emit(&mut body[2..])?;
        let mut mbx = self.mailboxes();
        let mut msg = mbx.message(position, MailboxType::COE, &body)?;
        if !mbx.try_write(position, &mut msg)? {
            return Ok(());
        }
        let now = self.engine.io.now_ns();
        self.diagnosis.sync_pending = Some((position, sm, now));
        self.diagnosis.next_sync += 1;
        if self.diagnosis.next_sync % round.max(1) == 0 {
            self.diagnosis.sync_due_ns = now + period_ns;
        }
        Ok(())
    }

    /// Polls `position`'s mailbox for the reply of its flag of `sm`; an emergency met on the
    /// way is an event as ever.
    fn await_sync_flag(&mut self, position: u16, sm: SyncSm) -> Result<()> {
        self.diagnosis.stats.mailbox_polls += 1;
        let payload = match self.mailboxes().poll(position) {
            Ok(crate::mailbox::Polled::Message(MailboxType::COE, payload)) => payload,
            Ok(_) => return Ok(()),
            // A mailbox error reply, a malformed one: the read is over.
            Err(MasterError::Slave { .. }) => {
                self.diagnosis.sync_pending = None;
                return Ok(());
            }
            Err(e) => return Err(e),
        };
        let (index, subindex) = sm.object();
        let flag = match coe::parse(&payload) {
            Ok((_, CoeMessage::Sdo(Sdo::UploadExpeditedResponse { index: i, subindex: s, data, .. })))
                if (i, s) == (index, subindex) =>
            {
                data[0] & 1 != 0
            }
            Ok((_, CoeMessage::Sdo(Sdo::Abort { index: i, subindex: s, .. }))) if (i, s) == (index, subindex) => {
                // The slave has no such object: it is not asked again.
                self.diagnosis.sync_unreadable.push((position, sm));
                self.diagnosis.sync_pending = None;
                return Ok(());
            }
            // Another reply (a late one of another client's): not the flag's.
            _ => return Ok(()),
        };
        self.diagnosis.sync_pending = None;
        self.diagnosis.stats.sync_flag_reads += 1;
        let k = position as usize;
        if self.diagnosis.sync_flags.len() <= k {
            self.diagnosis.sync_flags.resize(k + 1, SyncFlags::default());
        }
        let was = self.diagnosis.sync_flags[k].of(sm).replace(flag);
        if flag && was != Some(true) {
            self.diagnosis.stats.sync_errors += 1;
            let name = self.slaves[k].name.clone();
            self.push_event(MasterEvent::SyncError { position, name, index });
        }
        Ok(())
    }

    /// The last cycle's TxPDO State and Toggle entries, found in the image when it was laid
    /// out: a State set and a Toggle standing still for `Settings::txpdo_stale_ns` are events.
    fn watch_txpdo_entries(&mut self) {
        use crate::diagnosis_state::{TxPdoKind, TxPdoWatch};
        if self.diagnosis.txpdo.is_none() {
            let entries = self.slaves.iter().flat_map(|s| {
                s.mapping.inputs.iter().filter_map(move |e| {
                    TxPdoKind::of(e.index, e.subindex, &e.name, e.bits).map(|kind| {
                        (s.position, format!("{} ({:#06x}:{:#04x})", e.name, e.index, e.subindex), kind, e.image_bit)
                    })
                })
            });
            let watch = TxPdoWatch::new(entries);
            self.diagnosis.stats.txpdo_watched = watch.entries.len() as u64;
            self.diagnosis.txpdo = Some(watch);
        }
        let now = self.engine.io.now_ns();
        let stale_ns = self.settings.txpdo_stale_ns;
        let Some(watch) = self.diagnosis.txpdo.as_mut() else { return };
        if watch.entries.is_empty() {
            return;
        }
        for c in watch.observe(&self.image, now, stale_ns) {
            let name = self.slaves.get(c.position as usize).map(|s| s.name.clone()).unwrap_or_default();
            let (position, entry) = (c.position, c.entry);
            let event = match c.kind {
                TxPdoKind::State => {
                    self.diagnosis.stats.inputs_invalid += 1;
                    MasterEvent::InputsInvalid { position, name, entry }
                }
                TxPdoKind::Toggle => {
                    self.diagnosis.stats.inputs_stale += 1;
                    MasterEvent::InputsStale { position, name, entry, unchanged_ns: c.unchanged_ns }
                }
            };
            self.push_event(event);
        }
    }

    /// Polls the next mailbox that may hold a message nobody asked for (below).
    fn poll_mailbox_step(&mut self) -> Result<()> {
        let n = self.slaves.len();
        let Some(k) = (0..n).map(|i| (self.diagnosis.next_mailbox + i) % n).find(|&k| {
            self.slaves[k].mailbox.is_some()
                && self.slaves[k].mailbox().is_some_and(sends_unasked)
                && !self.acyclic.holds_mailbox(k as u16)
        }) else {
            return Ok(());
        };
        self.diagnosis.next_mailbox = k + 1;
        self.diagnosis.stats.mailbox_polls += 1;
        match self.mailboxes().poll(k as u16) {
            Ok(_) | Err(MasterError::Slave { .. }) => Ok(()),
            Err(e) => Err(e),
        }
    }
}

impl<'a, I: Io> crate::master::part::Diagnosis<'a, I> {
    /// Diagnosis before `deadline_ns` (the master's clock), at most two datagrams, each only
    /// where a round trip is left: the next slave's error counters when a round of them
    /// is due (one round every `counters_period_ns`), and a mailbox datagram: while a read of a
    /// slave's sync-error flag (0x1C32:20 or 0x1C33:20) is awaited, a poll of that slave's
    /// mailbox; else,
    /// when a round of those reads is due (one every `counters_period_ns` over the slaves whose
    /// SYNC0 the DC initialisation started), the next read's request; else a poll of the next
    /// CoE or SoE slave's mailbox (so that each is polled once every as many calls as there are).
    /// Before those, without a datagram, the last cycle's TxPDO State and Toggle entries. A
    /// counter that grew, an emergency, a flag found set, a TxPDO State set and a Toggle that
    /// stood still become events ([`MasterEvent::ErrorCounters`], [`MasterEvent::Emergency`],
    /// [`MasterEvent::SyncError`], [`MasterEvent::InputsInvalid`], [`MasterEvent::InputsStale`]). A datagram is waited for until the deadline at most and
    /// not sent again. Returns the datagrams sent.
    pub fn diagnose(&mut self, deadline_ns: u64, counters_period_ns: u64) -> Result<u32> {
        let n = self.m.slaves.len();
        if n == 0 {
            return Ok(0);
        }
        self.m.watch_txpdo_entries();
        self.m.diagnosis.counters.resize(n, None);
        let step_ns = self.m.cyc.stats.last_round_trip_ns.max(MIN_STEP_NS);
        let mailboxes = self.m.slaves.iter().any(|s| s.mailbox().is_some_and(sends_unasked));
        let (timeout, retries) = (self.m.engine.timeout_ns, self.m.engine.retries);
        let mut sent = 0;
        let mut result = Ok(0);
        for counters in [true, false] {
            let now = self.m.engine.io.now_ns();
            let wanted = if counters { now >= self.m.diagnosis.round_due_ns } else { mailboxes };
            if !wanted || now + step_ns > deadline_ns {
                continue;
            }
            (self.m.engine.timeout_ns, self.m.engine.retries) = (deadline_ns - now, 0);
            // A mailbox read's repeat request adds datagrams: none waited for past the deadline.
            self.m.engine.wait_until_ns = Some(deadline_ns);
            let r = if counters {
                self.m.read_counters_step(counters_period_ns)
            } else {
                self.m.mailbox_step(counters_period_ns)
            };
            sent += 1;
            match r {
                Ok(()) => result = Ok(sent),
                Err(MasterError::Timeout { .. }) => {
                    self.m.diagnosis.stats.given_up += 1;
                    result = Ok(sent);
                    break;
                }
                Err(e) => {
                    result = Err(e);
                    break;
                }
            }
        }
        (self.m.engine.timeout_ns, self.m.engine.retries) = (timeout, retries);
        self.m.engine.wait_until_ns = None;
        result
    }

    /// What diagnosis did so far.
    pub fn diagnosis_stats(&self) -> DiagnosisStats {
        self.m.diagnosis.stats
    }

    /// The error counters of every slave as diagnosis last read them.
    pub fn error_counters(self) -> &'a [Option<ErrorCounters>] {
        &self.m.diagnosis.counters
    }

    /// The sync-error flags (0x1C32:20, 0x1C33:20) of each slave as diagnosis last read them,
    /// by position.
    pub fn sync_error_flags(self) -> &'a [SyncFlags] {
        &self.m.diagnosis.sync_flags
    }
}

/// Whether a slave's mailbox may hold messages nobody asked for: CoE emergencies, SoE
/// notifications and emergencies.
fn sends_unasked(mb: &crate::slave::MailboxConfig) -> bool {
    mb.has_coe() || mb.has_protocol(ferrocat_wire::sii::mailbox_protocol::SOE)
}
