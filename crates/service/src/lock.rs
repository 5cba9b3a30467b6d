//! Where a running master is found, and the lock that keeps a second master off its segment.
//!
//! Each target (an interface's name, `udp-ADDR:PORT`) has a socket `NAME.sock` and a lock
//! `NAME.lock` in [`runtime_dir`]. Whoever takes the segment over (`ferrocat run`, or a
//! command that scans) holds the lock (`flock`, released by the kernel when the process ends,
//! however it ends) and writes its process id into it.
use std::fs::{File, OpenOptions};
use std::io::{Read, Seek, Write};
use std::os::fd::AsRawFd;
use std::path::{Path, PathBuf};

/// The system's directory: root's, and a service's (the systemd unit makes it).
pub const SYSTEM_DIR: &str = "/run/ferrocat";

/// The directory where this process makes its sockets, images and locks: `$FERROCAT_RUN_DIR`;
/// else `/run/ferrocat` for root, or for anyone who may write there; else
/// `$XDG_RUNTIME_DIR/ferrocat`; else `/tmp/ferrocat-UID`.
pub fn runtime_dir() -> PathBuf {
    if let Some(d) = std::env::var_os("FERROCAT_RUN_DIR").filter(|d| !d.is_empty()) {
        return PathBuf::from(d);
    }
    // SAFETY: geteuid has no preconditions and cannot fail.
    let uid = unsafe { libc::geteuid() };
    if uid == 0 || writable(Path::new(SYSTEM_DIR)) {
        return PathBuf::from(SYSTEM_DIR);
    }
    match std::env::var_os("XDG_RUNTIME_DIR").filter(|d| !d.is_empty()) {
        Some(d) => PathBuf::from(d).join("ferrocat"),
        None => PathBuf::from(format!("/tmp/ferrocat-{uid}")),
    }
}

fn writable(dir: &Path) -> bool {
    use std::os::unix::ffi::OsStrExt;
    let Ok(c) = std::ffi::CString::new(dir.as_os_str().as_bytes()) else { return false };
    // SAFETY: a NUL-terminated path.
    unsafe { libc::access(c.as_ptr(), libc::W_OK) == 0 }
}

/// The control socket this process serves for `target` (an interface's name, or
/// `udp-ADDR:PORT`).
pub fn socket_path(target: &str) -> PathBuf {
    runtime_dir().join(format!("{}.sock", file_name(target)))
}

/// The control socket of a master running on `target`: this process's own directory's, else
/// the system's where a service serves one that this process may not write beside.
pub fn find_socket(target: &str) -> PathBuf {
    let own = socket_path(target);
    let system = Path::new(SYSTEM_DIR).join(format!("{}.sock", file_name(target)));
    if !own.exists() && system.exists() {
        return system;
    }
    own
}

/// The lock of `target`'s segment.
pub fn lock_path(target: &str) -> PathBuf {
    runtime_dir().join(format!("{}.lock", file_name(target)))
}

/// `target` as a file name: `/` and NUL would leave the directory or end the name.
fn file_name(target: &str) -> String {
    target.chars().map(|c| if c == '/' || c == '\0' { '_' } else { c }).collect()
}

/// The segment is taken: by this process.
#[derive(Debug, Clone, PartialEq, Eq, thiserror::Error)]
#[error("{} holds {path}", .pid.map_or(String::from("another process"), |p| format!("process {p}")))]
pub struct Held {
    /// Whose it is, where the lock says.
    pub pid: Option<u32>,
    /// The lock file.
    pub path: String,
}

/// A held lock of a target's segment (released when dropped, or when the process ends).
#[derive(Debug)]
pub struct MasterLock {
    _file: File,
    path: PathBuf,
}

impl MasterLock {
    /// Takes `target`'s lock, making the directory (mode 0755) where it is missing.
    /// `Ok(Err(held))` when another process holds it.
    pub fn take(target: &str) -> std::io::Result<Result<MasterLock, Held>> {
        let path = lock_path(target);
        if let Some(dir) = path.parent() {
            std::fs::create_dir_all(dir)?;
        }
        let mut file = OpenOptions::new().read(true).write(true).create(true).truncate(false).open(&path)?;
        // SAFETY: the descriptor is the open file's for the whole call.
        if unsafe { libc::flock(file.as_raw_fd(), libc::LOCK_EX | libc::LOCK_NB) } != 0 {
            let e = std::io::Error::last_os_error();
            if e.raw_os_error() != Some(libc::EWOULDBLOCK) {
                return Err(e);
            }
            let mut text = String::new();
            let pid = file.read_to_string(&mut text).ok().and_then(|_| text.trim().parse().ok());
            return Ok(Err(Held { pid, path: path.display().to_string() }));
        }
        // A service's lock in the system's directory, where this process makes none of its
        // own: held there, the segment is taken too.
        let system = Path::new(SYSTEM_DIR).join(format!("{}.lock", file_name(target)));
        if system != path {
            if let Ok(mut other) = File::open(&system) {
                // SAFETY: the descriptor is the open file's for the whole call.
                if unsafe { libc::flock(other.as_raw_fd(), libc::LOCK_EX | libc::LOCK_NB) } != 0 {
                    let mut text = String::new();
                    let pid = other.read_to_string(&mut text).ok().and_then(|_| text.trim().parse().ok());
                    return Ok(Err(Held { pid, path: system.display().to_string() }));
                }
            }
        }
        file.set_len(0)?;
        file.rewind()?;
        writeln!(file, "{}", std::process::id())?;
        Ok(Ok(MasterLock { _file: file, path }))
    }

    /// Whether another process holds `target`'s lock, and which, without taking it.
    pub fn holder(target: &str) -> Option<Held> {
        match MasterLock::take(target) {
            Ok(Err(held)) => Some(held),
            _ => None,
        }
    }

    /// The lock file.
    pub fn path(&self) -> &std::path::Path {
        &self.path
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_target_is_one_file_name_in_the_directory() {
        assert_eq!(file_name("udp-127.0.0.1:34980"), "udp-127.0.0.1:34980");
        assert_eq!(file_name("../../etc/x"), ".._.._etc_x");
        assert_eq!(socket_path("eth0").file_name().unwrap(), "eth0.sock");
    }
}
