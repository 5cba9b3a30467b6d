//! Failures of the master are one clear line with the reason and a non-zero exit, never a panic.
use std::process::Command;

fn ferrocat(args: &[&str]) -> (bool, String, String) {
    let out = Command::new(env!("CARGO_BIN_EXE_ferrocat")).args(args).output().unwrap();
    (out.status.success(), String::from_utf8_lossy(&out.stdout).into(), String::from_utf8_lossy(&out.stderr).into())
}

#[test]
fn a_slave_refusing_op_is_named_with_its_status_code() {
    // A DC-synchronous terminal with firmware: without SYNC0 it refuses OP (0x0030).
    let seg = std::env::temp_dir().join(format!("ferrocat-refuse-{}.toml", std::process::id()));
    std::fs::write(&seg, "seed = 1\n[[device]]\nbuiltin = 'EK1100'\n[[device]]\nbuiltin = 'EL2004'\napp = 'dc'\ndevice_emulation = false\n").unwrap();
    let (ok, _, err) = ferrocat(&["run", "--seconds", "1", "--config", seg.to_str().unwrap()]);
    std::fs::remove_file(&seg).ok();
    assert!(!ok);
    // `run` also states its timestamps; the failure itself is one line.
    let errors: Vec<&str> = err.lines().filter(|l| l.contains("error")).collect();
    assert_eq!(errors.len(), 1, "{err}");
    assert!(
        err.contains("slave 1 (EL2004) did not reach OP") && err.contains("0x0030 (Invalid DC SYNC configuration)"),
        "{err}"
    );
}

#[test]
fn needs_shared_an_sdo_abort_is_named() {
    let esi = ferrocat_testdata::shared("esi/Nanotec_C5-E-2-21.xml");
    let dev = format!("{}:0x4F", esi.display());
    let (ok, out, _) = ferrocat(&["sdo", "read", "0", "0x1018:1", "--type", "u32", "--device", &dev]);
    assert!(ok && out.trim() == "620", "{out}");
    let (ok, _, err) = ferrocat(&["sdo", "read", "0", "0x1234", "--device", &dev]);
    assert!(!ok && err.lines().count() == 1, "{err}");
    assert!(
        err.contains("SDO 0x1234:0x00 aborted") && err.contains("does not exist in the object dictionary"),
        "{err}"
    );
    let (ok, _, err) = ferrocat(&["sdo", "write", "0", "0x1018:1", "5", "--device", &dev]);
    assert!(!ok && err.contains("read-only"), "{err}");
}

/// Negative numbers where clap would have said "unexpected argument" and suggested `-- -1`,
/// which then takes the options after it for values: said in the user's words instead.
#[test]
fn negative_numbers_are_answered_in_words() {
    for (args, want) in [
        (&["sdo", "read", "-1", "0x1000", "--device", "EK1100"][..], "positions count from 0"),
        (&["sii", "read", "-1", "--device", "EK1100"], "positions count from 0"),
        (&["eoe", "get-ip", "-2", "--device", "SERVO"], "positions count from 0"),
        (&["sdo", "read", "70000", "0x1000", "--device", "EK1100"], "65535"),
        (&["run", "--seconds", "-1", "--device", "EK1100"], "-1 s: give 0 or more seconds"),
        (&["foe", "read", "0", "x", "/tmp/never", "--password", "-5", "--device", "SERVO"], "--password '-5'"),
    ] {
        let (ok, _, err) = ferrocat(args);
        assert!(!ok && err.contains(want) && !err.contains("-- -1"), "{args:?}: {err}");
    }
}

