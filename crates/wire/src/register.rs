//! The ESC register map (esc-spec §2, §3, §5): addresses, and typed views of the registers the
//! master and the simulator touch. All multi-byte registers are little-endian.
use core::fmt;

use crate::bytes::{need, put, u16_at};
use crate::Result;

/// Register addresses.
pub mod addr {
    pub const TYPE: u16 = 0x0000;
    pub const REVISION: u16 = 0x0001;
    pub const BUILD: u16 = 0x0002;
    pub const FMMU_COUNT: u16 = 0x0004;
    pub const SM_COUNT: u16 = 0x0005;
    pub const RAM_SIZE_KB: u16 = 0x0006;
    pub const PORT_DESCRIPTOR: u16 = 0x0007;
    pub const FEATURES: u16 = 0x0008;
    pub const STATION_ADDRESS: u16 = 0x0010;
    pub const STATION_ALIAS: u16 = 0x0012;
    pub const WRITE_REGISTER_ENABLE: u16 = 0x0020;
    pub const WRITE_REGISTER_PROTECTION: u16 = 0x0021;
    pub const ESC_WRITE_ENABLE: u16 = 0x0030;
    pub const ESC_WRITE_PROTECTION: u16 = 0x0031;
    pub const ESC_RESET_ECAT: u16 = 0x0040;
    pub const ESC_RESET_PDI: u16 = 0x0041;
    pub const DL_CONTROL: u16 = 0x0100;
    pub const LOOP_CONTROL: u16 = 0x0101;
    pub const PHYSICAL_RW_OFFSET: u16 = 0x0108;
    pub const DL_STATUS: u16 = 0x0110;
    pub const AL_CONTROL: u16 = 0x0120;
    pub const AL_STATUS: u16 = 0x0130;
    pub const AL_STATUS_CODE: u16 = 0x0134;
    pub const PDI_CONTROL: u16 = 0x0140;
    pub const ESC_CONFIGURATION: u16 = 0x0141;
    pub const PDI_CONFIGURATION: u16 = 0x0150;
    pub const ECAT_EVENT_MASK: u16 = 0x0200;
    pub const AL_EVENT_MASK: u16 = 0x0204;
    pub const ECAT_EVENT_REQUEST: u16 = 0x0210;
    pub const AL_EVENT_REQUEST: u16 = 0x0220;
    pub const RX_ERROR_COUNTER: u16 = 0x0300;
    pub const FORWARDED_RX_ERROR_COUNTER: u16 = 0x0308;
    pub const PROCESSING_UNIT_ERROR_COUNTER: u16 = 0x030C;
    pub const PDI_ERROR_COUNTER: u16 = 0x030D;
    pub const LOST_LINK_COUNTER: u16 = 0x0310;
    pub const WATCHDOG_DIVIDER: u16 = 0x0400;
    pub const WATCHDOG_TIME_PDI: u16 = 0x0410;
    pub const WATCHDOG_TIME_PROCESS_DATA: u16 = 0x0420;
    pub const WATCHDOG_STATUS_PROCESS_DATA: u16 = 0x0440;
    pub const WATCHDOG_COUNTER_PROCESS_DATA: u16 = 0x0442;
    pub const WATCHDOG_COUNTER_PDI: u16 = 0x0443;
    pub const SII_CONFIG: u16 = 0x0500;
    pub const SII_PDI_ACCESS: u16 = 0x0501;
    pub const SII_CONTROL: u16 = 0x0502;
    pub const SII_ADDRESS: u16 = 0x0504;
    pub const SII_DATA: u16 = 0x0508;
    pub const MII_CONTROL: u16 = 0x0510;
    pub const FMMU0: u16 = 0x0600;
    pub const SM0: u16 = 0x0800;
    // Distributed clocks, 0x0900–0x09FF (esc-spec §3.2).
    pub const DC_RECEIVE_TIME_PORT0: u16 = 0x0900;
    pub const DC_RECEIVE_TIME_PORT1: u16 = 0x0904;
    pub const DC_RECEIVE_TIME_PORT2: u16 = 0x0908;
    pub const DC_RECEIVE_TIME_PORT3: u16 = 0x090C;
    pub const DC_SYSTEM_TIME: u16 = 0x0910;
    pub const DC_RECEIVE_TIME_EPU: u16 = 0x0918;
    pub const DC_SYSTEM_TIME_OFFSET: u16 = 0x0920;
    pub const DC_SYSTEM_TIME_DELAY: u16 = 0x0928;
    pub const DC_SYSTEM_TIME_DIFFERENCE: u16 = 0x092C;
    pub const DC_SPEED_COUNTER_START: u16 = 0x0930;
    pub const DC_SPEED_COUNTER_DIFF: u16 = 0x0932;
    pub const DC_SYSTEM_TIME_DIFF_FILTER_DEPTH: u16 = 0x0934;
    pub const DC_SPEED_COUNTER_FILTER_DEPTH: u16 = 0x0935;
    pub const DC_RECEIVE_TIME_LATCH_MODE: u16 = 0x0936;
    pub const DC_CYCLIC_UNIT_CONTROL: u16 = 0x0980;
    pub const DC_ACTIVATION: u16 = 0x0981;
    pub const DC_PULSE_LENGTH: u16 = 0x0982;
    pub const DC_ACTIVATION_STATUS: u16 = 0x0984;
    pub const DC_SYNC0_STATUS: u16 = 0x098E;
    pub const DC_SYNC1_STATUS: u16 = 0x098F;
    pub const DC_START_TIME: u16 = 0x0990;
    pub const DC_NEXT_SYNC1: u16 = 0x0998;
    pub const DC_SYNC0_CYCLE_TIME: u16 = 0x09A0;
    pub const DC_SYNC1_CYCLE_TIME: u16 = 0x09A4;
    pub const DC_LATCH0_CONTROL: u16 = 0x09A8;
    pub const DC_LATCH1_CONTROL: u16 = 0x09A9;
    pub const DC_LATCH0_STATUS: u16 = 0x09AE;
    pub const DC_LATCH1_STATUS: u16 = 0x09AF;
    pub const DC_LATCH0_POSITIVE: u16 = 0x09B0;
    pub const DC_LATCH0_NEGATIVE: u16 = 0x09B8;
    pub const DC_LATCH1_POSITIVE: u16 = 0x09C0;
    pub const DC_LATCH1_NEGATIVE: u16 = 0x09C8;
    pub const DC_ECAT_BUFFER_CHANGE_TIME: u16 = 0x09F0;
    pub const DC_PDI_BUFFER_START_TIME: u16 = 0x09F8;
    pub const DC_PDI_BUFFER_CHANGE_TIME: u16 = 0x09FC;
    pub const USER_RAM: u16 = 0x0F80;
    pub const PROCESS_RAM: u16 = 0x1000;

