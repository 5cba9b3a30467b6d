//! The drive's power stage, motor and load, and its control loops: a cascade of position
//! (P), velocity (PI) and a current-limited torque loop (first-order lag), stepped at a fixed
//! control rate in the drive's own time. SI units inside; increments at the edges.

/// Motor, load and control constants. The defaults are a small servo (≈ 200 W class): they
/// are not any vendor's figures, only plausible ones, and every one is a field to change.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct MotorParams {
    /// Motor plus load inertia.
    pub inertia_kg_m2: f64,
    pub viscous_nm_per_rad_s: f64,
    pub coulomb_nm: f64,
    /// Rated torque: 0x6071/0x6077/0x6072 are in per mille of it.
    pub rated_torque_nm: f64,
    /// Time constant of the current (torque) loop.
    pub torque_lag_s: f64,
    /// Position increments per motor revolution (0x608F when the dictionary gives one).
    pub increments_per_rev: f64,
    /// Position loop gain (1/s), velocity loop gain (N·m·s/rad) and integral time (s).
    pub position_kp_per_s: f64,
    pub velocity_kp: f64,
    pub velocity_ti_s: f64,
    /// The control loops' period (the drive's own timer).
    pub loop_ns: u64,
}

impl Default for MotorParams {
    fn default() -> Self {
        let inertia = 2.0e-4;
        // Velocity loop bandwidth ≈ 100 Hz; position loop a quarter of it.
        let w_v = 2.0 * std::f64::consts::PI * 100.0;
        MotorParams {
            inertia_kg_m2: inertia,
            viscous_nm_per_rad_s: 2.0e-4,
            coulomb_nm: 0.02,
            rated_torque_nm: 0.64,
            torque_lag_s: 0.2e-3,
            increments_per_rev: 131_072.0,
            position_kp_per_s: w_v / 4.0,
            velocity_kp: inertia * w_v,
            velocity_ti_s: 4.0 / w_v,
            loop_ns: 62_500,
        }
    }
}

/// What the loops are asked to follow at one control step.
#[derive(Debug, Clone, Copy, PartialEq)]
pub enum Demand {
    /// Power stage off: the motor coasts.
    Off,
    /// Position (increments) with velocity and acceleration feed-forward (increments/s, /s²).
    Position { pos: f64, vel: f64, acc: f64 },
    /// Velocity (increments/s).
    Velocity(f64),
    /// Torque (N·m).
    Torque(f64),
}

#[derive(Debug, Clone, Default, PartialEq)]
pub struct Mechanics {
    pub pos_rad: f64,
    pub vel_rad_s: f64,
    /// Torque the motor produces (after the current loop's lag and limit).
    pub torque_nm: f64,
    vel_integral: f64,
    /// The torque limit was hit in the last step.
    pub limited: bool,
}

impl Mechanics {
    pub fn reset_loops(&mut self) {
        self.vel_integral = 0.0;
    }

