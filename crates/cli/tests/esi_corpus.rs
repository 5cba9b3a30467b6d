//! Files of the ESI corpus (`../shared/esi-corpus/`) that the reader refused: two declared
//! ISO-8859-1 ("not UTF-8 text"), one with passive end terminals ("<Type> lacks
//! ProductCode"), and IgH's `ethercat xml` dump (root <EtherCATInfoList>).
use std::process::Command;

fn esi(file: &str, args: &[&str]) -> (bool, String, String) {
    let path = ferrocat_testdata::shared(&format!("esi-corpus/{file}"));
    let out = Command::new(env!("CARGO_BIN_EXE_ferrocat")).arg("esi").arg(&path).args(args).output().unwrap();
    (out.status.success(), String::from_utf8_lossy(&out.stdout).into(), String::from_utf8_lossy(&out.stderr).into())
}

#[test]
fn needs_shared_the_files_once_refused_are_read() {
    for (file, device) in [("Beckhoff EJ6xxx.xml", "EJ6002"), ("Beckhoff EKx9xx.xml", "EK1960-0000")] {
        let (ok, out, err) = esi(file, &[]);
        assert!(ok && out.contains(device) && out.contains("Beckhoff"), "{file}: {err}");
    }
    let (ok, out, err) = esi("Beckhoff EL9xxx.xml", &["--json"]);
    assert!(ok, "{err}");
    let v: serde_json::Value = serde_json::from_str(&out).unwrap();
    let passive: Vec<&str> = v["passive"].as_array().unwrap().iter().filter_map(|p| p["type"].as_str()).collect();
    assert!(passive.contains(&"EL9010") && passive.contains(&"EL9011"), "{v}");
    assert!(v["devices"].as_array().unwrap().iter().any(|d| d["type"] == "EL9110"), "the terminals with an ESC: {v}");
    let (ok, _, err) = esi("Beckhoff EL9xxx.xml", &["--device", "EL9010"]);
    assert!(!ok && err.contains("EL9010 (line 18) is a passive device"), "{err}");
    let (ok, out, err) = esi("topology.xml", &["--json"]);
    assert!(ok, "{err}");
    let v: serde_json::Value = serde_json::from_str(&out).unwrap();
    assert_eq!((v["vendor_id"].as_u64(), v["devices"].as_array().map(Vec::len)), (Some(0x22D2), Some(2)), "{v}");
}

/// The types that do not reach OP, each with the reason docs/esi-corpus.md names (none now:
/// the list stays, so that a failure found later is named here with its reason).
const KNOWN: [(&str, &str, &str); 0] = [];

/// The types whose files give them no process data by default, so that they reach OP with an
/// empty image (docs/esi-corpus.md): no PDO at all (the EL67xx fieldbus masters, whose image is
/// their fieldbus's configuration; the AX5805 option card, whose slots' modules carry none),
/// PDOs none of which is assigned (the EJ6002: the master may assign them), or PDOs of 0 bits
/// (EasyCAT's configurable type).
const NO_PROCESS_DATA: [(&str, &str); 13] = [
    ("Beckhoff EJ6xxx.xml", "EJ6002"),
    ("Beckhoff EL67xx.xml", "EL6720"),
    ("Beckhoff EL67xx.xml", "EL6731"),
    ("Beckhoff EL67xx.xml", "EL6731-0100"),
    ("Beckhoff EL67xx.xml", "EL6731-0010"),
    ("Beckhoff EL67xx.xml", "EL6731-1003"),
    ("Beckhoff EL67xx.xml", "EL6751"),
    ("Beckhoff EL67xx.xml", "EL6751-0005"),
    ("Beckhoff EL67xx.xml", "EL6751-0010"),
    ("Beckhoff EL67xx.xml", "EL6752"),
    ("Beckhoff EL67xx.xml", "EL6752-0010"),
    ("Beckhoff ELx9xx.xml", "AX5805"),
    ("EasyCAT_V2_0.xml", "EasyCAT configurable rev 1"),
];

/// `ferrocat run --dc` of an EK1100 and `devices` on the embedded segment: whether every slave
/// was in OP at the end with every working counter whole and the image not empty, and what it
/// said.
fn run_to_op(path: &std::path::Path, devices: &[&str]) -> (bool, String) {
    run_to_op_with(path, devices, true)
}

