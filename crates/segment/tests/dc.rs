//! The DC unit against the datasheet facts (esc-spec §3), observed through the wire.
mod common;

use common::Bus;
use ferrocat_segment::{MasterPort, SegmentConfig};
use ferrocat_wire::ethernet::{EthernetRepr, BROADCAST};
use ferrocat_wire::register::dc_activation as act;
use ferrocat_wire::{Address, Command, DatagramHeader, Frame, FrameWriter};

/// A line of `devices` on ESCs of kind `esc`, each with its SYNC out unit on (the terminals'
/// SIIs have it off, which leaves them receive times only).
fn line(devices: &[&str], esc: &str) -> Bus {
    let mut toml = String::from("seed = 3\n");
    for d in devices {
        toml += &format!("[[device]]\nbuiltin = '{d}'\nesc = '{esc}'\nsync_unit = true\n");
    }
    Bus::addressed(&toml)
}

#[test]
fn low_word_of_0918_equals_port0_time_and_write_latches_ports() {
    let mut bus = line(&["EK1100", "EL2004", "EL2004"], "et1100");
    assert_eq!(bus.tx(Command::BWR, Address::Device { adp: 0, ado: 0x0900 }, &[0; 4]).1, 3);
    for s in 0x1001..=0x1003 {
        let p0 = bus.fprd_u32(s, 0x0900);
        let epu = bus.fprd_u64(s, 0x0918);
        assert_eq!(epu as u32, p0, "slave {s:#x}");
    }
    // An APWR to 0x0900 counts but does not latch the ports (esc-spec §3.2).
    let before = bus.fprd_u32(0x1002, 0x0904);
    assert_eq!(bus.tx(Command::APWR, Address::position(1, 0x0900), &[0; 4]).1, 1);
    assert_eq!(bus.fprd_u32(0x1002, 0x0904), before);
    // Ports 1–3's receive times are read-only (datasheet II, 0x0904–0x090F r/-): a write that
    // misses 0x0900 leaves them and latches nothing.
    let (times, _) = bus.fp(Command::FPRD, 0x1002, 0x0900, &[0; 16]);
    assert_eq!(
        bus.fp(Command::FPWR, 0x1002, 0x0904, &[0xA5; 12]).1,
        0,
        "a write of read-only bytes only does not count"
    );
    assert_eq!(bus.fp(Command::FPRD, 0x1002, 0x0900, &[0; 16]).0, times);
}

#[test]
fn a_write_counts_only_where_one_of_its_bytes_is_writable() {
    // Eight real captures: a BWR of 0x092C (system time difference, r/-) alone comes back with
    // WKC 0 from ESCs that have it, while one of 0x0928 (delay) counts each of them.
    let mut bus = line(&["EK1100", "EL2004"], "et1100");
    let bwr =
        |bus: &mut Bus, ado: u16, len: usize| bus.tx(Command::BWR, Address::Device { adp: 0, ado }, &vec![0; len]).1;
    assert_eq!(bwr(&mut bus, 0x092C, 4), 0);
    assert_eq!(bwr(&mut bus, 0x0928, 4), 2);
    // A write that spans writable and read-only bytes counts (TwinCAT's BWR of 0x0910–0x092F).
    assert_eq!(bwr(&mut bus, 0x0910, 32), 2);
    assert_eq!(bus.fp(Command::FPWR, 0x1002, 0x0000, &[0; 8]).1, 0, "type, revision, build, counts: read-only");
    assert_eq!(bus.fp(Command::FPWR, 0x1002, 0x0130, &[0; 2]).1, 0, "AL status: read-only");
    assert_eq!(bus.fp(Command::FPWR, 0x1002, 0x0120, &[0x01, 0]).1, 1, "AL control: writable");
}

