//! The process image that a running master shares with other processes (docs/service.md, "The
//! shared process image").
//!
//! One file (`RUNDIR/NAME.image`), mapped by the master and by every client:
//!
//! - a header ([`field`]) with the sizes, where each area lies, and two seqlocks;
//! - the image as the last cycle exchanged it (outputs as sent, then inputs as received), which
//!   the master writes after every cycle under the *published* seqlock, with the cycle's number,
//!   its time and working counter; a reader copies it and retries if the sequence moved;
//! - the clients' outputs and a mask of the bits they own, which a client writes under the
//!   *outputs* seqlock while holding the file's `flock`, and which the master applies before
//!   every cycle: each bit of the mask takes the client's value, the rest stay the master's.
//!   The master reads them once a cycle, never waiting: a copy the sequence says is torn is
//!   left for the next cycle, so outputs are never half-applied;
//! - the symbol table, JSON: every variable's name, slave, group, direction, bit offset and
//!   width ([`Variable`]).
//!
//! A client killed while writing leaves the outputs' sequence odd: the master, finding the
//! `flock` free, puts back the last whole outputs and ends the sequence.
use std::fs::{File, OpenOptions};
use std::os::unix::fs::{OpenOptionsExt, PermissionsExt};
use std::path::{Path, PathBuf};
use std::sync::atomic::{fence, Ordering};

use serde::{Deserialize, Serialize};

use crate::shm::{self, Shared};

/// The file's first 8 bytes.
pub const MAGIC: [u8; 8] = *b"FCIMAGE\0";
/// The layout's version.
pub const LAYOUT_VERSION: u32 = 1;
/// The header's length; every area after it starts on a multiple of 64 bytes.
pub const HEADER_LEN: usize = 256;
/// The largest image a file may describe (each of outputs and inputs), bytes.
pub const MAX_AREA: usize = 1 << 20;
/// The longest symbol table, bytes.
pub const MAX_SYMBOLS: usize = 16 << 20;

/// Byte offsets of the header's fields (little-endian; the u64s on multiples of 8).
pub mod field {
    /// `[u8; 8]`: [`MAGIC`](super::MAGIC).
    pub const MAGIC: usize = 0;
    /// u32: [`LAYOUT_VERSION`](super::LAYOUT_VERSION).
    pub const VERSION: usize = 8;
    /// u32: [`HEADER_LEN`](super::HEADER_LEN).
    pub const HEADER_LEN: usize = 12;
    /// u32: bytes of outputs.
    pub const OUT_BYTES: usize = 16;
    /// u32: bytes of inputs.
    pub const IN_BYTES: usize = 20;
    /// u32: where the image as last exchanged lies (outputs, then inputs).
    pub const PUBLISHED: usize = 24;
    /// u32: where the clients' outputs lie.
    pub const CLIENT_OUT: usize = 28;
    /// u32: where the mask of the bits the clients own lies.
    pub const MASK: usize = 32;
    /// u32: where the symbol table lies.
    pub const SYMBOLS: usize = 36;
    /// u32: its length.
    pub const SYMBOLS_LEN: usize = 40;
    /// u32: the master's process id.
    pub const MASTER_PID: usize = 44;
    /// u64: the master's cycle, ns.
    pub const CYCLE_NS: usize = 48;
    /// u64: the published seqlock (odd while the master writes).
    pub const PUB_SEQ: usize = 64;
    /// u64: the cycle the published image is of (counted from 1).
    pub const PUB_CYCLE: usize = 72;
    /// u64: when its answer came, CLOCK_MONOTONIC ns (the master's clock).
    pub const PUB_TIME_NS: usize = 80;
    /// u32: its working counter.
    pub const PUB_WKC: usize = 88;
    /// u32: the working counter a whole cycle gives.
    pub const PUB_EXPECTED: usize = 92;
    /// u64: 1 while the master runs, 0 once it stopped.
    pub const RUNNING: usize = 96;
    /// u64: the outputs' seqlock (odd while a client writes).
    pub const OUT_SEQ: usize = 128;
    /// u64: writes of outputs committed.
    pub const OUT_COMMITS: usize = 136;
    /// u64: the commit the master last applied.
    pub const OUT_APPLIED: usize = 144;
    /// u64: the cycle that first sent it.
    pub const OUT_APPLIED_CYCLE: usize = 152;
}

