//! Bring-up: finding the slaves, reading what they are, configuring mailboxes and process data,
//! and walking them through the AL states.
use ferrocat_wire::register::addr;
use ferrocat_wire::register::{AlState, DlStatus};
use ferrocat_wire::sii::SiiInfo;
use ferrocat_wire::{Address, Command};

use crate::engine::{Engine, EngineStats, Pdu, RingState, SlaveTag, SplitRingClocks};
use crate::error::{MasterError, Result};
use crate::io::Io;
use crate::slave::{DcInfo, EscInfo, Identity, MailboxConfig, Ports, Slave};

mod clock;
pub(crate) use clock::loop_of;
mod delays;
mod far_steer;
mod groups;
mod init_cmds;
mod modules;
mod next_frame_latch;
pub mod part;
mod process_data;
pub(crate) use process_data::{WATCHDOG_DIVIDER, WATCHDOG_STEP_NS};
mod sii;
mod speed_direction;
mod split_start;
mod states;

use crate::event::MasterEvent;
use crate::settings::Settings;
pub use far_steer::FarReferenceKept;
pub use groups::Group;
pub use part::{Acyclic, Clock, Config, Cyclic, Dc, Diagnosis, Image, States};
pub use sii::Eeprom;
pub use split_start::SplitLatch;

/// First station address; slave k gets `STATION_BASE + k` (SOEM's convention).
pub const STATION_BASE: u16 = 0x1001;

#[derive(Debug)]
/// An EtherCAT master on the world `I`: its slaves, its process image, its events.
pub struct Master<I: Io> {
    pub(crate) engine: Engine<I>,
    pub(crate) settings: Settings,
    /// The slaves found by the scan, by position.
    pub(crate) slaves: crate::slave::Slaves,
    /// The process image: all outputs, then all inputs.
    pub(crate) image: Vec<u8>,
    /// Bytes of outputs in the image.
    pub(crate) out_bytes: u32,
    /// Bytes of inputs in the image.
    pub(crate) in_bytes: u32,
    /// The LRW working counter a complete cycle gives: 2 per slave with outputs, 1 per slave
    /// with inputs.
    pub(crate) expected_wkc: u16,
    /// What happened during cyclic operation, in order (see [`States::supervise`](crate::part::States::supervise)). Kept until
    /// taken: a loop that runs for long takes them now and then ([`Diagnosis::take_events`](crate::part::Diagnosis::take_events)).
    pub(crate) events: Vec<MasterEvent>,
    pub(crate) cyc: crate::cycle_state::CycleState,
    /// Device descriptions from ESI files: the PDO mapping of slaves whose CoE and SII do not
    /// give one (vendor, device).
    pub(crate) esi: Vec<(u32, ferrocat_esi::Device)>,
    /// Station address of the reference clock when the cycle distributes it (FRMW of 0x0910).
    pub(crate) dc_reference: Option<u16>,
    /// The reference clock's system time as the last cycle's FRMW read it.
    pub(crate) dc_time: u64,
    pub(crate) frmw: [u8; 8],
    /// Master clock → DC system time (ns since 2000), fixed at first use.
    pub(crate) epoch_offset_ns: Option<u64>,
    /// Cable redundancy: the port (slave position, port) by which an intact ring's frames
    /// leave for the master's secondary port — a link, but no branch of the tree.
    pub(crate) ring_port: Option<(u16, u8)>,
    /// On an intact ring, how much sooner a frame is back than on the line the ring's port
    /// makes when closed (measured by `find_ring_port`; 0 otherwise).
    pub(crate) ring_shortening_ns: i64,
    /// A split ring's far reference being kept on the reference's time (`far_clock.rs`).
    pub(crate) far_steer: Option<crate::far_clock::FarSteer>,
    /// The last latch of the receive times found the ring split: the far half's delays are
    /// from its own reference (`split_start.rs`).
    pub(crate) split_latch: Option<SplitLatch>,
    /// Positions whose receive times the last latch took from a second latch: controllers whose
    /// ports 1–3 take the frame after the write, where the first did not fit (`next_frame_latch.rs`).
    pub(crate) relatched: Vec<usize>,
    /// A clock-sync method's writes waiting to ride on the cyclic frames.
    pub(crate) dc_writes: crate::dc_writes::DcWrites,
    /// A process-data plan from outside ([`Config::set_plan`](crate::part::Config::set_plan)) and its buffers.
    pub(crate) plan: Option<(crate::plan::Plan, crate::plan::PlanBuffers)>,
    /// Slave-to-slave copies within the image ([`Cyclic::set_copies`](crate::part::Cyclic::set_copies)).
    pub(crate) copies: Vec<(crate::handle::Handle, crate::handle::Handle)>,
    /// Process-data groups ([`Config::set_groups`](crate::part::Config::set_groups)).
    pub(crate) groups: Vec<groups::Group>,
    /// Diagnosis while cyclic ([`Diagnosis::diagnose`](crate::part::Diagnosis::diagnose)).
    pub(crate) diagnosis: crate::diagnosis_state::Diagnosis,
    /// Requests beside the cycle ([`Acyclic::submit`](crate::part::Acyclic::submit)).
    pub(crate) acyclic: crate::acyclic_state::Acyclic,
}

