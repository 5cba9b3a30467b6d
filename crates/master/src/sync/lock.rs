//! The lock state of a running clock-sync method, in the manner of linuxptp's servo states:
//! from the master's offset to the reference that each cycle's frame measures.

/// How far along a method is, from its measured offset to the reference.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
pub enum LockState {
    /// No offset measured yet, the last [`LockThresholds::lost_cycles`] frames all lost, or a
    /// method that keeps no estimate of the reference's time to compare (`chen2016`).
    #[default]
    Unlocked,
    /// Offsets measured, but not yet [`LockThresholds::lock_cycles`] in a row within
    /// [`LockThresholds::lock_ns`].
    Locking,
    /// The filtered offset has stayed within [`LockThresholds::lock_ns`] for
    /// [`LockThresholds::lock_cycles`] answered frames in a row, and not since left
    /// [`LockThresholds::unlock_ns`].
    Locked,
}

impl LockState {
    /// The state in lower case, as logs and JSON give it.
    pub fn name(self) -> &'static str {
        match self {
            LockState::Unlocked => "unlocked",
            LockState::Locking => "locking",
            LockState::Locked => "locked",
        }
    }
}

impl std::fmt::Display for LockState {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.write_str(self.name())
    }
}

/// When a method counts as locked. The offset compared is the median of the last
/// 15 measured offsets, so that one late frame neither locks nor unlocks. The bounds widen
/// with the offsets' measured noise ([`Lock::bounds_ns`]): on a host whose software stamps
/// scatter the offsets by microseconds, a median that wanders by its own noise is not a lost
/// lock.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct LockThresholds {
    /// Lock within this |offset|, ns, or three standard deviations of the median where that is
    /// more (default 1 000).
    pub lock_ns: u64,
    /// Leave lock beyond this |offset|, ns, or six standard deviations of the median where that
    /// is more (default 4 000).
    pub unlock_ns: u64,
    /// Answered frames in a row within the lock bound to lock (default 100).
    pub lock_cycles: u32,
    /// Answered frames in a row beyond the unlock bound to leave lock (default 15, the
    /// median's length: a stall that holds a few frames does not unlock).
    pub unlock_cycles: u32,
    /// Frames lost in a row that unlock (default 100).
    pub lost_cycles: u32,
}

impl Default for LockThresholds {
    fn default() -> Self {
        LockThresholds { lock_ns: 1_000, unlock_ns: 4_000, lock_cycles: 100, unlock_cycles: 15, lost_cycles: 100 }
    }
}

/// The offsets' noise: a running mean (over about 64 answered frames) of each offset's
/// distance from the median, each distance capped at four times the mean (at least 1 µs),
/// so that a stall's offsets do not make the noise.
#[derive(Debug, Clone, Copy, Default, PartialEq, Eq)]
struct Noise {
    mean_abs_ns: i64,
    n: u64,
}

impl Noise {
    fn learn(&mut self, distance_ns: i64) {
        let d = distance_ns.min(4 * self.mean_abs_ns.max(250));
        self.mean_abs_ns += (d - self.mean_abs_ns) / (self.n as i64 + 1).min(64);
        self.n += 1;
    }

    /// The median's standard deviation, ns: for a normal spread σ ≈ 1.25 × the mean absolute
    /// deviation, and the median of 15 has 1.25 σ / √15 ≈ 0.32 σ, so ≈ 0.4 × the mean.
    fn median_sigma_ns(&self) -> u64 {
        (self.mean_abs_ns.max(0) as u64) * 2 / 5
    }
}

/// Offsets the median is taken over.
const FILTER_LEN: usize = 15;

/// Follows a method's offsets and says its [`LockState`].
#[derive(Debug, Clone, Copy, Default, PartialEq, Eq)]
pub struct Lock {
    /// When to lock and unlock.
    pub thresholds: LockThresholds,
    state: LockState,
    recent: [i64; FILTER_LEN],
    filled: usize,
    next: usize,
    within: u32,
    beyond: u32,
    lost_in_row: u32,
    noise: Noise,
    offset_ns: Option<i64>,
    /// Cycles observed, changes of state, and the cycle that first locked (counted from 1).
    observed: u64,
    changes: u64,
    first_locked: Option<u64>,
    trips: TripScreen,
}

/// Which frames' offsets to leave out: a frame whose round trip is far above the usual one was
/// held on its way (a host stall, a simulator late to answer), and the offset it measures is off
/// by about half the excess, whatever the clocks did. A stall of a few ms holds several frames
/// in a row, enough to move the median.
#[derive(Debug, Clone, Copy, Default, PartialEq, Eq)]
struct TripScreen {
    /// The usual round trip and its spread (running means over about 64 frames, ns).
    centre_ns: i64,
    spread_ns: i64,
    n: u64,
    left_out: u64,
}

/// Round trips learned before any is left out.
const TRIP_WARM_UP: u64 = 32;
/// Left out beyond the usual round trip by this many spreads, and by at least `TRIP_MIN_NS`.
const TRIP_SPREADS: i64 = 6;
const TRIP_MIN_NS: i64 = 10_000;

