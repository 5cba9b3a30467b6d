//! Process-data groups: slaves whose process data go in a frame of their own, each group's
//! frame sent every so many base cycles, with its own working-counter check.
use ferrocat_wire::{Address, Command};

use super::Master;
use crate::error::{ConfigError, Result};
use crate::io::Io;
use crate::plan::{Plan, PlanDatagram};

/// The most process data one frame's LRW carries (1 500 bytes of payload less the EtherCAT
/// header, the datagram's header and its working counter).
const MAX_GROUP_BYTES: u32 = 1486;

/// A process-data group.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct Group {
    /// Its name, for statistics and messages.
    pub name: String,
    /// Its slaves, by position.
    pub positions: Vec<u16>,
    /// Every how many base cycles its frame is sent (1: every cycle).
    pub every: u32,
}

impl<I: Io> Master<I> {
    /// The plan the groups make of the slaves' mapping.
    pub(super) fn plan_for_groups(&self) -> Result<Plan> {
        let n = self.slaves.len();
        let mut member: Vec<Option<&str>> = vec![None; n];
        for g in &self.groups {
            if g.every == 0 {
                return Err(ConfigError::GroupEveryZero(g.name.clone()).into());
            }
            for &p in &g.positions {
                match member.get_mut(p as usize) {
                    None => {
                        return Err(
                            ConfigError::GroupNoSuchSlave { group: g.name.clone(), position: p, count: n }.into()
                        )
                    }
                    Some(Some(other)) => {
                        return Err(ConfigError::SlaveInTwoGroups {
                            position: p,
                            first: other.to_string(),
                            second: g.name.clone(),
                        }
                        .into())
                    }
                    Some(m) => *m = Some(&g.name),
                }
            }
        }
        let mut groups = self.groups.clone();
        let rest: Vec<u16> = (0..n as u16).filter(|&p| member[p as usize].is_none()).collect();
        if !rest.is_empty() {
            groups.push(Group { name: "default".into(), positions: rest, every: 1 });
        }
        groups.sort_by_key(|g| g.every);
        let mut plan = Plan { registers: vec![Vec::new(); n], entries_at: vec![(None, None); n], ..Plan::default() };
        let mut logical = 0u32;
        for g in &groups {
            let start = logical;
            let mut at = start;
            let mut places = Vec::new();
            for &p in &g.positions {
                let bytes = self.slaves[p as usize].mapping().output_bits().div_ceil(8);
                places.push((p, at, None));
                at += bytes;
            }
            for place in &mut places {
                let bytes = self.slaves[place.0 as usize].mapping().input_bits().div_ceil(8);
                place.2 = Some(at);
                at += bytes;
            }
            let len = at - start;
            if len == 0 {
                continue;
            }
            if len > MAX_GROUP_BYTES {
                return Err(
                    ConfigError::GroupTooLarge { group: g.name.clone(), bytes: len, max: MAX_GROUP_BYTES }.into()
                );
            }
            let mut wkc = 0u16;
            for &(p, out_at, in_at) in &places {
                let s = &self.slaves[p as usize];
                let (has_out, has_in) = (s.mapping().output_bits() > 0, s.mapping().input_bits() > 0);
                wkc += 2 * has_out as u16 + has_in as u16;
                let in_at = in_at.unwrap_or(out_at);
                plan.registers[p as usize] = super::process_data::process_registers(s, out_at, in_at);
                // The images mirror the frame: a datagram's data 10 bytes after its offset.
                plan.entries_at[p as usize] =
                    (has_out.then_some((out_at + 10) * 8), has_in.then_some((in_at + 10) * 8));
            }
            plan.frames.push(vec![PlanDatagram {
                command: Command::LRW,
                address: Address::Logical(start),
                length: len as u16,
                output_offset: Some(start),
                input_offset: Some(start),
                expected_wkc: Some(wkc),
            }]);
            plan.frame_every.push(g.every);
            plan.frame_names.push(g.name.clone());
            logical = at;
        }
        plan.output_bytes = logical + 10 + 2;
        plan.input_bytes = logical + 10 + 2;
        plan.validate()?;
        Ok(plan)
    }
}

impl<'a, I: Io> crate::master::part::Config<'a, I> {
    /// Puts the process data in groups, from the next
    /// [`States::configure`](crate::part::States::configure) on: each group's slaves' outputs, then their inputs, in an
    /// LRW of its own at a logical address of its own, sent every `every` cycles and checked
    /// on its own ([`Diagnosis::plan_frame_stats`](crate::part::Diagnosis::plan_frame_stats)). Slaves in no group form a group `default`,
    /// sent every cycle. The groups that go every cycle come first: the first frame of a cycle
    /// carries the clock-sync method's datagrams. A slave in two groups, a position past the
    /// last slave, a group sent never (`every` 0) or one whose data do not fit a frame is an
    /// error at the layout.
    pub fn set_groups(&mut self, groups: Vec<Group>) {
        self.m.groups = groups;
    }

    /// The groups given ([`Config::set_groups`](crate::part::Config::set_groups)).
    pub fn groups(self) -> &'a [Group] {
        &self.m.groups
    }
}
