//! The SII interface's busy time against real ESCs: every poll of the EEPROM status that
//! ethercrab made in its captures (recorded on Linux, with per-frame timestamps: the
//! replay-* files) and SOEM in its captures of EK1100s and EL1004s (on Windows, timestamps in
//! µs: soem-sdinfo-ek1100-*) is made again at the same offset from its read command, and the
//! busy bit must come back as the real one did.
mod common;

use common::Bus;
use ferrocat_wire::{Address, Command, Frame};

/// Each SII read command of a capture: the offsets (ns) of its status polls and whether the
/// real ESC answered busy.
fn reads(path: &std::path::Path) -> Vec<Vec<(u64, bool)>> {
    let bytes = std::fs::read(path).unwrap();
    let mut out = Vec::new();
    let mut open: std::collections::BTreeMap<u16, (u64, Vec<(u64, bool)>)> = Default::default();
    ferrocat_capture::for_each_packet(&bytes, |p| {
        let Ok(Some(f)) = Frame::parse(&p.data) else { return Ok(()) };
        let t = p.timestamp.as_nanos() as u64;
        for d in f.pdu.datagrams().filter(|d| d.wkc() > 0) {
            let Address::Device { adp, ado } = d.header().address else { continue };
            let data = d.data();
            let cmd = d.header().command;
            if matches!(cmd, Command::FPWR | Command::APWR) && ado == 0x0502 && data.len() >= 2 && data[1] & 0x01 != 0 {
                if let Some((_, polls)) = open.insert(adp, (t, Vec::new())) {
                    out.push(polls);
                }
            } else if matches!(cmd, Command::FPRD | Command::APRD)
                && ado <= 0x0502
                && (ado as usize + data.len()) > 0x0503
            {
                if let Some((t0, polls)) = open.get_mut(&adp) {
                    let at = (0x0502 - ado) as usize;
                    let busy = u16::from_le_bytes([data[at], data[at + 1]]) & 0x8000 != 0;
                    polls.push((t.saturating_sub(*t0), busy));
                    if !busy {
                        out.push(open.remove(&adp).unwrap().1);
                    }
                }
            }
        }
        Ok(())
    })
    .unwrap();
    out
}

#[test]
fn needs_shared_the_eeprom_is_busy_as_long_as_real_escs_were() {
    let reads: Vec<Vec<(u64, bool)>> = ferrocat_testdata::shared_files("captures", ".pcapng")
        .iter()
        .filter(|p| {
            p.file_name().is_some_and(|n| {
                let n = n.to_string_lossy();
                n.starts_with("replay-") || n.starts_with("soem-sdinfo-ek1100-")
            })
        })
        .flat_map(|p| reads(p))
        .collect();
    let dump = ferrocat_testdata::shared("captures/eeprom/ek1100.hex");
    let mut bus = Bus::addressed(&format!("[[device]]\neeprom = '{}'\n", dump.display()));
    let (mut polls, mut same) = (0usize, 0usize);
    for (k, read) in reads.iter().enumerate() {
        let word = (k % 64) as u32 * 2;
        let mut cmd = vec![0x00, 0x01];
        cmd.extend_from_slice(&word.to_le_bytes());
        let t0 = bus.t;
        assert_eq!(bus.fp(Command::FPWR, 0x1001, 0x0502, &cmd).1, 1, "read command");
        for &(dt, real_busy) in read {
            bus.t = bus.t.max(t0 + dt);
            let (d, _) = bus.fp(Command::FPRD, 0x1001, 0x0502, &[0; 2]);
            let ours = u16::from_le_bytes([d[0], d[1]]) & 0x8000 != 0;
            polls += 1;
            same += (ours == real_busy) as usize;
        }
        // Let the read finish before the next command.
        bus.t += 5_000_000;
    }
    let share = same as f64 / polls.max(1) as f64;
    println!(
        "{} SII reads, {polls} status polls: busy bit as the real ESC's in {same} ({:.1} %)",
        reads.len(),
        100.0 * share
    );
    assert!(polls > 1000, "the captures hold the polls");
    assert!(share >= 0.99, "busy bit as real in {:.1} % of polls", 100.0 * share);
}