#[test]
fn bad_arguments_are_errors_not_panics() {
    for args in [
        &["scan"][..],
        &["scan", "--device", "/nonexistent.bin"],
        &["sdo", "read", "0", "zz:1", "--device", "EK1100"],
        &["run", "--seconds", "-1", "--device", "EK1100"],
        &["sii", "write", "0", "/nonexistent.bin", "--device", "EK1100"],
        &["sii", "alias", "0", "70000", "--device", "EK1100"],
        &["sii", "alias", "0", "-1", "--device", "EK1100"],
        &["sii", "alias", "0", "0xZZ", "--device", "EK1100"],
        &["sii", "alias", "5", "7", "--device", "EK1100"],
        // A multi-byte character in a hex value: was sliced by bytes, a panic.
        &["sdo", "write", "0", "0x6000:1", "0\u{113}0", "--type", "hex", "--device", "EK1100"],
    ] {
        let (ok, _, err) = ferrocat(args);
        assert!(!ok && !err.contains("panicked") && !err.trim().is_empty(), "{args:?}: {err}");
    }
}

/// An endless file (/dev/zero) where a command takes a file: an error naming the file and the
/// bound, at once, not a read until memory runs out.
#[test]
fn an_endless_file_is_refused_by_every_command_that_reads_one() {
    let toml = std::env::temp_dir().join(format!("ferrocat-endless-{}.toml", std::process::id()));
    std::fs::write(&toml, "[[device]]\neeprom = '/dev/zero'\n").unwrap();
    let segment = format!("--config={}", toml.display());
    let (ok, _, err) = ferrocat(&["pcap", "/dev/zero"]);
    assert!(!ok && err.contains("/dev/zero") && err.contains("not a pcap or pcapng capture"), "{err}");
    for args in [
        &["sii", "/dev/zero"][..],
        &["esi", "/dev/zero"],
        &["scan", "--device", "/dev/zero"],
        &["scan", &segment],
        &["lab", "run", "/dev/zero"],
    ] {
        let (ok, _, err) = ferrocat(args);
        assert!(!ok && err.contains("/dev/zero") && err.contains("larger than"), "{args:?}: {err}");
    }
    std::fs::remove_file(&toml).ok();
}

#[test]
fn lab_park2020_prints_its_table_as_json() {
    let (ok, out, err) = ferrocat(&["lab", "park2020", "--quick", "--slaves", "2", "--rounds", "1", "--json"]);
    assert!(ok, "{err}");
    let v: serde_json::Value = serde_json::from_str(out.trim()).unwrap();
    let rows = v["rows"].as_array().unwrap();
    assert_eq!(rows.len(), 4, "conventional, park2020, ferrocat, ferrocat-mfr");
    for r in rows {
        for key in
            ["slaves", "method", "host", "ref_gmean_us", "ref_mrms_us", "last_gmean_us", "last_mrms_us", "lock_ms"]
        {
            assert!(r.get(key).is_some(), "{key} missing in {r}");
        }
        assert_eq!(r["host"], "beaglebone-rt");
        assert!(r["ref_mrms_us"].as_f64().unwrap() > 0.0);
    }
    let (ok, _, err) = ferrocat(&["lab", "park2020", "--quick", "--host", "vax"]);
    assert!(!ok && err.contains("vax") && err.contains("beaglebone-rt"), "{err}");
}

#[test]
fn lab_chen2016_refuses_bad_cycles_and_hosts() {
    let (ok, _, err) = ferrocat(&["lab", "chen2016", "--quick", "--cycle-us", "5"]);
    let first = err.lines().next().unwrap_or_default();
    assert!(!ok && first.contains("--cycle-us") && first.contains("from 10 to 100000 µs"), "{err}");
    let (ok, _, err) = ferrocat(&["lab", "chen2016", "--host", "vax"]);
    assert!(!ok && err.contains("rtx-10us"), "{err}");
}

