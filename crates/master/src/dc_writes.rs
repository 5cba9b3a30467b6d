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

    /// Bytes on the wire: a datagram header, the data and a working counter each.
    pub(crate) fn wire_len(&self) -> usize {
        use ferrocat_wire::datagram::{HEADER_LEN, WKC_LEN};
        self.list[..self.count].iter().map(|r| HEADER_LEN + r.len as usize + WKC_LEN).sum()
    }
}
