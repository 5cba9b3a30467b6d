//! ferrocat's own machine description on the command line, on the embedded virtual segment:
//! written from a scan, edited, run alone, and checked against other segments.
use std::path::PathBuf;
use std::process::Command;

fn ferrocat(args: &[&str]) -> (bool, String, String) {
    let o = Command::new(env!("CARGO_BIN_EXE_ferrocat")).args(args).output().unwrap();
    (
        o.status.success(),
        String::from_utf8_lossy(&o.stdout).into_owned(),
        String::from_utf8_lossy(&o.stderr).into_owned(),
    )
}

fn temp(tag: &str) -> PathBuf {
    let p = std::env::temp_dir().join(format!("ferrocat-machine-{tag}-{}.toml", std::process::id()));
    std::fs::remove_file(&p).ok();
    p
}

#[test]
fn scan_writes_a_description_that_runs_once_it_names_its_devices() {
    let path = temp("scan");
    let p = path.to_str().unwrap();
    let line = ["--device", "EK1100", "--device", "EL2004", "--device", "EL1004"];
    let (ok, _, err) = ferrocat(&[&["scan", "--write-machine", p][..], &line].concat());
    assert!(ok && err.contains("(3 slaves): edit it"), "{err}");
    let text = std::fs::read_to_string(&path).unwrap();
    assert_eq!(text.matches("[[slave]]").count(), 3, "{text}");
    assert!(text.contains("name = \"EL2004\"\nvendor = 0x2\nproduct = 0x07d43052\nrevision = 0x00100000"), "{text}");
    // Never over an existing file: it may hold the user's edits.
    let (ok, _, err) = ferrocat(&[&["scan", "--write-machine", p][..], &line].concat());
    assert!(!ok && err.contains("exists: a machine description is not overwritten"), "{err}");
    // As written it describes the network, but names nothing to simulate.
    let (ok, _, err) = ferrocat(&[&["scan", "--machine", p][..], &line].concat());
    assert!(ok && err.contains("describes it: 3 slaves"), "{err}");
    let (ok, _, err) = ferrocat(&["run", "--machine", p, "--seconds", "0.2"]);
    assert!(!ok && err.contains("slave 0 ('EK1100') has no `device = …` to simulate"), "{err}");
    // Named by the user, each with its device: the description alone runs.
    let edited = text
        .replacen("name = \"EK1100\"\n", "name = \"coupler\"\ndevice = \"EK1100\"\n", 1)
        .replacen("name = \"EL2004\"\n", "name = \"lamps\"\ndevice = \"EL2004\"\n", 1)
        .replacen("name = \"EL1004\"\n", "name = \"buttons\"\ndevice = \"EL1004\"\n", 1);
    std::fs::write(&path, &edited).unwrap();
    let (ok, out, err) = ferrocat(&["run", "--machine", p, "--seconds", "0.3", "--json"]);
    assert!(ok, "{err}");
    let v: serde_json::Value = serde_json::from_str(&out).unwrap();
    assert_eq!(v["wkc_errors"], 0, "{v}");
    // Another network: the user's names in the error.
    let other = ["--device", "EK1100", "--device", "EL1004", "--device", "EL1004"];
    let (ok, _, err) = ferrocat(&[&["run", "--machine", p, "--seconds", "0.2"][..], &other].concat());
    assert!(!ok && err.contains("position 1: expected 'lamps'") && err.contains("found 'EL1004'"), "{err}");
    let (ok, _, err) =
        ferrocat(&["run", "--machine", p, "--device", "EK1100", "--device", "EL1004", "--seconds", "0.2"]);
    assert!(!ok && err.contains("position 1: 'lamps'") && err.contains("missing"), "{err}");
    std::fs::remove_file(&path).ok();
}

