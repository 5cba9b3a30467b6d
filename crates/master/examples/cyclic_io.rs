//! Brings a segment to OP and exchanges process data every millisecond, naming the entries it
//! uses: a running light on the first output entry, the first input entry read back.
//!
//!     cargo run --example cyclic_io -- eth0 [CYCLES]
use std::sync::atomic::{AtomicBool, Ordering};
use std::sync::Arc;

use ferrocat_master::io::RawIo;
use ferrocat_master::Master;
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
    let iface = args.next().ok_or("usage: cyclic_io INTERFACE [CYCLES]")?;
    let cycles: u64 = args.next().map_or(Ok(2_000), |n| n.parse())?;
    let mut master = Master::new(RawIo::open(&iface)?);
    // A cycle's frame is given up at ¾ of the cycle: a lost one costs its own cycle, not the next.
    master.config().settings_mut().cyclic_timeout_ns = CYCLE_NS * 3 / 4;
    master.states().bring_up()?;
    // Entries by name, as the slaves' EEPROMs (or CoE) name them.
    let find = |outputs: bool| {
        master.slaves().iter().find_map(|s| {
            let list = if outputs { &s.mapping().outputs } else { &s.mapping().inputs };
            list.first().map(|e| (s.position(), e.name.clone()))
        })
    };
    let (out_slave, out_name) = find(true).ok_or("no slave has outputs")?;
    let input = find(false);
    let light = master.image().output(out_slave, &out_name)?;
    println!("writing '{out_name}' of slave {out_slave}");
    let mut next = master.cyclic().now_ns();
    let mut last_input = None;
    let (mut short, mut done) = (0, 0);
    for k in 0..cycles {
        if stop.load(Ordering::Relaxed) {
            break;
        }
        master.cyclic().set(light, (k / 100) & 1);
        let wkc = master.cyclic().cycle()?;
        if wkc != master.image().expected_wkc() {
            short += 1;
            eprintln!("cycle {k}: working counter {wkc}, expected {}", master.image().expected_wkc());
        }
        if let Some((pos, name)) = &input {
            last_input = Some((name.clone(), master.image().get(master.image().input(*pos, name)?)));
        }
        done += 1;
        next += CYCLE_NS;
        master.cyclic().sleep_until(next);
    }
    master.states().shut_down()?;
    println!("{done} cycles, {short} with a working counter short");
    if let Some((name, value)) = last_input {
        println!("input '{name}' = {value}");
    }
    Ok(())
}
