//! A CiA402 driver: one [`Axis`] per drive walks the drive's state machine to where the
//! application wants it (operation enabled, disabled, quick stop) one controlword per cycle,
//! resets faults, switches modes, and starts cyclic synchronous or interpolated position without
//! a jump (the target follows the actual position until operation is enabled).
//!
//! A drive with several axes carries axis n's objects n × 0x800 above the first's (axis B's
//! controlword at 0x6840, CiA 402-2): [`Axis::all`] finds every axis a slave maps.
use ferrocat_wire::cia402::{control, index as ix, Command};
/// The CiA402 operation modes and states the driver takes and reports.
pub use ferrocat_wire::cia402::{Mode, State};

use crate::error::{Cia402Error, ConfigError, MasterError, Result, SlaveError};
use crate::io::Io;
use crate::master::Master;
use crate::process::Handle;

/// Where the application wants the drive.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Goal {
    /// Switch on disabled, power off.
    Disabled,
    /// Operation enabled: the drive follows its set-points.
    OperationEnabled,
    /// Quick stop active: the drive brakes on its quick-stop ramp.
    QuickStop,
}

impl Goal {
    /// Its name, as errors give it.
    pub fn name(self) -> &'static str {
        match self {
            Goal::Disabled => "Disabled",
            Goal::OperationEnabled => "OperationEnabled",
            Goal::QuickStop => "QuickStop",
        }
    }
}

/// The process-data entries of one drive (by object index, so that any vendor's names work).
#[derive(Debug, Clone, Copy)]
struct Handles {
    controlword: Handle,
    statusword: Handle,
    mode: Option<Handle>,
    mode_display: Option<Handle>,
    target_position: Option<Handle>,
    /// Interpolated position's set-point, 0x60C1:01.
    ip_setpoint: Option<Handle>,
    target_velocity: Option<Handle>,
    target_torque: Option<Handle>,
    position_actual: Option<Handle>,
    velocity_actual: Option<Handle>,
    torque_actual: Option<Handle>,
    following_error: Option<Handle>,
}

#[derive(Debug, Clone)]
/// One CiA402 axis: its process-data handles and the driver's state machine.
pub struct Axis {
    /// The slave's position on the segment.
    pub position: u16,
    /// The axis on that slave: 0 for the first, n for the one whose objects sit n × 0x800 higher.
    pub axis: u8,
    h: Handles,
    goal: Goal,
    mode: Mode,
    /// The application's mode-specific controlword bits (`set_mode_bits`).
    mode_bits: u16,
    controlword: u16,
    state: Option<State>,
    /// Cycles spent in the current state, for timeouts the application may impose.
    pub cycles_in_state: u64,
    /// Faults seen (rising edges of the fault state).
    pub faults: u64,
}

/// Axes a drive may have (CiA 402-2: eight, 0x800 of the profile area each).
pub const MAX_AXES: u8 = 8;

/// How far axis `axis`'s objects sit above the first axis's.
pub fn axis_offset(axis: u8) -> u16 {
    axis as u16 * 0x800
}

fn signed(v: u64, bits: u8) -> i64 {
    let shift = 64 - bits as u32;
    ((v << shift) as i64) >> shift
}

/// What a drive reports in the image ([`Axis::feedback`]); `None` where the object is not
/// mapped.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct Feedback {
    /// The statusword (0x6041).
    pub statusword: u16,
    /// The mode the drive says it runs (0x6061).
    pub mode: Option<Mode>,
    /// Operation enabled in the wanted mode (as far as the image shows the mode).
    pub ready: bool,
    /// Position actual value (0x6064, else 0x6063).
    pub position: Option<i32>,
    /// Velocity actual value (0x606C).
    pub velocity: Option<i32>,
    /// Torque actual value (0x6077, per mille of rated).
    pub torque: Option<i16>,
    /// Following error actual value (0x60F4).
    pub following_error: Option<i32>,
}

/// One of an axis's outputs, to write ([`Axis::write`]).
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Output {
    /// The position to follow: the target position (0x607A) and interpolated position's
    /// set-point (0x60C1:01), whichever the image holds.
    Position(i32),
    /// The target velocity (0x60FF).
    Velocity(i32),
    /// The target torque (0x6071, per mille of rated).
    Torque(i16),
    /// The controlword (0x6040) as given.
    Controlword(u16),
}

