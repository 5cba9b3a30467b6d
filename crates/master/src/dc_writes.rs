//! A clock-sync method's writes to the slaves' DC registers (an offset shift to every clock,
//! the followers' delay bias) that ride on the cyclic frames when the cycle has no room for
//! frames of their own: on a segment whose round trip is most of the cycle, one more frame
//! makes the next cycle late.
//!
//! Every write carries an absolute value (the offset read plus the shift, the delay measured
//! plus the bias), so a frame lost with its writes is sent again as it was: whether the lost
//! one took effect does not matter.

/// At most this many datagrams ride on one frame (a frame of 1 486 bytes takes 74 such
/// 8-byte writes; these leave room for the image's last chunk). A segment with more DC slaves
/// writes in frames of its own.
pub const MAX_RIDERS: usize = 16;

/// Writes waiting for a cyclic frame.
#[derive(Debug, Clone, Default)]
pub(crate) struct DcWrites {
    /// Offset shift to every DC slave but the station skipped (ns), and the offsets read for
    /// it: `None` until a frame has read them all.
    pub(crate) shift: Option<Shift>,
    /// The followers' delay bias to write (ns), and the reference, which has none.
    pub(crate) bias: Option<(i64, u16)>,
    /// Writes that rode on frames, and frames whose riders were not all answered.
    pub(crate) rode: u64,
    pub(crate) retried: u64,
}

#[derive(Debug, Clone, Copy, Default)]
pub(crate) struct Shift {
    pub(crate) shift_ns: i64,
    pub(crate) skip: Option<u16>,
    /// (station, offset read, its width in bytes) per DC slave, once read.
    pub(crate) read: Option<[(u16, u64, u8); MAX_RIDERS]>,
    pub(crate) count: usize,
}

impl DcWrites {
    /// Whether anything waits.
    pub(crate) fn pending(&self) -> bool {
        self.shift.is_some() || self.bias.is_some()
    }

    /// One more shift of every offset but `skip`'s: added to one waiting (its offsets, once
    /// read, stay the ones the whole shift is added to).
    pub(crate) fn add_shift(&mut self, shift_ns: i64, skip: Option<u16>) {
        match self.shift.as_mut() {
            Some(s) if s.skip == skip => s.shift_ns = s.shift_ns.wrapping_add(shift_ns),
            _ => self.shift = Some(Shift { shift_ns, skip, read: None, count: 0 }),
        }
    }
}

/// One datagram riding on a cyclic frame.
#[derive(Debug, Clone, Copy, Default)]
pub(crate) struct Rider {
    pub(crate) write: bool,
    pub(crate) station: u16,
    pub(crate) ado: u16,
    pub(crate) data: [u8; 8],
    pub(crate) len: u8,
}

/// The datagrams riding on one frame.
#[derive(Debug, Clone, Copy, Default)]
pub(crate) struct Riders {
    pub(crate) list: [Rider; MAX_RIDERS],
    pub(crate) count: usize,
    /// What they do: read the offsets for the shift, write them shifted, write the bias.
    pub(crate) reads_offsets: bool,
    pub(crate) writes_offsets: bool,
    pub(crate) writes_bias: bool,
}

impl Riders {
    /// Adds one; false when full.
    pub(crate) fn push(&mut self, r: Rider) -> bool {
        if self.count == MAX_RIDERS {
            return false;
        }
        self.list[self.count] = r;
        self.count += 1;
        true
    }

    /// The offsets the riders read for a shift, as answered: (station, value, width in bytes).
    /// Only those: a frame may carry the followers' delay bias beside them.
    pub(crate) fn offsets_read(&self) -> impl Iterator<Item = (u16, u64, u8)> + '_ {
        use ferrocat_wire::register::addr;
        self.list[..self.count].iter().filter(|r| !r.write && r.ado == addr::DC_SYSTEM_TIME_OFFSET).map(|r| {
            let mut b = [0u8; 8];
            b[..r.len as usize].copy_from_slice(&r.data[..r.len as usize]);
            (r.station, u64::from_le_bytes(b), r.len)
        })
    }

    /// Bytes on the wire: a datagram header, the data and a working counter each.
    pub(crate) fn wire_len(&self) -> usize {
        use ferrocat_wire::datagram::{HEADER_LEN, WKC_LEN};
        self.list[..self.count].iter().map(|r| HEADER_LEN + r.len as usize + WKC_LEN).sum()
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use ferrocat_wire::register::addr;

    #[test]
    fn the_offsets_read_are_the_offset_reads_alone() {
        let mut r = Riders::default();
        let read = |station, v: u32| Rider {
            station,
            ado: addr::DC_SYSTEM_TIME_OFFSET,
            data: (v as u64).to_le_bytes(),
            len: 4,
            ..Rider::default()
        };
        assert!(r.push(read(0x1001, 7)) && r.push(read(0x1002, 9)));
        // The followers' delay bias on the same frame.
        let bias = Rider { write: true, station: 0x1002, ado: addr::DC_SYSTEM_TIME_DELAY, len: 4, ..Rider::default() };
        assert!(r.push(bias));
        assert_eq!(r.offsets_read().collect::<Vec<_>>(), [(0x1001, 7, 4), (0x1002, 9, 4)]);
        assert_eq!(r.wire_len(), 3 * (10 + 4 + 2));
        // Full at MAX_RIDERS.
        while r.push(bias) {}
        assert_eq!(r.count, MAX_RIDERS);
    }

    #[test]
    fn shifts_add_up_until_written() {
        let mut w = DcWrites::default();
        assert!(!w.pending());
        w.add_shift(100, Some(0x1001));
        w.add_shift(-30, Some(0x1001));
        assert_eq!(w.shift.map(|s| s.shift_ns), Some(70));
        // Another reference skipped: a fresh shift.
        w.add_shift(5, None);
        assert_eq!(w.shift.map(|s| (s.shift_ns, s.skip)), Some((5, None)));
        assert!(w.pending());
    }
}
