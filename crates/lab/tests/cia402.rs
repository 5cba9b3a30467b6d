//! The simulated CiA402 drive against the master's driver, in virtual time: every transition of
//! the state machine, a following-error fault and its reset, CSP, CSV and CST — for the built-in
//! servo and for the Nanotec drive as its ESI file describes it.
use ferrocat_esc::{Cia402Drive, Switches};
use ferrocat_master::cia402::Output;
use ferrocat_master::cia402::{drive_to_goal, map_for_csp, Axis, Goal};
use ferrocat_master::{DcConfig, Master, MasterEvent};
use ferrocat_segment::SegmentConfig;
use ferrocat_segment::{HostModel, VirtualIo};
use ferrocat_wire::cia402::{error_code, index as ix, Mode, State};

const CYCLE_NS: u64 = 1_000_000;
const DRIVE: u16 = 1;

fn master(drive_toml: &str, prepare: &dyn Fn(&mut Master<VirtualIo>)) -> Master<VirtualIo> {
    let toml = format!("seed = 3\n[[device]]\nbuiltin = 'EK1100'\n[[device]]\n{drive_toml}\n");
    let cfg: SegmentConfig = toml::from_str(&toml).unwrap();
    let mut m = Master::new(VirtualIo::new(cfg.build().unwrap(), HostModel::pc_rt(), 3));
    m.states().scan().unwrap();
    m.states().configure().unwrap();
    prepare(&mut m);
    m.dc()
        .init_dc(&DcConfig {
            sync0_slaves: Some(vec![DRIVE]),
            sync0_shift_ns: 500_000,
            start_delay_ns: 10_000_000,
            ..DcConfig::default()
        })
        .unwrap();
    m.states().start().unwrap();
    // Until SYNC0 runs, a DC-synchronous drive takes no set-points.
    cycles(&mut m, 20);
    m
}

fn cycles(m: &mut Master<VirtualIo>, n: u64) {
    for _ in 0..n {
        m.cyclic().cycle().unwrap();
        let now = m.cyclic().now_ns();
        m.cyclic().sleep_until(now + CYCLE_NS);
    }
}

fn drive(m: &Master<VirtualIo>) -> &Cia402Drive {
    m.io().seg.nodes[DRIVE as usize].esc.app().as_any().downcast_ref::<Cia402Drive>().unwrap()
}

/// Writes `cw`, runs a few cycles, returns the state the statusword reports.
fn command(m: &mut Master<VirtualIo>, a: &Axis, cw: u16) -> Option<State> {
    a.write(m, Output::Controlword(cw));
    cycles(m, 4);
    State::from_statusword(a.feedback(m).statusword)
}

fn walk_every_transition(drive_toml: &str, prepare: &dyn Fn(&mut Master<VirtualIo>)) {
    use State::*;
    let mut m = master(drive_toml, prepare);
    assert!(drive(&m).dc_synchronous(), "the drive takes its set-points on SYNC0");
    let mut a = Axis::on_axis(&m, DRIVE, 0).unwrap();
    a.set_mode(&mut m, Mode::CyclicSyncPosition).unwrap();
    cycles(&mut m, 4);
    assert_eq!(State::from_statusword(a.feedback(&m).statusword), Some(SwitchOnDisabled));
    // Keep the target on the actual position while enabling (a CSP start without a jump).
    let hold = |m: &mut Master<VirtualIo>, a: &Axis| {
        let p = a.feedback(m).position.unwrap();
        a.write(m, Output::Position(p));
    };
    let up = |m: &mut Master<VirtualIo>, a: &Axis| {
        hold(m, a);
        assert_eq!(command(m, a, 0x06), Some(ReadyToSwitchOn), "2");
        assert_eq!(command(m, a, 0x07), Some(SwitchedOn), "3");
        assert_eq!(command(m, a, 0x0F), Some(OperationEnabled), "4");
    };
    up(&mut m, &a);
    assert_eq!(command(&mut m, &a, 0x07), Some(SwitchedOn), "5");
    assert_eq!(command(&mut m, &a, 0x06), Some(ReadyToSwitchOn), "6");
    assert_eq!(command(&mut m, &a, 0x00), Some(SwitchOnDisabled), "7");
    up(&mut m, &a);
    assert_eq!(command(&mut m, &a, 0x06), Some(ReadyToSwitchOn), "8");
    assert_eq!(command(&mut m, &a, 0x07), Some(SwitchedOn), "3");
    assert_eq!(command(&mut m, &a, 0x00), Some(SwitchOnDisabled), "10");
    up(&mut m, &a);
    assert_eq!(command(&mut m, &a, 0x00), Some(SwitchOnDisabled), "9");
    // Quick stop with option code 2: decelerate, then switch on disabled (11, 12).
    m.acyclic().coe().sdo_write(DRIVE, ix::QUICK_STOP_OPTION, 0, &2i16.to_le_bytes()).unwrap();
    up(&mut m, &a);
    a.write(&mut m, Output::Controlword(0x02));
    m.cyclic().cycle().unwrap();
    let mut seen_quick_stop = false;
    for _ in 0..50 {
        cycles(&mut m, 1);
        match State::from_statusword(a.feedback(&m).statusword) {
            // The statusword answers a cycle or two later.
            Some(OperationEnabled) if !seen_quick_stop => {}
            Some(QuickStopActive) => seen_quick_stop = true,
            Some(SwitchOnDisabled) => break,
            other => panic!("11/12: {other:?}"),
        }
    }
    assert!(seen_quick_stop, "11: quick stop active first");
    assert_eq!(State::from_statusword(a.feedback(&m).statusword), Some(SwitchOnDisabled), "12");
    // Option code 6: stay in quick stop active; enable operation returns (16).
    m.acyclic().coe().sdo_write(DRIVE, ix::QUICK_STOP_OPTION, 0, &6i16.to_le_bytes()).unwrap();
    up(&mut m, &a);
    assert_eq!(command(&mut m, &a, 0x02), Some(QuickStopActive), "11");
    cycles(&mut m, 20);
    assert_eq!(State::from_statusword(a.feedback(&m).statusword), Some(QuickStopActive), "stays with option 6");
    hold(&mut m, &a);
    assert_eq!(command(&mut m, &a, 0x0F), Some(OperationEnabled), "16");
    // 13, 14: a blocked axis (its torque limit below friction) behind a target beyond the
    // following-error window for longer than the window's timeout.
    m.diagnosis().take_events();
    m.acyclic().coe().sdo_write(DRIVE, ix::MAX_TORQUE, 0, &1u16.to_le_bytes()).unwrap();
    m.acyclic().coe().sdo_write(DRIVE, ix::FOLLOWING_ERROR_WINDOW, 0, &13_107u32.to_le_bytes()).unwrap();
    let p = a.feedback(&m).position.unwrap();
    a.write(&mut m, Output::Position(p.wrapping_add(30_000)));
    let mut states = Vec::new();
    for _ in 0..400 {
        cycles(&mut m, 1);
        let s = State::from_statusword(a.feedback(&m).statusword);
        if states.last() != Some(&s) {
            states.push(s);
        }
        if s == Some(Fault) {
            break;
        }
    }
    // At standstill the fault reaction (13) ends at once; `run_modes` sees it while moving.
    assert_eq!(states.last(), Some(&Some(Fault)), "13, 14: {states:?}");
    let code = m.acyclic().coe().sdo_read(DRIVE, ix::ERROR_CODE, 0).unwrap();
    assert_eq!(u16::from_le_bytes([code[0], code[1]]), error_code::FOLLOWING_ERROR);
    m.acyclic().poll_mailboxes().unwrap();
    assert!(
        m.diagnosis().events().iter().any(|e| matches!(e, MasterEvent::Emergency { error_code: 0x8611, .. })),
        "an emergency: {:?}",
        m.diagnosis().events()
    );
    m.acyclic().coe().sdo_write(DRIVE, ix::MAX_TORQUE, 0, &3000u16.to_le_bytes()).unwrap();
    // Faults ignore everything but a rising edge of bit 7 (15).
    assert_eq!(command(&mut m, &a, 0x0F), Some(Fault));
    assert_eq!(command(&mut m, &a, 0x80), Some(SwitchOnDisabled), "15");
    let code = m.acyclic().coe().sdo_read(DRIVE, ix::ERROR_CODE, 0).unwrap();
    assert_eq!(code[..2], [0, 0], "the error code clears with the reset");
    // The driver brings it back from a fault on its own.
    drive_mut(&mut m).inject_fault(error_code::OVERCURRENT);
    cycles(&mut m, 2);
    assert_eq!(State::from_statusword(a.feedback(&m).statusword), Some(Fault));
    a.set_goal(Goal::OperationEnabled);
    let n = drive_to_goal(&mut m, std::slice::from_mut(&mut a), CYCLE_NS, 100).unwrap();
    assert!(a.faults >= 1 && n > 3, "{n} cycles, {} faults", a.faults);
}

