//! A master cycling on the embedded virtual segment in a thread of its own, its control socket
//! (and, where asked, its mailbox gateway) served once a cycle: what the socket's and the
//! gateway's tests run against.
#![allow(dead_code)] // each test binary uses a part of it
use std::path::PathBuf;
use std::sync::atomic::{AtomicBool, Ordering};
use std::sync::Arc;

use ferrocat_master::{Master, MasterEvent};
use ferrocat_segment::{HostModel, SegmentConfig, VirtualIo};
use ferrocat_service::protocol::Hello;
use ferrocat_service::{GatewayOptions, Server, ServerOptions};

const CYCLE_NS: u64 = 1_000_000;

/// The loop's thread, its socket and its gateway's address.
pub struct Running {
    pub path: PathBuf,
    pub gateway: Option<std::net::SocketAddr>,
    stop: Arc<AtomicBool>,
    thread: Option<std::thread::JoinHandle<(u64, u64)>>,
}

impl Running {
    /// Stops the loop: its cycles and the cycles whose working counter was short.
    pub fn stop(mut self) -> (u64, u64) {
        self.stop.store(true, Ordering::Relaxed);
        let r = self.thread.take().unwrap().join().unwrap();
        assert!(!self.path.exists(), "the socket goes with the server");
        std::fs::remove_dir(self.path.parent().unwrap()).ok();
        r
    }
}

/// What the loop is started with.
#[derive(Default)]
pub struct Setup {
    pub register_writes: bool,
    /// Events of the loop's own handed to the server at its tenth cycle (slave 1 back in OP,
    /// each under this name), besides the master's.
    pub events: Vec<String>,
    pub gateway: Option<GatewayOptions>,
}

/// EK1100, EL2004 and a SERVO in OP, cycling in virtual time (each cycle also 50 µs of real
/// time, so that clients get their turn), its control socket at a path of the test's own.
pub fn running(name: &str, setup: Setup) -> Running {
    let dir = std::env::temp_dir().join(format!("ferrocat-service-test-{name}-{}", std::process::id()));
    let path = dir.join(format!("{name}.sock"));
    let (ready_tx, ready) = std::sync::mpsc::channel();
    let stop = Arc::new(AtomicBool::new(false));
    let stop_loop = Arc::clone(&stop);
    let p = path.clone();
    let thread = std::thread::spawn(move || {
        let cfg: SegmentConfig = toml::from_str(
            "[[device]]\nbuiltin = 'EK1100'\n[[device]]\nbuiltin = 'EL2004'\n[[device]]\nbuiltin = 'SERVO'\n",
        )
        .unwrap();
        let mut m = Master::new(VirtualIo::new(cfg.build().unwrap(), HostModel::ideal(), 1));
        m.states().bring_up().unwrap();
        let register_writes = setup.register_writes;
        let hello = Hello {
            service: "ferrocat".into(),
            protocol: ferrocat_service::protocol::VERSION,
            pid: std::process::id(),
            target: "virtual".into(),
            cycle_us: 1000,
            slaves: m.slaves().len(),
            register_writes,
        };
        let mut server =
            Server::start(ServerOptions { path: p, mode: 0o600, group: None, register_writes, hello }).unwrap();
        let gateway = setup.gateway.map(|o| server.start_gateway(o).unwrap());
        ready_tx.send(gateway).unwrap();
        let mut next = m.cyclic().now_ns();
        let mut short = 0;
        while !stop_loop.load(Ordering::Relaxed) {
            next += CYCLE_NS;
            if m.cyclic().cycle().unwrap() != m.image().expected_wkc() {
                short += 1;
            }
            server.serve(&mut m, next - CYCLE_NS / 4, &|_| serde_json::json!({ "lock": "none" })).unwrap();
            let mut taken = m.diagnosis().take_events();
            if m.diagnosis().cycle_stats().cycles == 10 {
                taken
                    .extend(setup.events.iter().map(|name| MasterEvent::Recovered { position: 1, name: name.clone() }));
            }
            server.note_events(&taken, 0.5);
            m.cyclic().sleep_until(next);
            std::thread::sleep(std::time::Duration::from_micros(50));
        }
        (m.diagnosis().cycle_stats().cycles, short)
    });
    let gateway = ready.recv().unwrap();
    Running { path, gateway, stop, thread: Some(thread) }
}
