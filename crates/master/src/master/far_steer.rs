//! The master's side of keeping a split ring's far reference on the reference's time: the
//! I/O after each cyclic frame around the sans-IO [`FarClock`](crate::far_clock::FarClock).
use crate::engine::{SplitPasses, SplitRingClocks};
use crate::error::Result;
use crate::far_clock::{
    measured_difference_ns, FarClock, FarSteer, ANCHOR_SD_NS, FAST_DRIFT, SETTLED_SD_NS, STEER_EVERY_NS, STEP_NS,
    WHOLE_HALF_NS,
};
use crate::io::Io;
use crate::master::Master;
use crate::pass_filter::PassFilter;
use ferrocat_wire::register::addr;
use ferrocat_wire::{Address, Command};

impl<I: Io> Master<I> {
    /// After a cyclic frame (`passes`, if it went round both halves): while the ring is split
    /// and the far half follows its own reference ([`SplitRingClocks::FarReference`]), the
    /// frame's two passes are a sample of that reference's error, and its System_Time_Offset
    /// is moved to cancel it (module comment). A closed ring ends it; the next break starts
    /// afresh.
    pub(crate) fn keep_far_reference(&mut self, passes: Option<SplitPasses>) -> Result<()> {
        let steered = self.engine.redundancy.clocks == SplitRingClocks::FarReference;
        let Some(station) = self.engine.redundancy.far_reference.filter(|_| steered) else {
            self.far_steer = None;
            return Ok(());
        };
        let Some(p) = passes.filter(|p| p.len > 0) else { return Ok(()) };
        // The second pass went through every clock behind the break: the far reference read,
        // each other one took.
        let n = self.slaves.len();
        let far = (self.engine.redundancy.far_half_slaves as usize).min(n);
        let clocks = self.slaves[n - far..].iter().filter(|s| s.dc.has_system_time).count();
        let Some(k) = self.slaves.iter().position(|s| s.station == station) else { return Ok(()) };
        if p.far_wkc as usize != clocks {
            return Ok(());
        }
        if self.far_steer.as_ref().is_none_or(|f| f.station != station) {
            // Split from the start: the level is the latch's geometry, not the break's.
            let latch = self.split_latch.as_ref().filter(|l| l.far_reference == Some(k));
            let clock = latch.map_or_else(FarClock::new, |l| FarClock::anchored(l.anchor_ns, ANCHOR_SD_NS));
            self.far_steer =
                Some(FarSteer { station, clock, filter: PassFilter::new(), last_move_ns: None, offset: None });
        }
        let Some(f) = self.far_steer.as_mut() else { return Ok(()) };
        // Not a sample whose passes took far longer than the path needs (pass_filter.rs).
        if !f.filter.admits(&p) {
            return Ok(());
        }
        let wide = p.len >= 8 && self.slaves[k].dc.is_64bit;
        let (x, diff) = measured_difference_ns(&p, wide);
        let spacing_ns = f.clock.last_sample_ns().map_or(STEER_EVERY_NS, |p| x.wrapping_sub(p)).min(STEER_EVERY_NS);
        f.clock.push(x, diff);
        // Moved every 10 ms, a far reference drifting from the reference saw-tooths by half an
        // interval's drift (±50 ns at 10 ppm: one that never followed the reference, split
        // from the start, runs at its own crystal's rate); drifting by more than `FAST_DRIFT`
        // it is moved with every frame instead.
        let every_ns = if f.clock.drift().abs() > FAST_DRIFT { 0 } else { STEER_EVERY_NS };
        let interval_ns = every_ns.max(spacing_ns);
        if f.last_move_ns.is_some_and(|t| x.wrapping_sub(t) < every_ns) {
            return Ok(());
        }
        // A settled line moves the far reference to its estimate every time (the estimate
        // changes little from one move to the next); a young one only by an error it shows
        // (three standard deviations), since its noise would move it further than holding
        // over does. Each move aims at zero halfway to the next, and takes up a level error
        // by at most `STEP_NS` (the far half's loops follow small steps smoothly).
        let Some((error, sd)) = f.clock.error_ns(x) else { return Ok(()) };
        let ahead_ns = f.clock.drift() * (interval_ns / 2) as f64;
        let aim = error as f64 + ahead_ns;
        if sd > SETTLED_SD_NS && aim.abs() <= 3.0 * sd {
            return Ok(());
        }
        // Split from the start (the level was the latch's geometry): an error far beyond the
        // fine steps — the latch's and the static drift compensation's stamps saw other
        // latencies than the cycles' do — moves the whole far half at once, its clocks
        // together, so that their loops see no step.
        if f.clock.knew_level() && aim.abs() > WHOLE_HALF_NS && aim.abs() > 5.0 * sd {
            f.last_move_ns = Some(x);
            f.offset = None;
            let delta = -aim.round() as i64;
            if self.shift_far_half(delta, Some(station)) {
                if let Some(f) = self.far_steer.as_mut() {
                    f.clock.applied(delta);
                }
            }
            return Ok(());
        }
        // Keeping up takes the drift since the last move (which aimed halfway to this one;
        // at least one interval's, however late this move comes).
        let since_ns = f.last_move_ns.map_or(interval_ns, |t| x.wrapping_sub(t).max(interval_ns)) as f64;
        // (`max` also keeps the bound a number whatever the line says: `clamp` refuses NaN.)
        let limit = ((f.clock.drift() * since_ns).abs() + STEP_NS).max(STEP_NS);
        let delta = -aim.clamp(-limit, limit).round() as i64;
        f.last_move_ns = Some(x);
        let wide_offset = self.slaves[k].dc.is_64bit;
        if delta != 0 && self.move_far_offset(station, wide_offset, delta).is_ok() {
            if let Some(f) = self.far_steer.as_mut() {
                f.clock.applied(delta);
            }
        }
        Ok(())
    }