/// `ferrocat foe`: firmware into the AKD in BOOT (its SII's bootstrap mailbox), and the
/// failures one line each — a slave without a bootstrap mailbox, a missing file on the slave,
/// a missing file here, a password that is no number.
#[test]
fn needs_shared_foe_writes_firmware_in_boot_and_names_its_failures() {
    let akd = ferrocat_testdata::shared("captures/eeprom/akd.hex");
    let fw = std::env::temp_dir().join(format!("ferrocat-fw-{}.bin", std::process::id()));
    std::fs::write(&fw, vec![0x5A; 3000]).unwrap();
    let fw_s = fw.to_str().unwrap();
    let akd_s = akd.to_str().unwrap();
    let (ok, _, err) =
        ferrocat(&["foe", "write", "1", "akd.i00", fw_s, "--boot", "--device", "EK1100", "--device", akd_s]);
    assert!(ok && err.contains("wrote") && err.contains("3000 bytes"), "{err}");
    let failures: [(&[&str], &str); 5] = [
        (&["foe", "write", "0", "x", fw_s, "--boot", "--device", "SERVO"], "no bootstrap mailbox"),
        (&["foe", "read", "0", "none", "/dev/null", "--device", "SERVO"], "0x8001 (file not found)"),
        (&["foe", "write", "0", "x", "/nonexistent/fw", "--device", "SERVO"], "reading /nonexistent/fw"),
        // A read's file where no file can be made: said before the bring-up, not after the transfer.
        (&["foe", "read", "0", "x", "/nonexistent/fw", "--device", "SERVO"], "creating /nonexistent/fw.part"),
        (&["foe", "write", "0", "x", fw_s, "--password", "zz", "--device", "SERVO"], "--password 'zz'"),
    ];
    for (args, want) in failures {
        let (ok, _, err) = ferrocat(args);
        assert!(!ok && err.lines().count() == 1 && err.contains(want), "{args:?}: {err}");
    }
    std::fs::remove_file(&fw).unwrap();
}

/// `ferrocat sii alias`: the alias and the checksum written (two words), the ESC told to take it
/// at its next power-on; a slave whose EEPROM's checksum is wrong named by `scan`.
#[test]
fn sii_alias_writes_two_words_and_scan_names_a_bad_checksum() {
    let (ok, _, err) = ferrocat(&["sii", "alias", "1", "0x0BAD", "--device", "EK1100", "--device", "EL2004"]);
    assert!(ok, "{err}");
    assert!(err.contains("slave 1 (EL2004): alias 0x0bad") && err.contains("2 words written"), "{err}");
    // An EL2004 image whose alias was changed without its checksum.
    let img = std::env::temp_dir().join(format!("ferrocat-badcrc-{}.bin", std::process::id()));
    let (ok, _, err) =
        ferrocat(&["sii", "read", "1", "--out", img.to_str().unwrap(), "--device", "EK1100", "--device", "EL2004"]);
    assert!(ok, "{err}");
    let mut bytes = std::fs::read(&img).unwrap();
    bytes[8] ^= 0x01;
    std::fs::write(&img, &bytes).unwrap();
    let (ok, out, err) = ferrocat(&["scan", "--device", "EK1100", "--device", img.to_str().unwrap()]);
    let (ok_json, json, _) = ferrocat(&["scan", "--json", "--device", "EK1100", "--device", img.to_str().unwrap()]);
    std::fs::remove_file(&img).ok();
    assert!(ok, "{err}");
    assert!(out.contains("ESC unconfigured") && out.contains("checksum"), "{out}");
    let v: serde_json::Value = serde_json::from_str(&json).unwrap();
    assert!(ok_json && v[1]["eeprom_loaded"] == false && v[0]["eeprom_loaded"] == true, "{json}");
}