#[test]
fn ecat_read_of_0910_subtracts_the_delay_and_a_write_does_not_overwrite() {
    let mut bus = line(&["EK1100", "EL2004"], "et1100");
    let delay = 12_345u32;
    assert_eq!(bus.fp(Command::FPWR, 0x1002, 0x0928, &delay.to_le_bytes()).1, 1);
    let read = bus.fprd_u64(0x1002, 0x0910);
    let (node, timing) = bus.seg.last_visits()[1];
    assert_eq!(node, 1);
    let dc = bus.seg.nodes[1].esc.dc.as_ref().unwrap();
    assert_eq!(read, dc.system_at(timing.epu_ns) - delay as u64);
    // A write is a sample for the control loop; the register keeps counting.
    let far = 0x7777_0000_0000u64;
    bus.fp(Command::FPWR, 0x1002, 0x0910, &far.to_le_bytes());
    let after = bus.fprd_u64(0x1002, 0x0910);
    assert!(after > read && after < read + 1_000_000, "{after} vs {read}");
    assert!(bus.fprd_u32(0x1002, 0x092C) & 0x7FFF_FFFF > 0, "the sample shows in 0x092C");
}

#[test]
fn a_system_time_write_is_compared_with_the_time_latched_at_start_of_frame() {
    // esc-spec 0x0910: the value written is compared, at the end of the frame, with the local
    // copy latched at SOF — with the offset and delay in force then, not with the ones the
    // same frame writes (those apply at its end).
    let diff_after = |also_offset: bool| {
        let mut bus = line(&["EK1100", "EL2004"], "et1100");
        let now = bus.fprd_u64(0x1002, 0x0910);
        // A time 1 µs behind what the slave will read: its difference becomes positive.
        let sample = (now + 30_000 - 1_000).to_le_bytes();
        let (offset, delay) = (5_000_000u64.to_le_bytes(), 7_000u32.to_le_bytes());
        let at = |ado| Address::Device { adp: 0x1002, ado };
        let mut frame: Vec<(Command, Address, &[u8])> = vec![(Command::FPWR, at(0x0910), &sample)];
        if also_offset {
            frame.push((Command::FPWR, at(0x0920), &offset));
            frame.push((Command::FPWR, at(0x0928), &delay));
        }
        bus.t += 20_000;
        assert!(bus.tx_all(&frame).iter().all(|(_, w, _)| *w == 1));
        bus.fprd_u32(0x1002, 0x092C)
    };
    let alone = diff_after(false);
    assert!(alone != 0, "the sample shows in 0x092C");
    assert_eq!(diff_after(true), alone);
}

#[test]
fn writing_0930_resets_the_filters() {
    let mut bus = line(&["EK1100", "EL2004"], "et1100");
    // FRMW of the reference's time into the second slave, a few hundred times.
    for _ in 0..300 {
        bus.tx(Command::FRMW, Address::Device { adp: 0x1001, ado: 0x0910 }, &[0; 8]);
    }
    let diff = bus.fprd_u32(0x1002, 0x092C);
    let (scd, _) = bus.fp(Command::FPRD, 0x1002, 0x0932, &[0; 2]);
    assert!(diff != 0 || scd != [0, 0], "the loop ran");
    assert_eq!(bus.fp(Command::FPWR, 0x1002, 0x0930, &0x1000u16.to_le_bytes()).1, 1);
    assert_eq!(bus.fprd_u32(0x1002, 0x092C), 0);
    assert_eq!(bus.fp(Command::FPRD, 0x1002, 0x0932, &[0; 2]).0, [0, 0]);
}

#[test]
fn sync0_fires_on_the_system_time_grid() {
    let mut bus = line(&["EK1100", "EL2004"], "et1100");
    let now = bus.fprd_u64(0x1002, 0x0910);
    let cycle = 250_000u64;
    let start = (now / cycle + 4) * cycle;
    bus.fp(Command::FPWR, 0x1002, 0x0981, &[0]);
    bus.fp(Command::FPWR, 0x1002, 0x09A0, &(cycle as u32).to_le_bytes());
    bus.fp(Command::FPWR, 0x1002, 0x0990, &start.to_le_bytes());
    bus.fp(Command::FPWR, 0x1002, 0x0981, &[act::CYCLIC_OPERATION | act::SYNC0]);
    let t = bus.t + 20 * cycle;
    bus.seg.advance_to(t);
    let esc = &bus.seg.nodes[1].esc;
    assert!(esc.sync0_log.count >= 15, "{} pulses", esc.sync0_log.count);
    let dc = esc.dc.as_ref().unwrap();
    for &(sys, true_ns) in &esc.sync0_log.pulses {
        assert_eq!((sys - start) % cycle, 0, "pulse {sys} off the grid");
        // At the pulse's true instant the system time has just reached it.
        let at = dc.system_at(true_ns);
        assert!(at >= sys && at - sys <= 10, "system time {at} at the pulse for {sys}");
    }
    let sys_now = dc.system_at(t);
    // 0x0990 reads the next pulse.
    let next = bus.fprd_u64(0x1002, 0x0990);
    assert_eq!((next - start) % cycle, 0);
    assert!(next > sys_now);
}