fn drive_mut(m: &mut Master<VirtualIo>) -> &mut Cia402Drive {
    m.cyclic().io_mut().seg.nodes[DRIVE as usize].esc.app_mut().as_any_mut().downcast_mut::<Cia402Drive>().unwrap()
}

/// 500 cycles of position set-points from `p0`: up to `v` (increments/s) over 100 ms, then at
/// that speed (0.9 s of travel at `v` in all); the statusword after each cycle.
fn follow_ramp(m: &mut Master<VirtualIo>, a: &mut Axis, p0: f64, v: f64) -> Vec<u16> {
    (0..500)
        .map(|k| {
            let t = k as f64 * 1e-3;
            let p = if t < 0.1 { 0.5 * v / 0.1 * t * t } else { v * 0.05 + v * (t - 0.1) };
            a.write(m, Output::Position((p0 + p) as i64 as i32));
            cycles(m, 1);
            a.update(m);
            a.feedback(m).statusword
        })
        .collect()
}

/// CSP follows a ramp with a small following error; CSV reaches its speed; CST accelerates
/// the inertia as the torque says.
fn run_modes(drive_toml: &str, prepare: &dyn Fn(&mut Master<VirtualIo>)) {
    let mut m = master(drive_toml, prepare);
    let mut a = Axis::on_axis(&m, DRIVE, 0).unwrap();
    let per_rev = drive(&m).motor().increments_per_rev;
    // CSP: enable without a jump, then 2 rev/s for half a second.
    a.set_mode(&mut m, Mode::CyclicSyncPosition).unwrap();
    a.set_goal(Goal::OperationEnabled);
    drive_to_goal(&mut m, std::slice::from_mut(&mut a), CYCLE_NS, 100).unwrap();
    let p0 = a.feedback(&m).position.unwrap() as f64;
    let actual0 = drive(&m).position_increments();
    assert!((p0 - actual0).abs() < 2.0, "image {p0} vs drive {actual0}");
    drive_mut(&mut m).reset_stats();
    follow_ramp(&mut m, &mut a, p0, 2.0 * per_rev);
    let fe = drive(&m).stats.max_following_error;
    assert!(fe < 0.01 * per_rev, "CSP following error {fe} increments");
    assert_eq!(a.state(), Some(State::OperationEnabled));
    let moved = (drive(&m).position_increments() - actual0) / per_rev;
    assert!((moved - 0.9).abs() < 0.05, "moved {moved} rev (0.9 commanded, minus the pipeline)");
    // CSV: 5 rev/s.
    a.set_mode(&mut m, Mode::CyclicSyncVelocity).unwrap();
    for _ in 0..300 {
        if a.feedback(&m).ready {
            a.write(&mut m, Output::Velocity((5.0 * per_rev) as i32));
        }
        cycles(&mut m, 1);
        a.update(&mut m);
    }
    let vel = drive(&m).velocity_increments() / per_rev;
    assert!((vel - 5.0).abs() < 0.05, "CSV: {vel} rev/s");
    if a.feedback(&m).velocity.is_some() {
        assert!((a.feedback(&m).velocity.unwrap() as f64 / per_rev - 5.0).abs() < 0.05);
    }
    // A fault while moving: the reaction decelerates (13), then the fault (14); the driver
    // resets it and enables again.
    drive_mut(&mut m).inject_fault(error_code::DC_LINK_UNDERVOLTAGE);
    // From the state it was in: the first cycle after the injection may still show it (the
    // drive takes the fault at its next processing, which the seed places).
    let mut states = vec![Some(State::OperationEnabled)];
    for _ in 0..1000 {
        cycles(&mut m, 1);
        let s = a.update(&mut m);
        if states.last() != Some(&s) {
            states.push(s);
        }
        if a.feedback(&m).ready && states.len() > 3 {
            break;
        }
    }
    assert_eq!(
        states[1..4],
        [Some(State::FaultReactionActive), Some(State::Fault), Some(State::SwitchOnDisabled)],
        "{states:?}"
    );
    assert!(a.feedback(&m).ready, "{states:?}");
    // CST: from the speed reached, 100 ‰ of rated torque for 100 ms.
    a.set_mode(&mut m, Mode::CyclicSyncTorque).unwrap();
    let mut v0 = None;
    for _ in 0..200 {
        if a.feedback(&m).ready {
            a.write(&mut m, Output::Torque(100));
            v0.get_or_insert(drive(&m).velocity_increments());
        }
        cycles(&mut m, 1);
        a.update(&mut m);
        if v0.is_some() && a.feedback(&m).ready && drive(&m).torque_nm() > 0.05 {
            break;
        }
    }
    let (w0, t0) = (drive(&m).velocity_increments(), m.cyclic().now_ns());
    cycles(&mut m, 100);
    let dt = (m.cyclic().now_ns() - t0) as f64 * 1e-9;
    let d = drive(&m);
    let p = *d.motor();
    let accel = (d.velocity_increments() - w0) / per_rev * std::f64::consts::TAU / dt;
    // a = (T − Coulomb − viscous·ω) / J at about 5 rev/s.
    let w = w0 / per_rev * std::f64::consts::TAU;
    let expected = (0.1 * p.rated_torque_nm - p.coulomb_nm - p.viscous_nm_per_rad_s * w) / p.inertia_kg_m2;
    assert!((accel - expected).abs() / expected < 0.1, "CST: {accel} rad/s² vs {expected}");
    if let Some(t) = a.feedback(&m).torque {
        assert!((t - 100).abs() <= 2, "torque actual {t} ‰");
    }
}

#[test]
fn the_builtin_servo_walks_every_transition() {
    walk_every_transition("builtin = 'SERVO'", &|_| {});
}

#[test]
fn the_builtin_servo_runs_csp_csv_and_cst() {
    run_modes("builtin = 'SERVO'", &|_| {});
}

fn nanotec() -> String {
    let p = ferrocat_testdata::shared("esi/Nanotec_C5-E-2-21.xml");
    format!("esi = '{}'\nproduct = '#x4F'", p.display())
}

#[test]
fn needs_shared_nanotec_esi_walks_every_transition() {
    // Its dictionary assigns only the PDOs with the controlword and statusword by default: the
    // driver adds the ESI's PDOs with the target position and the position actual value.
    walk_every_transition(&nanotec(), &|m| {
        assert!(Axis::on_axis(m, DRIVE, 0).unwrap().feedback(m).position.is_none());
        map_for_csp(m, DRIVE).unwrap();
        assert!(Axis::on_axis(m, DRIVE, 0).unwrap().feedback(m).position.is_some());
    });
}

#[test]
fn needs_shared_nanotec_esi_runs_csp_csv_and_cst_after_remapping() {
    run_modes(&nanotec(), &|m| {
        // The ESI's default PDOs carry no target velocity or torque: map them into 0x1602 and
        // their actual values into 0x1A02, as an integrator would.
        let w =
            |m: &mut Master<VirtualIo>, i: u16, s: u8, v: &[u8]| m.acyclic().coe().sdo_write(DRIVE, i, s, v).unwrap();
        w(m, 0x1602, 0, &[0]);
        w(m, 0x1602, 1, &0x60FF_0020u32.to_le_bytes());
        w(m, 0x1602, 2, &0x6071_0010u32.to_le_bytes());
        w(m, 0x1602, 0, &[2]);
        w(m, 0x1A02, 0, &[0]);
        w(m, 0x1A02, 1, &0x606C_0020u32.to_le_bytes());
        w(m, 0x1A02, 2, &0x6077_0010u32.to_le_bytes());
        w(m, 0x1A02, 0, &[2]);
        m.config().remap(DRIVE, true, &[0x1600, 0x1601, 0x1602]).unwrap();
        m.config().remap(DRIVE, false, &[0x1A00, 0x1A01, 0x1A02]).unwrap();
        // The Nanotec's defaults (a 10 % torque limit, a 256-increment window) are tighter than
        // the test's moves: set them as an integrator would.
        w(m, ix::MAX_TORQUE, 0, &3000u16.to_le_bytes());
        w(m, ix::FOLLOWING_ERROR_WINDOW, 0, &13_107u32.to_le_bytes());
        w(m, ix::QUICK_STOP_DECELERATION, 0, &2_621_440u32.to_le_bytes());
    });
}

