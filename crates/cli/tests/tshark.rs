//! `ferrocat pcap --json` against Wireshark's EtherCAT dissector, datagram by datagram, over
//! every shared capture. tshark is an independent decoder; any difference fails the test. The
//! frame's time is compared too (pcapng files say in what units they count it).
use std::io::{BufRead, BufReader};
use std::process::{Command, Stdio};

#[derive(Debug, Default, Clone, PartialEq, Eq)]
struct Dg {
    frame: u64,
    time_ns: u64,
    cmd: u64,
    idx: u64,
    adp: Option<u64>,
    ado: Option<u64>,
    logical: Option<u64>,
    len: u64,
    circulating: bool,
    more: bool,
    irq: u64,
    wkc: u64,
}

fn num(s: &str) -> u64 {
    match s.strip_prefix("0x") {
        Some(h) => u64::from_str_radix(h, 16).unwrap_or_else(|_| panic!("bad hex {s}")),
        None => s.parse().unwrap_or_else(|_| panic!("bad number {s}")),
    }
}

fn attr<'a>(line: &'a str, name: &str) -> Option<&'a str> {
    let key = format!(" {name}=\"");
    let start = line.find(&key)? + key.len();
    Some(&line[start..start + line[start..].find('"')?])
}

/// tshark's epoch time, "1657036734.840250000", in ns.
fn epoch_ns(s: &str) -> u64 {
    let (secs, frac) = s.split_once('.').unwrap_or((s, "0"));
    assert!(frac.len() <= 9, "epoch time {s} finer than ns");
    num(secs) * 1_000_000_000 + num(&format!("{frac:0<9}"))
}

/// Datagrams as tshark's dissector reports them (PDML, one field per line).
fn tshark_datagrams(path: &std::path::Path) -> Vec<Dg> {
    let mut child = Command::new("tshark")
        .args(["-n", "-r"])
        .arg(path)
        .args(["-T", "pdml", "-J", "frame ecat"])
        .stdout(Stdio::piped())
        .stderr(Stdio::null())
        .spawn()
        .expect("tshark is not installed: scripts/test.sh installs it (Debian package tshark)");
    let mut out = Vec::new();
    let (mut frame, mut time_ns) = (0, 0);
    for line in BufReader::new(child.stdout.take().unwrap()).lines() {
        let line = line.unwrap();
        let Some(name) = attr(&line, "name") else { continue };
        let show = attr(&line, "show").unwrap_or("");
        match name {
            "num" => frame = num(show),
            "frame.time_epoch" => time_ns = epoch_ns(show),
            "ecat.cmd" => out.push(Dg { frame, time_ns, cmd: num(show), ..Default::default() }),
            _ if name.starts_with("ecat.") => {
                let Some(d) = out.last_mut() else { continue };
                match name {
                    "ecat.idx" => d.idx = num(show),
                    "ecat.adp" => d.adp = Some(num(show)),
                    "ecat.ado" => d.ado = Some(num(show)),
                    "ecat.lad" => d.logical = Some(num(show)),
                    "ecat.subframe.length" => d.len = num(show),
                    "ecat.subframe.circulating" => d.circulating = show == "1",
                    "ecat.subframe.more" => d.more = show == "1",
                    "ecat.int" => d.irq = num(show),
                    "ecat.cnt" => d.wkc = num(show),
                    _ => {}
                }
            }
            _ => {}
        }
    }
    assert!(child.wait().unwrap().success(), "tshark failed on {}", path.display());
    out
}

fn ferrocat_datagrams(path: &std::path::Path) -> Vec<Dg> {
    let out = Command::new(env!("CARGO_BIN_EXE_ferrocat")).arg("pcap").arg("--json").arg(path).output().unwrap();
    assert!(out.status.success(), "ferrocat pcap failed: {}", String::from_utf8_lossy(&out.stderr));
    String::from_utf8(out.stdout)
        .unwrap()
        .lines()
        .map(|l| {
            let v: serde_json::Value = serde_json::from_str(l).unwrap();
            let u = |k: &str| v.get(k).and_then(|x| x.as_u64());
            Dg {
                frame: u("frame").unwrap(),
                time_ns: u("time_ns").unwrap(),
                cmd: u("cmd").unwrap(),
                idx: u("idx").unwrap(),
                adp: u("adp"),
                ado: u("ado"),
                logical: u("logical"),
                len: u("len").unwrap(),
                circulating: v["circulating"].as_bool().unwrap(),
                more: v["more"].as_bool().unwrap(),
                irq: u("irq").unwrap(),
                wkc: u("wkc").unwrap(),
            }
        })
        .collect()
}