/// `sdo read|write --type` takes only the types it knows; a number type reads only an object
/// of exactly its width, and a value that does not fit its type is refused with the range.
#[test]
fn sdo_types_are_checked_both_ways() {
    let seg = ["--device", "EK1100", "--device", "SERVO"];
    let sdo = |args: &[&str]| ferrocat(&[&["sdo"], args, &seg[..]].concat());
    let (ok, _, err) = sdo(&["read", "1", "0x1008", "--type", "bogus"]);
    assert!(!ok && err.contains("invalid value 'bogus'") && err.contains("possible values"), "{err}");
    let (ok, _, err) = sdo(&["read", "1", "0x1008", "--type", "u8"]);
    assert!(!ok && err.contains("holds 37 byte(s) and --type u8 reads 1"), "{err}");
    let (ok, out, _) = sdo(&["read", "1", "0x1008", "--type", "string"]);
    assert!(ok && out.trim() == "ferrocat simulated CiA402 servo drive", "{out}");
    let (ok, _, err) = sdo(&["write", "1", "0x6060", "300", "--type", "u8"]);
    assert!(!ok && err.contains("value 300 is out of the range of --type u8 (0 to 255)"), "{err}");
    let (ok, _, err) = sdo(&["write", "1", "0x6060", "zzz", "--type", "i8"]);
    assert!(!ok && err.contains("value 'zzz' is not a number (decimal or 0x hex) for --type i8"), "{err}");
    let (ok, _, err) = sdo(&["write", "1", "0x6060", "-1", "--type", "i8"]);
    assert!(ok, "{err}");
    let (ok, out, err) = sdo(&["read", "1", "0x6060", "--type", "i8"]);
    assert!(ok && out.trim() == "0", "a fresh segment each run: {out}{err}");
    let (ok, out, err) = sdo(&["read", "1", "0x1000", "--type", "u32"]);
    assert!(ok && out.trim().parse::<u32>().is_ok(), "{out}{err}");
    // Without --type, the object's own type from SDO information (0x6060 is INTEGER8), and
    // what was written said.
    let (ok, _, err) = sdo(&["write", "1", "0x6060", "8"]);
    assert!(ok && err.contains("wrote 8 to 0x6060:0x00 of slave 1 (i8, 1 byte(s))"), "{err}");
    let (ok, _, err) = sdo(&["write", "1", "0x6060", "300"]);
    assert!(!ok && err.contains("value 300 is out of the range of --type i8"), "{err}");
    // Hex as the help promises it, 0x and all.
    let (ok, _, err) = sdo(&["write", "1", "0x6060", "0x08", "--type", "hex"]);
    assert!(ok && err.contains("(hex, 1 byte(s))"), "{err}");
    // A subindex past 255 in the user's words, not the conversion's.
    let (ok, _, err) = sdo(&["read", "1", "0x1018:999"]);
    assert!(!ok && err.contains("subindex '999' is more than 0xFF (255)") && !err.contains("integral"), "{err}");
}

/// `run --cycle-us` is bounded; the summary says what the cycle was (back to back for
/// --max-rate) and the period achieved; SIGINT ends a run with the same summary.
#[test]
fn run_bounds_its_cycle_and_sums_up_when_interrupted() {
    let seg = ["--device", "EK1100", "--device", "EL2004"];
    for bad in ["1", "9", "1000001", "99999999999"] {
        let (ok, _, err) = ferrocat(&[&["run", "--cycle-us", bad], &seg[..]].concat());
        assert!(!ok && err.contains("--cycle-us") && err.contains("from 10 to 1000000 µs"), "{bad}: {err}");
    }
    let (ok, out, err) = ferrocat(&[&["run", "--seconds", "0.05", "--max-rate"], &seg[..]].concat());
    assert!(ok && out.contains("cycles back to back (mean period "), "{out}{err}");
    let (ok, out, err) = ferrocat(&[&["run", "--seconds", "0.05", "--cycle-us", "250"], &seg[..]].concat());
    assert!(ok && out.starts_with("200 cycles of 250 µs (mean period 250.0 µs)"), "{out}{err}");
    // A run without end (--seconds 0, as a service runs it), stopped by SIGINT once it is
    // cycling (its handlers are in place before the bring-up it reports).
    use std::io::{BufRead, Read};
    let mut child = Command::new(env!("CARGO_BIN_EXE_ferrocat"))
        .args([&["run", "--seconds", "0"], &seg[..]].concat())
        .stdout(std::process::Stdio::piped())
        .stderr(std::process::Stdio::piped())
        .spawn()
        .unwrap();
    let mut lines = std::io::BufReader::new(child.stderr.take().unwrap());
    let mut err = String::new();
    while !err.contains("bring-up to OP") {
        assert!(lines.read_line(&mut err).unwrap() > 0, "{err}");
    }
    Command::new("kill").args(["-INT", &child.id().to_string()]).status().unwrap();
    lines.read_to_string(&mut err).unwrap();
    let o = child.wait_with_output().unwrap();
    let out = String::from_utf8_lossy(&o.stdout);
    assert!(o.status.success(), "{out}{err}");
    // However soon the signal came: "1 cycle of" was seen once in a loaded CI run, the signal
    // right after the bring-up.
    let summed = out.contains(" cycles of 1000 µs (mean period") || out.contains("1 cycle of 1000 µs (mean period");
    assert!(err.contains("stopped by a signal after") && summed, "{out}{err}");
}