/// SYNC1 on SYNC0's grid (ESC datasheet section I 9.2.3.5): 0x0998 reads the next SYNC1 pulse,
/// 0x0984 bit 1 is set until the first. A SYNC1 time shorter than the SYNC0 cycle is a shift
/// after every SYNC0 pulse; a longer one repeats at the smallest multiple of the SYNC0 cycle
/// that is not shorter.
#[test]
fn sync1_follows_sync0_by_its_cycle_time() {
    let cycle0 = 250_000u64;
    for (cycle1, period) in
        [(50_000u64, 250_000u64), (0, 250_000), (250_000, 250_000), (500_000, 500_000), (600_000, 750_000)]
    {
        let mut bus = line(&["EK1100", "EL2004"], "et1100");
        let now = bus.fprd_u64(0x1002, 0x0910);
        let start = (now / cycle0 + 4) * cycle0;
        bus.fp(Command::FPWR, 0x1002, 0x0981, &[0]);
        bus.fp(Command::FPWR, 0x1002, 0x09A0, &(cycle0 as u32).to_le_bytes());
        bus.fp(Command::FPWR, 0x1002, 0x09A4, &(cycle1 as u32).to_le_bytes());
        bus.fp(Command::FPWR, 0x1002, 0x0990, &start.to_le_bytes());
        bus.fp(Command::FPWR, 0x1002, 0x0981, &[act::CYCLIC_OPERATION | act::SYNC0 | act::SYNC1]);
        assert_eq!(bus.fprd_u64(0x1002, 0x0998), start + cycle1, "cycle1 {cycle1}: the first SYNC1");
        if cycle1 == 600_000 {
            // SYNC1 alone: SYNC0's pulses still time it but raise no SYNC0 signal.
            bus.fp(Command::FPWR, 0x1002, 0x0981, &[act::CYCLIC_OPERATION | act::SYNC1]);
        }
        assert_eq!(bus.fp(Command::FPRD, 0x1002, 0x0984, &[0]).0[0] & 0b11, 0b11, "both first pulses pending");
        for k in 1..=12 {
            bus.t += 173_000 * k;
            let sys = bus.fprd_u64(0x1002, 0x0910);
            let next1 = bus.fprd_u64(0x1002, 0x0998);
            let status = bus.fp(Command::FPRD, 0x1002, 0x0984, &[0]).0[0];
            assert_eq!((next1 - start - cycle1) % period, 0, "cycle1 {cycle1}: {next1} off the SYNC1 grid");
            // The read of 0x0998 is a few µs after that of 0x0910: allow one frame between.
            let first = start + cycle1;
            assert!(
                next1 + 10_000 > sys && next1 <= sys.max(first) + period + 10_000,
                "cycle1 {cycle1}: next {next1} at {sys}"
            );
            if sys.abs_diff(first) > 10_000 {
                assert_eq!(status & 0b10 != 0, sys < first, "cycle1 {cycle1}: pending bit at {sys}");
            }
        }
        let log = &bus.seg.nodes[1].esc.sync0_log;
        let seen = log.count - log.merged;
        assert!(log.count > 40, "cycle1 {cycle1}: {} SYNC0 pulses", log.count);
        assert_eq!(seen == 0, cycle1 == 600_000, "cycle1 {cycle1}: {seen} SYNC0 edges");
    }
}

