//! The process-data (SM) watchdog the application sets (0x0400 and 0x0420): written in 100 µs
//! steps, armed by the simulated ESC once the outputs' SyncManager runs with its watchdog
//! trigger (control bit 6, as the LAN9252 board's SII sets it), and a gap in the process data
//! longer than it takes a firmware slave out of OP with 0x001B, where the ESC's default
//! (100 ms) lets the same gap pass.
use ferrocat_master::{ConfigError, Master, MasterError, MasterEvent};
use ferrocat_segment::SegmentConfig;
use ferrocat_segment::{HostModel, VirtualIo};
use ferrocat_wire::register::{addr, AlStatusCode};
use ferrocat_wire::{Address, Command};

const CYCLE_NS: u64 = 1_000_000;
const BOARD: u16 = 1;

/// EK1100 and the LAN9252 board in OP (no DC), the board's watchdog set to `watchdog_ns` first, then a gap
/// of `gap_ns` without process data and 200 more cycles; the events after the gap.
fn gap_after(watchdog_ns: Option<u64>, gap_ns: u64) -> (Master<VirtualIo>, Vec<MasterEvent>) {
    let cfg: SegmentConfig =
        toml::from_str("[[device]]\nbuiltin = 'EK1100'\n[[device]]\nbuiltin = 'LAN9252-EVB'\n").unwrap();
    let mut m = Master::new(VirtualIo::new(cfg.build().unwrap(), HostModel::ideal(), 1));
    m.states().scan().unwrap();
    if let Some(ns) = watchdog_ns {
        m.config().set_process_data_watchdog(BOARD, ns).unwrap();
    }
    m.states().configure().unwrap();
    m.states().start().unwrap();
    let mut next = m.cyclic().now_ns();
    let cycles = |m: &mut Master<VirtualIo>, next: &mut u64, n: usize| {
        for _ in 0..n {
            m.cyclic().cycle().unwrap();
            *next += CYCLE_NS;
            m.cyclic().sleep_until(*next);
        }
    };
    cycles(&mut m, &mut next, 100);
    let before = m.diagnosis().events().len();
    next += gap_ns;
    m.cyclic().sleep_until(next);
    cycles(&mut m, &mut next, 200);
    let events = m.diagnosis().events()[before..].to_vec();
    (m, events)
}

fn watchdog_steps(m: &mut Master<VirtualIo>) -> u16 {
    let station = m.slaves().at(BOARD).unwrap().station();
    let mut d = [0u8; 2];
    m.cyclic()
        .expect_datagram(
            Command::FPRD,
            Address::Device { adp: station, ado: addr::WATCHDOG_TIME_PROCESS_DATA },
            &mut d,
            1,
        )
        .unwrap();
    u16::from_le_bytes(d)
}

#[test]
fn a_gap_longer_than_the_watchdog_takes_the_drive_out_of_op() {
    let (mut m, events) = gap_after(Some(10_000_000), 20 * CYCLE_NS);
    assert_eq!(watchdog_steps(&mut m), 100, "10 ms in 100 µs steps");
    let text: Vec<String> = events.iter().map(|e| e.to_string()).collect();
    assert!(
        events.iter().any(
            |e| matches!(e, MasterEvent::LeftOp { position: BOARD, code, .. } if *code == AlStatusCode::SM_WATCHDOG)
        ),
        "{text:#?}"
    );
    // The master brings it back, and the watchdog with it.
    assert!(events.iter().any(|e| matches!(e, MasterEvent::Recovered { position: BOARD, .. })), "{text:#?}");
    assert_eq!(watchdog_steps(&mut m), 100);
}

#[test]
fn the_esc_default_lets_the_same_gap_pass() {
    let (mut m, events) = gap_after(None, 20 * CYCLE_NS);
    assert_eq!(watchdog_steps(&mut m), 1000, "the ESC's default: 100 ms");
    assert!(events.iter().all(|e| !matches!(e, MasterEvent::LeftOp { .. })), "{events:?}");
}

#[test]
fn a_watchdog_past_what_0x0420_counts_is_refused() {
    let cfg: SegmentConfig = toml::from_str("[[device]]\nbuiltin = 'LAN9252-EVB'\n").unwrap();
    let mut m = Master::new(VirtualIo::new(cfg.build().unwrap(), HostModel::ideal(), 1));
    m.states().scan().unwrap();
    let e = m.config().set_process_data_watchdog(0, 7_000_000_000).unwrap_err();
    assert!(matches!(e, MasterError::Config(ConfigError::WatchdogTooLong(7_000_000_000))), "{e:?}");
    assert!(e.to_string().contains("6.5535 s"), "{e}");
    // 0 turns it off; a time between steps rounds up.
    m.config().set_process_data_watchdog(0, 0).unwrap();
    m.config().set_process_data_watchdog(0, 150_000).unwrap();
    let mut d = [0u8; 2];
    m.cyclic()
        .expect_datagram(
            Command::FPRD,
            Address::Device { adp: 0x1001, ado: addr::WATCHDOG_TIME_PROCESS_DATA },
            &mut d,
            1,
        )
        .unwrap();
    assert_eq!(u16::from_le_bytes(d), 2);
}
