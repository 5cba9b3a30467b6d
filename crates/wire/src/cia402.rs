//! The CiA402 drive profile (IEC 61800-7-201, as CoE carries it): the power drive system's
//! state machine as the controlword (0x6040) commands it and the statusword (0x6041) reports
//! it, the modes of operation, and the indices of the profile's objects. Both the simulated
//! drive and the master's driver use these, so they cannot disagree on a bit.

/// Object indices of the profile.
pub mod index {
    pub const ERROR_CODE: u16 = 0x603F;
    pub const CONTROLWORD: u16 = 0x6040;
    pub const STATUSWORD: u16 = 0x6041;
    pub const QUICK_STOP_OPTION: u16 = 0x605A;
    /// What transition 8 (shutdown from operation enabled) does: 0 coast, 1 the profile
    /// deceleration first.
    pub const SHUTDOWN_OPTION: u16 = 0x605B;
    /// What transition 5 (disable operation) does: 0 coast, 1 the profile deceleration first.
    pub const DISABLE_OPERATION_OPTION: u16 = 0x605C;
    /// How halt (controlword bit 8) stops the shaft: 1 profile deceleration, 2 quick-stop
    /// deceleration, 3 current limit, 4 voltage limit.
    pub const HALT_OPTION: u16 = 0x605D;
    /// What the fault reaction does: 0 coast, 1 profile deceleration, 2 quick-stop
    /// deceleration, 3 current limit, 4 voltage limit.
    pub const FAULT_REACTION_OPTION: u16 = 0x605E;
    pub const MODES_OF_OPERATION: u16 = 0x6060;
    pub const MODES_OF_OPERATION_DISPLAY: u16 = 0x6061;
    pub const POSITION_ACTUAL_INTERNAL: u16 = 0x6063;
    pub const POSITION_ACTUAL: u16 = 0x6064;
    pub const FOLLOWING_ERROR_WINDOW: u16 = 0x6065;
    pub const FOLLOWING_ERROR_TIMEOUT: u16 = 0x6066;
    pub const VELOCITY_ACTUAL: u16 = 0x606C;
    pub const VELOCITY_WINDOW: u16 = 0x606D;
    pub const VELOCITY_WINDOW_TIME: u16 = 0x606E;
    pub const VELOCITY_THRESHOLD: u16 = 0x606F;
    pub const VELOCITY_THRESHOLD_TIME: u16 = 0x6070;
    pub const TARGET_TORQUE: u16 = 0x6071;
    pub const MAX_TORQUE: u16 = 0x6072;
    pub const TORQUE_ACTUAL: u16 = 0x6077;
    pub const TARGET_POSITION: u16 = 0x607A;
    pub const HOME_OFFSET: u16 = 0x607C;
    pub const PROFILE_VELOCITY: u16 = 0x6081;
    pub const PROFILE_ACCELERATION: u16 = 0x6083;
    pub const PROFILE_DECELERATION: u16 = 0x6084;
    pub const QUICK_STOP_DECELERATION: u16 = 0x6085;
    pub const HOMING_METHOD: u16 = 0x6098;
    /// Subindex 1: speed during the search for a switch; 2: during the search for zero.
    pub const HOMING_SPEEDS: u16 = 0x6099;
    pub const HOMING_ACCELERATION: u16 = 0x609A;
    pub const FOLLOWING_ERROR_ACTUAL: u16 = 0x60F4;
    /// Bit 0 negative limit switch, 1 positive limit switch, 2 home switch.
    pub const DIGITAL_INPUTS: u16 = 0x60FD;
    pub const TARGET_VELOCITY: u16 = 0x60FF;
    /// Interpolated position: 0 linear interpolation.
    pub const INTERPOLATION_SUB_MODE: u16 = 0x60C0;
    /// Subindex 1: the interpolated position mode's set-point.
    pub const INTERPOLATION_DATA: u16 = 0x60C1;
    /// Subindex 1: the period's value, 2: its unit as a power of ten seconds (1, −3: 1 ms).
    pub const INTERPOLATION_TIME_PERIOD: u16 = 0x60C2;
    pub const SUPPORTED_DRIVE_MODES: u16 = 0x6502;
}

/// Controlword bits.
pub mod control {
    pub const SWITCH_ON: u16 = 1 << 0;
    pub const ENABLE_VOLTAGE: u16 = 1 << 1;
    /// Active low: 0 commands a quick stop.
    pub const QUICK_STOP: u16 = 1 << 2;
    pub const ENABLE_OPERATION: u16 = 1 << 3;
    /// Profile position: a rising edge takes a new set-point.
    pub const NEW_SETPOINT: u16 = 1 << 4;
    /// Homing: a rising edge starts homing, a falling edge interrupts it (the same bit).
    pub const HOMING_START: u16 = 1 << 4;
    /// Interpolated position: set, the drive follows the set-points; clear, it holds.
    pub const ENABLE_IP_MODE: u16 = 1 << 4;
    pub const CHANGE_SET_IMMEDIATELY: u16 = 1 << 5;
    pub const RELATIVE: u16 = 1 << 6;
    /// A rising edge resets a fault.
    pub const FAULT_RESET: u16 = 1 << 7;
    pub const HALT: u16 = 1 << 8;