#[test]
fn revision_ranges_optional_slaves_and_bad_files() {
    let path = temp("rules");
    let p = path.to_str().unwrap();
    std::fs::write(
        &path,
        "name = \"rules\"\n[[slave]]\nvendor = 2\nproduct = 0x044C2C52\nrevision = \"any\"\n\
         [[slave]]\nname = \"lamps\"\nvendor = 2\nproduct = 0x07D43052\nrevision_min = 0x100000\nrevision_max = 0x100000\n\
         [[slave]]\nname = \"spare\"\nvendor = 2\nproduct = 0x03EC3052\noptional = true\n",
    )
    .unwrap();
    let (ok, _, err) = ferrocat(&["scan", "--machine", p, "--device", "EK1100", "--device", "EL2004"]);
    assert!(ok, "the optional slave may be absent: {err}");
    let (ok, _, err) =
        ferrocat(&["scan", "--machine", p, "--device", "EK1100", "--device", "EL2004", "--device", "EL2004"]);
    assert!(!ok && err.contains("position 2: expected 'spare'"), "{err}");
    std::fs::write(&path, "[[slave]]\nvendor = 2\nproduct = 3\nrevisoin = 1\n").unwrap();
    let (ok, _, err) = ferrocat(&["scan", "--machine", p, "--device", "EK1100"]);
    assert!(
        !ok && err.contains(p) && err.contains("line 4, column 1") && err.contains("unknown field `revisoin`"),
        "{err}"
    );
    let (ok, _, err) = ferrocat(&["scan", "--device", "EK1100", "--allow-mismatch"]);
    assert!(!ok && err.contains("--allow-mismatch goes with --eni or --machine"), "{err}");
    std::fs::remove_file(&path).ok();
}

#[test]
fn groups_of_a_description_run_at_their_own_rates() {
    let path = temp("groups");
    std::fs::write(
        &path,
        "[[slave]]\nname = \"coupler\"\nvendor = 2\nproduct = 0x044C2C52\ndevice = \"EK1100\"\n\
         [[slave]]\nname = \"lamps\"\nvendor = 2\nproduct = 0x07D43052\ndevice = \"EL2004\"\n\
         [[slave]]\nname = \"buttons\"\nvendor = 2\nproduct = 0x03EC3052\ndevice = \"EL1004\"\n\
         [[slave]]\nname = \"axis\"\nvendor = 0\nproduct = 0x402\ndevice = \"SERVO\"\n\
         [[group]]\nname = \"io\"\nslaves = [\"lamps\", \"buttons\"]\nevery = 4\n\
         [[group]]\nname = \"motion\"\nslaves = [\"axis\"]\n\
         [[copy]]\nfrom = \"buttons:Input\"\nto = \"lamps:Output\"\n",
    )
    .unwrap();
    let p = path.to_str().unwrap();
    // The copy from the buttons (0 in the simulator) overwrites what --set wrote to the lamps.
    let (ok, out, err) = ferrocat(&[
        "run",
        "--machine",
        p,
        "--seconds",
        "1",
        "--dc",
        "--json",
        "--set",
        "1:Output=1",
        "--show",
        "1:Output",
    ]);
    assert!(ok, "{err}");
    let v: serde_json::Value = serde_json::from_str(&out).unwrap();
    let groups = v["groups"].as_array().unwrap();
    let names: Vec<&str> = groups.iter().map(|g| g["name"].as_str().unwrap()).collect();
    assert_eq!(names, ["motion", "io"], "the fastest first: {v}");
    let (motion, io) = (&groups[0], &groups[1]);
    assert_eq!((motion["every"].as_u64(), io["every"].as_u64()), (Some(1), Some(4)));
    let (m, i) = (motion["sent"].as_u64().unwrap(), io["sent"].as_u64().unwrap());
    assert!(m >= 1000 && i * 4 >= m - 4 && i * 4 <= m + 4, "{v}");
    assert!(groups.iter().all(|g| g["short"] == 0 && g["lost"] == 0), "{v}");
    assert_eq!((motion["expected_wkc"].as_u64(), io["expected_wkc"].as_u64()), (Some(3), Some(3)));
    assert_eq!(v["clock_sync"]["lock"], "locked", "{v}");
    assert!(err.contains("1 slave-to-slave copy after every cycle"), "{err}");
    assert_eq!(v["values"]["1:Output"], 0, "{v}");
    std::fs::remove_file(&path).ok();
}

