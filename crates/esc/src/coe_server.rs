//! A CoE device: an SDO server over an object dictionary behind the mailbox, and process data
//! laid out by the PDO assignment (0x1C12/0x1C13) and mapping (0x16xx/0x1Axx) objects, so that
//! remapping really changes the process image.
use std::any::Any;
use std::collections::VecDeque;

use ferrocat_wire::coe::{
    self, AbortCode, CoeHeader, CoeMessage, CoeService, Emergency, InfoHeader, InfoOpcode, Sdo, SdoInfo,
};
use ferrocat_wire::mailbox::{Mailbox, MailboxHeader, MailboxType, HEADER_LEN as MBX_HEADER};
use ferrocat_wire::register::{AlState, AlStatusCode};

use crate::app::{Application, Pdi};
use crate::eoe_server::EoeServer;
use crate::foe_server::FoeServer;
use crate::od::ObjectDictionary;

#[derive(Debug, Clone)]
struct Upload {
    data: Vec<u8>,
    pos: usize,
    toggle: bool,
}

#[derive(Debug, Clone)]
struct Download {
    index: u16,
    sub: u8,
    complete_access: bool,
    total: usize,
    data: Vec<u8>,
    toggle: bool,
}

/// Hooks for what the device does with its objects (a drive, an I/O module).
pub trait DeviceLogic: std::fmt::Debug + Send {
    /// New outputs were copied into the dictionary.
    fn outputs(&mut self, _od: &mut ObjectDictionary, _t_ns: u64) {}
    /// SYNC0 fired.
    fn sync0(&mut self, _od: &mut ObjectDictionary, _t_ns: u64) {}
    fn state_changed(&mut self, _od: &mut ObjectDictionary, _state: AlState) {}
    fn as_any(&self) -> &dyn Any;
}

/// No behaviour beyond the dictionary.
#[derive(Debug, Default)]
pub struct PassiveLogic;

impl DeviceLogic for PassiveLogic {
    fn as_any(&self) -> &dyn Any {
        self
    }
}

#[derive(Debug)]
pub struct CoeDevice {
    pub od: ObjectDictionary,
    pub logic: Box<dyn DeviceLogic>,
    pub sm_count: u8,
    state: AlState,
    upload: Option<Upload>,
    download: Option<Download>,
    queue: VecDeque<Vec<u8>>,
    counter: u8,
    /// Station address of this device, for the mailbox header.
    pub sdo_requests: u64,
    /// The FoE file server, where the SII names FoE among the mailbox protocols.
    pub foe: Option<FoeServer>,
    /// The EoE endpoint, where the SII names EoE among the mailbox protocols.
    pub eoe: Option<EoeServer>,
    /// The SoE service channel, where the SII names SoE among the mailbox protocols.
    pub soe: Option<crate::SoeServer>,
    /// Whether it serves CoE (its SII names it). A drive that speaks SoE alone answers CoE with
    /// the mailbox error "unsupported protocol", and its process data are what its SoE
    /// telegram configuration (S-0-0016, S-0-0024) names.
    pub serves_coe: bool,
}

/// A mapped entry of the process image.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct Mapped {
    pub index: u16,
    pub sub: u8,
    pub bits: u8,
}

impl CoeDevice {
    pub fn new(od: ObjectDictionary, sm_count: u8, logic: Box<dyn DeviceLogic>) -> Self {
        CoeDevice {
            od,
            logic,
            sm_count,
            state: AlState::Init,
            upload: None,
            download: None,
            queue: VecDeque::new(),
            counter: 0,
            sdo_requests: 0,
            foe: None,
            eoe: None,
            soe: None,
            serves_coe: true,
        }
    }