    /// Address of FMMU `n`.
    pub const fn fmmu(n: u8) -> u16 {
        FMMU0 + 16 * n as u16
    }
    /// Address of SyncManager `n`.
    pub const fn sm(n: u8) -> u16 {
        SM0 + 8 * n as u16
    }
    /// Receive time of port `n` (0–3).
    pub const fn dc_receive_time(port: u8) -> u16 {
        DC_RECEIVE_TIME_PORT0 + 4 * port as u16
    }
}

/// ESC features register 0x0008.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
pub struct Features(pub u16);

impl Features {
    pub const FMMU_BYTE_ORIENTED: u16 = 1 << 0;
    pub const DC: u16 = 1 << 2;
    pub const DC_64BIT: u16 = 1 << 3;
    pub const EBUS_LOW_JITTER: u16 = 1 << 4;
    pub const EBUS_ENHANCED_LINK_DETECTION: u16 = 1 << 5;
    pub const MII_ENHANCED_LINK_DETECTION: u16 = 1 << 6;
    pub const SEPARATE_FCS_ERRORS: u16 = 1 << 7;
    pub const ENHANCED_DC_SYNC_ACTIVATION: u16 = 1 << 8;
    pub const NO_LRW: u16 = 1 << 9;
    pub const NO_READ_WRITE: u16 = 1 << 10;
    pub const FIXED_FMMU_SM_CONFIG: u16 = 1 << 11;