#[test]
fn a_32_bit_dc_wraps() {
    let mut bus = line(&["EK1100", "EL2004"], "esc20");
    // Put the system time 1 ms before the 32-bit wrap.
    let now = bus.fprd_u32(0x1002, 0x0910);
    let offset = (u32::MAX - 1_000_000).wrapping_sub(now);
    bus.fp(Command::FPWR, 0x1002, 0x0920, &offset.to_le_bytes());
    let a = bus.fprd_u32(0x1002, 0x0910);
    bus.t += 2_000_000;
    let b = bus.fprd_u32(0x1002, 0x0910);
    assert!(a > 0xFFF0_0000 && b < 0x0020_0000, "{a:#x} then {b:#x}");
    let elapsed = b.wrapping_sub(a);
    assert!((2_000_000..2_100_000).contains(&elapsed), "2 ms (and a frame) later across the wrap: {elapsed} ns");
    // 8-byte reads of the 32-bit system time: the upper half does not exist.
    let (d, _) = bus.fp(Command::FPRD, 0x1002, 0x0910, &[0; 8]);
    assert_eq!(&d[4..], &[0, 0, 0, 0]);
}

#[test]
fn latch_inputs_single_event_and_continuous() {
    let mut bus = line(&["EK1100", "EL2004"], "et1100");
    // Unit 0: rising edge single event, falling edge continuous.
    bus.fp(Command::FPWR, 0x1002, 0x09A8, &[0x01]);
    let t = bus.t;
    let esc = &mut bus.seg.nodes[1].esc;
    esc.latch_input(0, true, t + 1_000);
    let first = esc.dc.as_ref().unwrap().system_at(t + 1_000);
    esc.latch_input(0, false, t + 2_000);
    esc.latch_input(0, true, t + 3_000); // ignored: the first rising edge is not read yet
    esc.latch_input(0, false, t + 4_000);
    let last_fall = esc.dc.as_ref().unwrap().system_at(t + 4_000);
    bus.t = t + 10_000;
    let (st, _) = bus.fp(Command::FPRD, 0x1002, 0x09AE, &[0]);
    assert_eq!(st[0] & 0x01, 0x01, "rising event pending");
    assert_eq!(bus.fprd_u64(0x1002, 0x09B0), first, "the first rising edge kept");
    assert_eq!(bus.fprd_u64(0x1002, 0x09B8), last_fall, "continuous: the latest falling edge");
    let (st, _) = bus.fp(Command::FPRD, 0x1002, 0x09AE, &[0]);
    assert_eq!(st[0] & 0x01, 0, "reading the time cleared the event");
}

#[test]
fn a_watch_sees_each_clock_at_its_instant_whatever_frames_passed_since() {
    // Two identical segments; one frame moves the second slave's offset by 1 ms, its twin
    // only reads. A watch placed between the send and the frame's passage holds the clock
    // from before the write, one after it the clock with the write, in both segments alike.
    let mut a = line(&["EK1100", "EK1100"], "et1100");
    let mut b = line(&["EK1100", "EK1100"], "et1100");
    let offset = a.fprd_u64(0x1002, 0x0920);
    assert_eq!(offset, b.fprd_u64(0x1002, 0x0920));
    let t = a.t;
    assert_eq!(t, b.t);
    let (before, after) = (t + 100, t + 50_000_000);
    for bus in [&mut a, &mut b] {
        bus.seg.watch(before);
        bus.seg.watch(after);
    }
    let moved = offset + 1_000_000;
    a.fp(Command::FPWR, 0x1002, 0x0920, &moved.to_le_bytes());
    b.fp(Command::FPRD, 0x1002, 0x0920, &[0; 8]);
    let (wa, wb) = (a.seg.watched().expect("every clock passed"), b.seg.watched().expect("every clock passed"));
    assert_eq!(wa.at_ns, before);
    assert_eq!(wa, wb, "the write came after the instant");
    let dc = b.seg.nodes[1].esc.dc.as_ref().unwrap();
    assert_eq!(wb.system_ns[1], Some(dc.system_at(before)));
    // Nothing has reached the second instant yet; the next frame fills it in, or the end of a run.
    assert!(a.seg.watched().is_none());
    a.t = after + 1;
    a.fp(Command::FPRD, 0x1002, 0x0920, &[0; 8]);
    let wa = a.seg.watched().expect("the next frame passed every clock");
    let wb = b.seg.watched_now().expect("read as the clocks stand");
    assert_eq!(wa.at_ns, after);
    assert_eq!(wa.system_ns[0], wb.system_ns[0], "the first slave was not written");
    assert_eq!(wa.system_ns[1].unwrap() - wb.system_ns[1].unwrap(), 1_000_000);
}

