//! The mailbox gateway (ETG.8200) of `ferrocat run` over a veth pair against `ferrocat sim`,
//! read by a client written elsewhere: `pyetg1510` from PyPI (scripts/test.sh puts it in
//! `.venv`), unmodified, fetches the master's object dictionary (ETG.1510) by SDO information
//! and then every object. The simulator corrupts frames, pulls a cable and has a slave's
//! application report an error; what pyetg1510 reads agrees with `ferrocat slaves` and with
//! the simulator's own report.
mod common;

use std::process::{Child, Command, Stdio};
use std::time::{Duration, Instant};

use common::{python, ReportingSim, VethPair};

struct Running(Child);

impl Drop for Running {
    fn drop(&mut self) {
        let _ = self.0.kill();
        let _ = self.0.wait();
    }
}

fn ferrocat(net: &VethPair, dir: &std::path::Path, args: &[&str]) -> Command {
    let mut c = VethPair::cmd(&net.master_ns, env!("CARGO_BIN_EXE_ferrocat"));
    c.args(args).args(["--iface", &net.master_if]).env("FERROCAT_RUN_DIR", dir);
    c
}

fn json_of(c: &mut Command) -> serde_json::Value {
    let o = c.output().unwrap();
    assert!(o.status.success(), "{}", String::from_utf8_lossy(&o.stderr));
    serde_json::from_slice(&o.stdout).unwrap()
}

/// The segment: a coupler, the servo, an EL2004 and an EL1004; 0.2 % of frames corrupted on
/// their way; 4 s after the simulator starts, the servo's application reports error 0x8001
/// (a vendor's code) and the cable behind the EL2004 is pulled, so that the EL1004 is lost.
const SEGMENT: &str = "corruption_probability = 0.002\n\
    [[device]]\nbuiltin = 'EK1100'\n[[device]]\nbuiltin = 'SERVO'\n\
    [[device]]\nbuiltin = 'EL2004'\n[[device]]\nbuiltin = 'EL1004'\n\
    [[event]]\nat_ms = 4000\nal_error = { device = 1, code = 0x8001 }\n\
    [[event]]\nat_ms = 4000\nlink_down = { device = 2, port = 1 }\n";