/// Slave positions count from 0 in every command and output: `scan` as text and JSON, `sdo`,
/// `run`'s SYNC0 line, and the error for a position past the end.
#[test]
fn positions_count_from_zero_everywhere() {
    let seg = ["--device", "EK1100", "--device", "EL2004", "--device", "EL1004", "--device", "SERVO"];
    let (ok, text, err) = ferrocat(&[&["scan"], &seg[..]].concat());
    assert!(ok && text.starts_with("4 slaves found"), "{text}{err}");
    assert!(text.contains("Slave 0: EK1100") && text.contains("Slave 3: SERVO") && !text.contains("Slave 4"), "{text}");
    assert!(
        text.contains("\n  0 EK1100 (port 0") && text.contains("\n        3 SERVO (port 1"),
        "topology from 0: {text}"
    );
    let (_, json, _) = ferrocat(&[&["scan", "--json"], &seg[..]].concat());
    let v: serde_json::Value = serde_json::from_str(&json).unwrap();
    assert_eq!((v[3]["position"].as_u64(), v[3]["name"].as_str()), (Some(3), Some("SERVO")));
    let (ok, out, _) = ferrocat(&[&["sdo", "read", "3", "0x1008", "--type", "string"], &seg[..]].concat());
    assert!(ok && out.contains("servo"), "{out}");
    let (ok, _, err) = ferrocat(&[&["sdo", "read", "4", "0x1008"], &seg[..]].concat());
    assert!(!ok && err.contains("no slave at position 4 (positions count from 0: 0 to 3)"), "{err}");
    let (ok, _, err) = ferrocat(&[&["run", "--dc", "--seconds", "0.1"], &seg[..]].concat());
    assert!(ok && (err.contains("SYNC0 on slave 3;") || err.contains("SYNC0 on slave 3\n")), "{err}");
    let (ok, text, _) = ferrocat(&["scan", "--device", "ek1100"]);
    assert!(
        ok && text.starts_with("1 slave found") && text.contains("Slave 0: EK1100"),
        "built-in names in any case: {text}"
    );
}