impl TripScreen {
    /// Whether a frame with round trip `trip_ns` measures the clocks; learns from it.
    fn measures(&mut self, trip_ns: i64) -> bool {
        if self.n == 0 {
            self.centre_ns = trip_ns;
        }
        let dev = trip_ns - self.centre_ns;
        let ok = self.n < TRIP_WARM_UP || dev <= (TRIP_SPREADS * self.spread_ns).max(TRIP_MIN_NS);
        // Learned with the deviation capped, so that a stall does not become the usual.
        let capped = dev.clamp(-4 * self.spread_ns.max(1_000), 4 * self.spread_ns.max(1_000));
        self.centre_ns += capped / 64;
        self.spread_ns += (capped.abs() - self.spread_ns) / 64;
        self.n += 1;
        self.left_out += !ok as u64;
        ok
    }
}

impl Lock {
    /// The state now.
    pub fn state(&self) -> LockState {
        self.state
    }

    /// The filtered offset (median of the last 15), ns: the reference's time
    /// less the method's estimate of it; `None` before the first.
    pub fn offset_ns(&self) -> Option<i64> {
        self.offset_ns
    }

    /// Changes of state so far: a lock that holds changes twice (unlocked, locking, locked).
    pub fn changes(&self) -> u64 {
        self.changes
    }

    /// The cycle (counted from 1, lost frames too) that first locked.
    pub fn first_locked_cycle(&self) -> Option<u64> {
        self.first_locked
    }

    /// The lock and unlock bounds in force, ns: the thresholds, widened to three and six
    /// standard deviations of the median where the measured noise makes those more.
    pub fn bounds_ns(&self) -> (u64, u64) {
        let sigma = self.noise.median_sigma_ns();
        (self.thresholds.lock_ns.max(3 * sigma), self.thresholds.unlock_ns.max(6 * sigma))
    }

    /// The offsets' measured noise: the mean distance of an offset from the median, ns.
    pub fn noise_ns(&self) -> u64 {
        self.noise.mean_abs_ns.max(0) as u64
    }

    /// Frames whose offsets were left out for their round trip ([`Lock::observe_frame`]).
    pub fn left_out(&self) -> u64 {
        self.trips.left_out
    }

    /// [`Lock::observe`] for a frame answered with round trip `trip_ns`: a frame held far
    /// longer than usual on its way is left out (it neither counts towards a lock nor against
    /// one).
    pub fn observe_frame(&mut self, offset_ns: Option<i64>, trip_ns: i64) -> LockState {
        if !self.trips.measures(trip_ns) {
            return self.state;
        }
        self.observe(offset_ns, false)
    }

    /// Takes one cycle's measured offset (`None`: the frame was lost, or the method keeps no
    /// estimate to compare) and returns the state after it.
    pub fn observe(&mut self, offset_ns: Option<i64>, frame_lost: bool) -> LockState {
        let before = self.state;
        self.observed += 1;
        let after = self.step(offset_ns, frame_lost);
        self.changes += (after != before) as u64;
        if after == LockState::Locked && self.first_locked.is_none() {
            self.first_locked = Some(self.observed);
        }
        after
    }