/// Profile position: a new set-point on the rising edge of bit 4, acknowledged in bit 12, the
/// drive's own trapezoid to the target, target reached in bit 10.
#[test]
fn the_builtin_servo_runs_profile_position() {
    use ferrocat_wire::cia402::{control, status};
    let mut m = master("builtin = 'SERVO'", &|_| {});
    let mut a = Axis::on_axis(&m, DRIVE, 0).unwrap();
    a.set_mode(&mut m, Mode::ProfilePosition).unwrap();
    a.set_goal(Goal::OperationEnabled);
    drive_to_goal(&mut m, std::slice::from_mut(&mut a), CYCLE_NS, 100).unwrap();
    let per_rev = drive(&m).motor().increments_per_rev;
    // 3 rev/s, 30 rev/s² both ways; 2 revolutions from here.
    m.acyclic().coe().sdo_write(DRIVE, ix::PROFILE_VELOCITY, 0, &((3.0 * per_rev) as u32).to_le_bytes()).unwrap();
    for i in [ix::PROFILE_ACCELERATION, ix::PROFILE_DECELERATION] {
        m.acyclic().coe().sdo_write(DRIVE, i, 0, &((30.0 * per_rev) as u32).to_le_bytes()).unwrap();
    }
    let start = a.feedback(&m).position.unwrap();
    let target = start.wrapping_add((2.0 * per_rev) as i32);
    a.write(&mut m, Output::Position(target));
    a.write(&mut m, Output::Controlword(control::ENABLE_OPERATION_CMD | control::NEW_SETPOINT));
    let mut acknowledged = false;
    let mut reached_after = None;
    for k in 0..2000 {
        cycles(&mut m, 1);
        let sw = a.feedback(&m).statusword;
        if sw & status::OP_SPECIFIC_12 != 0 {
            acknowledged = true;
            a.write(&mut m, Output::Controlword(control::ENABLE_OPERATION_CMD));
        }
        if acknowledged && k > 10 && sw & status::TARGET_REACHED != 0 {
            reached_after = Some(k);
            break;
        }
    }
    assert!(acknowledged, "set-point acknowledge");
    let k = reached_after.expect("target reached") as f64 * 1e-3;
    // 2 rev at 3 rev/s with 0.1 s ramps each way: 0.767 s, plus the settling of the loops.
    assert!((0.7..1.0).contains(&k), "reached after {k} s");
    let end = a.feedback(&m).position.unwrap();
    assert!(end.wrapping_sub(target).abs() < 100, "ends at {end}, target {target}");
}

/// The AKD as its EEPROM dump describes it: its default PDOs carry an interpolated set-point
/// (0x60C1, mode 7, not modelled); the driver assigns the SII's PDOs with target and actual
/// position, and the drive's profile objects come from the model.
#[test]
fn needs_shared_akd_eeprom_walks_every_transition() {
    let p = ferrocat_testdata::shared("captures/eeprom/akd.hex");
    walk_every_transition(&format!("eeprom = '{}'", p.display()), &|m| {
        map_for_csp(m, DRIVE).unwrap();
        let s = m.slaves().at(DRIVE).unwrap();
        assert!(
            s.mapping().outputs.iter().any(|e| e.index == 0x607A)
                && s.mapping().inputs.iter().any(|e| e.index == 0x6064)
        );
    });
}

/// Brings the built-in servo to operation enabled in `mode`; returns the master, the axis and
/// the drive's increments per revolution.
fn enabled_in(mode: Mode) -> (Master<VirtualIo>, Axis, f64) {
    let mut m = master("builtin = 'SERVO'", &|_| {});
    let mut a = Axis::on_axis(&m, DRIVE, 0).unwrap();
    a.set_mode(&mut m, mode).unwrap();
    a.set_goal(Goal::OperationEnabled);
    drive_to_goal(&mut m, std::slice::from_mut(&mut a), CYCLE_NS, 100).unwrap();
    let per_rev = drive(&m).motor().increments_per_rev;
    (m, a, per_rev)
}

/// Runs 1 ms cycles until `sw` (the statusword) satisfies `done`; returns how many it took.
fn until(m: &mut Master<VirtualIo>, a: &Axis, max: u64, done: &dyn Fn(u16) -> bool) -> Option<u64> {
    for k in 0..max {
        cycles(m, 1);
        if done(a.feedback(m).statusword) {
            return Some(k);
        }
    }
    None
}

/// Profile velocity: the drive ramps to the target velocity at the profile acceleration and
/// reports target reached (bit 10) once the velocity has stayed in its window for the window
/// time; halt (bit 8) brings it down at the deceleration, and bit 12 reports the shaft standing.
#[test]
fn the_builtin_servo_runs_profile_velocity() {
    use ferrocat_wire::cia402::{control, status};
    let (mut m, a, per_rev) = enabled_in(Mode::ProfileVelocity);
    m.acyclic().coe().sdo_write(DRIVE, ix::PROFILE_ACCELERATION, 0, &((20.0 * per_rev) as u32).to_le_bytes()).unwrap();
    m.acyclic().coe().sdo_write(DRIVE, ix::PROFILE_DECELERATION, 0, &((40.0 * per_rev) as u32).to_le_bytes()).unwrap();
    m.acyclic().coe().sdo_write(DRIVE, ix::VELOCITY_WINDOW_TIME, 0, &100u16.to_le_bytes()).unwrap();
    assert_ne!(a.feedback(&m).statusword & status::OP_SPECIFIC_12, 0, "standing before the move");
    let target = (4.0 * per_rev) as i32;
    a.write(&mut m, Output::Velocity(target));
    cycles(&mut m, 5);
    assert_eq!(a.feedback(&m).statusword & status::TARGET_REACHED, 0, "4 rev/s at 20 rev/s² takes 0.2 s");
    let k = until(&mut m, &a, 1000, &|sw| sw & status::TARGET_REACHED != 0).expect("target velocity reached") as f64;
    // The ramp's 0.2 s, then 0.1 s in the window.
    assert!((280.0..360.0).contains(&k), "reached after {k} ms");
    let v = a.feedback(&m).velocity.unwrap();
    assert!((v - target).abs() as f64 <= 0.05 * per_rev, "{v} against {target}");
    assert_eq!(a.feedback(&m).statusword & status::OP_SPECIFIC_12, 0, "moving");
    // Halt: down at 40 rev/s², 0.1 s.
    a.write(&mut m, Output::Controlword(control::ENABLE_OPERATION_CMD | control::HALT));
    let k = until(&mut m, &a, 1000, &|sw| sw & status::OP_SPECIFIC_12 != 0).expect("stopped") as f64;
    assert!((80.0..160.0).contains(&k), "stopped after {k} ms");
    assert!(a.feedback(&m).velocity.unwrap().abs() as f64 <= 0.01 * per_rev);
}

