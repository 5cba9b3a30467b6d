//! `ferrocat rtt` on interfaces the test makes: it measures a segment `ferrocat sim` serves,
//! refuses an addressed interface without `--force`, does not count its own looped-back
//! frames, and gives up quickly where nothing answers.
mod common;

use std::time::{Duration, Instant};

use common::{Sim, VethPair};

fn rtt(ns: &str, args: &[&str]) -> (bool, String, String, Duration) {
    let t0 = Instant::now();
    let o = VethPair::cmd(ns, env!("CARGO_BIN_EXE_ferrocat")).arg("rtt").args(args).output().unwrap();
    let (out, err) = (String::from_utf8_lossy(&o.stdout).to_string(), String::from_utf8_lossy(&o.stderr).to_string());
    (o.status.success(), out, err, t0.elapsed())
}

#[test]
fn rtt_measures_a_segment_and_refuses_what_is_not_one() {
    let net = VethPair::new("rt");
    // Nothing on the other end yet: 20 unanswered frames of 50 ms, then an error.
    let (ok, _, err, took) = rtt(&net.master_ns, &["--iface", &net.master_if, "--frames", "2000"]);
    assert!(!ok && err.contains("no slave answered 20 frames in a row") && err.contains("nothing came back"), "{err}");
    assert!(took < Duration::from_secs(10), "gave up after {took:?}");
    // `lo` hands every frame back unprocessed; it has an address, so only with --force.
    let (ok, _, err, _) = rtt(&net.master_ns, &["--iface", "lo", "--frames", "50"]);
    assert!(!ok && err.contains("lo has address(es) 127.0.0.1") && err.contains("--force"), "{err}");
    let (ok, out, err, _) = rtt(&net.master_ns, &["--iface", "lo", "--frames", "50", "--force"]);
    assert!(!ok && err.contains("came back unprocessed") && out.is_empty(), "{out}{err}");
    let (ok, _, err, _) = rtt(&net.master_ns, &["--iface", &net.master_if, "--frames", "0"]);
    assert!(!ok && err.contains("0 is not in 1.."), "{err}");
    // A segment: every frame answered.
    let sim = Sim::start(&net, &["--device", "EK1100", "--device", "EL2004", "--device", "EL1004"]);
    let (ok, out, err, _) = rtt(&net.master_ns, &["--iface", &net.master_if, "--frames", "200"]);
    sim.stop();
    assert!(ok, "{out}{err}");
    assert!(out.starts_with("200 frames, 0 unanswered (0 back unprocessed); round trip median "), "{out}");
    // An interface that is down: the system's reason, once.
    let st =
        std::process::Command::new("ip").args(["-n", &net.master_ns, "link", "set", &net.master_if, "down"]).status();
    assert!(st.unwrap().success());
    let o = VethPair::cmd(&net.master_ns, env!("CARGO_BIN_EXE_ferrocat"))
        .args(["run", "--iface", &net.master_if, "--seconds", "1"])
        .output()
        .unwrap();
    let err = String::from_utf8_lossy(&o.stderr);
    assert!(!o.status.success() && err.matches("Network is down").count() == 1, "{err}");
    // The real-time set-up in words, not Rust's.
    assert!(err.contains("real time: memory ") && !err.contains("Some(") && !err.contains("None"), "{err}");
}
