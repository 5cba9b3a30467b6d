//! `ferrocat soe read|write|list` on the embedded virtual segment, against the simulated drive
//! of our `ferrocat_soe_drive.xml`: values shown as their attributes say, written back,
//! refused with the drive's words, and the IDN given as S-0-…/P-0-… or refused with what to
//! give.
use std::process::Command;

fn soe(args: &[&str]) -> (bool, String, String) {
    let esi = concat!(env!("CARGO_MANIFEST_DIR"), "/../esi/tests/data/ferrocat_soe_drive.xml");
    let out = Command::new(env!("CARGO_BIN_EXE_ferrocat"))
        .arg("soe")
        .args(args)
        .args(["--device", "EK1100", "--device", &format!("{esi}:FC-SOE-DRIVE")])
        .output()
        .unwrap();
    (
        out.status.success(),
        String::from_utf8_lossy(&out.stdout).into_owned(),
        String::from_utf8_lossy(&out.stderr).into_owned(),
    )
}

#[test]
fn an_idn_is_read_written_and_listed() {
    let (ok, out, err) = soe(&["read", "1", "S-0-0030"]);
    assert!(ok, "{err}");
    assert_eq!(out.trim(), "\"ferrocat SoE drive (ferrocat simulation)\"");
    let (ok, out, err) = soe(&["read", "1", "P-0-0001", "--element", "all"]);
    assert!(ok, "{err}");
    for line in ["P-0-0001  Gain", "unit      %", "min       0", "max       1000", "value     100"] {
        assert!(out.contains(line), "{line:?} in {out}");
    }
    let (ok, out, err) = soe(&["read", "1", "0x0010"]);
    assert!(ok && out.trim() == "S-0-0135, S-0-0051", "{out}{err}");
    // Written in one run (each run is a fresh segment): the drive took it.
    let (ok, _, err) = soe(&["write", "1", "P-0-0001", "250"]);
    assert!(ok && err.contains("wrote 2 byte(s) to P-0-0001"), "{err}");
    let (ok, out, err) = soe(&["list", "1"]);
    assert!(ok, "{err}");
    assert!(
        out.lines().any(|l| l.starts_with("S-0-0016  Configuration list of AT") && l.ends_with("S-0-0135, S-0-0051")),
        "{out}"
    );
    assert_eq!(out.lines().count(), 11, "{out}");
}

#[test]
fn the_drive_s_refusals_and_bad_idns_are_errors_that_say_so() {
    let (ok, _, err) = soe(&["write", "1", "P-0-0001", "1001"]);
    assert!(!ok && err.contains("SoE error 0x7007 (operation data is greater than the maximum)"), "{err}");
    let (ok, _, err) = soe(&["write", "1", "P-0-0001", "70000"]);
    assert!(!ok && err.contains("out of range for 2 bytes"), "{err}");
    let (ok, _, err) = soe(&["read", "1", "S-0-0999"]);
    assert!(!ok && err.contains("SoE error 0x1001 (no IDN)"), "{err}");
    let (ok, _, err) = soe(&["read", "1", "Q-0-0001"]);
    assert!(!ok && err.contains("IDN 'Q-0-0001': give S-SET-BLOCK or P-SET-BLOCK"), "{err}");
    let (ok, _, err) = soe(&["read", "1", "S-0-0001", "--element", "colour"]);
    assert!(!ok && err.contains("--element 'colour': give data-state, name, attribute"), "{err}");
    let (ok, _, err) = soe(&["read", "0", "S-0-0001"]);
    assert!(!ok && err.contains("slave 0 (EK1100): has no mailbox"), "{err}");
}

/// `ferrocat esi` lists a description's SoE init commands, and `ferrocat run --esi` sends them
/// at their transitions: the one on an IDN this drive lacks is left out with a warning naming
/// it, and the drive reaches OP.
#[test]
fn esi_soe_init_commands_are_listed_and_sent_by_run() {
    let esi = concat!(env!("CARGO_MANIFEST_DIR"), "/../esi/tests/data/ferrocat_soe_drive.xml");
    let out = Command::new(env!("CARGO_BIN_EXE_ferrocat"))
        .args(["esi", esi, "--device", "FC-SOE-DRIVE-INIT"])
        .output()
        .unwrap();
    let text = String::from_utf8_lossy(&out.stdout);
    assert!(out.status.success(), "{text}");
    for line in [
        "SoE IP S-0-0001 drive 0 ← f401 (value) \"NC cycle time\"",
        "SoE PS P-0-0001 drive 0 ← fa00 (value) \"Gain\"",
        "SoE SO P-0-0001 drive 0 ← 2c01 (value) \"Gain in OP\"",
    ] {
        assert!(text.contains(line), "{line:?} in {text}");
    }
    let out = Command::new(env!("CARGO_BIN_EXE_ferrocat"))
        .args(["run", "--seconds", "0.1", "--json", "--esi", esi, "--device", "EK1100"])
        .args(["--device", &format!("{esi}:FC-SOE-DRIVE-INIT")])
        .output()
        .unwrap();
    let err = String::from_utf8_lossy(&out.stderr);
    assert!(out.status.success(), "{err}");
    assert!(
        err.contains("ESI SoE init command PS S-0-0999 drive 0 (\"Brake delay (later revisions)\", line 83) not sent"),
        "{err}"
    );
    let v: serde_json::Value = serde_json::from_slice(&out.stdout).unwrap();
    assert_eq!((&v["slaves"]["in_op_at_end"], &v["slaves"]["left_op"]), (&2.into(), &0.into()), "{v}");
}

