//! Two (or more) CiA402 drives in cyclic synchronous position mode, driven from a process of
//! its own beside `ferrocat run --dc`: every drive the master's image has a controlword for is
//! enabled through the image (fault reset, shutdown, switch on, enable operation), put in CSP,
//! and moved by `MOVE` increments along a smooth profile, a set-point a cycle; the master keeps
//! the cycle and the clocks, this program only the image.
//!
//!     ferrocat run --iface eth0 --dc --seconds 0 &
//!     cargo run -p ferrocat-service --example csp_app -- eth0 [MOVE]
use std::sync::atomic::{AtomicBool, Ordering};
use std::sync::Arc;
use std::time::{Duration, Instant};

use ferrocat_service::{image, ImageClient};
use ferrocat_wire::cia402::{control, State};

/// One drive's variables in the image, by name.
struct Drive {
    position: u16,
    control: String,
    status: String,
    mode: String,
    target: String,
    actual: String,
}

fn main() -> Result<(), Box<dyn std::error::Error>> {
    // Ctrl-C or SIGTERM ends the move; the drives are disabled on the way out.
    let stop = Arc::new(AtomicBool::new(false));
    for sig in [signal_hook::consts::SIGINT, signal_hook::consts::SIGTERM] {
        signal_hook::flag::register(sig, Arc::clone(&stop))?;
    }
    let mut args = std::env::args().skip(1);
    let target = args.next().ok_or("usage: csp_app INTERFACE [MOVE]")?;
    let travel: i64 = args.next().map_or(Ok(1 << 16), |m| m.parse())?;
    let mut img = ImageClient::attach(image::find_image(&target))?;
    let name = |pos: u16, entry: &str| format!("{pos}:{entry}");
    let drives: Vec<Drive> = img
        .variables()
        .iter()
        .filter(|v| v.output && v.index == 0x6040)
        .map(|v| Drive {
            position: v.position,
            control: v.name.clone(),
            status: name(v.position, "Statusword"),
            mode: name(v.position, "Modes of operation"),
            target: name(v.position, "Target position"),
            actual: name(v.position, "Position actual value"),
        })
        .collect();
    if drives.is_empty() {
        return Err("no drive in the image (no controlword 0x6040 mapped)".into());
    }
    for d in &drives {
        for n in [&d.status, &d.mode, &d.target, &d.actual] {
            img.variable(n)?;
        }
    }
    // The master's cycle: one set-point each.
    let snap = img.read()?;
    let cycle = Duration::from_micros(1000);
    println!(
        "{} drive(s) at positions {:?}; image of cycle {}",
        drives.len(),
        drives.iter().map(|d| d.position).collect::<Vec<_>>(),
        snap.cycle
    );

    let t0 = Instant::now();
    enable(&mut img, &drives, &stop, cycle)?;
    println!("enabled after {:.0} ms", t0.elapsed().as_secs_f64() * 1e3);

    // The move: a cosine profile over one second from where each drive stands. A drive that
    // leaves operation enabled on the way (the master's host stalled and the drive's sync
    // supervision took it out of OP, say) is enabled again where it stands, and the rest of
    // the move goes on from there to the same end, as a machine's application does.
    let actual_of = |img: &ImageClient, snap: &image::Snapshot, d: &Drive| -> Result<i64, image::ImageError> {
        Ok(snap.get(img.variable(&d.actual)?) as u32 as i32 as i64)
    };
    let snap = img.read()?;
    let start: Vec<i64> = drives.iter().map(|d| actual_of(&img, &snap, d)).collect::<Result<_, _>>()?;
    let goal: Vec<i64> = start.iter().map(|p| p + travel).collect();
    let mut from = start.clone();
    let (mut t_move, mut steps, mut k, mut resumed) = (Instant::now(), 1000u32, 0u32, 0u32);
    while k <= steps && !stop.load(Ordering::Relaxed) {
        let snap = img.read()?;
        let out = drives.iter().find(|d| {
            let sw = img.variable(&d.status).map(|v| snap.get(v) as u16).unwrap_or(0);
            State::from_statusword(sw) != Some(State::OperationEnabled)
        });
        if let Some(d) = out {
            resumed += 1;
            if resumed > 5 {
                return Err(format!("drive {} left operation enabled a sixth time in one move", d.position).into());
            }
            enable(&mut img, &drives, &stop, cycle)?;
            let snap = img.read()?;
            from = drives.iter().map(|d| actual_of(&img, &snap, d)).collect::<Result<_, _>>()?;
            (t_move, steps, k) = (Instant::now(), (steps - k).max(200), 0);
            continue;
        }
        let s = 0.5 - 0.5 * (std::f64::consts::PI * k as f64 / steps as f64).cos();
        let pairs: Vec<(String, u64)> = drives
            .iter()
            .zip(from.iter().zip(&goal))
            .map(|(d, (&p0, &end))| (d.target.clone(), (p0 + (s * (end - p0) as f64) as i64) as i32 as u32 as u64))
            .collect();
        let refs: Vec<(&str, u64)> = pairs.iter().map(|(n, v)| (n.as_str(), *v)).collect();
        img.write(&refs)?;
        // On the set-point's cycle, not on this process's luck: the next k when its time comes.
        let due = cycle * (k + 1);
        if let Some(wait) = due.checked_sub(t_move.elapsed()) {
            std::thread::sleep(wait);
        }
        k += 1;
    }
    if resumed > 0 {
        println!("a drive left operation enabled {resumed} time(s) during the move: enabled again, the move resumed");
    }
    std::thread::sleep(Duration::from_millis(200));
    let snap = img.read()?;
    for (d, p0) in drives.iter().zip(&start) {
        let actual = actual_of(&img, &snap, d)?;
        println!("drive {}: moved {} of {travel} increments", d.position, actual - p0);
    }
    // Disabled on the way out (the master keeps running).
    let off: Vec<(&str, u64)> = drives.iter().map(|d| (d.control.as_str(), control::SHUTDOWN as u64)).collect();
    img.write(&off)?;
    Ok(())
}

