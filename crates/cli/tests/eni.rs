//! ENI files on the command line, on the embedded virtual segment: `ferrocat eni` shows one,
//! `run --eni` alone runs the machine it describes, and with another segment every kind of
//! difference stops the start-up with one error naming them all.
use std::path::PathBuf;
use std::process::Command;

fn lenient() -> PathBuf {
    PathBuf::from(env!("CARGO_MANIFEST_DIR")).join("../machine/tests/data/ferrocat_lenient.eni.xml")
}

fn ferrocat(args: &[&str]) -> (bool, String, String) {
    let o = Command::new(env!("CARGO_BIN_EXE_ferrocat")).args(args).output().unwrap();
    (
        o.status.success(),
        String::from_utf8_lossy(&o.stdout).into_owned(),
        String::from_utf8_lossy(&o.stderr).into_owned(),
    )
}

/// A segment file of the ENI's slaves in the order `slaves` gives (`None`: a built-in EL2004),
/// written for the test.
fn segment_of(tag: &str, eni: &std::path::Path, slaves: &[Option<usize>]) -> PathBuf {
    let mut toml = String::from("seed = 1\n");
    for s in slaves {
        match s {
            Some(k) => toml += &format!("[[device]]\neni = '{}'\neni_slave = {k}\n", eni.display()),
            None => toml += "[[device]]\nbuiltin = 'EL2004'\n",
        }
    }
    let path = std::env::temp_dir().join(format!("ferrocat-eni-{tag}-{}.toml", std::process::id()));
    std::fs::write(&path, toml).unwrap();
    path
}

#[test]
fn eni_shows_a_file_and_strict_refuses_departures() {
    let f = lenient();
    let (ok, out, err) = ferrocat(&["eni", f.to_str().unwrap()]);
    assert!(ok, "{err}");
    assert!(out.contains("master 'ferrocat test master', 3 slaves, 1 cyclic task"), "{out}");
    assert!(out.contains("Term 2 (EL2008)") && out.contains("Drive \u{b5}"), "{out}");
    assert!(out.contains("frame 0: LRW  0x01000000      13 B  working counter 5"), "{out}");
    assert_eq!(err.matches("warning: ").count(), 10, "{err}");
    assert!(err.contains("line 64, column") && err.contains("ProductCode: '0x7d83052' read as 131608658"), "{err}");
    let (ok, out, _) = ferrocat(&["eni", f.to_str().unwrap(), "--json"]);
    assert!(ok);
    let v: serde_json::Value = serde_json::from_str(&out).unwrap();
    assert_eq!(v["slaves"][2]["identity"]["vendor_id"], 0xA8F);
    assert_eq!(v["slaves"][1]["init_cmds"][2]["transitions"][0], "PI");
    assert_eq!(v["cyclic"][0]["frames"][0]["cmds"][0]["command"], "LRW");
    assert_eq!(v["warnings"].as_array().unwrap().len(), 10);
    let (ok, _, err) = ferrocat(&["eni", f.to_str().unwrap(), "--strict"]);
    assert!(!ok && err.contains("10 departures from ETG.2100") && err.contains("--strict"), "{err}");
    let (ok, _, err) = ferrocat(&["eni", "/nonexistent.xml"]);
    assert!(!ok && err.contains("reading /nonexistent.xml"), "{err}");
}

#[test]
fn run_with_an_eni_alone_runs_its_machine_on_the_virtual_segment() {
    let f = lenient();
    let (ok, out, err) = ferrocat(&["run", "--eni", f.to_str().unwrap(), "--seconds", "0.5", "--json"]);
    assert!(ok, "{err}");
    assert!(err.contains("network as") && err.contains("describes it: 3 slaves"), "{err}");
    let v: serde_json::Value = serde_json::from_str(&out).unwrap();
    assert_eq!(v["wkc_errors"], 0, "{v}");
    assert!(v["cycles"].as_u64().unwrap() >= 400, "{v}");
}

/// The master follows the ENI's layout: its FMMUs, its cyclic frames at their logical
/// addresses, and an image that mirrors the frames. A drive's controlword written at the
/// ENI's offset reaches that drive, and its statusword lands at the ENI's offset: 0x240
/// (switch on disabled) with the controlword 0, 0x231 (ready to switch on) with 6.
fn statuswords(eni: &std::path::Path, sets: &[&str], shows: &[&str], extra: &[&str]) -> serde_json::Value {
    let mut args = vec!["run", "--eni", eni.to_str().unwrap(), "--seconds", "0.3", "--json"];
    for s in sets {
        args.extend(["--set", s]);
    }
    for s in shows {
        args.extend(["--show", s]);
    }
    args.extend(extra);
    let (ok, out, err) = ferrocat(&args);
    assert!(ok, "{err}");
    let v: serde_json::Value = serde_json::from_str(&out).unwrap();
    assert_eq!(v["wkc_errors"], 0, "{v}");
    v["values"].clone()
}