    /// The device-control commands (the low bits; bit 7 clear).
    pub const SHUTDOWN: u16 = ENABLE_VOLTAGE | QUICK_STOP;
    pub const SWITCH_ON_CMD: u16 = SWITCH_ON | ENABLE_VOLTAGE | QUICK_STOP;
    pub const ENABLE_OPERATION_CMD: u16 = SWITCH_ON | ENABLE_VOLTAGE | QUICK_STOP | ENABLE_OPERATION;
    pub const DISABLE_OPERATION: u16 = SWITCH_ON_CMD;
    pub const DISABLE_VOLTAGE: u16 = 0;
    pub const QUICK_STOP_CMD: u16 = ENABLE_VOLTAGE;
}

/// Statusword bits.
pub mod status {
    pub const READY_TO_SWITCH_ON: u16 = 1 << 0;
    pub const SWITCHED_ON: u16 = 1 << 1;
    pub const OPERATION_ENABLED: u16 = 1 << 2;
    pub const FAULT: u16 = 1 << 3;
    pub const VOLTAGE_ENABLED: u16 = 1 << 4;
    /// Active low: 0 while a quick stop is active.
    pub const QUICK_STOP: u16 = 1 << 5;
    pub const SWITCH_ON_DISABLED: u16 = 1 << 6;
    pub const WARNING: u16 = 1 << 7;
    pub const REMOTE: u16 = 1 << 9;
    pub const TARGET_REACHED: u16 = 1 << 10;
    pub const INTERNAL_LIMIT: u16 = 1 << 11;
    /// Profile position: set-point acknowledge; cyclic modes: the drive follows the target;
    /// profile velocity: speed is zero; homing: homing attained; interpolated position: ip mode
    /// active.
    pub const OP_SPECIFIC_12: u16 = 1 << 12;
    /// Profile position, CSP and interpolated position: following error; homing: homing error.
    pub const OP_SPECIFIC_13: u16 = 1 << 13;
}

/// The states of the power drive system.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash)]
pub enum State {
    NotReadyToSwitchOn,
    SwitchOnDisabled,
    ReadyToSwitchOn,
    SwitchedOn,
    OperationEnabled,
    QuickStopActive,
    FaultReactionActive,
    Fault,
}

impl State {
    /// The state a statusword reports (bits 0–3, 5, 6; the profile's table of patterns).
    /// `None` for a pattern the profile does not define.
    pub fn from_statusword(sw: u16) -> Option<State> {
        use State::*;
        let s = sw & 0x006F;
        Some(match (s & 0x4F, s) {
            (0x00, _) => NotReadyToSwitchOn,
            (0x40, _) => SwitchOnDisabled,
            (0x0F, _) => FaultReactionActive,
            (0x08, _) => Fault,
            (_, 0x21) => ReadyToSwitchOn,
            (_, 0x23) => SwitchedOn,
            (_, 0x27) => OperationEnabled,
            (_, 0x07) => QuickStopActive,
            _ => return None,
        })
    }

    /// The statusword bits that report this state (bits 0–3, 5 and 6).
    pub fn statusword_bits(self) -> u16 {
        use status::*;
        use State::*;
        match self {
            NotReadyToSwitchOn => 0,
            SwitchOnDisabled => SWITCH_ON_DISABLED,
            ReadyToSwitchOn => QUICK_STOP | READY_TO_SWITCH_ON,
            SwitchedOn => QUICK_STOP | READY_TO_SWITCH_ON | SWITCHED_ON,
            OperationEnabled => QUICK_STOP | READY_TO_SWITCH_ON | SWITCHED_ON | OPERATION_ENABLED,
            QuickStopActive => READY_TO_SWITCH_ON | SWITCHED_ON | OPERATION_ENABLED,
            FaultReactionActive => READY_TO_SWITCH_ON | SWITCHED_ON | OPERATION_ENABLED | FAULT,
            Fault => FAULT,
        }
    }

    pub fn name(self) -> &'static str {
        use State::*;
        match self {
            NotReadyToSwitchOn => "not ready to switch on",
            SwitchOnDisabled => "switch on disabled",
            ReadyToSwitchOn => "ready to switch on",
            SwitchedOn => "switched on",
            OperationEnabled => "operation enabled",
            QuickStopActive => "quick stop active",
            FaultReactionActive => "fault reaction active",
            Fault => "fault",
        }
    }
}

/// What a controlword commands (bits 0–3 and 7), by the profile's device-control table.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Command {
    Shutdown,
    SwitchOn,
    EnableOperation,
    DisableVoltage,
    QuickStop,
    FaultReset,
}

impl Command {
    /// Decodes bits 0–3 (bit 7, a fault reset, is an edge and is decoded by the caller).
    pub fn from_controlword(cw: u16) -> Command {
        use control::*;
        if cw & ENABLE_VOLTAGE == 0 {
            Command::DisableVoltage
        } else if cw & QUICK_STOP == 0 {
            Command::QuickStop
        } else if cw & SWITCH_ON == 0 {
            Command::Shutdown
        } else if cw & ENABLE_OPERATION == 0 {
            Command::SwitchOn
        } else {
            Command::EnableOperation
        }
    }

