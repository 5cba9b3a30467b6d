//! Homing (CiA402 mode 6) for a drive with no limit or home switch wired: the methods that need
//! only the motor's encoder — 33 and 34 (the index pulse, searched in the negative or positive
//! direction) and 35 and 37 (the current position). A method that needs a switch ends in a
//! homing error, as a drive without the switch reports.
//!
//! Homing defines where the user's position scale sits on the shaft: the home position (the
//! index pulse, or where the shaft stands) becomes the home offset (0x607C).

/// Where homing stands.
#[derive(Debug, Clone, Copy, PartialEq)]
pub(super) enum Phase {
    /// Not started since homing mode was entered.
    Idle,
    /// Moving towards the index pulse in direction `dir` (±1).
    Searching { dir: f64 },
    /// The home position is set; braking to a stop.
    Stopping,
    /// Done: the shaft holds still.
    Attained,
    /// Halted or stopped by the controlword before it was done (braking while still moving).
    Interrupted,
    /// The method cannot be run here (braking while still moving).
    Error,
}

/// The homing run: its phase and the velocity demand of its moves (increments/s).
#[derive(Debug, Clone, Copy)]
pub(super) struct Homing {
    pub phase: Phase,
    pub vel: f64,
    /// Speed of the search for the index pulse and the homing acceleration (increments/s, /s²).
    pub speed: f64,
    pub acc: f64,
}

impl Default for Homing {
    fn default() -> Self {
        Homing { phase: Phase::Idle, vel: 0.0, speed: 0.0, acc: 1.0 }
    }
}

/// What starting `method` does.
pub(super) enum Start {
    /// The home position is where the shaft stands (methods 35 and 37).
    Here,
    /// Search for the index pulse in this direction (33: negative, 34: positive).
    Index(f64),
    /// Not possible without switches.
    Unsupported,
}

pub(super) fn start(method: i64) -> Start {
    match method {
        35 | 37 => Start::Here,
        33 => Start::Index(-1.0),
        34 => Start::Index(1.0),
        _ => Start::Unsupported,
    }
}

impl Homing {
    /// Whether the drive is moving under homing's velocity demand (otherwise it holds position).
    pub fn moving(&self) -> bool {
        match self.phase {
            Phase::Searching { .. } | Phase::Stopping => true,
            Phase::Interrupted | Phase::Error => self.vel != 0.0,
            Phase::Idle | Phase::Attained => false,
        }
    }

    /// One control-loop step of the velocity demand: towards the search speed while searching,
    /// towards zero otherwise, at the homing acceleration. A stop ends `Stopping` in `Attained`.
    pub fn step(&mut self, dt: f64) -> f64 {
        let want = match self.phase {
            Phase::Searching { dir } => dir * self.speed,
            _ => 0.0,
        };
        let step = self.acc * dt;
        self.vel += (want - self.vel).clamp(-step, step);
        if self.vel == 0.0 && self.phase == Phase::Stopping {
            self.phase = Phase::Attained;
        }
        self.vel
    }

    /// The index pulse between two shaft positions (rad), if the search crossed one: the
    /// pulse comes once a revolution, at the angles 2πk.
    pub fn index_crossed(&self, before_rad: f64, after_rad: f64) -> Option<f64> {
        let Phase::Searching { .. } = self.phase else { return None };
        let turn = std::f64::consts::TAU;
        let (a, b) = ((before_rad / turn).floor(), (after_rad / turn).floor());
        if a == b {
            return None;
        }
        // Upwards the pulse is at the higher turn's start, downwards at the lower's end.
        Some(a.max(b) * turn)
    }

    /// Statusword bits 13, 12 and 10 (homing error, homing attained, target reached), CiA402's
    /// table for homing mode.
    pub fn status_bits(&self) -> (bool, bool, bool) {
        let still = self.vel == 0.0;
        match self.phase {
            Phase::Idle => (false, false, true),
            Phase::Searching { .. } => (false, false, false),
            Phase::Stopping => (false, true, false),
            Phase::Attained => (false, true, true),
            Phase::Interrupted => (false, false, still),
            Phase::Error => (true, false, still),
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn the_index_is_found_where_the_shaft_crosses_a_whole_turn_either_way() {
        let s = Homing { phase: Phase::Searching { dir: 1.0 }, ..Homing::default() };
        let turn = std::f64::consts::TAU;
        assert_eq!(s.index_crossed(0.9 * turn, 1.1 * turn), Some(turn));
        assert_eq!(s.index_crossed(-1.1 * turn, -0.9 * turn), Some(-turn));
        assert_eq!(s.index_crossed(-0.1 * turn, 0.1 * turn), Some(0.0));
        assert_eq!(s.index_crossed(2.1 * turn, 1.9 * turn), Some(2.0 * turn));
        assert_eq!(s.index_crossed(1.2 * turn, 1.3 * turn), None);
        let idle = Homing::default();
        assert_eq!(idle.index_crossed(0.9 * turn, 1.1 * turn), None, "only while searching");
    }

    #[test]
    fn a_stop_after_the_index_attains_homing() {
        let mut h = Homing { phase: Phase::Stopping, vel: 10.0, speed: 10.0, acc: 100.0 };
        assert_eq!(h.status_bits(), (false, true, false));
        for _ in 0..20 {
            h.step(0.01);
        }
        assert_eq!((h.phase, h.vel), (Phase::Attained, 0.0));
        assert_eq!(h.status_bits(), (false, true, true));
    }

    #[test]
    fn methods_needing_switches_are_refused() {
        assert!(matches!(start(37), Start::Here));
        assert!(matches!(start(35), Start::Here));
        assert!(matches!(start(33), Start::Index(d) if d < 0.0));
        assert!(matches!(start(34), Start::Index(d) if d > 0.0));
        for m in [1, 2, 17, 18, 19, 27, 36, 0, -1] {
            assert!(matches!(start(m), Start::Unsupported), "{m}");
        }
    }
}