/// Enables every drive: each one's controlword from the state its statusword shows, every
/// cycle, with the target position held at the actual one so that enabling does not move it,
/// until all are in operation enabled (5 s at most).
fn enable(
    img: &mut ImageClient,
    drives: &[Drive],
    stop: &AtomicBool,
    cycle: Duration,
) -> Result<(), Box<dyn std::error::Error>> {
    let t0 = Instant::now();
    loop {
        let snap = img.read()?;
        let mut writes = Vec::new();
        let mut enabled = 0;
        for d in drives {
            let sw = snap.get(img.variable(&d.status)?) as u16;
            let actual = snap.get(img.variable(&d.actual)?);
            let cw = match State::from_statusword(sw) {
                Some(State::OperationEnabled) => {
                    enabled += 1;
                    control::ENABLE_OPERATION_CMD
                }
                Some(State::Fault) => control::FAULT_RESET,
                Some(State::SwitchedOn) => control::ENABLE_OPERATION_CMD,
                Some(State::ReadyToSwitchOn) => control::SWITCH_ON_CMD,
                _ => control::SHUTDOWN,
            };
            writes.push((d.control.clone(), cw as u64));
            writes.push((d.mode.clone(), 8));
            writes.push((d.target.clone(), actual));
        }
        let pairs: Vec<(&str, u64)> = writes.iter().map(|(n, v)| (n.as_str(), *v)).collect();
        img.write(&pairs)?;
        if enabled == drives.len() {
            return Ok(());
        }
        if t0.elapsed() > Duration::from_secs(5) || stop.load(Ordering::Relaxed) {
            return Err("the drives did not reach operation enabled within 5 s".into());
        }
        std::thread::sleep(cycle);
    }
}