    pub fn dc(self) -> bool {
        self.0 & Self::DC != 0
    }
    pub fn dc_64bit(self) -> bool {
        self.0 & Self::DC_64BIT != 0
    }
    pub fn lrw_supported(self) -> bool {
        self.0 & Self::NO_LRW == 0
    }
}

/// Physical type of one port, from the port descriptor 0x0007.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum PortType {
    NotImplemented,
    NotConfigured,
    Ebus,
    Mii,
}

/// Port descriptor 0x0007: two bits per port.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
pub struct PortDescriptor(pub u8);

impl PortDescriptor {
    pub fn port(self, n: u8) -> PortType {
        match (self.0 >> (2 * (n & 3))) & 3 {
            0 => PortType::NotImplemented,
            1 => PortType::NotConfigured,
            2 => PortType::Ebus,
            _ => PortType::Mii,
        }
    }

    /// Whether port `n` can carry a link: E-Bus or MII, not "not implemented" or "not
    /// configured" (a LAN9252's unused third port reads the latter).
    pub fn can_link(self, n: u8) -> bool {
        matches!(self.port(n), PortType::Ebus | PortType::Mii)
    }
}

/// DL status 0x0110.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
pub struct DlStatus(pub u16);

impl DlStatus {
    pub fn pdi_operational(self) -> bool {
        self.0 & 1 != 0
    }
    pub fn physical_link(self, port: u8) -> bool {
        self.0 & (1 << (4 + (port & 3))) != 0
    }
    /// Loop closed on `port` (frames loop back instead of leaving through it).
    pub fn loop_closed(self, port: u8) -> bool {
        self.0 & (1 << (8 + 2 * (port & 3))) != 0
    }
    pub fn communication(self, port: u8) -> bool {
        self.0 & (1 << (9 + 2 * (port & 3))) != 0
    }
    /// A port leads somewhere: communication established and loop open.
    pub fn port_active(self, port: u8) -> bool {
        self.communication(port) && !self.loop_closed(port)
    }
}

/// AL states (0x0120 / 0x0130 bits 3:0).
#[derive(Debug, Clone, Copy, PartialEq, Eq, PartialOrd, Ord, Hash)]
pub enum AlState {
    Init = 1,
    PreOp = 2,
    Bootstrap = 3,
    SafeOp = 4,
    Op = 8,
}

impl AlState {
    pub fn from_bits(bits: u8) -> Option<Self> {
        match bits & 0x0F {
            1 => Some(AlState::Init),
            2 => Some(AlState::PreOp),
            3 => Some(AlState::Bootstrap),
            4 => Some(AlState::SafeOp),
            8 => Some(AlState::Op),
            _ => None,
        }
    }
    pub fn name(self) -> &'static str {
        match self {
            AlState::Init => "INIT",
            AlState::PreOp => "PREOP",
            AlState::Bootstrap => "BOOT",
            AlState::SafeOp => "SAFEOP",
            AlState::Op => "OP",
        }
    }
}

impl fmt::Display for AlState {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        f.write_str(self.name())
    }
}

/// AL control 0x0120 / AL status 0x0130: state bits, error flag (status) or acknowledge
/// (control), device-identification bit.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
pub struct AlStatus(pub u16);

impl AlStatus {
    pub const ERROR: u16 = 1 << 4;
    pub const ID: u16 = 1 << 5;
    pub fn new(state: AlState, error: bool) -> Self {
        AlStatus(state as u16 | if error { Self::ERROR } else { 0 })
    }
    pub fn state_bits(self) -> u8 {
        (self.0 & 0x0F) as u8
    }
    pub fn state(self) -> Option<AlState> {
        AlState::from_bits(self.state_bits())
    }
    pub fn error(self) -> bool {
        self.0 & Self::ERROR != 0
    }
}

/// AL status code 0x0134, with the name of every standard code.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash, Default)]
pub struct AlStatusCode(pub u16);

