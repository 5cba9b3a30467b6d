#![no_main]
//! Any bytes as a line to a running master's control socket: read as a request of the
//! protocol, and a request that reads is served by a master cycling on the embedded virtual
//! segment (EK1100, SERVO) for up to 50 cycles. Any bytes as a reply, as a client reads it.
use std::cell::RefCell;

use ferrocat_master::Master;
use ferrocat_segment::{HostModel, SegmentConfig, VirtualIo};
use libfuzzer_sys::fuzz_target;

thread_local! {
    static MASTER: RefCell<Option<Master<VirtualIo>>> = const { RefCell::new(None) };
}

fn running() -> Master<VirtualIo> {
    let cfg: SegmentConfig = toml::from_str("[[device]]\nbuiltin = 'EK1100'\n[[device]]\nbuiltin = 'SERVO'\n").unwrap();
    let mut m = Master::new(VirtualIo::new(cfg.build().unwrap(), HostModel::ideal(), 1));
    m.states().bring_up().unwrap();
    m
}

fuzz_target!(|data: &[u8]| {
    let _ = serde_json::from_slice::<ferrocat_service::protocol::Reply>(data);
    let Ok(envelope) = ferrocat_service::protocol::parse_request(data) else { return };
    let Ok(request) = ferrocat_service::master_request(envelope.request) else { return };
    MASTER.with(|cell| {
        let mut slot = cell.borrow_mut();
        let m = slot.get_or_insert_with(running);
        let id = m.acyclic().submit(request);
        let mut next = m.cyclic().now_ns();
        for _ in 0..50 {
            next += 1_000_000;
            // A request may leave a slave unanswering (a register write): the loop's errors
            // are the loop's, not the request's, and are not what this target looks for.
            let _ = m.cyclic().cycle();
            let _ = m.acyclic().serve_requests(next - 250_000);
            if m.acyclic().take_answers().iter().any(|(k, _)| *k == id) {
                return;
            }
            m.cyclic().sleep_until(next);
        }
    });
});