/// As [`run_to_op`]; `with_data` false asks for an empty image instead.
fn run_to_op_with(path: &std::path::Path, devices: &[&str], with_data: bool) -> (bool, String) {
    let mut cmd = Command::new(env!("CARGO_BIN_EXE_ferrocat"));
    cmd.args(["run", "--device", "EK1100", "--dc", "--seconds", "0.2", "--json", "--no-control"]);
    for d in devices {
        cmd.arg("--device").arg(format!("{}:{d}", path.display()));
    }
    let out = cmd.output().unwrap();
    let err = String::from_utf8_lossy(&out.stderr).into_owned();
    let Ok(v) = serde_json::from_slice::<serde_json::Value>(&out.stdout) else { return (false, err) };
    let s = &v["slaves"];
    // With process data: the image holds the devices' outputs or inputs (the EK1100 has none).
    let image = &v["image_bytes"];
    let good = out.status.success()
        && s["count"].as_u64() == Some(devices.len() as u64 + 1)
        && s["in_op_at_end"] == s["count"]
        && v["wkc_errors"] == 0
        && (image["outputs"].as_u64().unwrap_or(0) + image["inputs"].as_u64().unwrap_or(0) > 0) == with_data;
    (good, format!("{v}\n{err}"))
}

/// Every device type of every corpus file, as a new user tries it: read (`esi --json`), then
/// the file's types on one segment behind an EK1100, brought to OP with DC and process data
/// (each file read once: the segment parses an ESI once for all its devices). A file with a
/// known failure, or whose types do not come up together, is run type by type, and each known
/// one must fail as named.
#[test]
fn needs_shared_every_corpus_device_reaches_op() {
    let files = ferrocat_testdata::shared_files("esi-corpus", ".xml");
    assert!(!files.is_empty(), "no ESI file in the corpus");
    let (mut types, mut reached, mut passive, mut without_data) = (0usize, 0usize, 0usize, 0usize);
    for path in &files {
        let name = path.file_name().unwrap().to_string_lossy().into_owned();
        let (ok, out, err) = esi(&name, &["--json"]);
        assert!(ok, "{name} is refused: {err}");
        let v: serde_json::Value = serde_json::from_str(&out).unwrap();
        passive += v["passive"].as_array().map_or(0, Vec::len);
        let mut list: Vec<String> = Vec::new();
        for d in v["devices"].as_array().unwrap() {
            let t = match d["type"].as_str() {
                Some(t) if !t.is_empty() => t.to_string(),
                _ => format!("#x{:x}", d["product_code"].as_u64().unwrap()),
            };
            if !list.contains(&t) {
                list.push(t);
            }
        }
        types += list.len();
        let known: Vec<_> = KNOWN.iter().filter(|k| k.0 == name).collect();
        let empty: Vec<&str> = NO_PROCESS_DATA.iter().filter(|k| k.0 == name).map(|k| k.1).collect();
        if known.is_empty() && empty.is_empty() {
            // All the file's types on one segment; where that does not come up (a device
            // with one port cannot have another behind it), each behind its own coupler.
            let all: Vec<&str> = list.iter().map(String::as_str).collect();
            if run_to_op(path, &all).0 {
                reached += list.len();
                continue;
            }
        }
        for t in &list {
            if empty.contains(&t.as_str()) {
                let (good, said) = run_to_op_with(path, &[t], false);
                assert!(good, "{name}: {t} was to reach OP with no process data: {said}");
                (reached, without_data) = (reached + 1, without_data + 1);
                continue;
            }
            let (good, said) = run_to_op(path, &[t]);
            match known.iter().find(|k| k.1 == t) {
                Some(k) => assert!(!good && said.contains(k.2), "{name}: {t} was to fail with {}: {said}", k.2),
                None => {
                    assert!(good, "{name}: {t}: {said}");
                    reached += 1;
                }
            }
        }
    }
    println!(
        "{reached} of {types} types reached OP, {} of them with process data, {without_data} with none by their files; {passive} passive devices listed",
        reached - without_data
    );
    assert_eq!(without_data, NO_PROCESS_DATA.len(), "every type without process data is a named one");
    assert!(reached * 100 >= types * 95, "{reached} of {types} types reached OP, fewer than 95 %");
    assert_eq!(types - reached, KNOWN.len(), "every failure is a known one");
    assert_eq!(reached, types, "every type reaches OP");
}