    /// A frame from the host a bridged EoE endpoint stands for: its fragments, of at most
    /// `max_len` bytes of service data, queued for the master's reads of the send mailbox.
    /// `false` where the device has no EoE endpoint or the frame has no EoE form.
    pub fn eoe_from_host(&mut self, frame: &[u8], max_len: usize) -> bool {
        let Some(e) = self.eoe.as_mut() else { return false };
        let bodies = e.send(frame, max_len);
        if bodies.is_empty() {
            return false;
        }
        for b in bodies {
            let msg = self.typed_message(MailboxType::EOE, &b);
            self.queue.push_back(msg);
        }
        true
    }

    /// The CoE device an application is or holds (a drive's), if any.
    pub fn of(app: &mut dyn Application) -> Option<&mut CoeDevice> {
        let any = app.as_any_mut();
        if any.is::<CoeDevice>() {
            return any.downcast_mut::<CoeDevice>();
        }
        any.downcast_mut::<crate::Cia402Drive>().map(|d| &mut d.coe)
    }

    /// As [`CoeDevice::of`], to look at.
    pub fn of_ref(app: &dyn Application) -> Option<&CoeDevice> {
        let any = app.as_any();
        any.downcast_ref::<CoeDevice>().or_else(|| any.downcast_ref::<crate::Cia402Drive>().map(|d| &d.coe))
    }

    /// Queues an emergency message for the master.
    pub fn emergency(&mut self, e: Emergency) {
        let mut body = CoeHeader::new(CoeService::EMERGENCY).word().to_le_bytes().to_vec();
        body.extend_from_slice(&e.to_bytes());
        let msg = self.message(&body);
        self.queue.push_back(msg);
    }

    /// Queues an SoE notification (opcode 5) or emergency (opcode 6) of `drive` about `idn`
    /// with `data` (its value element) for the master; `false` where the device speaks no SoE
    /// or the drive number is no 0–7.
    pub fn soe_message(&mut self, drive: u8, idn: ferrocat_wire::soe::Idn, emergency: bool, data: &[u8]) -> bool {
        use ferrocat_wire::soe::{opcode, Elements, SoeHeader, HEADER_LEN};
        if self.soe.is_none() {
            return false;
        }
        let h = SoeHeader {
            opcode: if emergency { opcode::EMERGENCY } else { opcode::NOTIFICATION },
            incomplete: false,
            error: false,
            drive,
            elements: Elements::VALUE,
            idn: idn.0,
        };
        let mut body = vec![0u8; HEADER_LEN];
        if h.emit(&mut body).is_err() {
            return false;
        }
        body.extend_from_slice(data);
        let msg = self.typed_message(MailboxType::SOE, &body);
        self.queue.push_back(msg);
        true
    }

    /// The entries the assignment object (`0x1C12` outputs, `0x1C13` inputs) maps, in order.
    pub fn mapping(&self, outputs: bool) -> Vec<Mapped> {
        self.assigned(if outputs { 0x1C12 } else { 0x1C13 })
    }

    /// The entries the PDOs of assignment object `assign` map, in order.
    fn assigned(&self, assign: u16) -> Vec<Mapped> {
        let mut v = Vec::new();
        let n = self.od.read(assign, 0).ok().and_then(|b| b.first().copied()).unwrap_or(0);
        for k in 1..=n {
            let Ok(p) = self.od.read(assign, k) else { continue };
            let pdo = u16::from_le_bytes([p[0], *p.get(1).unwrap_or(&0)]);
            let m = self.od.read(pdo, 0).ok().and_then(|b| b.first().copied()).unwrap_or(0);
            for j in 1..=m {
                if let Ok(e) = self.od.read(pdo, j) {
                    if e.len() >= 4 {
                        let w = u32::from_le_bytes([e[0], e[1], e[2], e[3]]);
                        v.push(Mapped { index: (w >> 16) as u16, sub: (w >> 8) as u8, bits: w as u8 });
                    }
                }
            }
        }
        v
    }

    fn image_bits(&self, outputs: bool) -> u32 {
        self.mapping(outputs).iter().map(|m| m.bits as u32).sum()
    }