#[test]
fn pyetg1510_reads_the_master_s_dictionary_and_each_slave_s_diagnosis_through_the_gateway() {
    let net = VethPair::new("gw");
    let sim = ReportingSim::start(&net, "gateway", SEGMENT, &[]);
    let started = Instant::now();
    let dir = std::env::temp_dir().join(format!("ferrocat-gateway-live-{}", std::process::id()));
    std::fs::create_dir_all(&dir).unwrap();
    let log = dir.join("run.log");
    let run = ferrocat(&net, &dir, &["run", "--seconds", "0", "--mailbox-gateway"])
        .stdout(Stdio::null())
        .stderr(std::fs::File::create(&log).unwrap())
        .spawn()
        .unwrap();
    let mut run = Running(run);
    // Its socket first (a `ferrocat slaves` before it would scan the segment itself), then
    // every slave in OP.
    let socket = dir.join(format!("{}.sock", net.master_if));
    while std::os::unix::net::UnixStream::connect(&socket).is_err() {
        assert!(started.elapsed() < Duration::from_secs(30), "no control socket after 30 s");
        if let Ok(Some(s)) = run.0.try_wait() {
            panic!("ferrocat run exited with {s}: {}", std::fs::read_to_string(&log).unwrap_or_default());
        }
        std::thread::sleep(Duration::from_millis(20));
    }
    loop {
        let said = || std::fs::read_to_string(&log).unwrap_or_default();
        assert!(started.elapsed() < Duration::from_secs(30), "the slaves did not reach OP in 30 s: {}", said());
        if let Ok(Some(s)) = run.0.try_wait() {
            panic!("ferrocat run exited with {s}: {}", said());
        }
        let o = ferrocat(&net, &dir, &["slaves", "--json"]).output().unwrap();
        let v: serde_json::Value = serde_json::from_slice(&o.stdout).unwrap_or_default();
        if v.as_array().is_some_and(|a| a.len() == 4 && a.iter().all(|s| s["state"] == "OP")) {
            break;
        }
        std::thread::sleep(Duration::from_millis(100));
    }
    // The servo kept in SAFEOP from now on (the master does not walk it back), so that the
    // error its application reports stays to be read.
    let o = ferrocat(&net, &dir, &["state", "1", "SAFEOP"]).output().unwrap();
    assert!(o.status.success(), "{}", String::from_utf8_lossy(&o.stderr));
    assert!(started.elapsed() < Duration::from_millis(3500), "the SAFEOP request came after the error was due");
    std::thread::sleep(Duration::from_millis(4500).saturating_sub(started.elapsed()) + Duration::from_millis(500));

    let script = concat!(env!("CARGO_MANIFEST_DIR"), "/tests/python/etg1510_client.py");
    let t = Instant::now();
    let out = VethPair::cmd(&net.master_ns, python().to_str().unwrap())
        .args([script, "127.0.0.1", "34980"])
        .output()
        .unwrap();
    let stdout = String::from_utf8_lossy(&out.stdout);
    assert!(out.status.success(), "pyetg1510: {stdout}{}", String::from_utf8_lossy(&out.stderr));
    println!("pyetg1510 read the dictionary and every object in {:?}", t.elapsed());
    let line = stdout.lines().rev().find(|l| l.starts_with('{')).unwrap_or_else(|| panic!("no JSON in {stdout}"));
    let etg: serde_json::Value = serde_json::from_str(line).unwrap();
    let slaves = json_of(&mut ferrocat(&net, &dir, &["slaves", "--json"]));
    let stats = json_of(&mut ferrocat(&net, &dir, &["stats", "--json"]));
    drop(run);
    let report = sim.report();

    let o = &etg["objects"];
    assert_eq!(o["0x1008"]["DeviceName"], "ferrocat EtherCAT master");
    for s in slaves.as_array().unwrap() {
        let k = s["position"].as_u64().unwrap();
        let c = &o[format!("{:#06x}", 0x8000 + k)];
        assert_eq!(c["FixedStationAddress"], s["station"], "{c}");
        assert_eq!(c["VendorId"], s["vendor_id"], "{c}");
        assert_eq!(c["ProductCode"], s["product_code"], "{c}");
        assert_eq!(c["RevisionNumber"], s["revision"], "{c}");
        assert_eq!(c["Name"], s["name"], "{c}");
    }
    let d = |k: u16| &o[format!("{:#06x}", 0xA000 + k)];
    // The servo: SAFEOP with the error indication and the code its application reported, as
    // `ferrocat slaves` reads it and the simulator ended with.
    assert_eq!(d(1)["ALStatus"], 0x14, "{}", d(1));
    assert_eq!(d(1)["ALStatusCode"], 0x8001, "{}", d(1));
    assert_eq!(etg["diagnosis"]["0xa001"]["al_status"], "SAFEOP", "{etg}");
    assert_eq!(slaves[1]["al_status_code"], 0x8001, "{slaves}");
    assert_eq!(report["devices"][1]["al_status_code"], 0x8001);
    // The EL1004 behind the pulled cable is not present: counted once at least, and the
    // EL2004's port 1 has no link (pyetg1510's port status: communication, link).
    assert!(d(3)["SlaveNotPresentCounter"].as_u64().unwrap() >= 1, "{}", d(3));
    assert_eq!(etg["diagnosis"]["0xa002"]["ports"][1], serde_json::json!([false, false]), "{etg}");
    assert_eq!(etg["diagnosis"]["0xa002"]["ports"][0], serde_json::json!([true, true]), "{etg}");
    assert!(d(0)["AbnormalStateChangeCounter"] == 0, "{}", d(0));
    // Corrupted frames: the slaves' invalid-frame counters, read live, are the simulator's
    // (which only grow) at most, and some counted.
    let mut counted = 0;
    for k in 0..3u16 {
        let ports = d(k)["FrameErrorCounterPort"].as_array().unwrap().clone();
        let sim = report["devices"][k as usize]["error_counters"].as_array().unwrap().clone();
        for (p, v) in ports.iter().enumerate() {
            let invalid = v.as_u64().unwrap() & 0xFF;
            counted += invalid;
            assert!(invalid <= sim[2 * p].as_u64().unwrap(), "slave {k} port {p}: {v} against {sim:?}");
        }
    }
    assert!(counted > 0, "no invalid frame counted: {etg}");
    let g = &stats["extra"]["gateway"];
    assert!(g["replies"].as_u64().unwrap() > 50, "{g}");
    assert_eq!(g["malformed"], 0, "{g}");
    std::fs::remove_dir_all(&dir).ok();
}