impl<I: Io> Master<I> {
    /// A master on `io`, knowing no slave yet.
    pub fn new(io: I) -> Self {
        Master {
            engine: Engine::new(io),
            settings: Settings::default(),
            slaves: Default::default(),
            image: Vec::new(),
            out_bytes: 0,
            in_bytes: 0,
            expected_wkc: 0,
            events: Vec::new(),
            cyc: Default::default(),
            esi: Vec::new(),
            dc_reference: None,
            dc_time: 0,
            frmw: [0; 8],
            epoch_offset_ns: None,
            ring_port: None,
            ring_shortening_ns: 0,
            far_steer: None,
            split_latch: None,
            relatched: Vec::new(),
            dc_writes: Default::default(),
            plan: None,
            copies: Vec::new(),
            groups: Vec::new(),
            diagnosis: Default::default(),
            acyclic: Default::default(),
        }
    }

    /// Records an event for the application (`events`) and logs it (`tracing`, info): the
    /// application is told through `events`, the log is for whoever runs it.
    pub(crate) fn push_event(&mut self, e: MasterEvent) {
        tracing::info!("{e}");
        self.events.push(e);
    }

    /// The slave at `position`, or an error saying how many there are.
    pub(crate) fn slave(&self, position: u16) -> Result<&Slave> {
        crate::slave::slave_at(&self.slaves, position)
    }

    /// The world the master runs on.
    pub fn io(&self) -> &I {
        &self.engine.io
    }

    /// The slaves found by the scan, by position.
    pub fn slaves(&self) -> &crate::slave::Slaves {
        &self.slaves
    }

