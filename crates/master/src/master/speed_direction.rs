//! Which way the time control loop's speed counter moves a clock.
//!
//! The datasheet gives the deviation of a speed counter difference (0x0932), SCD / (5·(SCS +
//! SCD + 2)·(SCS − SCD + 2)), but not its direction (esc-spec §3.5). A master that takes the
//! loop's corrections back out of a follower's clock (ferrocat's flywheel) must know it, so it
//! measures it: right after the loops are reset (SCD 0), two latches of the processing unit's
//! receive time (0x0918) some milliseconds apart give every clock's raw crystal rate against
//! the reference's; once the static drift compensation has converged, each loop holds its
//! clock at the reference's rate, so the deviation it applies equals that difference, and its
//! sign says the direction. (Only where the reference runs free meanwhile: a reference steered
//! by its offset runs at the master's rate, and so then do the followers.)
use ferrocat_wire::register::addr;
use ferrocat_wire::{Address, Command};

use super::Master;
use crate::error::Result;
use crate::io::Io;

/// Between the two latches: long enough for 10 ns ticks to show a few ppm.
const LATCH_GAP_NS: u64 = 20_000_000;
/// A crystal difference smaller than this (ppm) says nothing of the direction.
const MIN_DIFFERENCE_PPM: f64 = 3.0;
/// The deviation applied must be within this factor of the difference measured.
const SCALE_TOLERANCE: f64 = 2.0;

/// Every 64-bit follower's raw crystal rate against the reference's (ppm), by slave index.
pub(crate) struct CrystalRates(Vec<(usize, f64)>);

impl<I: Io> Master<I> {
    /// The followers' raw crystal rates against the reference's, while their loops are reset.
    pub(crate) fn measure_crystal_rates(&mut self, reference: usize) -> Result<CrystalRates> {
        let first = self.epu_times()?;
        let until = self.engine.io.now_ns().saturating_add(LATCH_GAP_NS);
        self.engine.io.sleep_until(until);
        let second = self.epu_times()?;
        let span =
            |k: usize| Some(second.get(k).copied().flatten()?.wrapping_sub(first.get(k).copied().flatten()?) as i64);
        let Some(reference_span) = span(reference).filter(|&s| s > 0) else { return Ok(CrystalRates(Vec::new())) };
        let rates = (0..self.slaves.len())
            .filter(|&k| k != reference)
            .filter_map(|k| Some((k, (span(k)? - reference_span) as f64 / reference_span as f64 * 1e6)))
            .collect();
        Ok(CrystalRates(rates))
    }

    /// With the loops converged: each follower's speed counter against its crystal's rate.
    pub(crate) fn measure_speed_direction(&mut self, rates: &CrystalRates) -> Result<()> {
        for &(k, ppm) in &rates.0 {
            let mut speed = [0u8; 4];
            self.fprd(self.slaves[k].station, addr::DC_SPEED_COUNTER_START, &mut speed)?;
            let (scs, scd) = (u16::from_le_bytes([speed[0], speed[1]]), i16::from_le_bytes([speed[2], speed[3]]));
            let applied_ppm = crate::sync::speed_deviation(scs, scd) * 1e6;
            // Converged, the loop applies the crystal's difference: (1 + f)·(1 ∓ d) = 1.
            let ratio = applied_ppm.abs() / ppm.abs();
            let plain = ppm.abs() >= MIN_DIFFERENCE_PPM && (1.0 / SCALE_TOLERANCE..=SCALE_TOLERANCE).contains(&ratio);
            self.slaves[k].dc.speed_diff_slows = plain.then_some(applied_ppm * ppm > 0.0);
        }
        Ok(())
    }

    /// Every 64-bit DC slave's processing-unit receive time (0x0918) of one latching frame.
    fn epu_times(&mut self) -> Result<Vec<Option<u64>>> {
        self.engine.one(Command::BWR, Address::Device { adp: 0, ado: addr::DC_RECEIVE_TIME_PORT0 }, &mut [0u8; 4])?;
        let mut times = Vec::with_capacity(self.slaves.len());
        for k in 0..self.slaves.len() {
            let s = &self.slaves[k];
            if !(s.dc.has_system_time && s.dc.is_64bit) {
                times.push(None);
                continue;
            }
            let mut t = [0u8; 8];
            let station = s.station;
            let ok = self
                .engine
                .one(Command::FPRD, Address::Device { adp: station, ado: addr::DC_RECEIVE_TIME_EPU }, &mut t)
                .is_ok_and(|w| w == 1);
            times.push(ok.then(|| u64::from_le_bytes(t)));
        }
        Ok(times)
    }
}