/// A single EL2004 (ET1100-like ESC) whose EEPROM words 1 and 2 — PDI configuration
/// (0x0150–0x0151) and SYNC pulse length (0x0982) — are patched, and whose AL control a
/// firmware answers (device emulation off in word 0).
fn patched_terminal(pdi_config: u16, pulse_10ns: u16) -> Bus {
    common::patched_device(&mut line(&["EL2004"], "et1100"), 0x1001, |h| {
        h.pdi_config = pdi_config;
        h.pdi_control &= !0x0100; // no device emulation: a firmware answers AL control
        h.sync_impulse_len = pulse_10ns;
    })
}

/// SYNC0/SYNC1 status (0x098E/0x098F) and the AL event request (0x0220) read by the master at
/// chosen instants: in acknowledge mode (pulse length 0) a SYNC signal is active from its pulse
/// until the firmware reads its status register (1 µs later in our model); with 0x0151 bits 3
/// and 7 set (as in the HBM ClipX dump's 0xCC) 0x0220 bits 2 and 3 follow them; bit 0 is set
/// while the firmware has not yet read a write of AL control. In pulse mode the status reads 0.
#[test]
fn sync_status_in_acknowledge_mode_and_the_al_event_request() {
    for pulse_10ns in [0u16, 100] {
        let mut bus = patched_terminal(0x8800, pulse_10ns);
        let s = 0x1001;
        assert_eq!(bus.fp(Command::FPRD, s, 0x0982, &[0; 2]).0, pulse_10ns.to_le_bytes());
        let (cycle0, shift1) = (250_000u64, 100_000u64);
        let start = (bus.fprd_u64(s, 0x0910) / cycle0 + 4) * cycle0;
        bus.fp(Command::FPWR, s, 0x0981, &[0]);
        bus.fp(Command::FPWR, s, 0x09A0, &(cycle0 as u32).to_le_bytes());
        bus.fp(Command::FPWR, s, 0x09A4, &(shift1 as u32).to_le_bytes());
        bus.fp(Command::FPWR, s, 0x0990, &start.to_le_bytes());
        bus.fp(Command::FPWR, s, 0x0981, &[act::CYCLIC_OPERATION | act::SYNC0 | act::SYNC1]);
        bus.t += 2_000_000;
        // How long after its sending a frame passes the slave.
        let probe_at = bus.t;
        bus.fp(Command::FPRD, s, 0x0000, &[0; 2]);
        let lead = bus.seg.last_visits()[0].1.epu_ns - probe_at;
        bus.seg.advance_to(bus.t);
        let pulse = bus.seg.nodes[0].esc.dc.as_ref().unwrap().next_sync0_true(bus.t + 50_000).unwrap();
        // (0x098E, 0x098F, 0x0220) read by one frame that passes the slave at `at`.
        let read_at = |bus: &mut Bus, at: u64| {
            bus.t = at - lead;
            let r = bus.tx_all(&[
                (Command::FPRD, Address::Device { adp: s, ado: 0x098E }, &[0; 2]),
                (Command::FPRD, Address::Device { adp: s, ado: 0x0220 }, &[0; 4]),
            ]);
            assert_eq!(bus.seg.last_visits()[0].1.epu_ns, at);
            (r[0].0[0], r[0].0[1], u32::from_le_bytes(r[1].0[..4].try_into().unwrap()))
        };
        let ack = pulse_10ns == 0;
        let on = |b: bool, v: u8| if b { v } else { 0 };
        // A frame takes ≈ 6 µs on the wire: one read per pulse. The slave's clock runs within
        // ppm of true time, tens of ns over these cycles.
        let p = |k: u64| pulse + k * cycle0;
        assert_eq!(
            read_at(&mut bus, p(0) + 300),
            (on(ack, 1), 0, on(ack, 0b0100) as u32),
            "pulse {pulse_10ns}: SYNC0 just fired"
        );
        assert_eq!(read_at(&mut bus, p(1) + 1_500), (0, 0, 0), "pulse {pulse_10ns}: acknowledged");
        assert_eq!(
            read_at(&mut bus, p(2) + shift1 + 300),
            (0, on(ack, 1), on(ack, 0b1000) as u32),
            "pulse {pulse_10ns}: SYNC1"
        );
        assert_eq!(read_at(&mut bus, p(3) + shift1 + 1_500), (0, 0, 0), "pulse {pulse_10ns}: SYNC1 acknowledged");
        // AL control written: bit 0 until the firmware has read it (≈ 1 ms).
        bus.fp(Command::FPWR, s, 0x0120, &[0x02, 0x00]);
        let t = bus.t + 10_000;
        assert_eq!(read_at(&mut bus, t + lead).2 & 1, 1, "AL control not yet read");
        let t = bus.t + 2_000_000;
        assert_eq!(read_at(&mut bus, t + lead).2 & 1, 0, "read by the firmware");
    }
}