    pub(crate) fn mailboxes(&mut self) -> crate::mailbox::Mailboxes<'_, I> {
        crate::mailbox::Mailboxes {
            engine: &mut self.engine,
            slaves: &mut self.slaves,
            events: &mut self.events,
            timeout_ns: self.settings.mailbox_timeout_ns,
        }
    }

    pub(crate) fn fprd(&mut self, station: u16, ado: u16, out: &mut [u8]) -> Result<()> {
        self.engine.expect_wkc(Command::FPRD, Address::Device { adp: station, ado }, out, 1)
    }

    /// The receive times of ports 0–3 (0x0900–0x090F) of the slave at `station`.
    pub(crate) fn port_receive_times(&mut self, station: u16) -> Result<[u32; 4]> {
        let mut t = [0u8; 16];
        self.fprd(station, addr::DC_RECEIVE_TIME_PORT0, &mut t)?;
        Ok(port_times(&t))
    }

    pub(crate) fn fpwr(&mut self, station: u16, ado: u16, data: &[u8]) -> Result<()> {
        let mut d = data.to_vec();
        self.engine.expect_wkc(Command::FPWR, Address::Device { adp: station, ado }, &mut d, 1)
    }

    fn read_slave(&mut self, pos: u16, station: u16, sii_bytes: Vec<u8>) -> Result<Slave> {
        let (mut id, mut alias, mut dl, mut pdi, mut sii_status) = ([0u8; 10], [0u8; 2], [0u8; 2], [0u8; 2], [0u8; 2]);
        let mut p = [
            Pdu::new(Command::FPRD, Address::Device { adp: station, ado: addr::TYPE }, &mut id),
            Pdu::new(Command::FPRD, Address::Device { adp: station, ado: addr::STATION_ALIAS }, &mut alias),
            Pdu::new(Command::FPRD, Address::Device { adp: station, ado: addr::DL_STATUS }, &mut dl),
            Pdu::new(Command::FPRD, Address::Device { adp: station, ado: addr::PDI_CONTROL }, &mut pdi),
        ];
        // Every read must reach the one slave (on a ring asked again when short: `expect_wkc_each`).
        self.engine.expect_wkc_each(&mut p, 1).map_err(|e| match e {
            MasterError::Wkc { datagram, got, .. } => MasterError::Wkc {
                datagram,
                expected: 1,
                got,
                slaves: format!(": the identity of slave {pos} (station {station:#06x})"),
            },
            e => e,
        })?;
        let dl_status = DlStatus(u16::from_le_bytes(dl));
        if !dl_status.pdi_operational() {
            // An unconfigured ESC: the SII status says why (read only then, so that a healthy
            // segment's bring-up is the same frames as ever).
            self.fprd(station, addr::SII_CONTROL, &mut sii_status)?;
        }
        let sii =
            SiiInfo::from_image(&sii_bytes).map_err(|e| MasterError::of(pos, "?", crate::error::SlaveError::Sii(e)))?;
        let h = sii.header;
        let features = u16::from_le_bytes([id[8], id[9]]);
        let mailbox = MailboxConfig::standard(&h);
        Ok(Slave {
            position: pos,
            station,
            alias: u16::from_le_bytes(alias),
            name: sii.string(1).unwrap_or_else(|| format!("{:#010x}", h.product_code)),
            identity: Identity {
                vendor_id: h.vendor_id,
                product_code: h.product_code,
                revision: h.revision,
                serial: h.serial,
            },
            esc: EscInfo {
                kind: id[0],
                fmmu_count: id[4],
                sm_count: id[5],
                features,
                device_emulation: pdi[1] & 0x01 != 0,
                eeprom_status: u16::from_le_bytes(sii_status),
                pdi_operational: dl_status.pdi_operational(),
            },
            ports: Ports {
                dl_status,
                active: [0, 1, 2, 3].map(|p| dl_status.port_active(p)),
                descriptor: id[7],
                entry: 0,
                parent: None,
                parent_port: 0,
            },
            dc: DcInfo {
                supported: features & 0x04 != 0,
                has_system_time: features & 0x04 != 0,
                is_64bit: features & 0x08 != 0,
                ..Default::default()
            },
            mailbox,
            mbx_counter: 0,
            mbx_in_counter: 0,
            mbx_repeated: None,
            mbx_read_lost: false,
            mbx_repeats: 0,
            mapping: Default::default(),
            state: AlState::Init,
            health: Default::default(),
            assignment: [None, None],
            pd_watchdog_steps: None,
            setup: Default::default(),
            eoe: Default::default(),
            sii,
        })
    }

    /// Adds an FRMW of the reference clock's system time (the first DC slave) to every cyclic
    /// frame, as SOEM and ethercrab do; returns the reference's position.
    pub(crate) fn distribute_dc(&mut self) -> Option<u16> {
        let r = self.slaves.iter().find(|s| s.dc.has_system_time)?;
        self.dc_reference = Some(r.station);
        Some(r.position)
    }

    /// The world back, the master done with.
    pub fn into_io(self) -> I {
        self.engine.io
    }
}

