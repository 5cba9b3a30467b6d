//! The acyclic side of a running master (`Acyclic::submit`, `serve_requests`): SDO transfers,
//! SDO information, registers and state requests served in the cycles' spare time while the
//! cyclic exchange goes on whole, and each bad request answered with its error.
use ferrocat_master::{AlState, Answer, Master, MasterError, Request, RequestError, RequestId};
use ferrocat_segment::SegmentConfig;
use ferrocat_segment::{HostModel, VirtualIo};
use ferrocat_wire::register::addr;

const CYCLE_NS: u64 = 1_000_000;

/// EK1100, EL2004 and a SERVO in OP.
fn running() -> Master<VirtualIo> {
    let cfg: SegmentConfig = toml::from_str(
        "[[device]]\nbuiltin = 'EK1100'\n[[device]]\nbuiltin = 'EL2004'\n[[device]]\nbuiltin = 'SERVO'\n",
    )
    .unwrap();
    let mut m = Master::new(VirtualIo::new(cfg.build().unwrap(), HostModel::pc_rt(), 7));
    m.states().bring_up().unwrap();
    m
}

/// Cycles until `id` is answered (at most `limit` cycles), serving requests in each cycle's
/// first three quarters; the answer, and the cycles whose working counter was short.
fn cycle_until(m: &mut Master<VirtualIo>, id: RequestId, limit: u32) -> (Result<Answer, MasterError>, u32) {
    let mut next = m.cyclic().now_ns();
    let mut short = 0;
    for _ in 0..limit {
        next += CYCLE_NS;
        if m.cyclic().cycle().unwrap() != m.image().expected_wkc() {
            short += 1;
        }
        m.acyclic().serve_requests(next - CYCLE_NS / 4).unwrap();
        if let Some((_, a)) = m.acyclic().take_answers().into_iter().find(|(k, _)| *k == id) {
            return (a, short);
        }
        m.cyclic().sleep_until(next);
    }
    panic!("request {id:?} not answered in {limit} cycles");
}

#[test]
fn sdo_transfers_and_information_are_served_beside_a_whole_cycle() {
    let mut m = running();
    let id = m.acyclic().submit(Request::SdoRead { position: 2, index: 0x1018, subindex: 1, complete_access: false });
    let (a, short) = cycle_until(&mut m, id, 200);
    let vendor = m.slaves()[2].identity().vendor_id;
    assert_eq!(a.unwrap(), Answer::Data(vendor.to_le_bytes().to_vec()));
    assert_eq!(short, 0);

    // A write, then the value read back (0x10F1:02, the sync error counter limit).
    let id = m.acyclic().submit(Request::SdoWrite {
        position: 2,
        index: 0x10F1,
        subindex: 2,
        complete_access: false,
        data: vec![5, 0],
    });
    assert_eq!(cycle_until(&mut m, id, 200).0.unwrap(), Answer::Written);
    let id = m.acyclic().submit(Request::SdoRead { position: 2, index: 0x10F1, subindex: 2, complete_access: false });
    assert_eq!(cycle_until(&mut m, id, 200).0.unwrap(), Answer::Data(vec![5, 0]));

    // A string longer than an expedited transfer's 4 bytes (the device name).
    let id = m.acyclic().submit(Request::SdoRead { position: 2, index: 0x1008, subindex: 0, complete_access: false });
    let Answer::Data(name) = cycle_until(&mut m, id, 200).0.unwrap() else { panic!() };
    assert!(name.len() > 4, "{name:?}");

    let id = m.acyclic().submit(Request::EntryInfo { position: 2, index: 0x6060, subindex: 0 });
    let Answer::Entry(e) = cycle_until(&mut m, id, 200).0.unwrap() else { panic!() };
    assert_eq!(e.bit_length, 8);
    let id = m.acyclic().submit(Request::OdList { position: 2 });
    let Answer::List(list) = cycle_until(&mut m, id, 400).0.unwrap() else { panic!() };
    assert!(list.contains(&0x1018) && list.contains(&0x6060), "{list:x?}");
    let s = m.acyclic().acyclic_stats();
    assert_eq!((s.answered, s.failed), (6, 0));
    assert_eq!(m.diagnosis().cycle_stats().wkc_errors, 0);
}