/// An ET1100 or ET1200 whose SYNC out and latch in units are off (0x0141 bits 2–3; SII word 0 =
/// 0x0104 on the real EL1004, EL2004 and EL2828) answers its receive times but not its system
/// time, not even 0x0918: SOEM's FPRD 0x0918 of a real EL1004 came back with WKC 0, TwinCAT's
/// BWRs of 0x0910, 0x0930, 0x0934 and 0x0981 counted only the EK1100; ethercrab's four captures
/// of an EK1914 (an ET1100: features 0x00FC, 8 FMMUs and SyncManagers) show it the same. Either
/// unit turns the system time on; a DC-synchronous application turns the SYNC unit on.
#[test]
fn an_et1100_or_et1200_without_sync_and_latch_units_has_receive_times_only() {
    // The EL2004's SII has both units off (word 0 = 0x0104), the EK1100's on (0x0D00): on
    // either ASIC the SII decides, as the real EL1004/EL2828 (ET1200) and EK1914 (ET1100) show.
    let toml = "seed = 3\n[[device]]\nbuiltin = 'EK1100'\n[[device]]\nbuiltin = 'EL2004'\n\
                [[device]]\nbuiltin = 'EL2004'\napp = 'dc'\n[[device]]\nbuiltin = 'EL1004'\nesc = 'et1100'\n\
                [[device]]\nbuiltin = 'EL1004'\nesc = 'et1100'\nlatch_unit = true\n\
                [[device]]\nbuiltin = 'EK1100'\nsync_unit = false\nlatch_unit = false\n";
    let cfg: SegmentConfig = toml::from_str(toml).unwrap();
    let mut bus = Bus::new(cfg.build().unwrap());
    bus.address_all();
    let units: Vec<u8> = (0x1001..=0x1006).map(|s| bus.fp(Command::FPRD, s, 0x0141, &[0]).0[0] & 0x0C).collect();
    assert_eq!(units, [0x0C, 0, 0x04, 0, 0x08, 0], "SYNC and latch units from the SII and the overrides");
    assert_eq!(bus.tx(Command::BWR, Address::Device { adp: 0, ado: 0x0900 }, &[0; 4]).1, 6, "receive times: all");
    for s in [0x1002, 0x1004, 0x1006] {
        assert_ne!(bus.fprd_u32(s, 0x0900), 0, "{s:#06x} latched its port 0");
    }
    for (ado, len) in [(0x0910u16, 8usize), (0x0918, 8), (0x0920, 8), (0x0928, 4), (0x092C, 4), (0x0981, 1)] {
        let wkc: Vec<u16> = (0x1001..=0x1006).map(|s| bus.fp(Command::FPRD, s, ado, &vec![0; len]).1).collect();
        assert_eq!(wkc, [1, 0, 1, 0, 1, 0], "{ado:#06x}");
    }
    assert_eq!(bus.tx(Command::BWR, Address::Device { adp: 0, ado: 0x0930 }, &0x1000u16.to_le_bytes()).1, 3);
    let has: Vec<bool> = bus.seg.nodes.iter().map(|n| n.esc.has_system_time()).collect();
    assert_eq!(has, [true, false, true, false, true, false]);
}

