#![no_main]
//! Our master against a segment whose answers lie: every frame goes through a real simulated
//! segment (the coupler, I/O terminals and the CiA402 drive), and the input then tampers with
//! what comes back, one instruction per frame received — pass it, set one byte, cut it short
//! or drop it — as a faulty or hostile device, or a corrupting link whose NIC kept the frame,
//! would. The master brings the segment up (scan, CoE mapping, DC, OP), runs cycles and reads
//! the drive's dictionary. It may fail with an error at any point; it must not panic or hang.
//! An input whose first byte is odd closes the line into a ring back to the master's second
//! port and pulls the cable before the third device once the slaves are in OP: the frames of
//! both ports are tampered with, the far half served round the secondary port, its reference
//! kept on the reference's time from what the two passes read. If its second bit is set too,
//! the cable is pulled before the master starts instead (the far half latched as its own
//! tree, set up from the two passes, its ports auto-close) and put back 50 ms into the cycles
//! (the master opens the ring and latches the far half again). Its third bit enters the input
//! terminal (an ET1200) on port 1 with the drive behind its port 0, which the master latches
//! again (master/next_frame_latch.rs); its fourth makes the drive's controller an IP core.
//! Last, the drive's EoE: IP parameters set and read, a ping, and frames pumped between cycles.
use ferrocat_master::{DcConfig, EoePing, Master};
use ferrocat_segment::{Event, SegmentConfig};
use ferrocat_segment::{HostModel, Tamper, VirtualIo};
use ferrocat_wire::eoe::IpParameters;
use libfuzzer_sys::fuzz_target;

const SEGMENT: &str = r#"
seed = 3
[[device]]
builtin = "EK1100"
[[device]]
builtin = "EL2004"
[[device]]
builtin = "EL1004"
"#;

/// The input's instruction for the next frame received: pass it, set one byte, cut it short
/// or drop it; every frame passes once the script is used up.
fn tamper(script: &mut &[u8], buf: &mut [u8], n: usize) -> Option<usize> {
    let [op, lo, hi, value, rest @ ..] = *script else { return Some(n) };
    *script = rest;
    let at = u16::from_le_bytes([*lo, *hi]) as usize % n.max(1);
    match op % 4 {
        0 => Some(n),
        1 => {
            buf[at] = *value;
            Some(n)
        }
        2 => Some(at),
        _ => None,
    }
}

fuzz_target!(|data: &[u8]| {
    let Some((&mode, script)) = data.split_first() else { return };
    let ring = mode & 1 == 1;
    let split_first = ring && mode & 2 == 2;
    let entered = if mode & 4 != 0 { "port = 1\n" } else { "" };
    let esc = if mode & 8 != 0 { "esc = \"ipcore\"\n" } else { "" };
    let mut toml = format!("{SEGMENT}{entered}[[device]]\nbuiltin = \"SERVO\"\n{esc}");
    if ring {
        toml += "[secondary]\ndevice = 3\n";
    }
    let cfg: SegmentConfig = toml::from_str(&toml).expect("the fuzz segment parses");
    let mut seg = cfg.build().expect("the fuzz segment builds");
    if split_first {
        seg.schedule(0, Event::LinkDown { node: 2, port: 0 });
    }
    let mut script = script;
    let hook = move |buf: &mut [u8], n: usize, _: bool| tamper(&mut script, buf, n);
    let io = Tamper { inner: VirtualIo::new(seg, HostModel::ideal(), 1), hook };
    let mut m = Master::new(io);
    if m.states().scan().is_err() || m.states().configure().is_err() {
        return;
    }
    let dc = DcConfig { max_frames: 300, sync0_cycle_ns: 500_000, ..DcConfig::default() };
    let _ = m.dc().init_dc(&dc);
    if m.states().start().is_err() {
        return;
    }
    // A ring: its cable pulled now, and cycles enough for the far reference to be kept.
    let cycles = if ring {
        let now = m.cyclic().now_ns();
        let event = if split_first {
            (now + 50_000_000, Event::LinkUp { node: 2, port: 0 })
        } else {
            (now, Event::LinkDown { node: 2, port: 0 })
        };
        m.cyclic().io_mut().inner.seg.schedule(event.0, event.1);
        200
    } else {
        20
    };
    let mut next = m.cyclic().now_ns();
    for _ in 0..cycles {
        let _ = m.cyclic().cycle();
        let _ = m.dc().dc_monitor();
        if ring {
            next += 1_000_000;
            m.cyclic().sleep_until(next);
        }
    }
    let _ = m.states().supervise();
    // The drive's position: the last, or before the reversed terminal behind which it hangs.
    let drive = m.slaves().iter().position(|s| s.name() == "SERVO").unwrap_or(3) as u16;
    if let Ok(list) = m.acyclic().coe().od_list(drive) {
        for index in list.into_iter().take(16) {
            let _ = m.acyclic().coe().object_info(drive, index);
            let _ = m.acyclic().coe().sdo_read(drive, index, 0);
        }
    }
    let _ = m.acyclic().coe().sdo_write(drive, 0x6060, 0, &[8]);
    // EoE with the drive: its address set and read, a ping, and the pump between cycles.
    let params = IpParameters { mac: Some([2, 0, 0, 0, 0, 2]), ip: Some([10, 0, 0, 2]), ..Default::default() };
    let _ = m.acyclic().eoe().set_ip(drive, &params);
    let _ = m.acyclic().eoe().get_ip(drive);
    let p = EoePing {
        from_mac: [2, 0, 0, 0, 0, 1],
        from_ip: [10, 0, 0, 1],
        to_mac: [2, 0, 0, 0, 0, 2],
        to_ip: [10, 0, 0, 2],
    };
    let _ = m.acyclic().eoe().ping(drive, &p, 1, 200, 5_000_000);
    if let Ok(frame) = p.echo_request(2, &[7; 300]) {
        let _ = m.acyclic().eoe().queue(drive, &frame);
        for _ in 0..20 {
            let _ = m.cyclic().cycle();
            let _ = m.acyclic().eoe().pump(drive);
        }
    }
});
