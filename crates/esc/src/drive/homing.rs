//! Homing (CiA402 mode 6). The drive's encoder gives one index pulse per revolution (at whole
//! turns of the shaft); limit and home switches exist where the integrator put them
//! ([`Switches`], reported in 0x60FD). The methods:
//!
//! - 1, 2 / 17, 18: the negative / positive limit switch, left slowly the other way; home is
//!   the first index pulse after it goes inactive (1, 2) or that edge itself (17, 18);
//! - 3, 4 / 19, 20: a home switch active above its position ("positive"), approached from
//!   below (4, 20) or left downwards (3, 19); home is the next index pulse or the edge;
//! - 5, 6 / 21, 22: a home switch active below its position ("negative"), mirrored;
//! - 7–14 / 23–30: a home switch of finite width (a cam), searched first upwards (7–10) or
//!   downwards (11–14), reversing at the limit switch on that side; home is its lower or upper
//!   edge, crossed downwards or upwards, and the index after it (7–14) or the edge (23–30);
//! - 33, 34: the index pulse, searched downwards or upwards; 35, 37: the current position.
//!
//! A switch is searched at 0x6099:01, the edge and the index at 0x6099:02, both at 0x609A.
//! A method needing a switch the drive does not have, or a limit switch met on the way (but
//! the one 7–14 reverse at), end in a homing error. Home then reads the home offset (0x607C).

use std::f64::consts::TAU;

/// Where the switches sit on the shaft (revolutions on its absolute scale); `None`: none.
#[derive(Debug, Clone, Copy, Default, PartialEq)]
pub struct Switches {
    /// Active at and below this position.
    pub negative_limit_rev: Option<f64>,
    /// Active at and above this position.
    pub positive_limit_rev: Option<f64>,
    /// Active at and above this position, or at and below it with `home_active_below`, or
    /// up to `home_to_rev` (a cam).
    pub home_rev: Option<f64>,
    pub home_active_below: bool,
    pub home_to_rev: Option<f64>,
}

/// Which switch a method looks for.
#[derive(Debug, Clone, Copy, PartialEq)]
pub(super) enum Switch {
    NegativeLimit,
    PositiveLimit,
    Home,
}

impl Switches {
    fn present(&self, s: Switch) -> bool {
        match s {
            Switch::NegativeLimit => self.negative_limit_rev.is_some(),
            Switch::PositiveLimit => self.positive_limit_rev.is_some(),
            Switch::Home => self.home_rev.is_some(),
        }
    }

    /// Whether switch `s` is active with the shaft at `rad`.
    pub(super) fn active(&self, s: Switch, rad: f64) -> bool {
        let rev = rad / TAU;
        match s {
            Switch::NegativeLimit => self.negative_limit_rev.is_some_and(|p| rev <= p),
            Switch::PositiveLimit => self.positive_limit_rev.is_some_and(|p| rev >= p),
            Switch::Home => self.home_rev.is_some_and(|h| match (self.home_to_rev, self.home_active_below) {
                (Some(to), _) => (h..=to).contains(&rev),
                (None, true) => rev <= h,
                (None, false) => rev >= h,
            }),
        }
    }

    /// The edge of switch `s` the shaft crossed from `before` to `after` (rad): the one between
    /// them, or, should rounding put it a hair outside, the nearest.
    fn edge_between(&self, s: Switch, before: f64, after: f64) -> Option<f64> {
        let edges = match s {
            Switch::NegativeLimit => [self.negative_limit_rev, None],
            Switch::PositiveLimit => [self.positive_limit_rev, None],
            Switch::Home => [self.home_rev, self.home_to_rev],
        };
        let (lo, hi) = (before.min(after), before.max(after));
        let off = |e: f64| {
            if e < lo {
                lo - e
            } else if e > hi {
                e - hi
            } else {
                0.0
            }
        };
        edges.into_iter().flatten().map(|rev| rev * TAU).min_by(|a, b| off(*a).total_cmp(&off(*b)))
    }

    /// The digital inputs object 0x60FD: bit 0 negative limit, 1 positive limit, 2 home.
    pub fn inputs(&self, rad: f64) -> u32 {
        self.active(Switch::NegativeLimit, rad) as u32
            | (self.active(Switch::PositiveLimit, rad) as u32) << 1
            | (self.active(Switch::Home, rad) as u32) << 2
    }
}