    pub(crate) fn copy_outputs(&mut self, buf: &[u8]) {
        let mut bit = 0usize;
        for m in self.mapping(true) {
            if m.index != 0 {
                if let Some(e) = self.od.objects.get_mut(&m.index).and_then(|o| o.entry_mut(m.sub)) {
                    for b in 0..m.bits as usize {
                        let v = buf.get((bit + b) / 8).is_some_and(|x| x >> ((bit + b) % 8) & 1 == 1);
                        if let Some(t) = e.value.get_mut(b / 8) {
                            *t = (*t & !(1 << (b % 8))) | ((v as u8) << (b % 8));
                        }
                    }
                }
            }
            bit += m.bits as usize;
        }
    }

    /// The process image the dictionary holds for the outputs (as the device last received
    /// them; padding reads 0) or the inputs.
    pub fn image(&self, outputs: bool) -> Vec<u8> {
        let bits = self.image_bits(outputs) as usize;
        let mut buf = vec![0u8; bits.div_ceil(8)];
        let mut bit = 0usize;
        for m in self.mapping(outputs) {
            if let Some(e) = self.od.get(m.index).and_then(|o| o.entry(m.sub)) {
                for b in 0..m.bits as usize {
                    if e.value.get(b / 8).is_some_and(|x| x >> (b % 8) & 1 == 1) {
                        buf[(bit + b) / 8] |= 1 << ((bit + b) % 8);
                    }
                }
            }
            bit += m.bits as usize;
        }
        buf
    }

    /// Writes the input image into the input SyncManager's buffer.
    pub fn publish_inputs(&self, pdi: &mut Pdi<'_>) {
        if let Some((_, sm)) = pdi.process_data_sm(false, self.sm_count) {
            let img = self.image(false);
            let n = img.len().min(sm.length as usize);
            pdi.write(sm.start, &img[..n]);
        }
    }

    fn message(&mut self, coe_body: &[u8]) -> Vec<u8> {
        self.typed_message(MailboxType::COE, coe_body)
    }

    fn typed_message(&mut self, mailbox_type: MailboxType, body: &[u8]) -> Vec<u8> {
        self.counter = ferrocat_wire::mailbox::next_counter(self.counter);
        let mut v = MailboxHeader::new(mailbox_type, body.len() as u16, self.counter).to_bytes().to_vec();
        v.extend_from_slice(body);
        v
    }

    fn sdo_reply(&mut self, sdo: Sdo<'_>) -> Vec<u8> {
        let mut body = vec![0u8; 2 + 8 + sdo_len(&sdo)];
        CoeHeader::new(sdo.service()).emit(&mut body).ok();
        let n = sdo.emit(&mut body[2..]).unwrap_or(0);
        body.truncate(2 + n);
        self.message(&body)
    }

    fn abort(&mut self, index: u16, subindex: u8, code: AbortCode) -> Vec<u8> {
        self.upload = None;
        self.download = None;
        self.sdo_reply(Sdo::Abort { index, subindex, code })
    }

