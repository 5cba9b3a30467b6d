//! The master following the reference (ferrocat-mfr): the next period from the estimate's
//! line, planned against the host's mean lateness, and frames held back after a late one so
//! that the slaves repeat a cycle instead of losing one (docs/clock-sync.md, "Master follows
//! reference").
use super::super::{Correction, Sample};
use super::estimator::Estimator;

/// The master's schedule on the reference's clock: the frames pass the reference at its
/// cycle's start, SYNC0 (where the method knows it) at `sync0_phase_ns` of the cycle.
#[derive(Debug)]
pub(super) struct Schedule {
    cycle_ns: u64,
    /// The reference-time phase of the SYNC0 the frames serve. A frame whose process data
    /// ended after it (a late wake-up or send) is consumed a SYNC0 late; the next frame is
    /// held back one cycle so that it does not overwrite it before then: the slaves repeat
    /// one cycle instead of repeating one and losing the next.
    pub(super) sync0_phase_ns: Option<u64>,
    /// Frames held back so.
    pub(super) held_back: u64,
    /// The reference time the next frame is aimed at (its slot on the cycle's grid).
    aimed_ns: Option<u64>,
    /// Frames in a row held back.
    late_run: u32,
    /// When this cycle was planned to start on the master's clock (the last one plus the
    /// period returned), and how late cycles start on average against it. A wake-up's
    /// lateness is known after the fact and says nothing of the next one's, so the period is
    /// chosen for the planned start plus the mean lateness, not for the actual start: feeding
    /// a part of each cycle's lateness back makes the loop chase the host's jitter and a
    /// coarse timer's rounding, and widens both.
    pub(super) plan_ns: Option<u64>,
    /// Cycles in a row more than half a cycle off the plan.
    off_plan_run: u32,
    lateness: RunningMean,
}

/// Late frames in a row after which the count of slots starts again (`Schedule::slots_to_hold`):
/// more than a late wake-up and a late send in a row.
pub(super) const SLOT_SLIP_RUN: u32 = 4;
/// Cycles in a row more than half a cycle off the plan before it starts again from them
/// (`Schedule::lateness_deviation`). A loop that fell behind by a long wake-up catches up
/// over several cycles, each giving back what is left of its cycle after its frames: on a
/// stock kernel at 250 µs (two frames a cycle) that took four cycles often enough that four
/// in a row moved the plan back and forth (the demo's ferrocat-mfr: 1 217 late set-points
/// with one seed, 50–80 with sixteen over seeds 1–6).
const PLAN_MOVED_RUN: u32 = 16;

/// The mean of every value so far, and once there are `2^LONG_SHIFT` of them an exponential
/// average over as many: a coarse timer's rounding is a sawtooth that sweeps its step only as
/// the reference slides past the timer's grid (thousands of cycles), and a mean that followed
/// it would have the loop chase it.
#[derive(Debug, Default, Clone, Copy)]
struct RunningMean {
    sum: i128,
    n: u64,
}

const LONG_SHIFT: u32 = 16;

impl RunningMean {
    fn push(&mut self, v: i64) {
        if self.n < 1 << LONG_SHIFT {
            self.n += 1;
        } else {
            self.sum -= self.sum >> LONG_SHIFT;
        }
        self.sum += v as i128;
    }
    fn mean(&self) -> i64 {
        (self.sum / self.n.max(1) as i128) as i64
    }
}

impl Schedule {
    pub(super) fn new(cycle_ns: u64) -> Self {
        Schedule {
            cycle_ns,
            sync0_phase_ns: None,
            held_back: 0,
            aimed_ns: None,
            late_run: 0,
            plan_ns: None,
            off_plan_run: 0,
            lateness: RunningMean::default(),
        }
    }

    /// The next period after frame `s` passed at master time `x_ns`: the cycle on the line's
    /// rate, 1/16 of the phase error taken out, and a cycle more for each slot held back.
    pub(super) fn period_after(&mut self, s: &Sample, x_ns: u64, dev: i64, line: &Estimator) -> Correction {
        // The reference's time, from the fit, where this frame would have passed had its
        // cycle started as late as cycles do on average; its phase in the cycle against the
        // target, in integers.
        let (Some(y), Some(rate)) = (line.at(x_ns.wrapping_add_signed(dev.wrapping_neg())), line.rate()) else {
            return self.planned(Correction { shift_offsets_ns: 0, next_period_ns: Some(self.cycle_ns) });
        };
        let c = self.cycle_ns as f64;
        let mut phase = (y % self.cycle_ns) as f64;
        if phase > c / 2.0 {
            phase -= c;
        }
        // One cycle of reference time is cycle/rate of master time; 1/16 of the phase error is
        // taken out per cycle, so that the line's and the mean's own noise averages away.
        let mut period = (c - phase / 16.0) / rate;
        let hold = self.slots_to_hold(s);
        period += hold as f64 * c / rate;
        self.held_back += hold;
        self.planned(Correction { shift_offsets_ns: 0, next_period_ns: Some(period.max(1.0) as u64) })
    }

    /// A cycle whose frame was lost: the nominal period, the slot counted on.
    pub(super) fn lost(&mut self) -> Correction {
        self.aimed_ns = self.aimed_ns.map(|a| a.wrapping_add(self.cycle_ns));
        self.planned(Correction { shift_offsets_ns: 0, next_period_ns: Some(self.cycle_ns) })
    }