/// An edge a method homes on: switch `switch` leaving state `from` while moving in `dir`
/// (±1), then the next index pulse in `dir` if `index`.
#[derive(Debug, Clone, Copy, PartialEq)]
pub(super) struct Edge {
    pub switch: Switch,
    pub from: bool,
    pub dir: f64,
    pub index: bool,
}

/// Where homing stands.
#[derive(Debug, Clone, Copy, PartialEq)]
pub(super) enum Phase {
    /// Not started since homing mode was entered.
    Idle,
    /// Methods 7–14: moving in `dir` at the switch speed until the home switch is active,
    /// reversing once at the limit switch ahead.
    FindCam { dir: f64, reversed: bool, edge: Edge },
    /// Moving against the final direction, at the switch speed, until the switch reads
    /// `edge.from`.
    ToSwitch(Edge),
    /// Moving in the final direction, at the zero speed, until the switch leaves `edge.from`.
    ToEdge(Edge),
    /// Moving towards the index pulse in direction `dir` (±1), at the zero speed.
    Searching { dir: f64 },
    /// The home position is set; braking to a stop.
    Stopping,
    /// Done: the shaft holds still.
    Attained,
    /// Halted or stopped by the controlword before it was done (braking while still moving).
    Interrupted,
    /// The method cannot be run here, or met a limit switch (braking while still moving).
    Error,
}

/// The homing run: its phase and the velocity demand of its moves (increments/s).
#[derive(Debug, Clone, Copy)]
pub(super) struct Homing {
    pub phase: Phase,
    pub vel: f64,
    /// Speeds of the search for a switch and for the edge or index, and the acceleration
    /// (increments/s, /s²).
    pub switch_speed: f64,
    pub zero_speed: f64,
    pub acc: f64,
}

impl Default for Homing {
    fn default() -> Self {
        Homing { phase: Phase::Idle, vel: 0.0, switch_speed: 0.0, zero_speed: 0.0, acc: 1.0 }
    }
}

/// What starting a method does.
#[derive(Debug, Clone, Copy, PartialEq)]
pub(super) enum Start {
    /// The home position is where the shaft stands (methods 35 and 37).
    Here,
    /// Search for the index pulse in this direction (33: negative, 34: positive).
    Index(f64),
    /// Home on a switch's edge (and the index after it).
    Edge(Edge),
    /// Find the home switch first, moving in this direction (methods 7–14, 23–30).
    Cam(f64, Edge),
    /// Not a method this drive runs.
    Unsupported,
}

pub(super) fn start(method: i64) -> Start {
    let edge = |switch, from, dir, index| Start::Edge(Edge { switch, from, dir, index });
    match method {
        35 | 37 => Start::Here,
        33 => Start::Index(-1.0),
        34 => Start::Index(1.0),
        1 | 17 => edge(Switch::NegativeLimit, true, 1.0, method == 1),
        2 | 18 => edge(Switch::PositiveLimit, true, -1.0, method == 2),
        3 | 19 => edge(Switch::Home, true, -1.0, method == 3),
        4 | 20 => edge(Switch::Home, false, 1.0, method == 4),
        5 | 21 => edge(Switch::Home, true, 1.0, method == 5),
        6 | 22 => edge(Switch::Home, false, -1.0, method == 6),
        7..=14 | 23..=30 => {
            // 7–10 search upwards and reverse at the positive limit, 11–14 mirror them; each
            // homes on an edge crossed one way: (first direction, from, final direction).
            let k = if method <= 14 { method - 7 } else { method - 23 };
            let (first, from, dir) = [
                (1.0, true, -1.0),  // 7: leave the cam at its lower edge, downwards
                (1.0, false, 1.0),  // 8: enter it at its lower edge, upwards
                (1.0, false, -1.0), // 9: enter it at its upper edge, downwards
                (1.0, true, 1.0),   // 10: leave it at its upper edge, upwards
                (-1.0, true, 1.0),  // 11: mirrors 7 (upper edge, upwards)
                (-1.0, false, -1.0),
                (-1.0, false, 1.0),
                (-1.0, true, -1.0),
            ][k as usize];
            Start::Cam(first, Edge { switch: Switch::Home, from, dir, index: method <= 14 })
        }
        _ => Start::Unsupported,
    }
}