    fn handle_sdo(&mut self, sdo: Sdo<'_>, mbx_len: usize) -> Vec<u8> {
        self.sdo_requests += 1;
        // Largest data in a normal response and in a segment (esc-spec §6.3).
        let first_max = mbx_len.saturating_sub(MBX_HEADER + 2 + 8).max(1);
        let seg_max = mbx_len.saturating_sub(MBX_HEADER + 2 + 1).max(7);
        match sdo {
            Sdo::UploadRequest { index, subindex, complete_access, .. } => {
                let data = if complete_access {
                    self.od.read_complete(index, subindex)
                } else {
                    self.od.read(index, subindex).map(|d| d.to_vec())
                };
                let data = match data {
                    Ok(d) => d,
                    Err(code) => return self.abort(index, subindex, code),
                };
                if data.len() <= 4 && !data.is_empty() {
                    let mut four = [0u8; 4];
                    four[..data.len()].copy_from_slice(&data);
                    return self.sdo_reply(Sdo::UploadExpeditedResponse {
                        index,
                        subindex,
                        complete_access,
                        size: Some(data.len() as u8),
                        data: four,
                    });
                }
                let first = data.len().min(first_max);
                let reply = self.sdo_reply(Sdo::UploadNormalResponse {
                    index,
                    subindex,
                    complete_access,
                    complete_size: data.len() as u32,
                    data: &data[..first],
                });
                self.upload = (first < data.len()).then_some(Upload { data, pos: first, toggle: false });
                reply
            }
            Sdo::UploadSegmentRequest { toggle, .. } => {
                let Some(mut up) = self.upload.take() else { return self.abort(0, 0, AbortCode::INVALID_COMMAND) };
                if toggle != up.toggle {
                    return self.abort(0, 0, AbortCode::TOGGLE_BIT);
                }
                let n = (up.data.len() - up.pos).min(seg_max);
                let mut seg = up.data[up.pos..up.pos + n].to_vec();
                let unused = if n < 7 { (7 - n) as u8 } else { 0 };
                seg.resize(n.max(7), 0);
                up.pos += n;
                let last = up.pos >= up.data.len();
                let reply = self.sdo_reply(Sdo::UploadSegmentResponse { toggle, last, unused, segment: &seg });
                up.toggle = !up.toggle;
                if !last {
                    self.upload = Some(up);
                }
                reply
            }
            Sdo::DownloadExpeditedRequest { index, subindex, complete_access, size, data } => {
                let len = match size {
                    Some(s) => s as usize,
                    None => self.od.read(index, subindex).map(|d| d.len().min(4)).unwrap_or(4),
                };
                self.commit(index, subindex, complete_access, data[..len].to_vec())
            }
            Sdo::DownloadNormalRequest { index, subindex, complete_access, complete_size, data } => {
                let total = complete_size as usize;
                if data.len() >= total {
                    return self.commit(index, subindex, complete_access, data[..total].to_vec());
                }
                self.download =
                    Some(Download { index, sub: subindex, complete_access, total, data: data.to_vec(), toggle: false });
                self.sdo_reply(Sdo::DownloadResponse { index, subindex, complete_access, reserved: [0; 4] })
            }
            s @ Sdo::DownloadSegmentRequest { toggle, last, .. } => {
                let Some(mut dl) = self.download.take() else { return self.abort(0, 0, AbortCode::INVALID_COMMAND) };
                if toggle != dl.toggle {
                    return self.abort(dl.index, dl.sub, AbortCode::TOGGLE_BIT);
                }
                dl.data.extend_from_slice(s.segment_data().unwrap_or(&[]));
                if dl.data.len() > dl.total {
                    return self.abort(dl.index, dl.sub, AbortCode::LENGTH_TOO_HIGH);
                }
                if last {
                    if dl.data.len() != dl.total {
                        return self.abort(dl.index, dl.sub, AbortCode::LENGTH_TOO_LOW);
                    }
                    let r = self.commit_checked(dl.index, dl.sub, dl.complete_access, &dl.data);
                    return match r {
                        Ok(()) => self.sdo_reply(Sdo::DownloadSegmentResponse { toggle, reserved: [0; 7] }),
                        Err(code) => self.abort(dl.index, dl.sub, code),
                    };
                }
                dl.toggle = !dl.toggle;
                self.download = Some(dl);
                self.sdo_reply(Sdo::DownloadSegmentResponse { toggle, reserved: [0; 7] })
            }
            Sdo::Abort { .. } => {
                self.upload = None;
                self.download = None;
                Vec::new()
            }
            _ => self.abort(0, 0, AbortCode::INVALID_COMMAND),
        }
    }

    fn commit_checked(&mut self, index: u16, sub: u8, ca: bool, data: &[u8]) -> Result<(), AbortCode> {
        if ca {
            self.od.write_complete(index, sub, data, self.state)
        } else {
            self.od.write(index, sub, data, self.state)
        }
    }

