//! A real clock moves between two readings of it; the master's conversion of the link's stamps
//! to its own clock must not depend on how many readings it takes. In the virtual world every
//! reading within an instant is the same, so a world whose readings each take time stands in
//! for a real one: on this VM two readings were ≈ 20–40 ns apart, and every stamp was converted
//! that much late, which put the master's copy of the reference's clock that much behind
//! (`ferrocat lab live`).
use ferrocat_master::io::Io;
use ferrocat_master::sync::{ClockSync, Correction, Coupling, Ferrocat};
use ferrocat_master::{DcConfig, Master};
use ferrocat_segment::{HostModel, Stamps, VirtualIo};
use ferrocat_segment::{Segment, SegmentConfig};

const CYCLE_NS: u64 = 1_000_000;
/// What one reading of the clock costs in this world.
const READ_NS: u64 = 50;

/// The virtual world, but each reading of its clock takes `READ_NS` of its time.
struct SlowClock {
    io: VirtualIo,
    wake_target_ns: Option<u64>,
}

impl Io for SlowClock {
    fn now_ns(&mut self) -> u64 {
        let t = self.io.now_ns();
        self.io.sleep_until(t + READ_NS);
        t
    }
    fn send(&mut self, frame: &[u8]) -> std::io::Result<()> {
        self.io.send(frame)
    }
    fn recv(&mut self, buf: &mut [u8], deadline_ns: u64) -> std::io::Result<Option<(usize, u64)>> {
        self.io.recv(buf, deadline_ns)
    }
    fn sleep_until(&mut self, t_ns: u64) {
        self.wake_target_ns = Some(t_ns);
        self.io.sleep_until(t_ns);
    }
    fn wake_target_ns(&self) -> Option<u64> {
        self.wake_target_ns
    }
    fn last_tx_ns(&mut self) -> Option<u64> {
        self.io.last_tx_ns()
    }
    fn rx_stamps_start_of_frame(&self) -> bool {
        self.io.rx_stamps_start_of_frame()
    }
    fn is_virtual(&self) -> bool {
        true
    }
    fn timer_resolution_ns(&self) -> u64 {
        self.io.timer_resolution_ns()
    }
    fn last_rx_secondary(&self) -> bool {
        self.io.last_rx_secondary()
    }
}

/// A world whose true clocks the test reads.
trait Simulated: Io {
    fn segment(&self) -> &Segment;
}

impl Simulated for VirtualIo {
    fn segment(&self) -> &Segment {
        &self.seg
    }
}

impl Simulated for SlowClock {
    fn segment(&self) -> &Segment {
        &self.io.seg
    }
}

/// A NIC's stamps and nothing else of a host: no latencies, no wake-up delay (a sleep of the
/// slow clock's is then exact).
fn host() -> HostModel {
    HostModel { stamps: Stamps::Hardware, ..HostModel::ideal() }
}

fn virtual_io() -> VirtualIo {
    let cfg: SegmentConfig = toml::from_str(
        "seed = 5\n\
         [[device]]\nbuiltin = 'EK1100'\ndrift_ppm = 30.0\n\
         [[device]]\nbuiltin = 'EK1100'\ndrift_ppm = -40.0\n",
    )
    .unwrap();
    VirtualIo::new(cfg.build().unwrap(), host(), 5)
}

/// The mean of the method's clock minus the reference's true system time over cycles
/// 2 000–3 999 of ferrocat (reference follows master), ns.
fn mean_error<I: Simulated>(io: I) -> f64 {
    let mut m = Master::new(io);
    m.states().bring_up().unwrap();
    m.dc().init_dc(&DcConfig { sync0_slaves: Some(vec![]), ..DcConfig::default() }).unwrap();
    let mut sync = Ferrocat::new(Coupling::ReferenceFollowsMaster, CYCLE_NS);
    let mut st = m.clock().sync_state().unwrap();
    let mut next = m.cyclic().now_ns();
    let mut c = Correction::default();
    let mut sum = 0.0;
    for k in 0..4_000 {
        next += c.next_period_ns.unwrap_or(CYCLE_NS);
        m.cyclic().sleep_until(next);
        c = m.clock().sync_step(&mut sync, &mut st).unwrap();
        if k >= 2_000 {
            // The world's time first, then the master's clock at that same reading.
            let t = m.cyclic().now_ns();
            let own = m.clock().master_system_time_at(t);
            let master = sync.master_time(own).unwrap_or(own);
            let seg = m.io().segment();
            let reference = seg.nodes[0].esc.dc.as_ref().unwrap().system_at(t);
            sum += master.wrapping_sub(reference) as i64 as f64;
        }
    }
    sum / 2_000.0
}

#[test]
fn stamps_are_converted_the_same_however_long_the_clock_takes_to_read() {
    let exact = mean_error(virtual_io());
    let slow = mean_error(SlowClock { io: virtual_io(), wake_target_ns: None });
    println!("mean master − reference: {exact:.1} ns where readings take no time, {slow:.1} ns where each takes {READ_NS} ns");
    // Stamps converted late by a reading would put the master READ_NS behind.
    assert!((slow - exact).abs() < 0.2 * READ_NS as f64, "{slow:.1} ns against {exact:.1} ns");
}