/// Halt in profile velocity stops the shaft as 0x605D says — 1 the profile deceleration, 2
/// the quick-stop deceleration, 3 the current limit — and the drive stays in operation
/// enabled: released, it runs up to the target again.
#[test]
fn halt_stops_as_its_option_code_says() {
    use ferrocat_wire::cia402::{control, status};
    let mut stops = Vec::new();
    for code in [1i16, 2, 3] {
        let (mut m, a, per_rev) = enabled_in(Mode::ProfileVelocity);
        m.acyclic()
            .coe()
            .sdo_write(DRIVE, ix::PROFILE_ACCELERATION, 0, &((50.0 * per_rev) as u32).to_le_bytes())
            .unwrap();
        m.acyclic()
            .coe()
            .sdo_write(DRIVE, ix::PROFILE_DECELERATION, 0, &((20.0 * per_rev) as u32).to_le_bytes())
            .unwrap();
        m.acyclic()
            .coe()
            .sdo_write(DRIVE, ix::QUICK_STOP_DECELERATION, 0, &((100.0 * per_rev) as u32).to_le_bytes())
            .unwrap();
        m.acyclic().coe().sdo_write(DRIVE, ix::HALT_OPTION, 0, &code.to_le_bytes()).unwrap();
        let target = (4.0 * per_rev) as i32;
        a.write(&mut m, Output::Velocity(target));
        cycles(&mut m, 5);
        assert_eq!(a.feedback(&m).statusword & (status::TARGET_REACHED | status::OP_SPECIFIC_12), 0, "accelerating");
        until(&mut m, &a, 1000, &|sw| sw & status::TARGET_REACHED != 0).expect("target velocity reached");
        a.write(&mut m, Output::Controlword(control::ENABLE_OPERATION_CMD | control::HALT));
        let k = until(&mut m, &a, 1000, &|sw| sw & status::OP_SPECIFIC_12 != 0).expect("stopped");
        let sw = a.feedback(&m).statusword;
        assert_eq!(sw & 0x6F, 0x27, "halt {code}: still operation enabled ({sw:#06x})");
        stops.push(k);
        a.write(&mut m, Output::Controlword(control::ENABLE_OPERATION_CMD));
        cycles(&mut m, 5);
        until(&mut m, &a, 1000, &|sw| sw & status::TARGET_REACHED != 0).expect("running again");
        let v = a.feedback(&m).velocity.unwrap();
        assert!((v - target).abs() as f64 <= 0.05 * per_rev, "halt {code}: {v} against {target} after release");
    }
    println!(
        "4 rev/s to standing (bit 12, 10 ms below 0.01 rev/s): halt 1 {} ms, 2 {} ms, 3 {} ms",
        stops[0], stops[1], stops[2]
    );
    // 0.2 s at 20 rev/s², 40 ms at 100 rev/s², shorter still at the current limit (each
    // with the 10 ms of standing that bit 12 waits for).
    assert!((180..260).contains(&stops[0]), "{stops:?}");
    assert!((35..80).contains(&stops[1]), "{stops:?}");
    assert!(stops[2] < stops[1], "{stops:?}");
}

/// Halt in profile position stops the move at the halt option's deceleration and keeps its
/// target: the drive reports target reached (halted, standing) short of it, and released,
/// the move goes on to the target.
#[test]
fn halt_interrupts_a_profile_position_move_and_release_resumes_it() {
    use ferrocat_wire::cia402::{control, status};
    let (mut m, a, per_rev) = enabled_in(Mode::ProfilePosition);
    m.acyclic().coe().sdo_write(DRIVE, ix::PROFILE_VELOCITY, 0, &((2.0 * per_rev) as u32).to_le_bytes()).unwrap();
    m.acyclic().coe().sdo_write(DRIVE, ix::PROFILE_ACCELERATION, 0, &((20.0 * per_rev) as u32).to_le_bytes()).unwrap();
    m.acyclic().coe().sdo_write(DRIVE, ix::PROFILE_DECELERATION, 0, &((20.0 * per_rev) as u32).to_le_bytes()).unwrap();
    let start = a.feedback(&m).position.unwrap();
    let target = start.wrapping_add((3.0 * per_rev) as i32);
    a.write(&mut m, Output::Position(target));
    a.write(&mut m, Output::Controlword(control::ENABLE_OPERATION_CMD | control::NEW_SETPOINT));
    until(&mut m, &a, 100, &|sw| sw & status::OP_SPECIFIC_12 != 0).expect("set-point acknowledged");
    a.write(&mut m, Output::Controlword(control::ENABLE_OPERATION_CMD));
    cycles(&mut m, 500);
    a.write(&mut m, Output::Controlword(control::ENABLE_OPERATION_CMD | control::HALT));
    // From 2 rev/s at 20 rev/s²: 0.1 s.
    let k = until(&mut m, &a, 1000, &|sw| sw & status::TARGET_REACHED != 0).expect("halted");
    cycles(&mut m, 20);
    let held = a.feedback(&m).position.unwrap();
    let v = a.feedback(&m).velocity.unwrap();
    println!("halted after {k} ms at {:.2} rev of 3", held.wrapping_sub(start) as f64 / per_rev);
    assert!((90..200).contains(&k), "{k} ms");
    assert!((v as f64).abs() < 0.01 * per_rev, "{v}");
    let done = held.wrapping_sub(start) as f64 / per_rev;
    assert!((0.5..2.0).contains(&done), "{done} rev");
    a.write(&mut m, Output::Controlword(control::ENABLE_OPERATION_CMD));
    cycles(&mut m, 5);
    assert_eq!(a.feedback(&m).statusword & status::TARGET_REACHED, 0, "moving again");
    until(&mut m, &a, 3000, &|sw| sw & status::TARGET_REACHED != 0).expect("target reached");
    let end = a.feedback(&m).position.unwrap();
    assert!(end.wrapping_sub(target).abs() < 100, "ends at {end}, target {target}");
}

/// Homing on the current position (method 37): the position actual becomes the home offset
/// where the shaft stands, at once; homing attained (bit 12) and target reached (bit 10).
#[test]
fn homing_on_the_current_position_sets_the_home_offset_there() {
    use ferrocat_wire::cia402::{control, status};
    let (mut m, a, _) = enabled_in(Mode::Homing);
    let before = a.feedback(&m).position.unwrap();
    m.acyclic().coe().sdo_write(DRIVE, ix::HOMING_METHOD, 0, &[37]).unwrap();
    m.acyclic().coe().sdo_write(DRIVE, ix::HOME_OFFSET, 0, &1_000i32.to_le_bytes()).unwrap();
    let sw = a.feedback(&m).statusword;
    assert_eq!(sw & (status::OP_SPECIFIC_12 | status::OP_SPECIFIC_13), 0, "not homed yet");
    a.write(&mut m, Output::Controlword(control::ENABLE_OPERATION_CMD | control::HOMING_START));
    let done = status::OP_SPECIFIC_12 | status::TARGET_REACHED;
    until(&mut m, &a, 20, &|sw| sw & done == done).expect("homing attained");
    // The position in the image was latched at the SYNC0 before the application homed.
    cycles(&mut m, 2);
    let after = a.feedback(&m).position.unwrap();
    assert!((after - 1_000).abs() <= 2, "position {after} after homing (was {before})");
}

/// Homing on the index pulse in the positive direction (method 34): the drive moves at the
/// zero-search speed to the next whole turn of the shaft, where the position then reads the
/// home offset, brakes at the homing acceleration and holds.
#[test]
fn homing_on_the_index_pulse_puts_the_home_offset_on_it() {
    use ferrocat_wire::cia402::{control, status};
    let (mut m, a, per_rev) = enabled_in(Mode::Homing);
    let start = drive(&m).position_increments();
    let index = (start / per_rev).ceil() * per_rev;
    m.acyclic().coe().sdo_write(DRIVE, ix::HOMING_METHOD, 0, &[34]).unwrap();
    m.acyclic().coe().sdo_write(DRIVE, ix::HOME_OFFSET, 0, &(-500i32).to_le_bytes()).unwrap();
    m.acyclic().coe().sdo_write(DRIVE, ix::HOMING_SPEEDS, 2, &((2.0 * per_rev) as u32).to_le_bytes()).unwrap();
    m.acyclic().coe().sdo_write(DRIVE, ix::HOMING_ACCELERATION, 0, &((50.0 * per_rev) as u32).to_le_bytes()).unwrap();
    a.write(&mut m, Output::Controlword(control::ENABLE_OPERATION_CMD | control::HOMING_START));
    cycles(&mut m, 5);
    let sw = a.feedback(&m).statusword;
    assert_eq!(sw & (status::OP_SPECIFIC_12 | status::TARGET_REACHED), 0, "searching: {sw:#06x}");
    assert!(a.feedback(&m).velocity.unwrap() > 0, "moving the positive way");
    let done = status::OP_SPECIFIC_12 | status::TARGET_REACHED;
    // At most a turn at 2 rev/s, then 40 ms of braking.
    let k = until(&mut m, &a, 1000, &|sw| sw & done == done).expect("homing attained");
    assert!(k < 700, "{k} ms");
    cycles(&mut m, 50);
    let shaft = drive(&m).position_increments();
    let actual = a.feedback(&m).position.unwrap() as f64;
    // Where the shaft stands now is as far past the index as the position is past the offset.
    assert!(((shaft - index) - (actual + 500.0)).abs() <= 2.0, "shaft {shaft}, index {index}, position {actual}");
    assert!(shaft > index && shaft - index < 0.1 * per_rev, "stopped just past the index: {}", shaft - index);
    assert_eq!(a.feedback(&m).statusword & status::OP_SPECIFIC_13, 0);
}

