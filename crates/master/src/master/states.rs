//! Walking the slaves through the AL states, and bringing fallen ones back during operation.
use ferrocat_wire::register::addr;
use ferrocat_wire::register::{AlState, AlStatus, AlStatusCode, DlStatus};
use ferrocat_wire::{Address, Command};

use super::{Master, MasterEvent};
use crate::engine::Pdu;
use crate::error::{code_text, MasterError, Result, SlaveError, StateCause};
use crate::io::Io;

impl<I: Io> Master<I> {
    pub(super) fn wait_state_all(&mut self, state: AlState) -> Result<()> {
        for k in 0..self.slaves.len() as u16 {
            self.wait_state(k, state)?;
        }
        Ok(())
    }

    /// DL status and the SII status read again; why the ESC is unconfigured, if it is.
    fn eeprom_problem_now(&mut self, position: u16) -> Result<Option<String>> {
        let st = self.slave(position)?.station;
        let (mut dl, mut sii) = ([0u8; 2], [0u8; 2]);
        self.fprd(st, addr::DL_STATUS, &mut dl)?;
        self.fprd(st, addr::SII_CONTROL, &mut sii)?;
        let s = &mut self.slaves[position as usize];
        (s.ports.dl_status, s.esc.eeprom_status) = (DlStatus(u16::from_le_bytes(dl)), u16::from_le_bytes(sii));
        Ok(s.esc().eeprom_problem())
    }

    /// Polls AL status until `state` or an error; an error is acknowledged and reported by name.
    pub(crate) fn wait_state(&mut self, position: u16, state: AlState) -> Result<()> {
        let (st, name) = {
            let s = self.slave(position)?;
            (s.station, s.name.clone())
        };
        let deadline = self.engine.io.now_ns() + self.settings.state_timeout_ns;
        loop {
            let mut d = [0u8; 6];
            self.fprd(st, addr::AL_STATUS, &mut d)?;
            let status = AlStatus(u16::from_le_bytes([d[0], d[1]]));
            let code = AlStatusCode(u16::from_le_bytes([d[4], d[5]]));
            let error = self.slaves[position as usize].esc().al_error(status, code);
            if status.state() == Some(state) && !error {
                self.slaves[position as usize].state = state;
                tracing::debug!("slave {position} ({name}) in {}", state.name());
                return Ok(());
            }
            // An ESC whose configuration area failed to load (a wrong checksum or no EEPROM,
            // seen at the scan) cannot leave INIT: say why at once rather than after the
            // timeout, if it still has none. One still loading (a controller that emulates
            // the EEPROM and is booting) is waited for; at the timeout the reason is given.
            let timed_out = self.engine.io.now_ns() > deadline;
            if state != AlState::Init && (timed_out || self.slaves[position as usize].esc().eeprom_failed()) {
                if let Ok(Some(why)) = self.eeprom_problem_now(position) {
                    let sii_status = self.slaves[position as usize].esc.eeprom_status;
                    return Err(MasterError::State {
                        position,
                        name,
                        requested: state,
                        stayed: status.state(),
                        code,
                        cause: StateCause::EepromNotLoaded { sii_status, why },
                    });
                }
            }
            if error || timed_out {
                if error {
                    // Acknowledge, so that the slave accepts requests again.
                    let ack = status.state_bits() as u16 | AlStatus::ERROR;
                    let _ = self.engine.one(
                        Command::FPWR,
                        Address::Device { adp: st, ado: addr::AL_CONTROL },
                        &mut ack.to_le_bytes(),
                    );
                }
                tracing::debug!(
                    "slave {position} ({name}) did not reach {}: AL status {:#06x}{}",
                    state.name(),
                    status.0,
                    code_text(code)
                );
                return Err(MasterError::State {
                    position,
                    name,
                    requested: state,
                    stayed: status.state(),
                    code,
                    cause: if error { StateCause::Error } else { StateCause::Timeout },
                });
            }
            // Give the slave time between polls.
            let now = self.engine.io.now_ns();
            self.engine.io.sleep_until(now + 100_000);
        }
    }
}

