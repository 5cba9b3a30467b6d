//! `ferrocat soe` on a raw interface against `ferrocat sim` over a veth pair, serving our SoE
//! drive (`ferrocat_soe_drive.xml`, a 40-byte mailbox): an IDN read in fragments, a value
//! written and read back within one run of the simulator, and a refusal by code.
mod common;

use common::{Sim, VethPair};

#[test]
fn soe_reads_and_writes_a_simulated_drive_s_idns_over_a_real_socket() {
    let net = VethPair::new("so");
    let esi = concat!(env!("CARGO_MANIFEST_DIR"), "/../esi/tests/data/ferrocat_soe_drive.xml");
    let device = format!("{esi}:FC-SOE-DRIVE");
    let sim = Sim::start(&net, &["--device", "EK1100", "--device", &device]);
    let soe = |args: &[&str]| {
        let out = VethPair::cmd(&net.master_ns, env!("CARGO_BIN_EXE_ferrocat"))
            .arg("soe")
            .args(args)
            .args(["--iface", &net.master_if, "--force"])
            .env("FERROCAT_RUN_DIR", std::env::temp_dir())
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
    sim.stop();
}
