//! The profile objects a CiA402 drive needs, added where the dictionary (from an ESI file or
//! an SII) does not already describe them, and typed access to their values.
use ferrocat_wire::cia402::{index as ix, Mode};

use crate::od::{data_type as dt, Access, Entry, Object, ObjectCode, ObjectDictionary};

fn access(write: bool, rx: bool, tx: bool) -> Access {
    Access { read: true, write, write_preop_only: false, rx_mappable: rx, tx_mappable: tx }
}

/// Sync types supported (0x1C32:04, ETG.1020): free run, SM-synchronous, DC SYNC0.
pub const SYNC_TYPES_SUPPORTED: u16 = 0b0000_0111;
/// 0x1C32:01 values.
pub const SYNC_FREE_RUN: u16 = 0;
pub const SYNC_SM: u16 = 1;
pub const SYNC_DC_SYNC0: u16 = 2;

/// The modes the simulated drive runs.
pub const MODES: [Mode; 7] = [
    Mode::ProfilePosition,
    Mode::ProfileVelocity,
    Mode::Homing,
    Mode::InterpolatedPosition,
    Mode::CyclicSyncPosition,
    Mode::CyclicSyncVelocity,
    Mode::CyclicSyncTorque,
];

/// A record's entry of up to 32 bits, not mappable.
fn entry(sub: u8, name: &str, ty: u16, bits: u16, write: bool, v: u32) -> Entry {
    Entry {
        subindex: sub,
        name: name.into(),
        data_type: ty,
        bit_len: bits,
        bit_offset: 0,
        access: access(write, false, false),
        value: v.to_le_bytes()[..(bits as usize / 8)].to_vec(),
    }
}

fn sync_parameters(index: u16, name: &str, min_cycle_ns: u32, calc_copy_ns: u32) -> Object {
    let mut o = Object::list(
        index,
        name,
        ObjectCode::Record,
        0x0042,
        Access::RO,
        vec![
            entry(0x01, "Synchronization type", dt::UNSIGNED16, 16, true, SYNC_FREE_RUN as u32),
            entry(0x02, "Cycle time", dt::UNSIGNED32, 32, true, 0),
            entry(0x03, "Shift time", dt::UNSIGNED32, 32, false, 0),
            entry(0x04, "Synchronization types supported", dt::UNSIGNED16, 16, false, SYNC_TYPES_SUPPORTED as u32),
            entry(0x05, "Minimum cycle time", dt::UNSIGNED32, 32, false, min_cycle_ns),
            entry(0x06, "Calc and copy time", dt::UNSIGNED32, 32, false, calc_copy_ns),
            entry(0x09, "Delay time", dt::UNSIGNED32, 32, false, 0),
            entry(0x0A, "Sync0 cycle time", dt::UNSIGNED32, 32, false, 0),
            entry(0x0B, "SM event missed", dt::UNSIGNED16, 16, false, 0),
            entry(0x0C, "Cycle time too small", dt::UNSIGNED16, 16, false, 0),
            entry(0x20, "Sync error", dt::BOOLEAN, 8, false, 0),
        ],
    );
    // Subindex 0 holds the highest subindex, not the count.
    if let Some(s0) = o.entry_mut(0) {
        s0.value = vec![0x20];
    }
    o
}

/// Axes at most (CiA 402-2 gives each of up to eight axes its 0x800 of the profile area).
pub const MAX_AXES: u16 = 8;

/// The object offsets of the axes `od` has: the first axis always, and axis n (n × 0x800)
/// where its controlword and statusword are.
pub fn axis_bases(od: &ObjectDictionary) -> Vec<u16> {
    (0..MAX_AXES)
        .map(|n| n * 0x800)
        .filter(|&b| b == 0 || (od.get(ix::CONTROLWORD + b).is_some() && od.get(ix::STATUSWORD + b).is_some()))
        .collect()
}

/// Adds the profile's objects that `od` lacks, for every axis at `bases`, with the model's
/// defaults.
pub fn complete_profile(od: &mut ObjectDictionary, bases: &[u16], max_processing_ns: u32) {
    for &base in bases {
        complete_axis(od, base);
    }
    for (index, name) in [(0x1C32, "SM output parameter"), (0x1C33, "SM input parameter")] {
        if od.get(index).is_none() {
            od.insert(sync_parameters(index, name, 125_000, max_processing_ns));
        }
    }
}

