//! ferrocat as an unprivileged user, as its Debian package installs it: a copy of the binary
//! given cap_net_raw, cap_sys_nice and cap_ipc_lock (`setcap`, as the package's postinst does),
//! run as `nobody` (`setpriv`) in a network namespace the test makes, scans and runs with DC;
//! a copy without them says which capability is missing.
mod common;

use std::os::unix::fs::PermissionsExt;
use std::process::{Command, Output};

use common::{Sim, VethPair};

/// The test binary copied to a folder `nobody` can read, with `caps` set on it (or none).
fn copy_with(dir: &std::path::Path, name: &str, caps: Option<&str>) -> std::path::PathBuf {
    let path = dir.join(name);
    std::fs::copy(env!("CARGO_BIN_EXE_ferrocat"), &path).unwrap();
    std::fs::set_permissions(&path, std::fs::Permissions::from_mode(0o755)).unwrap();
    if let Some(c) = caps {
        let st = Command::new("setcap")
            .arg(c)
            .arg(&path)
            .status()
            .expect("setcap (libcap2-bin; scripts/test.sh installs it)");
        assert!(st.success(), "setcap {c}");
    }
    path
}

/// `bin args…` in the master's namespace as the user nobody, with no supplementary groups,
/// its runtime directory (locks) in `dir/run`, which goes with `dir`.
fn as_nobody(net: &VethPair, dir: &std::path::Path, bin: &std::path::Path, args: &[&str]) -> Output {
    let run = dir.join("run");
    std::fs::create_dir_all(&run).unwrap();
    std::fs::set_permissions(&run, std::fs::Permissions::from_mode(0o777)).unwrap();
    VethPair::cmd(&net.master_ns, "setpriv")
        .args(["--reuid=65534", "--regid=65534", "--clear-groups", "--"])
        .arg(bin)
        .args(args)
        .env("FERROCAT_RUN_DIR", &run)
        .output()
        .unwrap()
}

#[test]
fn an_unprivileged_user_with_three_capabilities_scans_and_runs_dc() {
    let net = VethPair::new("cp");
    let dir = std::env::temp_dir().join(format!("ferrocat-caps-{}", std::process::id()));
    std::fs::create_dir_all(&dir).unwrap();
    std::fs::set_permissions(&dir, std::fs::Permissions::from_mode(0o755)).unwrap();
    let with = copy_with(&dir, "ferrocat-caps", Some("cap_net_raw,cap_sys_nice,cap_ipc_lock+ep"));
    let without = copy_with(&dir, "ferrocat-plain", None);
    let sim = Sim::start(&net, &["--device", "EK1100", "--device", "EL2004", "--device", "SERVO"]);
    let who = as_nobody(&net, &dir, std::path::Path::new("/usr/bin/id"), &["-u"]);
    assert_eq!(String::from_utf8_lossy(&who.stdout).trim(), "65534");
    let scan = as_nobody(&net, &dir, &with, &["scan", "--iface", &net.master_if]);
    let run = as_nobody(&net, &dir, &with, &["run", "--iface", &net.master_if, "--dc", "--seconds", "1"]);
    let plain = as_nobody(&net, &dir, &without, &["scan", "--iface", &net.master_if]);
    sim.stop();
    std::fs::remove_dir_all(&dir).ok();
    let text = |o: &Output| format!("{}{}", String::from_utf8_lossy(&o.stdout), String::from_utf8_lossy(&o.stderr));
    assert!(scan.status.success() && text(&scan).starts_with("3 slaves found"), "{}", text(&scan));
    let r = text(&run);
    assert!(run.status.success(), "{r}");
    assert!(r.contains("DC: reference slave") && r.contains("bring-up to OP"), "{r}");
    // Its real-time set-up was granted: locked memory and SCHED_FIFO, no refusal.
    assert!(r.contains("real time: memory locked, SCHED_FIFO priority 80, CPU 1") && !r.contains("refused"), "{r}");
    // Without the capabilities: one clear line naming the one that is missing.
    let p = text(&plain);
    assert!(!plain.status.success() && p.contains("needs CAP_NET_RAW"), "{p}");
    assert!(p.contains(&format!("no permission to send raw frames on {}", net.master_if)), "{p}");
    assert_eq!(p.lines().filter(|l| l.contains("error")).count(), 1, "{p}");
}