#[test]
fn an_abort_and_a_slave_without_coe_are_answers_not_errors_of_the_loop() {
    let mut m = running();
    let id = m.acyclic().submit(Request::SdoRead { position: 2, index: 0x5FFF, subindex: 0, complete_access: false });
    let (a, short) = cycle_until(&mut m, id, 200);
    assert!(matches!(a, Err(MasterError::Abort { position: 2, index: 0x5FFF, .. })), "{a:?}");
    assert_eq!(short, 0);
    let id = m.acyclic().submit(Request::SdoRead { position: 0, index: 0x1018, subindex: 1, complete_access: false });
    let a = cycle_until(&mut m, id, 10).0;
    assert!(a.as_ref().is_err_and(|e| e.to_string().contains("has no mailbox")), "{a:?}");
    let id = m.acyclic().submit(Request::RegisterRead { position: 9, register: 0, len: 2 });
    let a = cycle_until(&mut m, id, 10).0;
    assert!(matches!(a, Err(MasterError::NoSuchSlave { position: 9, count: 3 })), "{a:?}");
    let id = m.acyclic().submit(Request::RegisterRead { position: 1, register: 0xFFFF, len: 2 });
    let a = cycle_until(&mut m, id, 10).0;
    assert!(matches!(a, Err(MasterError::Request(RequestError::RegisterRange { .. }))), "{a:?}");
    let id = m.acyclic().submit(Request::RegisterWrite { position: 1, register: 0, data: vec![] });
    let a = cycle_until(&mut m, id, 10).0;
    assert!(matches!(a, Err(MasterError::Request(RequestError::RegisterLength { len: 0, .. }))), "{a:?}");
}

#[test]
fn registers_and_a_state_request_reach_the_slave_and_supervision_keeps_it_there() {
    let mut m = running();
    let id = m.acyclic().submit(Request::RegisterRead { position: 1, register: addr::AL_STATUS, len: 2 });
    assert_eq!(cycle_until(&mut m, id, 10).0.unwrap(), Answer::Data(vec![AlState::Op as u8, 0]));
    let id = m.acyclic().submit(Request::State { position: 1, state: AlState::SafeOp });
    assert_eq!(cycle_until(&mut m, id, 1000).0.unwrap(), Answer::State(AlState::SafeOp));
    // Supervision does not take it back to OP.
    let id = m.acyclic().submit(Request::RegisterRead { position: 1, register: addr::AL_STATUS, len: 2 });
    let _ = cycle_until(&mut m, id, 300);
    let id = m.acyclic().submit(Request::RegisterRead { position: 1, register: addr::AL_STATUS, len: 2 });
    assert_eq!(cycle_until(&mut m, id, 10).0.unwrap(), Answer::Data(vec![AlState::SafeOp as u8, 0]));
    let id = m.acyclic().submit(Request::State { position: 1, state: AlState::Op });
    assert_eq!(cycle_until(&mut m, id, 1000).0.unwrap(), Answer::State(AlState::Op));
    let id = m.acyclic().submit(Request::State { position: 1, state: AlState::Bootstrap });
    assert!(matches!(cycle_until(&mut m, id, 10).0, Err(MasterError::Request(RequestError::State(_)))));
}

#[test]
fn a_full_queue_answers_at_once_and_nothing_is_lost() {
    let mut m = running();
    let ids: Vec<RequestId> = (0..70)
        .map(|_| m.acyclic().submit(Request::RegisterRead { position: 0, register: addr::AL_STATUS, len: 2 }))
        .collect();
    let refused = m.acyclic().take_answers();
    assert_eq!(refused.len(), 70 - ferrocat_master::acyclic::QUEUE_LIMIT);
    assert!(refused.iter().all(|(_, a)| matches!(a, Err(MasterError::Request(RequestError::QueueFull { .. })))));
    let mut answered = refused.len();
    let last = *ids.last().unwrap();
    let mut next = m.cyclic().now_ns();
    for _ in 0..200 {
        next += CYCLE_NS;
        m.cyclic().cycle().unwrap();
        m.acyclic().serve_requests(next - CYCLE_NS / 4).unwrap();
        answered += m.acyclic().take_answers().iter().filter(|(_, a)| a.is_ok()).count();
        m.cyclic().sleep_until(next);
    }
    assert_eq!(answered, 70, "every request answered once (the last was {last:?})");
    assert_eq!(m.acyclic().requests_pending(), 0);
}

