//! Distributed clocks with a chosen clock-sync method, reporting its lock state.
//!
//!     cargo run --example dc_sync -- eth0 [METHOD] [SECONDS]
//!
//! METHOD is one of `SyncMethod::PRESETS` (default `ferrocat`).
use std::sync::atomic::{AtomicBool, Ordering};
use std::sync::Arc;

use ferrocat_master::io::RawIo;
use ferrocat_master::sync::{Coupling, SyncMethod};
use ferrocat_master::{DcConfig, Master};
use tracing_subscriber::EnvFilter;

const CYCLE_NS: u64 = 1_000_000;

fn main() -> Result<(), Box<dyn std::error::Error>> {
    // The master's events and warnings on stderr (RUST_LOG=debug for each step).
    let filter = EnvFilter::try_from_default_env().unwrap_or_else(|_| EnvFilter::new("info"));
    tracing_subscriber::fmt().with_env_filter(filter).with_writer(std::io::stderr).init();
    // Ctrl-C or SIGTERM ends the loop, not the program: the slaves are stepped down first.
    let stop = Arc::new(AtomicBool::new(false));
    for sig in [signal_hook::consts::SIGINT, signal_hook::consts::SIGTERM] {
        signal_hook::flag::register(sig, Arc::clone(&stop))?;
    }
    let mut args = std::env::args().skip(1);
    let iface = args.next().ok_or("usage: dc_sync INTERFACE [METHOD] [SECONDS]")?;
    let name = args.next().unwrap_or_else(|| "ferrocat".into());
    let seconds: u64 = args.next().map_or(Ok(3), |s| s.parse())?;
    let method = SyncMethod::preset(&name, Coupling::ReferenceFollowsMaster)
        .ok_or_else(|| format!("unknown method {name}; known: {}", SyncMethod::PRESETS.join(", ")))?;
    let mut master = Master::new(RawIo::open(&iface)?);
    // A cycle's frame is given up at ¾ of the cycle: a lost one costs its own cycle, not the next.
    master.config().settings_mut().cyclic_timeout_ns = CYCLE_NS * 3 / 4;
    master.states().scan()?;
    master.states().configure()?;
    // In PREOP: delays, offsets, static drift compensation, SYNC0 every cycle; then the method.
    let dc = DcConfig { sync0_cycle_ns: CYCLE_NS as u32, ..DcConfig::default() };
    let (mut sync, report, mut state) = master.clock().start_clock_sync(&dc, &method, CYCLE_NS)?;
    println!("reference clock: slave {}; method {}", report.reference, sync.name());
    master.states().start()?;
    let mut next = master.cyclic().now_ns();
    for k in 1..=seconds * 1_000 {
        if stop.load(Ordering::Relaxed) {
            break;
        }
        // Process data and the clock-sync datagrams in one frame.
        let (_, correction) = master.cyclic().cycle_sync(sync.as_mut(), &mut state)?;
        if k % 500 == 0 {
            println!("t = {:.1} s  {}  offset {:?} ns", k as f64 / 1e3, state.lock.state(), state.lock.offset_ns());
        }
        // A method where the master follows the reference sets the next period.
        next += correction.next_period_ns.unwrap_or(CYCLE_NS);
        master.cyclic().sleep_until(next);
    }
    master.states().shut_down()?;
    println!("lock state: {}", state.lock.state());
    Ok(())
}