/// Error messages say each thing once, in the user's terms, with what and where.
#[test]
fn error_texts_say_it_once_in_the_users_terms() {
    let dir = std::env::temp_dir().join(format!("ferrocat-texts-{}", std::process::id()));
    std::fs::create_dir_all(&dir).unwrap();
    // A pcap cut inside its file header: the header named, the reader's reason once.
    let short = dir.join("short.pcap");
    std::fs::write(&short, [0xd4, 0xc3, 0xb2, 0xa1, 0x02, 0x00, 0x04, 0x00]).unwrap();
    let (ok, _, err) = ferrocat(&["pcap", short.to_str().unwrap()]);
    assert!(!ok && err.contains("malformed capture file header") && !err.contains("frame 0"), "{err}");
    assert_eq!(err.matches("unexpected end of file").count(), 1, "{err}");
    // An object that is no number.
    let (ok, _, err) = ferrocat(&["sdo", "read", "1", "zzz", "--device", "EK1100", "--device", "SERVO"]);
    assert!(!ok && err.contains("object 'zzz': 'zzz' is not a number (give INDEX or INDEX:SUB"), "{err}");
    // An ESI file without devices is an error, not an empty listing.
    let empty = dir.join("empty.xml");
    std::fs::write(
        &empty,
        "<EtherCATInfo><Vendor><Id>2</Id></Vendor><Descriptions><Devices/></Descriptions></EtherCATInfo>",
    )
    .unwrap();
    let (ok, _, err) = ferrocat(&["esi", empty.to_str().unwrap()]);
    assert!(!ok && err.contains("describes no device"), "{err}");
    // The demo's drive named as --drive names it: a terminal's EEPROM (read out of the built-in
    // EL2004) is no CiA402 drive.
    let dump = dir.join("el2004.bin");
    let (ok, _, err) =
        ferrocat(&["sii", "read", "1", "--out", dump.to_str().unwrap(), "--device", "EK1100", "--device", "EL2004"]);
    assert!(ok, "{err}");
    let (ok, _, err) = ferrocat(&["demo", "--drive", dump.to_str().unwrap(), "--cycle-us", "1000"]);
    assert!(
        !ok && err.contains("has no CoE mailbox in its SII, so it is no CiA402 drive") && !err.contains("app = "),
        "{err}"
    );
    std::fs::remove_dir_all(&dir).ok();
}

/// EtherCAT over UDP to an address where nothing listens: said in those words, the address
/// named, by every command's first frames.
#[test]
fn a_udp_address_where_nothing_listens_is_named() {
    // A port just closed on loopback: the kernel refuses datagrams to it.
    let port = std::net::UdpSocket::bind("127.0.0.1:0").unwrap().local_addr().unwrap().port();
    let addr = format!("127.0.0.1:{port}");
    for args in [vec!["scan"], vec!["sdo", "read", "1", "0x1018:1"], vec!["run", "--seconds", "1"]] {
        let mut all = args.clone();
        all.extend(["--udp", addr.as_str()]);
        let (ok, _, err) = ferrocat(&all);
        assert!(!ok && err.lines().filter(|l| l.contains("error")).count() == 1, "{args:?}: {err}");
        assert!(err.contains(&format!("nothing listens at {addr} (UDP; connection refused)")), "{args:?}: {err}");
    }
}

/// `sii read` without --out dumps the EEPROM as xxd does: byte offsets, 16 bytes a line, the
/// printable bytes beside them.
#[test]
fn sii_read_dumps_byte_offsets() {
    let (ok, out, err) = ferrocat(&["sii", "read", "0", "--device", "EK1100"]);
    assert!(ok, "{err}");
    let lines: Vec<&str> = out.lines().collect();
    assert!(lines[0].starts_with("00000000: ") && lines[1].starts_with("00000010: "), "{out}");
    // Word 0x08 (byte 0x10) holds the vendor ID, Beckhoff's 2; word 0x0A the product code.
    assert!(lines[1].starts_with("00000010: 02 00 00 00 52 2c 4c 04"), "EK1100 is 0x044C2C52: {out}");
    assert!(lines.iter().all(|l| l.len() <= 10 + 47 + 2 + 16), "{out}");
}