#[test]
fn foe_files_go_there_and_back_beside_the_cycle() {
    // The drive answers each write's first data packet busy three times (a flash erased).
    let cfg: SegmentConfig = toml::from_str(
        "[[device]]\nbuiltin = 'EK1100'\n[[device]]\nbuiltin = 'EL2004'\n[[device]]\nbuiltin = 'SERVO'\nfoe_busy = 3\n",
    )
    .unwrap();
    let mut m = Master::new(VirtualIo::new(cfg.build().unwrap(), HostModel::pc_rt(), 7));
    m.states().bring_up().unwrap();
    let packet = ferrocat_wire::foe::max_data_len(m.slaves().at(2).unwrap().mailbox().unwrap().out.1 as usize);
    // Shorter than a packet, exactly three (an empty packet ends it), and a few and a half.
    for n in [10, 3 * packet, 5 * packet / 2] {
        let data: Vec<u8> = (0..n).map(|k| (k * 7 + k / 251) as u8).collect();
        let name = format!("file-{n}.bin");
        let id =
            m.acyclic().submit(Request::FoeWrite { position: 2, file: name.clone(), password: 0, data: data.clone() });
        let (a, short) = cycle_until(&mut m, id, 2000);
        assert_eq!((a.unwrap(), short), (Answer::Written, 0), "{n} bytes");
        let id = m.acyclic().submit(Request::FoeRead { position: 2, file: name, password: 0, max_bytes: 1 << 20 });
        assert_eq!(cycle_until(&mut m, id, 2000).0.unwrap(), Answer::Data(data), "{n} bytes read back");
    }
    // Longer than the reader takes: an error, the transfer aborted, and the next one as ever.
    let id = m.acyclic().submit(Request::FoeRead {
        position: 2,
        file: format!("file-{}.bin", 3 * packet),
        password: 0,
        max_bytes: packet,
    });
    let a = cycle_until(&mut m, id, 2000).0;
    assert!(a.as_ref().is_err_and(|e| e.to_string().contains("longer than")), "{a:?}");
    let id =
        m.acyclic().submit(Request::FoeRead { position: 2, file: "file-10.bin".into(), password: 0, max_bytes: 100 });
    assert!(matches!(cycle_until(&mut m, id, 2000).0, Ok(Answer::Data(d)) if d.len() == 10));
    // A file the slave does not have: its refusal, in words.
    let id = m.acyclic().submit(Request::FoeRead { position: 2, file: "none.bin".into(), password: 0, max_bytes: 100 });
    let a = cycle_until(&mut m, id, 2000).0;
    assert!(a.as_ref().is_err_and(|e| e.to_string().contains("none.bin")), "{a:?}");
    // A slave without FoE.
    let id = m.acyclic().submit(Request::FoeRead { position: 1, file: "x".into(), password: 0, max_bytes: 100 });
    assert!(cycle_until(&mut m, id, 10).0.is_err());
    assert_eq!(m.diagnosis().cycle_stats().wkc_errors, 0);
}

/// EK1100, EL2004 and a SERVO in OP behind a master link of `link_ns` each way.
fn running_far(link_ns: u32) -> Master<VirtualIo> {
    let cfg: SegmentConfig = toml::from_str(&format!(
        "master_link_ns = {link_ns}\n[[device]]\nbuiltin = 'EK1100'\n[[device]]\nbuiltin = 'EL2004'\n\
         [[device]]\nbuiltin = 'SERVO'\n"
    ))
    .unwrap();
    let mut m = Master::new(VirtualIo::new(cfg.build().unwrap(), HostModel::pc_rt(), 7));
    m.states().bring_up().unwrap();
    m.cyclic().set_period_ns(CYCLE_NS);
    m
}

#[test]
fn a_round_trip_of_most_of_the_cycle_starves_no_request_and_makes_no_cycle_late() {
    // 2 × 200 µs of cable: a round trip of about 400 µs, twice of which passes ¾ of the cycle.
    let mut m = running_far(200_000);
    let id = m.acyclic().submit(Request::SdoRead { position: 2, index: 0x1018, subindex: 1, complete_access: false });
    let mut next = m.cyclic().now_ns();
    let (mut answer, mut latest_end_ns) = (None, i64::MIN);
    for _ in 0..400 {
        next += CYCLE_NS;
        assert_eq!(m.cyclic().cycle().unwrap(), m.image().expected_wkc());
        m.acyclic().serve_requests(next - CYCLE_NS / 4).unwrap();
        // Where the acyclic side's work ended, against the next cycle's start.
        latest_end_ns = latest_end_ns.max(m.cyclic().now_ns() as i64 - next as i64);
        if let Some((_, a)) = m.acyclic().take_answers().into_iter().find(|(k, _)| *k == id) {
            answer = Some(a);
            break;
        }
        m.cyclic().sleep_until(next);
    }
    let vendor = m.slaves()[2].identity().vendor_id;
    assert_eq!(answer.expect("answered in 400 cycles").unwrap(), Answer::Data(vendor.to_le_bytes().to_vec()));
    let s = m.acyclic().acyclic_stats();
    assert!(s.starved >= ferrocat_master::acyclic::STARVED_CALLS as u64, "{s:?}");
    assert!(s.relieved > 0 && s.relieved <= s.datagrams, "{s:?}");
    // No datagram was waited for past a sixteenth of the period before the next cycle.
    assert!(latest_end_ns <= -((CYCLE_NS / 16) as i64) + 20_000, "{latest_end_ns} ns");
    let c = m.diagnosis().cycle_stats();
    assert_eq!((c.lost_frames, c.wkc_errors), (0, 0), "{c:?}");
}

