//! A process-data plan from outside the master, as a configuration tool makes one (an ENI's):
//! the station addresses the scan gives, the FMMU and SyncManager registers each slave gets,
//! where its entries sit, and the cyclic frames, each datagram with its place in the output and
//! input images. With a plan the master follows it to the byte instead of laying the image out
//! itself: an application built against the tool's image finds its variables where the tool
//! put them.
use ferrocat_wire::{Address, Command};

use crate::error::{ConfigError, ImageSide, Result};

/// The output and input images mirror the frames (as TwinCAT lays them out): a datagram's
/// offset is where its header starts, its data follow the 10-byte header.
const HEADER_LEN: u32 = 10;

/// Datagrams a plan's frame may hold (the cyclic exchange builds them on the stack).
pub const MAX_PLAN_DATAGRAMS: usize = 64;

/// A plan; see the module's documentation.
#[derive(Debug, Clone, Default, PartialEq, Eq)]
pub struct Plan {
    /// The station address of the slave at each position (empty: the master's own,
    /// [`crate::STATION_BASE`] + position).
    pub stations: Vec<u16>,
    /// By position: the registers written before SAFEOP (FMMUs, process-data SyncManagers),
    /// each its address and bytes, in order. These replace the master's own layout.
    pub registers: Vec<Vec<(u16, Vec<u8>)>>,
    /// By position: the SDO downloads made in PREOP before the mapping is read (PDO assignment
    /// and mapping, settings), in order.
    pub sdos: Vec<Vec<PlanSdo>>,
    /// By position: the SoE IDN writes made in PREOP after the SDOs, before the mapping is read
    /// (a drive's telegram configuration, its settings), in order.
    pub idns: Vec<Vec<PlanIdn>>,
    /// By position: the first bit of the slave's outputs in the output image and of its inputs
    /// in the input image, where it has them; its entries follow one another from there.
    pub entries_at: Vec<(Option<u32>, Option<u32>)>,
    /// The cyclic frames, sent one after the other in the cycles they are due.
    pub frames: Vec<Vec<PlanDatagram>>,
    /// By frame: every how many cycles it is sent (a process-data group's cycle, as a
    /// multiple of the base cycle; missing or 0: every cycle). The first frame due in a cycle
    /// carries the clock-sync method's datagrams: the fastest group's should be every cycle.
    pub frame_every: Vec<u32>,
    /// By frame: a name for statistics (a group's, a task's), where given.
    pub frame_names: Vec<String>,
    /// Bytes of the output image.
    pub output_bytes: u32,
    /// Bytes of the input image.
    pub input_bytes: u32,
}

/// An SDO download of a plan.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct PlanSdo {
    /// Object index.
    pub index: u16,
    /// Subindex.
    pub subindex: u8,
    /// The whole object at once.
    pub complete_access: bool,
    /// The data.
    pub data: Vec<u8>,
    /// What it is for, for messages.
    pub comment: String,
}

/// An SoE IDN write of a plan.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct PlanIdn {
    /// The drive (axis) of the device, 0–7.
    pub drive: u8,
    /// The IDN.
    pub idn: ferrocat_wire::soe::Idn,
    /// The elements written (usually the value).
    pub elements: ferrocat_wire::soe::Elements,
    /// The data.
    pub data: Vec<u8>,
    /// How long the drive may take to answer, where given, ms.
    pub timeout_ms: Option<u32>,
    /// What it is for, for messages.
    pub comment: String,
}

/// A datagram of a plan's cyclic frame.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct PlanDatagram {
    /// Its command.
    pub command: Command,
    /// Where it goes.
    pub address: Address,
    /// Bytes of data.
    pub length: u16,
    /// Where its header starts in the output image, if its data come from there.
    pub output_offset: Option<u32>,
    /// Where its header starts in the input image, if its answer goes there.
    pub input_offset: Option<u32>,
    /// The working counter a whole cycle gives, if checked.
    pub expected_wkc: Option<u16>,
}

