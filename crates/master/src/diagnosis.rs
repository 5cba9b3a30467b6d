//! Diagnosis while cyclic: every slave's error counters (0x0300–0x0313) read at a low rate and
//! every CoE slave's mailbox polled for emergencies, one datagram at a time in a cycle's spare
//! time, so that none of it makes a cycle late.
use ferrocat_wire::register::{addr, ErrorCounters};
use ferrocat_wire::{Address, Command};

use crate::diagnosis_state::DiagnosisStats;
use crate::error::{MasterError, Result};
use crate::io::Io;
use crate::master::Master;
use crate::MasterEvent;

/// A datagram of diagnosis is started only where twice this, or twice the last cyclic round
/// trip, is left before the deadline.
const MIN_STEP_NS: u64 = 50_000;

impl<I: Io> Master<I> {
    /// Diagnosis before `deadline_ns` (the master's clock), at most two datagrams, each only
    /// where twice a round trip is left: the next slave's error counters when a round of them
    /// is due (one round every `counters_period_ns`), and the next CoE slave's mailbox (so that
    /// each is polled once every as many calls as there are). A counter that grew and an
    /// emergency become events ([`MasterEvent::ErrorCounters`], [`MasterEvent::Emergency`]). A
    /// datagram is waited for until the deadline at most and not sent again. Returns the
    /// datagrams sent.
    pub fn diagnose(&mut self, deadline_ns: u64, counters_period_ns: u64) -> Result<u32> {
        let n = self.slaves.len();
        if n == 0 {
            return Ok(0);
        }
        self.diagnosis.counters.resize(n, None);
        let step_ns = self.cyc.stats.last_round_trip_ns.max(MIN_STEP_NS);
        let mailboxes = self.slaves.iter().any(|s| s.mailbox.is_some() && s.has_coe());
        let (timeout, retries) = (self.engine.timeout_ns, self.engine.retries);
        let mut sent = 0;
        let mut result = Ok(0);
        for counters in [true, false] {
            let now = self.engine.io.now_ns();
            let wanted = if counters { now >= self.diagnosis.round_due_ns } else { mailboxes };
            if !wanted || now + 2 * step_ns > deadline_ns {
                continue;
            }
            (self.engine.timeout_ns, self.engine.retries) = (deadline_ns - now, 0);
            let r = if counters { self.read_counters_step(counters_period_ns) } else { self.poll_mailbox_step() };
            sent += 1;
            match r {
                Ok(()) => result = Ok(sent),
                Err(MasterError::Timeout { .. }) => {
                    self.diagnosis.stats.given_up += 1;
                    result = Ok(sent);
                    break;
                }
                Err(e) => {
                    result = Err(e);
                    break;
                }
            }
        }
        (self.engine.timeout_ns, self.engine.retries) = (timeout, retries);
        result
    }

    /// What diagnosis did so far.
    pub fn diagnosis_stats(&self) -> DiagnosisStats {
        self.diagnosis.stats
    }

    /// The error counters of every slave as diagnosis last read them.
    pub fn error_counters(&self) -> &[Option<ErrorCounters>] {
        &self.diagnosis.counters
    }

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

    fn poll_mailbox_step(&mut self) -> Result<()> {
        let n = self.slaves.len();
        let Some(k) = (0..n)
            .map(|i| (self.diagnosis.next_mailbox + i) % n)
            .find(|&k| self.slaves[k].mailbox.is_some() && self.slaves[k].has_coe())
        else {
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
