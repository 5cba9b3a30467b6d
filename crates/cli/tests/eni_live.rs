//! An ENI's machine over a veth pair: `ferrocat sim --eni` serves the slaves the file
//! describes, and `ferrocat run --eni` checks them against the same file and runs them in OP
//! with every working counter whole (root).
mod common;

use std::path::PathBuf;

use common::{Sim, VethPair};

fn run_against_its_own_simulation(tag: &str, eni: &std::path::Path) {
    let net = VethPair::new(tag);
    let sim = Sim::start(&net, &["--eni", eni.to_str().unwrap()]);
    let o = VethPair::cmd(&net.master_ns, env!("CARGO_BIN_EXE_ferrocat"))
        .args(["run", "--iface", &net.master_if, "--eni", eni.to_str().unwrap(), "--seconds", "1", "--json"])
        .output()
        .unwrap();
    sim.stop();
    let (out, err) = (String::from_utf8_lossy(&o.stdout), String::from_utf8_lossy(&o.stderr));
    assert!(o.status.success(), "{}: {err}", eni.display());
    assert!(err.contains("describes it"), "{err}");
    let v: serde_json::Value = serde_json::from_str(&out).unwrap();
    let slaves = &v["slaves"];
    assert_eq!(slaves["in_op_at_end"], slaves["count"], "{v}");
    // Frames a loaded host loses count as short cycles; none came back short. `frames_lost`
    // also counts diagnosis's datagrams given up at their deadline, which are no cycle's.
    assert!(v["wkc_errors"].as_u64() <= v["frames_lost"].as_u64(), "{v}");
    println!("{}: {v}", eni.display());
}

#[test]
fn the_project_s_eni_runs_against_its_simulation() {
    let f = PathBuf::from(env!("CARGO_MANIFEST_DIR")).join("../machine/tests/data/ferrocat_lenient.eni.xml");
    run_against_its_own_simulation("en", &f);
}

#[test]
fn needs_shared_twincat_enis_run_against_their_simulation() {
    for (k, name) in ["mega_master_eni.xml", "test_eni.xml"].iter().enumerate() {
        run_against_its_own_simulation(&format!("e{k}"), &ferrocat_testdata::shared(&format!("eni/{name}")));
    }
}

#[test]
fn a_machine_description_runs_against_its_simulation() {
    let net = VethPair::new("md");
    let path = std::env::temp_dir().join(format!("ferrocat-machine-live-{}.toml", std::process::id()));
    std::fs::write(
        &path,
        "[[slave]]\nname = \"coupler\"\nvendor = 2\nproduct = 0x044C2C52\nrevision = 0x120000\ndevice = \"EK1100\"\n\
         [[slave]]\nname = \"axis\"\nvendor = 0\nproduct = 0x402\nrevision = \"any\"\ndevice = \"SERVO\"\n",
    )
    .unwrap();
    let p = path.to_str().unwrap();
    let sim = Sim::start(&net, &["--machine", p]);
    let o = VethPair::cmd(&net.master_ns, env!("CARGO_BIN_EXE_ferrocat"))
        .args(["run", "--iface", &net.master_if, "--machine", p, "--seconds", "1", "--json"])
        .output()
        .unwrap();
    sim.stop();
    std::fs::remove_file(&path).ok();
    let (out, err) = (String::from_utf8_lossy(&o.stdout), String::from_utf8_lossy(&o.stderr));
    assert!(o.status.success() && err.contains("describes it: 2 slaves"), "{err}");
    let v: serde_json::Value = serde_json::from_str(&out).unwrap();
    assert_eq!(v["slaves"]["in_op_at_end"], 2, "{v}");
    assert!(v["wkc_errors"].as_u64() <= v["frames_lost"].as_u64(), "{v}");
}
