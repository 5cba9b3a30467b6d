//! Two CiA402 drives in cyclic synchronous position mode with DC: both enabled, then moved
//! together by one revolution's worth of increments along a smooth profile.
//!
//!     cargo run --example two_axes_csp -- eth0 AXIS0 AXIS1
use ferrocat_master::cia402::Output;
use std::sync::atomic::{AtomicBool, Ordering};
use std::sync::Arc;

use ferrocat_master::cia402::{drive_to_goal, map_for_csp, Axis, Goal, Mode};
use ferrocat_master::io::RawIo;
use ferrocat_master::sync::SyncMethod;
use ferrocat_master::{DcConfig, Master};
use tracing_subscriber::EnvFilter;

const CYCLE_NS: u64 = 1_000_000;
const MOVE: i32 = 1 << 16;

fn main() -> Result<(), Box<dyn std::error::Error>> {
    // The master's events and warnings on stderr (RUST_LOG=debug for each step).
    let filter = EnvFilter::try_from_default_env().unwrap_or_else(|_| EnvFilter::new("info"));
    tracing_subscriber::fmt().with_env_filter(filter).with_writer(std::io::stderr).init();
    // Ctrl-C or SIGTERM ends the loop, not the program: the slaves are stepped down first.
    let stop = Arc::new(AtomicBool::new(false));
    for sig in [signal_hook::consts::SIGINT, signal_hook::consts::SIGTERM] {
        signal_hook::flag::register(sig, Arc::clone(&stop))?;
    }
    let args: Vec<String> = std::env::args().skip(1).collect();
    let [iface, a, b] = &args[..] else { return Err("usage: two_axes_csp INTERFACE AXIS0 AXIS1".into()) };
    let positions = [a.parse::<u16>()?, b.parse::<u16>()?];
    let mut master = Master::new(RawIo::open(iface)?);
    // A cycle's frame is given up at ¾ of the cycle: a lost one costs its own cycle, not the next.
    master.config().settings_mut().cyclic_timeout_ns = CYCLE_NS * 3 / 4;
    master.states().scan()?;
    master.states().configure()?;
    for &p in &positions {
        // Target position and position actual value in the process image.
        map_for_csp(&mut master, p)?;
    }
    let dc = DcConfig { sync0_cycle_ns: CYCLE_NS as u32, sync0_slaves: Some(positions.to_vec()), ..Default::default() };
    let (mut sync, _, mut state) = master.clock().start_clock_sync(&dc, &SyncMethod::default(), CYCLE_NS)?;
    let mut axes = positions.map(|p| Axis::on_axis(&master, p, 0)).into_iter().collect::<Result<Vec<_>, _>>()?;
    for axis in &mut axes {
        axis.set_mode(&mut master, Mode::CyclicSyncPosition)?;
        axis.set_goal(Goal::OperationEnabled);
    }
    master.states().start()?;
    drive_to_goal(&mut master, &mut axes, CYCLE_NS, 2_000)?;
    let start: Vec<i32> = axes.iter().map(|a| a.feedback(&master).position.unwrap_or(0)).collect();
    let steps = 1_000;
    let mut next = master.cyclic().now_ns();
    for k in 0..=steps + 200 {
        if stop.load(Ordering::Relaxed) {
            break;
        }
        // A cosine ramp from 0 to MOVE over `steps` cycles, then holding still.
        let s = (k.min(steps) as f64 / steps as f64 * std::f64::consts::PI).cos();
        for (axis, &from) in axes.iter_mut().zip(&start) {
            axis.write(&mut master, Output::Position(from.wrapping_add((MOVE as f64 * (1.0 - s) / 2.0) as i32)));
            axis.update(&mut master);
        }
        master.cyclic().cycle_sync(sync.as_mut(), &mut state)?;
        next += CYCLE_NS;
        master.cyclic().sleep_until(next);
    }
    master.states().shut_down()?;
    for (axis, &from) in axes.iter().zip(&start) {
        let moved = axis.feedback(&master).position.unwrap_or(from).wrapping_sub(from);
        println!("axis at slave {}: moved {moved} increments, {:?}", axis.position, axis.state());
    }
    println!("clock sync {}", state.lock.state());
    Ok(())
}