impl<'a, I: Io> crate::master::part::States<'a, I> {
    /// Requests `state` from every slave and waits until all are there.
    pub fn request_state_all(&mut self, state: AlState) -> Result<()> {
        self.m.engine.one(Command::BWR, Address::Device { adp: 0, ado: addr::AL_CONTROL }, &mut [state as u8, 0])?;
        self.m.wait_state_all(state)
    }

    /// Steps every slave down for a clean stop, as a program on its way out does: SAFEOP first,
    /// where outputs take their safe state while inputs still come, then INIT, where process
    /// data and mailboxes stop. Each step waits until every slave is there.
    ///
    /// Slaves on their way back to OP after an error are left where they are (the master stops
    /// bringing them back), each request acknowledges an error with it (AL control bit 4), and a
    /// slave that misses the broadcast request (an error met on the way) is asked on its own.
    pub fn shut_down(&mut self) -> Result<()> {
        self.m.cyc.recovering = false;
        for state in [AlState::SafeOp, AlState::Init] {
            let mut request = [state as u8 | 0x10, 0];
            self.m.engine.one(Command::BWR, Address::Device { adp: 0, ado: addr::AL_CONTROL }, &mut request)?;
            for k in 0..self.m.slaves.len() as u16 {
                if self.m.wait_state(k, state).is_err() {
                    self.m.states().request_state(k, state)?;
                }
            }
        }
        Ok(())
    }

    /// Requests `state` from one slave and waits for it. A slave whose firmware has not yet
    /// read the last AL control write refuses the next (no working counter): the request is
    /// repeated until it is taken or the state timeout passes.
    pub fn request_state(&mut self, position: u16, state: AlState) -> Result<()> {
        let st = self.m.slave(position)?.station;
        let deadline = self.m.engine.io.now_ns() + self.m.settings.state_timeout_ns;
        loop {
            let mut control = [state as u8, 0];
            let wkc =
                self.m.engine.one(Command::FPWR, Address::Device { adp: st, ado: addr::AL_CONTROL }, &mut control)?;
            if wkc == 1 || self.m.engine.io.now_ns() > deadline {
                break;
            }
            let now = self.m.engine.io.now_ns();
            self.m.engine.io.sleep_until(now + 100_000);
        }
        self.m.wait_state(position, state)
    }

    /// Lets a slave be addressed by its configured station alias (0x0012, from its EEPROM) as
    /// well as by its station address (DL control bit 24), and checks that it answers to it.
    pub fn enable_alias(&mut self, position: u16) -> Result<u16> {
        let (st, alias, name) = {
            let s = self.m.slave(position)?;
            (s.station, s.alias, s.name.clone())
        };
        if alias == 0 {
            return Err(MasterError::of(position, &name, SlaveError::NoAlias));
        }
        if self
            .m
            .slaves
            .iter()
            .any(|s| s.position != position && (s.alias == alias && s.alias != 0 || s.station == alias))
        {
            return Err(MasterError::of(position, &name, SlaveError::AliasNotUnique(alias)));
        }
        let mut dl = [0u8; 4];
        self.m.fprd(st, addr::DL_CONTROL, &mut dl)?;
        dl[3] |= 0x01;
        self.m.fpwr(st, addr::DL_CONTROL, &dl)?;
        let mut check = [0u8; 2];
        self.m.engine.expect_wkc(
            Command::FPRD,
            Address::Device { adp: alias, ado: addr::STATION_ADDRESS },
            &mut check,
            1,
        )?;
        Ok(alias)
    }

