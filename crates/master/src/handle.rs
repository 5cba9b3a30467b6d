//! A place in the process image (the master keeps some, the process-data functions make them).

/// Where an entry sits in the image: bit offset and width.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct Handle {
    /// Bit offset in the whole image.
    pub bit: u32,
    /// Width in bits.
    pub bits: u8,
}