#[test]
fn a_description_sets_a_slaves_process_data_watchdog() {
    let path = temp("watchdog");
    let p = path.to_str().unwrap();
    let servo = "[[slave]]\nname = \"coupler\"\nvendor = 2\nproduct = 0x044c2c52\ndevice = \"EK1100\"\n\
                 [[slave]]\nname = \"board\"\nvendor = 9\nproduct = 0x9252\ndevice = \"LAN9252-EVB\"\n";
    let run = |watchdog: &str| {
        std::fs::write(&path, format!("{servo}{watchdog}")).unwrap();
        ferrocat(&["run", "--machine", p, "--seconds", "0.3", "--cycle-us", "1000", "--json"])
    };
    // The ESC's default (100 ms): 1 ms cycles never let it expire.
    let (ok, out, err) = run("");
    assert!(ok, "{err}");
    let v: serde_json::Value = serde_json::from_str(&out).unwrap();
    assert_eq!(v["slaves"]["left_op"], 0, "{v}");
    // 100 µs, shorter than the 1 ms between the bring-up's frames: the board's watchdog (its
    // output SM triggers it) expires before OP, and the board says so.
    let (ok, _, err) = run("watchdog_us = 100\n");
    assert!(!ok && err.contains("slave 1 (LAN9252-EVB-HBI) did not reach OP") && err.contains("0x001b"), "{err}");
    // Not a multiple of 100 µs: refused at its line.
    std::fs::write(&path, format!("{servo}watchdog_us = 150\n")).unwrap();
    let (ok, _, err) = ferrocat(&["run", "--machine", p, "--seconds", "0.2"]);
    assert!(!ok && err.contains("line 11") && err.contains("in steps of 100"), "{err}");
    std::fs::remove_file(&path).ok();
}

#[test]
fn a_description_assigns_a_slaves_pdos() {
    let path = temp("pdos");
    let p = path.to_str().unwrap();
    let servo = "[[slave]]\nname = \"axis\"\nvendor = 0\nproduct = 0x402\ndevice = \"SERVO\"\n";
    let show = |assignment: &str| {
        std::fs::write(&path, format!("{servo}{assignment}")).unwrap();
        ferrocat(&["run", "--machine", p, "--seconds", "0.1", "--show", "0:Statusword", "--json"])
    };
    // The drive's own assignment (0x1A00) maps its statusword; so does naming it.
    for own in ["", "tx_pdos = [0x1A00]\n"] {
        let (ok, out, err) = show(own);
        assert!(ok, "{own}: {err}");
        let v: serde_json::Value = serde_json::from_str(&out).unwrap();
        assert!(v["values"]["0:Statusword"].is_number(), "{v}");
        assert_eq!(v["wkc_errors"], 0, "{v}");
    }
    // No TxPDO assigned: no inputs, and no statusword to show.
    let (ok, _, err) = show("tx_pdos = []\n");
    assert!(!ok && err.contains("Statusword"), "{err}");
    // A PDO the drive does not have: its abort, naming the description's slave and key.
    let (ok, _, err) = show("rx_pdos = [0x1601]\n");
    assert!(!ok && err.contains("slave 0 (axis)'s rx_pdos") && err.contains("0x06020000"), "{err}");
    std::fs::remove_file(&path).ok();
}

