//! EtherCAT over UDP on loopback: `ferrocat sim --udp` answers EtherCAT PDUs sent to it, drops
//! what is not one, and stops cleanly on SIGTERM.
use std::io::Read;
use std::net::UdpSocket;
use std::process::{Command, Stdio};
use std::time::Duration;

use ferrocat_wire::{Address, Command as Cmd, DatagramHeader, EcatPdu};

/// The simulator process, stopped whatever way the test ends.
struct Child(std::process::Child);

impl Drop for Child {
    fn drop(&mut self) {
        let _ = self.0.kill();
        let _ = self.0.wait();
    }
}

#[test]
fn sim_over_udp_on_loopback() {
    let report = std::env::temp_dir().join(format!("ferrocat-udp-report-{}.json", std::process::id()));
    let mut child = Child(
        Command::new(env!("CARGO_BIN_EXE_ferrocat"))
            .args(["sim", "--device", "EK1100", "--device", "EL2004", "--udp", "127.0.0.1:0", "--report"])
            .arg(&report)
            .stderr(Stdio::piped())
            .spawn()
            .unwrap(),
    );
    let mut err = child.0.stderr.take().unwrap();
    let mut seen = String::new();
    let mut b = [0u8; 256];
    let addr = loop {
        let n = err.read(&mut b).unwrap();
        assert!(n > 0, "sim exited: {seen}");
        seen += &String::from_utf8_lossy(&b[..n]);
        // A whole line: the address may arrive in two reads.
        if let Some(line) = seen.split_inclusive('\n').find(|l| l.contains(" on UDP ") && l.ends_with('\n')) {
            break line.trim_end().rsplit(' ').next().unwrap().to_string();
        }
    };
    let sock = UdpSocket::bind("127.0.0.1:0").unwrap();
    sock.set_read_timeout(Some(Duration::from_secs(2))).unwrap();
    sock.send_to(b"not an EtherCAT PDU at all", &addr).unwrap();
    // An EtherCAT PDU: header + one BRD of 0x0000.
    let mut pdu = vec![0u8; 2 + 12 + 2];
    ferrocat_wire::EcatHeader::dlpdu(14).emit(&mut pdu).unwrap();
    ferrocat_wire::datagram::emit_datagram(
        &mut pdu[2..],
        &DatagramHeader::new(Cmd::BRD, 7, Address::Device { adp: 0, ado: 0 }, 2),
        &[0, 0],
        0,
    )
    .unwrap();
    sock.send_to(&pdu, &addr).unwrap();
    let mut back = [0u8; 1500];
    let (n, _) = sock.recv_from(&mut back).expect("an answer");
    let reply = EcatPdu::parse(&back[..n]).unwrap();
    let d = reply.datagrams().next().unwrap();
    assert_eq!((d.header().index, d.wkc(), d.data()[0]), (7, 2, 0x11 | 0x12), "two slaves, ET1100 | ET1200");
    // The ferrocat master over UDP: a scan of the two slaves.
    let scan = Command::new(env!("CARGO_BIN_EXE_ferrocat")).args(["scan", "--json", "--udp", &addr]).output().unwrap();
    assert!(scan.status.success(), "{}", String::from_utf8_lossy(&scan.stderr));
    let slaves: serde_json::Value = serde_json::from_slice(&scan.stdout).unwrap();
    assert_eq!(
        slaves.as_array().unwrap().iter().map(|s| s["name"].as_str().unwrap()).collect::<Vec<_>>(),
        ["EK1100", "EL2004"]
    );
    Command::new("kill").args(["-TERM", &child.0.id().to_string()]).status().unwrap();
    assert!(child.0.wait().unwrap().success());
    let rep: serde_json::Value = serde_json::from_str(&std::fs::read_to_string(&report).unwrap()).unwrap();
    std::fs::remove_file(&report).ok();
    assert_eq!(rep["malformed"].as_u64(), Some(1), "{rep}");
    assert!(rep["frames_out"].as_u64().unwrap() > 10, "{rep}");
}