/// A variable of the image.
#[derive(Debug, Clone, PartialEq, Eq, Serialize, Deserialize)]
pub struct Variable {
    /// Its name: `POS:ENTRY` (a slave's position and the entry's name), or an ENI's variable.
    pub name: String,
    /// The slave's position.
    pub position: u16,
    /// The slave's name.
    pub slave: String,
    /// The process-data group the slave is in, if any.
    #[serde(default)]
    pub group: Option<String>,
    /// An output (written by clients) or an input.
    pub output: bool,
    /// Its first bit in the whole image (outputs first).
    pub bit: u32,
    /// Its width in bits (1 to 64).
    pub bits: u8,
    /// The PDO entry's object index (0 for an ENI variable).
    #[serde(default)]
    pub index: u16,
    /// Its subindex.
    #[serde(default)]
    pub subindex: u8,
}

/// What went wrong with an image file.
#[derive(Debug, thiserror::Error)]
pub enum ImageError {
    /// The file could not be opened, mapped or locked.
    #[error("{path}: {error}")]
    Io {
        /// The file.
        path: PathBuf,
        /// Why.
        error: std::io::Error,
    },
    /// The file is not an image of this layout.
    #[error("{path}: not a ferrocat process image of layout {LAYOUT_VERSION}: {what}")]
    Layout {
        /// The file.
        path: PathBuf,
        /// What is wrong, where.
        what: String,
    },
    /// No variable of that name.
    #[error("no variable '{0}' in the image")]
    NoVariable(String),
    /// A value written to an input.
    #[error("'{0}' is an input: a client writes outputs only")]
    NotOutput(String),
    /// A value wider than its variable.
    #[error("{value} does not fit the {bits} bits of '{name}'")]
    TooWide {
        /// The variable.
        name: String,
        /// Its width.
        bits: u8,
        /// The value.
        value: u64,
    },
    /// The master was writing every time the image was read (it stopped mid-write).
    #[error("the image changed under every one of {0} reads: the master stopped while writing it")]
    Torn(u32),
    /// The master's outputs stayed mid-write (a client died while writing, and the master
    /// does not run to put them back).
    #[error("the outputs stay mid-write: a client died writing them, and no master puts them back")]
    Stuck,
}

/// The image as one cycle left it.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct Snapshot {
    /// The cycle, counted from 1 (0: no cycle yet).
    pub cycle: u64,
    /// When its answer came, the master's CLOCK_MONOTONIC ns.
    pub time_ns: u64,
    /// Its working counter.
    pub wkc: u32,
    /// The working counter a whole cycle gives.
    pub expected_wkc: u32,
    /// Whether the master still runs.
    pub running: bool,
    /// The image: outputs as sent, then inputs as received.
    pub image: Vec<u8>,
}

impl Snapshot {
    /// The value of `v` (its low `bits` bits).
    pub fn get(&self, v: &Variable) -> u64 {
        get_bits(&self.image, v.bit, v.bits)
    }
}

fn get_bits(bytes: &[u8], bit: u32, bits: u8) -> u64 {
    let mut v = 0u64;
    for b in 0..bits.min(64) as u32 {
        let at = (bit + b) as usize;
        if bytes.get(at / 8).is_some_and(|byte| byte >> (at % 8) & 1 == 1) {
            v |= 1 << b;
        }
    }
    v
}

fn set_bits(bytes: &mut [u8], bit: u32, bits: u8, value: u64) {
    for b in 0..bits.min(64) as u32 {
        let at = (bit + b) as usize;
        let Some(byte) = bytes.get_mut(at / 8) else { return };
        if value >> b & 1 == 1 {
            *byte |= 1 << (at % 8);
        } else {
            *byte &= !(1 << (at % 8));
        }
    }
}