    /// One control step of `dt` seconds with torque limited to `max_torque_nm`.
    pub fn step(&mut self, p: &MotorParams, demand: Demand, max_torque_nm: f64, dt: f64) {
        let per_rad = p.increments_per_rev / std::f64::consts::TAU;
        let velocity_pi = |m: &mut Mechanics, vel_ref: f64, ff: f64| -> f64 {
            let e = vel_ref - m.vel_rad_s;
            let cmd = p.velocity_kp * (e + m.vel_integral / p.velocity_ti_s) + ff;
            // Anti-windup: integrate only while the command is inside the limit.
            if cmd.abs() < max_torque_nm {
                m.vel_integral += e * dt;
            }
            cmd
        };
        let cmd = match demand {
            Demand::Off => {
                self.vel_integral = 0.0;
                0.0
            }
            Demand::Position { pos, vel, acc } => {
                let vel_ref = p.position_kp_per_s * (pos / per_rad - self.pos_rad) + vel / per_rad;
                velocity_pi(self, vel_ref, p.inertia_kg_m2 * acc / per_rad)
            }
            Demand::Velocity(v) => velocity_pi(self, v / per_rad, 0.0),
            Demand::Torque(t) => t,
        };
        let limited_cmd = cmd.clamp(-max_torque_nm, max_torque_nm);
        self.limited = limited_cmd != cmd;
        // Current loop: first-order lag, exact for a constant command over the step. `libm`,
        // not the platform's `exp`: the same seed gives the same trajectory on every machine.
        let k = 1.0 - libm::exp(-dt / p.torque_lag_s);
        self.torque_nm = if demand == Demand::Off { 0.0 } else { self.torque_nm + (limited_cmd - self.torque_nm) * k };
        // Load: inertia, viscous and Coulomb friction; friction holds a slow motor at rest.
        let drive = self.torque_nm - p.viscous_nm_per_rad_s * self.vel_rad_s;
        let moving = self.vel_rad_s.abs() > 1e-9;
        let friction = if moving { p.coulomb_nm * self.vel_rad_s.signum() } else { 0.0 };
        if !moving && drive.abs() <= p.coulomb_nm {
            self.vel_rad_s = 0.0;
            return;
        }
        let stuck_friction = if moving { friction } else { p.coulomb_nm * drive.signum() };
        let new_vel = self.vel_rad_s + (drive - stuck_friction) / p.inertia_kg_m2 * dt;
        // Friction stops the motor; it does not reverse it.
        let new_vel = if moving && new_vel.signum() != self.vel_rad_s.signum() && drive.abs() <= p.coulomb_nm {
            0.0
        } else {
            new_vel
        };
        self.pos_rad += 0.5 * (self.vel_rad_s + new_vel) * dt;
        self.vel_rad_s = new_vel;
    }

    pub fn position_increments(&self, p: &MotorParams) -> f64 {
        self.pos_rad * p.increments_per_rev / std::f64::consts::TAU
    }

    pub fn velocity_increments(&self, p: &MotorParams) -> f64 {
        self.vel_rad_s * p.increments_per_rev / std::f64::consts::TAU
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn run(m: &mut Mechanics, p: &MotorParams, d: Demand, seconds: f64) {
        let dt = p.loop_ns as f64 * 1e-9;
        for _ in 0..(seconds / dt) as usize {
            m.step(p, d, 3.0 * p.rated_torque_nm, dt);
        }
    }

    #[test]
    fn the_position_loop_settles_on_its_target() {
        let p = MotorParams::default();
        let mut m = Mechanics::default();
        run(&mut m, &p, Demand::Position { pos: 50_000.0, vel: 0.0, acc: 0.0 }, 0.5);
        assert!((m.position_increments(&p) - 50_000.0).abs() < 5.0, "{}", m.position_increments(&p));
        assert!(m.vel_rad_s.abs() < 0.01);
    }

    #[test]
    fn the_velocity_loop_reaches_its_speed_and_torque_accelerates_the_inertia() {
        let p = MotorParams::default();
        let mut m = Mechanics::default();
        run(&mut m, &p, Demand::Velocity(131_072.0), 0.3);
        assert!((m.velocity_increments(&p) - 131_072.0).abs() < 100.0, "{}", m.velocity_increments(&p));
        // A constant torque beyond friction: a = (T − c − b·ω)/J, from rest.
        let mut m = Mechanics::default();
        run(&mut m, &p, Demand::Torque(0.1), 0.01);
        let expected = (0.1 - 0.02) / 2.0e-4 * 0.01;
        assert!((m.vel_rad_s - expected).abs() / expected < 0.05, "{} vs {expected}", m.vel_rad_s);
        // Below friction nothing moves.
        let mut m = Mechanics::default();
        run(&mut m, &p, Demand::Torque(0.01), 0.1);
        assert_eq!(m.vel_rad_s, 0.0);
    }

    #[test]
    fn the_torque_limit_holds() {
        let p = MotorParams::default();
        let mut m = Mechanics::default();
        run(&mut m, &p, Demand::Position { pos: 1e9, vel: 0.0, acc: 0.0 }, 0.05);
        assert!(m.limited);
        assert!(m.torque_nm <= 3.0 * p.rated_torque_nm + 1e-12);
    }
}
