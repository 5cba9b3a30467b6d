//! `ferrocat run` as a service on a veth pair against `ferrocat sim`: while it runs, `ferrocat
//! sdo`, `slaves`, `reg` and `stats` reach it through its control socket, `ferrocat set` (an
//! application of its own process) moves outputs through the shared image, a second master on
//! the interface is refused, and clients that vanish mid-request or mid-write change nothing;
//! the master keeps every slave in OP throughout.
mod common;

use std::io::Write;
use std::process::{Child, Command, Stdio};
use std::time::{Duration, Instant};

use common::{ReportingSim, VethPair};

/// `ferrocat ARGS` in the master's namespace, with the runtime directory `dir`.
fn ferrocat(net: &VethPair, dir: &std::path::Path, args: &[&str]) -> Command {
    let mut c = VethPair::cmd(&net.master_ns, env!("CARGO_BIN_EXE_ferrocat"));
    c.args(args).args(["--iface", &net.master_if]).env("FERROCAT_RUN_DIR", dir);
    c
}

/// How long a command beside the running master may take: past this it is stopped and the
/// test fails naming it (the client's own waits are longer: an FoE file's an hour).
const COMMAND_LIMIT: Duration = Duration::from_secs(60);

fn output(c: &mut Command) -> (bool, String, String) {
    use std::io::Read;
    let mut child = c.stdout(Stdio::piped()).stderr(Stdio::piped()).spawn().unwrap();
    let read = |mut r: Box<dyn Read + Send>| {
        std::thread::spawn(move || {
            let mut s = Vec::new();
            let _ = r.read_to_end(&mut s);
            String::from_utf8_lossy(&s).into_owned()
        })
    };
    let out = read(Box::new(child.stdout.take().unwrap()));
    let err = read(Box::new(child.stderr.take().unwrap()));
    let t0 = Instant::now();
    let status = loop {
        if let Some(status) = child.try_wait().unwrap() {
            break status;
        }
        if t0.elapsed() > COMMAND_LIMIT {
            let _ = child.kill();
            let _ = child.wait();
            panic!("{c:?} gave no answer in {COMMAND_LIMIT:?}: {}", err.join().unwrap_or_default());
        }
        std::thread::sleep(Duration::from_millis(20));
    };
    (status.success(), out.join().unwrap_or_default(), err.join().unwrap_or_default())
}

struct Running(Child);

impl Drop for Running {
    fn drop(&mut self) {
        let _ = self.0.kill();
        let _ = self.0.wait();
    }
}