#[test]
fn a_round_trip_that_leaves_no_room_at_all_is_an_answer_that_says_so() {
    // 2 × 320 µs: one round trip passes 15/16 of the cycle after the cyclic frame's.
    let mut m = running_far(320_000);
    let id = m.acyclic().submit(Request::SdoRead { position: 2, index: 0x1018, subindex: 1, complete_access: false });
    let (a, short) = cycle_until(&mut m, id, 5_000);
    assert_eq!(short, 0);
    let Err(MasterError::Request(RequestError::NoRoom { round_trip_us, spare_us, .. })) = a else { panic!("{a:?}") };
    assert!(round_trip_us > spare_us && round_trip_us >= 640, "{round_trip_us} µs, {spare_us} µs");
    assert_eq!(m.acyclic().acyclic_stats().datagrams, 0);
    assert_eq!(m.acyclic().requests_pending(), 0);
}

#[test]
fn every_request_is_answered_once_through_a_segment_that_loses_frames() {
    // A datagram lost (waited for until the deadline and given up) leaves its request to the
    // next call: none disappears, none fails for one lost frame, and a mailbox reply lost on
    // its way back is asked for again.
    let (mut given_up, mut repeats) = (0, 0);
    for seed in 1..=6 {
        let (s, r) = served_through_loss(seed);
        given_up += s.given_up;
        repeats += r;
    }
    assert!(given_up > 0, "no datagram was lost");
    assert!(repeats > 0, "no mailbox reply was asked for again");
}

/// 40 requests served through 20 % frame loss; the acyclic side's counts and the drive's
/// mailbox repeats.
fn served_through_loss(seed: u64) -> (ferrocat_master::AcyclicStats, u64) {
    let cfg: SegmentConfig = toml::from_str(&format!(
        "seed = {seed}\n[[device]]\nbuiltin = 'EK1100'\n[[device]]\nbuiltin = 'EL2004'\n[[device]]\nbuiltin = 'SERVO'\n"
    ))
    .unwrap();
    let mut m = Master::new(VirtualIo::new(cfg.build().unwrap(), HostModel::pc_rt(), seed));
    m.states().bring_up().unwrap();
    m.cyclic().io_mut().seg.loss_probability = 0.2;
    let requests = |k: u16| match k % 4 {
        0 => Request::RegisterRead { position: 1, register: addr::AL_STATUS, len: 2 },
        1 => Request::SdoRead { position: 2, index: 0x1018, subindex: 1, complete_access: false },
        2 => Request::RegisterWrite { position: 1, register: 0x0F80, data: vec![k as u8] },
        _ => Request::State { position: 1, state: AlState::Op },
    };
    let mut waiting: Vec<RequestId> = (0..40).map(|k| m.acyclic().submit(requests(k))).collect();
    let mut next = m.cyclic().now_ns();
    let mut failed = Vec::new();
    for _ in 0..20_000 {
        next += CYCLE_NS;
        let _ = m.cyclic().cycle();
        m.acyclic().serve_requests(next - CYCLE_NS / 4).unwrap();
        for (id, a) in m.acyclic().take_answers() {
            let k = waiting.iter().position(|w| *w == id).unwrap_or_else(|| panic!("seed {seed}: {id:?} twice"));
            waiting.remove(k);
            failed.extend(a.err());
        }
        if waiting.is_empty() {
            break;
        }
        m.cyclic().sleep_until(next);
    }
    let s = m.acyclic().acyclic_stats();
    assert!(waiting.is_empty(), "seed {seed}: never answered: {waiting:?} ({s:?})");
    assert!(failed.is_empty(), "seed {seed}: a lost frame is no failure: {failed:?}");
    (s, m.slaves().at(2).unwrap().status().mailbox_repeats())
}