    /// Requests `state` from a group of slaves at once and waits until all of them are there.
    pub fn request_state_group(&mut self, positions: &[u16], state: AlState) -> Result<()> {
        let mut bufs: Vec<[u8; 2]> = vec![[state as u8, 0]; positions.len()];
        let stations: Vec<u16> =
            positions.iter().map(|&p| self.m.slave(p).map(|s| s.station)).collect::<Result<_>>()?;
        {
            let mut p: Vec<Pdu<'_>> = stations
                .iter()
                .zip(bufs.iter_mut())
                .map(|(&st, b)| Pdu::new(Command::FPWR, Address::Device { adp: st, ado: addr::AL_CONTROL }, b))
                .collect();
            self.m.engine.transact(&mut p)?;
        }
        for &p in positions {
            self.m.wait_state(p, state)?;
        }
        Ok(())
    }

    /// Checks every slave after a cycle came back short, reports what changed once per slave,
    /// and takes one step of bringing each fallen slave back to OP (so that the cyclic exchange
    /// keeps running meanwhile). Returns how many slaves are not operational.
    ///
    /// Its frames are waited for the cyclic timeout and not sent again (the acyclic timeout,
    /// 20 ms, and its retries held the cycle up to 80 ms for one lost frame): one lost ends
    /// the pass, and the next cycle takes the step again (each step's writes are absolute
    /// values, written again as they were). The PDO assignment's SDO transfers keep the
    /// mailbox's own timeouts.
    pub fn supervise(&mut self) -> Result<usize> {
        let saved = (self.m.engine.timeout_ns, self.m.engine.retries);
        (self.m.engine.timeout_ns, self.m.engine.retries) = (self.m.settings.cyclic_timeout_ns, 0);
        let r = self.supervise_pass(saved);
        (self.m.engine.timeout_ns, self.m.engine.retries) = saved;
        match r {
            Err(crate::MasterError::Timeout { .. }) => {
                tracing::debug!("a recovery frame lost: the step is taken again at the next cycle");
                self.m.cyc.recovering = true;
                Ok(self.m.slaves.iter().filter(|s| s.health != crate::slave::Health::Operational).count())
            }
            r => r,
        }
    }

