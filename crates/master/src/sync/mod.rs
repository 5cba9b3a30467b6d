//! Cyclic clock synchronisation between the master and the reference clock. Every method sits
//! behind one small interface, as linuxptp's servos do: each cycle the master hands a
//! [`ClockSync`] what its DC frame measured and carries out the [`Correction`] it returns.
mod chen2016;
mod config;
mod conventional;
mod ferrocat;
mod flywheel;
mod lock;
mod park2020;
mod pi;
mod state;
mod sync0_plan;

pub use chen2016::Chen2016;
pub use config::{FerrocatSettings, SyncMethod};
pub use conventional::{Conventional, Nominal};
pub use ferrocat::{
    Ferrocat, FollowerDelays, LostFrames, Options as FerrocatOptions, ProbeFrames, Probing, Steering, DENSE_FIT_WINDOW,
    FIT_WINDOW,
};
pub use flywheel::speed_deviation;
pub use lock::{Lock, LockState, LockThresholds};
pub use park2020::Park2020;
pub use pi::SoemPi;
pub use state::{ProbeStats, SyncState};
pub use sync0_plan::Sync0Plan;

/// The longest cycle a method accepts: SYNC0's cycle register (0x09A0) is 32 bits of ns.
pub const MAX_CYCLE_NS: u64 = u32::MAX as u64;

/// Who follows whom.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Coupling {
    /// The master writes its time into the reference's 0x0910 every cycle (IgH, Park 2020).
    ReferenceFollowsMaster,
    /// The reference runs free; the master adjusts its cycle to it (SOEM's examples, Chen 2016).
    MasterFollowsReference,
}

/// What one cycle's DC frame measured. Times are DC system time (ns since 2000) on the
/// master's clock.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct Sample {
    /// Cycle number (gaps mean lost frames).
    pub cycle: u64,
    /// When the master built the frame (the time it wrote into it).
    pub built_ns: u64,
    /// When the frame left and when its reply began to arrive, if the link stamps them;
    /// otherwise `tx_ns` is `None` and `rx_ns` is when the master had the reply.
    pub tx_ns: Option<u64>,
    /// See `tx_ns`.
    pub rx_ns: u64,
    /// The reference's system time as the frame passed it (the FRMW reply; a 32-bit
    /// reference's unwrapped onto 64 bits).
    pub reference_ns: u64,
    /// The reference's System_Time_Offset (0x0920) in force as the frame passed it, where the
    /// frame read it (methods that steer the offset); unwrapped likewise.
    pub reference_offset_ns: Option<u64>,
    /// The reference's 0x092C (local − received, filtered), signed.
    pub difference_ns: i64,
    /// How long the frame spent behind the reference before it came back through it
    /// (receive time of its return port minus port 0).
    pub loop_ns: u64,
    /// Time on the wire the stamps include beyond the frame's head: the whole frame at
    /// 100 Mbit/s when the receive time is taken after the last byte (software), 0 for a
    /// NIC that stamps the start of frame.
    pub frame_ns: u64,
    /// From the frame's head to the end of its process data (its LRW datagrams), which the
    /// slaves take at their next SYNC0; 0 for a frame without.
    pub data_ns: u64,
    /// A follower's clock as the same frame found it, where the method asks for one
    /// ([`CyclePlan::read_follower_clock`]).
    pub follower: Option<FollowerClock>,
}

/// A follower's clock as a frame passed it: its local time and the speed its time control
/// loop was applying, from which the master takes the loop's corrections back out.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct FollowerClock {
    /// Local time (ns) at the frame's arrival: the ECAT read of 0x0910 plus its delay (0x0928)
    /// less its offset (0x0920), all from the same read.
    pub local_ns: u64,
    /// Speed counter start (0x0930) and difference (0x0932): the rate the loop applied since
    /// its last sample (esc-spec §3.5).
    pub speed_start: u16,
    /// See `speed_start`.
    pub speed_diff: i16,
    /// Which way a positive speed counter difference moves this ESC's clock, where the master
    /// measured it at the DC initialisation (true: it slows it).
    pub speed_diff_slows: Option<bool>,
}