/// The profile's objects for the axis whose objects sit `base` above the first axis's.
fn complete_axis(od: &mut ObjectDictionary, base: u16) {
    let supported: u32 = MODES.iter().map(|m| m.supported_bit()).sum();
    // The option codes' defaults are the profile's (CiA 402-2): shutdown coasts, disable
    // operation and the quick stop brake (profile and quick-stop deceleration), a fault at the
    // quick-stop deceleration, halt at the profile deceleration.
    let vars: [(u16, &str, u16, u16, Access, i64); 33] = [
        (ix::ERROR_CODE, "Error code", dt::UNSIGNED16, 16, access(false, false, true), 0),
        (ix::CONTROLWORD, "Controlword", dt::UNSIGNED16, 16, access(true, true, false), 0),
        (ix::STATUSWORD, "Statusword", dt::UNSIGNED16, 16, access(false, false, true), 0),
        (ix::QUICK_STOP_OPTION, "Quick stop option code", dt::INTEGER16, 16, access(true, false, false), 2),
        (ix::SHUTDOWN_OPTION, "Shutdown option code", dt::INTEGER16, 16, access(true, false, false), 0),
        (
            ix::DISABLE_OPERATION_OPTION,
            "Disable operation option code",
            dt::INTEGER16,
            16,
            access(true, false, false),
            1,
        ),
        (ix::HALT_OPTION, "Halt option code", dt::INTEGER16, 16, access(true, false, false), 1),
        (ix::FAULT_REACTION_OPTION, "Fault reaction option code", dt::INTEGER16, 16, access(true, false, false), 2),
        // Linear interpolation, the only kind the model runs.
        (ix::INTERPOLATION_SUB_MODE, "Interpolation sub mode select", dt::INTEGER16, 16, access(true, false, false), 0),
        (ix::MODES_OF_OPERATION, "Modes of operation", dt::INTEGER8, 8, access(true, true, false), 0),
        (ix::MODES_OF_OPERATION_DISPLAY, "Modes of operation display", dt::INTEGER8, 8, access(false, false, true), 0),
        (ix::POSITION_ACTUAL, "Position actual value", dt::INTEGER32, 32, access(false, false, true), 0),
        // 0.1 rev at the default resolution, for 100 ms.
        (ix::FOLLOWING_ERROR_WINDOW, "Following error window", dt::UNSIGNED32, 32, access(true, false, false), 13_107),
        (ix::FOLLOWING_ERROR_TIMEOUT, "Following error time out", dt::UNSIGNED16, 16, access(true, false, false), 100),
        (ix::VELOCITY_ACTUAL, "Velocity actual value", dt::INTEGER32, 32, access(false, false, true), 0),
        // Profile velocity: target reached within 0.05 rev/s, zero speed below 0.01 rev/s,
        // each for 10 ms.
        (ix::VELOCITY_WINDOW, "Velocity window", dt::UNSIGNED16, 16, access(true, false, false), 6_554),
        (ix::VELOCITY_WINDOW_TIME, "Velocity window time", dt::UNSIGNED16, 16, access(true, false, false), 10),
        (ix::VELOCITY_THRESHOLD, "Velocity threshold", dt::UNSIGNED16, 16, access(true, false, false), 1_311),
        (ix::VELOCITY_THRESHOLD_TIME, "Velocity threshold time", dt::UNSIGNED16, 16, access(true, false, false), 10),
        (ix::TARGET_TORQUE, "Target torque", dt::INTEGER16, 16, access(true, true, false), 0),
        (ix::MAX_TORQUE, "Max torque", dt::UNSIGNED16, 16, access(true, true, false), 3000),
        (ix::TORQUE_ACTUAL, "Torque actual value", dt::INTEGER16, 16, access(false, false, true), 0),
        (ix::TARGET_POSITION, "Target position", dt::INTEGER32, 32, access(true, true, false), 0),
        (ix::HOME_OFFSET, "Home offset", dt::INTEGER32, 32, access(true, false, false), 0),
        // Homing on the current position (37) until told otherwise.
        (ix::HOMING_METHOD, "Homing method", dt::INTEGER8, 8, access(true, false, false), 37),
        (ix::HOMING_ACCELERATION, "Homing acceleration", dt::UNSIGNED32, 32, access(true, false, false), 655_360),
        (ix::PROFILE_VELOCITY, "Profile velocity", dt::UNSIGNED32, 32, access(true, true, false), 131_072),
        (ix::PROFILE_ACCELERATION, "Profile acceleration", dt::UNSIGNED32, 32, access(true, true, false), 655_360),
        (ix::PROFILE_DECELERATION, "Profile deceleration", dt::UNSIGNED32, 32, access(true, true, false), 655_360),
        (
            ix::QUICK_STOP_DECELERATION,
            "Quick stop deceleration",
            dt::UNSIGNED32,
            32,
            access(true, false, false),
            2_621_440,
        ),
        (ix::FOLLOWING_ERROR_ACTUAL, "Following error actual value", dt::INTEGER32, 32, access(false, false, true), 0),
        (ix::TARGET_VELOCITY, "Target velocity", dt::INTEGER32, 32, access(true, true, false), 0),
        (ix::DIGITAL_INPUTS, "Digital inputs", dt::UNSIGNED32, 32, access(false, false, true), 0),
    ];
    for (index, name, ty, bits, acc, v) in vars {
        let index = index + base;
        if od.get(index).is_none() {
            od.insert(Object::var(index, name, ty, bits, acc, v.to_le_bytes()[..bits as usize / 8].to_vec()));
        }
    }
    if od.get(ix::HOMING_SPEEDS + base).is_none() {
        let speed = |sub: u8, name: &str, v: u32| Entry {
            subindex: sub,
            name: name.into(),
            data_type: dt::UNSIGNED32,
            bit_len: 32,
            bit_offset: 0,
            access: access(true, false, false),
            value: v.to_le_bytes().to_vec(),
        };
        // 1 rev/s looking for a switch, 0.25 rev/s for the index pulse.
        od.insert(Object::list(
            ix::HOMING_SPEEDS + base,
            "Homing speeds",
            ObjectCode::Array,
            dt::UNSIGNED32,
            Access::RO,
            vec![speed(1, "Speed during search for switch", 131_072), speed(2, "Speed during search for zero", 32_768)],
        ));
    }
    let sub = |sub: u8, name: &str, ty: u16, bits: u16, acc: Access, v: i64| Entry {
        subindex: sub,
        name: name.into(),
        data_type: ty,
        bit_len: bits,
        bit_offset: 0,
        access: acc,
        value: v.to_le_bytes()[..bits as usize / 8].to_vec(),
    };
    if od.get(ix::INTERPOLATION_DATA + base).is_none() {
        od.insert(Object::list(
            ix::INTERPOLATION_DATA + base,
            "Interpolation data record",
            ObjectCode::Array,
            dt::INTEGER32,
            Access::RO,
            vec![sub(1, "1st set-point", dt::INTEGER32, 32, access(true, true, false), 0)],
        ));
    }
    if od.get(ix::INTERPOLATION_TIME_PERIOD + base).is_none() {
        // 1 ms (1 × 10⁻³ s) until the master says its cycle.
        od.insert(Object::list(
            ix::INTERPOLATION_TIME_PERIOD + base,
            "Interpolation time period",
            ObjectCode::Record,
            0x0080,
            Access::RO,
            vec![
                sub(1, "Interpolation time period value", dt::UNSIGNED8, 8, access(true, false, false), 1),
                sub(2, "Interpolation time index", dt::INTEGER8, 8, access(true, false, false), -3),
            ],
        ));
    }
    if od.get(ix::SUPPORTED_DRIVE_MODES + base).is_none() {
        od.insert(Object::var(
            ix::SUPPORTED_DRIVE_MODES + base,
            "Supported drive modes",
            dt::UNSIGNED32,
            32,
            Access::RO,
            supported.to_le_bytes().to_vec(),
        ));
    }
}