impl AlStatusCode {
    pub const NO_ERROR: Self = Self(0x0000);
    pub const INVALID_STATE_CHANGE: Self = Self(0x0011);
    pub const UNKNOWN_STATE: Self = Self(0x0012);
    pub const BOOTSTRAP_NOT_SUPPORTED: Self = Self(0x0013);
    pub const INVALID_BOOT_MAILBOX_CONFIG: Self = Self(0x0015);
    pub const INVALID_MAILBOX_CONFIG: Self = Self(0x0016);
    pub const INVALID_SM_CONFIG: Self = Self(0x0017);
    pub const SYNC_ERROR: Self = Self(0x001A);
    pub const SM_WATCHDOG: Self = Self(0x001B);
    pub const INVALID_OUTPUT_CONFIG: Self = Self(0x001D);
    pub const INVALID_INPUT_CONFIG: Self = Self(0x001E);
    pub const MODULE_IDENT_LIST_MISMATCH: Self = Self(0x0070);
    pub const FATAL_SYNC_ERROR: Self = Self(0x002C);
    pub const INVALID_DC_SYNC_CONFIG: Self = Self(0x0030);

    /// The standard description (ETG.1000.6 / esc-spec §5.2), or `None` for vendor codes.
    pub fn name(self) -> Option<&'static str> {
        Some(match self.0 {
            0x0000 => "No error",
            0x0001 => "Unspecified error",
            0x0002 => "No memory",
            0x0003 => "Invalid device setup",
            0x0004 => "Invalid revision",
            0x0006 => "SII/EEPROM information does not match firmware",
            0x0007 => "Firmware update not successful",
            0x000E => "License error",
            0x0011 => "Invalid requested state change",
            0x0012 => "Unknown requested state",
            0x0013 => "Bootstrap not supported",
            0x0014 => "No valid firmware",
            0x0015 => "Invalid mailbox configuration (BOOT)",
            0x0016 => "Invalid mailbox configuration (PREOP)",
            0x0017 => "Invalid sync manager configuration",
            0x0018 => "No valid inputs available",
            0x0019 => "No valid outputs",
            0x001A => "Synchronization error",
            0x001B => "Sync manager watchdog",
            0x001C => "Invalid sync manager types",
            0x001D => "Invalid output configuration",
            0x001E => "Invalid input configuration",
            0x001F => "Invalid watchdog configuration",
            0x0020 => "Slave needs cold start",
            0x0021 => "Slave needs INIT",
            0x0022 => "Slave needs PREOP",
            0x0023 => "Slave needs SAFEOP",
            0x0024 => "Invalid input mapping",
            0x0025 => "Invalid output mapping",
            0x0026 => "Inconsistent settings",
            0x0027 => "Freerun not supported",
            0x0028 => "Synchronization not supported",
            0x0029 => "Freerun needs 3-buffer mode",
            0x002A => "Background watchdog",
            0x002B => "No valid inputs and outputs",
            0x002C => "Fatal sync error",
            0x002D => "No sync error",
            0x002E => "Cycle time too small",
            0x0030 => "Invalid DC SYNC configuration",
            0x0031 => "Invalid DC latch configuration",
            0x0032 => "PLL error",
            0x0033 => "DC sync IO error",
            0x0034 => "DC sync timeout error",
            0x0035 => "DC invalid sync cycle time",
            0x0036 => "DC SYNC0 cycle time",
            0x0037 => "DC SYNC1 cycle time",
            0x0041 => "MBX_AOE",
            0x0042 => "MBX_EOE",
            0x0043 => "MBX_COE",
            0x0044 => "MBX_FOE",
            0x0045 => "MBX_SOE",
            0x004F => "MBX_VOE",
            0x0050 => "EEPROM no access",
            0x0051 => "EEPROM error",
            0x0052 => "External hardware not ready",
            0x0060 => "Slave restarted locally",
            0x0061 => "Device identification value updated",
            0x0070 => "Detected module ident list does not match",
            0x0080 => "Supply voltage too low",
            0x0081 => "Supply voltage too high",
            0x0082 => "Temperature too low",
            0x0083 => "Temperature too high",
            0x00F0 => "Application controller available",
            _ => return None,
        })
    }
}

impl fmt::Display for AlStatusCode {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        match self.name() {
            Some(n) => write!(f, "{:#06x} ({n})", self.0),
            None => write!(f, "{:#06x} (vendor-specific)", self.0),
        }
    }
}