/// Ports 0–3's receive times from the 16 bytes of 0x0900–0x090F.
pub(crate) fn port_times(b: &[u8; 16]) -> [u32; 4] {
    std::array::from_fn(|p| u32::from_le_bytes([b[4 * p], b[4 * p + 1], b[4 * p + 2], b[4 * p + 3]]))
}

impl<'a, I: Io> crate::master::part::Config<'a, I> {
    /// Follows `plan` instead of laying the process image out itself: its station addresses at
    /// the next [`States::scan`](crate::part::States::scan), its FMMU and SyncManager registers at the next
    /// [`States::configure`](crate::part::States::configure), its
    /// cyclic frames at every [`Cyclic::cycle`](crate::part::Cyclic::cycle) ([`crate::plan`]). Set it before the scan.
    pub fn set_plan(&mut self, plan: crate::plan::Plan) -> Result<()> {
        plan.validate()?;
        let buffers = crate::plan::PlanBuffers::for_plan(&plan);
        self.m.plan = Some((plan, buffers));
        Ok(())
    }

    /// The plan the master follows, if one was set.
    pub fn plan(self) -> Option<&'a crate::plan::Plan> {
        self.m.plan.as_ref().map(|(p, _)| p)
    }

    /// What the master waits for and does on its own.
    pub fn settings(self) -> &'a Settings {
        &self.m.settings
    }

    /// The settings, to change: they hold from the next exchange on.
    pub fn settings_mut(self) -> &'a mut Settings {
        &mut self.m.settings
    }

    /// Adds an ESI device description (`vendor`, device): the PDO mapping of slaves of that
    /// vendor and product whose CoE and SII give none, and their modules and init commands.
    pub fn add_esi(&mut self, vendor_id: u32, device: ferrocat_esi::Device) {
        self.m.esi.push((vendor_id, device));
    }
}

impl<'a, I: Io> crate::master::part::Diagnosis<'a, I> {
    /// What the master's two ports show of a ring (cable redundancy).
    pub fn ring_state(&self) -> RingState {
        self.m.engine.redundancy.state
    }

    /// The events so far, in order, leaving none: what a long-running loop calls now and then
    /// so that [`Diagnosis::events`](crate::part::Diagnosis::events)(Master) does not grow for as long as the master runs.
    pub fn take_events(&mut self) -> Vec<MasterEvent> {
        std::mem::take(&mut self.m.events)
    }

    /// What happened during cyclic operation, in order (see [`States::supervise`](crate::part::States::supervise)), until
    /// taken ([`Diagnosis::take_events`](crate::part::Diagnosis::take_events)).
    pub fn events(self) -> &'a [MasterEvent] {
        &self.m.events
    }
}

impl<'a, I: Io> crate::master::part::Cyclic<'a, I> {
    /// The image's outputs, to write (the next cycle sends them): the first
    /// [`Image::byte_counts`](crate::part::Image::byte_counts)`().0` bytes of the image.
    pub fn outputs_mut(self) -> &'a mut [u8] {
        let n = (self.m.out_bytes as usize).min(self.m.image.len());
        &mut self.m.image[..n]
    }
}

impl<'a, I: Io> crate::master::part::Dc<'a, I> {
    /// On a broken ring, how the far half gets its clock.
    pub fn set_split_ring_clocks(&mut self, clocks: SplitRingClocks) {
        self.m.engine.redundancy.clocks = clocks;
    }

    /// Station address of the reference clock when the cycle distributes it (FRMW of 0x0910).
    pub fn dc_reference(&self) -> Option<u16> {
        self.m.dc_reference
    }