/// Where each area lies, from the sizes.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
struct Areas {
    out_bytes: usize,
    in_bytes: usize,
    published: usize,
    client_out: usize,
    mask: usize,
    symbols: usize,
}

impl Areas {
    fn new(out_bytes: usize, in_bytes: usize) -> Areas {
        let up = |n: usize| n.div_ceil(64) * 64;
        let published = HEADER_LEN;
        let client_out = published + up(out_bytes + in_bytes);
        let mask = client_out + up(out_bytes);
        let symbols = mask + up(out_bytes);
        Areas { out_bytes, in_bytes, published, client_out, mask, symbols }
    }
}

/// The image this process's master serves for `target`.
pub fn image_path(target: &str) -> PathBuf {
    crate::socket_path(target).with_extension("image")
}

/// The image of a master running on `target` (beside its control socket,
/// [`find_socket`](crate::find_socket)).
pub fn find_image(target: &str) -> PathBuf {
    crate::find_socket(target).with_extension("image")
}

/// A client of a running master's image.
#[derive(Debug)]
pub struct ImageClient {
    file: File,
    map: Shared,
    areas: Areas,
    path: PathBuf,
    variables: Vec<Variable>,
}

impl ImageClient {
    /// Maps the image at `path` and reads its symbol table (checking every offset and size
    /// against the file).
    pub fn attach(path: impl AsRef<Path>) -> Result<ImageClient, ImageError> {
        let path = path.as_ref().to_path_buf();
        let io = |error| ImageError::Io { path: path.clone(), error };
        let file = OpenOptions::new().read(true).write(true).open(&path).map_err(io)?;
        let len = file.metadata().map_err(io)?.len() as usize;
        let bad = |what: String| ImageError::Layout { path: path.clone(), what };
        if len < HEADER_LEN {
            return Err(bad(format!("{len} bytes, shorter than the {HEADER_LEN}-byte header")));
        }
        let map = Shared::map(&file, len).map_err(io)?;
        let mut magic = [0u8; 8];
        map.load(field::MAGIC, &mut magic);
        if magic != MAGIC {
            return Err(bad(format!("bytes 0–7 are {magic:02x?}, not {MAGIC:02x?}")));
        }
        let u32_at = |at| map.u32_at(at).load(Ordering::Acquire) as usize;
        let version = u32_at(field::VERSION) as u32;
        if version != LAYOUT_VERSION {
            return Err(bad(format!("layout version {version} (byte 8)")));
        }
        let (out_bytes, in_bytes) = (u32_at(field::OUT_BYTES), u32_at(field::IN_BYTES));
        if out_bytes > MAX_AREA || in_bytes > MAX_AREA {
            return Err(bad(format!("{out_bytes} bytes of outputs and {in_bytes} of inputs: at most {MAX_AREA} each")));
        }
        let areas = Areas::new(out_bytes, in_bytes);
        let found = (
            u32_at(field::HEADER_LEN),
            u32_at(field::PUBLISHED),
            u32_at(field::CLIENT_OUT),
            u32_at(field::MASK),
            u32_at(field::SYMBOLS),
        );
        if found != (HEADER_LEN, areas.published, areas.client_out, areas.mask, areas.symbols) {
            return Err(bad(format!("areas at {found:?}, where the sizes put them at {areas:?}")));
        }
        let symbols_len = u32_at(field::SYMBOLS_LEN);
        if symbols_len > MAX_SYMBOLS || areas.symbols + symbols_len > len {
            return Err(bad(format!("a symbol table of {symbols_len} bytes at {} in a file of {len}", areas.symbols)));
        }
        let mut text = vec![0u8; symbols_len];
        map.load(areas.symbols, &mut text);
        let variables: Vec<Variable> = serde_json::from_slice(&text).map_err(|e| bad(format!("symbol table: {e}")))?;
        let total_bits = (out_bytes + in_bytes) as u64 * 8;
        if let Some(v) =
            variables.iter().find(|v| v.bits == 0 || v.bits > 64 || v.bit as u64 + v.bits as u64 > total_bits)
        {
            return Err(bad(format!("variable '{}' at bit {} of {} bits lies past the image", v.name, v.bit, v.bits)));
        }
        if let Some(v) = variables.iter().find(|v| v.output && (v.bit as u64 + v.bits as u64) > out_bytes as u64 * 8) {
            return Err(bad(format!("output '{}' lies past the outputs", v.name)));
        }
        Ok(ImageClient { file, map, areas, path, variables })
    }