#[test]
fn commands_reach_a_running_master_through_its_socket_and_a_second_master_is_refused() {
    let net = VethPair::new("sv");
    let sim = ReportingSim::start(
        &net,
        "service",
        "[[device]]\nbuiltin = 'EK1100'\n[[device]]\nbuiltin = 'EL2004'\n[[device]]\nbuiltin = 'SERVO'\n",
        &[],
    );
    let dir = std::env::temp_dir().join(format!("ferrocat-service-live-{}", std::process::id()));
    // A described machine: the network is checked against it before anything leaves INIT.
    std::fs::create_dir_all(&dir).unwrap();
    let machine = dir.join("machine.toml");
    std::fs::write(
        &machine,
        "name = \"bench\"\n\
         [[slave]]\nname = \"coupler\"\nvendor = 2\nproduct = 0x044C2C52\n\
         [[slave]]\nname = \"lamps\"\nvendor = 2\nproduct = 0x07D43052\n\
         [[slave]]\nname = \"axis\"\nvendor = 0\nproduct = 0x402\n\
         [[variable]]\nname = \"status\"\nentry = \"axis:Statusword\"\n",
    )
    .unwrap();
    let run = ferrocat(&net, &dir, &["run", "--machine", machine.to_str().unwrap(), "--seconds", "0", "--json"])
        .stdout(Stdio::piped())
        .stderr(Stdio::piped())
        .spawn()
        .unwrap();
    let mut run = Running(run);
    // Ready once its socket answers.
    let socket = dir.join(format!("{}.sock", net.master_if));
    let t0 = Instant::now();
    while ferrocat_service_ready(&socket).is_none() {
        assert!(t0.elapsed() < Duration::from_secs(30), "no control socket at {} after 30 s", socket.display());
        if let Ok(Some(s)) = run.0.try_wait() {
            panic!("ferrocat run exited with {s}");
        }
        std::thread::sleep(Duration::from_millis(50));
    }

    let t = Instant::now();
    let (ok, out, err) = output(&mut ferrocat(&net, &dir, &["sdo", "read", "2", "0x1018:1", "--type", "hex"]));
    println!("sdo read beside the running master: {:?} (the command's whole run)", t.elapsed());
    assert!(ok, "{err}");
    assert!(err.contains("through the master running on"), "{err}");
    assert_eq!(out.trim().split(' ').count(), 4, "{out}");

    let (ok, out, err) = output(&mut ferrocat(&net, &dir, &["slaves", "--json"]));
    assert!(ok, "{err}");
    let slaves: serde_json::Value = serde_json::from_str(&out).unwrap();
    let states: Vec<&str> = slaves.as_array().unwrap().iter().map(|s| s["state"].as_str().unwrap()).collect();
    assert_eq!(states, ["OP", "OP", "OP"], "{out}");

    let (ok, out, err) = output(&mut ferrocat(&net, &dir, &["pdos", "1"]));
    assert!(ok && out.lines().filter(|l| l.contains("0x7")).count() == 4, "{out} {err}");
    let (ok, _, err) = output(&mut ferrocat(&net, &dir, &["events"]));
    assert!(ok, "{err}");
    // FoE beside the master: a parameter file there and back.
    let params = dir.join("params.bin");
    std::fs::write(&params, (0..2000u32).map(|k| (k * 13) as u8).collect::<Vec<u8>>()).unwrap();
    let (ok, _, err) =
        output(&mut ferrocat(&net, &dir, &["foe", "write", "2", "params.bin", params.to_str().unwrap()]));
    assert!(ok && err.contains("through the master running on"), "{err}");
    let back = dir.join("back.bin");
    let (ok, _, err) = output(&mut ferrocat(&net, &dir, &["foe", "read", "2", "params.bin", back.to_str().unwrap()]));
    assert!(ok, "{err}");
    assert_eq!(std::fs::read(&back).unwrap(), std::fs::read(&params).unwrap());
    let (ok, _, err) =
        output(&mut ferrocat(&net, &dir, &["foe", "write", "2", "fw.bin", params.to_str().unwrap(), "--boot"]));
    assert!(!ok && err.contains("stop that master first"), "{err}");
    let sii = dir.join("servo.sii");
    let (ok, _, err) = output(&mut ferrocat(&net, &dir, &["sii", "read", "2", "--out", sii.to_str().unwrap()]));
    assert!(ok && err.contains("through the master running on"), "{err}");
    let (ok, out, err) = output(Command::new(env!("CARGO_BIN_EXE_ferrocat")).args(["sii", sii.to_str().unwrap()]));
    assert!(ok && out.contains("0x00000402"), "{out}{err}");
    let (ok, out, err) = output(&mut ferrocat(&net, &dir, &["reg", "read", "1", "0x0130"]));
    assert!(ok && out.trim() == "08 00", "{out} {err}");
    let (ok, _, err) = output(&mut ferrocat(&net, &dir, &["reg", "write", "1", "0x0f80", "01"]));
    assert!(!ok && err.contains("--allow-register-writes"), "{err}");

    // An application in a process of its own moves outputs through the shared image, as one
    // write; a client killed mid-write (its lock released by the kernel) leaves no trace.
    let (ok, _, err) = output(&mut ferrocat(&net, &dir, &["set", "1:Output#2=1", "1:Output#3=1"]));
    assert!(ok && err.contains("first sent by cycle"), "{err}");
    let (ok, out, err) = output(&mut ferrocat(&net, &dir, &["get", "1:Output#2", "1:Output#1", "--json"]));
    assert!(ok, "{err}");
    let got: serde_json::Value = serde_json::from_str(&out).unwrap();
    assert_eq!(
        (got["values"]["1:Output#2"].as_u64(), got["values"]["1:Output#1"].as_u64()),
        (Some(1), Some(0)),
        "{got}"
    );
    // The description's variable, by its name, from another process.
    let (ok, out, err) = output(&mut ferrocat(&net, &dir, &["get", "status", "2:Statusword", "--json"]));
    let got: serde_json::Value = serde_json::from_str(&out).unwrap_or_default();
    assert!(ok && got["values"]["status"].is_u64(), "{out}{err}");
    let image = socket.with_extension("image");
    let mut dying = ferrocat_service::ImageClient::attach(&image).unwrap();
    dying.begin_write_and_abandon("1:Output#4", 1).unwrap();
    drop(dying);
    let (ok, _, err) = output(&mut ferrocat(&net, &dir, &["set", "1:Output#1=1"]));
    assert!(ok, "{err}");

    // The description edited while the master runs: a process-data watchdog for the lamps,
    // written at `ferrocat reload` in the cycles' spare time (100 µs steps: 500 for 50 ms).
    let text = std::fs::read_to_string(&machine).unwrap();
    std::fs::write(&machine, text.replace("name = \"lamps\"\n", "name = \"lamps\"\nwatchdog_us = 50000\n")).unwrap();
    let (ok, _, err) = output(&mut ferrocat(&net, &dir, &["reload"]));
    assert!(ok && err.contains("slave 1's process-data watchdog to 50000 µs"), "{err}");
    let (ok, out, err) = output(&mut ferrocat(&net, &dir, &["reg", "read", "1", "0x0420"]));
    assert!(ok && out.trim() == "f4 01", "{out}{err}");
    // SIGHUP does the same (the summary's stderr says so at the end).
    Command::new("kill").args(["-HUP", &run.0.id().to_string()]).status().unwrap();

    // A second master, and a command that scans, are refused with the way to the first.
    for args in [&["run", "--seconds", "1"][..], &["scan"][..]] {
        let (ok, _, err) = output(&mut ferrocat(&net, &dir, args));
        assert!(!ok && err.contains("a master runs on") && err.contains(".sock"), "{args:?}: {err}");
    }

    // Clients that send a request and vanish before the reply.
    for _ in 0..5 {
        let mut s = std::os::unix::net::UnixStream::connect(&socket).unwrap();
        s.write_all(b"{\"id\":1,\"op\":\"od_list\",\"position\":2}\n").unwrap();
    }
    let (ok, out, err) = output(&mut ferrocat(&net, &dir, &["stats", "--json"]));
    assert!(ok, "{err}");
    let stats: serde_json::Value = serde_json::from_str(&out).unwrap();
    assert!(stats["cycles"].as_u64().unwrap() > 0, "{stats}");
    // Diagnosis while cyclic, as the master has it: error counters read.
    assert!(stats["extra"]["diagnosis"]["counter_reads"].as_u64().unwrap() > 0, "{stats}");

    Command::new("kill").args(["-INT", &run.0.id().to_string()]).status().unwrap();
    let child = std::mem::replace(&mut run.0, Command::new("true").spawn().unwrap());
    let o = child.wait_with_output().unwrap();
    let err = String::from_utf8_lossy(&o.stderr);
    assert!(o.status.success(), "{err}");
    let summary: serde_json::Value = serde_json::from_slice(&o.stdout).unwrap();
    // No slave left OP: nothing the clients asked took one out (without DC, a host's stall
    // does not either; a lost frame may shorten a working counter, which is not asserted).
    assert_eq!(summary["slaves"]["left_op"], 0, "{summary}");
    assert_eq!(summary["slaves"]["in_op_at_end"], 3, "{summary}");
    assert!(summary["control"]["requests_answered"].as_u64().unwrap() >= 4, "{summary}");
    assert_eq!(summary["control"]["image"]["writes_dropped_half_done"], 1, "{summary}");
    assert!(!socket.exists() && !image.exists(), "the socket and the image go when the master stops");
    // What the EL2004 last received: outputs 1–3 on, 4 (the half-done write) off. And the
    // master, stopped by a signal, stepped every slave down to INIT.
    assert!(err.contains("slaves stepped down to SAFEOP, then INIT"), "{err}");
    assert_eq!(err.matches("reload: ").count(), 2, "{err}");
    let report = sim.report();
    let el2004 = &report["devices"][1];
    assert_eq!(el2004["outputs"], serde_json::json!([0b0111]), "{el2004}");
    let states: Vec<&str> =
        report["devices"].as_array().unwrap().iter().map(|d| d["al_state"].as_str().unwrap()).collect();
    assert_eq!(states, ["INIT"; 3], "{report}");
    std::fs::remove_dir_all(&dir).ok();
}

