//! `ferrocat soe` on a raw interface against `ferrocat sim` over a veth pair, serving our SoE
//! drive (`ferrocat_soe_drive.xml`, a 40-byte mailbox): an IDN read in fragments, a value
//! written and read back within one run of the simulator, a refusal by code; then the same
//! beside a running `ferrocat run`, through its control socket.
mod common;

use common::{Sim, VethPair};

#[test]
fn soe_reads_and_writes_a_simulated_drive_s_idns_over_a_real_socket() {
    let net = VethPair::new("so");
    let esi = concat!(env!("CARGO_MANIFEST_DIR"), "/../esi/tests/data/ferrocat_soe_drive.xml");
    let device = format!("{esi}:FC-SOE-DRIVE");
    let sim = Sim::start(&net, &["--device", "EK1100", "--device", &device]);
    // The runtime directory (the interface's lock, the running master's socket): the test's
    // own, removed at its end.
    let dir = std::env::temp_dir().join(format!("ferrocat-soe-live-{}", std::process::id()));
    std::fs::create_dir_all(&dir).unwrap();
    let soe = |args: &[&str]| {
        let out = VethPair::cmd(&net.master_ns, env!("CARGO_BIN_EXE_ferrocat"))
            .arg("soe")
            .args(args)
            .args(["--iface", &net.master_if, "--force"])
            .env("FERROCAT_RUN_DIR", &dir)
            .output()
            .unwrap();
        (
            out.status.success(),
            String::from_utf8_lossy(&out.stdout).into_owned(),
            String::from_utf8_lossy(&out.stderr).into_owned(),
        )
    };
    let (ok, out, err) = soe(&["read", "1", "S-0-0030"]);
    assert!(ok, "{err}");
    assert_eq!(out.trim(), "\"ferrocat SoE drive (ferrocat simulation)\"");
    let (ok, _, err) = soe(&["write", "1", "P-0-0001", "321"]);
    assert!(ok, "{err}");
    // The simulator keeps the value between the two commands' masters.
    let (ok, out, err) = soe(&["read", "1", "P-0-0001"]);
    assert!(ok && out.trim() == "321", "{out}{err}");
    let (ok, _, err) = soe(&["read", "1", "S-0-4000"]);
    assert!(!ok && err.contains("SoE error 0x1001 (no IDN)"), "{err}");

    // Beside a running master: through its control socket, between its cycles.
    let mut run = VethPair::cmd(&net.master_ns, env!("CARGO_BIN_EXE_ferrocat"))
        .args(["run", "--iface", &net.master_if, "--seconds", "0"])
        .env("FERROCAT_RUN_DIR", &dir)
        .stdout(std::process::Stdio::null())
        .stderr(std::process::Stdio::null())
        .spawn()
        .unwrap();
    let socket = dir.join(format!("{}.sock", net.master_if));
    let t0 = std::time::Instant::now();
    while std::os::unix::net::UnixStream::connect(&socket).is_err() {
        if t0.elapsed() > std::time::Duration::from_secs(30) || run.try_wait().unwrap().is_some() {
            let _ = run.kill();
            panic!("no control socket at {}", socket.display());
        }
        std::thread::sleep(std::time::Duration::from_millis(50));
    }
    let beside = |args: &[&str]| {
        let out = VethPair::cmd(&net.master_ns, env!("CARGO_BIN_EXE_ferrocat"))
            .arg("soe")
            .args(args)
            .args(["--iface", &net.master_if])
            .env("FERROCAT_RUN_DIR", &dir)
            .output()
            .unwrap();
        (
            out.status.success(),
            String::from_utf8_lossy(&out.stdout).into_owned(),
            String::from_utf8_lossy(&out.stderr).into_owned(),
        )
    };
    let (ok, out, err) = beside(&["read", "1", "S-0-0030"]);
    let firmware = out.trim() == "\"ferrocat SoE drive (ferrocat simulation)\"";
    let (wrote, _, err_w) = beside(&["write", "1", "P-0-0001", "654"]);
    let (ok_r, back, err_r) = beside(&["read", "1", "P-0-0001", "--element", "all"]);
    let _ = std::process::Command::new("kill").args(["-INT", &run.id().to_string()]).status();
    let _ = run.wait();
    std::fs::remove_dir_all(&dir).ok();
    sim.stop();
    assert!(ok && firmware && err.contains("through the master running on"), "{out}{err}");
    assert!(wrote, "{err_w}");
    assert!(ok_r && back.contains("value     654") && back.contains("max       1000"), "{back}{err_r}");
}