    /// Adds `delta_ns` to the far reference's System_Time_Offset: one FPRW of the value it
    /// should hold now, which answers the value it replaced. If someone else moved it since
    /// (a method that moves every offset, Park's eq. 5), that value is moved instead. A
    /// frame that goes astray leaves the offset as the master knows it not (read again).
    fn move_far_offset(&mut self, station: u16, wide: bool, delta_ns: i64) -> Result<()> {
        let len = if wide { 8 } else { 4 };
        let known = self.far_steer.as_ref().and_then(|f| f.offset);
        let mut d = [0u8; 8];
        let result = (|| {
            let before = match known {
                Some(v) => v,
                None => {
                    self.fprd(station, addr::DC_SYSTEM_TIME_OFFSET, &mut d[..len])?;
                    u64::from_le_bytes(d)
                }
            };
            let mut w = before.wrapping_add_signed(delta_ns).to_le_bytes();
            self.engine.expect_wkc(
                Command::FPRW,
                Address::Device { adp: station, ado: addr::DC_SYSTEM_TIME_OFFSET },
                &mut w[..len],
                3,
            )?;
            w[len..].fill(0);
            let replaced = u64::from_le_bytes(w);
            let mask = if wide { u64::MAX } else { u32::MAX as u64 };
            let mut now = before.wrapping_add_signed(delta_ns) & mask;
            if replaced != before & mask {
                now = replaced.wrapping_add_signed(delta_ns) & mask;
                let mut w = now.to_le_bytes();
                self.engine.expect_wkc(
                    Command::FPWR,
                    Address::Device { adp: station, ado: addr::DC_SYSTEM_TIME_OFFSET },
                    &mut w[..len],
                    1,
                )?;
            }
            Ok(now)
        })();
        if let Some(f) = self.far_steer.as_mut() {
            f.offset = result.as_ref().ok().copied();
        }
        result.map(|_| ())
    }
}

/// How the master keeps a split ring's far reference on the reference's time
/// ([`Dc::far_reference`](crate::Dc::far_reference)).
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct FarReferenceKept {
    /// What the master has added to the far reference's offset since the ring split (ns).
    pub offset_ns: i64,
    /// The samples its estimator took.
    pub samples_taken: u64,
    /// The samples it left out because their passes took over twice the floor (docs/master.md,
    /// "Which samples count").
    pub samples_left_out: u64,
}

impl<'a, I: Io> crate::master::part::Dc<'a, I> {
    /// How the master keeps the far reference since the ring split (None while it keeps none).
    pub fn far_reference(&self) -> Option<FarReferenceKept> {
        self.m.far_steer.as_ref().map(|f| {
            let (samples_taken, samples_left_out) = f.filter.counts();
            FarReferenceKept { offset_ns: f.clock.applied_ns(), samples_taken, samples_left_out }
        })
    }
}