impl Plan {
    /// Checks that every datagram's data lie within its images, and that no frame holds more
    /// datagrams than the cyclic exchange takes.
    pub fn validate(&self) -> Result<()> {
        for (f, frame) in self.frames.iter().enumerate() {
            if frame.len() > MAX_PLAN_DATAGRAMS {
                return Err(ConfigError::PlanFrameTooLong {
                    frame: f,
                    datagrams: frame.len(),
                    max: MAX_PLAN_DATAGRAMS,
                }
                .into());
            }
            for (k, d) in frame.iter().enumerate() {
                for (offset, bytes, image) in [
                    (d.output_offset, self.output_bytes, ImageSide::Output),
                    (d.input_offset, self.input_bytes, ImageSide::Input),
                ] {
                    if let Some(o) = offset {
                        let end = o as u64 + HEADER_LEN as u64 + d.length as u64;
                        if end > bytes as u64 {
                            return Err(ConfigError::PlanDataOutsideImage {
                                frame: f,
                                datagram: k,
                                end,
                                bytes,
                                side: image,
                            }
                            .into());
                        }
                    }
                }
            }
        }
        Ok(())
    }

    /// Where the data of a datagram at `offset` start in its image.
    pub(crate) fn data_at(offset: u32) -> usize {
        (offset + HEADER_LEN) as usize
    }

    /// The working counter a whole cycle gives: the sum of the checked datagrams'.
    pub fn expected_wkc(&self) -> u16 {
        self.frames.iter().flatten().filter_map(|d| d.expected_wkc).fold(0u16, u16::saturating_add)
    }

    /// Every how many cycles frame `f` is sent.
    pub fn every(&self, f: usize) -> u64 {
        self.frame_every.get(f).copied().unwrap_or(1).max(1) as u64
    }

    /// Whether frame `f` is sent in cycle `cycle` (counted from 0).
    pub(crate) fn due(&self, f: usize, cycle: u64) -> bool {
        cycle % self.every(f) == 0
    }
}

/// What became of one of a plan's frames (a process-data group's) so far.
#[derive(Debug, Clone, Copy, Default, PartialEq, Eq)]
pub struct FrameStats {
    /// Cycles it was sent in.
    pub sent: u64,
    /// Of those, the ones it was lost in.
    pub lost: u64,
    /// Of those answered, the ones with a working counter short of its datagrams' expected.
    pub short: u64,
    /// Its working counter the last time it was answered.
    pub last_wkc: u16,
    /// The working counter it should come back with.
    pub expected_wkc: u16,
}

/// A plan's buffers for one cycle: one per datagram, made when the plan is set, so that the
/// exchange does not allocate; and each frame's statistics.
#[derive(Debug, Default)]
pub(crate) struct PlanBuffers {
    pub frames: Vec<Vec<Vec<u8>>>,
    pub stats: Vec<FrameStats>,
}

impl PlanBuffers {
    pub fn for_plan(plan: &Plan) -> Self {
        PlanBuffers {
            frames: plan.frames.iter().map(|f| f.iter().map(|d| vec![0u8; d.length as usize]).collect()).collect(),
            stats: plan
                .frames
                .iter()
                .map(|f| FrameStats {
                    expected_wkc: f.iter().filter_map(|d| d.expected_wkc).fold(0u16, u16::saturating_add),
                    ..FrameStats::default()
                })
                .collect(),
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn lrw(length: u16, offset: u32, wkc: u16) -> PlanDatagram {
        PlanDatagram {
            command: Command::LRW,
            address: Address::Logical(0x0100_0000),
            length,
            output_offset: Some(offset),
            input_offset: Some(offset),
            expected_wkc: Some(wkc),
        }
    }

    #[test]
    fn a_plan_s_datagrams_stay_within_its_images() {
        let mut p = Plan {
            frames: vec![vec![lrw(13, 16, 5), lrw(2, 41, 3)]],
            output_bytes: 64,
            input_bytes: 64,
            ..Plan::default()
        };
        p.validate().unwrap();
        assert_eq!(p.expected_wkc(), 8);
        // 41 + 10 + 2 = 53 bytes: within 64, not within 52.
        p.input_bytes = 52;
        let e = p.validate().unwrap_err().to_string();
        assert!(e.contains("datagram 1: its data end at byte 53 of the 52-byte input image"), "{e}");
        p.input_bytes = 64;
        p.frames[0] = vec![lrw(1, 16, 1); MAX_PLAN_DATAGRAMS + 1];
        let e = p.validate().unwrap_err().to_string();
        assert!(e.contains("65 datagrams, more than 64"), "{e}");
    }
}