/// One FMMU (16 bytes at 0x0600 + 16·n).
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
pub struct Fmmu {
    pub logical_start: u32,
    pub length: u16,
    pub logical_start_bit: u8,
    pub logical_stop_bit: u8,
    pub physical_start: u16,
    pub physical_start_bit: u8,
    /// bit0 read, bit1 write.
    pub fmmu_type: u8,
    pub active: bool,
}

/// Where each field of an FMMU (0x0600 + 16·n) and a SyncManager (0x0800 + 8·n) lies, in
/// bytes, as smoltcp's `mod field` says it once (ESC datasheet section II, 0x0600 and 0x0800).
mod field {
    pub type Field = core::ops::Range<usize>;

    pub mod fmmu {
        use super::Field;
        pub const LOGICAL_START: Field = 0..4;
        pub const LENGTH: Field = 4..6;
        pub const LOGICAL_START_BIT: usize = 6;
        pub const LOGICAL_STOP_BIT: usize = 7;
        pub const PHYSICAL_START: Field = 8..10;
        pub const PHYSICAL_START_BIT: usize = 10;
        pub const TYPE: usize = 11;
        pub const ACTIVATE: usize = 12;
    }

    pub mod sm {
        use super::Field;
        pub const START: Field = 0..2;
        pub const LENGTH: Field = 2..4;
        pub const CONTROL: usize = 4;
        pub const STATUS: usize = 5;
        pub const ACTIVATE: usize = 6;
        pub const PDI_CONTROL: usize = 7;
    }
}

impl Fmmu {
    pub const LEN: usize = 16;
    pub const READ: u8 = 1;
    pub const WRITE: u8 = 2;

    pub fn parse(buf: &[u8]) -> Result<Self> {
        need(buf, 0, Self::LEN, "FMMU")?;
        use field::fmmu as f;
        let mut start = [0u8; 4];
        start.copy_from_slice(&buf[f::LOGICAL_START]);
        Ok(Fmmu {
            logical_start: u32::from_le_bytes(start),
            length: u16_at(buf, f::LENGTH.start, "")?,
            logical_start_bit: buf[f::LOGICAL_START_BIT],
            logical_stop_bit: buf[f::LOGICAL_STOP_BIT],
            physical_start: u16_at(buf, f::PHYSICAL_START.start, "")?,
            physical_start_bit: buf[f::PHYSICAL_START_BIT],
            fmmu_type: buf[f::TYPE],
            active: buf[f::ACTIVATE] & 1 != 0,
        })
    }

    pub fn to_bytes(&self) -> [u8; 16] {
        use field::fmmu as f;
        let mut b = [0u8; Self::LEN];
        b[f::LOGICAL_START].copy_from_slice(&self.logical_start.to_le_bytes());
        b[f::LENGTH].copy_from_slice(&self.length.to_le_bytes());
        b[f::LOGICAL_START_BIT] = self.logical_start_bit;
        b[f::LOGICAL_STOP_BIT] = self.logical_stop_bit;
        b[f::PHYSICAL_START].copy_from_slice(&self.physical_start.to_le_bytes());
        b[f::PHYSICAL_START_BIT] = self.physical_start_bit;
        b[f::TYPE] = self.fmmu_type;
        b[f::ACTIVATE] = self.active as u8;
        b
    }

    pub fn emit(&self, out: &mut [u8]) -> Result<()> {
        put(out, 0, &self.to_bytes(), "FMMU")
    }
}

/// One SyncManager (8 bytes at 0x0800 + 8·n).
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
pub struct SyncManager {
    pub start: u16,
    pub length: u16,
    pub control: u8,
    pub status: u8,
    pub activate: u8,
    pub pdi_control: u8,
}