    /// [`supervise`](Self::supervise)'s pass; `acyclic`: the engine's own timeout and retries.
    fn supervise_pass(&mut self, acyclic: (u64, u32)) -> Result<usize> {
        // Only slaves the master has brought to OP can fall from it: one still on its way (a
        // frame lost while `start` walks it up) or put elsewhere on purpose is not "left OP",
        // and is not pushed back there.
        let watched: Vec<usize> = (0..self.m.slaves.len()).filter(|&k| self.m.slaves[k].state == AlState::Op).collect();
        // Every AL status in one exchange (as few frames as fit): a frame each, in a cycle of
        // 100 µs on a stock kernel, overran the next cycles and took more drives out of OP.
        let mut status = vec![[0u8; 6]; watched.len()];
        let wkcs: Vec<u16> = {
            let mut pdus: Vec<Pdu<'_>> = watched
                .iter()
                .zip(status.iter_mut())
                .map(|(&k, d)| {
                    Pdu::new(Command::FPRD, Address::Device { adp: self.m.slaves[k].station, ado: addr::AL_STATUS }, d)
                })
                .collect();
            // Within a cycle's frame timeout and not sent again: lost, as the cyclic frame may
            // have been, it is asked again after the next short cycle instead of holding the
            // cyclic loop for the acyclic timeout (20 ms) and its retries.
            match self.m.engine.transact_once(&mut pdus, self.m.settings.cyclic_timeout_ns) {
                Ok(()) => {}
                Err(crate::MasterError::Timeout { .. }) => {
                    tracing::debug!("supervision's status read lost: asked again after the next short cycle");
                    return Ok(self.m.slaves.iter().filter(|s| s.health != crate::slave::Health::Operational).count());
                }
                Err(e) => return Err(e),
            }
            pdus.iter().map(|p| p.wkc).collect()
        };
        let mut down = 0;
        for (i, &k) in watched.iter().enumerate() {
            let (st, name, pos) = (self.m.slaves[k].station, self.m.slaves[k].name.clone(), k as u16);
            let (mut d, mut wkc) = (status[i], wkcs[i]);
            if wkc == 0 {
                // Powered off and on again it has lost its station address: give it back.
                let mut a = [0u8; 2];
                if self.m.engine.one(Command::APRD, Address::position(pos, addr::STATION_ADDRESS), &mut a)? == 1
                    && a == [0, 0]
                {
                    self.m.engine.one(
                        Command::APWR,
                        Address::position(pos, addr::STATION_ADDRESS),
                        &mut st.to_le_bytes(),
                    )?;
                    wkc =
                        self.m.engine.one(Command::FPRD, Address::Device { adp: st, ado: addr::AL_STATUS }, &mut d)?;
                }
            }
            if wkc == 0 {
                if self.m.slaves[k].health != crate::slave::Health::Lost {
                    self.m.slaves[k].health = crate::slave::Health::Lost;
                    self.m.push_event(MasterEvent::Lost { position: pos, name });
                }
                down += 1;
                continue;
            }
            let status = AlStatus(u16::from_le_bytes([d[0], d[1]]));
            let code = AlStatusCode(u16::from_le_bytes([d[4], d[5]]));
            let error = self.m.slaves[k].esc().al_error(status, code);
            if status.state() == Some(AlState::Op) && !error {
                if self.m.slaves[k].health != crate::slave::Health::Operational {
                    self.m.slaves[k].health = crate::slave::Health::Operational;
                    self.m.push_event(MasterEvent::Recovered { position: pos, name });
                }
                continue;
            }
            down += 1;
            if self.m.slaves[k].health == crate::slave::Health::Operational {
                self.m.push_event(MasterEvent::LeftOp { position: pos, name, status, code });
            }
            self.m.slaves[k].health = crate::slave::Health::Recovering;
            // One step towards OP.
            if error {
                tracing::warn!(
                    "slave {pos} ({}) in {} with an error{}: acknowledged, on its way back to OP",
                    self.m.slaves[k].name,
                    status.state().map_or("an unknown state", |s| s.name()),
                    code_text(code)
                );
                let ack = status.state_bits() as u16 | AlStatus::ERROR;
                self.m.engine.one(
                    Command::FPWR,
                    Address::Device { adp: st, ado: addr::AL_CONTROL },
                    &mut ack.to_le_bytes(),
                )?;
                continue;
            }
            match status.state() {
                Some(AlState::Init) | Some(AlState::Bootstrap) | None => {
                    self.m.write_mailbox_config(pos)?;
                    self.m.engine.one(
                        Command::FPWR,
                        Address::Device { adp: st, ado: addr::AL_CONTROL },
                        &mut [AlState::PreOp as u8, 0],
                    )?;
                }
                Some(AlState::PreOp) => {
                    if self.m.slaves[k].mailbox().is_some_and(|mb| mb.has_coe()) {
                        let cyclic = (self.m.engine.timeout_ns, self.m.engine.retries);
                        (self.m.engine.timeout_ns, self.m.engine.retries) = acyclic;
                        let written: Result<()> =
                            [(0usize, true), (1, false)].into_iter().try_for_each(|(i, outputs)| {
                                match self.m.slaves[k].assignment[i].clone() {
                                    Some(p) => self.m.write_assignment(pos, outputs, &p),
                                    None => Ok(()),
                                }
                            });
                        (self.m.engine.timeout_ns, self.m.engine.retries) = cyclic;
                        written?;
                    }
                    self.m.write_process_config(pos)?;
                    self.m.engine.one(
                        Command::FPWR,
                        Address::Device { adp: st, ado: addr::AL_CONTROL },
                        &mut [AlState::SafeOp as u8, 0],
                    )?;
                }
                Some(AlState::SafeOp) | Some(AlState::Op) => {
                    self.m.engine.one(
                        Command::FPWR,
                        Address::Device { adp: st, ado: addr::AL_CONTROL },
                        &mut [AlState::Op as u8, 0],
                    )?;
                }
            }
        }
        self.m.cyc.recovering = down > 0;
        Ok(down)
    }
}