    /// The controlword bits 0–3 and 7 for this command.
    pub fn controlword(self) -> u16 {
        use control::*;
        match self {
            Command::Shutdown => SHUTDOWN,
            Command::SwitchOn => SWITCH_ON_CMD,
            Command::EnableOperation => ENABLE_OPERATION_CMD,
            Command::DisableVoltage => DISABLE_VOLTAGE,
            Command::QuickStop => QUICK_STOP_CMD,
            Command::FaultReset => FAULT_RESET,
        }
    }
}

/// Modes of operation (0x6060 / 0x6061).
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash)]
pub enum Mode {
    ProfilePosition,
    ProfileVelocity,
    Homing,
    InterpolatedPosition,
    CyclicSyncPosition,
    CyclicSyncVelocity,
    CyclicSyncTorque,
}

impl Mode {
    pub fn code(self) -> i8 {
        match self {
            Mode::ProfilePosition => 1,
            Mode::ProfileVelocity => 3,
            Mode::Homing => 6,
            Mode::InterpolatedPosition => 7,
            Mode::CyclicSyncPosition => 8,
            Mode::CyclicSyncVelocity => 9,
            Mode::CyclicSyncTorque => 10,
        }
    }

    pub fn from_code(c: i8) -> Option<Mode> {
        Some(match c {
            1 => Mode::ProfilePosition,
            3 => Mode::ProfileVelocity,
            6 => Mode::Homing,
            7 => Mode::InterpolatedPosition,
            8 => Mode::CyclicSyncPosition,
            9 => Mode::CyclicSyncVelocity,
            10 => Mode::CyclicSyncTorque,
            _ => return None,
        })
    }

    /// The mode's bit in 0x6502 (supported drive modes).
    pub fn supported_bit(self) -> u32 {
        match self {
            Mode::ProfilePosition => 1 << 0,
            Mode::ProfileVelocity => 1 << 2,
            Mode::Homing => 1 << 5,
            Mode::InterpolatedPosition => 1 << 6,
            Mode::CyclicSyncPosition => 1 << 7,
            Mode::CyclicSyncVelocity => 1 << 8,
            Mode::CyclicSyncTorque => 1 << 9,
        }
    }

    pub fn short_name(self) -> &'static str {
        match self {
            Mode::ProfilePosition => "PP",
            Mode::ProfileVelocity => "PV",
            Mode::Homing => "HM",
            Mode::InterpolatedPosition => "IP",
            Mode::CyclicSyncPosition => "CSP",
            Mode::CyclicSyncVelocity => "CSV",
            Mode::CyclicSyncTorque => "CST",
        }
    }
}

/// Error codes (0x603F, and the emergency's code) the simulated drive raises.
pub mod error_code {
    pub const FOLLOWING_ERROR: u16 = 0x8611;
    pub const OVERCURRENT: u16 = 0x2310;
    pub const DC_LINK_UNDERVOLTAGE: u16 = 0x3220;
    pub const SYNC_ERROR: u16 = 0x8700;
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn every_state_reads_back_from_its_statusword() {
        use State::*;
        for s in [
            NotReadyToSwitchOn,
            SwitchOnDisabled,
            ReadyToSwitchOn,
            SwitchedOn,
            OperationEnabled,
            QuickStopActive,
            FaultReactionActive,
            Fault,
        ] {
            // Other bits (voltage enabled, warning, remote, mode-specific) do not change it.
            for extra in [0u16, 0x0010, 0x0080, 0x0200, 0x3400] {
                assert_eq!(State::from_statusword(s.statusword_bits() | extra), Some(s), "{s:?} {extra:#x}");
            }
        }
        // Switch on disabled with bit 0 set is not a defined pattern.
        assert_eq!(State::from_statusword(0x0041), None);
    }

    #[test]
    fn commands_round_trip_through_the_controlword() {
        for c in [
            Command::Shutdown,
            Command::SwitchOn,
            Command::EnableOperation,
            Command::DisableVoltage,
            Command::QuickStop,
        ] {
            assert_eq!(Command::from_controlword(c.controlword()), c);
            // Bits 4–15 do not change the command.
            assert_eq!(Command::from_controlword(c.controlword() | 0xFF70), c);
        }
        // The profile's table: 0x0F enables, 0x06 shuts down, 0x02 quick-stops, 0x00 disables.
        assert_eq!(Command::from_controlword(0x000F), Command::EnableOperation);
        assert_eq!(Command::from_controlword(0x0006), Command::Shutdown);
        assert_eq!(Command::from_controlword(0x000B), Command::QuickStop);
        assert_eq!(Command::from_controlword(0x000D), Command::DisableVoltage);
    }

    #[test]
    fn modes_round_trip() {
        for c in -128i8..=127 {
            if let Some(m) = Mode::from_code(c) {
                assert_eq!(m.code(), c);
            }
        }
        assert_eq!(Mode::from_code(8), Some(Mode::CyclicSyncPosition));
        assert_eq!(Mode::from_code(0), None);
    }
}
