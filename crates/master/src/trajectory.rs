//! Synchronised point-to-point moves of several axes with jerk-limited (seven-segment S-curve)
//! profiles: every axis follows the same normalised profile s(t) ∈ [0, 1], scaled by its own
//! distance, so that all start and arrive together and none exceeds its own limits.

/// Velocity, acceleration and jerk limits of one axis (units per s, s², s³).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Limits {
    /// Velocity limit (units/s).
    pub velocity: f64,
    /// Acceleration limit (units/s²).
    pub acceleration: f64,
    /// Jerk limit (units/s³).
    pub jerk: f64,
}

/// A seven-segment S-curve from rest to rest over the distance 1.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct SCurve {
    /// Jerk phase, constant-acceleration phase and cruise durations (s).
    pub t_jerk: f64,
    /// See `t_jerk`.
    pub t_acc: f64,
    /// See `t_jerk`.
    pub t_cruise: f64,
    /// The jerk of the normalised profile (1/s³).
    pub jerk: f64,
}

/// Duration and distance of the acceleration from rest to `v` with limits `a`, `j`.
fn accel(v: f64, a: f64, j: f64) -> (f64, f64, f64) {
    let (tj, ta) = if v * j >= a * a { (a / j, v / a - a / j) } else { ((v / j).sqrt(), 0.0) };
    // Symmetric: the mean velocity of the phase is v / 2.
    (tj, ta, v * (2.0 * tj + ta) / 2.0)
}

impl SCurve {
    /// The fastest profile over distance 1 within `v`, `a`, `j` (all > 0).
    pub fn plan(v: f64, a: f64, j: f64) -> SCurve {
        let (tj, ta, d) = accel(v, a, j);
        if 2.0 * d <= 1.0 {
            return SCurve { t_jerk: tj, t_acc: ta, t_cruise: (1.0 - 2.0 * d) / v, jerk: j };
        }
        // Too short to cruise at v: the peak velocity whose two ramps cover exactly 1.
        let (mut lo, mut hi) = (0.0, v);
        for _ in 0..100 {
            let mid = 0.5 * (lo + hi);
            if 2.0 * accel(mid, a, j).2 > 1.0 {
                hi = mid;
            } else {
                lo = mid;
            }
        }
        let (tj, ta, _) = accel(lo, a, j);
        SCurve { t_jerk: tj, t_acc: ta, t_cruise: 0.0, jerk: j }
    }

    /// The profile's whole duration, s.
    pub fn duration_s(&self) -> f64 {
        4.0 * self.t_jerk + 2.0 * self.t_acc + self.t_cruise
    }

    /// Position, velocity and acceleration of the normalised profile at `t` seconds.
    pub fn at(&self, t: f64) -> (f64, f64, f64) {
        let j = self.jerk;
        let phases = [
            (self.t_jerk, j),
            (self.t_acc, 0.0),
            (self.t_jerk, -j),
            (self.t_cruise, 0.0),
            (self.t_jerk, -j),
            (self.t_acc, 0.0),
            (self.t_jerk, j),
        ];
        let (mut p, mut v, mut a) = (0.0f64, 0.0f64, 0.0f64);
        let mut left = t.max(0.0);
        for (dur, jk) in phases {
            let dt = left.min(dur);
            p += v * dt + a * dt * dt / 2.0 + jk * dt * dt * dt / 6.0;
            v += a * dt + jk * dt * dt / 2.0;
            a += jk * dt;
            left -= dt;
            if left <= 0.0 {
                break;
            }
        }
        if t >= self.duration_s() {
            return (1.0, 0.0, 0.0);
        }
        (p, v, a)
    }
}

/// A synchronised move of N axes from `from` to `to`.
#[derive(Debug, Clone, PartialEq)]
pub struct Move {
    /// Each axis's start.
    pub from: Vec<f64>,
    /// Each axis's end.
    pub to: Vec<f64>,
    /// The normalised profile every axis follows.
    pub profile: SCurve,
}

