//! Bounds-checked little-endian field access. Callers validate lengths once; these helpers turn
//! any remaining slip into an `Error` instead of a panic.
use crate::{Error, Result};

#[inline]
pub(crate) fn need(buf: &[u8], offset: usize, len: usize, what: &'static str) -> Result<()> {
    match offset.checked_add(len) {
        Some(end) if end <= buf.len() => Ok(()),
        _ => Err(Error::Truncated { what, offset, needed: len, available: buf.len().saturating_sub(offset) }),
    }
}

#[inline]
pub(crate) fn u8_at(buf: &[u8], offset: usize, what: &'static str) -> Result<u8> {
    need(buf, offset, 1, what)?;
    Ok(buf[offset])
}

#[inline]
pub(crate) fn u16_at(buf: &[u8], offset: usize, what: &'static str) -> Result<u16> {
    need(buf, offset, 2, what)?;
    Ok(u16::from_le_bytes([buf[offset], buf[offset + 1]]))
}

#[inline]
pub(crate) fn u32_at(buf: &[u8], offset: usize, what: &'static str) -> Result<u32> {
    need(buf, offset, 4, what)?;
    Ok(u32::from_le_bytes([buf[offset], buf[offset + 1], buf[offset + 2], buf[offset + 3]]))
}

#[inline]
pub(crate) fn slice_at<'a>(buf: &'a [u8], offset: usize, len: usize, what: &'static str) -> Result<&'a [u8]> {
    need(buf, offset, len, what)?;
    Ok(&buf[offset..offset + len])
}

/// Writes `src` at `offset` of `out`, or says how much room was missing.
#[inline]
pub(crate) fn put(out: &mut [u8], offset: usize, src: &[u8], what: &'static str) -> Result<()> {
    match offset.checked_add(src.len()) {
        Some(end) if end <= out.len() => {
            out[offset..end].copy_from_slice(src);
            Ok(())
        }
        _ => Err(Error::BufferTooSmall { what, needed: offset.saturating_add(src.len()), available: out.len() }),
    }
}