    /// Cable redundancy: the port (slave position, port) by which an intact ring's frames
    /// leave for the master's secondary port — a link, but no branch of the tree.
    pub fn ring_port(&self) -> Option<(u16, u8)> {
        self.m.ring_port
    }

    /// On an intact ring, how much sooner a frame is back than on the line the ring's port
    /// makes when closed, in ns (0 otherwise).
    pub fn ring_shortening_ns(&self) -> i64 {
        self.m.ring_shortening_ns
    }

    /// Where the last latch of the receive times found the ring split, if it did.
    pub fn split_latch(self) -> Option<&'a SplitLatch> {
        self.m.split_latch.as_ref()
    }

    /// Positions whose receive times the last latch took from a second latch: controllers
    /// whose ports 1–3 take the frame after the write.
    pub fn relatched(self) -> &'a [usize] {
        &self.m.relatched
    }
}

impl<'a, I: Io> crate::master::part::Acyclic<'a, I> {
    /// The CoE client: SDO upload and download, SDO information (each call waits up to
    /// `mailbox_timeout_ns` for room and for the reply).
    pub fn coe(self) -> crate::coe::Coe<'a, I> {
        crate::coe::Coe { mbx: self.m.mailboxes() }
    }

    /// The SoE client: IDNs of a servo drive (AX5000, IndraDrive and others).
    pub fn soe(self) -> crate::soe::Soe<'a, I> {
        crate::soe::Soe { mbx: self.m.mailboxes() }
    }

    /// Reads every CoE slave's send mailbox once: emergencies waiting there become events.
    /// Returns how many messages were read.
    pub fn poll_mailboxes(&mut self) -> Result<usize> {
        self.m.mailboxes().poll_all()
    }
}

impl<'a, I: Io> crate::master::part::States<'a, I> {
    /// Finds the slaves and reads everything about them: count, station addresses, identity
    /// and the whole SII, ESC features, DL status and topology, DC receive times and delays.
    pub fn scan(&mut self) -> Result<()> {
        // Reset: every slave to INIT, DL control default, no FMMUs/SMs (as SOEM and IgH do).
        let mut buf = [0u8; 2];
        let mut count = self.m.engine.one(Command::BRD, Address::Device { adp: 0, ado: 0 }, &mut buf)?;
        // With a second port, a probe that came back too late (a slow or busy segment) leaves
        // the count at the near half of a broken ring: count again, up to three times, until
        // a probe has come back (a second port with nothing on it never answers one).
        for _ in 0..3 {
            if !self.m.engine.io.has_secondary() || self.m.engine.secondary_alive() {
                break;
            }
            self.m.engine.expect_secondary(true);
            count = self.m.engine.one(Command::BRD, Address::Device { adp: 0, ado: 0 }, &mut buf)?;
        }
        if count == 0 {
            return Err(MasterError::NoSlaves);
        }
        tracing::info!("{count} slave(s) answer; to INIT, station addresses from {STATION_BASE:#06x}");
        self.m.engine.one(Command::BWR, Address::Device { adp: 0, ado: addr::AL_CONTROL }, &mut [0x11, 0])?;
        self.m.engine.one(Command::BWR, Address::Device { adp: 0, ado: addr::FMMU0 }, &mut [0u8; 256])?;
        self.m.engine.one(Command::BWR, Address::Device { adp: 0, ado: addr::SM0 }, &mut [0u8; 128])?;
        self.m.slaves.all.clear();
        let planned = |pos: u16| self.m.plan.as_ref().and_then(|(p, _)| p.stations.get(pos as usize).copied());
        let stations: Vec<u16> = (0..count).map(|p| planned(p).unwrap_or(STATION_BASE + p)).collect();
        for pos in 0..count {
            let station = stations[pos as usize];
            self.m.engine.expect_wkc(
                Command::APWR,
                Address::position(pos, addr::STATION_ADDRESS),
                &mut station.to_le_bytes(),
                1,
            )?;
        }
        // On an intact ring a slave the primary's frames pass without processing (entered by a
        // port other than 0, whose port 0 leads on round the ring) answers only the
        // secondary's probe: it would be missing from every count and every image.
        if self.m.engine.redundancy.state == crate::engine::RingState::Intact
            && self.m.engine.redundancy.backward_wkc > 0
        {
            return Err(crate::error::ConfigError::RingCabledBackwards(self.m.engine.redundancy.backward_wkc).into());
        }
        let images = self.m.read_all_sii(&stations)?;
        for (pos, img) in images.into_iter().enumerate() {
            let slave = self.m.read_slave(pos as u16, stations[pos], img)?;
            tracing::debug!(
                "slave {pos} ({}): vendor {:#010x} product {:#010x} revision {:#010x}, station {:#06x}{}",
                slave.name,
                slave.identity.vendor_id,
                slave.identity.product_code,
                slave.identity.revision,
                slave.station,
                if slave.esc.device_emulation { ", device emulation" } else { "" }
            );
            self.m.slaves.all.push(slave);
        }
        self.m.engine.directory = self
            .m
            .slaves
            .iter()
            .map(|s| SlaveTag { position: s.position, station: s.station, alias: s.alias, name: s.name.clone() })
            .collect();
        self.m.wait_state_all(AlState::Init)?;
        self.m.find_ring_port()?;
        self.m.topology();
        self.m.measure_delays()?;
        Ok(())
    }
}