    /// Every variable.
    pub fn variables(&self) -> &[Variable] {
        &self.variables
    }

    /// The variable named `name`.
    pub fn variable(&self, name: &str) -> Result<&Variable, ImageError> {
        self.variables.iter().find(|v| v.name == name).ok_or_else(|| ImageError::NoVariable(name.to_string()))
    }

    /// The master's process id.
    pub fn master_pid(&self) -> u32 {
        self.map.u32_at(field::MASTER_PID).load(Ordering::Relaxed)
    }

    /// The image as the last cycle left it (a seqlock read: retried while the master writes,
    /// up to 10 000 times).
    pub fn read(&self) -> Result<Snapshot, ImageError> {
        const TRIES: u32 = 10_000;
        let seq = self.map.u64_at(field::PUB_SEQ);
        let mut image = vec![0u8; self.areas.out_bytes + self.areas.in_bytes];
        for _ in 0..TRIES {
            let s1 = seq.load(Ordering::Acquire);
            if s1 % 2 == 1 {
                std::hint::spin_loop();
                continue;
            }
            self.map.load(self.areas.published, &mut image);
            let u64_at = |at| self.map.u64_at(at).load(Ordering::Relaxed);
            let u32_at = |at| self.map.u32_at(at).load(Ordering::Relaxed);
            let snapshot = Snapshot {
                cycle: u64_at(field::PUB_CYCLE),
                time_ns: u64_at(field::PUB_TIME_NS),
                wkc: u32_at(field::PUB_WKC),
                expected_wkc: u32_at(field::PUB_EXPECTED),
                running: u64_at(field::RUNNING) == 1,
                image: Vec::new(),
            };
            fence(Ordering::Acquire);
            if seq.load(Ordering::Relaxed) == s1 {
                return Ok(Snapshot { image, ..snapshot });
            }
        }
        Err(ImageError::Torn(TRIES))
    }

    /// Writes `values` to their outputs as one change: the master applies all of them at the
    /// start of one cycle, or none. Takes the file's lock for as long (waiting for another
    /// client's write). Returns the write's number, which [`applied`](Self::applied) compares
    /// with.
    pub fn write(&mut self, values: &[(&str, u64)]) -> Result<u64, ImageError> {
        let mut chosen = Vec::with_capacity(values.len());
        for &(name, value) in values {
            let v = self.variable(name)?;
            if !v.output {
                return Err(ImageError::NotOutput(name.to_string()));
            }
            if v.bits < 64 && value >> v.bits != 0 {
                return Err(ImageError::TooWide { name: name.to_string(), bits: v.bits, value });
            }
            chosen.push((v.bit, v.bits, value));
        }
        let io = |error| ImageError::Io { path: self.path.clone(), error };
        let seq = self.map.u64_at(field::OUT_SEQ);
        // A sequence left odd by a client that died: the master puts the outputs back within
        // a cycle or so.
        let mut waited = 0;
        loop {
            shm::lock(&self.file, true).map_err(io)?;
            if seq.load(Ordering::Acquire) % 2 == 0 {
                break;
            }
            shm::unlock(&self.file);
            waited += 1;
            if waited > 1000 {
                return Err(ImageError::Stuck);
            }
            std::thread::sleep(std::time::Duration::from_millis(1));
        }
        let (n, a) = (self.areas.out_bytes, self.areas);
        let mut out = vec![0u8; n];
        let mut mask = vec![0u8; n];
        self.map.load(a.client_out, &mut out);
        self.map.load(a.mask, &mut mask);
        for &(bit, bits, value) in &chosen {
            set_bits(&mut out, bit, bits, value);
            set_bits(&mut mask, bit, bits, u64::MAX);
        }
        let s = seq.load(Ordering::Relaxed);
        seq.store(s + 1, Ordering::Relaxed);
        fence(Ordering::Release);
        self.map.store(a.client_out, &out);
        self.map.store(a.mask, &mask);
        let commits = self.map.u64_at(field::OUT_COMMITS);
        let commit = commits.load(Ordering::Relaxed) + 1;
        commits.store(commit, Ordering::Relaxed);
        seq.store(s + 2, Ordering::Release);
        shm::unlock(&self.file);
        Ok(commit)
    }

