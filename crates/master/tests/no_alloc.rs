//! The steady-state cycle allocates nothing: 10 000 cycles of the master against the virtual
//! segment (which runs in the same thread and is counted too) under a counting allocator.
use ferrocat_master::Master;
use ferrocat_segment::SegmentConfig;
use ferrocat_segment::{HostModel, VirtualIo};

use ferrocat_testdata::{allocations, CountingAllocator};

#[global_allocator]
static GLOBAL: CountingAllocator = CountingAllocator;

#[test]
fn ten_thousand_cycles_allocate_nothing() {
    let cfg: SegmentConfig = toml::from_str(
        "seed = 3\n[[device]]\nbuiltin = 'EK1100'\n[[device]]\nbuiltin = 'EL2004'\n[[device]]\nbuiltin = 'EL1004'\n[[device]]\nbuiltin = 'EL2004'\n",
    )
    .unwrap();
    let mut m = Master::new(VirtualIo::new(cfg.build().unwrap(), HostModel::pc_rt(), 3));
    m.states().bring_up().unwrap();
    let out = m.image().output(1, "Output").unwrap();
    let inp = m.image().input(2, "Input").unwrap();
    let period = 1_000_000;
    let mut next = m.cyclic().now_ns();
    let mut run = |m: &mut Master<VirtualIo>, cycles: u64| {
        for k in 0..cycles {
            m.cyclic().set(out, k & 1);
            let _ = m.image().get(inp);
            m.cyclic().cycle().unwrap();
            next += period;
            m.cyclic().sleep_until(next);
        }
    };
    run(&mut m, 200);
    let allocations = counted(|| run(&mut m, 10_000));
    let s = m.diagnosis().cycle_stats();
    println!("10 000 cycles: {allocations} allocations, {} WKC errors, last WKC {}", s.wkc_errors, s.last_wkc);
    assert_eq!(s.wkc_errors, 0);
    assert_eq!(allocations, 0);

    // A ring whose cable is pulled: the far half served from the secondary port, its
    // reference kept on the reference's time, once the split is known (in the same test: the
    // counter is the process's).
    let (mut m, mut next) = ring("");
    m.cyclic().io_mut().seg.schedule(next + 1_000_000_000, ferrocat_segment::Event::LinkDown { node: 2, port: 0 });
    run_cycles(&mut m, &mut next, 3_000);
    assert_eq!(m.diagnosis().ring_state(), ferrocat_master::RingState::Broken);
    let allocations = counted(|| run_cycles(&mut m, &mut next, 10_000));
    let moved = m.dc().far_reference().map(|f| f.offset_ns);
    println!("ring split: 10 000 cycles, {allocations} allocations, far reference moved by {moved:?} ns");
    assert!(moved.is_some(), "the far reference is being kept");
    assert_eq!(m.diagnosis().cycle_stats().wkc_errors, 0);
    assert_eq!(allocations, 0);

    // The same ring split before the master starts: the far reference kept from the latch's
    // geometry, moved with every frame while it drifts, and the DL status read every 100 ms
    // for the cable at the break.
    let (mut m, mut next) = ring("[[event]]\nat_ms = 0\nlink_down = { device = 2, port = 0 }\n");
    assert!(m.dc().split_latch().is_some_and(|l| l.watch_next_ns.is_some()), "{:?}", m.dc().split_latch());
    run_cycles(&mut m, &mut next, 3_000);
    let allocations = counted(|| run_cycles(&mut m, &mut next, 10_000));
    let moved = m.dc().far_reference().map(|f| f.offset_ns);
    println!(
        "ring split from the start: 10 000 cycles, {allocations} allocations, far reference moved by {moved:?} ns"
    );
    assert!(moved.is_some_and(|ns| ns != 0), "the far reference is being kept");
    assert_eq!(m.diagnosis().ring_state(), ferrocat_master::RingState::Broken);
    assert_eq!(allocations, 0);

    // A plan from outside (an ENI's layout): its FMMUs at logical 0x01000000, one LRW in an
    // image that mirrors the frame.
    let mut m = planned();
    let out = m.image().output(1, "Output").unwrap();
    let mut next = m.cyclic().now_ns();
    let mut cycles = |m: &mut Master<VirtualIo>, n: u64| {
        for k in 0..n {
            m.cyclic().set(out, k & 1);
            m.cyclic().cycle().unwrap();
            next += 1_000_000;
            m.cyclic().sleep_until(next);
        }
    };
    cycles(&mut m, 200);
    let allocations = counted(|| cycles(&mut m, 10_000));
    println!("a plan's frames: 10 000 cycles, {allocations} allocations, expected WKC {}", m.image().expected_wkc());
    assert_eq!((m.diagnosis().cycle_stats().wkc_errors, m.image().expected_wkc()), (0, 3));
    assert_eq!(allocations, 0);
}