impl Move {
    /// The fastest common profile for which every axis stays within its limits.
    pub fn new(from: &[f64], to: &[f64], limits: &[Limits]) -> Move {
        let (mut v, mut a, mut j) = (f64::INFINITY, f64::INFINITY, f64::INFINITY);
        for ((f, t), l) in from.iter().zip(to).zip(limits) {
            let d = (t - f).abs();
            if d > 0.0 {
                v = v.min(l.velocity / d);
                a = a.min(l.acceleration / d);
                j = j.min(l.jerk / d);
            }
        }
        let profile = if v.is_finite() {
            SCurve::plan(v, a, j)
        } else {
            SCurve { t_jerk: 0.0, t_acc: 0.0, t_cruise: 0.0, jerk: 1.0 }
        };
        Move { from: from.to_vec(), to: to.to_vec(), profile }
    }

    /// The move's duration, s.
    pub fn duration_s(&self) -> f64 {
        self.profile.duration_s()
    }

    /// Every axis's position at `t` seconds after the start.
    pub fn positions(&self, t: f64, out: &mut [f64]) {
        let (s, _, _) = self.profile.at(t);
        for ((o, f), to) in out.iter_mut().zip(&self.from).zip(&self.to) {
            *o = f + (to - f) * s;
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn check(m: &Move, limits: &[Limits]) {
        let t_end = m.duration_s();
        let dt = 1e-4;
        let n = m.from.len();
        let mut prev = vec![0.0; n];
        let mut prev_v = vec![0.0; n];
        m.positions(0.0, &mut prev);
        assert_eq!(prev, m.from);
        let mut cur = vec![0.0; n];
        let mut k = 1;
        while (k as f64) * dt <= t_end + dt {
            m.positions(k as f64 * dt, &mut cur);
            for i in 0..n {
                let v = (cur[i] - prev[i]) / dt;
                let a = (v - prev_v[i]) / dt;
                let l = limits[i];
                assert!(v.abs() <= l.velocity * 1.001 + 1e-9, "axis {i} v {v} at {}", k as f64 * dt);
                assert!(a.abs() <= l.acceleration * 1.02 + 1e-6, "axis {i} a {a} at {}", k as f64 * dt);
                prev_v[i] = v;
            }
            prev.copy_from_slice(&cur);
            k += 1;
        }
        m.positions(t_end, &mut cur);
        for (i, (c, t)) in cur.iter().zip(&m.to).enumerate() {
            assert!((c - t).abs() < 1e-6, "axis {i} ends at {c} not {t}");
        }
    }

    #[test]
    fn long_and_short_moves_reach_their_targets_within_every_limit() {
        let l = Limits { velocity: 10.0, acceleration: 50.0, jerk: 1000.0 };
        // Long (cruises), short (never reaches v), very short (never reaches a).
        for d in [20.0, 1.0, 0.01] {
            let m = Move::new(&[0.0, 5.0], &[d, 5.0 - d / 2.0], &[l, l]);
            check(&m, &[l, l]);
        }
    }

    #[test]
    fn the_axis_with_the_longest_move_sets_the_pace_and_all_arrive_together() {
        let l = Limits { velocity: 10.0, acceleration: 50.0, jerk: 1000.0 };
        let alone = Move::new(&[0.0], &[20.0], &[l]);
        let together = Move::new(&[0.0, 0.0, 3.0], &[20.0, 2.0, 3.0], &[l, l, l]);
        assert!((alone.duration_s() - together.duration_s()).abs() < 1e-9);
        // 20 at 10/s plus the ramps: 2 s cruise-equivalent + v/a + a/j.
        assert!((alone.duration_s() - (2.0 + 10.0 / 50.0 + 50.0 / 1000.0)).abs() < 1e-6, "{}", alone.duration_s());
        let mut half = [0.0; 3];
        together.positions(together.duration_s() / 2.0, &mut half);
        assert!((half[0] - 10.0).abs() < 1e-6 && (half[1] - 1.0).abs() < 1e-6 && half[2] == 3.0, "{half:?}");
    }

    #[test]
    fn nothing_to_move_takes_no_time() {
        let l = Limits { velocity: 1.0, acceleration: 1.0, jerk: 1.0 };
        let m = Move::new(&[1.0], &[1.0], &[l]);
        assert_eq!(m.duration_s(), 0.0);
        let mut p = [0.0];
        m.positions(5.0, &mut p);
        assert_eq!(p, [1.0]);
    }
}
