//! Test hosts: network namespaces joined by a veth pair, created and removed by the test.
#![allow(dead_code)]
use std::path::PathBuf;
use std::process::{Child, Command, Stdio};
use std::time::{Duration, Instant};

fn ip(args: &[&str]) {
    let out = Command::new("ip").args(args).output().expect("the ip command (iproute2) is needed");
    assert!(out.status.success(), "ip {}: {}", args.join(" "), String::from_utf8_lossy(&out.stderr));
}

/// Two namespaces, `master` and `segment`, with a veth pair between them. Dropping it removes
/// both (and with them the veth pair).
pub struct VethPair {
    pub master_ns: String,
    pub segment_ns: String,
    pub master_if: String,
    pub segment_if: String,
}

impl VethPair {
    pub fn new(tag: &str) -> Self {
        assert!(
            unsafe_is_root(),
            "this test creates network namespaces and raw sockets: it must run as root (CI does)"
        );
        let id = format!("{}{}", tag, std::process::id() % 100_000);
        let p = VethPair {
            master_ns: format!("fc{id}m"),
            segment_ns: format!("fc{id}s"),
            master_if: format!("fc{id}a"),
            segment_if: format!("fc{id}b"),
        };
        let _ = Command::new("ip").args(["netns", "del", &p.master_ns]).output();
        let _ = Command::new("ip").args(["netns", "del", &p.segment_ns]).output();
        ip(&["netns", "add", &p.master_ns]);
        ip(&["netns", "add", &p.segment_ns]);
        ip(&["link", "add", &p.master_if, "type", "veth", "peer", "name", &p.segment_if]);
        ip(&["link", "set", &p.master_if, "netns", &p.master_ns]);
        ip(&["link", "set", &p.segment_if, "netns", &p.segment_ns]);
        for (ns, ifc) in [(&p.master_ns, &p.master_if), (&p.segment_ns, &p.segment_if)] {
            ip(&["-n", ns, "link", "set", ifc, "up"]);
            ip(&["-n", ns, "link", "set", "lo", "up"]);
        }
        p
    }

    /// A second veth pair between the same namespaces (a master's redundant port): the master's
    /// end and the segment's. It goes with the namespaces.
    pub fn second_link(&self) -> (String, String) {
        let stem = self.master_if.strip_suffix('a').unwrap();
        let (m, s) = (format!("{stem}c"), format!("{stem}d"));
        ip(&["link", "add", &m, "type", "veth", "peer", "name", &s]);
        ip(&["link", "set", &m, "netns", &self.master_ns]);
        ip(&["link", "set", &s, "netns", &self.segment_ns]);
        ip(&["-n", &self.master_ns, "link", "set", &m, "up"]);
        ip(&["-n", &self.segment_ns, "link", "set", &s, "up"]);
        (m, s)
    }

    /// A command run inside `ns`.
    pub fn cmd(ns: &str, program: &str) -> Command {
        let mut c = Command::new("ip");
        c.args(["netns", "exec", ns, program]);
        c
    }
}

impl Drop for VethPair {
    fn drop(&mut self) {
        let _ = Command::new("ip").args(["netns", "del", &self.master_ns]).output();
        let _ = Command::new("ip").args(["netns", "del", &self.segment_ns]).output();
    }
}

fn unsafe_is_root() -> bool {
    Command::new("id").arg("-u").output().map(|o| o.stdout.starts_with(b"0")).unwrap_or(false)
}

/// The Python with pysoem that scripts/test.sh prepares.
pub fn python() -> PathBuf {
    let p = std::env::var_os("FERROCAT_PYTHON")
        .map(PathBuf::from)
        .unwrap_or_else(|| PathBuf::from(env!("CARGO_MANIFEST_DIR")).join("../../.venv/bin/python"));
    assert!(
        p.exists(),
        "{} not found: scripts/test.sh creates .venv with pysoem (or set FERROCAT_PYTHON)",
        p.display()
    );
    p
}

/// `ferrocat sim` serving `segment_if` in its namespace; stopped with SIGTERM on drop.
pub struct Sim {
    child: Child,
    /// What the simulator says after it is ready (its statistics on exit).
    said: Option<std::thread::JoinHandle<String>>,
}

impl Sim {
    pub fn start(net: &VethPair, args: &[&str]) -> Self {
        let mut c = VethPair::cmd(&net.segment_ns, env!("CARGO_BIN_EXE_ferrocat"));
        c.arg("sim").args(args).args(["--iface", &net.segment_if]).stdout(Stdio::null()).stderr(Stdio::piped());
        // Owned by the guard at once, so that it is stopped even if it never gets ready.
        let mut sim = Sim { child: c.spawn().unwrap(), said: None };
        // Ready once it has bound its socket and said so.
        let mut err = sim.child.stderr.take().unwrap();
        let t0 = Instant::now();
        let mut seen = Vec::new();
        let mut b = [0u8; 256];
        use std::io::Read;
        while !String::from_utf8_lossy(&seen).contains(" on ") {
            let n = err.read(&mut b).unwrap_or(0);
            assert!(
                n > 0 && t0.elapsed() < Duration::from_secs(20),
                "ferrocat sim did not start: {}",
                String::from_utf8_lossy(&seen)
            );
            seen.extend_from_slice(&b[..n]);
        }
        // Keep what the simulator says (its statistics on exit) for failure messages.
        sim.said = Some(std::thread::spawn(move || {
            let mut rest = String::from_utf8_lossy(&seen).into_owned();
            let _ = err.read_to_string(&mut rest);
            if !rest.trim().is_empty() {
                eprintln!("ferrocat sim said: {}", rest.trim());
            }
            rest
        }));
        sim
    }

