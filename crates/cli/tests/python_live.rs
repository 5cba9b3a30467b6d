//! The Python package (python/, installed into the suite's .venv by scripts/test.sh) on veth
//! pairs: its master on a raw interface against `ferrocat sim`, its cycles in a Rust thread
//! beside a Python thread that burns CPU; a segment served from Python and scanned by SOEM
//! (pysoem, unmodified); its client of a running `ferrocat run`.
mod common;

use std::io::{BufRead, BufReader, Write};
use std::process::{Command, Stdio};
use std::time::{Duration, Instant};

use common::{python, ReportingSim, Sim, VethPair};

fn script(name: &str) -> String {
    format!("{}/../../python/tests/live/{name}", env!("CARGO_MANIFEST_DIR"))
}

fn example(name: &str) -> String {
    format!("{}/../../python/examples/{name}", env!("CARGO_MANIFEST_DIR"))
}

fn run_python(ns: &str, args: &[&str]) -> (bool, String, String) {
    let o = VethPair::cmd(ns, python().to_str().unwrap()).args(args).output().unwrap();
    (
        o.status.success(),
        String::from_utf8_lossy(&o.stdout).into_owned(),
        String::from_utf8_lossy(&o.stderr).into_owned(),
    )
}

#[test]
fn the_python_master_cycles_in_a_thread_beside_busy_python_and_serves_sdo_between_cycles() {
    let net = VethPair::new("py");
    let sim = ReportingSim::start(
        &net,
        "python-loop",
        "[[device]]\nbuiltin = 'EK1100'\n[[device]]\nbuiltin = 'EL2004'\n[[device]]\nbuiltin = 'SERVO'\n",
        &[],
    );
    let (ok, out, err) = run_python(&net.master_ns, &[&script("master_loop.py"), &net.master_if]);
    let report = sim.report();
    assert!(ok, "master_loop.py: {err}");
    let r: serde_json::Value = serde_json::from_str(out.trim()).unwrap_or_else(|e| panic!("{e}: {out}"));
    println!("Python master: {r}");
    // The loop ran on while Python burned CPU: at 1 ms, at least a third of the cycles the
    // time allowed (a loaded CI host stalls, but a loop held up by the GIL would run none).
    let elapsed_ms = r["elapsed_s"].as_f64().unwrap() * 1e3;
    assert!(r["cycles"].as_f64().unwrap() > elapsed_ms / 3.0, "{r}");
    assert_eq!(r["running_during"], true);
    assert_eq!(r["running_after"], false);
    let second = r["second"].as_str().unwrap_or_default();
    assert!(second.contains("a master runs on") && second.contains("process"), "{r}");
    // SDO between cycles: the servo's vendor ID (0), a value written and read back, an abort
    // with its code.
    assert_eq!(r["vendor"], 0);
    assert_eq!(r["readback"], 4242);
    assert_eq!(r["abort"], 0x0602_0000);
    // Outputs 2 and 4 reached the EL2004, and every device is in OP.
    assert_eq!(r["outputs"], 3);
    let devices = report["devices"].as_array().unwrap();
    assert_eq!(devices[1]["outputs"], serde_json::json!([0x0A]), "{report}");
    for d in devices {
        assert_eq!(d["al_state"], "OP", "{d}");
    }
}

#[test]
fn the_python_basic_example_runs_on_an_interface_and_a_dropped_master_stops_its_loop() {
    let net = VethPair::new("pb");
    let sim = Sim::start(&net, &["--device", "EK1100", "--device", "EL2004", "--device", "EL1004"]);
    let (ok, out, err) = run_python(&net.master_ns, &[&example("basic_example.py"), &net.master_if]);
    // The loop's thread comes with start() and goes with the master's Python object.
    let (dropped, said, err_d) = run_python(&net.master_ns, &[&script("loop_drop.py"), &net.master_if]);
    sim.stop();
    assert!(ok, "basic_example.py: {err}");
    assert!(dropped, "loop_drop.py: {err_d}");
    let t: serde_json::Value = serde_json::from_str(said.trim()).unwrap();
    let t: Vec<u64> = t["threads"].as_array().unwrap().iter().map(|v| v.as_u64().unwrap()).collect();
    assert!(t[1] == t[0] + 1 && t[2] == t[0], "threads idle, looping, after the drop: {t:?}");
    assert!(out.contains("all slaves in OP: EK1100") && out.contains("cycles in a Rust thread"), "{out}");
    assert!(out.contains("basic_example done"), "{out}");
}

