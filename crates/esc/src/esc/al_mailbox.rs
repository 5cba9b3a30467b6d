//! The firmware's side of AL control and of the mailbox SyncManagers.
use ferrocat_wire::register::{AlState, AlStatusCode, SyncManager};
use ferrocat_wire::sii::SmEntry;
use rand::{Rng, SeedableRng};
use rand_chacha::ChaCha8Rng;

use super::{sm_area, unsupported_protocol_reply, Esc};
use crate::app::Pdi;

impl Esc {
    pub(super) fn al_control(&mut self, control: u16) {
        let before = self.al.clone();
        if self.device_emulation() {
            self.al.copy_control(control);
        } else {
            let mut expected = self.expected.clone();
            for (n, e, len) in expected.process_data.iter_mut() {
                if let Some(b) = self.app.process_data_bytes(*n, e.sm_type == SmEntry::TYPE_OUTPUTS) {
                    *len = b;
                }
            }
            let sms: Vec<SyncManager> = (0..self.config.sm_count).map(|n| self.sm(n)).collect();
            let Esc { app, mem, now_ns, .. } = self;
            let mut check = |from: AlState, to: AlState| -> Result<(), AlStatusCode> {
                // SM0 and SM1 as the SII's (standard or bootstrap) mailbox.
                let mailbox_as = |(out, inp): &(SmEntry, SmEntry)| {
                    let good = |s: Option<&SyncManager>, e: &SmEntry, writes: bool| {
                        s.is_some_and(|s| {
                            s.enabled()
                                && s.is_mailbox()
                                && s.ecat_writes() == writes
                                && s.start == e.start
                                && s.length == e.length
                        })
                    };
                    good(sms.first(), out, true) && good(sms.get(1), inp, false)
                };
                if from == AlState::Init && to == AlState::PreOp {
                    if let Some(m) = &expected.mailbox {
                        if !mailbox_as(m) {
                            return Err(AlStatusCode::INVALID_MAILBOX_CONFIG);
                        }
                    }
                }
                if from == AlState::Init && to == AlState::Bootstrap {
                    match &expected.bootstrap {
                        None => return Err(AlStatusCode::BOOTSTRAP_NOT_SUPPORTED),
                        Some(m) if !mailbox_as(m) => return Err(AlStatusCode::INVALID_BOOT_MAILBOX_CONFIG),
                        Some(_) => {}
                    }
                }
                if from == AlState::PreOp && to == AlState::SafeOp {
                    for (n, e, len) in &expected.process_data {
                        let s = sms.get(*n as usize).copied().unwrap_or_default();
                        let outputs = e.sm_type == SmEntry::TYPE_OUTPUTS;
                        let good = if *len == 0 {
                            !s.enabled() || s.length == 0
                        } else {
                            // In the operation mode the device describes: most buffer their
                            // process data (three buffers), some hand it over in one (mailbox
                            // mode: the AX2000's inputs, control byte 0x22 in its ESI).
                            s.enabled()
                                && s.length == *len
                                && s.ecat_writes() == outputs
                                && s.is_mailbox() == (e.control & 0b11 == SyncManager::MODE_MAILBOX)
                        };
                        if !good {
                            return Err(if outputs {
                                AlStatusCode::INVALID_OUTPUT_CONFIG
                            } else {
                                AlStatusCode::INVALID_INPUT_CONFIG
                            });
                        }
                    }
                }
                let mut pdi = Pdi { mem, now_ns: *now_ns };
                app.check_transition(&mut pdi, from, to)
            };
            self.al.request(control, &mut check);
        }
        if self.al.state == AlState::Op && before.state != AlState::Op {
            self.wd_last_trigger_ns = self.now_ns;
        }
        if before.error && !self.al.error {
            // The error acknowledged: the firmware gives its outputs back.
            self.pdi_deactivate_outputs(false);
        }
        if self.al != before {
            self.al_changes += 1;
            let mut pdi = Pdi { mem: &mut self.mem, now_ns: self.now_ns };
            self.app.state_changed(&mut pdi, self.al.state);
            // The firmware stops its mailbox in INIT (a new master's first counter is no repeat
            // of the last one's) and starts it on leaving INIT, the master's SyncManager
            // configuration written.
            if self.al.state == AlState::Init {
                (self.mbx_in_counter, self.mbx_repeat_at, self.mbx_request_bit) = (0, None, None);
            } else if before.state == AlState::Init {
                self.check_repeat_request();
            }
        }
    }

