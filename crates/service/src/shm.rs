//! A shared mapping of a file, read and written through atomics only: the other side is another
//! process, so every access that may meet its writes is an atomic one (relaxed, ordered by the
//! seqlocks' fences), never a plain read of memory someone else writes.
use std::fs::File;
use std::os::fd::AsRawFd;
use std::sync::atomic::{AtomicU32, AtomicU64, AtomicU8, Ordering};

/// A `MAP_SHARED` mapping of a whole file (unmapped when dropped).
#[derive(Debug)]
pub(crate) struct Shared {
    ptr: *mut u8,
    len: usize,
}

// SAFETY: the mapping is plain memory, reached only through atomics.
unsafe impl Send for Shared {}

impl Shared {
    /// Maps `len` bytes of `file`, read and write.
    pub fn map(file: &File, len: usize) -> std::io::Result<Shared> {
        if len == 0 {
            return Err(std::io::Error::other("an empty file"));
        }
        // SAFETY: a new mapping of an open file; the kernel checks the descriptor and length.
        let ptr = unsafe {
            libc::mmap(
                std::ptr::null_mut(),
                len,
                libc::PROT_READ | libc::PROT_WRITE,
                libc::MAP_SHARED,
                file.as_raw_fd(),
                0,
            )
        };
        if ptr == libc::MAP_FAILED {
            return Err(std::io::Error::last_os_error());
        }
        Ok(Shared { ptr: ptr.cast(), len })
    }

    /// The u32 at byte `at` (a multiple of 4 within the mapping; panics otherwise, a bug of
    /// the layout's, not of the file's: offsets from a file are checked before use).
    pub fn u32_at(&self, at: usize) -> &AtomicU32 {
        assert!(at % 4 == 0 && at + 4 <= self.len, "u32 at {at} of {}", self.len);
        // SAFETY: aligned (the mapping is page-aligned), in bounds, and only ever atomic.
        unsafe { &*(self.ptr.add(at) as *const AtomicU32) }
    }

    /// The u64 at byte `at` (a multiple of 8 within the mapping).
    pub fn u64_at(&self, at: usize) -> &AtomicU64 {
        assert!(at % 8 == 0 && at + 8 <= self.len, "u64 at {at} of {}", self.len);
        // SAFETY: as u32_at.
        unsafe { &*(self.ptr.add(at) as *const AtomicU64) }
    }

    fn bytes(&self, at: usize, len: usize) -> &[AtomicU8] {
        assert!(at.checked_add(len).is_some_and(|end| end <= self.len), "{len} bytes at {at} of {}", self.len);
        // SAFETY: in bounds; AtomicU8 has the layout of u8.
        unsafe { std::slice::from_raw_parts(self.ptr.add(at) as *const AtomicU8, len) }
    }

    /// Copies `out.len()` bytes from byte `at` (relaxed loads: a seqlock orders them).
    pub fn load(&self, at: usize, out: &mut [u8]) {
        let n = out.len();
        for (o, b) in out.iter_mut().zip(self.bytes(at, n)) {
            *o = b.load(Ordering::Relaxed);
        }
    }

    /// Copies `data` to byte `at` (relaxed stores: a seqlock orders them).
    pub fn store(&self, at: usize, data: &[u8]) {
        for (d, b) in data.iter().zip(self.bytes(at, data.len())) {
            b.store(*d, Ordering::Relaxed);
        }
    }
}

impl Drop for Shared {
    fn drop(&mut self) {
        // SAFETY: the mapping made in `map`, unmapped once.
        unsafe { libc::munmap(self.ptr.cast(), self.len) };
    }
}

/// `flock` on `file`: `Ok(true)` when taken, `Ok(false)` when another holds it and `wait` is
/// off.
pub(crate) fn lock(file: &File, wait: bool) -> std::io::Result<bool> {
    let op = libc::LOCK_EX | if wait { 0 } else { libc::LOCK_NB };
    // SAFETY: the descriptor is the open file's for the whole call.
    if unsafe { libc::flock(file.as_raw_fd(), op) } == 0 {
        return Ok(true);
    }
    let e = std::io::Error::last_os_error();
    if e.raw_os_error() == Some(libc::EWOULDBLOCK) {
        return Ok(false);
    }
    Err(e)
}

/// Releases the lock taken by [`lock`].
pub(crate) fn unlock(file: &File) {
    // SAFETY: as lock.
    unsafe { libc::flock(file.as_raw_fd(), libc::LOCK_UN) };
}