/// Beckhoff's own ESI describes the same switch on its couplers: the EK1100 and EK1122 up to
/// revision 0x0010 carry ConfigData 0x0001 (SYNC and latch units off), from 0x0011 on 0x000D.
/// Built from that file, an EK1100 of revision 0x00100000 latches receive times but has no
/// system time (so it cannot be the reference clock), one of 0x00110000 has one.
#[test]
fn needs_shared_an_early_ek1100_from_beckhoffs_esi_has_receive_times_only() {
    let esi = ferrocat_testdata::shared("esi/Beckhoff_EK11xx.xml");
    let toml = format!(
        "seed = 3\n[[device]]\nesi = '{0}'\nproduct = 0x044C2C52\nrevision = 0x00100000\n\
         [[device]]\nesi = '{0}'\nproduct = 0x044C2C52\nrevision = 0x00110000\n",
        esi.display()
    );
    let mut bus = Bus::addressed(&toml);
    let units: Vec<u8> = (0x1001..=0x1002).map(|s| bus.fp(Command::FPRD, s, 0x0141, &[0]).0[0]).collect();
    assert_eq!(units, [0x01, 0x0D], "ESC configuration from the ESI's ConfigData");
    assert_eq!(bus.tx(Command::BWR, Address::Device { adp: 0, ado: 0x0900 }, &[0; 4]).1, 2, "receive times: both");
    let wkc: Vec<u16> = (0x1001..=0x1002).map(|s| bus.fp(Command::FPRD, s, 0x0910, &[0; 8]).1).collect();
    assert_eq!(wkc, [0, 1], "system time: the later revision only");
    let has: Vec<bool> = bus.seg.nodes.iter().map(|n| n.esc.has_system_time()).collect();
    assert_eq!(has, [false, true]);
}

/// A coupler, then a device of kind `esc` entered on its port 1 with a terminal behind its
/// port 0 (processing order: coupler, terminal, device at 0x1003).
fn reversed(esc: &str) -> Bus {
    Bus::addressed(&format!(
        "seed = 4\n[[device]]\nname = 'c'\nbuiltin = 'EK1100'\n\
         [[device]]\nname = 'x'\nbuiltin = 'SERVO'\nesc = '{esc}'\nparent = 'c'\nparent_port = 2\nport = 1\n\
         [[device]]\nbuiltin = 'SERVO'\nparent = 'x'\nparent_port = 0\n"
    ))
}

/// Port 1 less port 0 of station `st`, as one read sees them.
fn port1_less_port0(bus: &mut Bus, st: u16) -> i64 {
    let (t, _) = bus.fp(Command::FPRD, st, 0x0900, &[0; 8]);
    let p = |k: usize| u32::from_le_bytes(t[4 * k..4 * k + 4].try_into().unwrap());
    p(1).wrapping_sub(p(0)) as i32 as i64
}

#[test]
fn which_frame_ports_1_to_3_latch_by_controller() {
    // Entered on port 1, the frame reaches port 1 before the processing unit sees the write,
    // and port 0 (coming back from the terminal) just before it.
    // An ET1100 takes the writing frame at every port: port 1 before port 0.
    let mut bus = reversed("et1100");
    bus.tx(Command::BWR, Address::Device { adp: 0, ado: 0x0900 }, &[0; 4]);
    let same = port1_less_port0(&mut bus, 0x1003);
    assert!((-3_000..0).contains(&same), "{same}");
    // An ET1200 or ESC20 only enables port 1: the read's own frame is the next it receives
    // (reads run before the frame's end), a frame later; the one after finds it disabled.
    for esc in ["esc20", "ipcore"] {
        let mut bus = reversed(esc);
        bus.tx(Command::BWR, Address::Device { adp: 0, ado: 0x0900 }, &[0; 4]);
        let next = port1_less_port0(&mut bus, 0x1003);
        assert!(next > 0, "{esc}: {next}");
        assert_eq!(port1_less_port0(&mut bus, 0x1003), next, "{esc}: port 1 takes one frame");
        // Enabled again, port 1 takes the next frame, which reads it and then writes: port 0
        // takes that frame too. Port 1 and port 0 of one frame, read across two frames.
        bus.tx(Command::BWR, Address::Device { adp: 0, ado: 0x0900 }, &[0; 4]);
        let both = bus.tx_all(&[
            (Command::FPRD, Address::Device { adp: 0x1003, ado: 0x0904 }, &[0; 4]),
            (Command::BWR, Address::Device { adp: 0, ado: 0x0900 }, &[0; 4]),
        ]);
        let p1 = u32::from_le_bytes(both[0].0[..4].try_into().unwrap());
        let p0 = bus.fprd_u32(0x1003, 0x0900);
        assert_eq!(p1.wrapping_sub(p0) as i32 as i64, same, "{esc}: the geometry of one frame");
    }
    // The IP core in reverse mode (0x0936 = 1) takes the last frame each port received
    // before the write: here the writing frame itself.
    let mut bus = reversed("ipcore");
    bus.tx(Command::BWR, Address::Device { adp: 0, ado: 0x0936 }, &[1]);
    bus.tx(Command::BWR, Address::Device { adp: 0, ado: 0x0900 }, &[0; 4]);
    assert_eq!(port1_less_port0(&mut bus, 0x1003), same);
}