    /// The last write the master applied, and the cycle that first sent it.
    pub fn applied(&self) -> (u64, u64) {
        (
            self.map.u64_at(field::OUT_APPLIED).load(Ordering::Acquire),
            self.map.u64_at(field::OUT_APPLIED_CYCLE).load(Ordering::Acquire),
        )
    }

    /// Writes the sequence's first half and stops, as a client killed mid-write would leave it
    /// (for tests of the master's recovery), the lock released as the kernel releases a dead
    /// process's.
    #[doc(hidden)]
    pub fn begin_write_and_abandon(&mut self, name: &str, value: u64) -> Result<(), ImageError> {
        self.begin_write_and_abandon_locked(name, value)?;
        shm::unlock(&self.file);
        Ok(())
    }

    /// As [`begin_write_and_abandon`](Self::begin_write_and_abandon), the lock kept: a process
    /// that then stops, or is killed, is a client dead mid-write.
    #[doc(hidden)]
    pub fn begin_write_and_abandon_locked(&mut self, name: &str, value: u64) -> Result<(), ImageError> {
        let v = self.variable(name)?.clone();
        shm::lock(&self.file, true).map_err(|error| ImageError::Io { path: self.path.clone(), error })?;
        let seq = self.map.u64_at(field::OUT_SEQ);
        let s = seq.load(Ordering::Relaxed);
        seq.store(s + 1, Ordering::Relaxed);
        fence(Ordering::Release);
        let mut out = vec![0u8; self.areas.out_bytes];
        self.map.load(self.areas.client_out, &mut out);
        set_bits(&mut out, v.bit, v.bits, value);
        self.map.store(self.areas.client_out, &out);
        let mut mask = vec![0u8; self.areas.out_bytes];
        self.map.load(self.areas.mask, &mut mask);
        set_bits(&mut mask, v.bit, v.bits, u64::MAX);
        self.map.store(self.areas.mask, &mask);
        Ok(())
    }
}

/// What [`SharedImage::apply_outputs`] did this cycle.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Applied {
    /// No client has written.
    Nothing,
    /// The outputs of the last whole write, applied (again).
    Applied,
    /// A client was writing: the last whole write applied, the new one at the next cycle.
    Busy,
    /// A client died mid-write: its write dropped, the last whole one put back.
    Recovered,
}

/// What the clients' outputs did so far.
#[derive(Debug, Clone, Copy, Default, PartialEq, Eq)]
pub struct ImageStats {
    /// Cycles published.
    pub published: u64,
    /// Writes of clients taken.
    pub writes_taken: u64,
    /// Cycles that found a client writing.
    pub busy: u64,
    /// Writes left half-done by a client that died, dropped.
    pub recovered: u64,
}

/// The master's side of its shared image (the file is removed when dropped).
#[derive(Debug)]
pub struct SharedImage {
    file: File,
    map: Shared,
    areas: Areas,
    path: PathBuf,
    /// The last whole write of the clients: their outputs and mask.
    outputs: Vec<u8>,
    mask: Vec<u8>,
    /// Where a write is copied before the sequence says whether it is whole.
    scratch_outputs: Vec<u8>,
    scratch_mask: Vec<u8>,
    seen_seq: u64,
    any_write: bool,
    /// A write taken but not yet sent: its number.
    taken_commit: Option<u64>,
    stats: ImageStats,
}