impl Sample {
    /// The one-way time from building the frame to its passing the reference, as a round trip
    /// shows it: the send delay where the link stamps it, plus half of what remains of the
    /// round trip once the loop behind the reference and the frame's own length are taken out
    /// (Park 2020 eq. 3 per sample, without its frame-length bias).
    pub fn lead_ns(&self) -> i64 {
        // Differences of u64 times on the wrapping circle, as DC time does.
        let sent = self.tx_ns.unwrap_or(self.built_ns);
        let send = sent.wrapping_sub(self.built_ns) as i64;
        let rtt =
            (self.rx_ns.wrapping_sub(sent) as i64).wrapping_sub(self.loop_ns as i64).wrapping_sub(self.frame_ns as i64);
        send.wrapping_add(rtt / 2)
    }
}

/// What the master does after a sample.
#[derive(Debug, Clone, Copy, Default, PartialEq, Eq)]
pub struct Correction {
    /// Add this to every DC slave's System_Time_Offset (0x0920); where the method steers the
    /// reference's offset, to every other one (the method moves the reference itself).
    pub shift_offsets_ns: i64,
    /// The master's next cycle period (master-follows-reference methods).
    pub next_period_ns: Option<u64>,
}

/// Counts of what a method's line has been through.
#[derive(Debug, Clone, Copy, Default, PartialEq, Eq)]
pub struct LineEvents {
    /// Restarts: a change of rate or phase (or a gap too long to share a line).
    pub restarts: u64,
    /// Changes the change test signalled and the points after it did not confirm.
    pub false_alarms: u64,
}

impl LineEvents {
    /// What happened since `earlier`.
    pub fn since(self, earlier: LineEvents) -> LineEvents {
        LineEvents {
            restarts: self.restarts.saturating_sub(earlier.restarts),
            false_alarms: self.false_alarms.saturating_sub(earlier.false_alarms),
        }
    }
}

/// What a method wants of a cycle's frames, as one value ([`ClockSync::plan`]).
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct CyclePlan {
    /// Reference-follows-master: the cycle's frame carries the master's time into the
    /// reference's 0x0910 ([`ClockSync::reference_time`]).
    pub write_reference_time: bool,
    /// Reference-follows-master: the method steers the reference through its
    /// System_Time_Offset (0x0920) instead of its time control loop; its frames then read the
    /// offset, or replace it with what [`ReferenceSteering::reference_offset`] returns.
    pub steer_reference_offset: bool,
    /// The cycle's frame also reads a follower's clock ([`Sample::follower`]).
    pub read_follower_clock: bool,
    /// Probe frames after the cycle's: each only reads the reference's time (and offset), and
    /// its sample goes to [`ReferenceSteering::probe`].
    pub probes: u32,
    /// How long after the cycle's frame was built its probes must have ended (ns): the next
    /// cycle's frame is due then. None starts that, at twice the probes' mean duration so far,
    /// would not end in time.
    pub probe_window_ns: u64,
    /// Offset steering: probe frames give the reference its offset too, not only read it.
    pub probes_give_offset: bool,
    /// A lost cycle's frame is made up at once by a frame that gives the reference its offset
    /// and reads its time (a probe's sample).
    pub make_up_lost_frames: bool,
}

impl Default for CyclePlan {
    /// The conventional cycle: the master's time into the reference's 0x0910, nothing else.
    fn default() -> Self {
        CyclePlan {
            write_reference_time: true,
            steer_reference_offset: false,
            read_follower_clock: false,
            probes: 0,
            probe_window_ns: 0,
            probes_give_offset: false,
            make_up_lost_frames: false,
        }
    }
}