impl Axis {
    /// Every axis of the drive at `position` whose controlword and statusword are in the
    /// process image, the first axis always (an error where it lacks them).
    pub fn all<I: Io>(m: &Master<I>, position: u16) -> Result<Vec<Self>> {
        let s = m.slave(position)?;
        let mapped = |axis: u8| {
            let at = axis_offset(axis);
            s.mapping.outputs.iter().any(|e| e.index == ix::CONTROLWORD + at)
                && s.mapping.inputs.iter().any(|e| e.index == ix::STATUSWORD + at)
        };
        let mut axes = vec![Self::on_axis(m, position, 0)?];
        for axis in (1..MAX_AXES).filter(|&n| mapped(n)) {
            axes.push(Self::on_axis(m, position, axis)?);
        }
        Ok(axes)
    }

    /// Axis `axis` (0 the first; fewer than [`MAX_AXES`]) of the drive at `position`.
    pub fn on_axis<I: Io>(m: &Master<I>, position: u16, axis: u8) -> Result<Self> {
        let s = m.slave(position)?;
        if axis >= MAX_AXES {
            return Err(MasterError::of(
                position,
                &s.name,
                SlaveError::Cia402(Cia402Error::NoSuchAxis { axis, max: MAX_AXES }),
            ));
        }
        let at = axis_offset(axis);
        let find_sub = |outputs: bool, index: u16, sub: Option<u8>| {
            let list = if outputs { &s.mapping.outputs } else { &s.mapping.inputs };
            list.iter()
                .find(|e| e.index == index + at && sub.is_none_or(|k| e.subindex == k))
                .map(|e| Handle { bit: e.image_bit, bits: e.bits })
        };
        let find = |outputs: bool, index: u16| find_sub(outputs, index, None);
        let need = |h: Option<Handle>, object: &'static str, index: u16| {
            h.ok_or_else(|| {
                MasterError::of(
                    position,
                    &s.name,
                    SlaveError::Cia402(Cia402Error::NotMapped { axis, object, index: index + at }),
                )
            })
        };
        let h = Handles {
            controlword: need(find(true, ix::CONTROLWORD), "controlword", ix::CONTROLWORD)?,
            statusword: need(find(false, ix::STATUSWORD), "statusword", ix::STATUSWORD)?,
            mode: find(true, ix::MODES_OF_OPERATION),
            mode_display: find(false, ix::MODES_OF_OPERATION_DISPLAY),
            target_position: find(true, ix::TARGET_POSITION),
            ip_setpoint: find_sub(true, ix::INTERPOLATION_DATA, Some(1)),
            target_velocity: find(true, ix::TARGET_VELOCITY),
            target_torque: find(true, ix::TARGET_TORQUE),
            position_actual: find(false, ix::POSITION_ACTUAL).or_else(|| find(false, ix::POSITION_ACTUAL_INTERNAL)),
            velocity_actual: find(false, ix::VELOCITY_ACTUAL),
            torque_actual: find(false, ix::TORQUE_ACTUAL),
            following_error: find(false, ix::FOLLOWING_ERROR_ACTUAL),
        };
        Ok(Axis {
            position,
            axis,
            h,
            goal: Goal::Disabled,
            mode: Mode::CyclicSyncPosition,
            mode_bits: 0,
            controlword: 0,
            state: None,
            cycles_in_state: 0,
            faults: 0,
        })
    }

    /// A profile object's index for this axis (`ix::CONTROLWORD` is 0x6840 on axis 1).
    pub fn index(&self, profile_index: u16) -> u16 {
        profile_index + axis_offset(self.axis)
    }

    /// Where the driver should take the drive; [`Axis::update`] walks it there.
    pub fn set_goal(&mut self, goal: Goal) {
        self.goal = goal;
    }

    /// The mode to run in; set through the process image when 0x6060 is mapped, else by SDO
    /// (which needs the mailbox, so call it outside the cycle's hot path).
    pub fn set_mode<I: Io>(&mut self, m: &mut Master<I>, mode: Mode) -> Result<()> {
        self.mode = mode;
        match self.h.mode {
            Some(h) => m.cyclic().set(h, mode.code() as u8 as u64),
            None => m.acyclic().coe().sdo_write(
                self.position,
                self.index(ix::MODES_OF_OPERATION),
                0,
                &[mode.code() as u8],
            )?,
        }
        Ok(())
    }

    /// The mode-specific controlword bits (4–6, 8, 9: new set-point, homing start, halt …)
    /// every later `update` sends along with its command. In interpolated position the driver
    /// sets bit 4 (enable ip mode) itself whenever it enables operation.
    pub fn set_mode_bits(&mut self, bits: u16) {
        self.mode_bits = bits & !0x008F;
    }

    /// Tells an interpolated-position drive the period of its set-points (0x60C2 by SDO, as
    /// value × 10^index s: 1 ms is 1, −3; 250 µs is 25, −5). Call it before enabling, with the
    /// master's cycle; a period no such pair gives exactly is an error.
    pub fn set_interpolation_period<I: Io>(&self, m: &mut Master<I>, period_ns: u64) -> Result<()> {
        let (value, index) =
            interpolation_period(period_ns).ok_or(MasterError::Config(ConfigError::InterpolationPeriod(period_ns)))?;
        m.acyclic().coe().sdo_write(self.position, self.index(ix::INTERPOLATION_TIME_PERIOD), 1, &[value])?;
        m.acyclic().coe().sdo_write(self.position, self.index(ix::INTERPOLATION_TIME_PERIOD), 2, &[index as u8])?;
        Ok(())
    }

    /// The drive's state from its last statusword, if it had one.
    pub fn state(&self) -> Option<State> {
        self.state
    }

    /// Whether the image holds what `mode` commands: the target position (0x607A) or
    /// interpolated position's set-point for CSP and IP, the target velocity (0x60FF) for CSV,
    /// the target torque (0x6071) for CST; for the profile modes and homing, the mode object
    /// (0x6060) or nothing (they are set by SDO).
    pub fn can_run(&self, mode: Mode) -> bool {
        match mode {
            Mode::CyclicSyncPosition | Mode::InterpolatedPosition => {
                self.h.target_position.is_some() || self.h.ip_setpoint.is_some()
            }
            Mode::CyclicSyncVelocity => self.h.target_velocity.is_some(),
            Mode::CyclicSyncTorque => self.h.target_torque.is_some(),
            _ => true,
        }
    }

    /// What the drive reports in the image now: the statusword, the mode it says it runs, and
    /// the actual values that are mapped; `ready` is operation enabled in the wanted mode (as
    /// far as the image shows the mode).
    pub fn feedback<I: Io>(&self, m: &Master<I>) -> Feedback {
        let image = m.image();
        let value = |h: Option<Handle>| h.map(|h| signed(image.get(h), h.bits));
        let mode = self.mode_display(m);
        Feedback {
            statusword: image.get(self.h.statusword) as u16,
            mode,
            ready: self.ready(mode),
            position: value(self.h.position_actual).map(|v| v as i32),
            velocity: value(self.h.velocity_actual).map(|v| v as i32),
            torque: value(self.h.torque_actual).map(|v| v as i16),
            following_error: value(self.h.following_error).map(|v| v as i32),
        }
    }

    /// The mode the drive says it runs (0x6061), where mapped.
    fn mode_display<I: Io>(&self, m: &Master<I>) -> Option<Mode> {
        self.h.mode_display.and_then(|h| Mode::from_code(m.image().get(h) as u8 as i8))
    }

    /// Operation enabled in the wanted mode, as far as `shown` (the mode display) tells.
    fn ready(&self, shown: Option<Mode>) -> bool {
        self.state == Some(State::OperationEnabled) && shown.is_none_or(|d| d == self.mode)
    }

    /// Writes one of the axis's outputs into the image (where it is mapped; the next cycle
    /// sends it). A controlword written so is sent as it is, for tools and tests that walk the
    /// state machine by hand; [`Axis::update`] overwrites it.
    pub fn write<I: Io>(&self, m: &mut Master<I>, output: Output) {
        let mut c = m.cyclic();
        match output {
            Output::Position(pos) => {
                for h in [self.h.target_position, self.h.ip_setpoint].into_iter().flatten() {
                    c.set(h, pos as u32 as u64);
                }
            }
            Output::Velocity(vel) => {
                if let Some(h) = self.h.target_velocity {
                    c.set(h, vel as u32 as u64);
                }
            }
            Output::Torque(per_mille) => {
                if let Some(h) = self.h.target_torque {
                    c.set(h, per_mille as u16 as u64);
                }
            }
            Output::Controlword(cw) => c.set(self.h.controlword, cw as u64),
        }
    }

    /// After each cycle: reads the statusword and writes the next controlword (and, until
    /// operation is enabled in a cyclic mode, targets that hold the drive where it stands).
    /// Returns the drive's state.
    pub fn update<I: Io>(&mut self, m: &mut Master<I>) -> Option<State> {
        let state = State::from_statusword(m.image().get(self.h.statusword) as u16);
        if state != self.state {
            if state == Some(State::Fault) {
                self.faults += 1;
            }
            self.cycles_in_state = 0;
        } else {
            self.cycles_in_state += 1;
        }
        self.state = state;
        let holding = !self.ready(self.mode_display(m));
        if holding {
            // Until the drive runs in the wanted mode, command what it is doing now: no jump.
            if let Some(p) = self.feedback(m).position {
                self.write(m, Output::Position(p));
            }
            self.write(m, Output::Velocity(0));
            self.write(m, Output::Torque(0));
        }
        if let Some(h) = self.h.mode {
            m.cyclic().set(h, self.mode.code() as u8 as u64);
        }
        let cw = self.next_controlword(state);
        self.controlword = cw;
        m.cyclic().set(self.h.controlword, cw as u64);
        state
    }

    fn next_controlword(&self, state: Option<State>) -> u16 {
        use State::*;
        let mut keep_high = self.mode_bits;
        if self.mode == Mode::InterpolatedPosition {
            keep_high |= control::ENABLE_IP_MODE;
        }
        let cmd = match (self.goal, state) {
            // A fault reset is a rising edge of bit 7: alternate 0 and the reset.
            (_, Some(Fault)) => {
                return if self.controlword & control::FAULT_RESET != 0 { 0 } else { control::FAULT_RESET };
            }
            (_, None | Some(NotReadyToSwitchOn | FaultReactionActive)) => Command::DisableVoltage,
            (Goal::Disabled, _) => Command::DisableVoltage,
            (Goal::QuickStop, Some(OperationEnabled | QuickStopActive)) => Command::QuickStop,
            (Goal::QuickStop, _) => Command::DisableVoltage,
            (Goal::OperationEnabled, Some(SwitchOnDisabled)) => Command::Shutdown,
            (Goal::OperationEnabled, Some(ReadyToSwitchOn)) => Command::SwitchOn,
            (Goal::OperationEnabled, Some(SwitchedOn | OperationEnabled)) => Command::EnableOperation,
            // Left in quick stop by someone else: back through switch on disabled.
            (Goal::OperationEnabled, Some(QuickStopActive)) => Command::DisableVoltage,
        };
        keep_high | cmd.controlword()
    }
}