/// ETG.1020's error settings (0x10F1) as the Slave Stack Code's dictionary has them: local
/// error reaction 1, and the sync error counter limit (writable; 0 turns the reaction off).
pub fn add_error_settings(od: &mut ObjectDictionary, limit: u16) {
    if od.get(0x10F1).is_none() {
        od.insert(Object::list(
            0x10F1,
            "Error settings",
            ObjectCode::Record,
            0x0000,
            Access::RO,
            vec![
                entry(0x01, "Local error reaction", dt::UNSIGNED32, 32, true, 1),
                entry(0x02, "Sync error counter limit", dt::UNSIGNED16, 16, true, 0),
            ],
        ));
    }
    set(od, 0x10F1, 2, limit as i64);
}

/// A value of an entry as a little-endian signed integer of its width (0 when absent).
pub fn get(od: &ObjectDictionary, index: u16, sub: u8) -> i64 {
    let Ok(v) = od.read(index, sub) else { return 0 };
    match v.len() {
        1 => v[0] as i8 as i64,
        2 => i16::from_le_bytes([v[0], v[1]]) as i64,
        4 => i32::from_le_bytes([v[0], v[1], v[2], v[3]]) as i64,
        _ => 0,
    }
}

/// The same value read as unsigned.
pub fn get_unsigned(od: &ObjectDictionary, index: u16, sub: u8) -> u64 {
    let Ok(v) = od.read(index, sub) else { return 0 };
    v.iter().take(8).rev().fold(0u64, |a, &b| a << 8 | b as u64)
}

/// Sets an entry the drive produces (its width decides the bytes; absent entries are skipped).
pub fn set(od: &mut ObjectDictionary, index: u16, sub: u8, value: i64) {
    if let Some(e) = od.objects.get_mut(&index).and_then(|o| o.entry_mut(sub)) {
        let n = e.value.len().min(8);
        e.value[..n].copy_from_slice(&value.to_le_bytes()[..n]);
    }
}