impl SyncManager {
    pub const LEN: usize = 8;
    /// Control bits 1:0.
    pub const MODE_BUFFERED: u8 = 0b00;
    pub const MODE_MAILBOX: u8 = 0b10;
    /// Control bits 3:2: 0b01 = ECAT writes, PDI reads (outputs, mailbox out).
    pub const DIR_ECAT_WRITES: u8 = 0b0100;
    pub const ECAT_EVENT: u8 = 1 << 4;
    pub const AL_EVENT: u8 = 1 << 5;
    pub const WATCHDOG: u8 = 1 << 6;
    /// Status bit 0: a buffer was completely written (by the side that writes it).
    pub const STATUS_INT_WRITE: u8 = 1 << 0;
    /// Status bit 1: a buffer was completely read (by the side that reads it).
    pub const STATUS_INT_READ: u8 = 1 << 1;
    pub const STATUS_MAILBOX_FULL: u8 = 1 << 3;
    pub const ACTIVATE_ENABLE: u8 = 1;
    pub const ACTIVATE_REPEAT: u8 = 1 << 1;

    pub fn parse(buf: &[u8]) -> Result<Self> {
        need(buf, 0, Self::LEN, "SyncManager")?;
        use field::sm;
        Ok(SyncManager {
            start: u16_at(buf, sm::START.start, "")?,
            length: u16_at(buf, sm::LENGTH.start, "")?,
            control: buf[sm::CONTROL],
            status: buf[sm::STATUS],
            activate: buf[sm::ACTIVATE],
            pdi_control: buf[sm::PDI_CONTROL],
        })
    }

    pub fn to_bytes(&self) -> [u8; 8] {
        use field::sm;
        let mut b = [0u8; Self::LEN];
        b[sm::START].copy_from_slice(&self.start.to_le_bytes());
        b[sm::LENGTH].copy_from_slice(&self.length.to_le_bytes());
        b[sm::CONTROL] = self.control;
        b[sm::STATUS] = self.status;
        b[sm::ACTIVATE] = self.activate;
        b[sm::PDI_CONTROL] = self.pdi_control;
        b
    }

    pub fn emit(&self, out: &mut [u8]) -> Result<()> {
        put(out, 0, &self.to_bytes(), "SyncManager")
    }

    pub fn is_mailbox(&self) -> bool {
        self.control & 0b11 == Self::MODE_MAILBOX
    }
    pub fn ecat_writes(&self) -> bool {
        self.control & 0b1100 == Self::DIR_ECAT_WRITES
    }
    pub fn enabled(&self) -> bool {
        self.activate & Self::ACTIVATE_ENABLE != 0
    }
}

/// SII control/status 0x0502 (esc-spec §5.3).
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
pub struct SiiControl(pub u16);

impl SiiControl {
    pub const WRITE_ENABLE: u16 = 1 << 0;
    pub const EMULATION: u16 = 1 << 5;
    pub const READ_8_BYTES: u16 = 1 << 6;
    pub const TWO_BYTE_ADDRESS: u16 = 1 << 7;
    pub const CMD_READ: u16 = 0x0100;
    pub const CMD_WRITE: u16 = 0x0200;
    pub const CMD_RELOAD: u16 = 0x0400;
    pub const CMD_MASK: u16 = 0x0700;
    pub const CHECKSUM_ERROR: u16 = 1 << 11;
    pub const NOT_LOADED: u16 = 1 << 12;
    pub const ACK_ERROR: u16 = 1 << 13;
    pub const WRITE_ERROR: u16 = 1 << 14;
    pub const BUSY: u16 = 1 << 15;

    pub fn busy(self) -> bool {
        self.0 & Self::BUSY != 0
    }
    pub fn errors(self) -> u16 {
        self.0 & (Self::CHECKSUM_ERROR | Self::NOT_LOADED | Self::ACK_ERROR | Self::WRITE_ERROR)
    }
}

/// ECAT event request 0x0210 bits; each ESC ORs those its ECAT event mask (0x0200) lets
/// through into the IRQ field of every datagram that passes it.
pub mod ecat_event {
    /// A DC latch input event is waiting in 0x09AE/0x09AF (ECAT-controlled latch units).
    pub const LATCH: u16 = 1 << 0;
    /// DL status (0x0110) changed; cleared by an ECAT read of it.
    pub const DL_STATUS: u16 = 1 << 2;
    /// AL status (0x0130) changed; cleared by an ECAT read of it.
    pub const AL_STATUS: u16 = 1 << 3;
    /// SyncManager `n` (0–7) has an event for the master.
    pub const fn sync_manager(n: u8) -> u16 {
        1 << (4 + (n & 7))
    }
}