impl SharedImage {
    /// Makes the image at `path` (mode `mode`) for `out_bytes` of outputs and `in_bytes` of
    /// inputs, with `variables` as its symbol table. It is written under a name of its own and
    /// renamed into place, so that a client never maps a half-made file.
    pub fn create(
        path: &Path,
        out_bytes: usize,
        in_bytes: usize,
        variables: &[Variable],
        cycle_ns: u64,
        mode: u32,
    ) -> std::io::Result<SharedImage> {
        if out_bytes > MAX_AREA || in_bytes > MAX_AREA {
            return Err(std::io::Error::other(format!(
                "an image of {out_bytes} + {in_bytes} bytes: at most {MAX_AREA} each"
            )));
        }
        if let Some(dir) = path.parent() {
            std::fs::create_dir_all(dir)?;
        }
        let symbols = serde_json::to_vec(variables).map_err(std::io::Error::other)?;
        let areas = Areas::new(out_bytes, in_bytes);
        let len = areas.symbols + symbols.len();
        let making = path.with_extension(format!("image.{}", std::process::id()));
        let file = OpenOptions::new().read(true).write(true).create(true).truncate(true).mode(mode).open(&making)?;
        file.set_permissions(std::fs::Permissions::from_mode(mode))?;
        file.set_len(len as u64)?;
        let map = Shared::map(&file, len)?;
        map.store(field::MAGIC, &MAGIC);
        let put32 = |at, v: usize| map.u32_at(at).store(v as u32, Ordering::Relaxed);
        put32(field::VERSION, LAYOUT_VERSION as usize);
        put32(field::HEADER_LEN, HEADER_LEN);
        put32(field::OUT_BYTES, out_bytes);
        put32(field::IN_BYTES, in_bytes);
        put32(field::PUBLISHED, areas.published);
        put32(field::CLIENT_OUT, areas.client_out);
        put32(field::MASK, areas.mask);
        put32(field::SYMBOLS, areas.symbols);
        put32(field::SYMBOLS_LEN, symbols.len());
        put32(field::MASTER_PID, std::process::id() as usize);
        map.u64_at(field::CYCLE_NS).store(cycle_ns, Ordering::Relaxed);
        map.u64_at(field::RUNNING).store(1, Ordering::Relaxed);
        map.store(areas.symbols, &symbols);
        fence(Ordering::Release);
        std::fs::rename(&making, path)?;
        Ok(SharedImage {
            file,
            map,
            areas,
            path: path.to_path_buf(),
            outputs: vec![0; out_bytes],
            mask: vec![0; out_bytes],
            scratch_outputs: vec![0; out_bytes],
            scratch_mask: vec![0; out_bytes],
            seen_seq: 0,
            any_write: false,
            taken_commit: None,
            stats: ImageStats::default(),
        })
    }

    /// The file.
    pub fn path(&self) -> &Path {
        &self.path
    }

    /// What the clients' outputs did so far.
    pub fn stats(&self) -> ImageStats {
        self.stats
    }

    /// The clients' writes so far (a heartbeat: a watchdog compares it between cycles).
    pub fn commits(&self) -> u64 {
        self.map.u64_at(field::OUT_COMMITS).load(Ordering::Acquire)
    }