/// A coupler's negative E-Bus current is explained: it is what the coupler supplies.
#[test]
fn the_ebus_current_says_which_way_it_flows() {
    let img = std::env::temp_dir().join(format!("ferrocat-ek1100-{}.bin", std::process::id()));
    let (ok, _, err) = ferrocat(&["sii", "read", "0", "--out", img.to_str().unwrap(), "--device", "EK1100"]);
    assert!(ok, "{err}");
    let (ok, out, err) = ferrocat(&["sii", img.to_str().unwrap()]);
    std::fs::remove_file(&img).ok();
    assert!(ok && out.contains("E-Bus current -2000 mA (it supplies 2000 mA to the E-Bus)"), "{out}{err}");
}

/// What the commands print is in the user's words: no `Some(…)` or `None` of Rust's.
#[test]
fn needs_shared_no_rust_internals_in_the_output() {
    let esi = ferrocat_testdata::shared("esi/Nanotec_C5-E-2-21.xml");
    let esi = esi.to_str().unwrap();
    let seg = ["--device", "EK1100", "--device", "EL2004", "--device", "SERVO"];
    for args in [
        vec!["esi", esi, "--device", "0"],
        [&["scan"][..], &seg[..]].concat(),
        [&["run", "--dc", "--seconds", "0.1"][..], &seg[..]].concat(),
        vec!["sii", ferrocat_testdata::shared("captures/eeprom/ek1100.hex").to_str().unwrap()],
    ] {
        let (ok, out, err) = ferrocat(&args);
        assert!(ok, "{args:?}: {err}");
        let all = format!("{out}{err}");
        assert!(!all.contains("Some(") && !all.contains("None"), "{args:?}: {all}");
    }
}

/// Logging: quiet by default; -v logs the bring-up's steps, -vv each slave and state; RUST_LOG
/// chooses for itself; the library prints nothing of its own.
#[test]
fn the_log_says_as_much_as_asked() {
    let seg = ["--device", "EK1100", "--device", "EL2004"];
    let run = |pre: &[&str], env: Option<&str>| {
        let mut c = Command::new(env!("CARGO_BIN_EXE_ferrocat"));
        c.args(pre).arg("scan").args(seg).env_remove("RUST_LOG");
        if let Some(v) = env {
            c.env("RUST_LOG", v);
        }
        let o = c.output().unwrap();
        assert!(o.status.success());
        String::from_utf8_lossy(&o.stderr).into_owned()
    };
    assert_eq!(run(&[], None), "", "nothing logged by default on a healthy segment");
    let v = run(&["-v"], None);
    assert!(v.contains("INFO") && v.contains("2 slave(s) answer") && !v.contains("DEBUG"), "{v}");
    let vv = run(&["-vv"], None);
    assert!(vv.contains("DEBUG slave 1 (EL2004) in INIT") && vv.contains("device emulation"), "{vv}");
    let env = run(&[], Some("ferrocat_master=debug"));
    assert!(env.contains("DEBUG slave 0 (EK1100)"), "{env}");
    assert_eq!(run(&["-q"], None), "");
}

