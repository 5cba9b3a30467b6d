//! Process-data groups on the virtual segment: each group's frame at its own rate with its own
//! working-counter check, outputs and inputs through it, the clock sync behind the fastest.
use ferrocat_esc::DigitalIo;
use ferrocat_master::{Group, Master};
use ferrocat_segment::{HostModel, SegmentConfig, VirtualIo};

fn segment() -> Master<VirtualIo> {
    let cfg: SegmentConfig = toml::from_str(
        "seed = 4\n[[device]]\nbuiltin = 'EK1100'\n[[device]]\nbuiltin = 'EL2004'\n[[device]]\nbuiltin = 'EL1004'\n\
         [[device]]\nbuiltin = 'SERVO'\n",
    )
    .unwrap();
    Master::new(VirtualIo::new(cfg.build().unwrap(), HostModel::pc_rt(), 4))
}

#[test]
fn groups_run_at_their_own_rates_with_their_own_checks() {
    let mut m = segment();
    m.config().set_groups(vec![
        Group { name: "inputs".into(), positions: vec![2], every: 4 },
        Group { name: "fast".into(), positions: vec![1, 3], every: 1 },
    ]);
    m.states().bring_up().unwrap();
    let out = m.image().output(1, "Output").unwrap();
    let inp = m.image().input(2, "Input").unwrap();
    m.cyclic().io_mut().seg.nodes[2].esc.app_mut().as_any_mut().downcast_mut::<DigitalIo>().unwrap().inputs =
        vec![0b0101];
    m.diagnosis().reset_cycle_stats();
    let before = m.diagnosis().plan_frame_stats();
    let mut next = m.cyclic().now_ns();
    for k in 0..400u64 {
        m.cyclic().set(out, k & 1);
        m.cyclic().cycle().unwrap();
        next += 1_000_000;
        m.cyclic().sleep_until(next);
    }
    let plan = m.config().plan().unwrap();
    // The fastest first; the slave in no group (the coupler, without process data) adds none.
    assert_eq!(plan.frame_names, ["fast", "inputs"]);
    assert_eq!(plan.frame_every, [1, 4]);
    let stats = m.diagnosis().plan_frame_stats();
    let sent: Vec<u64> = stats.iter().zip(&before).map(|(a, b)| a.sent - b.sent).collect();
    assert_eq!(sent, [400, 100]);
    // The EL2004 writes (2) and the servo reads and writes (3); the EL1004 reads (1).
    assert_eq!(stats.iter().map(|s| (s.expected_wkc, s.short)).collect::<Vec<_>>(), [(5, 0), (1, 0)]);
    assert_eq!(m.diagnosis().cycle_stats().wkc_errors, 0);
    // The EL1004's four inputs (its entries one bit each) through the slow group's frame.
    assert_eq!(m.image().get(ferrocat_master::Handle { bits: 4, ..inp }), 0b0101);
    let el2004 =
        m.cyclic().io_mut().seg.nodes[1].esc.app().as_any().downcast_ref::<DigitalIo>().unwrap().outputs.clone();
    assert_eq!(el2004, [1], "the last cycle's output (399 & 1)");
}

#[test]
fn a_group_the_frames_cannot_carry_is_refused() {
    let mut m = segment();
    m.config().set_groups(vec![Group { name: "never".into(), positions: vec![1], every: 0 }]);
    m.states().scan().unwrap();
    let e = m.states().configure().unwrap_err().to_string();
    assert!(e.contains("group never: every 0 cycles"), "{e}");
    let mut m = segment();
    m.config().set_groups(vec![
        Group { name: "a".into(), positions: vec![1], every: 1 },
        Group { name: "b".into(), positions: vec![1, 9], every: 2 },
    ]);
    m.states().scan().unwrap();
    let e = m.states().configure().unwrap_err().to_string();
    assert!(e.contains("slave 1 is in groups a and b") || e.contains("no slave at position 9"), "{e}");
}

#[test]
fn the_clock_sync_rides_with_the_fastest_group() {
    let mut m = segment();
    m.config().set_groups(vec![
        Group { name: "slow".into(), positions: vec![1, 2], every: 10 },
        Group { name: "axis".into(), positions: vec![3], every: 1 },
    ]);
    m.states().scan().unwrap();
    m.states().configure().unwrap();
    let dc = ferrocat_master::DcConfig { sync0_cycle_ns: 1_000_000, ..Default::default() };
    let (mut sync, _, mut state) =
        m.clock().start_clock_sync(&dc, &ferrocat_master::sync::SyncMethod::default(), 1_000_000).unwrap();
    m.states().start().unwrap();
    let mut next = m.cyclic().now_ns();
    for _ in 0..3000 {
        let (_, c) = m.cyclic().cycle_sync(sync.as_mut(), &mut state).unwrap();
        next += c.next_period_ns.unwrap_or(1_000_000);
        m.cyclic().sleep_until(next);
    }
    assert_eq!(state.lock.state().name(), "locked", "{:?}", state.lock.offset_ns());
    assert!(m.diagnosis().plan_frame_stats().iter().all(|s| s.short == 0), "{:?}", m.diagnosis().plan_frame_stats());
    assert_eq!(m.slaves()[3].status().state(), ferrocat_wire::register::AlState::Op);
}

/// Slave-to-slave through the master: an input copied into an output after each cycle reaches
/// its slave with the next cycle's frame, one cycle after it was read.
#[test]
fn a_copy_reaches_the_other_slave_one_cycle_later() {
    let mut m = segment();
    m.states().bring_up().unwrap();
    let from = ferrocat_master::Handle { bits: 4, ..m.image().input(2, "Input").unwrap() };
    let to = ferrocat_master::Handle { bits: 4, ..m.image().output(1, "Output").unwrap() };
    m.cyclic().set_copies(vec![(from, to)]).unwrap();
    let terminal = |m: &mut Master<VirtualIo>| {
        m.cyclic().io_mut().seg.nodes[1].esc.app().as_any().downcast_ref::<DigitalIo>().unwrap().outputs.clone()
    };
    m.cyclic().cycle().unwrap();
    m.cyclic().io_mut().seg.nodes[2].esc.app_mut().as_any_mut().downcast_mut::<DigitalIo>().unwrap().inputs =
        vec![0b0110];
    // The cycle that reads the inputs sends the outputs copied the cycle before.
    m.cyclic().cycle().unwrap();
    assert_eq!(m.image().get(from), 0b0110);
    assert_eq!(terminal(&mut m), [0]);
    m.cyclic().cycle().unwrap();
    assert_eq!(terminal(&mut m), [0b0110]);
    // A copy of other widths, or past the image, is refused.
    let wide = ferrocat_master::Handle { bits: 8, ..to };
    assert!(m.cyclic().set_copies(vec![(from, wide)]).unwrap_err().to_string().contains("4 bits into 8 bits"));
    let past = ferrocat_master::Handle { bit: 1 << 20, ..to };
    assert!(m.cyclic().set_copies(vec![(from, past)]).unwrap_err().to_string().contains("of a"));
}