/// A homing method that needs a limit or home switch, which this drive does not have: homing
/// error (bit 13), and the shaft does not move.
#[test]
fn homing_methods_that_need_a_switch_end_in_a_homing_error() {
    use ferrocat_wire::cia402::{control, status};
    let (mut m, a, _) = enabled_in(Mode::Homing);
    let before = a.feedback(&m).position.unwrap();
    m.acyclic().coe().sdo_write(DRIVE, ix::HOMING_METHOD, 0, &[17]).unwrap();
    a.write(&mut m, Output::Controlword(control::ENABLE_OPERATION_CMD | control::HOMING_START));
    until(&mut m, &a, 20, &|sw| sw & status::OP_SPECIFIC_13 != 0).expect("homing error");
    assert_eq!(a.feedback(&m).statusword & status::OP_SPECIFIC_12, 0);
    cycles(&mut m, 50);
    assert!((a.feedback(&m).position.unwrap() - before).abs() < 50);
}

/// Profile position takes every rising edge of bit 4 as a new set-point: two moves in a row.
#[test]
fn profile_position_takes_one_set_point_after_another() {
    use ferrocat_wire::cia402::{control, status};
    let (mut m, a, per_rev) = enabled_in(Mode::ProfilePosition);
    let start = a.feedback(&m).position.unwrap();
    for (i, revs) in [1.0, -0.5].iter().enumerate() {
        let target = start.wrapping_add((revs * per_rev) as i32);
        a.write(&mut m, Output::Position(target));
        a.write(&mut m, Output::Controlword(control::ENABLE_OPERATION_CMD | control::NEW_SETPOINT));
        until(&mut m, &a, 100, &|sw| sw & status::OP_SPECIFIC_12 != 0).expect("set-point acknowledged");
        a.write(&mut m, Output::Controlword(control::ENABLE_OPERATION_CMD));
        until(&mut m, &a, 100, &|sw| sw & status::OP_SPECIFIC_12 == 0).expect("acknowledge cleared");
        until(&mut m, &a, 3000, &|sw| sw & status::TARGET_REACHED != 0).expect("target reached");
        let end = a.feedback(&m).position.unwrap();
        assert!(end.wrapping_sub(target).abs() < 100, "move {i}: ends at {end}, target {target}");
    }
}

/// The driver's own loop homes a drive: the mode bits set once ride along with every command
/// `update` sends, and clearing them interrupts homing as the profile says.
#[test]
fn the_driver_homes_through_its_update_loop() {
    use ferrocat_wire::cia402::{control, status};
    let (mut m, mut a, per_rev) = enabled_in(Mode::Homing);
    m.acyclic().coe().sdo_write(DRIVE, ix::HOMING_METHOD, 0, &[33]).unwrap();
    m.acyclic().coe().sdo_write(DRIVE, ix::HOMING_SPEEDS, 2, &((1.0 * per_rev) as u32).to_le_bytes()).unwrap();
    a.set_mode_bits(control::HOMING_START);
    let step = |m: &mut Master<VirtualIo>, a: &mut Axis| {
        a.update(m);
        cycles(m, 1);
    };
    for _ in 0..20 {
        step(&mut m, &mut a);
    }
    assert!(a.feedback(&m).velocity.unwrap() < 0, "searching the negative way");
    a.set_mode_bits(0);
    let mut interrupted = false;
    for _ in 0..300 {
        step(&mut m, &mut a);
        let sw = a.feedback(&m).statusword;
        if sw & status::TARGET_REACHED != 0 && a.feedback(&m).velocity.unwrap().abs() < (0.01 * per_rev) as i32 {
            interrupted = sw & (status::OP_SPECIFIC_12 | status::OP_SPECIFIC_13) == 0;
            break;
        }
    }
    assert!(interrupted, "stopped, not homed, no error");
    assert_eq!(a.state(), Some(State::OperationEnabled));
    a.set_mode_bits(control::HOMING_START);
    let done = status::OP_SPECIFIC_12 | status::TARGET_REACHED;
    let mut homed = false;
    for _ in 0..2000 {
        step(&mut m, &mut a);
        if a.feedback(&m).statusword & done == done {
            homed = true;
            break;
        }
    }
    assert!(homed, "homing attained after the restart");
}

/// The drive in `drive_toml` enabled in homing mode, with the homing speeds (rev/s) and
/// acceleration (rev/s²) set.
fn homing_with(drive_toml: &str, switch_rps: f64, zero_rps: f64, acc_rps2: f64) -> (Master<VirtualIo>, Axis, f64) {
    let mut m = master(drive_toml, &|_| {});
    let mut a = Axis::on_axis(&m, DRIVE, 0).unwrap();
    a.set_mode(&mut m, Mode::Homing).unwrap();
    a.set_goal(Goal::OperationEnabled);
    drive_to_goal(&mut m, std::slice::from_mut(&mut a), CYCLE_NS, 100).unwrap();
    let per_rev = drive(&m).motor().increments_per_rev;
    let u32le = |x: f64| ((x * per_rev) as u32).to_le_bytes();
    m.acyclic().coe().sdo_write(DRIVE, ix::HOMING_SPEEDS, 1, &u32le(switch_rps)).unwrap();
    m.acyclic().coe().sdo_write(DRIVE, ix::HOMING_SPEEDS, 2, &u32le(zero_rps)).unwrap();
    m.acyclic().coe().sdo_write(DRIVE, ix::HOMING_ACCELERATION, 0, &u32le(acc_rps2)).unwrap();
    (m, a, per_rev)
}

/// Starts homing method `method` with home offset `offset` and runs until the statusword says
/// attained (Ok, after how many cycles) or error (Err).
fn home(m: &mut Master<VirtualIo>, a: &Axis, method: i8, offset: i32, max: u64) -> Result<u64, u16> {
    use ferrocat_wire::cia402::{control, status};
    m.acyclic().coe().sdo_write(DRIVE, ix::HOMING_METHOD, 0, &[method as u8]).unwrap();
    m.acyclic().coe().sdo_write(DRIVE, ix::HOME_OFFSET, 0, &offset.to_le_bytes()).unwrap();
    a.write(m, Output::Controlword(control::ENABLE_OPERATION_CMD | control::HOMING_START));
    let done = status::OP_SPECIFIC_12 | status::TARGET_REACHED;
    let end = until(m, a, max, &|sw| sw & done == done || sw & status::OP_SPECIFIC_13 != 0).expect("homing ends");
    let sw = a.feedback(m).statusword;
    if sw & status::OP_SPECIFIC_13 != 0 {
        Err(sw)
    } else {
        Ok(end)
    }
}

/// Where the home position is on the shaft, from what the drive now reports: position actual
/// minus the offset is the shaft's distance past home.
fn home_on_shaft(m: &mut Master<VirtualIo>, a: &Axis, offset: i32) -> f64 {
    cycles(m, 20);
    drive(m).position_increments() - (a.feedback(m).position.unwrap() - offset) as f64
}

fn digital_inputs(m: &mut Master<VirtualIo>) -> u32 {
    u32::from_le_bytes(m.acyclic().coe().sdo_read(DRIVE, ix::DIGITAL_INPUTS, 0).unwrap()[..4].try_into().unwrap())
}

/// A home switch from the segment file (active above 5 rev of the shaft; the drive starts
/// within ±4 rev), method 20: up to the switch's edge, where the position then reads the
/// home offset; 0x60FD shows the switch.
#[test]
fn homing_on_a_home_switch_from_the_segment_file() {
    let (mut m, a, per_rev) = homing_with("builtin = 'SERVO'\nhome_switch_rev = 5.0", 5.0, 5.0, 100.0);
    assert_eq!(digital_inputs(&mut m), 0, "below the switch");
    let k = home(&mut m, &a, 20, 700, 5000).expect("homed");
    let home = home_on_shaft(&mut m, &a, 700);
    assert!((home - 5.0 * per_rev).abs() <= 2.0, "home at {} rev, after {k} ms", home / per_rev);
    let past = (drive(&m).position_increments() - home) / per_rev;
    // Braking from 5 rev/s at 100 rev/s²: 0.125 rev.
    assert!((0.1..0.2).contains(&past), "stopped {past} rev past the edge");
    assert_eq!(digital_inputs(&mut m), 0b100, "on the switch");
}

/// The negative limit switch and the index pulse (method 1): down to the switch, slowly back
/// off it, and home on the first index pulse above its edge.
#[test]
fn homing_on_the_negative_limit_switch_and_the_index_pulse() {
    let (mut m, a, per_rev) = homing_with("builtin = 'SERVO'", 4.0, 1.0, 50.0);
    let start_rev = drive(&m).position_increments() / per_rev;
    let limit_rev = start_rev - 1.3;
    drive_mut(&mut m).set_switches(Switches { negative_limit_rev: Some(limit_rev), ..Switches::default() });
    home(&mut m, &a, 1, 0, 10_000).expect("homed");
    let home = home_on_shaft(&mut m, &a, 0) / per_rev;
    assert!(
        (home - limit_rev.ceil()).abs() * per_rev <= 2.0,
        "home {home} rev; limit at {limit_rev}, start {start_rev}"
    );
    assert_eq!(digital_inputs(&mut m), 0, "off the limit switch");
}