    /// Before a cycle: the clients' outputs into `outputs` (the master's outputs, changed only
    /// where the clients' mask says), never waiting. A write read torn is left for the next
    /// cycle; one left odd by a client that died (the file's lock free) is dropped and the
    /// last whole one put back.
    pub fn apply_outputs(&mut self, outputs: &mut [u8]) -> Applied {
        let seq = self.map.u64_at(field::OUT_SEQ);
        let s1 = seq.load(Ordering::Acquire);
        let mut result = if self.any_write { Applied::Applied } else { Applied::Nothing };
        if s1 % 2 == 1 {
            // A writer holds the lock: it is writing. Nobody does, and the sequence is still
            // where it was (a writer that finished between the two looks moved it on): it
            // died writing.
            let dead = match shm::lock(&self.file, false) {
                Ok(true) if seq.load(Ordering::Acquire) == s1 => true,
                Ok(true) => {
                    shm::unlock(&self.file);
                    false
                }
                _ => false,
            };
            if dead {
                self.map.store(self.areas.client_out, &self.outputs);
                self.map.store(self.areas.mask, &self.mask);
                seq.store(s1 + 1, Ordering::Release);
                self.seen_seq = s1 + 1;
                shm::unlock(&self.file);
                self.stats.recovered += 1;
                result = Applied::Recovered;
            } else {
                self.stats.busy += 1;
                result = Applied::Busy;
            }
        } else if s1 != self.seen_seq {
            // Into the scratch copies, which take the place of the last whole write only when
            // the sequence says this one is whole: no allocation in the cycle.
            self.map.load(self.areas.client_out, &mut self.scratch_outputs);
            self.map.load(self.areas.mask, &mut self.scratch_mask);
            let commit = self.map.u64_at(field::OUT_COMMITS).load(Ordering::Relaxed);
            fence(Ordering::Acquire);
            if seq.load(Ordering::Relaxed) == s1 {
                std::mem::swap(&mut self.outputs, &mut self.scratch_outputs);
                std::mem::swap(&mut self.mask, &mut self.scratch_mask);
                self.seen_seq = s1;
                self.any_write = true;
                self.taken_commit = Some(commit);
                self.stats.writes_taken += 1;
                result = Applied::Applied;
            } else {
                self.stats.busy += 1;
                result = Applied::Busy;
            }
        }
        if self.any_write {
            for ((o, c), m) in outputs.iter_mut().zip(&self.outputs).zip(&self.mask) {
                *o = (*o & !m) | (c & m);
            }
        }
        result
    }

    /// After a cycle: the image as it exchanged it, under the published seqlock, with its
    /// cycle (from 1), time (the master's clock) and working counter; and the write of the
    /// clients it sent first, if any.
    pub fn publish(&mut self, image: &[u8], cycle: u64, time_ns: u64, wkc: u32, expected_wkc: u32) {
        let seq = self.map.u64_at(field::PUB_SEQ);
        let s = seq.load(Ordering::Relaxed);
        seq.store(s + 1, Ordering::Relaxed);
        fence(Ordering::Release);
        let n = image.len().min(self.areas.out_bytes + self.areas.in_bytes);
        self.map.store(self.areas.published, &image[..n]);
        self.map.u64_at(field::PUB_CYCLE).store(cycle, Ordering::Relaxed);
        self.map.u64_at(field::PUB_TIME_NS).store(time_ns, Ordering::Relaxed);
        self.map.u32_at(field::PUB_WKC).store(wkc, Ordering::Relaxed);
        self.map.u32_at(field::PUB_EXPECTED).store(expected_wkc, Ordering::Relaxed);
        seq.store(s + 2, Ordering::Release);
        if let Some(commit) = self.taken_commit.take() {
            self.map.u64_at(field::OUT_APPLIED_CYCLE).store(cycle, Ordering::Relaxed);
            self.map.u64_at(field::OUT_APPLIED).store(commit, Ordering::Release);
        }
        self.stats.published += 1;
    }
}