#[test]
fn the_process_image_is_the_eni_s() {
    let f = lenient();
    // The file's CopyInfo copies the statusword's bit 0 (ready to switch on) into the EL2008's
    // first output after every cycle, whatever --set wrote there.
    for (cw, sw, copied) in [(0, 0x240, 0), (6, 0x231, 1)] {
        let set = format!("Drive \u{b5}.Outputs.Controlword={cw}");
        let el2008 = format!("Term 2 (EL2008).Channel 1.Output={}", 1 - copied);
        let v = statuswords(
            &f,
            &[&set, &el2008],
            &["Drive \u{b5}.Inputs.Statusword", "Term 2 (EL2008).Channel 1.Output"],
            &[],
        );
        assert_eq!(v["Drive \u{b5}.Inputs.Statusword"], sw, "{v}");
        assert_eq!(v["Term 2 (EL2008).Channel 1.Output"], copied, "{v}");
    }
    // Shown every second while it runs, too.
    let (ok, _, err) = ferrocat(&[
        "run",
        "--eni",
        f.to_str().unwrap(),
        "--seconds",
        "1.5",
        "--set",
        "Drive \u{b5}.Outputs.Controlword=6",
        "--show",
        "Drive \u{b5}.Inputs.Statusword",
    ]);
    assert!(ok && err.contains("          Drive \u{b5}.Inputs.Statusword = 561"), "{err}");
    // With clock synchronisation behind the ENI's frame.
    let v = statuswords(&f, &["Drive \u{b5}.Outputs.Controlword=6"], &["Drive \u{b5}.Inputs.Statusword"], &["--dc"]);
    assert_eq!(v["Drive \u{b5}.Inputs.Statusword"], 0x231, "{v}");
    // Names that are not the image's.
    let (ok, _, err) = ferrocat(&["run", "--eni", f.to_str().unwrap(), "--set", "Drive \u{b5}.Inputs.Statusword=1"]);
    assert!(!ok && err.contains("is an input: it cannot be set"), "{err}");
    let (ok, _, err) = ferrocat(&["run", "--eni", f.to_str().unwrap(), "--set", "nothing=1"]);
    assert!(!ok && err.contains("give POS:ENTRY"), "{err}");
    let (ok, _, err) = ferrocat(&["run", "--eni", f.to_str().unwrap(), "--set", "Term 2 (EL2008).Channel 1.Output=2"]);
    assert!(!ok && err.contains("2 does not fit 1 bits"), "{err}");
}

#[test]
fn needs_shared_each_drive_of_a_twincat_eni_at_its_own_offsets() {
    let f = ferrocat_testdata::shared("eni/test_eni.xml");
    let v = statuswords(
        &f,
        &["WheelRearLeft.Outputs.Control word=6", "WheelFrontRight.Outputs.Control word=6"],
        &[
            "WheelRearLeft.Inputs.Status word",
            "WheelRearRight.Inputs.Status word",
            "WheelFrontRight.Inputs.Status word",
        ],
        &[],
    );
    assert_eq!(v["WheelRearLeft.Inputs.Status word"], 0x231, "{v}");
    assert_eq!(v["WheelRearRight.Inputs.Status word"], 0x240, "{v}");
    assert_eq!(v["WheelFrontRight.Inputs.Status word"], 0x231, "{v}");
}

#[test]
fn needs_shared_both_twincat_enis_run_on_the_virtual_segment() {
    for name in ["mega_master_eni.xml", "test_eni.xml"] {
        let f = ferrocat_testdata::shared(&format!("eni/{name}"));
        let (ok, out, err) = ferrocat(&["run", "--eni", f.to_str().unwrap(), "--seconds", "0.5", "--json"]);
        assert!(ok, "{name}: {err}");
        let v: serde_json::Value = serde_json::from_str(&out).unwrap();
        assert_eq!(v["wkc_errors"], 0, "{name}: {v}");
    }
}