/// An EK1100, an EL2004 and an EL1004 in OP on a plan: the EL2004's outputs at logical
/// 0x01000000, the EL1004's inputs at 0x01000001, one LRW of both with the working counter 3.
fn planned() -> Master<VirtualIo> {
    use ferrocat_master::plan::{Plan, PlanDatagram};
    use ferrocat_wire::register::{Fmmu, SyncManager};
    let cfg: SegmentConfig = toml::from_str(
        "seed = 3\n[[device]]\nbuiltin = 'EK1100'\n[[device]]\nbuiltin = 'EL2004'\n[[device]]\nbuiltin = 'EL1004'\n",
    )
    .unwrap();
    let fmmu = |logical_start, physical_start, fmmu_type| {
        let f = Fmmu {
            logical_start,
            length: 1,
            logical_start_bit: 0,
            logical_stop_bit: 3,
            physical_start,
            physical_start_bit: 0,
            fmmu_type,
            active: true,
        };
        (0x0600, f.to_bytes().to_vec())
    };
    let sm = |start, control| {
        let s = SyncManager { start, length: 1, control, status: 0, activate: 1, pdi_control: 0 };
        (0x0800, s.to_bytes().to_vec())
    };
    let plan = Plan {
        registers: vec![
            vec![],
            vec![sm(0x0F00, 0x44), fmmu(0x0100_0000, 0x0F00, Fmmu::WRITE)],
            vec![sm(0x1000, 0x00), fmmu(0x0100_0001, 0x1000, Fmmu::READ)],
        ],
        entries_at: vec![(None, None), (Some(26 * 8), None), (None, Some(27 * 8))],
        frames: vec![vec![PlanDatagram {
            command: ferrocat_wire::Command::LRW,
            address: ferrocat_wire::Address::Logical(0x0100_0000),
            length: 2,
            output_offset: Some(16),
            input_offset: Some(16),
            expected_wkc: Some(3),
        }]],
        output_bytes: 32,
        input_bytes: 32,
        ..Plan::default()
    };
    let mut m = Master::new(VirtualIo::new(cfg.build().unwrap(), HostModel::pc_rt(), 3));
    m.config().set_plan(plan).unwrap();
    m.states().bring_up().unwrap();
    m
}

/// Two couplers with an output terminal each as a ring, `events` in its file, in OP with DC
/// (no SYNC0); and the master's time.
fn ring(events: &str) -> (Master<VirtualIo>, u64) {
    let cfg: SegmentConfig = toml::from_str(&format!(
        "seed = 3\n[[device]]\nbuiltin = 'EK1100'\n[[device]]\nbuiltin = 'EL2004'\n[[device]]\nbuiltin = 'EK1100'\n\
         parent = 0\n[[device]]\nbuiltin = 'EL2004'\n[secondary]\ndevice = 2\n{events}"
    ))
    .unwrap();
    let mut m = Master::new(VirtualIo::new(cfg.build().unwrap(), HostModel::pc_rt(), 3));
    m.states().bring_up().unwrap();
    m.dc().init_dc(&ferrocat_master::DcConfig { sync0_slaves: Some(vec![]), ..Default::default() }).unwrap();
    let now = m.cyclic().now_ns();
    (m, now)
}

/// `cycles` 1 ms cycles from `next` on.
fn run_cycles(m: &mut Master<VirtualIo>, next: &mut u64, cycles: u64) {
    for _ in 0..cycles {
        m.cyclic().cycle().unwrap();
        *next += 1_000_000;
        m.cyclic().sleep_until(*next);
    }
}

/// The allocations `f` made.
fn counted(f: impl FnOnce()) -> u64 {
    let before = allocations();
    f();
    allocations() - before
}