/// The command line's second pass (#77): each input a user met, answered in the user's words.
#[test]
fn second_pass_inputs_are_answered_in_the_users_words() {
    let seg = ["--device", "EK1100", "--device", "SERVO"];
    let with = |args: &[&str]| ferrocat(&[args, &seg[..]].concat());
    // A subindex typed in decimal comes back with its radix, not as bare hex.
    let (ok, _, err) = with(&["sdo", "read", "1", "0x1018:99"]);
    assert!(!ok && err.contains("SDO 0x1018:0x63 aborted") && !err.contains(":63 "), "{err}");
    // SDO information in CiA 301's names.
    let (ok, out, err) = with(&["sdo", "list", "1"]);
    assert!(ok && out.contains("VAR    UNSIGNED32") && out.contains("RECORD IDENTITY"), "{out}{err}");
    assert!(!out.contains("type 0x0007") && !out.contains(" code 7"), "{out}");
    // One interface as both ports of a ring.
    let (ok, _, err) = ferrocat(&["run", "--iface", "fcat-none", "--secondary-iface", "fcat-none", "--seconds", "0.1"]);
    assert!(!ok && err.contains("--secondary-iface fcat-none is --iface itself"), "{err}");
    // A ping of nothing, and one without --from on a slave without a gateway.
    let (ok, _, err) = with(&["eoe", "ping", "1", "--ip", "192.168.9.20", "--count", "0"]);
    assert!(!ok && err.contains("--count") && err.contains("1..=65535"), "{err}");
    let (ok, out, err) = with(&["eoe", "ping", "1", "--ip", "192.168.9.20", "--count", "1"]);
    assert!(ok && out.contains("from 192.168.9.1:") && out.contains("1 sent, 1 received"), "{out}{err}");
    // Every cycle time's bounds, said the same way by every command.
    for (args, bounds) in [
        (&["run", "--cycle-us", "5", "--device", "EK1100"][..], "from 10 to 1000000 µs"),
        (&["demo", "--cycle-us", "50"], "from 100 to 10000 µs"),
        (&["lab", "park2020", "--cycle-us", "5"], "from 10 to 100000 µs"),
        (&["lab", "chen2016", "--cycle-us", "-3"], "from 10 to 100000 µs"),
        (&["lab", "live", "--cycle-us", "50"], "from 100 to 100000 µs"),
    ] {
        let (ok, _, err) = ferrocat(args);
        assert!(!ok && err.contains("--cycle-us") && err.contains(bounds), "{args:?}: {err}");
    }
    for args in [&["demo", "--help"][..], &["lab", "park2020", "--help"], &["lab", "live", "--help"]] {
        let (_, help, _) = ferrocat(args);
        assert!(help.contains(" to 1") && help.contains("µs"), "{args:?} states its bounds: {help}");
    }
    // --out onto a file, said before any work.
    let file = std::env::temp_dir().join(format!("ferrocat-out-file-{}.png", std::process::id()));
    std::fs::write(&file, b"x").unwrap();
    for cmd in [&["demo"][..], &["lab", "robustness"]] {
        let (ok, _, err) = ferrocat(&[cmd, &["--out", file.to_str().unwrap()][..]].concat());
        assert!(!ok && err.contains("that is a file; --out takes a folder"), "{cmd:?}: {err}");
    }
    std::fs::remove_file(&file).ok();
    // Logging's flags under a heading of their own, in words that fit a command without a master.
    for cmd in ["pcap", "esi", "sdo"] {
        let (_, help, _) = ferrocat(&[cmd, "--help"]);
        let logging = help.split("\nLogging:\n").nth(1).unwrap_or_else(|| panic!("{cmd}: {help}"));
        assert!(logging.contains("--verbose") && logging.contains("--quiet"), "{cmd}: {help}");
        assert!(!help.split("\nLogging:\n").next().unwrap().contains("--verbose"), "{cmd}: {help}");
    }
    // Units in the output as in the help.
    let (ok, out, err) = ferrocat(&["run", "--seconds", "0.05", "--device", "EK1100", "--device", "EL2004"]);
    assert!(ok && out.contains(" µs") && !out.contains(" us ") && !out.contains(" us;"), "{out}{err}");
}

/// `esi --device NAME` says which of several revisions it shows and how to choose another.
#[test]
fn needs_shared_esi_names_the_revision_it_chose() {
    let esi = ferrocat_testdata::shared("esi/Beckhoff_EK11xx.xml");
    let (ok, _, err) = ferrocat(&["esi", esi.to_str().unwrap(), "--device", "EK1100"]);
    assert!(ok && err.contains("type EK1100 has 5 revisions in the file"), "{err}");
    assert!(err.contains("the newest, 0x00120000, is shown; --device EK1100:REVISION chooses another"), "{err}");
    let (ok, _, err) = ferrocat(&["esi", esi.to_str().unwrap(), "--device", "EK1100:0x00100000"]);
    assert!(ok && !err.contains("revisions in the file"), "{err}");
}
