//! What waiting for an answer costs a master's CPU on this machine, by the way it waits:
//! spinning through the answer, or sleeping until it comes (a blocking receive, or `ppoll`
//! with a timeout, as the packet ring and io_uring paths sleep; a timeout shorter than the
//! scheduler's tick, as a frame's is, has a timer programmed for it). Two threads on two CPUs
//! exchange datagrams over a UNIX socket pair: the answerer spins on its socket, holds each
//! question for `answer_us` (the simulator's time per frame, 14 µs with 16 slaves) and
//! answers; the asker asks and waits. Last, what a timer sleep costs (as a cyclic loop sleeps
//! to its next cycle). docs/benchmarks.md quotes it.
//!
//! `cargo run --release -p ferrocat-link --example wake_cost [answer_us] [exchanges] [rounds]`
//! (defaults 14, 10000, 5; real-time priority and pinning where permitted).
use std::io;
use std::os::fd::{AsRawFd, FromRawFd, OwnedFd};

use ferrocat_link::{monotonic_ns, real_time};

#[derive(Clone, Copy, Debug)]
enum Wait {
    Spin,
    Block,
    /// A timeout past the next scheduler tick: no timer to program.
    PpollLong,
    /// A timeout within the tick, as a frame's is: a timer programmed for each wait.
    PpollShort,
}

impl Wait {
    const ALL: [Wait; 4] = [Wait::Spin, Wait::Block, Wait::PpollLong, Wait::PpollShort];

    fn name(self) -> &'static str {
        match self {
            Wait::Spin => "spinning on a non-blocking receive",
            Wait::Block => "a blocking receive (SO_RCVTIMEO)",
            Wait::PpollLong => "ppoll with a 1 s timeout, then a receive",
            Wait::PpollShort => "ppoll with a 1 ms timeout, then a receive",
        }
    }
}

fn arg(n: usize, default: u64, what: &str) -> Result<u64, String> {
    match std::env::args().nth(n) {
        None => Ok(default),
        Some(s) => match s.parse::<u64>() {
            Ok(v) if v > 0 => Ok(v),
            _ => Err(format!("argument {n} ({what}): expected a whole number above 0, got {s:?}")),
        },
    }
}

fn socket_pair() -> io::Result<(OwnedFd, OwnedFd)> {
    let mut fds = [0; 2];
    // SAFETY: socketpair writes two descriptors into the array we own; each is owned once.
    if unsafe { libc::socketpair(libc::AF_UNIX, libc::SOCK_DGRAM, 0, fds.as_mut_ptr()) } != 0 {
        return Err(io::Error::last_os_error());
    }
    // SAFETY: both descriptors are fresh and ours.
    Ok(unsafe { (OwnedFd::from_raw_fd(fds[0]), OwnedFd::from_raw_fd(fds[1])) })
}

fn send(fd: &OwnedFd, b: &[u8]) -> io::Result<()> {
    // SAFETY: send reads b.len() bytes of the slice.
    if unsafe { libc::send(fd.as_raw_fd(), b.as_ptr() as *const libc::c_void, b.len(), 0) } < 0 {
        return Err(io::Error::last_os_error());
    }
    Ok(())
}

/// One datagram's first byte, or `None` where none waits (non-blocking) or the timeout ran out.
fn recv(fd: &OwnedFd, flags: libc::c_int) -> io::Result<Option<u8>> {
    let mut b = [0u8; 64];
    // SAFETY: recv writes at most b.len() bytes into the buffer we own.
    let r = unsafe { libc::recv(fd.as_raw_fd(), b.as_mut_ptr() as *mut libc::c_void, b.len(), flags) };
    if r < 0 {
        let e = io::Error::last_os_error();
        return match e.kind() {
            io::ErrorKind::WouldBlock | io::ErrorKind::Interrupted => Ok(None),
            _ => Err(e),
        };
    }
    Ok(Some(b[0]))
}

fn ppoll(fd: &OwnedFd, timeout_ns: u64) -> io::Result<()> {
    let mut p = libc::pollfd { fd: fd.as_raw_fd(), events: libc::POLLIN, revents: 0 };
    let ts = libc::timespec {
        tv_sec: (timeout_ns / 1_000_000_000) as libc::time_t,
        tv_nsec: (timeout_ns % 1_000_000_000) as libc::c_long,
    };
    // SAFETY: ppoll reads and writes the one pollfd we own and reads the timespec.
    if unsafe { libc::ppoll(&mut p, 1, &ts, std::ptr::null()) } < 0 {
        return Err(io::Error::last_os_error());
    }
    Ok(())
}

fn thread_cpu_ns() -> u64 {
    let mut t = libc::timespec { tv_sec: 0, tv_nsec: 0 };
    // SAFETY: clock_gettime writes the timespec we own.
    unsafe { libc::clock_gettime(libc::CLOCK_THREAD_CPUTIME_ID, &mut t) };
    t.tv_sec as u64 * 1_000_000_000 + t.tv_nsec as u64
}

