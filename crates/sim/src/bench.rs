//! The virtual-time workload the benchmarks measure: a line of I/O terminals (an EK1100, then
//! EL1004/EL2004 alternating) brought to OP, then one frame per cycle with an LRW of the
//! whole process image and an FRMW distributing the reference clock, as SOEM sends it.
use ferrocat_wire::ethernet::{EthernetRepr, BROADCAST};
use ferrocat_wire::register::{Fmmu, SyncManager};
use ferrocat_wire::{Address, Command, DatagramHeader, FrameWriter};

use ferrocat_esc::dc::DcUnit;
use ferrocat_esc::DcWidth;
use ferrocat_segment::{Segment, SegmentConfig};

/// A segment of `slaves` devices, configured and in OP, with the cyclic frame ready.
#[derive(Debug)]
pub struct CyclicBench {
    pub seg: Segment,
    frame: Vec<u8>,
    /// The frame as it goes round, refilled each cycle (kept, so that a run allocates nothing).
    buf: Vec<u8>,
    len: usize,
    pub t_ns: u64,
    pub cycle_ns: u64,
    pub lost: u64,
}

/// Why a workload could not be built.
#[derive(Debug, thiserror::Error)]
pub enum BenchError {
    /// The segment of that size does not build.
    #[error("the benchmark's segment: {0}")]
    Segment(#[from] ferrocat_segment::SegmentError),
    /// A frame does not fit (a process image larger than one frame carries).
    #[error("the benchmark's frame: {0}")]
    Frame(#[from] ferrocat_wire::Error),
}

fn single(seg: &mut Segment, t: &mut u64, cmd: Command, address: Address, data: &[u8]) -> Result<(), BenchError> {
    let eth = EthernetRepr { dst: BROADCAST, src: [0x10; 6], vlan_tci: None, ethertype: 0 };
    let mut buf = [0u8; 1514];
    let mut w = FrameWriter::new(&mut buf, &eth)?;
    w.push(&DatagramHeader::new(cmd, 0, address, data.len() as u16), data, 0)?;
    let n = w.finish()?;
    let back = seg.exchange(&mut buf[..n], *t).unwrap_or(*t + 100_000);
    *t = back + 1_000;
    Ok(())
}

impl CyclicBench {
    pub fn new(slaves: usize, cycle_ns: u64, seed: u64) -> Result<Self, BenchError> {
        // Every terminal's SYNC unit on, so that each ESC has a system time and takes a time
        // control loop sample per cycle (the terminals as their SII has them, SYNC and latch
        // units off, have receive times only and would take none).
        let mut toml = format!("seed = {seed}\n[[device]]\nbuiltin = 'EK1100'\n");
        for k in 1..slaves {
            toml += if k % 2 == 1 { "[[device]]\nbuiltin = 'EL1004'\n" } else { "[[device]]\nbuiltin = 'EL2004'\n" };
            toml += "sync_unit = true\n";
        }
        let cfg: SegmentConfig = toml::from_str(&toml).map_err(|e| ferrocat_segment::SegmentError::Parse {
            path: "(the benchmark's segment)".into(),
            message: e.to_string(),
        })?;
        let mut seg = cfg.build()?;
        let mut t = 1_000_000;
        let mut bit = 0u32;
        for pos in 0..slaves as u16 {
            single(&mut seg, &mut t, Command::APWR, Address::position(pos, 0x0010), &(0x1001 + pos).to_le_bytes())?;
        }
        for k in 1..slaves as u16 {
            let station = 0x1001 + k;
            let outputs = k % 2 == 0;
            let start = if outputs { 0x0F00 } else { 0x1000 };
            let sm = SyncManager {
                start,
                length: 1,
                control: if outputs { 0x44 } else { 0x00 },
                status: 0,
                activate: 1,
                pdi_control: 0,
            };
            single(&mut seg, &mut t, Command::FPWR, Address::Device { adp: station, ado: 0x0800 }, &sm.to_bytes())?;
            let f = Fmmu {
                logical_start: bit / 8,
                length: 1,
                logical_start_bit: (bit % 8) as u8,
                logical_stop_bit: (bit % 8) as u8 + 3,
                physical_start: start,
                physical_start_bit: 0,
                fmmu_type: if outputs { Fmmu::WRITE } else { Fmmu::READ },
                active: true,
            };
            single(&mut seg, &mut t, Command::FPWR, Address::Device { adp: station, ado: 0x0600 }, &f.to_bytes())?;
            bit += 4;
        }
        for state in [2u8, 4, 8] {
            single(&mut seg, &mut t, Command::BWR, Address::Device { adp: 0, ado: 0x0120 }, &[state, 0])?;
        }
        let image = bit.div_ceil(8) as u16;
        let eth = EthernetRepr { dst: BROADCAST, src: [0x10; 6], vlan_tci: None, ethertype: 0 };
        let mut frame = vec![0u8; 1514];
        let mut w = FrameWriter::new(&mut frame, &eth)?;
        w.push_chained(
            &DatagramHeader::new(Command::LRW, 1, Address::Logical(0), image),
            &vec![0x5A; image as usize],
            0,
        )?;
        w.push_chained(
            &DatagramHeader::new(Command::FRMW, 2, Address::Device { adp: 0x1001, ado: 0x0910 }, 8),
            &[0; 8],
            0,
        )?;
        let len = w.finish()?;
        Ok(CyclicBench {
            seg,
            buf: frame.clone(),
            frame,
            len,
            t_ns: t.div_ceil(cycle_ns) * cycle_ns,
            cycle_ns,
            lost: 0,
        })
    }

    /// Runs `cycles` cycles of virtual time.
    pub fn run(&mut self, cycles: u64) {
        for _ in 0..cycles {
            self.buf[..self.len].copy_from_slice(&self.frame[..self.len]);
            if self.seg.exchange(&mut self.buf[..self.len], self.t_ns).is_none() {
                self.lost += 1;
            }
            self.t_ns += self.cycle_ns;
        }
    }
}

/// The time control loop alone: `units` DC units with crystals spread over ±50 ppm, each taking
/// one sample per cycle of `cycle_ns` as the followers of [`CyclicBench`] do, nothing else in
/// the loop. Its cost per sample is a floor under the cost of an ESC visit in that workload.
#[derive(Debug)]
pub struct TclBench {
    units: Vec<DcUnit>,
    t_ns: u64,
    cycle_ns: u64,
}

impl TclBench {
    /// `units` units, run for 5 000 cycles so that every loop has settled (its SCD moving
    /// sample by sample, as in the cyclic workload).
    pub fn new(units: usize, cycle_ns: u64) -> Self {
        let units = (0..units as i64)
            .map(|k| DcUnit::new(DcWidth::Bits64, 0, 1_000_000 + k as u64 * 37, (k * 7_919) % 100_001 - 50_000))
            .collect();
        let mut b = TclBench { units, t_ns: 1_000_000, cycle_ns };
        b.run(5_000);
        b
    }

    /// `cycles` cycles: one sample per unit each, the units 600 ns apart as on a line, each
    /// written the reference time at its own arrival (a follower's FRMW, its delay taken out).
    pub fn run(&mut self, cycles: u64) {
        for _ in 0..cycles {
            for (k, u) in self.units.iter_mut().enumerate() {
                let at_ns = self.t_ns + k as u64 * 600;
                u.tcl_sample(at_ns, (at_ns + 1_000_000) as u32);
            }
            self.t_ns += self.cycle_ns;
        }
    }

    pub fn units(&self) -> usize {
        self.units.len()
    }

    /// The units' speed counter differences (to show the loops are moving).
    pub fn scd_sum(&self) -> i64 {
        self.units.iter().map(|u| u.scd as i64).sum()
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// The loop workload is the settled one the cyclic bench has: every unit's difference is
    /// pulled in and its SCD counters its own crystal (positive SCD slows a fast clock).
    #[test]
    fn tcl_bench_units_settle_against_their_crystals() {
        let b = TclBench::new(8, 100_000);
        for u in &b.units {
            assert!(u.diff_mean_ns().abs() <= 20, "difference {} ns", u.diff_mean_ns());
            assert_eq!(u.scd.signum() as i64, u.drift_ppb.signum(), "drift {} ppb, SCD {}", u.drift_ppb, u.scd);
        }
    }
}