/// `ferrocat demo --drive` with a drive of the SoE profile, beside CoE or alone: refused at
/// once, saying that the demo drives CiA402 drives and that the SoE profile is not modelled.
#[test]
fn the_demo_says_it_does_not_drive_the_soe_profile() {
    let esi = concat!(env!("CARGO_MANIFEST_DIR"), "/../esi/tests/data/ferrocat_soe_drive.xml");
    for (device, speaks) in [("FC-SOE-DRIVE", "SoE beside CoE"), ("FC-SOE-ONLY", "SoE, not CoE")] {
        let out = Command::new(env!("CARGO_BIN_EXE_ferrocat"))
            .args(["demo", "--drive", &format!("{esi}:{device}"), "--cycle-us", "1000", "--method", "none"])
            .current_dir(std::env::temp_dir())
            .output()
            .unwrap();
        let err = String::from_utf8_lossy(&out.stderr);
        assert!(!out.status.success(), "{err}");
        assert!(err.contains(&format!("{device} is a drive of the SoE profile (its SII names {speaks}")), "{err}");
        assert!(err.contains("the demo drives CiA402 drives only"), "{err}");
    }
}

/// SoE notifications and emergencies a drive sends (scheduled `soe_message` events) reach the
/// user of `run` while cyclic, decoded and counted; an event the drive cannot send is refused
/// naming why.
#[test]
fn soe_notifications_and_emergencies_reach_the_user_while_cyclic() {
    let esi = concat!(env!("CARGO_MANIFEST_DIR"), "/../esi/tests/data/ferrocat_soe_drive.xml");
    let run = |tag: &str, events: &str| {
        let product = if tag == "alone" { "FC-SOE-ONLY" } else { "FC-SOE-DRIVE" };
        let toml =
            format!("[[device]]\nbuiltin = 'EK1100'\n[[device]]\nesi = '{esi}'\nproduct = '{product}'\n{events}");
        let path = std::env::temp_dir().join(format!("ferrocat-soe-events-{tag}-{}.toml", std::process::id()));
        std::fs::write(&path, toml).unwrap();
        let o = Command::new(env!("CARGO_BIN_EXE_ferrocat"))
            .args(["run", "--config", path.to_str().unwrap(), "--seconds", "1", "--json"])
            .output()
            .unwrap();
        std::fs::remove_file(&path).unwrap();
        (
            o.status.success(),
            String::from_utf8_lossy(&o.stdout).into_owned(),
            String::from_utf8_lossy(&o.stderr).into_owned(),
        )
    };
    let (ok, out, err) = run(
        "sent",
        "[[event]]\nat_ms = 300\nsoe_message = { device = 1, idn = 'S-0-0095', data = '4f7665722074656d70' }\n\
         [[event]]\nat_ms = 600\nsoe_message = { device = 1, drive = 0, idn = 11, data = '0100', emergency = true }\n",
    );
    assert!(ok, "{err}");
    assert!(err.contains("slave 1 (FC-SOE-DRIVE) drive 0: SoE notification for S-0-0095: \"Over temp\""), "{err}");
    assert!(err.contains("slave 1 (FC-SOE-DRIVE) drive 0: SoE emergency for S-0-0011: [01, 00]"), "{err}");
    let v: serde_json::Value = serde_json::from_str(&out).unwrap();
    assert_eq!(v["diagnosis"]["soe_messages"], 2, "{v}");
    // A drive that speaks SoE alone is polled too (CoE emergencies are not all there is).
    let (ok, _, err) =
        run("alone", "[[event]]\nat_ms = 300\nsoe_message = { device = 1, idn = 'S-0-0095', data = '4f4b' }\n");
    assert!(ok, "{err}");
    assert!(err.contains("slave 1 (FC-SOE-ONLY) drive 0: SoE notification for S-0-0095: \"OK\""), "{err}");
    let long = format!("device = 1, idn = 1, data = '{}'", "00".repeat(31));
    for (tag, event, says) in [
        ("nosoe", "device = 0, idn = 'S-0-0095'", "device 0 ('EK1100') speaks no SoE"),
        ("long", long.as_str(), "31 bytes, more than the device's mailbox carries (30)"),
        ("idn", "device = 1, idn = 'Q-0-0001'", "soe_message.idn 'Q-0-0001'"),
        ("data", "device = 1, idn = 1, data = 'abc'", "soe_message.data 'abc': not hex bytes"),
        ("drive", "device = 1, idn = 1, drive = 8", "soe_message.drive 8"),
    ] {
        let (ok, _, err) = run(tag, &format!("[[event]]\nat_ms = 1\nsoe_message = {{ {event} }}\n"));
        assert!(!ok && err.contains(says), "{tag}: {err}");
    }
}