#[test]
fn needs_shared_pcap_json_matches_tshark_on_every_capture() {
    let mut total = 0;
    for path in ferrocat_testdata::shared_files("captures", ".pcapng") {
        let theirs = tshark_datagrams(&path);
        let ours = ferrocat_datagrams(&path);
        let diffs: Vec<_> = ours.iter().zip(&theirs).filter(|(a, b)| a != b).take(5).collect();
        assert!(
            diffs.is_empty() && ours.len() == theirs.len(),
            "{}: {} datagrams from ferrocat, {} from tshark; first differences (ours, tshark): {diffs:#?}",
            path.display(),
            ours.len(),
            theirs.len()
        );
        assert!(!ours.is_empty());
        println!("{:45} {:6} datagrams agree with tshark", path.file_name().unwrap().to_string_lossy(), ours.len());
        total += ours.len();
    }
    println!("total {total} datagrams");
}

/// FoE as Wireshark decodes what `ferrocat foe` put on the (virtual) wire, recorded with
/// `--pcap`: the received frames (working counter ≥ 1) of a 300-byte write to the servo —
/// write request with the name, acknowledge 0, data packets 1–3 (116, 116, 68 bytes) each
/// acknowledged — and of a read of a missing file, answered by error 0x8001 with its text.
#[test]
fn tshark_decodes_foe_as_we_sent_it() {
    let dir = std::env::temp_dir().join(format!("ferrocat-tshark-foe-{}", std::process::id()));
    std::fs::create_dir_all(&dir).unwrap();
    let file = dir.join("fw.bin");
    std::fs::write(&file, (0..300u32).map(|k| k as u8).collect::<Vec<_>>()).unwrap();
    let run = |args: &[&str], pcap: &std::path::Path| {
        let out = Command::new(env!("CARGO_BIN_EXE_ferrocat"))
            .args(args)
            .args(["--device", "EK1100", "--device", "SERVO", "--pcap"])
            .arg(pcap)
            .output()
            .unwrap();
        String::from_utf8_lossy(&out.stderr).to_string()
    };
    let foe = |pcap: &std::path::Path| -> Vec<String> {
        let out = Command::new("tshark")
            .args(["-n", "-r"])
            .arg(pcap)
            .args(["-Y", "ecat_mailbox.foe && ecat.cnt > 0", "-T", "fields"])
            .args(["-e", "ecat_mailbox.length", "-e", "ecat_mailbox.foe_opmode", "-e", "ecat_mailbox.foe_packetno"])
            .args(["-e", "ecat_mailbox.foe_filename"])
            .args(["-e", "ecat_mailbox.foe_errcode", "-e", "ecat_mailbox.foe_errtext"])
            .stderr(Stdio::null())
            .output()
            .expect("tshark is not installed: scripts/test.sh installs it (Debian package tshark)");
        String::from_utf8_lossy(&out.stdout).lines().map(|l| l.trim_end().to_string()).collect()
    };
    let written = dir.join("write.pcapng");
    let said = run(&["foe", "write", "1", "fw.bin", file.to_str().unwrap()], &written);
    assert!(said.contains("wrote") && said.contains("300 bytes"), "{said}");
    assert_eq!(
        foe(&written),
        // The mailbox length: the FoE header's 6 bytes and the name or the data.
        [
            "12\t0x02\t\tfw.bin",
            "6\t0x04\t0",
            "122\t0x03\t1",
            "6\t0x04\t1",
            "122\t0x03\t2",
            "6\t0x04\t2",
            "74\t0x03\t3",
            "6\t0x04\t3"
        ]
    );
    let missing = dir.join("missing.pcapng");
    let said = run(&["foe", "read", "1", "none.bin", dir.join("out").to_str().unwrap()], &missing);
    assert!(said.contains("file not found"), "{said}");
    assert_eq!(foe(&missing), ["14\t0x01\t\tnone.bin", "20\t0x05\t\t\t32769\tfile not found"]);
    std::fs::remove_dir_all(&dir).unwrap();
}