/// A limit switch met while looking for the home switch (method 4, no reversal): homing error,
/// the drive stopped near the limit.
#[test]
fn a_limit_switch_on_the_way_to_the_home_switch_is_a_homing_error() {
    let (mut m, a, per_rev) = homing_with("builtin = 'SERVO'", 2.0, 2.0, 50.0);
    let start_rev = drive(&m).position_increments() / per_rev;
    drive_mut(&mut m).set_switches(Switches {
        positive_limit_rev: Some(start_rev + 0.5),
        home_rev: Some(start_rev + 2.0),
        ..Switches::default()
    });
    let sw = home(&mut m, &a, 4, 0, 5000).expect_err("homing error");
    assert_eq!(sw & ferrocat_wire::cia402::status::OP_SPECIFIC_12, 0);
    cycles(&mut m, 200);
    let at = drive(&m).position_increments() / per_rev - start_rev;
    assert!((0.5..0.6).contains(&at), "stopped {at} rev from the start");
    assert_eq!(digital_inputs(&mut m) & 0b010, 0b010, "on the positive limit");
}

/// A home switch of finite width (a cam from 1.0 to 1.5 rev past the start) and the positive
/// limit switch: method 7 from beyond the cam runs up into the limit, reverses, crosses the cam
/// downwards and homes on the first index pulse below its lower edge; method 10 from below
/// finds the cam going up and homes on the first index pulse above its upper edge.
#[test]
fn homing_on_a_cam_with_reversal_at_the_limit_switch() {
    for (method, start_off_rev, want) in [(7, 1.8, "below the lower edge"), (10, 0.0, "above the upper edge")] {
        let (mut m, a, per_rev) = homing_with("builtin = 'SERVO'", 3.0, 1.0, 50.0);
        let s = drive(&m).position_increments() / per_rev;
        let (lo, hi) = (s - start_off_rev + 1.0, s - start_off_rev + 1.5);
        // The limit beyond the index pulse method 10 homes on (the start's fraction of a turn
        // is the seed's: with the limit at a fixed 2.2 rev, seed 7 put it before that pulse,
        // and homing rightly failed).
        let limit = (s - start_off_rev + 2.2).max(hi.ceil() + 0.25);
        drive_mut(&mut m).set_switches(Switches {
            home_rev: Some(lo),
            home_to_rev: Some(hi),
            positive_limit_rev: Some(limit),
            ..Switches::default()
        });
        home(&mut m, &a, method, 0, 20_000).unwrap_or_else(|sw| panic!("method {method}: homing error {sw:#06x}"));
        let home = home_on_shaft(&mut m, &a, 0) / per_rev;
        let expect = if method == 7 { lo.floor() } else { hi.ceil() };
        assert!((home - expect).abs() * per_rev <= 2.0, "method {method}: home {home} rev, {want} ({lo}..{hi})");
    }
}

/// Outside homing a limit switch stops motion toward it. Profile velocity at 3 rev/s into the
/// positive limit (0.5 rev ahead): the drive brakes at the quick-stop deceleration (60 rev/s²:
/// 0.075 rev past the switch), holds there with bit 11 (internal limit active) and 0x60FD bit 1,
/// however long the target still points into the limit; a target the other way moves it off.
#[test]
fn a_limit_switch_stops_profile_velocity_toward_it_and_lets_it_back() {
    use ferrocat_wire::cia402::status;
    let (mut m, a, per_rev) = enabled_in(Mode::ProfileVelocity);
    let u32le = |x: f64| ((x * per_rev) as u32).to_le_bytes();
    m.acyclic().coe().sdo_write(DRIVE, ix::PROFILE_ACCELERATION, 0, &u32le(30.0)).unwrap();
    m.acyclic().coe().sdo_write(DRIVE, ix::PROFILE_DECELERATION, 0, &u32le(30.0)).unwrap();
    m.acyclic().coe().sdo_write(DRIVE, ix::QUICK_STOP_DECELERATION, 0, &u32le(60.0)).unwrap();
    let start = drive(&m).position_increments() / per_rev;
    let limit = start + 0.5;
    drive_mut(&mut m).set_switches(Switches { positive_limit_rev: Some(limit), ..Switches::default() });
    assert_eq!(a.feedback(&m).statusword & status::INTERNAL_LIMIT, 0);
    a.write(&mut m, Output::Velocity((3.0 * per_rev) as i32));
    until(&mut m, &a, 1000, &|sw| sw & status::INTERNAL_LIMIT != 0).expect("the limit reached");
    cycles(&mut m, 500);
    let at = drive(&m).position_increments() / per_rev - limit;
    // 3 rev/s at 60 rev/s²: 0.075 rev, and a control period's travel.
    assert!((0.06..0.09).contains(&at), "held {at} rev past the switch");
    assert!(drive(&m).velocity_increments().abs() < 0.01 * per_rev, "standing");
    let sw = a.feedback(&m).statusword;
    assert_ne!(sw & status::INTERNAL_LIMIT, 0, "bit 11 while held: {sw:#06x}");
    assert_eq!(a.state(), Some(State::OperationEnabled), "stopped, not faulted");
    assert_eq!(digital_inputs(&mut m) & 0b010, 0b010, "on the positive limit");
    // Away from the limit: free.
    a.write(&mut m, Output::Velocity(-(3.0 * per_rev) as i32));
    until(&mut m, &a, 1000, &|sw| sw & status::INTERNAL_LIMIT == 0).expect("off the limit");
    cycles(&mut m, 300);
    assert!(drive(&m).velocity_increments() < -2.9 * per_rev, "moving away at the target");
    assert!(drive(&m).position_increments() / per_rev < limit, "off the switch");
    assert_eq!(digital_inputs(&mut m) & 0b010, 0);
}

/// Cyclic synchronous position into the negative limit: the drive stops at the switch and holds
/// while the master's set-points run on past it (following error grows, bit 11 set), and
/// follows again once the set-points come back to its side.
#[test]
fn a_limit_switch_holds_cyclic_position_set_points_beyond_it() {
    use ferrocat_wire::cia402::status;
    let (mut m, a, per_rev) = enabled_in(Mode::CyclicSyncPosition);
    m.acyclic()
        .coe()
        .sdo_write(DRIVE, ix::QUICK_STOP_DECELERATION, 0, &((100.0 * per_rev) as u32).to_le_bytes())
        .unwrap();
    // No following-error fault while the set-points run away (0xFFFFFFFF: check off).
    m.acyclic().coe().sdo_write(DRIVE, ix::FOLLOWING_ERROR_WINDOW, 0, &u32::MAX.to_le_bytes()).unwrap();
    let shaft0 = drive(&m).position_increments();
    let p0 = a.feedback(&m).position.unwrap() as f64;
    let limit = shaft0 / per_rev - 0.3;
    drive_mut(&mut m).set_switches(Switches { negative_limit_rev: Some(limit), ..Switches::default() });
    // −1 rev/s for 600 ms: 0.6 rev, twice the way to the switch.
    let v = -per_rev;
    let mut target = p0;
    for _ in 0..600 {
        target += v * 1e-3;
        a.write(&mut m, Output::Position(target as i64 as i32));
        cycles(&mut m, 1);
    }
    let at = drive(&m).position_increments() / per_rev - limit;
    // 1 rev/s at 100 rev/s²: 0.005 rev past the switch.
    assert!((-0.01..0.0).contains(&at), "stopped {at} rev from the switch");
    let fe = drive(&m).following_error_increments() / per_rev;
    assert!(fe.abs() > 0.2, "set-points ran on: following error {fe} rev");
    assert_ne!(a.feedback(&m).statusword & status::INTERNAL_LIMIT, 0);
    assert_eq!(a.state(), Some(State::OperationEnabled));
    // Set-points back on the free side, 0.1 rev above where it stopped: it follows there.
    let back = p0 + (limit + 0.1) * per_rev - shaft0;
    for _ in 0..300 {
        a.write(&mut m, Output::Position(back as i64 as i32));
        cycles(&mut m, 1);
    }
    let off = (drive(&m).position_increments() - (back - p0 + shaft0)) / per_rev;
    assert!(off.abs() < 0.01, "follows again: {off} rev from the set-point");
    assert_eq!(a.feedback(&m).statusword & status::INTERNAL_LIMIT, 0);
}