#[test]
fn every_kind_of_difference_from_the_eni_is_named_and_stops_the_start_up() {
    let f = lenient();
    let eni = f.to_str().unwrap();
    // The ENI's EK1100 with another revision, for the revision check.
    let older = std::env::temp_dir().join(format!("ferrocat-eni-older-{}.xml", std::process::id()));
    let text = std::fs::read(&f).unwrap();
    let text = String::from_utf8_lossy(&text).replacen(
        "<RevisionNo>1179648</RevisionNo>",
        "<RevisionNo>1114112</RevisionNo>",
        1,
    );
    std::fs::write(&older, text.replace("ISO-8859-1", "UTF-8")).unwrap();
    // (name, the segment's slaves by ENI position or a built-in EL2004, the ENI, what it says)
    type Case<'a> = (&'a str, &'a [Option<usize>], &'a str, &'a [&'a str]);
    let cases: &[Case] = &[
        ("same", &[Some(0), Some(1), Some(2)], eni, &[]),
        ("missing", &[Some(0), Some(2)], eni, &["position 1: 'Term 2 (EL2008)' (vendor 0x2 product 0x7d83052 revision 0x120000) missing"]),
        ("extra", &[Some(0), Some(1), Some(2), None], eni, &["position 3: 'EL2004' (vendor 0x2 product 0x7d43052 revision 0x100000) found, not expected"]),
        ("swapped", &[Some(0), Some(2), Some(1)], eni, &["positions 1 and 2 swapped: 'Term 2 (EL2008)"]),
        ("device", &[Some(0), None, Some(2)], eni, &["position 1: expected 'Term 2 (EL2008)' (vendor 0x2 product 0x7d83052 revision 0x120000), found 'EL2004'"]),
        ("revision", &[Some(0), Some(1), Some(2)], older.to_str().unwrap(), &["position 0: 'Term 1 (EK1100)' has revision 0x120000, expected 0x110000"]),
    ];
    for (tag, slaves, expected, want) in cases {
        let seg = segment_of(tag, &f, slaves);
        let (ok, _, err) = ferrocat(&["run", "--config", seg.to_str().unwrap(), "--eni", expected, "--seconds", "0.2"]);
        if want.is_empty() {
            assert!(ok, "{tag}: {err}");
        } else {
            assert!(!ok, "{tag}: ran");
            assert!(err.contains("the network differs from") && err.contains("nothing went past INIT"), "{tag}: {err}");
            for w in *want {
                assert!(err.contains(w), "{tag}: {w}\n{err}");
            }
            // --allow-mismatch: the same differences as a warning, and the run goes on.
            let (ok, _, err) =
                ferrocat(&["scan", "--config", seg.to_str().unwrap(), "--eni", expected, "--allow-mismatch"]);
            assert!(ok && err.contains("--allow-mismatch: going on") && err.contains(want[0]), "{tag}: {err}");
        }
        std::fs::remove_file(seg).ok();
    }
    std::fs::remove_file(older).ok();
}

/// An ENI's SoE init commands run with its machine: the drive takes them in PREOP and the
/// machine reaches OP; a value the drive refuses stops the start-up with an error naming the
/// command and the drive's reason.
#[test]
fn an_eni_s_soe_init_commands_go_to_its_drive() {
    let f = PathBuf::from(env!("CARGO_MANIFEST_DIR")).join("../machine/tests/data/ferrocat_soe.eni.xml");
    let (ok, out, err) = ferrocat(&["run", "--eni", f.to_str().unwrap(), "--seconds", "0.3", "--json"]);
    assert!(ok, "{err}");
    assert!(err.contains("IDN -1 does not fit SoE's 16 bits: left out"), "{err}");
    let v: serde_json::Value = serde_json::from_str(&out).unwrap();
    assert_eq!(v["wkc_errors"], 0, "{v}");
    // The gain above the drive's maximum (1000).
    let text = std::fs::read(&f).unwrap();
    let at = text.windows(13).position(|w| w == b"<Data>fa00</D").unwrap();
    let mut refused = text.clone();
    refused[at + 6..at + 10].copy_from_slice(b"e903");
    let path = std::env::temp_dir().join(format!("ferrocat-soe-refused-{}.eni.xml", std::process::id()));
    std::fs::write(&path, refused).unwrap();
    let (ok, _, err) = ferrocat(&["run", "--eni", path.to_str().unwrap(), "--seconds", "0.3"]);
    std::fs::remove_file(&path).unwrap();
    assert!(!ok, "{err}");
    assert!(
        err.contains(
            "slave 2 (Drive \u{b5}): plan IDN P-0-0001 drive 0 (Gain): SoE P-0-0001 (drive 0): SoE error 0x7007"
        ),
        "{err}"
    );
}