/// DC activation 0x0981 bits.
pub mod dc_activation {
    pub const CYCLIC_OPERATION: u8 = 1 << 0;
    pub const SYNC0: u8 = 1 << 1;
    pub const SYNC1: u8 = 1 << 2;
    pub const AUTO_ACTIVATE: u8 = 1 << 3;
    pub const START_TIME_EXTENSION: u8 = 1 << 4;
    pub const START_TIME_CHECK: u8 = 1 << 5;
    pub const NEAR_FUTURE_2S: u8 = 1 << 6;
    pub const DEBUG_PULSE: u8 = 1 << 7;
}

/// System time difference 0x092C: sign–magnitude, bits 30:0 the mean |difference| in ns.
/// We use the convention bit 31 = 1 ⇔ the local copy is behind the received time (older
/// datasheet, esc-spec §3.2, marked C there); masters use only the magnitude.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
pub struct SystemTimeDifference(pub u32);

impl SystemTimeDifference {
    /// Encodes `local − received` in ns, saturating the magnitude at 0x7FFF_FFFF.
    pub fn from_ns(diff_ns: i64) -> Self {
        let mag = diff_ns.unsigned_abs().min(0x7FFF_FFFF) as u32;
        SystemTimeDifference(if diff_ns < 0 { mag | 0x8000_0000 } else { mag })
    }
    pub fn magnitude_ns(self) -> u32 {
        self.0 & 0x7FFF_FFFF
    }
    /// `local − received` in ns under our sign convention.
    pub fn as_ns(self) -> i64 {
        let m = self.magnitude_ns() as i64;
        if self.0 & 0x8000_0000 != 0 {
            -m
        } else {
            m
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn error_counters_by_port_and_kind() {
        let mut b = [0u8; ErrorCounters::LEN];
        (b[0], b[1], b[2], b[9], b[12], b[13], b[19]) = (1, 2, 3, 4, 5, 6, 7);
        let c = ErrorCounters::parse(&b).unwrap();
        assert_eq!((c.invalid_frames, c.rx_errors), ([1, 3, 0, 0], [2, 0, 0, 0]));
        assert_eq!((c.forwarded_errors, c.processing_unit, c.pdi, c.lost_links), ([0, 4, 0, 0], 5, 6, [0, 0, 0, 7]));
        let nonzero: Vec<_> = c.each().filter(|x| x.2 > 0).map(|(k, p, v)| (k.name(), p, v)).collect();
        assert_eq!(
            nonzero,
            [
                ("invalid frames", Some(0), 1),
                ("receive errors", Some(0), 2),
                ("invalid frames", Some(1), 3),
                ("frames marked bad upstream", Some(1), 4),
                ("links lost", Some(3), 7),
                ("processing unit errors", None, 5),
                ("PDI errors", None, 6),
            ]
        );
        assert!(ErrorCounters::parse(&b[..19]).is_err());
    }

    #[test]
    fn fmmu_and_sm_round_trip() {
        let f = Fmmu {
            logical_start: 0x10000,
            length: 1,
            logical_start_bit: 0,
            logical_stop_bit: 3,
            physical_start: 0x0F00,
            physical_start_bit: 0,
            fmmu_type: Fmmu::WRITE,
            active: true,
        };
        assert_eq!(Fmmu::parse(&f.to_bytes()).unwrap(), f);
        let sm = SyncManager { start: 0x1000, length: 128, control: 0x26, status: 0, activate: 1, pdi_control: 0 };
        assert_eq!(SyncManager::parse(&sm.to_bytes()).unwrap(), sm);
        assert!(sm.is_mailbox() && sm.ecat_writes() && sm.enabled());
        assert!(SyncManager::parse(&[0; 7]).is_err());
    }

    #[test]
    fn dl_status_ports() {
        // Port 0 and 1 linked with communication, ports 2/3 closed (typical EL terminal).
        let s = DlStatus(0x5A31);
        assert!(s.physical_link(0) && s.physical_link(1) && !s.physical_link(2));
        assert!(s.loop_closed(2) && s.loop_closed(3));
        assert!(s.port_active(0) && s.port_active(1) && !s.port_active(2));
    }

    #[test]
    fn al_codes_and_difference() {
        assert_eq!(AlStatusCode(0x1B).name(), Some("Sync manager watchdog"));
        assert_eq!(AlStatusCode(0x8001).name(), None);
        assert_eq!(AlStatus(0x14).state(), Some(AlState::SafeOp));
        assert!(AlStatus(0x14).error());
        for v in [-5_i64, 0, 7, i64::MIN, i64::MAX] {
            let d = SystemTimeDifference::from_ns(v);
            assert_eq!(d.as_ns(), v.clamp(-0x7FFF_FFFF, 0x7FFF_FFFF));
        }
    }
}

/// The error counters of an ESC, registers 0x0300–0x0313 (ET1100 datasheet, section II,
/// "Error counters"): per port, frames received invalid (0x0300 + 2·port) and physical-layer
/// receive errors (0x0301 + 2·port), frames that came in already marked bad by a slave before
/// (0x0308 + port), frames the processing unit found wrong (0x030C), PDI errors (0x030D) and
/// links lost (0x0310 + port). Each counts up to 255 and stays there; a write clears it.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
pub struct ErrorCounters {
    pub invalid_frames: [u8; 4],
    pub rx_errors: [u8; 4],
    pub forwarded_errors: [u8; 4],
    pub processing_unit: u8,
    pub pdi: u8,
    pub lost_links: [u8; 4],
}

/// Where each counter lies, in bytes from 0x0300.
mod error_counter_field {
    use core::ops::Range;
    /// Invalid frame and RX error counters, interleaved by port.
    pub const PORTS: Range<usize> = 0..8;
    pub const FORWARDED: Range<usize> = 8..12;
    pub const PROCESSING_UNIT: usize = 12;
    pub const PDI: usize = 13;
    pub const LOST_LINKS: Range<usize> = 16..20;
}

/// One kind of error counter, for a report.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum ErrorCounterKind {
    InvalidFrames,
    RxErrors,
    ForwardedErrors,
    LostLinks,
    ProcessingUnit,
    Pdi,
}

impl ErrorCounterKind {
    /// In words.
    pub fn name(self) -> &'static str {
        match self {
            ErrorCounterKind::InvalidFrames => "invalid frames",
            ErrorCounterKind::RxErrors => "receive errors",
            ErrorCounterKind::ForwardedErrors => "frames marked bad upstream",
            ErrorCounterKind::LostLinks => "links lost",
            ErrorCounterKind::ProcessingUnit => "processing unit errors",
            ErrorCounterKind::Pdi => "PDI errors",
        }
    }
}

