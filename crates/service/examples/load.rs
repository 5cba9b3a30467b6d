//! A client that loads a running master, for `scripts/bench-service.sh`: one kind of load until
//! SIGTERM (or SIGKILL), then what it measured as one line.
//!
//!     load TARGET sdo              SDO uploads of 0x1018:01 of the first CoE slave, back to back
//!     load TARGET read HZ          the whole image read HZ times a second
//!     load TARGET write OUTPUT     OUTPUT toggled each cycle; how many cycles each write took
//!                                  to reach the wire (the cycle that sent it less the one
//!                                  published when it was written)
//!     load ADDR:PORT gateway      a flood of the mailbox gateway, as fast as one socket sends:
//!                                  diagnosis uploads from station 0 (each a register read
//!                                  of the slave), and one malformed datagram in ten
//!     load TARGET write-abandon OUTPUT   begins a write of OUTPUT and stops in its middle, the
//!                                  file locked and the sequence odd, until killed: a client
//!                                  killed mid-write
use std::sync::atomic::{AtomicBool, Ordering};
use std::sync::Arc;
use std::time::{Duration, Instant};

use ferrocat_service::{image, Client, ImageClient};

fn main() -> Result<(), Box<dyn std::error::Error>> {
    let stop = Arc::new(AtomicBool::new(false));
    for sig in [signal_hook::consts::SIGINT, signal_hook::consts::SIGTERM] {
        signal_hook::flag::register(sig, Arc::clone(&stop))?;
    }
    let args: Vec<String> = std::env::args().skip(1).collect();
    let usage = "usage: load TARGET sdo | read HZ | write OUTPUT | write-abandon OUTPUT | gateway";
    let (target, kind) = (args.first().ok_or(usage)?, args.get(1).ok_or(usage)?);
    let running = || !stop.load(Ordering::Relaxed);
    match kind.as_str() {
        "gateway" => {
            let to: std::net::SocketAddr = target.parse()?;
            let sock = std::net::UdpSocket::bind("127.0.0.1:0")?;
            sock.set_nonblocking(true)?;
            // SDO upload of 0xA000:01 (the first slave's AL status) from the master (station
            // 0): the EtherCAT header (16 bytes follow, type 5), the mailbox header (10 bytes,
            // CoE, counter 1), the CoE and SDO headers.
            let upload = [0x10, 0x50, 10, 0, 0, 0, 0, 0x13, 0, 0x20, 0x40, 0, 0xA0, 1, 0, 0, 0, 0];
            let (mut sent, mut replies, mut limited) = (0u64, 0u64, 0u64);
            let mut buf = [0u8; 2048];
            while running() {
                let d: &[u8] = if sent % 10 == 9 { &[0x10, 0x50, 0xFF] } else { &upload };
                if sock.send_to(d, to).is_ok() {
                    sent += 1;
                }
                while let Ok(n) = sock.recv(&mut buf) {
                    replies += 1;
                    limited += u64::from(buf.get(7).is_some_and(|b| b & 0x0F == 0) && n == 12);
                }
                std::thread::sleep(Duration::from_micros(20));
            }
            println!("gateway: {sent} datagrams sent, {replies} replies ({limited} mailbox errors: over the rate)");
        }
        "sdo" => {
            let mut c = Client::connect(ferrocat_service::find_socket(target))?;
            let position = c.slaves()?.into_iter().find(|s| s.coe).ok_or("no CoE slave")?.position;
            let mut times = Vec::new();
            while running() {
                let t = Instant::now();
                // The master stopping ends the load too.
                if let Err(e) = c.sdo_read(position, 0x1018, 1) {
                    eprintln!("sdo: {e}");
                    break;
                }
                times.push(t.elapsed().as_micros() as u64);
            }
            times.sort_unstable();
            let q = |p: usize| times.get(times.len() * p / 100).copied().unwrap_or(0);
            println!(
                "sdo: {} uploads, p50 {} us, p99 {} us, max {} us",
                times.len(),
                q(50),
                q(99),
                times.last().unwrap_or(&0)
            );
        }
        "read" => {
            let hz: f64 = args.get(2).ok_or(usage)?.parse()?;
            let c = ImageClient::attach(image::find_image(target))?;
            let period = Duration::from_secs_f64(1.0 / hz);
            let (t0, mut reads) = (Instant::now(), 0u64);
            while running() && c.read()?.running {
                reads += 1;
                let next = period * reads as u32;
                if let Some(wait) = next.checked_sub(t0.elapsed()) {
                    std::thread::sleep(wait);
                }
            }
            println!("read: {reads} reads in {:.1} s", t0.elapsed().as_secs_f64());
        }
        "write-abandon" => {
            let output = args.get(2).ok_or(usage)?;
            let mut c = ImageClient::attach(image::find_image(target))?;
            c.begin_write_and_abandon_locked(output, 1)?;
            println!("write-abandon: mid-write, the lock held");
            loop {
                std::thread::sleep(Duration::from_secs(1));
            }
        }
        "write" => {
            let output = args.get(2).ok_or(usage)?;
            let mut c = ImageClient::attach(image::find_image(target))?;
            let cycle_ns = 1_000_000u64;
            let mut lags: Vec<u64> = Vec::new();
            let mut value = 0;
            while running() {
                value ^= 1;
                let before = c.read()?.cycle;
                let commit = c.write(&[(output.as_str(), value)])?;
                // Until a cycle has sent it (at most a second).
                let t = Instant::now();
                loop {
                    let (applied, cycle) = c.applied();
                    if applied >= commit {
                        lags.push(cycle.saturating_sub(before));
                        break;
                    }
                    if t.elapsed() > Duration::from_secs(1) || !running() {
                        break;
                    }
                    std::thread::sleep(Duration::from_micros(50));
                }
                std::thread::sleep(Duration::from_nanos(cycle_ns / 2));
            }
            lags.sort_unstable();
            let q = |p: usize| lags.get(lags.len() * p / 100).copied().unwrap_or(0);
            println!(
                "write: {} writes, cycles to the wire p50 {}, p99 {}, max {}",
                lags.len(),
                q(50),
                q(99),
                lags.last().unwrap_or(&0)
            );
        }
        _ => return Err(usage.into()),
    }
    Ok(())
}
