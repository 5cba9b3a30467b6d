//! An application in a process of its own beside `ferrocat run`: a running light on the first
//! output of the master's shared process image, the first input read back, an SDO read of the
//! first CoE slave through the control socket; it never touches the segment itself.
//!
//!     ferrocat run --iface eth0 --seconds 0 &
//!     cargo run -p ferrocat-service --example io_app -- eth0 [SECONDS]
use std::sync::atomic::{AtomicBool, Ordering};
use std::sync::Arc;
use std::time::{Duration, Instant};

use ferrocat_service::{image, Client, ImageClient};

fn main() -> Result<(), Box<dyn std::error::Error>> {
    // Ctrl-C or SIGTERM ends the loop at its next step; the master keeps running.
    let stop = Arc::new(AtomicBool::new(false));
    for sig in [signal_hook::consts::SIGINT, signal_hook::consts::SIGTERM] {
        signal_hook::flag::register(sig, Arc::clone(&stop))?;
    }
    let mut args = std::env::args().skip(1);
    let target = args.next().ok_or("usage: io_app INTERFACE [SECONDS]")?;
    let seconds: f64 = args.next().map_or(Ok(2.0), |s| s.parse())?;

    let mut master = Client::connect(ferrocat_service::find_socket(&target))?;
    println!("master on {} (process {}), {} slaves", master.hello().target, master.hello().pid, master.hello().slaves);
    if let Some(s) = master.slaves()?.into_iter().find(|s| s.coe) {
        let v = master.sdo_read(s.position, 0x1018, 1)?;
        println!("slave {} ({}): vendor id {:02x?}", s.position, s.name, v);
    }

    let mut image = ImageClient::attach(image::find_image(&target))?;
    let output = image.variables().iter().find(|v| v.output).ok_or("no output in the image")?.name.clone();
    let input = image.variables().iter().find(|v| !v.output).map(|v| v.name.clone());
    println!("writing '{output}'");
    let t0 = Instant::now();
    let mut writes = 0u64;
    while t0.elapsed().as_secs_f64() < seconds && !stop.load(Ordering::Relaxed) {
        let on = (t0.elapsed().as_millis() / 100) % 2;
        image.write(&[(output.as_str(), on as u64)])?;
        writes += 1;
        std::thread::sleep(Duration::from_millis(10));
    }
    let snapshot = image.read()?;
    let (applied, cycle) = image.applied();
    println!("{writes} writes; write {applied} first sent by cycle {cycle}; the image is of cycle {}", snapshot.cycle);
    if let Some(name) = input {
        println!("input '{name}' = {}", snapshot.get(image.variable(&name)?));
    }
    Ok(())
}