/// The master's hello on `socket`, if it answers.
fn ferrocat_service_ready(socket: &std::path::Path) -> Option<String> {
    use std::io::BufRead;
    let s = std::os::unix::net::UnixStream::connect(socket).ok()?;
    let mut line = String::new();
    std::io::BufReader::new(s).read_line(&mut line).ok()?;
    line.contains("hello").then_some(line)
}

/// The service crate's examples, built with the profile this test was built with.
fn service_examples() -> std::path::PathBuf {
    let exe = std::env::current_exe().unwrap();
    let profile_dir = exe.parent().and_then(|d| d.parent()).unwrap().to_path_buf();
    let cargo = std::env::var_os("CARGO").unwrap_or_else(|| "cargo".into());
    let mut build = Command::new(cargo);
    build.args(["build", "--quiet", "-p", "ferrocat-service", "--examples"]);
    if profile_dir.file_name().is_some_and(|n| n == "release") {
        build.arg("--release");
    }
    let status = build.current_dir(env!("CARGO_MANIFEST_DIR")).status().expect("cargo, to build the examples");
    assert!(status.success(), "building the service examples failed");
    profile_dir.join("examples")
}

#[test]
fn an_application_of_its_own_process_runs_beside_the_master() {
    let examples = service_examples();
    let net = VethPair::new("sa");
    // The drives' sync supervision is off: this test is about an application beside the
    // master, and a stall of the host of three cycles (this VM's vCPUs stall 4-6 ms several
    // times a second) would take them out of OP more often than the application re-enables
    // them in one move. The recovery itself is the soak's and `soem_live`'s.
    let sim = ReportingSim::start(
        &net,
        "service-app",
        "[[device]]\nbuiltin = 'EK1100'\n[[device]]\nbuiltin = 'EL2004'\n[[device]]\nbuiltin = 'EL1004'\n\
         [[device]]\nbuiltin = 'SERVO'\nsync_error_limit = 0\n[[device]]\nbuiltin = 'SERVO'\nsync_error_limit = 0\n",
        &[],
    );
    let dir = std::env::temp_dir().join(format!("ferrocat-service-app-{}", std::process::id()));
    let run = ferrocat(&net, &dir, &["run", "--dc", "--seconds", "0", "--json"])
        .stdout(Stdio::piped())
        .stderr(Stdio::piped())
        .spawn()
        .unwrap();
    let mut run = Running(run);
    let socket = dir.join(format!("{}.sock", net.master_if));
    let t0 = Instant::now();
    while ferrocat_service_ready(&socket).is_none() {
        assert!(t0.elapsed() < Duration::from_secs(30), "no control socket after 30 s");
        std::thread::sleep(Duration::from_millis(50));
    }
    let example = |name: &str, args: &[&str]| {
        let mut c = VethPair::cmd(&net.master_ns, examples.join(name).to_str().unwrap());
        c.arg(&net.master_if).args(args).env("FERROCAT_RUN_DIR", &dir);
        c
    };
    let (ok, out, err) = output(&mut example("io_app", &["1"]));
    println!("{out}");
    assert!(ok, "io_app: {out}{err}");
    assert!(out.contains("vendor id") && out.contains("writing '1:Output#1'"), "{out}");
    let writes: u64 = out.lines().find_map(|l| l.split(" writes;").next()?.parse().ok()).unwrap_or(0);
    assert!(writes > 10, "{out}");

    // Two drives enabled and moved in CSP by a process of their own, a set-point a cycle.
    let (ok, out, err) = output(&mut example("csp_app", &["65536"]));
    println!("{out}");
    assert!(ok, "csp_app: {out}{err}");
    let moved: Vec<i64> =
        out.lines().filter_map(|l| l.split(": moved ").nth(1)?.split(' ').next()?.parse().ok()).collect();
    assert_eq!(moved.len(), 2, "{out}");
    // Where the profile ends: a drive follows its set-points within its following window.
    assert!(moved.iter().all(|m| (m - 65536).abs() < 4096), "{out}");

    // The benchmark's writer: its figures printed, not asserted (they are the host's).
    let writer = example("load", &["write", "1:Output#3"]).stdout(Stdio::piped()).spawn().unwrap();
    std::thread::sleep(Duration::from_millis(500));
    Command::new("kill").args(["-TERM", &writer.id().to_string()]).status().unwrap();
    let said = String::from_utf8_lossy(&writer.wait_with_output().unwrap().stdout).into_owned();
    println!("{said}");
    assert!(said.starts_with("write: ") && !said.starts_with("write: 0 writes"), "{said}");

    Command::new("kill").args(["-TERM", &run.0.id().to_string()]).status().unwrap();
    let child = std::mem::replace(&mut run.0, Command::new("true").spawn().unwrap());
    let o = child.wait_with_output().unwrap();
    assert!(o.status.success(), "{}", String::from_utf8_lossy(&o.stderr));
    let summary: serde_json::Value = serde_json::from_slice(&o.stdout).unwrap();
    // Every slave that left OP (a stall of the host of several cycles) came back, and all are
    // in OP at the end.
    assert_eq!(summary["slaves"]["left_op"], summary["slaves"]["recovered"], "{summary}");
    assert_eq!(summary["slaves"]["in_op_at_end"], 5, "{summary}");
    assert!(summary["control"]["image"]["writes_taken"].as_u64().unwrap() > 10, "{summary}");
    sim.report();
    std::fs::remove_dir_all(&dir).ok();
}