    fn step(&mut self, offset_ns: Option<i64>, frame_lost: bool) -> LockState {
        let t = self.thresholds;
        if frame_lost {
            self.lost_in_row = self.lost_in_row.saturating_add(1);
            if self.lost_in_row >= t.lost_cycles.max(1) {
                self.state = LockState::Unlocked;
                self.within = 0;
            }
            return self.state;
        }
        self.lost_in_row = 0;
        let Some(offset) = offset_ns else {
            self.state = LockState::Unlocked;
            return self.state;
        };
        self.recent[self.next] = offset;
        self.next = (self.next + 1) % FILTER_LEN;
        self.filled = (self.filled + 1).min(FILTER_LEN);
        let mut window = self.recent;
        let window = &mut window[..self.filled];
        window.sort_unstable();
        let median = window[window.len() / 2];
        self.offset_ns = Some(median);
        if self.filled == FILTER_LEN {
            self.noise.learn((offset - median).abs());
        }
        let size = median.unsigned_abs();
        let (lock_ns, unlock_ns) = self.bounds_ns();
        self.within = if size <= lock_ns { self.within.saturating_add(1) } else { 0 };
        self.beyond = if size > unlock_ns { self.beyond.saturating_add(1) } else { 0 };
        self.state = match self.state {
            LockState::Locked if self.beyond < t.unlock_cycles.max(1) => LockState::Locked,
            _ if self.within >= t.lock_cycles.max(1) => LockState::Locked,
            _ => LockState::Locking,
        };
        self.state
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn run(lock: &mut Lock, offsets: impl IntoIterator<Item = i64>) -> LockState {
        offsets.into_iter().map(|o| lock.observe(Some(o), false)).last().unwrap_or_default()
    }

    #[test]
    fn a_frame_held_far_longer_than_usual_is_left_out() {
        let mut lock = Lock::default();
        // 40 µs round trips within ±2 µs, the offsets within: locked after 100.
        for k in 0..200 {
            lock.observe_frame(Some(100), 40_000 + (k % 5) * 1_000 - 2_000);
        }
        assert_eq!(lock.state(), LockState::Locked);
        // A stall: ten frames in a row held 2 ms, their offsets 1 ms off: left out, still locked.
        for _ in 0..10 {
            assert_eq!(lock.observe_frame(Some(-1_000_000), 2_040_000), LockState::Locked);
        }
        assert_eq!(lock.left_out(), 10);
        // The same offsets from frames with the usual round trip unlock, once the median has
        // stayed beyond for 15 frames.
        for _ in 0..22 {
            lock.observe_frame(Some(-1_000_000), 40_000);
        }
        assert_eq!(lock.state(), LockState::Locking);
    }

    #[test]
    fn counts_its_changes_and_the_cycle_it_first_locked_at() {
        let mut lock = Lock::default();
        assert_eq!((lock.changes(), lock.first_locked_cycle()), (0, None));
        run(&mut lock, [50_000; 20]);
        assert_eq!((lock.changes(), lock.first_locked_cycle()), (1, None), "unlocked -> locking");
        // The median within after 8 of 15, locked 100 cycles later: cycle 20 + 7 + 100.
        run(&mut lock, [0; 200]);
        assert_eq!((lock.changes(), lock.first_locked_cycle()), (2, Some(127)));
        // Out and back: two more changes; the first lock stays where it was.
        run(&mut lock, [10_000; 30]);
        run(&mut lock, [0; 200]);
        assert_eq!((lock.changes(), lock.first_locked_cycle()), (4, Some(127)));
    }

    #[test]
    fn locks_after_enough_cycles_within_and_unlocks_with_hysteresis() {
        let mut lock = Lock::default();
        assert_eq!(lock.state(), LockState::Unlocked);
        assert_eq!(run(&mut lock, [50_000; 20]), LockState::Locking);
        // The median needs 8 of 15 within before it is; then 100 in a row.
        assert_eq!(run(&mut lock, [300; 106]), LockState::Locking);
        assert_eq!(run(&mut lock, [300; 1]), LockState::Locked);
        // Between lock_ns and unlock_ns: still locked.
        assert_eq!(run(&mut lock, [3_000; 30]), LockState::Locked);
        // One outlier does not move the median.
        assert_eq!(run(&mut lock, [-90_000; 1]), LockState::Locked);
        // Beyond unlock_ns: the median there from the 8th, and 15 frames of it in a row unlock.
        assert_eq!(run(&mut lock, [9_000; 7 + 14]), LockState::Locked);
        assert_eq!(lock.offset_ns(), Some(9_000));
        assert_eq!(run(&mut lock, [9_000; 1]), LockState::Locking);
    }

    #[test]
    fn noisy_offsets_widen_the_bounds_so_that_the_median_s_own_wander_does_not_unlock() {
        // Offsets scattered ±6 µs about 0 (a software-stamped host): the median of 15 wanders
        // past 1 µs now and then, and past 4 µs too rarely to matter; the bounds follow.
        let mut lock = Lock::default();
        let mut x: u64 = 1;
        let mut noisy = || {
            x = x.wrapping_mul(6364136223846793005).wrapping_add(1442695040888963407);
            ((x >> 33) % 12_001) as i64 - 6_000
        };
        for _ in 0..3_000 {
            lock.observe(Some(noisy()), false);
        }
        let (lock_ns, unlock_ns) = lock.bounds_ns();
        assert!(lock.noise_ns() > 2_500 && lock.noise_ns() < 3_500, "{}", lock.noise_ns());
        assert!(lock_ns > 3_000 && unlock_ns > 6_000, "{lock_ns} {unlock_ns}");
        assert_eq!(lock.state(), LockState::Locked);
        let changes = lock.changes();
        for _ in 0..30_000 {
            lock.observe(Some(noisy()), false);
        }
        assert_eq!(lock.changes(), changes, "no flapping");
        // A real offset of 40 µs, far beyond the noise, unlocks.
        for _ in 0..40 {
            lock.observe(Some(40_000 + noisy()), false);
        }
        assert_eq!(lock.state(), LockState::Locking);
        // Quiet offsets keep the thresholds as they are.
        let mut quiet = Lock::default();
        run(&mut quiet, (0..500).map(|k| (k % 7) * 20 - 60));
        assert_eq!(quiet.bounds_ns(), (1_000, 4_000));
    }

    #[test]
    fn lost_frames_unlock_only_after_enough_in_a_row() {
        let mut lock = Lock::default();
        run(&mut lock, [0; 200]);
        assert_eq!(lock.state(), LockState::Locked);
        for _ in 0..99 {
            lock.observe(None, true);
        }
        assert_eq!(lock.state(), LockState::Locked);
        assert_eq!(lock.observe(None, true), LockState::Unlocked);
        assert_eq!(lock.observe(Some(0), false), LockState::Locking);
        // A method without an estimate stays unlocked.
        assert_eq!(lock.observe(None, false), LockState::Unlocked);
    }
}
