//! Free-run, SM- and DC-synchronous applications lose or repeat process-data cycles when the
//! master's clock and the slave's differ (Chen et al. 2016, Table 2), and the counts are real:
//! a DC-synchronous slave whose master follows its clock loses none.
mod common;

use common::Bus;
use ferrocat_esc::SyncApp;
use ferrocat_segment::SegmentConfig;
use ferrocat_wire::register::{dc_activation as act, Fmmu, SyncManager};
use ferrocat_wire::{Address, Command};

const CYCLE: u64 = 1_000_000;

/// EK1100 + one EL2004 whose application runs in `app` mode on a crystal 100 ppm fast.
fn segment(app: &str) -> Bus {
    let toml = format!(
        "seed = 5\n[[device]]\nbuiltin = 'EK1100'\ndrift_ppm = 0.0\n[[device]]\nbuiltin = 'EL2004'\ndrift_ppm = 100.0\napp = '{app}'\napp_period_us = 1000.0\n"
    );
    let cfg: SegmentConfig = toml::from_str(&toml).unwrap();
    let mut bus = Bus::new(cfg.build().unwrap());
    bus.address_all();
    let sm = SyncManager { start: 0x0F00, length: 1, control: 0x44, status: 0, activate: 1, pdi_control: 0 };
    bus.fp(Command::FPWR, 0x1002, 0x0800, &sm.to_bytes());
    let f = Fmmu {
        logical_start: 0,
        length: 1,
        logical_start_bit: 0,
        logical_stop_bit: 7,
        physical_start: 0x0F00,
        physical_start_bit: 0,
        fmmu_type: Fmmu::WRITE,
        active: true,
    };
    bus.fp(Command::FPWR, 0x1002, 0x0600, &f.to_bytes());
    if app == "dc" {
        let now = bus.fprd_u64(0x1002, 0x0910);
        let start = (now / CYCLE + 20) * CYCLE;
        bus.fp(Command::FPWR, 0x1002, 0x09A0, &(CYCLE as u32).to_le_bytes());
        bus.fp(Command::FPWR, 0x1002, 0x0990, &start.to_le_bytes());
        bus.fp(Command::FPWR, 0x1002, 0x0981, &[act::CYCLIC_OPERATION | act::SYNC0]);
    }
    for s in [2u8, 4, 8] {
        bus.tx(Command::BWR, Address::Device { adp: 0, ado: 0x0120 }, &[s, 0]);
    }
    let (st, _) = bus.fp(Command::FPRD, 0x1002, 0x0130, &[0; 2]);
    assert_eq!(st[0], 8, "OP");
    bus
}

fn counts(bus: &Bus) -> (u64, u64, u64) {
    let a = bus.seg.nodes[1].esc.app().as_any().downcast_ref::<SyncApp>().unwrap();
    (a.consumed, a.lost, a.repeated)
}

/// The master sends one LRW per cycle on its own (true-time) clock for `seconds`.
fn run_on_master_clock(bus: &mut Bus, seconds: u64) {
    let mut t = bus.t.div_ceil(CYCLE) * CYCLE + 300_000;
    for k in 0..seconds * 1000 {
        bus.t = t;
        bus.tx(Command::LRW, Address::Logical(0), &[k as u8]);
        t += CYCLE;
    }
}

#[test]
fn free_run_and_dc_drift_against_the_master_but_sm_does_not() {
    // The slave's crystal is 100 ppm fast: over 20 s its 1 ms cycle runs 2 ms ahead, so it
    // consumes two buffers twice.
    for (app, expect_repeated) in [("free-run", 2u64), ("dc", 2), ("sm", 0)] {
        let mut bus = segment(app);
        run_on_master_clock(&mut bus, 20);
        let (consumed, lost, repeated) = counts(&bus);
        println!("{app:9}: consumed {consumed}, lost {lost}, repeated {repeated}");
        assert!(consumed >= 19_900, "{app}: consumed {consumed}");
        assert_eq!(lost, 0, "{app}: a fast slave repeats, it does not lose");
        assert!(repeated.abs_diff(expect_repeated) <= 1, "{app}: repeated {repeated}, expected ≈{expect_repeated}");
    }
}

#[test]
fn dc_mode_loses_nothing_when_the_master_follows_the_reference() {
    let mut bus = segment("dc");
    // Send each frame 300 µs before the slave's next SYNC0, whatever its clock does.
    for k in 0..20_000u64 {
        bus.seg.advance_to(bus.t);
        let next = |bus: &Bus, from: u64| bus.seg.nodes[1].esc.dc.as_ref().unwrap().next_sync0_true(from).unwrap();
        let mut n = next(&bus, bus.t);
        if n < bus.t + 300_000 {
            // Too close: aim at the pulse after it.
            bus.seg.advance_to(n);
            n = next(&bus, n + 1);
        }
        bus.t = n - 300_000;
        bus.tx(Command::LRW, Address::Logical(0), &[k as u8]);
    }
    let (consumed, lost, repeated) = counts(&bus);
    println!("dc, master following the slave: consumed {consumed}, lost {lost}, repeated {repeated}");
    assert!(consumed >= 19_000);
    assert_eq!((lost, repeated), (0, 0));
}