    /// A complete request arrived in the mailbox SM: the application answers into SM1 once the
    /// firmware's response time has passed (replies leave in the order of their requests).
    pub(super) fn mailbox_request(&mut self, sm: u8) {
        let s = self.sm(sm);
        let req = self.mem[sm_area(&s, self.mem.len())].to_vec();
        // SM0 is consumed by the PDI at once: opened (clearing the write event) and read.
        let st = &mut self.sms[sm as usize];
        st.full = false;
        st.int_write = false;
        st.int_read = true;
        // A request with the counter of the one before is that one written again by a master
        // that lost the frame after it got here (ETG.1000.4; SOEM and ours write it again as
        // it was): taken and dropped. Counter 0 is never a repeat.
        let counter = req.get(5).map_or(0, |b| (b >> 4) & 0x07);
        if counter != 0 && counter == self.mbx_in_counter {
            self.mbx_duplicates += 1;
            return;
        }
        self.mbx_in_counter = counter;
        let reply = {
            let mut pdi = Pdi { mem: &mut self.mem, now_ns: self.now_ns };
            self.app.mailbox(&mut pdi, &req)
        };
        let reply = reply.unwrap_or_else(|| unsupported_protocol_reply(&req));
        if reply.is_empty() {
            // Handled with nothing to answer (FoE's last acknowledge).
            return;
        }
        let ready = self.now_ns.saturating_add(self.mailbox_response.draw_ns());
        let ready = ready.max(self.mbx_queue.back().map_or(0, |m| m.0));
        self.mbx_queue.push_back((ready, reply));
        self.deliver_mailbox();
    }

    /// A frame from the host of a bridged EoE endpoint, queued for the master in fragments as
    /// long as the send mailbox allows. `false` where the device has no EoE endpoint, its send
    /// mailbox is not configured, or the frame has no EoE form.
    pub fn eoe_from_host(&mut self, frame: &[u8]) -> bool {
        let Some((_, s)) = self.send_mailbox() else { return false };
        let max_len = (s.length as usize).saturating_sub(ferrocat_wire::mailbox::HEADER_LEN);
        crate::CoeDevice::of(self.app.as_mut()).is_some_and(|c| c.eoe_from_host(frame, max_len))
    }

    /// The next frame a bridged EoE endpoint received from the master for its host.
    pub fn eoe_to_host(&mut self) -> Option<Vec<u8>> {
        crate::CoeDevice::of(self.app.as_mut())?.eoe.as_mut()?.to_host.pop_front()
    }

    /// Bridges the device's EoE endpoint to a host (or not): `false` where it has none.
    pub fn set_eoe_bridged(&mut self, bridged: bool) -> bool {
        let Some(e) = crate::CoeDevice::of(self.app.as_mut()).and_then(|c| c.eoe.as_mut()) else { return false };
        e.bridged = bridged;
        true
    }

    /// The send mailbox: the first mailbox SyncManager the ECAT side reads.
    fn send_mailbox(&self) -> Option<(u8, SyncManager)> {
        (0..self.config.sm_count)
            .map(|n| (n, self.sm(n)))
            .find(|(_, s)| s.enabled() && s.is_mailbox() && !s.ecat_writes())
    }