    fn commit(&mut self, index: u16, subindex: u8, complete_access: bool, data: Vec<u8>) -> Vec<u8> {
        match self.commit_checked(index, subindex, complete_access, &data) {
            Ok(()) => self.sdo_reply(Sdo::DownloadResponse { index, subindex, complete_access, reserved: [0; 4] }),
            Err(code) => self.abort(index, subindex, code),
        }
    }

    fn info_messages(&mut self, req: SdoInfo<'_>, mbx_len: usize) -> Vec<Vec<u8>> {
        let room = mbx_len.saturating_sub(MBX_HEADER + 2 + InfoHeader::LEN).max(2);
        let header =
            |opcode, incomplete, fragments_left| InfoHeader { opcode, incomplete, reserved: 0, fragments_left };
        let mut bodies: Vec<Vec<u8>> = Vec::new();
        let push = |bodies: &mut Vec<Vec<u8>>, info: SdoInfo<'_>| {
            let mut b = vec![0u8; 4096];
            CoeHeader::new(CoeService::SDO_INFORMATION).emit(&mut b).ok();
            let n = info.emit(&mut b[2..]).unwrap_or(0);
            b.truncate(2 + n);
            bodies.push(b);
        };
        match req {
            SdoInfo::OdListRequest { list_type, .. } => {
                let pick = |f: &dyn Fn(&crate::od::Object) -> bool| -> Vec<u16> {
                    self.od.objects.values().filter(|o| f(o)).map(|o| o.index).collect()
                };
                let mut data = list_type.to_le_bytes().to_vec();
                let lists: [Vec<u16>; 5] = [
                    pick(&|_| true),
                    pick(&|o| o.entries.iter().any(|e| e.access.rx_mappable)),
                    pick(&|o| o.entries.iter().any(|e| e.access.tx_mappable)),
                    Vec::new(),
                    Vec::new(),
                ];
                match list_type {
                    0 => lists.iter().for_each(|l| data.extend_from_slice(&(l.len() as u16).to_le_bytes())),
                    1..=5 => {
                        lists[list_type as usize - 1].iter().for_each(|i| data.extend_from_slice(&i.to_le_bytes()))
                    }
                    _ => {
                        push(
                            &mut bodies,
                            SdoInfo::Error {
                                header: header(InfoOpcode::ERROR_REQUEST, false, 0),
                                code: AbortCode::VALUE_RANGE,
                            },
                        );
                        return bodies.into_iter().map(|b| self.message(&b)).collect();
                    }
                }
                let room = room & !1;
                let chunks: Vec<&[u8]> = data.chunks(room).collect();
                let total = chunks.len();
                for (k, c) in chunks.iter().enumerate() {
                    let left = (total - 1 - k) as u16;
                    push(
                        &mut bodies,
                        SdoInfo::OdListResponse {
                            header: header(InfoOpcode::GET_OD_LIST_RESPONSE, left > 0, left),
                            data: c,
                        },
                    );
                }
            }
            SdoInfo::ObjectDescriptionRequest { index, .. } => match self.od.get(index) {
                Some(o) => push(
                    &mut bodies,
                    SdoInfo::ObjectDescriptionResponse {
                        header: header(InfoOpcode::GET_OBJECT_DESCRIPTION_RESPONSE, false, 0),
                        index,
                        data_type: o.data_type,
                        max_subindex: o.max_subindex(),
                        object_code: o.code as u8,
                        name: o.name.as_bytes(),
                    },
                ),
                None => push(
                    &mut bodies,
                    SdoInfo::Error { header: header(InfoOpcode::ERROR_REQUEST, false, 0), code: AbortCode::NO_OBJECT },
                ),
            },
            SdoInfo::EntryDescriptionRequest { index, subindex, .. } => {
                match self.od.get(index).map(|o| o.entry(subindex)) {
                    Some(Some(e)) => push(
                        &mut bodies,
                        SdoInfo::EntryDescriptionResponse {
                            header: header(InfoOpcode::GET_ENTRY_DESCRIPTION_RESPONSE, false, 0),
                            index,
                            subindex,
                            value_info: 0,
                            data_type: e.data_type,
                            bit_length: e.bit_len,
                            object_access: e.access.word(),
                            rest: e.name.as_bytes(),
                        },
                    ),
                    Some(None) => push(
                        &mut bodies,
                        SdoInfo::Error {
                            header: header(InfoOpcode::ERROR_REQUEST, false, 0),
                            code: AbortCode::NO_SUBINDEX,
                        },
                    ),
                    None => push(
                        &mut bodies,
                        SdoInfo::Error {
                            header: header(InfoOpcode::ERROR_REQUEST, false, 0),
                            code: AbortCode::NO_OBJECT,
                        },
                    ),
                }
            }
            _ => push(
                &mut bodies,
                SdoInfo::Error {
                    header: header(InfoOpcode::ERROR_REQUEST, false, 0),
                    code: AbortCode::INVALID_COMMAND,
                },
            ),
        }
        bodies.into_iter().map(|b| self.message(&b)).collect()
    }
}

