//! The master's examples (crates/master/examples), each a complete program on a raw
//! interface, run unmodified against `ferrocat sim` over a veth pair, so that none can rot.
mod common;

use std::path::PathBuf;
use std::process::Command;

use common::{ReportingSim, Sim, VethPair};

/// The examples, built with the profile this test was built with.
fn examples_dir() -> PathBuf {
    let exe = std::env::current_exe().unwrap();
    // target/<profile>/deps/<this test>
    let profile_dir = exe.parent().and_then(|d| d.parent()).unwrap().to_path_buf();
    let release = profile_dir.file_name().is_some_and(|n| n == "release");
    let cargo = std::env::var_os("CARGO").unwrap_or_else(|| "cargo".into());
    let mut build = Command::new(cargo);
    build.args(["build", "--quiet", "-p", "ferrocat-master", "--examples"]);
    if release {
        build.arg("--release");
    }
    let status = build.current_dir(env!("CARGO_MANIFEST_DIR")).status().expect("cargo, to build the examples");
    assert!(status.success(), "building the examples failed");
    profile_dir.join("examples")
}

fn run(net: &VethPair, dir: &std::path::Path, example: &str, args: &[&str]) -> String {
    let out = VethPair::cmd(&net.master_ns, dir.join(example).to_str().unwrap())
        .arg(&net.master_if)
        .args(args)
        .output()
        .unwrap();
    let stdout = String::from_utf8_lossy(&out.stdout).into_owned();
    println!("--- {example} {}\n{stdout}", args.join(" "));
    assert!(out.status.success(), "{example}: {stdout}{}", String::from_utf8_lossy(&out.stderr));
    stdout
}

#[test]
fn every_example_runs_against_the_simulator() {
    let dir = examples_dir();
    let net = VethPair::new("ex");
    let devices = ["EK1100", "EL2004", "EL1004", "SERVO", "SERVO"];
    let args: Vec<&str> = devices.iter().flat_map(|d| ["--device", d]).collect();
    let sim = Sim::start(&net, &args);

    let out = run(&net, &dir, "scan", &[]);
    assert!(out.starts_with("5 slaves on "), "{out}");
    assert_eq!(out.lines().filter(|l| l.contains("EK1100") || l.contains("EL2004")).count(), 2, "{out}");

    let out = run(&net, &dir, "cyclic_io", &["500"]);
    assert!(out.contains("writing '") && out.contains("of slave 1"), "the EL2004's first output: {out}");
    assert!(out.contains("500 cycles"), "{out}");

    let out = run(&net, &dir, "sdo", &["3"]);
    assert!(out.contains("device name: ferrocat simulated CiA402 servo drive"), "{out}");
    assert!(out.contains("0x6060 mode of operation: 8"), "{out}");

    let out = run(&net, &dir, "dc_sync", &["ferrocat", "4"]);
    assert!(out.starts_with("reference clock: slave 0; method ferrocat"), "{out}");
    // A report every 0.5 s with a state and an offset. Whether it locks is this machine's
    // business: software stamps on a loaded CI machine (debug build, no real-time priority)
    // left the offset at −27 to +12 µs for 4 s; lock.rs and run_dc.rs test the lock itself.
    let reports: Vec<&str> = out.lines().filter(|l| l.starts_with("t = ")).collect();
    assert_eq!(reports.len(), 8, "{out}");
    let states = ["unlocked", "locking", "locked"];
    assert!(reports.iter().all(|l| states.iter().any(|s| l.contains(&format!("  {s}  offset ")))), "{out}");
    assert!(reports.iter().any(|l| l.contains("offset Some(")), "no offset measured in 4 s: {out}");

    let out = run(&net, &dir, "two_axes_csp", &["3", "4"]);
    let moved: Vec<i64> =
        out.lines().filter_map(|l| l.split("moved ").nth(1)?.split(' ').next()?.parse().ok()).collect();
    assert_eq!(moved.len(), 2, "{out}");
    for m in moved {
        assert!((m - 65_536).abs() < 2_000, "an axis moved {m} increments of 65 536: {out}");
    }
    sim.stop();
}

/// Ctrl-C ends a cyclic example's loop, not the program: it steps the slaves down to INIT on the
/// way out and exits cleanly, as a machine's program must.
#[test]
fn a_cyclic_example_stopped_by_ctrl_c_leaves_every_slave_in_init() {
    let dir = examples_dir();
    let net = VethPair::new("ec");
    let toml = "[[device]]\nbuiltin = 'EK1100'\n[[device]]\nbuiltin = 'EL2004'\n[[device]]\nbuiltin = 'EL1004'\n";
    let sim = ReportingSim::start(&net, "ctrlc", toml, &[]);
    let mut child = VethPair::cmd(&net.master_ns, dir.join("cyclic_io").to_str().unwrap())
        .args([&net.master_if, "600000"])
        .stdout(std::process::Stdio::piped())
        .spawn()
        .unwrap();
    // In OP and cycling once it has said which output it writes.
    let mut out = child.stdout.take().unwrap();
    let mut seen = Vec::new();
    let mut b = [0u8; 256];
    use std::io::Read;
    while !String::from_utf8_lossy(&seen).contains("writing '") {
        let n = out.read(&mut b).unwrap();
        assert!(n > 0, "cyclic_io ended before it cycled: {}", String::from_utf8_lossy(&seen));
        seen.extend_from_slice(&b[..n]);
    }
    std::thread::sleep(std::time::Duration::from_millis(500));
    Command::new("kill").args(["-INT", &child.id().to_string()]).status().unwrap();
    out.read_to_end(&mut seen).unwrap();
    let status = child.wait().unwrap();
    let said = String::from_utf8_lossy(&seen).into_owned();
    assert!(status.success(), "cyclic_io after SIGINT: {status}: {said}");
    let done: u64 = said.lines().find_map(|l| l.split(" cycles,").next()?.parse().ok()).unwrap();
    assert!(done > 0 && done < 600_000, "{said}");
    let report = sim.report();
    let states: Vec<&str> =
        report["devices"].as_array().unwrap().iter().map(|n| n["al_state"].as_str().unwrap()).collect();
    assert_eq!(states, ["INIT"; 3], "{report}");
}