    /// The master toggled the send mailbox's repeat request (SM activate bit 1): the firmware
    /// will answer it once its response time has passed. A mailbox the firmware starts (on
    /// leaving INIT, or enabled later) takes the request bit as it finds it and acknowledges
    /// it, without a repeat (as SOES syncs its toggle when it starts the mailbox): a master's
    /// configuration writes the bit without asking for anything.
    pub(super) fn check_repeat_request(&mut self) {
        if self.al.state == AlState::Init {
            return;
        }
        let Some((n, s)) = self.send_mailbox() else {
            self.mbx_request_bit = None;
            return;
        };
        let request = s.activate & 0x02;
        match self.mbx_request_bit {
            None => {
                self.set_repeat_ack(n, request);
                self.mbx_request_bit = Some(request);
            }
            Some(seen) if seen != request => {
                self.mbx_request_bit = Some(request);
                if self.mbx_repeat_at.is_none() {
                    self.mbx_repeat_at = Some(self.now_ns.saturating_add(self.mailbox_response.draw_ns()));
                }
            }
            Some(_) => {}
        }
    }

    /// The firmware's repeat acknowledge: SyncManager `n`'s PDI control bit 1 set to `bit`.
    fn set_repeat_ack(&mut self, n: u8, bit: u8) {
        let a = ferrocat_wire::register::addr::sm(n) as usize + 7;
        self.mem[a] = (self.mem[a] & !0x02) | (bit & 0x02);
    }

    /// Moves the next waiting message into the send mailbox if it is free; a repeat request
    /// due is answered first.
    pub(super) fn deliver_mailbox(&mut self) {
        let Some((n, out)) = self.send_mailbox() else { return };
        if let Some(at) = self.mbx_repeat_at {
            if at > self.now_ns {
                return;
            }
            self.mbx_repeat_at = None;
            self.mbx_repeats += 1;
            // The message again where the master took it (and lost it); one still unread
            // stays as it is. Then the acknowledge: PDI control bit 1 as the request.
            if !self.sms[n as usize].full && !self.mbx_last.is_empty() {
                let msg = std::mem::take(&mut self.mbx_last);
                self.put_in_send_mailbox(n, &out, &msg);
                self.mbx_last = msg;
            }
            self.set_repeat_ack(n, out.activate & 0x02);
            return;
        }
        if self.sms[n as usize].full {
            return;
        }
        let msg = match self.mbx_queue.front() {
            Some(&(ready, _)) if ready > self.now_ns => return,
            Some(_) => self.mbx_queue.pop_front().map(|m| m.1),
            None => self.app.pending_mailbox(),
        };
        let Some(msg) = msg else { return };
        self.put_in_send_mailbox(n, &out, &msg);
        self.mbx_last = msg;
    }

    fn put_in_send_mailbox(&mut self, n: u8, out: &SyncManager, msg: &[u8]) {
        let area = sm_area(out, self.mem.len());
        let area = &mut self.mem[area];
        let len = area.len().min(msg.len());
        area.fill(0);
        area[..len].copy_from_slice(&msg[..len]);
        let st = &mut self.sms[n as usize];
        st.full = true;
        st.int_write = true;
        st.int_read = false;
        self.put_sm_status(n);
    }
}

/// How long a slave's firmware takes from a mailbox request to its reply: from `min` to `max`,
/// uniformly, drawn per request from its own seeded stream (0: at once, the default).
#[derive(Debug, Clone)]
pub struct MailboxResponse {
    min_ns: u64,
    max_ns: u64,
    rng: ChaCha8Rng,
}

impl Default for MailboxResponse {
    fn default() -> Self {
        MailboxResponse::uniform(0, 0, 0)
    }
}

impl MailboxResponse {
    /// From `min_ns` to `max_ns` (taken as `min_ns` if smaller).
    pub fn uniform(min_ns: u64, max_ns: u64, seed: u64) -> Self {
        MailboxResponse { min_ns, max_ns: max_ns.max(min_ns), rng: ChaCha8Rng::seed_from_u64(seed) }
    }

    fn draw_ns(&mut self) -> u64 {
        if self.max_ns == self.min_ns {
            self.min_ns
        } else {
            self.rng.gen_range(self.min_ns..=self.max_ns)
        }
    }
}