/// An E-Bus terminal whose SyncManagers lie past the ET1200's 1 KB of process RAM (our
/// `ferrocat_ebus_8k.xml`, placed as Beckhoff's EL6751 places them) gets an ESC that holds
/// them: its mailbox answers, it reaches OP with process data, and it reads as an ET1100
/// (0x0000 = 0x11). With the ET1200 its mailbox at 0x1400 lay outside the ESC's memory, and
/// every SDO went unanswered.
#[test]
fn a_terminal_whose_sync_managers_pass_1_kb_gets_an_esc_that_holds_them() {
    let path = std::path::Path::new(env!("CARGO_MANIFEST_DIR")).join("../esi/tests/data/ferrocat_ebus_8k.xml");
    let (good, said) = run_to_op(&path, &["FC-GATEWAY"]);
    assert!(good, "{said}");
    let device = format!("{}:FC-GATEWAY", path.display());
    let ferrocat = |args: &[&str]| {
        let out = Command::new(env!("CARGO_BIN_EXE_ferrocat"))
            .args(args)
            .args(["--device", "EK1100", "--device", &device])
            .output()
            .unwrap();
        assert!(out.status.success(), "{args:?}: {}", String::from_utf8_lossy(&out.stderr));
        String::from_utf8_lossy(&out.stdout).into_owned()
    };
    assert!(ferrocat(&["sdo", "read", "1", "0x1018:1"]).contains("3c 0f 00 00"), "the vendor id 0xF3C");
    let esc_type = ferrocat(&["reg", "read", "1", "0x0000", "1"]);
    assert_eq!(esc_type.trim(), "11", "ESC type 0x0000");
}

/// A drive whose inputs' SyncManager is in mailbox mode (one buffer, control byte 0x22: our
/// `ferrocat_single_buffer_inputs.xml`, as Beckhoff's AX2000-B110 describes its inputs): the
/// master configures the mode the file gives, the device takes it (it refused SAFEOP with
/// 0x001E when it wanted three buffers), every working counter is whole, and the drive's
/// statusword arrives through the one buffer.
#[test]
fn a_drive_whose_inputs_are_single_buffered_reaches_op_and_its_inputs_arrive() {
    let path =
        std::path::Path::new(env!("CARGO_MANIFEST_DIR")).join("../esi/tests/data/ferrocat_single_buffer_inputs.xml");
    let (good, said) = run_to_op(&path, &["FC-DRIVE-1BUF"]);
    assert!(good, "{said}");
    let out = Command::new(env!("CARGO_BIN_EXE_ferrocat"))
        .args(["run", "--device", "EK1100", "--seconds", "0.1", "--no-control", "--show", "1:Statusword"])
        .arg("--device")
        .arg(format!("{}:FC-DRIVE-1BUF", path.display()))
        .output()
        .unwrap();
    let (said, err) = (String::from_utf8_lossy(&out.stdout), String::from_utf8_lossy(&out.stderr));
    assert!(out.status.success(), "{err}");
    // CiA402's SWITCH ON DISABLED (0x0040 with the drive's remote bit 0x0200), not the zeros of
    // a buffer never handed over.
    assert!(said.contains("1:Statusword = 576 (0x240)"), "{said}{err}");
}

/// The Ingenia drive's SII (its ESI's ConfigData) sets a SYNC pulse of 400 µs: at a shorter
/// cycle its SYNC0 output stays active after the first pulse, so the drive would run once. The
/// demo says so at once, naming the slave and the pulse, instead of waiting for drives that
/// never leave Switch on disabled.
#[test]
fn needs_shared_a_drive_whose_sync_pulse_outlasts_the_cycle_is_refused_naming_it() {
    let drive = format!("{}:EVS-NET-01", ferrocat_testdata::shared("esi-corpus/ingenia_esi.xml").display());
    let dir = std::env::temp_dir().join(format!("ferrocat-demo-pulse-{}", std::process::id()));
    let out = Command::new(env!("CARGO_BIN_EXE_ferrocat"))
        .args(["demo", "--drives", "1", "--cycle-us", "250", "--method", "none", "--drive", &drive, "--out"])
        .arg(&dir)
        .output()
        .unwrap();
    let _ = std::fs::remove_dir_all(&dir);
    let err = String::from_utf8_lossy(&out.stderr);
    assert!(!out.status.success(), "{err}");
    assert!(
        err.contains("slave 3: its SYNC pulse (0x0982, from its SII) is 400 µs, longer than the 250 µs cycle"),
        "{err}"
    );
    assert!(err.contains("WARN slave 3 (EVS-NET-01): its SYNC pulse"), "the master's warning: {err}");
}