fn sdo_len(s: &Sdo<'_>) -> usize {
    match s {
        Sdo::UploadNormalResponse { data, .. } | Sdo::DownloadNormalRequest { data, .. } => data.len(),
        Sdo::UploadSegmentResponse { segment, .. } | Sdo::DownloadSegmentRequest { segment, .. } => segment.len(),
        _ => 0,
    }
}

impl Application for CoeDevice {
    fn check_transition(&mut self, _pdi: &mut Pdi<'_>, from: AlState, to: AlState) -> Result<(), AlStatusCode> {
        // A modular device (ETG.5001) refuses SAFEOP while the modules the master configured
        // (0xF030, once written) are not those detected (0xF050).
        if from == AlState::PreOp && to == AlState::SafeOp {
            let list = |index| -> Option<Vec<u8>> {
                let o = self.od.get(index)?;
                let n = *o.entry(0)?.value.first()?;
                Some((1..=n).flat_map(|k| o.entry(k).map_or(vec![], |e| e.value.clone())).collect())
            };
            if let (Some(configured), Some(detected)) = (list(0xF030), list(0xF050)) {
                if !configured.is_empty() && configured != detected {
                    return Err(AlStatusCode::MODULE_IDENT_LIST_MISMATCH);
                }
            }
        }
        Ok(())
    }
    fn process_data_bytes(&self, sm: u8, outputs: bool) -> Option<u16> {
        if let (false, Some(soe)) = (self.serves_coe, &self.soe) {
            // IEC 61800-7-304: the MDT goes to the outputs' SyncManager, the AT comes from the
            // inputs'.
            return if sm <= 3 { soe.telegram_bytes(outputs) } else { Some(0) };
        }
        // SyncManager n's PDOs are those of its assignment object, 0x1C10 + n (ETG.1000.6): a
        // TwinSAFE controller's SM6 beside SM2. Where SM2 or SM3 is not the direction's
        // SyncManager, 0x1C12 and 0x1C13 still say what the outputs and inputs carry; a further
        // SyncManager without an object of its own carries nothing.
        let own = 0x1C10 + sm as u16;
        let bits = if own != 0x1C12 && own != 0x1C13 && self.od.get(own).is_some() {
            self.assigned(own).iter().map(|m| m.bits as u32).sum()
        } else if sm <= 3 {
            self.image_bits(outputs)
        } else {
            0
        };
        Some(bits.div_ceil(8) as u16)
    }
    fn state_changed(&mut self, pdi: &mut Pdi<'_>, state: AlState) {
        self.state = state;
        // The mailbox counts afresh from INIT: the AKD's replies in twincat-akd-nc-mode are
        // numbered 1, 2 in each of TwinCAT's four sessions.
        if state == AlState::Init {
            self.counter = 0;
        }
        self.logic.state_changed(&mut self.od, state);
        if matches!(state, AlState::SafeOp | AlState::Op) {
            self.publish_inputs(pdi);
        }
    }
    fn outputs_written(&mut self, pdi: &mut Pdi<'_>, sm: u8) {
        let s = pdi.sm(sm);
        let buf = pdi.read(s.start, s.length as usize).to_vec();
        self.copy_outputs(&buf);
        self.logic.outputs(&mut self.od, pdi.now_ns());
        self.publish_inputs(pdi);
    }
    fn sync0(&mut self, pdi: &mut Pdi<'_>, _sys_ns: u64) {
        self.logic.sync0(&mut self.od, pdi.now_ns());
        self.publish_inputs(pdi);
    }
    fn mailbox(&mut self, pdi: &mut Pdi<'_>, request: &[u8]) -> Option<Vec<u8>> {
        let m = Mailbox::parse(request).ok()?;
        if m.header.mailbox_type == MailboxType::FOE {
            let out_len = pdi.sm(0).length as usize;
            let in_len = pdi.process_mailbox_len();
            let reply = self.foe.as_mut()?.handle(m.payload, out_len, in_len);
            return Some(if reply.is_empty() { reply } else { self.typed_message(MailboxType::FOE, &reply) });
        }
        // In BOOT a device's bootloader serves file access only.
        if self.state == AlState::Bootstrap {
            return None;
        }
        if m.header.mailbox_type == MailboxType::EOE {
            let max_len = pdi.process_mailbox_len().saturating_sub(MBX_HEADER);
            let bodies = self.eoe.as_mut()?.handle(m.payload, max_len);
            let mut msgs: VecDeque<Vec<u8>> = bodies.iter().map(|b| self.typed_message(MailboxType::EOE, b)).collect();
            let first = msgs.pop_front().unwrap_or_default();
            self.queue.extend(msgs);
            return Some(first);
        }
        if m.header.mailbox_type == MailboxType::SOE {
            let in_len = pdi.process_mailbox_len();
            let state = self.state;
            let bodies = self.soe.as_mut()?.handle(m.payload, in_len, state);
            let mut msgs: VecDeque<Vec<u8>> = bodies.iter().map(|b| self.typed_message(MailboxType::SOE, b)).collect();
            // A fragment of a write is taken without a reply (an empty one: handled).
            let first = msgs.pop_front().unwrap_or_default();
            self.queue.extend(msgs);
            return Some(first);
        }
        if m.header.mailbox_type != MailboxType::COE {
            return None;
        }
        if !self.serves_coe {
            // The ESC answers "unsupported protocol".
            return None;
        }
        let mbx_len = pdi.process_mailbox_len();
        let reply = match coe::parse(m.payload) {
            Ok((_, CoeMessage::Sdo(s))) => self.handle_sdo(s, mbx_len),
            Ok((_, CoeMessage::Information(i))) => {
                let mut msgs = self.info_messages(i, mbx_len);
                let first = if msgs.is_empty() { Vec::new() } else { msgs.remove(0) };
                self.queue.extend(msgs);
                first
            }
            _ => {
                // A CoE service we do not serve: mailbox error "service not supported".
                let mut v = MailboxHeader::new(MailboxType::ERR, 4, m.header.counter).to_bytes().to_vec();
                v.extend_from_slice(&ferrocat_wire::mailbox::MailboxErrorCode::SERVICE_NOT_SUPPORTED.to_bytes());
                v
            }
        };
        (!reply.is_empty()).then_some(reply)
    }
    fn pending_mailbox(&mut self) -> Option<Vec<u8>> {
        self.queue.pop_front()
    }
    fn as_any(&self) -> &dyn Any {
        self
    }
    fn as_any_mut(&mut self) -> &mut dyn Any {
        self
    }
}
