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