#[test]
fn soem_scans_a_segment_served_from_python() {
    let net = VethPair::new("ps");
    let mut served = VethPair::cmd(&net.segment_ns, python().to_str().unwrap())
        .args([&script("serve_segment.py"), &net.segment_if, "EK1100", "EL2004", "SERVO"])
        .stdin(Stdio::piped())
        .stdout(Stdio::piped())
        .stderr(Stdio::piped())
        .spawn()
        .unwrap();
    let mut lines = BufReader::new(served.stdout.take().unwrap()).lines();
    let t0 = Instant::now();
    let first = lines.next().and_then(|l| l.ok()).unwrap_or_default();
    assert!(first == "serving" && t0.elapsed() < Duration::from_secs(30), "serve_segment.py said {first:?}");
    let soem = concat!(env!("CARGO_MANIFEST_DIR"), "/tests/python/soem_scan.py");
    let (ok, out, err) = run_python(&net.master_ns, &[soem, &net.master_if]);
    // Closing its stdin ends the serving.
    drop(served.stdin.take());
    let stats = lines.next().and_then(|l| l.ok()).unwrap_or_default();
    let status = served.wait().unwrap();
    assert!(ok, "pysoem: {err}");
    assert!(status.success(), "serve_segment.py exited with {status}");
    let found: serde_json::Value = serde_json::from_str(out.trim()).unwrap();
    let ids: Vec<(u64, u64)> = found
        .as_array()
        .unwrap()
        .iter()
        .map(|s| (s["vendor_id"].as_u64().unwrap(), s["product_code"].as_u64().unwrap()))
        .collect();
    assert_eq!(ids, [(2, 0x044C_2C52), (2, 0x07D4_3052), (0, 0x402)], "{out}");
    let stats: serde_json::Value = serde_json::from_str(&stats).unwrap();
    assert!(stats["frames_in"].as_u64().unwrap() > 10 && stats["malformed"] == 0, "{stats}");
}

#[test]
fn the_python_client_reaches_a_running_master() {
    let net = VethPair::new("pc");
    let sim = Sim::start(&net, &["--device", "EK1100", "--device", "EL2004", "--device", "SERVO"]);
    let dir = std::env::temp_dir().join(format!("ferrocat-python-client-{}", std::process::id()));
    std::fs::create_dir_all(&dir).unwrap();
    let mut run = VethPair::cmd(&net.master_ns, env!("CARGO_BIN_EXE_ferrocat"))
        .args(["run", "--iface", &net.master_if, "--seconds", "0"])
        .env("FERROCAT_RUN_DIR", &dir)
        .stdout(Stdio::null())
        .stderr(Stdio::piped())
        .spawn()
        .unwrap();
    let socket = dir.join(format!("{}.sock", net.master_if));
    let t0 = Instant::now();
    while std::os::unix::net::UnixStream::connect(&socket).is_err() {
        if t0.elapsed() > Duration::from_secs(30) || run.try_wait().unwrap().is_some() {
            let _ = run.kill();
            panic!("no control socket at {}", socket.display());
        }
        std::thread::sleep(Duration::from_millis(50));
    }
    let (ok, out, err) = run_python(&net.master_ns, &[&script("client.py"), socket.to_str().unwrap()]);
    let _ = Command::new("kill").args(["-INT", &run.id().to_string()]).status();
    let _ = run.wait();
    if let Some(mut e) = run.stderr.take() {
        let mut said = String::new();
        let _ = std::io::Read::read_to_string(&mut e, &mut said);
        let _ = std::io::stderr().write_all(said.as_bytes());
    }
    sim.stop();
    std::fs::remove_dir_all(&dir).ok();
    assert!(ok, "client.py: {err}");
    let r: serde_json::Value = serde_json::from_str(out.trim()).unwrap_or_else(|e| panic!("{e}: {out}"));
    assert_eq!(r["hello"]["service"], "ferrocat");
    assert_eq!(r["hello"]["slaves"], 3);
    assert_eq!(r["states"], serde_json::json!(["OP", "OP", "OP"]));
    assert_eq!(r["vendor"], 0);
    assert!(r["variables"].as_array().unwrap().iter().any(|v| v == "1:Output#2"), "{r}");
    let seen = &r["seen"];
    assert!(seen.is_object(), "the written output never showed in a cycle: {r}");
    assert_eq!(seen["values"]["1:Output#1"], 0);
    assert!(seen["cycle"].as_u64().unwrap() > 0);
}