impl Drop for SharedImage {
    fn drop(&mut self) {
        self.map.u64_at(field::RUNNING).store(0, Ordering::Release);
        let _ = std::fs::remove_file(&self.path);
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn vars() -> Vec<Variable> {
        let v = |name: &str, output, bit, bits| Variable {
            name: name.into(),
            position: 1,
            slave: "EL2004".into(),
            group: None,
            output,
            bit,
            bits,
            index: 0x7000,
            subindex: 1,
        };
        vec![
            v("1:Output 1", true, 0, 1),
            v("1:Output 2", true, 1, 1),
            v("1:Word", true, 8, 16),
            v("2:Input", false, 24, 8),
        ]
    }

    fn temp(name: &str) -> PathBuf {
        std::env::temp_dir().join(format!("ferrocat-image-{name}-{}.image", std::process::id()))
    }

    #[test]
    fn a_client_writes_whole_outputs_and_reads_what_the_master_published() {
        let path = temp("rw");
        let mut master = SharedImage::create(&path, 3, 1, &vars(), 1_000_000, 0o600).unwrap();
        let mut client = ImageClient::attach(&path).unwrap();
        assert_eq!(client.variables().len(), 4);
        let mut outputs = [0xF0u8, 0, 0];
        assert_eq!(master.apply_outputs(&mut outputs), Applied::Nothing);
        assert_eq!(outputs, [0xF0, 0, 0]);
        let commit = client.write(&[("1:Output 2", 1), ("1:Word", 0xBEEF)]).unwrap();
        assert_eq!(master.apply_outputs(&mut outputs), Applied::Applied);
        // Only the bits the client owns change.
        assert_eq!(outputs, [0xF2, 0xEF, 0xBE]);
        master.publish(&[outputs[0], outputs[1], outputs[2], 0x5A], 7, 123, 3, 3);
        assert_eq!(client.applied(), (commit, 7));
        let s = client.read().unwrap();
        assert_eq!((s.cycle, s.time_ns, s.wkc, s.running), (7, 123, 3, true));
        assert_eq!(s.get(client.variable("2:Input").unwrap()), 0x5A);
        assert_eq!(s.get(client.variable("1:Word").unwrap()), 0xBEEF);
        // Applied again each cycle over what the master's own logic wrote.
        outputs = [0, 0, 0];
        assert_eq!(master.apply_outputs(&mut outputs), Applied::Applied);
        assert_eq!(outputs, [0x02, 0xEF, 0xBE]);
        assert!(matches!(client.write(&[("2:Input", 1)]), Err(ImageError::NotOutput(_))));
        assert!(matches!(client.write(&[("1:Output 1", 2)]), Err(ImageError::TooWide { .. })));
        assert!(matches!(client.write(&[("nope", 1)]), Err(ImageError::NoVariable(_))));
        drop(master);
        assert!(!client.read().unwrap().running);
        assert!(!path.exists());
    }

    #[test]
    fn a_write_abandoned_midway_is_dropped_never_half_applied() {
        let path = temp("abandon");
        let mut master = SharedImage::create(&path, 3, 1, &vars(), 1_000_000, 0o600).unwrap();
        let mut client = ImageClient::attach(&path).unwrap();
        client.write(&[("1:Word", 0x1111)]).unwrap();
        let mut outputs = [0u8; 3];
        master.apply_outputs(&mut outputs);
        // A client that dies between the two halves of its sequence (its lock released by
        // the kernel, here by hand).
        let mut dying = ImageClient::attach(&path).unwrap();
        dying.begin_write_and_abandon("1:Word", 0x2222).unwrap();
        assert_eq!(master.apply_outputs(&mut outputs), Applied::Recovered);
        assert_eq!(outputs, [0, 0x11, 0x11]);
        assert_eq!(master.stats().recovered, 1);
        // The next client writes as ever.
        client.write(&[("1:Word", 0x3333)]).unwrap();
        assert_eq!(master.apply_outputs(&mut outputs), Applied::Applied);
        assert_eq!(outputs, [0, 0x33, 0x33]);
    }

    #[test]
    fn a_file_that_is_no_image_is_refused_in_words() {
        let path = temp("bad");
        for (bytes, says) in [
            (vec![0u8; 10], "shorter than"),
            (vec![0u8; 300], "bytes 0–7"),
            (
                {
                    let mut b = vec![0u8; 300];
                    b[..8].copy_from_slice(&MAGIC);
                    b[8] = 9;
                    b
                },
                "layout version 9",
            ),
            (
                {
                    let mut b = vec![0u8; 300];
                    b[..8].copy_from_slice(&MAGIC);
                    b[8] = 1;
                    b[16..20].copy_from_slice(&u32::MAX.to_le_bytes());
                    b
                },
                "at most",
            ),
            (
                {
                    let mut b = vec![0u8; 300];
                    b[..8].copy_from_slice(&MAGIC);
                    b[8] = 1;
                    b[12] = 0;
                    b
                },
                "areas at",
            ),
        ] {
            std::fs::write(&path, &bytes).unwrap();
            let e = ImageClient::attach(&path).unwrap_err().to_string();
            assert!(e.contains(says), "{e}");
        }
        std::fs::remove_file(&path).ok();
    }
}
