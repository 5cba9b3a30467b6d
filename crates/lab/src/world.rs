//! What the lab may know of the world a master runs in: the simulated segment where there is
//! one. The master's own [`Io`] has no such door; the lab adds it for its measurements.
use ferrocat_master::io::{Io, RawIo, UdpIo};
use ferrocat_segment::{Segment, Tamper, VirtualIo};

/// A world whose true clocks the lab may read: the in-process segment, or none on a real link.
pub trait World: Io {
    /// The simulated segment, where the world is virtual.
    fn segment(&self) -> Option<&Segment> {
        None
    }
    /// The simulated segment, to change (faults, drives' loads).
    fn segment_mut(&mut self) -> Option<&mut Segment> {
        None
    }
}

impl World for VirtualIo {
    fn segment(&self) -> Option<&Segment> {
        Some(&self.seg)
    }
    fn segment_mut(&mut self) -> Option<&mut Segment> {
        Some(&mut self.seg)
    }
}

impl World for RawIo {}
impl World for UdpIo {}

impl<I: World, F: FnMut(&mut [u8], usize, bool) -> Option<usize>> World for Tamper<I, F> {
    fn segment(&self) -> Option<&Segment> {
        self.inner.segment()
    }
    fn segment_mut(&mut self) -> Option<&mut Segment> {
        self.inner.segment_mut()
    }
}
