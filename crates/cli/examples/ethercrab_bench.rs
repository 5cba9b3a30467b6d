//! The benchmark of docs/benchmarks.md for ethercrab (unmodified, from crates.io): time from
//! start to OP, then one-frame LRW + FRMW cycles back to back for a few seconds, with the
//! process's CPU time per cycle. `scripts/bench-masters.sh` runs it against `ferrocat sim`.
//!
//!     ethercrab_bench IFACE SECONDS
use std::time::{Duration, Instant};

use ethercrab::std::ethercat_now;
use ethercrab::{MainDevice, MainDeviceConfig, PduStorage, Timeouts};

const MAX_SUBDEVICES: usize = 32;
const MAX_PDU_DATA: usize = PduStorage::element_size(1100);
static PDU_STORAGE: PduStorage<16, MAX_PDU_DATA> = PduStorage::new();

fn cpu_ns() -> u64 {
    // SAFETY: getrusage fills the struct we own.
    let mut u: libc::rusage = unsafe { std::mem::zeroed() };
    unsafe { libc::getrusage(libc::RUSAGE_SELF, &mut u) };
    let t = |tv: libc::timeval| tv.tv_sec as u64 * 1_000_000_000 + tv.tv_usec as u64 * 1000;
    t(u.ru_utime) + t(u.ru_stime)
}

fn main() {
    let mut args = std::env::args().skip(1);
    let iface = args.next().expect("IFACE");
    let seconds: f64 = args.next().and_then(|s| s.parse().ok()).unwrap_or(3.0);
    let (tx, rx, pdu_loop) = PDU_STORAGE.try_split().expect("split once");
    let task = ethercrab::std::tx_rx_task(&iface, tx, rx).expect("TX/RX task");
    std::thread::spawn(move || futures_lite::future::block_on(task));
    std::thread::sleep(Duration::from_millis(100));
    // No static drift compensation: the comparison is of bring-up, not of DC (ferrocat does not
    // run one here either).
    let md = MainDevice::new(
        pdu_loop,
        Timeouts::default(),
        MainDeviceConfig { dc_static_sync_iterations: 0, ..Default::default() },
    );
    futures_lite::future::block_on(async {
        let start = Instant::now();
        let group = md.init_single_group::<MAX_SUBDEVICES, 256>(ethercat_now).await.expect("init");
        let group = group.into_op(&md).await.expect("OP");
        let to_op = start.elapsed();
        let n = group.len();
        let cpu0 = cpu_ns();
        let t0 = Instant::now();
        let mut cycles = 0u64;
        while t0.elapsed().as_secs_f64() < seconds {
            group.tx_rx_sync_system_time(&md).await.expect("cycle");
            cycles += 1;
        }
        let wall = t0.elapsed().as_secs_f64();
        let cpu = cpu_ns() - cpu0;
        println!(
            "ethercrab: {n} slaves; bring-up to OP {:.1} ms; {:.0} cycles/s; CPU {:.2} us per cycle",
            to_op.as_secs_f64() * 1e3,
            cycles as f64 / wall,
            cpu as f64 / 1000.0 / cycles as f64
        );
    });
}