/// The AKD as its EEPROM dump describes it runs interpolated position (mode 7) on its default
/// PDOs — the set-point 0x60C1:01 and the controlword out, the internal position and the
/// statusword in — with the mode and the period (0x60C2) set by SDO: the same ramp as CSP's
/// with the same small following error, bit 12 (ip mode active) while the driver holds bit 4;
/// with bit 4 cleared the drive stops at the last set-point and ignores the next ones.
#[test]
fn needs_shared_akd_eeprom_runs_interpolated_position_on_its_default_pdos() {
    use ferrocat_wire::cia402::{control, status};
    let p = ferrocat_testdata::shared("captures/eeprom/akd.hex");
    let mut m = master(&format!("eeprom = '{}'", p.display()), &|_| {});
    let s = m.slaves().at(DRIVE).unwrap();
    assert!(
        s.mapping().outputs.iter().any(|e| (e.index, e.subindex) == (ix::INTERPOLATION_DATA, 1)),
        "the default PDOs"
    );
    assert!(!s.mapping().outputs.iter().any(|e| e.index == ix::TARGET_POSITION));
    let mut a = Axis::on_axis(&m, DRIVE, 0).unwrap();
    a.set_interpolation_period(&mut m, CYCLE_NS).unwrap();
    assert_eq!(m.acyclic().coe().sdo_read(DRIVE, ix::INTERPOLATION_TIME_PERIOD, 2).unwrap(), [(-3i8) as u8]);
    a.set_mode(&mut m, Mode::InterpolatedPosition).unwrap();
    a.set_goal(Goal::OperationEnabled);
    drive_to_goal(&mut m, std::slice::from_mut(&mut a), CYCLE_NS, 100).unwrap();
    assert_eq!(drive(&m).mode(), Some(Mode::InterpolatedPosition));
    let per_rev = drive(&m).motor().increments_per_rev;
    let p0 = a.feedback(&m).position.unwrap() as f64;
    let actual0 = drive(&m).position_increments();
    drive_mut(&mut m).reset_stats();
    let v = 2.0 * per_rev;
    let sws = follow_ramp(&mut m, &mut a, p0, v);
    let active = sws.iter().filter(|&&sw| sw & status::OP_SPECIFIC_12 != 0).count();
    assert!(active >= 495, "ip mode active in {active} of 500 cycles");
    let fe = drive(&m).stats.max_following_error;
    assert!(fe < 0.01 * per_rev, "IP following error {fe} increments");
    let moved = (drive(&m).position_increments() - actual0) / per_rev;
    assert!((moved - 0.9).abs() < 0.05, "moved {moved} rev (0.9 commanded, minus the pipeline)");
    // Bit 4 cleared by hand: the set-points run on, the drive stops where the last one was.
    let last = drive(&m).position_increments();
    for k in 0..300 {
        let t = 0.5 + k as f64 * 1e-3;
        a.write(&mut m, Output::Position((p0 + v * 0.05 + v * (t - 0.1)) as i64 as i32));
        a.write(&mut m, Output::Controlword(control::ENABLE_OPERATION_CMD));
        cycles(&mut m, 1);
    }
    let stopped = (drive(&m).position_increments() - last) / per_rev;
    // At most the two set-points in the pipeline (2 rev/s × 2 ms) beyond where it was.
    assert!((0.0..0.006).contains(&stopped), "went on {stopped} rev after bit 4 cleared");
    let sw = a.feedback(&m).statusword;
    assert_eq!(sw & status::OP_SPECIFIC_12, 0, "ip mode inactive: {sw:#06x}");
    assert_ne!(sw & status::TARGET_REACHED, 0, "standing at the last set-point: {sw:#06x}");
    assert_eq!(a.state(), Some(State::OperationEnabled));
}

/// The built-in servo with its outputs remapped to carry 0x60C1:01 (controlword, set-point,
/// mode), in interpolated position with the period `period_ns`, operation enabled; and its
/// increments per revolution.
fn ip_servo(period_ns: u64) -> (Master<VirtualIo>, Axis, f64) {
    let mut m = master("builtin = 'SERVO'", &|m| {
        let w =
            |m: &mut Master<VirtualIo>, i: u16, s: u8, v: &[u8]| m.acyclic().coe().sdo_write(DRIVE, i, s, v).unwrap();
        w(m, 0x1600, 0, &[0]);
        w(m, 0x1600, 1, &0x6040_0010u32.to_le_bytes());
        w(m, 0x1600, 2, &0x60C1_0120u32.to_le_bytes());
        w(m, 0x1600, 3, &0x6060_0008u32.to_le_bytes());
        w(m, 0x1600, 0, &[3]);
        m.config().remap(DRIVE, true, &[0x1600]).unwrap();
    });
    let mut a = Axis::on_axis(&m, DRIVE, 0).unwrap();
    a.set_interpolation_period(&mut m, period_ns).unwrap();
    a.set_mode(&mut m, Mode::InterpolatedPosition).unwrap();
    a.set_goal(Goal::OperationEnabled);
    drive_to_goal(&mut m, std::slice::from_mut(&mut a), CYCLE_NS, 100).unwrap();
    let per_rev = drive(&m).motor().increments_per_rev;
    (m, a, per_rev)
}

/// The built-in servo in interpolated position after remapping its outputs to carry 0x60C1:01,
/// with an interpolation period of 2 ms at a 1 ms cycle: each set-point is approached at the
/// rate of a 2 ms step, from where the demand stands, so at a steady speed the demand runs two
/// set-points behind instead of one — a cycle's travel more.
#[test]
fn interpolation_follows_the_period_0x60c2_gives() {
    let run = |period_ns: u64| {
        let (mut m, mut a, per_rev) = ip_servo(period_ns);
        let p0 = a.feedback(&m).position.unwrap() as f64;
        let actual0 = drive(&m).position_increments();
        // 1 rev/s from standstill, 300 ms: the demand's lag behind the set-points at the end.
        for k in 1..=300 {
            a.write(&mut m, Output::Position((p0 + per_rev * k as f64 * 1e-3) as i64 as i32));
            cycles(&mut m, 1);
            a.update(&mut m);
        }
        assert_eq!(a.state(), Some(State::OperationEnabled));
        // The demand (actual plus following error): the servo's own lag behind it moves with
        // the drive's processing-time draws by a few 0.1 ms of travel from run to run.
        let d = drive(&m);
        (0.3 * per_rev - (d.position_increments() + d.following_error_increments() - actual0)) / per_rev
    };
    let (lag_1ms, lag_2ms) = (run(1_000_000), run(2_000_000));
    // Each set-point reached a period later than the one before: at 1 rev/s one extra
    // millisecond is 0.001 rev.
    let extra = lag_2ms - lag_1ms;
    assert!((0.0007..0.0013).contains(&extra), "lags {lag_1ms} and {lag_2ms} rev");
}

