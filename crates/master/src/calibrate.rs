//! A one-time calibration of what no round trip can show. Software timestamps put a frame's
//! departure early and its arrival late by different amounts; a round trip sees only their
//! sum, so half their difference stays in every estimate of when the frame passed the
//! reference. An independent path measures it: the host's general-purpose output wired to a
//! slave's LATCH0 input. The master notes its clock, raises the pin, reads the slave's latched
//! system time (0x09B0) and compares it with its own clock one known output latency later —
//! as Park 2020 §IV-B measure with GPIs, but with the ESC's latch (10 ns) at the slave's end.
//! The median over many pulses (robust to a pulse delayed by preemption) goes to the method.
use crate::io::Io;
use crate::sync::ClockSync;
use crate::{Master, MasterError, Result};

/// Latch0 positive-edge time, and latch0 control (0: both edges latched continuously).
const LATCH0_POS: u16 = ferrocat_wire::register::addr::DC_LATCH0_POSITIVE;
const LATCH0_CONTROL: u16 = ferrocat_wire::register::addr::DC_LATCH0_CONTROL;

#[derive(Debug, Clone)]
/// A calibration of the master's clock against a slave's LATCH0 input, pulsed by a host output (a GPIO) whose latency is known.
pub struct GpioCalibration {
    /// Position of the slave whose LATCH0 input the output drives.
    pub slave: u16,
    /// Mean time from writing the output to its pin changing, as measured on the rig (a scope).
    pub output_latency_ns: u64,
    /// Pulses to take before the median goes to the method.
    pub pulses: usize,
    errors: Vec<i64>,
    last_latch: Option<u64>,
    armed: bool,
}

impl GpioCalibration {
    /// A calibration of the LATCH0 input of `slave`, the output's latency `output_latency_ns`, over `pulses` pulses (at least 1).
    pub fn new(slave: u16, output_latency_ns: u64, pulses: usize) -> Self {
        let pulses = pulses.max(1);
        GpioCalibration {
            slave,
            output_latency_ns,
            pulses,
            errors: Vec::with_capacity(pulses),
            last_latch: None,
            armed: false,
        }
    }

    /// The errors measured so far (master − slave, ns).
    pub fn errors(&self) -> &[i64] {
        &self.errors
    }

    /// One pulse (call once per cycle, after the cycle's frames). Once `pulses` are in, their
    /// median master − slave error is handed to `sync` and returned; later calls do nothing.
    pub fn pulse<I: Io>(&mut self, m: &mut Master<I>, sync: &mut dyn ClockSync) -> Result<Option<i64>> {
        if self.errors.len() >= self.pulses {
            return Ok(None);
        }
        let s = m.slave(self.slave)?;
        if !s.dc.has_system_time {
            return Err(MasterError::of(self.slave, &s.name, crate::error::SlaveError::NoLatchTime));
        }
        let (station, wide) = (s.station, s.dc.is_64bit);
        if !self.armed {
            m.fpwr(station, LATCH0_CONTROL, &[0])?;
            m.engine.io.set_gpio(false)?;
            self.armed = true;
        }
        let own = m.clock().master_system_time().wrapping_add(self.output_latency_ns);
        m.engine.io.set_gpio(true)?;
        let claimed = sync.reference_belief_ns(own);
        let mut latch = [0u8; 8];
        let n = if wide { 8 } else { 4 };
        m.fprd(station, LATCH0_POS, &mut latch[..n])?;
        m.engine.io.set_gpio(false)?;
        let latched = u64::from_le_bytes(latch);
        // An unchanged latch: the edge came after the read (a delayed output); no sample.
        if self.last_latch.replace(latched) == Some(latched) {
            return Ok(None);
        }
        let error = if wide {
            claimed.wrapping_sub(latched) as i64
        } else {
            (claimed as u32).wrapping_sub(latched as u32) as i32 as i64
        };
        self.errors.push(error);
        if self.errors.len() < self.pulses {
            return Ok(None);
        }
        let error = robust_mean(&self.errors);
        if let Some(steering) = sync.reference_steering() {
            steering.take_error(error);
        }
        Ok(Some(error))
    }
}

/// The mean of `v` without its gross outliers (further from the median than eight standard
/// deviations, estimated from the median absolute deviation, or 1 µs if more): a pulse delayed
/// by preemption is dropped, while the error's own skew, which the mean must keep, stays in.
pub fn robust_mean(v: &[i64]) -> i64 {
    if v.is_empty() {
        return 0;
    }
    let median = |v: &mut Vec<i64>| {
        v.sort_unstable();
        v[v.len() / 2]
    };
    let m = median(&mut v.to_vec());
    let mad = median(&mut v.iter().map(|&x| x.saturating_sub(m).saturating_abs()).collect());
    // 1.4826 · MAD estimates σ for a normal core; a tight core (hardware stamps, a fast
    // output) still keeps everything within 1 µs.
    let limit = (8.0 * 1.4826 * mad as f64).max(1_000.0) as i64;
    let kept: Vec<i128> =
        v.iter().filter(|&&x| x.saturating_sub(m).saturating_abs() <= limit).map(|&x| x as i128).collect();
    (kept.iter().sum::<i128>() / kept.len().max(1) as i128) as i64
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn the_robust_mean_keeps_the_skew_and_drops_gross_outliers() {
        // A skewed core: 900 at 0, 100 at 1 000 (mean 100, median 0), and ten pulses 150 µs late.
        let mut v = vec![0i64; 900];
        v.extend([1_000; 100]);
        v.extend([-150_000; 10]);
        assert_eq!(robust_mean(&v), 100);
        assert_eq!(robust_mean(&[]), 0);
        assert_eq!(robust_mean(&[i64::MIN, i64::MAX, 5, 5, 6]), 5);
    }
}