/// The first phase of methods 7–14 (23–30) from shaft position `rad`.
pub(super) fn begin_cam(first: f64, edge: Edge, switches: &Switches, rad: f64) -> Phase {
    if switches.home_rev.is_none() {
        return Phase::Error;
    }
    if switches.active(Switch::Home, rad) {
        after_cam(edge, switches, rad)
    } else {
        Phase::FindCam { dir: first, reversed: false, edge }
    }
}

/// On the home switch: straight to the edge if it is left that way, else off it first.
fn after_cam(edge: Edge, switches: &Switches, rad: f64) -> Phase {
    if switches.active(Switch::Home, rad) == edge.from {
        Phase::ToEdge(edge)
    } else {
        Phase::ToSwitch(edge)
    }
}

/// The first phase of a homing on `edge` from shaft position `rad`, or an error where the
/// switch is missing (or methods 3–6's home switch has the other polarity).
pub(super) fn begin(edge: Edge, switches: &Switches, rad: f64) -> Phase {
    if !switches.present(edge.switch) {
        return Phase::Error;
    }
    if edge.switch == Switch::Home && switches.home_to_rev.is_none() {
        // Methods 3, 4 (19, 20) expect the switch active above, 5, 6 (21, 22) below (a cam
        // is both, at its lower and upper edge).
        let active_above = (edge.from && edge.dir < 0.0) || (!edge.from && edge.dir > 0.0);
        if active_above == switches.home_active_below {
            return Phase::Error;
        }
    }
    if switches.active(edge.switch, rad) == edge.from {
        Phase::ToEdge(edge)
    } else {
        Phase::ToSwitch(edge)
    }
}

impl Homing {
    /// Whether the drive is moving under homing's velocity demand (otherwise it holds position).
    pub fn moving(&self) -> bool {
        match self.phase {
            Phase::FindCam { .. }
            | Phase::ToSwitch(_)
            | Phase::ToEdge(_)
            | Phase::Searching { .. }
            | Phase::Stopping => true,
            Phase::Interrupted | Phase::Error => self.vel != 0.0,
            Phase::Idle | Phase::Attained => false,
        }
    }

    /// One control-loop step of the velocity demand towards the phase's speed and direction
    /// (zero once home is set or on a stop), at the homing acceleration. A stop ends
    /// `Stopping` in `Attained`.
    pub fn step(&mut self, dt: f64) -> f64 {
        let want = match self.phase {
            Phase::FindCam { dir, .. } => dir * self.switch_speed,
            Phase::ToSwitch(e) => -e.dir * self.switch_speed,
            Phase::ToEdge(e) => e.dir * self.zero_speed,
            Phase::Searching { dir } => dir * self.zero_speed,
            _ => 0.0,
        };
        let step = self.acc * dt;
        self.vel += (want - self.vel).clamp(-step, step);
        if self.vel == 0.0 && self.phase == Phase::Stopping {
            self.phase = Phase::Attained;
        }
        self.vel
    }

    /// Follows the shaft from `before` to `after` (rad) through the method's phases; returns
    /// the home position (rad) when this step found it.
    pub fn track(&mut self, before: f64, after: f64, switches: &Switches) -> Option<f64> {
        let limit_met = |exempt: Option<Switch>| {
            [Switch::NegativeLimit, Switch::PositiveLimit]
                .into_iter()
                .any(|s| Some(s) != exempt && switches.active(s, after) && !switches.active(s, before))
        };
        match self.phase {
            Phase::FindCam { dir, reversed, edge } => {
                let ahead = if dir > 0.0 { Switch::PositiveLimit } else { Switch::NegativeLimit };
                if switches.active(Switch::Home, after) {
                    self.phase = after_cam(edge, switches, after);
                } else if !reversed && switches.active(ahead, after) {
                    self.phase = Phase::FindCam { dir: -dir, reversed: true, edge };
                } else if limit_met(None) {
                    self.phase = Phase::Error;
                }
            }
            Phase::ToSwitch(e) | Phase::ToEdge(e) if limit_met(Some(e.switch)) => self.phase = Phase::Error,
            Phase::ToSwitch(e) if switches.active(e.switch, after) == e.from => self.phase = Phase::ToEdge(e),
            Phase::ToEdge(e)
                if switches.active(e.switch, before) == e.from && switches.active(e.switch, after) != e.from =>
            {
                if e.index {
                    self.phase = Phase::Searching { dir: e.dir };
                } else {
                    self.phase = Phase::Stopping;
                    return switches.edge_between(e.switch, before, after);
                }
            }
            Phase::Searching { .. } if limit_met(None) => self.phase = Phase::Error,
            Phase::Searching { .. } => {
                let (a, b) = ((before / TAU).floor(), (after / TAU).floor());
                if a != b {
                    self.phase = Phase::Stopping;
                    // Upwards the pulse is at the higher turn's start, downwards at the lower's end.
                    return Some(a.max(b) * TAU);
                }
            }
            _ => {}
        }
        None
    }