impl<'a, I: Io> crate::master::part::Cyclic<'a, I> {
    /// The world the master runs on, to change (a simulator's faults, a recording's file).
    pub fn io_mut(self) -> &'a mut I {
        &mut self.m.engine.io
    }

    /// Counts of the frames sent, received, lost, late and retried so far.
    pub fn frame_stats(&self) -> EngineStats {
        self.m.engine.stats
    }

    /// One datagram as given, sent now and waited for with the engine's retries; returns its
    /// working counter. For registers the master has no call for (SOEM's `ec_FPRD` and
    /// kin); writing to registers the master manages can break what it keeps.
    pub fn datagram(&mut self, cmd: Command, address: Address, data: &mut [u8]) -> Result<u16> {
        self.m.engine.one(cmd, address, data)
    }

    /// [`Cyclic::datagram`](crate::part::Cyclic::datagram) that must reach `expected` slaves: a shortfall is an error naming
    /// the datagram and the slave it was meant for.
    pub fn expect_datagram(&mut self, cmd: Command, address: Address, data: &mut [u8], expected: u16) -> Result<()> {
        self.m.engine.expect_wkc(cmd, address, data, expected)
    }

    /// The world's clock now, ns (CLOCK_MONOTONIC on a real link).
    pub fn now_ns(&mut self) -> u64 {
        self.m.engine.io.now_ns()
    }

    /// Sleeps until `t_ns` of [`Cyclic::now_ns`](crate::part::Cyclic::now_ns)'s clock (absolute, so that a cyclic loop
    /// keeps its period however long each cycle took).
    pub fn sleep_until(&mut self, t_ns: u64) {
        self.m.engine.io.sleep_until(t_ns)
    }
}

impl<'a, I: Io> crate::master::part::Image<'a, I> {
    /// The process image: all outputs, then all inputs.
    pub fn bytes(self) -> &'a [u8] {
        &self.m.image
    }

    /// Bytes of outputs and of inputs in the image.
    pub fn byte_counts(&self) -> (u32, u32) {
        (self.m.out_bytes, self.m.in_bytes)
    }

    /// The LRW working counter a complete cycle gives: 2 per slave with outputs, 1 per slave
    /// with inputs.
    pub fn expected_wkc(&self) -> u16 {
        self.m.expected_wkc
    }
}
