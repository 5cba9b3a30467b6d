//! Reads and writes CoE objects of one slave by SDO: its device name (0x1008), its identity
//! (0x1018), and the mode of operation of a CiA402 drive (0x6060), written and read back.
//!
//!     cargo run --example sdo -- eth0 POSITION
use ferrocat_master::io::RawIo;
use ferrocat_master::Master;
use tracing_subscriber::EnvFilter;

fn main() -> Result<(), Box<dyn std::error::Error>> {
    // The master's events and warnings on stderr (RUST_LOG=debug for each step).
    let filter = EnvFilter::try_from_default_env().unwrap_or_else(|_| EnvFilter::new("info"));
    tracing_subscriber::fmt().with_env_filter(filter).with_writer(std::io::stderr).init();
    let mut args = std::env::args().skip(1);
    let (iface, position) = match (args.next(), args.next()) {
        (Some(i), Some(p)) => (i, p.parse::<u16>()?),
        _ => return Err("usage: sdo INTERFACE POSITION".into()),
    };
    let mut master = Master::new(RawIo::open(&iface)?);
    master.states().scan()?;
    // Mailboxes set up and every slave in PREOP, where SDOs work.
    master.states().configure()?;
    let name = master.acyclic().coe().sdo_read(position, 0x1008, 0)?;
    println!("0x1008 device name: {}", String::from_utf8_lossy(&name));
    let vendor = master.acyclic().coe().sdo_read(position, 0x1018, 1)?;
    println!("0x1018:01 vendor id: {:#010x}", u32::from_le_bytes(vendor[..4].try_into()?));
    // Cyclic synchronous position (8), as a CiA402 drive takes it.
    master.acyclic().coe().sdo_write(position, 0x6060, 0, &[8])?;
    let mode = master.acyclic().coe().sdo_read(position, 0x6060, 0)?;
    println!("0x6060 mode of operation: {}", mode[0] as i8);
    Ok(())
}