    /// Stops the simulator with SIGTERM, waits for it to exit cleanly and returns what it said
    /// on stderr.
    pub fn stop(mut self) -> String {
        let pid = self.child.id().to_string();
        Command::new("kill").args(["-TERM", &pid]).status().unwrap();
        let status = self.child.wait().unwrap();
        assert!(status.success(), "ferrocat sim exited with {status}");
        self.said.take().and_then(|h| h.join().ok()).unwrap_or_default()
    }
}

impl Sim {
    /// Waits up to `timeout` for the simulator to exit by itself: its status (`None` if it is
    /// still running) and what it said.
    pub fn wait_exit(mut self, timeout: Duration) -> (Option<std::process::ExitStatus>, String) {
        let t0 = Instant::now();
        while t0.elapsed() < timeout {
            if let Ok(Some(status)) = self.child.try_wait() {
                return (Some(status), self.said.take().and_then(|h| h.join().ok()).unwrap_or_default());
            }
            std::thread::sleep(Duration::from_millis(20));
        }
        (None, String::new())
    }
}

impl Drop for Sim {
    fn drop(&mut self) {
        // SIGTERM first, so that the simulator reports its statistics.
        let _ = Command::new("kill").args(["-TERM", &self.child.id().to_string()]).status();
        std::thread::sleep(Duration::from_millis(200));
        let _ = self.child.kill();
        let _ = self.child.wait();
    }
}

/// `ferrocat sim` serving the segment file `toml` (written for it) with `args` besides, and
/// the report it writes on exit (read with [`ReportingSim::report`]).
pub struct ReportingSim {
    pub sim: Sim,
    path: PathBuf,
    report: PathBuf,
}

impl ReportingSim {
    pub fn start(net: &VethPair, tag: &str, toml: &str, args: &[&str]) -> Self {
        let stem = std::env::temp_dir().join(format!("ferrocat-{tag}-{}", std::process::id()));
        let (path, report) = (stem.with_extension("toml"), stem.with_extension("json"));
        std::fs::write(&path, toml).unwrap();
        let mut all = vec!["--config", path.to_str().unwrap(), "--report", report.to_str().unwrap()];
        all.extend_from_slice(args);
        let sim = Sim::start(net, &all);
        ReportingSim { sim, path, report }
    }

    /// Stops the simulator; its report.
    pub fn report(self) -> serde_json::Value {
        self.sim.stop();
        let rep = serde_json::from_str(&std::fs::read_to_string(&self.report).unwrap()).unwrap();
        std::fs::remove_file(&self.path).ok();
        std::fs::remove_file(&self.report).ok();
        rep
    }
}

/// A ring served on two veth pairs: two couplers with an EL2004 each, the second coupler's
/// X2 OUT back to the master's second interface, the cable between the couplers pulled
/// `break_ms` after the simulator starts; `events`, more `[[event]]` tables. Returns the
/// simulator, the master's second interface, and the report it writes on exit (read with
/// [`RingSim::report`]).
pub struct RingSim {
    pub sim: ReportingSim,
    pub master_secondary: String,
}

impl RingSim {
    pub fn start(net: &VethPair, tag: &str, break_ms: u32, events: &str) -> Self {
        Self::start_segment(
            net,
            tag,
            &format!(
                "[[device]]\nbuiltin = 'EK1100'\n[[device]]\nbuiltin = 'EL2004'\n\
                 [[device]]\nbuiltin = 'EK1100'\nparent = 0\n[[device]]\nbuiltin = 'EL2004'\n\
                 [secondary]\ndevice = 2\n\
                 [[event]]\nat_ms = {break_ms}\nlink_down = {{ device = 2, port = 0 }}\n{events}"
            ),
        )
    }

    /// A ring the segment file `toml` describes (with its `[secondary]` and events).
    pub fn start_segment(net: &VethPair, tag: &str, toml: &str) -> Self {
        let (master_secondary, segment_secondary) = net.second_link();
        let sim = ReportingSim::start(net, tag, toml, &["--secondary-iface", &segment_secondary]);
        RingSim { sim, master_secondary }
    }

    /// Stops the simulator; its report.
    pub fn report(self) -> serde_json::Value {
        self.sim.report()
    }
}
