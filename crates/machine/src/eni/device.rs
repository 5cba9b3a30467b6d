//! An ENI slave as a device description, so that a simulator can serve the slave the file
//! expects: its identity, SyncManagers, PDOs, mailbox and DC.
use ferrocat_esi::{CoeDesc, DcOpModeDesc, Device, FmmuKind, MailboxDesc, PdoDesc, PdoEntryDesc, SmDesc, SmKind};

use super::{Pdo, Slave};

impl Slave {
    /// The device this slave describes, as an ESI file would (`ferrocat_esi::Device`, whose
    /// `to_sii` gives its EEPROM image). What an ENI does not say is filled in as a
    /// configuration tool would have found it: every FMMU kind, CoE with SDO information and
    /// PDO assignment and configuration, and for a slave with `<DC>` one operation mode with
    /// SYNC0 (assign-activate 0x0300); its SoE init commands too. Its type name is the order
    /// number of `<ProductRevision>` (`EL2008-0000-0018` → `EL2008`) where given, else its name.
    pub fn to_device(&self) -> Device {
        let mut sync_managers = Vec::new();
        if let Some(m) = &self.mailbox {
            sync_managers.push(SmDesc {
                kind: SmKind::MailboxOut,
                start: m.send.0,
                default_size: Some(m.send.1),
                control: 0x26,
                enable: true,
            });
            sync_managers.push(SmDesc {
                kind: SmKind::MailboxIn,
                start: m.recv.0,
                default_size: Some(m.recv.1),
                control: 0x22,
                enable: true,
            });
        }
        let mut pd = self.process_data.sms.clone();
        pd.sort_by_key(|s| s.number);
        for sm in &pd {
            // SyncManagers are numbered by position in the SII: fill any gap before this one.
            while sync_managers.len() < sm.number as usize {
                sync_managers.push(SmDesc {
                    kind: SmKind::Unused,
                    start: 0,
                    default_size: None,
                    control: 0,
                    enable: false,
                });
            }
            let kind = match sm.kind.to_ascii_lowercase().as_str() {
                "outputs" => SmKind::Outputs,
                "inputs" => SmKind::Inputs,
                _ if sm.control & 0x0C == 0x04 => SmKind::Outputs,
                _ => SmKind::Inputs,
            };
            sync_managers.push(SmDesc {
                kind,
                start: sm.start,
                default_size: sm.default_size,
                control: sm.control,
                enable: sm.enable,
            });
        }
        let assigned = |p: &Pdo| {
            p.sm.or_else(|| self.process_data.sms.iter().find(|s| s.pdos.contains(&p.index)).map(|s| s.number))
        };
        let pdo = |p: &Pdo| PdoDesc {
            index: p.index,
            name: p.name.clone(),
            sm: assigned(p),
            fixed: p.fixed,
            entries: p
                .entries
                .iter()
                .map(|e| PdoEntryDesc {
                    index: e.index,
                    subindex: e.subindex,
                    bit_len: e.bits.min(u8::MAX as u16) as u8,
                    name: e.name.clone(),
                    data_type: e.data_type.clone().unwrap_or_default(),
                    ..Default::default()
                })
                .collect(),
            ..Default::default()
        };
        let has =
            |p: &str| self.mailbox.as_ref().is_some_and(|m| m.protocols.iter().any(|q| q.eq_ignore_ascii_case(p)));
        let mailbox = self.mailbox.as_ref().map(|_| MailboxDesc {
            coe: has("CoE").then_some(CoeDesc {
                sdo_info: true,
                pdo_assign: true,
                pdo_config: true,
                pdo_upload: false,
                complete_access: true,
            }),
            foe: has("FoE"),
            eoe: has("EoE"),
            soe: has("SoE"),
            aoe: has("AoE"),
            voe: has("VoE"),
        });
        let dc_op_modes = match self.dc {
            Some(dc) => vec![DcOpModeDesc {
                name: "DC".into(),
                description: "DC-synchronous (from the ENI)".into(),
                assign_activate: 0x0300,
                cycle_time_sync0_ns: dc.cycle_time0_ns,
                shift_time_sync0_ns: dc.shift_time_ns,
                cycle_time_sync1_ns: dc.cycle_time1_ns,
                ..Default::default()
            }],
            None => Vec::new(),
        };
        // Its SoE init commands, so that a simulator gives it the drives they address.
        let soe_init_cmds = self
            .mailbox
            .iter()
            .flat_map(|m| &m.soe_init_cmds)
            .map(|c| ferrocat_esi::SoeInitCmd {
                line: c.place.line,
                transitions: c.transitions.iter().map(|t| t.to_string()).collect(),
                drive: c.drive,
                idn: ferrocat_wire::soe::Idn(c.idn),
                elements: ferrocat_wire::soe::Elements(c.elements),
                data: c.data.clone(),
                timeout_ms: c.timeout_ms,
                comment: c.comment.clone(),
            })
            .collect();
        Device {
            line: self.place.line,
            type_name: self.type_name(),
            name: self.name.clone(),
            product_code: self.identity.product_code,
            revision: self.identity.revision,
            physics: self.physics.clone().unwrap_or_else(|| "YY".into()),
            profile_no: self.mailbox.as_ref().and_then(|m| m.profile_no),
            fmmus: vec![FmmuKind::Outputs, FmmuKind::Inputs, FmmuKind::MailboxState],
            sync_managers,
            rx_pdos: self.process_data.rx_pdos.iter().map(pdo).collect(),
            tx_pdos: self.process_data.tx_pdos.iter().map(pdo).collect(),
            mailbox,
            dc_op_modes,
            soe_init_cmds,
            ..Default::default()
        }
    }

    /// The slave's order number: `<ProductRevision>`'s first part where the file gives one,
    /// else the part of its name in brackets (`Term 1 (EK1100)`), else its name.
    pub fn type_name(&self) -> String {
        if let Some(t) = self.product_revision.as_deref().and_then(|r| r.split('-').next()).filter(|t| !t.is_empty()) {
            return t.to_string();
        }
        match (self.name.rfind('('), self.name.ends_with(')')) {
            (Some(i), true) if i + 2 < self.name.len() => self.name[i + 1..self.name.len() - 1].to_string(),
            _ => self.name.clone(),
        }
    }
}
