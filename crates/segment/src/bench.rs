//! The virtual-time workload the benchmarks measure: a line of I/O terminals (an EK1100, then
//! EL1004/EL2004 alternating) brought to OP, then one frame per cycle with an LRW of the
//! whole process image and an FRMW distributing the reference clock, as SOEM sends it.
use ferrocat_wire::ethernet::{EthernetRepr, BROADCAST};
use ferrocat_wire::register::{Fmmu, SyncManager};
use ferrocat_wire::{Address, Command, DatagramHeader, FrameWriter};

use crate::{Segment, SegmentConfig};

/// A segment of `slaves` devices, configured and in OP, with the cyclic frame ready.
#[derive(Debug)]
pub struct CyclicBench {
    pub seg: Segment,
    frame: Vec<u8>,
    len: usize,
    pub t_ns: u64,
    pub cycle_ns: u64,
    pub lost: u64,
}

fn single(seg: &mut Segment, t: &mut u64, cmd: Command, address: Address, data: &[u8]) {
    let eth = EthernetRepr { dst: BROADCAST, src: [0x10; 6], vlan_tci: None, ethertype: 0 };
    let mut buf = [0u8; 1514];
    let mut w = FrameWriter::new(&mut buf, &eth).expect("buffer");
    w.push(&DatagramHeader::new(cmd, 0, address, data.len() as u16), data, 0).expect("datagram fits");
    let n = w.finish().expect("frame");
    let back = seg.exchange(&mut buf[..n], *t).unwrap_or(*t + 100_000);
    *t = back + 1_000;
}

impl CyclicBench {
    pub fn new(slaves: usize, cycle_ns: u64, seed: u64) -> Self {
        let mut toml = format!("seed = {seed}\n[[device]]\nbuiltin = 'EK1100'\n");
        for k in 1..slaves {
            toml += if k % 2 == 1 { "[[device]]\nbuiltin = 'EL1004'\n" } else { "[[device]]\nbuiltin = 'EL2004'\n" };
        }
        let cfg: SegmentConfig = toml::from_str(&toml).expect("bench segment");
        let mut seg = cfg.build().expect("bench segment builds");
        let mut t = 1_000_000;
        let mut bit = 0u32;
        for pos in 0..slaves as u16 {
            single(&mut seg, &mut t, Command::APWR, Address::position(pos, 0x0010), &(0x1001 + pos).to_le_bytes());
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
            single(&mut seg, &mut t, Command::FPWR, Address::Device { adp: station, ado: 0x0800 }, &sm.to_bytes());
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
            single(&mut seg, &mut t, Command::FPWR, Address::Device { adp: station, ado: 0x0600 }, &f.to_bytes());
            bit += 4;
        }
        for state in [2u8, 4, 8] {
            single(&mut seg, &mut t, Command::BWR, Address::Device { adp: 0, ado: 0x0120 }, &[state, 0]);
        }
        let image = bit.div_ceil(8) as u16;
        let eth = EthernetRepr { dst: BROADCAST, src: [0x10; 6], vlan_tci: None, ethertype: 0 };
        let mut frame = vec![0u8; 1514];
        let mut w = FrameWriter::new(&mut frame, &eth).expect("buffer");
        w.push_chained(
            &DatagramHeader::new(Command::LRW, 1, Address::Logical(0), image),
            &vec![0x5A; image as usize],
            0,
        )
        .expect("LRW fits");
        w.push_chained(
            &DatagramHeader::new(Command::FRMW, 2, Address::Device { adp: 0x1001, ado: 0x0910 }, 8),
            &[0; 8],
            0,
        )
        .expect("FRMW fits");
        let len = w.finish().expect("frame");
        CyclicBench { seg, frame, len, t_ns: t.div_ceil(cycle_ns) * cycle_ns, cycle_ns, lost: 0 }
    }

    /// Runs `cycles` cycles of virtual time.
    pub fn run(&mut self, cycles: u64) {
        let mut buf = self.frame.clone();
        for _ in 0..cycles {
            buf[..self.len].copy_from_slice(&self.frame[..self.len]);
            if self.seg.exchange(&mut buf[..self.len], self.t_ns).is_none() {
                self.lost += 1;
            }
            self.t_ns += self.cycle_ns;
        }
    }
}