#[test]
fn a_description_sends_init_commands_and_names_variables() {
    let path = temp("init");
    let p = path.to_str().unwrap();
    let servo = "[[slave]]\nname = \"axis\"\nvendor = 0\nproduct = 0x402\ndevice = \"SERVO\"\n";
    let run = |rest: &str, extra: &[&str]| {
        std::fs::write(&path, format!("{servo}{rest}")).unwrap();
        ferrocat(&[&["run", "--machine", p, "--seconds", "0.1", "--json"][..], extra].concat())
    };
    // Variables by name, and a slave's entry by the slave's name in the description.
    let vars = "[[variable]]\nname = \"status\"\nentry = \"axis:Statusword\"\n\
                [[variable]]\nname = \"mode\"\nentry = \"0:Modes of operation\"\n";
    let (ok, out, err) = run(vars, &["--show", "status", "--show", "axis:Statusword", "--set", "mode=8"]);
    assert!(ok, "{err}");
    let v: serde_json::Value = serde_json::from_str(&out).unwrap();
    assert!(v["values"]["status"].is_number() && v["values"]["status"] == v["values"]["axis:Statusword"], "{v}");
    // A PS init command runs before the mapping is read: no TxPDO assigned, no statusword.
    let none = "[[slave.init]]\ntransition = \"PS\"\nindex = 0x1C13\nsubindex = 0\nvalue = 0\ntype = \"u8\"\n";
    let (ok, _, err) = run(none, &["--show", "0:Statusword"]);
    assert!(!ok && err.contains("Statusword"), "{err}");
    // An object the drive lacks: its abort, with the command's line.
    let bad = "[[slave.init]]\ntransition = \"PS\"\nindex = 0x2345\ndata = \"01\"\ncomment = \"gear\"\n";
    let (ok, _, err) = run(bad, &[]);
    assert!(
        !ok && err.contains("init command PS 0x2345:0x00 (\"gear\", line 8)") && err.contains("0x06020000"),
        "{err}"
    );
    // A variable naming no entry of its slave: said before OP, with the file.
    let (ok, _, err) = run("[[variable]]\nname = \"x\"\nentry = \"axis:Nothing\"\n", &[]);
    assert!(!ok && err.contains("[[variable]] 'x'") && err.contains(p), "{err}");
    std::fs::remove_file(&path).ok();
}

#[test]
fn a_description_sets_up_distributed_clocks() {
    let path = temp("dc");
    let p = path.to_str().unwrap();
    let pcap = std::env::temp_dir().join(format!("ferrocat-machine-dc-{}.pcapng", std::process::id()));
    let line = "[[slave]]\nname = \"coupler\"\nvendor = 2\nproduct = 0x044c2c52\ndevice = \"EK1100\"\n\
                [[slave]]\nname = \"lamps\"\nvendor = 2\nproduct = 0x07d43052\ndevice = \"EL2004\"\n\
                [[slave]]\nname = \"axis\"\nvendor = 0\nproduct = 0x402\ndevice = \"SERVO\"\n";
    let run = |rest: &str, extra: &[&str]| {
        std::fs::write(&path, format!("{line}{rest}")).unwrap();
        ferrocat(&[&["run", "--machine", p, "--seconds", "0.2", "--json"][..], extra].concat())
    };
    // [dc] alone turns DC on, with its method and SYNC1 (0x09A4, ns) on the SII's SYNC0 slave.
    let (ok, out, err) = run("[dc]\nsync = \"pi\"\nsync1_us = 20\n", &["--pcap", pcap.to_str().unwrap()]);
    assert!(ok && err.contains("SYNC0 on slave 2"), "{err}");
    let v: serde_json::Value = serde_json::from_str(&out).unwrap();
    assert_eq!(v["clock_sync"]["method"], "pi", "{v}");
    let (ok, dump, _) = ferrocat(&["pcap", pcap.to_str().unwrap(), "--json"]);
    std::fs::remove_file(&pcap).ok();
    assert!(ok && dump.lines().any(|l| l.contains("\"ado\":2468") && l.contains("\"data\":\"204e0000\"")), "no SYNC1");
    // The axis's own assign-activate word (cyclic operation and SYNC0: 0x03 into 0x0981 where
    // the master, SYNC1 asked for, would write 0x07; its low byte into 0x0980 after the stop's
    // 0), and the method's settings from [dc]: its probe budget, the static frames.
    let (ok, out, err) = run(
        "assign_activate = 0x0300\n[dc]\nsync1_us = 20\nprobe_budget_us = 7\nstatic_frames = 300\n",
        &["--pcap", pcap.to_str().unwrap()],
    );
    assert!(ok && err.contains("SYNC0 on slave 2") && err.contains("static drift compensation 300 frames"), "{err}");
    let v: serde_json::Value = serde_json::from_str(&out).unwrap();
    assert_eq!(v["clock_sync"]["probe_budget_us"], 7.0, "{v}");
    let (ok, dump, _) = ferrocat(&["pcap", pcap.to_str().unwrap(), "--json"]);
    std::fs::remove_file(&pcap).ok();
    let writes = |ado: u32, data: &str| {
        dump.lines()
            .filter(|l| {
                l.contains("FPWR")
                    && l.contains(&format!("\"ado\":{ado}"))
                    && l.contains(&format!("\"data\":\"{data}\""))
                    && l.contains("\"wkc\":1")
            })
            .count()
    };
    assert!(ok && writes(0x0981, "03") == 1 && writes(0x0981, "07") == 0, "0x0981 ← 0x03 once, never 0x07");
    assert_eq!(writes(0x0980, "00"), 2, "0x0980: the stop's 0, then the word's low byte");
    // A slave's sync0 = false over its SII; a flag over the description's method.
    let (ok, out, err) = run("sync0 = false\n[dc]\nsync = \"pi\"\n", &["--sync", "ferrocat"]);
    assert!(ok && err.contains("SYNC0 on no slave"), "{err}");
    let v: serde_json::Value = serde_json::from_str(&out).unwrap();
    assert_eq!(v["clock_sync"]["method"], "ferrocat", "{v}");
    // A method the master does not have, named with the file; a DC flag without DC.
    let (ok, _, err) = run("[dc]\nsync = \"magic\"\n", &[]);
    assert!(!ok && err.contains("[dc] sync = 'magic': not a method") && err.contains(p), "{err}");
    let (ok, _, err) = run("", &["--sync0-shift-us", "100"]);
    assert!(!ok && err.contains("--sync0-shift-us goes with --dc (or a machine description's [dc])"), "{err}");
    std::fs::remove_file(&path).ok();
}