#[test]
fn an_ip_core_in_reverse_mode_gives_the_ports_after_its_processing_unit_an_older_frame() {
    let mut bus = line(&["EK1100", "SERVO", "SERVO"], "ipcore");
    // Forwarding mode: port 1 takes the writing frame coming back, after port 0.
    bus.tx(Command::BWR, Address::Device { adp: 0, ado: 0x0900 }, &[0; 4]);
    let forwarding = port1_less_port0(&mut bus, 0x1002);
    assert!((0..5_000).contains(&forwarding), "{forwarding}");
    bus.tx(Command::BWR, Address::Device { adp: 0, ado: 0x0936 }, &[1]);
    bus.tx(Command::BWR, Address::Device { adp: 0, ado: 0x0900 }, &[0; 4]);
    let reverse = port1_less_port0(&mut bus, 0x1002);
    assert!(reverse < 0, "the frame before the write came back before this one came in: {reverse}");
}

#[test]
fn a_frame_that_only_passes_a_port_is_the_one_an_enabled_port_takes() {
    // An intact ring: the primary's frames leave by the last device's port 1 and never come
    // back through the middle one's port 1; the secondary's run the ring backwards through
    // every port 1 to port 0 without reaching a processing unit.
    for (esc, taken) in [("esc20", true), ("et1100", false)] {
        let mut bus = Bus::addressed(&format!(
            "seed = 4\n[[device]]\nname = 'c'\nbuiltin = 'EK1100'\n\
             [[device]]\nbuiltin = 'SERVO'\nesc = '{esc}'\nparent = 'c'\nparent_port = 2\n\
             [[device]]\nbuiltin = 'SERVO'\n[secondary]\ndevice = 2\n"
        ));
        bus.tx(Command::BWR, Address::Device { adp: 0, ado: 0x0900 }, &[0; 4]);
        let before = bus.fprd_u32(0x1002, 0x0904);
        // A broadcast read from the secondary port.
        let eth = EthernetRepr { dst: BROADCAST, src: [0x12; 6], vlan_tci: None, ethertype: 0 };
        let mut buf = [0u8; 128];
        let mut w = FrameWriter::new(&mut buf, &eth).unwrap();
        w.push_chained(&DatagramHeader::new(Command::BRD, 1, Address::Device { adp: 0, ado: 0 }, 2), &[0, 0], 0)
            .unwrap();
        let n = w.finish().unwrap();
        let (port, back) = bus.seg.exchange_on(MasterPort::Secondary, &mut buf[..n], bus.t).expect("round the ring");
        assert_eq!(port, MasterPort::Primary);
        let wkc = Frame::parse(&buf[..n]).unwrap().unwrap().pdu.datagrams().next().unwrap().wkc();
        assert_eq!(wkc, 0, "no processing unit saw it");
        bus.t = back + 10_000;
        let after = bus.fprd_u32(0x1002, 0x0904);
        assert_eq!(after != before, taken, "{esc}: port 1 {before} then {after}");
        // Taken once: the next one passes it by.
        if taken {
            bus.seg.exchange_on(MasterPort::Secondary, &mut buf[..n], bus.t + 50_000).unwrap();
            bus.t += 100_000;
            assert_eq!(bus.fprd_u32(0x1002, 0x0904), after, "{esc}");
        }
    }
}