/// Spins on its socket; holds each question `answer_ns`, then answers; ends at a `b'q'`.
fn answerer(fd: OwnedFd, answer_ns: u64) -> io::Result<()> {
    real_time(80, Some(0));
    loop {
        let Some(q) = recv(&fd, libc::MSG_DONTWAIT)? else {
            std::hint::spin_loop();
            continue;
        };
        if q == b'q' {
            return Ok(());
        }
        let until = monotonic_ns() + answer_ns;
        while monotonic_ns() < until {
            std::hint::spin_loop();
        }
        send(&fd, b"a")?;
    }
}

/// `exchanges` questions, each waited for as `wait` says: (wall, the asker's CPU) per exchange.
fn ask(fd: &OwnedFd, wait: Wait, exchanges: u64) -> io::Result<(f64, f64)> {
    let (wall0, cpu0) = (monotonic_ns(), thread_cpu_ns());
    for _ in 0..exchanges {
        send(fd, b"?")?;
        loop {
            let got = match wait {
                Wait::Spin => recv(fd, libc::MSG_DONTWAIT)?,
                Wait::Block => recv(fd, 0)?,
                Wait::PpollLong | Wait::PpollShort => {
                    let timeout_ns = if matches!(wait, Wait::PpollLong) { 1_000_000_000 } else { 1_000_000 };
                    ppoll(fd, timeout_ns)?;
                    recv(fd, libc::MSG_DONTWAIT)?
                }
            };
            if got.is_some() {
                break;
            }
        }
    }
    let n = exchanges as f64;
    Ok(((monotonic_ns() - wall0) as f64 / n / 1e3, (thread_cpu_ns() - cpu0) as f64 / n / 1e3))
}

/// `n` sleeps of `sleep_ns` each (`clock_nanosleep`, as a cyclic loop sleeps to its next cycle):
/// the median overshoot and the CPU per sleep, both in µs.
fn sleep_cost(n: u64, sleep_ns: u64) -> (f64, f64) {
    let ts = libc::timespec { tv_sec: 0, tv_nsec: sleep_ns as libc::c_long };
    let cpu0 = thread_cpu_ns();
    let mut late: Vec<f64> = (0..n)
        .map(|_| {
            let t = monotonic_ns();
            // SAFETY: a relative sleep reading the timespec we own; no remainder wanted.
            unsafe { libc::clock_nanosleep(libc::CLOCK_MONOTONIC, 0, &ts, std::ptr::null_mut()) };
            (monotonic_ns() - t).saturating_sub(sleep_ns) as f64 / 1e3
        })
        .collect();
    (median(&mut late), (thread_cpu_ns() - cpu0) as f64 / n as f64 / 1e3)
}

fn median(v: &mut [f64]) -> f64 {
    v.sort_by(f64::total_cmp);
    v[v.len() / 2]
}

fn main() -> Result<(), Box<dyn std::error::Error>> {
    let answer_us = arg(1, 14, "answer_us")?;
    let exchanges = arg(2, 10_000, "exchanges")?;
    let rounds = arg(3, 5, "rounds")?;
    let (asker_fd, answer_fd) = socket_pair()?;
    let tv = libc::timeval { tv_sec: 1, tv_usec: 0 };
    // SAFETY: setsockopt reads the timeval we own.
    let r = unsafe {
        libc::setsockopt(
            asker_fd.as_raw_fd(),
            libc::SOL_SOCKET,
            libc::SO_RCVTIMEO,
            &tv as *const libc::timeval as *const libc::c_void,
            std::mem::size_of::<libc::timeval>() as u32,
        )
    };
    if r != 0 {
        return Err(format!("SO_RCVTIMEO: {}", io::Error::last_os_error()).into());
    }
    let answering = std::thread::spawn(move || answerer(answer_fd, answer_us * 1000));
    let rt = real_time(80, Some(1));
    if !rt.refused.is_empty() {
        eprintln!("wake_cost: not granted: {}", rt.refused.join("; "));
    }
    let mut results = vec![(Vec::new(), Vec::new()); Wait::ALL.len()];
    for _ in 0..rounds {
        // Alternating, so that every way of waiting meets the machine in the same state.
        for (i, w) in Wait::ALL.iter().enumerate() {
            let (wall, cpu) = ask(&asker_fd, *w, exchanges)?;
            results[i].0.push(wall);
            results[i].1.push(cpu);
        }
    }
    send(&asker_fd, b"q")?;
    answering.join().map_err(|_| "the answering thread panicked")??;
    let (late_us, sleep_cpu_us) = sleep_cost(exchanges, 100_000);
    println!("an answer {answer_us} us after each question; {exchanges} exchanges a round, {rounds} rounds alternating (medians of the rounds)");
    println!("{:<42} {:>18} {:>21}", "the asker waits by", "wall per exchange", "its CPU per exchange");
    for (i, w) in Wait::ALL.iter().enumerate() {
        let (wall, cpu) = (median(&mut results[i].0), median(&mut results[i].1));
        println!("{:<42} {:>15.2} us {:>18.2} us", w.name(), wall, cpu);
    }
    println!(
        "a sleep of 100 us (clock_nanosleep), {exchanges} times: {late_us:.2} us late (median), {sleep_cpu_us:.2} us of CPU each"
    );
    Ok(())
}