#[test]
fn a_description_configures_and_checks_a_modular_devices_modules() {
    let path = temp("modules");
    let p = path.to_str().unwrap();
    let esi = concat!(env!("CARGO_MANIFEST_DIR"), "/../esi/tests/data/ferrocat_modular.xml");
    let run = |device: &str, modules: &str| {
        let text = format!(
            "[[slave]]\nname = \"drive\"\nvendor = 0xf3c\nproduct = 0x00010002\ndevice = \"{device}\"\nmodules = {modules}\n"
        );
        std::fs::write(&path, text).unwrap();
        ferrocat(&["run", "--machine", p, "--seconds", "0.1", "--show", "drive:Target velocity", "--json"])
    };
    // Plugged as described, configured and checked: axis 1 in velocity mode, its entry there.
    let (ok, out, err) = run(&format!("{esi}:#x00010002"), "[0x9010, 0x9020]");
    assert!(ok, "{err}");
    let v: serde_json::Value = serde_json::from_str(&out).unwrap();
    assert!(v["values"]["drive:Target velocity"].is_number() && v["wkc_errors"] == 0, "{v}");
    // The device carries other modules than described: the slot and both modules named.
    let (ok, _, err) = run(&format!("{esi}:#x00010002:0x9010,0x9010"), "[0x9010, 0x9020]");
    assert!(!ok && err.contains("slot 1: module 0x00009020 configured, 0x00009010 detected"), "{err}");
    std::fs::remove_file(&path).ok();
}

/// docs/machine.md's example description runs as the page says: DC on, the variable shown.
#[test]
fn the_documented_example_runs() {
    let page = std::fs::read_to_string(concat!(env!("CARGO_MANIFEST_DIR"), "/../../docs/machine.md")).unwrap();
    let after = page.split("A description after step 2").nth(1).expect("the example's heading");
    let toml = after.split("```toml\n").nth(1).and_then(|t| t.split("```").next()).expect("its TOML");
    let path = temp("documented");
    std::fs::write(&path, toml).unwrap();
    let (ok, out, err) =
        ferrocat(&["run", "--machine", path.to_str().unwrap(), "--show", "axis_status", "--seconds", "0.3", "--json"]);
    std::fs::remove_file(&path).ok();
    assert!(ok && err.contains("SYNC0 on slave 1"), "{err}");
    let v: serde_json::Value = serde_json::from_str(&out).unwrap();
    assert!(v["values"]["axis_status"].is_number() && v["clock_sync"]["method"] == "ferrocat", "{v}");
}