/// Halt in interpolated position: the built-in servo following 2 rev/s of set-points stops at
/// 0x605D's deceleration from where halt found its demand (at 20 rev/s², 0.1 rev further;
/// at the current limit, sooner), holds there in operation enabled with target reached while
/// the set-points run on, and released approaches them again.
#[test]
fn halt_in_interpolated_position_stops_at_the_halt_option_deceleration() {
    use ferrocat_wire::cia402::{control, status};
    let run = |code: i16| {
        let (mut m, mut a, per_rev) = ip_servo(CYCLE_NS);
        m.acyclic()
            .coe()
            .sdo_write(DRIVE, ix::PROFILE_DECELERATION, 0, &((20.0 * per_rev) as u32).to_le_bytes())
            .unwrap();
        m.acyclic().coe().sdo_write(DRIVE, ix::HALT_OPTION, 0, &code.to_le_bytes()).unwrap();
        let p0 = a.feedback(&m).position.unwrap() as f64;
        let mut k = 0u64;
        let mut step = |m: &mut Master<VirtualIo>, a: &mut Axis, cw: u16| {
            k += 1;
            // 2 rev/s, reached over the first 100 ms.
            let t = k as f64 * 1e-3;
            let p = if t < 0.1 { per_rev * 10.0 * t * t } else { per_rev * (0.1 + 2.0 * (t - 0.1)) };
            a.write(m, Output::Position((p0 + p) as i64 as i32));
            a.write(m, Output::Controlword(control::ENABLE_OPERATION_CMD | control::ENABLE_IP_MODE | cw));
            cycles(m, 1);
        };
        for _ in 0..300 {
            step(&mut m, &mut a, 0);
        }
        let at_halt = drive(&m).position_increments();
        for _ in 0..300 {
            step(&mut m, &mut a, control::HALT);
        }
        let after = (drive(&m).position_increments() - at_halt) / per_rev;
        let sw = a.feedback(&m).statusword;
        assert_eq!(a.state(), Some(State::OperationEnabled), "halt {code}");
        assert_ne!(sw & status::TARGET_REACHED, 0, "halt {code}: standing ({sw:#06x})");
        assert_eq!(sw & status::OP_SPECIFIC_12, 0, "halt {code}: ip mode inactive ({sw:#06x})");
        assert!(a.feedback(&m).velocity.unwrap().abs() as f64 <= 0.01 * per_rev);
        // Released: the set-points are approached again, from where it stood.
        for _ in 0..1_000 {
            step(&mut m, &mut a, 0);
        }
        let moving = a.feedback(&m).velocity.unwrap() as f64 / per_rev;
        (after, moving)
    };
    let (profile, profile_after) = run(1);
    let (limit, limit_after) = run(3);
    println!(
        "after halt: {profile:.4} rev at the profile deceleration, {limit:.4} rev at the current limit; \
         {profile_after:.2} and {limit_after:.2} rev/s after release"
    );
    // 2 rev/s at 20 rev/s²: 0.1 rev, give or take the cycle the halt waited for.
    assert!((0.08..0.13).contains(&profile), "{profile}");
    assert!(limit < profile / 2.0, "{limit} vs {profile}");
    // Released, the set-points run away at 2 rev/s: the drive follows them again.
    assert!(profile_after > 1.0 && limit_after > 1.0, "{profile_after}, {limit_after}");
}

/// Enables the built-in servo in CSV at 5 rev/s with the profile deceleration at 20 rev/s² and
/// the quick-stop deceleration at 100 rev/s², sets `option` to `code`, then writes `cw`; returns
/// the states the statusword showed (with the cycle each began) and the velocity (rev/s) 10 ms
/// after the command.
fn stop_by_option(option: u16, code: i16, cw: u16, fault: bool) -> (Vec<(u64, Option<State>)>, f64) {
    let (mut m, mut a, per_rev) = enabled_in(Mode::CyclicSyncVelocity);
    let u32le = |x: f64| ((x * per_rev) as u32).to_le_bytes();
    m.acyclic().coe().sdo_write(DRIVE, ix::PROFILE_DECELERATION, 0, &u32le(20.0)).unwrap();
    m.acyclic().coe().sdo_write(DRIVE, ix::QUICK_STOP_DECELERATION, 0, &u32le(100.0)).unwrap();
    m.acyclic().coe().sdo_write(DRIVE, option, 0, &code.to_le_bytes()).unwrap();
    for _ in 0..300 {
        a.write(&mut m, Output::Velocity((5.0 * per_rev) as i32));
        cycles(&mut m, 1);
        a.update(&mut m);
    }
    assert!((drive(&m).velocity_increments() / per_rev - 5.0).abs() < 0.05);
    if fault {
        drive_mut(&mut m).inject_fault(error_code::OVERCURRENT);
    } else {
        a.write(&mut m, Output::Controlword(cw));
    }
    let mut states = vec![(0, State::from_statusword(a.feedback(&m).statusword))];
    let mut vel_10ms = 0.0;
    for k in 1..=600 {
        cycles(&mut m, 1);
        if k == 10 {
            vel_10ms = drive(&m).velocity_increments() / per_rev;
        }
        let s = State::from_statusword(a.feedback(&m).statusword);
        if states.last().map(|l| l.1) != Some(s) {
            states.push((k, s));
        }
    }
    (states, vel_10ms)
}

/// The option codes 0x605C, 0x605B, 0x605A and 0x605E: 1 brakes at the profile deceleration
/// (5 rev/s at 20 rev/s²: 250 ms, operation staying enabled meanwhile for transitions 5 and 8),
/// 2 at the quick-stop deceleration (100 rev/s²: 50 ms), 3 at the torque limit (a few ms), 0
/// takes the power away at once and the shaft coasts on friction alone.
#[test]
fn option_codes_choose_how_the_drive_stops() {
    use ferrocat_wire::cia402::control::{DISABLE_OPERATION, QUICK_STOP_CMD, SHUTDOWN};
    use State::*;
    // The states after the first (operation enabled), each with the cycle it was first seen.
    let check =
        |(states, vel): (Vec<(u64, Option<State>)>, f64), want: &[(State, std::ops::Range<u64>)], what: &str| {
            assert_eq!(states[0].1, Some(OperationEnabled), "{what}: {states:?}");
            let got: Vec<_> = states[1..].iter().map(|&(k, s)| (s, k)).collect();
            assert_eq!(got.len(), want.len(), "{what}: {states:?}");
            for ((s, k), (ws, wk)) in got.iter().zip(want) {
                assert!(*s == Some(*ws) && wk.contains(k), "{what}: {states:?}, wanted {want:?}");
            }
            vel
        };
    let prompt = 1..6;
    // Disable operation (transition 5).
    let v = check(
        stop_by_option(ix::DISABLE_OPERATION_OPTION, 1, DISABLE_OPERATION, false),
        &[(SwitchedOn, 240..285)],
        "605C = 1",
    );
    assert!((4.7..4.9).contains(&v), "605C = 1: {v} rev/s after 10 ms");
    let coast = check(
        stop_by_option(ix::DISABLE_OPERATION_OPTION, 0, DISABLE_OPERATION, false),
        &[(SwitchedOn, prompt.clone())],
        "605C = 0",
    );
    // Shutdown (transition 8).
    check(stop_by_option(ix::SHUTDOWN_OPTION, 1, SHUTDOWN, false), &[(ReadyToSwitchOn, 240..285)], "605B = 1");
    check(stop_by_option(ix::SHUTDOWN_OPTION, 0, SHUTDOWN, false), &[(ReadyToSwitchOn, prompt.clone())], "605B = 0");
    // Quick stop (transition 11, then 12 or staying).
    let v = check(
        stop_by_option(ix::QUICK_STOP_OPTION, 2, QUICK_STOP_CMD, false),
        &[(QuickStopActive, prompt.clone()), (SwitchOnDisabled, 45..75)],
        "605A = 2",
    );
    assert!((4.1..4.4).contains(&v), "605A = 2: {v} rev/s after 10 ms");
    check(
        stop_by_option(ix::QUICK_STOP_OPTION, 1, QUICK_STOP_CMD, false),
        &[(QuickStopActive, prompt.clone()), (SwitchOnDisabled, 240..285)],
        "605A = 1",
    );
    check(
        stop_by_option(ix::QUICK_STOP_OPTION, 6, QUICK_STOP_CMD, false),
        &[(QuickStopActive, prompt.clone())],
        "605A = 6",
    );
    let v = check(
        stop_by_option(ix::QUICK_STOP_OPTION, 3, QUICK_STOP_CMD, false),
        &[(QuickStopActive, prompt.clone()), (SwitchOnDisabled, 3..15)],
        "605A = 3",
    );
    assert!(v.abs() < 0.05, "605A = 3: {v} rev/s after 10 ms");
    let v0 = check(
        stop_by_option(ix::QUICK_STOP_OPTION, 0, QUICK_STOP_CMD, false),
        &[(SwitchOnDisabled, prompt.clone())],
        "605A = 0",
    );
    // Fault reaction.
    check(
        stop_by_option(ix::FAULT_REACTION_OPTION, 2, 0, true),
        &[(FaultReactionActive, prompt.clone()), (Fault, 45..75)],
        "605E = 2",
    );
    check(
        stop_by_option(ix::FAULT_REACTION_OPTION, 1, 0, true),
        &[(FaultReactionActive, prompt.clone()), (Fault, 240..285)],
        "605E = 1",
    );
    let v1 = check(stop_by_option(ix::FAULT_REACTION_OPTION, 0, 0, true), &[(Fault, prompt)], "605E = 0");
    // Coasting: friction alone, ≈ 21 rev/s² at 5 rev/s for this motor.
    for (v, what) in [(coast, "605C = 0"), (v0, "605A = 0"), (v1, "605E = 0")] {
        assert!((4.7..4.9).contains(&v), "{what}: coasting at {v} rev/s after 10 ms");
    }
}