/// A clock-synchronisation method, as linuxptp's servos: each cycle the master hands it what the frame measured and carries out the [`Correction`] it returns.
/// `Send`, so that an application may run its cycles in a thread of their own.
pub trait ClockSync: Send {
    /// The method's name (a [`SyncMethod::PRESETS`] family).
    fn name(&self) -> &'static str;
    /// Who follows whom under it.
    fn coupling(&self) -> Coupling;
    /// Reference-follows-master: the time to write into the reference's 0x0910 for a frame
    /// built at `built_ns`.
    fn reference_time(&mut self, built_ns: u64) -> u64 {
        built_ns
    }
    /// What the method wants of cycle `cycle`'s frames. The master asks when it builds the
    /// cycle's frame, and again once [`ClockSync::update`] has taken the frame's sample, for
    /// what follows the frame (the probes, a lost frame made up, the offsets shifted): the
    /// sample may change that part.
    fn plan(&self, _cycle: u64) -> CyclePlan {
        CyclePlan::default()
    }
    /// The master's offset to the reference that `sample` measures, ns: the reference's time
    /// at the frame's passage less what the method believed it (its
    /// [`ClockSync::reference_belief_ns`] at the frame's build plus the one-way lead), as
    /// linuxptp's "master offset". Asked before [`ClockSync::update`] takes the sample. `None`
    /// where the method keeps no estimate of the reference's time to compare.
    fn offset_ns(&self, sample: &Sample) -> Option<i64> {
        if self.coupling() == Coupling::MasterFollowsReference && self.master_time(sample.built_ns).is_none() {
            return None;
        }
        let believed = self.reference_belief_ns(sample.built_ns).wrapping_add_signed(sample.lead_ns());
        Some(sample.reference_ns.wrapping_sub(believed) as i64)
    }
    /// Takes one cycle's sample (`None`: the frame was lost).
    fn update(&mut self, sample: Option<&Sample>) -> Correction;
    /// Master follows reference: the master's clock is its estimate of the reference's system
    /// time at `host_ns` (the master's own system time); `None` where the method keeps none.
    fn master_time(&self, _host_ns: u64) -> Option<u64> {
        None
    }
    /// What the method believes the reference's system time is at the master's own system
    /// time `host_ns`, for a calibration to compare with what the reference latched. By
    /// default the master's clock (its own time, or [`ClockSync::master_time`]); a method that
    /// lets the reference run on its crystal between corrections knows where in that
    /// sawtooth the instant falls, which is not an error of its stamps.
    fn reference_belief_ns(&self, host_ns: u64) -> u64 {
        self.master_time(host_ns).unwrap_or(host_ns)
    }
    /// The method's offset steering and probes, where it has them (ferrocat's method); `None`
    /// for a method that only takes the cycle's sample, as the papers' do.
    fn reference_steering(&mut self) -> Option<&mut dyn ReferenceSteering> {
        None
    }
}

/// What a method adds that steers the reference by its offset and takes samples between
/// cycles (ferrocat's; [`ClockSync::reference_steering`]): the master asks it only where the method has
/// it.
pub trait ReferenceSteering {
    /// The offset to give the reference in the frame built at `built_ns`, which stands for
    /// `holds_ns` after the frame's passage, until the next frame gives another (`None`: until
    /// the next cycle's frame); `None`: read it only.
    fn reference_offset(&mut self, built_ns: u64, holds_ns: Option<u64>) -> Option<u64>;
    /// Takes a probe frame's sample.
    fn probe(&mut self, sample: &Sample);
    /// A master − reference error measured by an independent path (`crate::calibrate`): a
    /// method that can takes it out from now on. Returns whether it did (the papers' methods,
    /// as published, do not).
    fn take_error(&mut self, error_ns: i64) -> bool;
    /// What the method's line has been through so far; `None`: it keeps no line.
    fn line_events(&self) -> Option<LineEvents>;
    /// What every follower's System_Time_Delay (0x0928) should carry over its measured delay
    /// from now on; `None`: leave the delays as they are.
    fn follower_delay_bias_ns(&mut self) -> Option<i64>;
}

#[cfg(test)]
mod tests;