    /// How many cycles to hold the next frame back: as many SYNC0s as the process data of
    /// `s` ended after the one it was aimed before. The frame's slot is counted on from the
    /// last one, not read off its phase, which could not tell a frame late by most of a cycle
    /// from an early one.
    fn slots_to_hold(&mut self, s: &Sample) -> u64 {
        let Some(sync0) = self.sync0_phase_ns else { return 0 };
        let c = self.cycle_ns;
        let late_of = |aimed: u64| s.reference_ns.wrapping_add(s.data_ns).wrapping_sub(aimed) as i64;
        let mut aimed = self.aimed_ns.unwrap_or_else(|| self.nearest_slot(s.reference_ns));
        // Far off the count (a stall, a jump of the reference): start counting again here.
        if !(-(c as i64) / 2..=8 * c as i64).contains(&late_of(aimed)) {
            aimed = self.nearest_slot(s.reference_ns);
        }
        let room = (sync0 % c) as i64;
        // At most the 8 cycles a frame may be late before the count starts again.
        let hold_for = |late: i64| if late >= room { ((late - room) / c as i64 + 1).min(8) as u64 } else { 0 };
        // A late frame is held back, and the next one, on time, is not. Late frames in a row
        // are a schedule that moved past the SYNC0: the loop, which steers to the nearest slot,
        // takes it on to the next one, while the count stays behind — and counting on held
        // every frame back from then on, each a repeated cycle (85 % of the cycles at 250 µs on
        // pc-stock with seed 1 without this rule; at 100 µs, with the plan's restart in
        // `lateness_deviation` alone, more than every other one with each seed tried). So the
        // `SLOT_SLIP_RUN`-th late frame in a row starts the count again at its own slot.
        let mut hold = hold_for(late_of(aimed));
        self.late_run = if hold > 0 { self.late_run + 1 } else { 0 };
        if self.late_run >= SLOT_SLIP_RUN {
            aimed = self.nearest_slot(s.reference_ns);
            hold = hold_for(late_of(aimed));
            self.late_run = 0;
        }
        self.aimed_ns = Some(aimed.wrapping_add((1 + hold) * c));
        hold
    }

    /// The slot (reference time on the cycle's grid) nearest to reference time `t_ns`.
    fn nearest_slot(&self, t_ns: u64) -> u64 {
        let c = self.cycle_ns;
        let off = t_ns.wrapping_add(c / 2) % c;
        t_ns.wrapping_sub(off).wrapping_add(c / 2)
    }

    /// This cycle's lateness against its plan less the mean lateness. A cycle more than half
    /// a cycle off is an outlier of the host (a wake-up that late, and the cycles that catch
    /// up after it), taken back to the plan like any other but kept out of the mean;
    /// `PLAN_MOVED_RUN` of them in a row are the schedule itself moving (a master that
    /// skipped cycles without a word), and the plan starts again from there, deviation 0.
    /// (Starting again at a single outlier would put the plan where that one late wake-up
    /// was: the cycles after it, back on the master's schedule, would all look early by as
    /// much, and the loop would move the frames that much later, to the SYNC0 and past it,
    /// for thousands of cycles on pc-stock.)
    pub(super) fn lateness_deviation(&mut self, built_ns: u64) -> i64 {
        let Some(plan) = self.plan_ns else {
            self.plan_ns = Some(built_ns);
            self.lateness.push(0);
            return 0;
        };
        let late = built_ns.wrapping_sub(plan) as i64;
        let mean = self.lateness.mean();
        let dev = late.wrapping_sub(mean);
        if dev.unsigned_abs() > self.cycle_ns / 2 {
            self.off_plan_run += 1;
            if self.off_plan_run < PLAN_MOVED_RUN {
                return dev;
            }
            self.plan_ns = Some(built_ns.wrapping_add_signed(mean.wrapping_neg()));
            self.off_plan_run = 0;
            return 0;
        }
        self.off_plan_run = 0;
        self.lateness.push(late);
        dev
    }

    /// The plan moved on by the period returned (master follows reference only).
    fn planned(&mut self, c: Correction) -> Correction {
        if let (Some(plan), Some(period)) = (self.plan_ns, c.next_period_ns) {
            self.plan_ns = Some(plan.wrapping_add(period));
        }
        c
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn one_wake_up_later_than_half_a_cycle_does_not_move_the_plan() {
        let c = 250_000u64;
        let mut f = Schedule::new(c);
        let t0 = 10 * c;
        let mut plan = t0;
        let mut step = |f: &mut Schedule, late: u64| {
            let dev = f.lateness_deviation(plan + late);
            f.plan_ns = f.plan_ns.map(|p| p + c);
            plan += c;
            dev
        };
        for _ in 0..100 {
            assert_eq!(step(&mut f, 20_000), 0);
        }
        // One wake-up 300 µs late is that far off, and the cycles after it are on the plan
        // again (they looked 280 µs early when that one had moved the plan).
        assert_eq!(step(&mut f, 320_000), 300_000);
        for _ in 0..10 {
            assert_eq!(step(&mut f, 20_000), 0);
        }
        // A schedule that moved by 300 µs for good: the plan follows on the sixteenth cycle.
        let devs: Vec<i64> = (0..18).map(|_| step(&mut f, 320_000)).collect();
        assert!(devs[..15].iter().all(|&d| d == 300_000) && devs[15..] == [0, 0, 0], "{devs:?}");
    }
}
