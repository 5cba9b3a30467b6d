//! The master's clock as DC system time, the stamps of a frame on it, and the two register
//! steps the bring-up shares with the clock sync: a frame's loop behind a slave, and one
//! slave's System_Time_Offset moved.
use ferrocat_wire::register::addr;

use super::Master;
use crate::error::Result;
use crate::io::Io;
use crate::sync::SyncState;

/// Nanoseconds from 1970-01-01 to 2000-01-01, the epoch of DC system time.
const EPOCH_2000_NS: u64 = 946_684_800_000_000_000;
/// The 8-byte preamble and start-of-frame delimiter at 100 Mbit/s.
const PREAMBLE_NS: u64 = 8 * 80;

/// The latest receive time of the other active ports less the entry port's (across the 32-bit
/// wrap): how long a frame spent behind a slave.
pub(crate) fn loop_of(receive_times: &[u32; 4], active_ports: [bool; 4], entry_port: u8) -> u64 {
    let e = entry_port as usize;
    (0..4)
        .filter(|&p| p != e && active_ports[p])
        .map(|p| receive_times[p].wrapping_sub(receive_times[e]) as i32 as i64)
        .max()
        .unwrap_or(0)
        .max(0) as u64
}

impl<I: Io> Master<I> {
    /// How long a frame spends behind slave `k` before it passes it again on its way back.
    pub(crate) fn loop_ns_of(&self, k: usize) -> u64 {
        let s = &self.slaves[k];
        loop_of(&s.dc.receive_times, s.ports.active, s.ports.entry)
    }

    /// A sample of the frame just answered, with its stamps; the reference's readings are
    /// the caller's to fill in.
    pub(crate) fn stamped_sample(&mut self, st: &SyncState, built_ns: u64, frame_bytes: u64) -> crate::sync::Sample {
        // A stamp is a reading of the world's clock: the master's clock at it is the same
        // epoch away. (Taken as "the master's clock now, less how long ago the stamp was",
        // the two readings of a real clock were ≈ 20–40 ns apart here and every stamp that late.)
        let to_sys = |m: &mut Self, world: u64| m.clock().master_system_time_at(world);
        // Hardware stamps mark the end of the start-of-frame delimiter, 8 bytes after the
        // first preamble bit, which is what an ESC latches: take them back to that bit.
        let hw = self.engine.io.rx_stamps_start_of_frame();
        let sfd = if hw { PREAMBLE_NS } else { 0 };
        let tx = self.engine.io.last_tx_ns().map(|t| t.wrapping_sub(sfd));
        let rx = self.engine.last_rx_ns.wrapping_sub(sfd);
        crate::sync::Sample {
            cycle: st.cycle,
            built_ns,
            tx_ns: tx.map(|t| to_sys(self, t)),
            rx_ns: to_sys(self, rx),
            reference_ns: st.reference_ns.unwrap_or(0),
            reference_offset_ns: None,
            difference_ns: 0,
            loop_ns: st.loop_ns,
            // A stamp after the last byte (software, or none) includes the whole frame.
            frame_ns: if hw { 0 } else { frame_bytes * 80 },
            data_ns: 0,
            follower: None,
        }
    }

    /// Adds `shift_ns` to the System_Time_Offset of the slave at station `st`.
    pub(crate) fn shift_offset(&mut self, st: u16, shift_ns: i64) -> Result<()> {
        let wide = self.slaves.iter().find(|s| s.station == st).is_some_and(|s| s.dc.is_64bit);
        let n = if wide { 8 } else { 4 };
        let mut d = [0u8; 8];
        self.fprd(st, addr::DC_SYSTEM_TIME_OFFSET, &mut d[..n])?;
        let v = u64::from_le_bytes(d).wrapping_add_signed(shift_ns);
        self.fpwr(st, addr::DC_SYSTEM_TIME_OFFSET, &v.to_le_bytes()[..n])
    }
}

impl<'a, I: Io> crate::master::part::Clock<'a, I> {
    /// The fixed offset from the world's clock to the master's DC time, once taken.
    pub fn epoch_offset_ns(&self) -> Option<u64> {
        self.m.epoch_offset_ns
    }

    /// The master's clock as DC system time (ns since 2000): the world's clock plus a fixed
    /// offset taken once (for real time from CLOCK_REALTIME).
    pub fn master_system_time(&mut self) -> u64 {
        let now = self.m.engine.io.now_ns();
        self.m.clock().master_system_time_at(now)
    }

    /// The world's clock (`Io::now_ns`) at the first instant after now at which the master's
    /// system time is `grid_ns` modulo `cycle_ns`: where to start cycling so that each cycle's
    /// frame leaves on that phase of the DC cycle (for example half a cycle before SYNC0, with
    /// `grid_ns` = [`DcReport::sync0_start`](crate::DcReport::sync0_start) less the shift). Where the reference follows the
    /// master, its SYNC0 stays on the master's clock, so the phase holds; where the master
    /// follows, its method keeps it.
    pub fn next_on_grid_ns(&mut self, grid_ns: u64, cycle_ns: u64) -> u64 {
        let now = self.m.engine.io.now_ns();
        let sys = self.m.clock().master_system_time_at(now);
        // The grid may lie ahead (the first SYNC0 still to come): the phase taken signed.
        let phase = (sys as i128 - grid_ns as i128).rem_euclid(cycle_ns.max(1) as i128) as u64;
        now + (cycle_ns - phase)
    }

    /// The master's clock as DC system time when the world's clock reads `t_ns`.
    pub fn master_system_time_at(&mut self, t_ns: u64) -> u64 {
        if self.m.epoch_offset_ns.is_none() {
            let now = self.m.engine.io.now_ns();
            self.m.epoch_offset_ns = Some(if self.m.engine.io.is_virtual() {
                // Virtual time starts at 2026-01-01 00:00 UTC.
                1_767_225_600_000_000_000 - EPOCH_2000_NS
            } else {
                let real = std::time::SystemTime::now()
                    .duration_since(std::time::UNIX_EPOCH)
                    .map(|d| d.as_nanos() as u64)
                    .unwrap_or(EPOCH_2000_NS);
                real.saturating_sub(EPOCH_2000_NS).saturating_sub(now)
            });
        }
        t_ns.wrapping_add(self.m.epoch_offset_ns.unwrap_or(0))
    }
}