/// 0x60C2's (value, index) for a period: the largest unit (a power of ten seconds) that gives it
/// exactly.
fn interpolation_period(period_ns: u64) -> Option<(u8, i8)> {
    (-9i8..=0).rev().find_map(|index| {
        let unit = 10u64.pow((9 + index) as u32);
        let value = period_ns / unit;
        (period_ns % unit == 0 && (1..=255).contains(&value)).then_some((value as u8, index))
    })
}

/// Makes sure every axis of the drive at `position` (in PREOP) carries a target position and a
/// position actual value in its process image. Where the present assignment lacks one, a PDO
/// its SII (or ESI) offers is assigned: on a one-axis drive, one that also holds the
/// controlword (statusword) replaces the assignment — fixed PDOs often repeat it, and a second
/// copy would override the first — else (and always on a drive with several axes, whose other
/// axes' PDOs must stay) the first with the object is added. A vendor's default assignment
/// often holds only the controlword and statusword (the Nanotec C5-E's does) or an
/// interpolated set-point (the AKD's).
pub fn map_for_csp<I: Io>(m: &mut Master<I>, position: u16) -> Result<()> {
    let axes: Vec<u16> = {
        let s = m.slave(position)?;
        (0..MAX_AXES)
            .map(axis_offset)
            .filter(|&at| at == 0 || s.mapping.outputs.iter().any(|e| e.index == ix::CONTROLWORD + at))
            .collect()
    };
    let sides =
        [(true, ix::TARGET_POSITION, ix::CONTROLWORD, 0x1C12u16), (false, ix::POSITION_ACTUAL, ix::STATUSWORD, 0x1C13)];
    for &at in &axes {
        for (outputs, object, word, assign) in sides {
            let (object, word) = (object + at, word + at);
            let s = m.slave(position)?;
            let mapped = if outputs { &s.mapping.outputs } else { &s.mapping.inputs };
            if mapped.iter().any(|e| e.index == object) {
                continue;
            }
            let offered = if outputs { s.sii.rx_pdos() } else { s.sii.tx_pdos() };
            let has = |p: &ferrocat_wire::sii::Pdo, i: u16| p.entries.iter().any(|e| e.index == i);
            let whole = offered.iter().find(|p| axes.len() == 1 && has(p, object) && has(p, word)).map(|p| p.index);
            let Some(pdo) = whole.or_else(|| offered.iter().find(|p| has(p, object)).map(|p| p.index)) else {
                continue;
            };
            let pdos = if whole.is_some() {
                vec![pdo]
            } else {
                let n = m.acyclic().coe().sdo_read(position, assign, 0)?.first().copied().unwrap_or(0);
                let mut pdos = Vec::with_capacity(n as usize + 1);
                for k in 1..=n {
                    let v = m.acyclic().coe().sdo_read(position, assign, k)?;
                    pdos.push(u16::from_le_bytes([v.first().copied().unwrap_or(0), v.get(1).copied().unwrap_or(0)]));
                }
                if !pdos.contains(&pdo) {
                    pdos.push(pdo);
                }
                pdos
            };
            m.config().remap(position, outputs, &pdos)?;
        }
    }
    Ok(())
}

