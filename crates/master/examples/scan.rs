//! Lists the slaves on a network interface, as `slaveinfo` does.
//!
//!     cargo run --example scan -- eth0
use ferrocat_master::io::RawIo;
use ferrocat_master::Master;
use tracing_subscriber::EnvFilter;

fn main() -> Result<(), Box<dyn std::error::Error>> {
    // The master's events and warnings on stderr (RUST_LOG=debug for each step).
    let filter = EnvFilter::try_from_default_env().unwrap_or_else(|_| EnvFilter::new("info"));
    tracing_subscriber::fmt().with_env_filter(filter).with_writer(std::io::stderr).init();
    let iface = std::env::args().nth(1).ok_or("usage: scan INTERFACE")?;
    let mut master = Master::new(RawIo::open(&iface)?);
    // Counts the slaves, gives them station addresses and reads their EEPROMs.
    master.states().scan()?;
    println!("{} slaves on {iface}", master.slaves().len());
    for s in master.slaves() {
        println!(
            "{:3}  {:<12} vendor {:#010x} product {:#010x} rev {:#010x}  station {:#06x}{}",
            s.position(),
            s.name(),
            s.identity().vendor_id,
            s.identity().product_code,
            s.identity().revision,
            s.station(),
            if s.dc().supported { "  DC" } else { "" }
        );
    }
    Ok(())
}