impl ErrorCounters {
    /// Bytes read from 0x0300.
    pub const LEN: usize = 20;

    pub fn parse(b: &[u8]) -> Result<Self> {
        use error_counter_field as f;
        need(b, 0, Self::LEN, "error counters")?;
        let mut c = ErrorCounters { processing_unit: b[f::PROCESSING_UNIT], pdi: b[f::PDI], ..Default::default() };
        for p in 0..4 {
            c.invalid_frames[p] = b[f::PORTS.start + 2 * p];
            c.rx_errors[p] = b[f::PORTS.start + 2 * p + 1];
            c.forwarded_errors[p] = b[f::FORWARDED.start + p];
            c.lost_links[p] = b[f::LOST_LINKS.start + p];
        }
        Ok(c)
    }

    /// Every counter with its port (`None` for the ESC's own), in register order.
    pub fn each(&self) -> impl Iterator<Item = (ErrorCounterKind, Option<u8>, u8)> + '_ {
        use ErrorCounterKind as K;
        (0..4u8)
            .flat_map(move |p| {
                let i = p as usize;
                [
                    (K::InvalidFrames, Some(p), self.invalid_frames[i]),
                    (K::RxErrors, Some(p), self.rx_errors[i]),
                    (K::ForwardedErrors, Some(p), self.forwarded_errors[i]),
                    (K::LostLinks, Some(p), self.lost_links[i]),
                ]
            })
            .chain([(K::ProcessingUnit, None, self.processing_unit), (K::Pdi, None, self.pdi)])
    }
}