/// Wireshark decodes our EoE as we sent it: Set IP Parameter with its fields, the response,
/// Get IP Parameter, the drive's ARP announcement and the ping's echo request and reply inside
/// their fragments, checksums good.
#[test]
fn tshark_decodes_eoe_as_we_sent_it() {
    let pcap = std::env::temp_dir().join(format!("ferrocat-tshark-eoe-{}.pcapng", std::process::id()));
    let out = Command::new(env!("CARGO_BIN_EXE_ferrocat"))
        .args(["eoe", "ping", "1", "--ip", "192.168.7.2", "--gateway", "192.168.7.1", "--netmask", "255.255.255.0"])
        .args(["--name", "axis-1", "--count", "1", "--size", "8", "--device", "EK1100", "--device", "SERVO", "--pcap"])
        .arg(&pcap)
        .output()
        .unwrap();
    let said = String::from_utf8_lossy(&out.stdout);
    assert!(out.status.success() && said.contains("1 received"), "{said}{}", String::from_utf8_lossy(&out.stderr));
    let fields = [
        "ecat_mailbox.eoe.type",
        "ecat_mailbox.eoe.init.macaddr",
        "ecat_mailbox.eoe.init.ipaddr",
        "ecat_mailbox.eoe.init.subnetmask",
        "ecat_mailbox.eoe.init.defaultgateway",
        "ecat_mailbox.eoe.init.dnsname",
        "ecat_mailbox.eoe.frame",
        "ecat_mailbox.eoe.last",
        "arp.opcode",
        "arp.src.proto_ipv4",
        "icmp.type",
        "icmp.checksum.status",
    ];
    let mut cmd = Command::new("tshark");
    cmd.args(["-n", "-r"]).arg(&pcap).args(["-Y", "ecat_mailbox.eoe && ecat.cnt > 0", "-T", "fields"]);
    for f in fields {
        cmd.args(["-e", f]);
    }
    let out = cmd
        .stderr(Stdio::null())
        .output()
        .expect("tshark is not installed: scripts/test.sh installs it (Debian package tshark)");
    let lines: Vec<String> = String::from_utf8_lossy(&out.stdout).lines().map(|l| l.trim_end().to_string()).collect();
    assert_eq!(
        lines,
        [
            // The MAC from the station address 0x1002 (locally administered).
            "2\t02:00:00:00:10:02\t192.168.7.2\t255.255.255.0\t192.168.7.1\taxis-1",
            "3",
            "6",
            "0\t\t\t\t\t\t0\t1\t1\t192.168.7.2",
            "7",
            "0\t\t\t\t\t\t0\t1\t\t\t8\t1",
            "0\t\t\t\t\t\t1\t1\t\t\t0\t1",
        ]
    );
    std::fs::remove_file(&pcap).unwrap();
}

/// Every shared capture cut to a snap length of 64 bytes by Wireshark's `editcap -s 64` (as
/// `tcpdump -s 64` would have recorded it) and written as classic pcap (in microseconds):
/// `ferrocat pcap` reads
/// the whole file, every datagram that survived whole decodes as from the full capture, and
/// the one the cut fell in is marked `truncated`, with no working counter and its data a prefix
/// of the real one's.
#[test]
fn needs_shared_pcap_reads_files_cut_by_a_snap_length() {
    let dir = std::env::temp_dir().join(format!("ferrocat-snaplen-{}", std::process::id()));
    std::fs::create_dir_all(&dir).unwrap();
    let json = |path: &std::path::Path| -> Vec<serde_json::Value> {
        let out = Command::new(env!("CARGO_BIN_EXE_ferrocat")).arg("pcap").arg("--json").arg(path).output().unwrap();
        assert!(out.status.success(), "{}: {}", path.display(), String::from_utf8_lossy(&out.stderr));
        String::from_utf8(out.stdout).unwrap().lines().map(|l| serde_json::from_str(l).unwrap()).collect()
    };
    let (mut truncated, mut whole) = (0, 0);
    for path in ferrocat_testdata::shared_files("captures", ".pcapng") {
        let cut = dir.join(path.file_name().unwrap()).with_extension("pcap");
        let st = Command::new("editcap").args(["-s", "64", "-F", "pcap"]).arg(&path).arg(&cut).status().unwrap();
        assert!(st.success(), "editcap on {}", path.display());
        let full = json(&path);
        let key = |v: &serde_json::Value| (v["frame"].as_u64().unwrap(), v["datagram"].as_u64().unwrap());
        let by_key: std::collections::HashMap<_, _> = full.iter().map(|v| (key(v), v)).collect();
        for mut v in json(&cut) {
            let real = by_key[&key(&v)];
            // Classic pcap counts microseconds.
            let (t, t_real) = (v["time_ns"].as_u64().unwrap(), real["time_ns"].as_u64().unwrap());
            assert_eq!(t, t_real / 1000 * 1000, "{}: time of {v}", path.display());
            v["time_ns"] = t_real.into();
            if v.get("truncated").is_some() {
                truncated += 1;
                assert!(v["wkc"].is_null(), "{v}");
                let (d, r) = (v["data"].as_str().unwrap(), real["data"].as_str().unwrap());
                assert!(r.starts_with(d), "{}: {v} against {real}", path.display());
                for k in ["cmd", "idx", "len", "adp", "ado", "logical", "irq", "time_ns"] {
                    assert_eq!(v.get(k), real.get(k), "{}: {k} of {v}", path.display());
                }
            } else {
                whole += 1;
                assert_eq!(&v, real, "{}", path.display());
            }
        }
    }
    std::fs::remove_dir_all(&dir).ok();
    println!("{whole} datagrams whole, {truncated} truncated by the snap length");
    assert!(truncated > 100 && whole > 1000, "{whole} whole, {truncated} truncated");
}