/// Runs cycles (one every `cycle_ns`) until every axis has reached its goal, at most
/// `max_cycles`; the error names the first axis that did not and its state.
pub fn drive_to_goal<I: Io>(m: &mut Master<I>, axes: &mut [Axis], cycle_ns: u64, max_cycles: u64) -> Result<u64> {
    let mut next = m.engine.io.now_ns();
    for k in 0..max_cycles {
        m.cyclic().cycle()?;
        let mut done = true;
        for a in axes.iter_mut() {
            let s = a.update(m);
            done &= match a.goal {
                Goal::OperationEnabled => a.feedback(m).ready,
                Goal::Disabled => s == Some(State::SwitchOnDisabled),
                Goal::QuickStop => matches!(s, Some(State::QuickStopActive | State::SwitchOnDisabled)),
            };
        }
        if done {
            return Ok(k + 1);
        }
        next += cycle_ns;
        m.engine.io.sleep_until(next);
    }
    let a = axes
        .iter()
        .find(|a| a.goal != Goal::OperationEnabled || !a.feedback(m).ready)
        .or(axes.first())
        .ok_or(MasterError::Config(ConfigError::NoAxes))?;
    let s = m.slave(a.position)?;
    Err(MasterError::of(
        a.position,
        &s.name,
        SlaveError::Cia402(Cia402Error::Stuck { state: a.state, wanted: a.goal.name(), cycles: max_cycles }),
    ))
}

#[cfg(test)]
mod tests {
    use super::interpolation_period;

    #[test]
    fn interpolation_periods_are_value_times_a_power_of_ten() {
        assert_eq!(interpolation_period(1_000_000), Some((1, -3)));
        assert_eq!(interpolation_period(250_000), Some((25, -5)));
        assert_eq!(interpolation_period(125_000), Some((125, -6)));
        assert_eq!(interpolation_period(2_000_000_000), Some((2, 0)));
        assert_eq!(interpolation_period(62_500), None, "625 × 10⁻⁷ s: no u8 value");
        assert_eq!(interpolation_period(0), None);
        assert_eq!(interpolation_period(300_000_000_000), None, "300 s");
    }
}