    /// Statusword bits 13, 12 and 10 (homing error, homing attained, target reached), CiA402's
    /// table for homing mode.
    pub fn status_bits(&self) -> (bool, bool, bool) {
        let still = self.vel == 0.0;
        match self.phase {
            Phase::Idle => (false, false, true),
            Phase::FindCam { .. } | Phase::ToSwitch(_) | Phase::ToEdge(_) | Phase::Searching { .. } => {
                (false, false, false)
            }
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

    fn searching(dir: f64) -> Homing {
        Homing { phase: Phase::Searching { dir }, ..Homing::default() }
    }

    #[test]
    fn the_index_is_found_where_the_shaft_crosses_a_whole_turn_either_way() {
        let none = Switches::default();
        for (from, to, at) in [(0.9, 1.1, 1.0), (-1.1, -0.9, -1.0), (-0.1, 0.1, 0.0), (2.1, 1.9, 2.0)] {
            assert_eq!(searching(1.0).track(from * TAU, to * TAU, &none), Some(at * TAU), "{from} → {to}");
        }
        assert_eq!(searching(1.0).track(1.2 * TAU, 1.3 * TAU, &none), None);
        assert_eq!(Homing::default().track(0.9 * TAU, 1.1 * TAU, &none), None, "only while searching");
    }

    #[test]
    fn a_stop_after_the_index_attains_homing() {
        let mut h = Homing { phase: Phase::Stopping, vel: 10.0, acc: 100.0, ..Homing::default() };
        assert_eq!(h.status_bits(), (false, true, false));
        for _ in 0..20 {
            h.step(0.01);
        }
        assert_eq!((h.phase, h.vel), (Phase::Attained, 0.0));
        assert_eq!(h.status_bits(), (false, true, true));
    }

    #[test]
    fn the_methods_map_to_their_switch_edge_and_direction() {
        assert_eq!(start(37), Start::Here);
        assert_eq!(start(35), Start::Here);
        assert!(matches!(start(33), Start::Index(d) if d < 0.0));
        assert!(matches!(start(34), Start::Index(d) if d > 0.0));
        let e = |m| match start(m) {
            Start::Edge(e) => (e.switch, e.from, e.dir, e.index),
            other => panic!("{m}: {other:?}"),
        };
        assert_eq!(e(1), (Switch::NegativeLimit, true, 1.0, true));
        assert_eq!(e(18), (Switch::PositiveLimit, true, -1.0, false));
        assert_eq!(e(3), (Switch::Home, true, -1.0, true));
        assert_eq!(e(20), (Switch::Home, false, 1.0, false));
        assert_eq!(e(5), (Switch::Home, true, 1.0, true));
        assert_eq!(e(22), (Switch::Home, false, -1.0, false));
        for m in [15, 16, 31, 32, 36, 0, -1, 38] {
            assert_eq!(start(m), Start::Unsupported, "{m}");
        }
        let cam = |m| match start(m) {
            Start::Cam(first, e) => (first, e.from, e.dir, e.index),
            other => panic!("{m}: {other:?}"),
        };
        assert_eq!(cam(7), (1.0, true, -1.0, true));
        assert_eq!(cam(10), (1.0, true, 1.0, true));
        assert_eq!(cam(12), (-1.0, false, -1.0, true));
        assert_eq!(cam(29), (-1.0, false, 1.0, false));
    }

    #[test]
    fn a_home_switch_method_runs_to_the_switch_then_back_to_its_edge() {
        // Method 3: home switch active above 1 rev; from 0.5 rev up to it, then down off it.
        let sw = Switches { home_rev: Some(1.0), ..Switches::default() };
        let Start::Edge(edge) = start(19) else { panic!() };
        let mut h = Homing { phase: begin(edge, &sw, 0.5 * TAU), ..Homing::default() };
        assert!(matches!(h.phase, Phase::ToSwitch(_)));
        assert_eq!(h.track(0.95 * TAU, 1.05 * TAU, &sw), None);
        assert!(matches!(h.phase, Phase::ToEdge(_)), "on the switch: back down");
        assert_eq!(h.track(1.1 * TAU, 1.05 * TAU, &sw), None, "still on it");
        assert_eq!(h.track(1.02 * TAU, 0.98 * TAU, &sw), Some(TAU), "home on the edge");
        assert_eq!(h.phase, Phase::Stopping);
        // The wrong polarity for the method, or no switch: an error at once.
        let below = Switches { home_active_below: true, ..sw };
        assert_eq!(begin(edge, &below, 0.5 * TAU), Phase::Error);
        assert_eq!(begin(edge, &Switches::default(), 0.5 * TAU), Phase::Error);
    }

    #[test]
    fn a_limit_switch_met_on_the_way_is_a_homing_error() {
        let sw = Switches { positive_limit_rev: Some(2.0), home_rev: Some(3.0), ..Switches::default() };
        let Start::Edge(edge) = start(20) else { panic!() };
        let mut h = Homing { phase: begin(edge, &sw, 0.0), ..Homing::default() };
        assert!(matches!(h.phase, Phase::ToEdge(_)));
        h.track(1.99 * TAU, 2.01 * TAU, &sw);
        assert_eq!(h.phase, Phase::Error);
        assert_eq!(sw.inputs(2.5 * TAU), 0b010);
        assert_eq!(sw.inputs(3.5 * TAU), 0b110);
    }

    #[test]
    fn a_cam_is_found_past_a_reversal_and_homed_on_the_edge_the_method_names() {
        // A cam from 1 to 2 rev, the positive limit at 3; method 23 (as 7, no index) from 2.5:
        // up to the limit, back down onto the cam, down off it at its lower edge.
        let sw = Switches {
            home_rev: Some(1.0),
            home_to_rev: Some(2.0),
            positive_limit_rev: Some(3.0),
            ..Switches::default()
        };
        let Start::Cam(first, edge) = start(23) else { panic!() };
        let mut h = Homing { phase: begin_cam(first, edge, &sw, 2.5 * TAU), ..Homing::default() };
        assert!(matches!(h.phase, Phase::FindCam { dir, reversed: false, .. } if dir > 0.0));
        h.track(2.99 * TAU, 3.01 * TAU, &sw);
        assert!(matches!(h.phase, Phase::FindCam { dir, reversed: true, .. } if dir < 0.0), "{:?}", h.phase);
        h.track(2.01 * TAU, 1.99 * TAU, &sw);
        assert!(matches!(h.phase, Phase::ToEdge(_)), "on the cam, leaving it downwards: {:?}", h.phase);
        assert_eq!(h.track(1.01 * TAU, 0.99 * TAU, &sw), Some(TAU), "its lower edge");
        // Method 26 (as 10, no index) from inside: up and off at the upper edge.
        let Start::Cam(first, edge) = start(26) else { panic!() };
        let mut h = Homing { phase: begin_cam(first, edge, &sw, 1.5 * TAU), ..Homing::default() };
        assert!(matches!(h.phase, Phase::ToEdge(_)));
        assert_eq!(h.track(1.99 * TAU, 2.01 * TAU, &sw), Some(2.0 * TAU));
        // Method 24 (as 8) from inside: down off the cam first, then up onto its lower edge.
        let Start::Cam(first, edge) = start(24) else { panic!() };
        let mut h = Homing { phase: begin_cam(first, edge, &sw, 1.5 * TAU), ..Homing::default() };
        assert!(matches!(h.phase, Phase::ToSwitch(_)));
        h.track(1.01 * TAU, 0.99 * TAU, &sw);
        assert!(matches!(h.phase, Phase::ToEdge(_)));
        assert_eq!(h.track(0.98 * TAU, 0.995 * TAU, &sw), None);
        assert_eq!(h.track(0.995 * TAU, 1.005 * TAU, &sw), Some(TAU));
        // Past the reversal the other limit is an error.
        let both = Switches { negative_limit_rev: Some(-1.0), ..sw };
        let mut h = Homing { phase: Phase::FindCam { dir: -1.0, reversed: true, edge }, ..Homing::default() };
        h.track(-0.99 * TAU, -1.01 * TAU, &both);
        assert_eq!(h.phase, Phase::Error);
        assert_eq!(begin_cam(first, edge, &Switches::default(), 0.0), Phase::Error, "no home switch");
    }
}
