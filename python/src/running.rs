//! The cyclic loop in a Rust thread of its own: Python reads and writes the image and asks for
//! acyclic services between cycles, and never holds what the loop needs for longer than a
//! copy of a few bytes (no Python code runs under the master's lock, so a busy Python thread,
//! which holds the GIL, cannot delay a cycle).
use std::sync::atomic::{AtomicBool, Ordering};
use std::sync::mpsc;
use std::sync::{Arc, Mutex};
use std::thread::JoinHandle;

use ferrocat_master::{Answer, Request, RequestId};

use crate::master::State;

/// A request from Python and where its answer goes.
pub type Reply = mpsc::SyncSender<ferrocat_master::Result<Answer>>;

/// What the loop measured, shared with Python.
#[derive(Debug, Default, Clone)]
pub struct LoopStats {
    pub cycles: u64,
    pub short_wkc: u64,
    pub overruns: u64,
    /// Wake-up lateness of the last cycles, ns (a ring of [`SAMPLES`]).
    pub wake_late_ns: Vec<u32>,
    pub next_sample: usize,
    /// The loop's error, if it ended on one.
    pub error: Option<String>,
    pub real_time: String,
}

/// Wake-up samples kept (about 100 s at 1 ms).
const SAMPLES: usize = 100_000;

impl LoopStats {
    fn add_wake(&mut self, late_ns: u64) {
        let v = late_ns.min(u32::MAX as u64) as u32;
        if self.wake_late_ns.len() < SAMPLES {
            self.wake_late_ns.push(v);
        } else {
            self.wake_late_ns[self.next_sample] = v;
        }
        self.next_sample = (self.next_sample + 1) % SAMPLES;
    }
    /// Percentiles `ps` (0–100) of the wake-up lateness kept, ns (one sort for all).
    pub fn wake_percentiles_ns(&self, ps: &[f64]) -> Vec<Option<u32>> {
        let mut v = self.wake_late_ns.clone();
        v.sort_unstable();
        ps.iter()
            .map(|p| {
                let k = ((p / 100.0) * v.len().saturating_sub(1) as f64).round() as usize;
                v.get(k.min(v.len().saturating_sub(1))).copied()
            })
            .collect()
    }
}

pub struct Running {
    pub stop: Arc<AtomicBool>,
    /// `None` once joined.
    pub thread: Option<JoinHandle<()>>,
    pub stats: Arc<Mutex<LoopStats>>,
    pub requests: mpsc::SyncSender<(Request, Reply)>,
}

/// A loop whose master is dropped (its Python object collected while the loop ran) stops
/// with it, rather than drive the segment on in a thread nobody can reach.
impl Drop for Running {
    fn drop(&mut self) {
        self.stop.store(true, Ordering::Relaxed);
    }
}

/// Requests waiting in the loop at most; more are refused (the caller hears it).
pub const QUEUE: usize = 16;

/// Starts the loop on `state`, whose cycle `bring_up` has set. `priority`: SCHED_FIFO for the
/// loop's thread (and memory locked), as `ferrocat run` takes for its own.
pub fn start(state: Arc<Mutex<State>>, priority: Option<i32>, cpu: Option<usize>) -> std::io::Result<Running> {
    let stop = Arc::new(AtomicBool::new(false));
    let stats = Arc::new(Mutex::new(LoopStats::default()));
    let (tx, rx) = mpsc::sync_channel::<(Request, Reply)>(QUEUE);
    let (flag, shared) = (Arc::clone(&stop), Arc::clone(&stats));
    let thread = std::thread::Builder::new().name(String::from("ferrocat-cycle")).spawn(move || {
        let rt = match priority {
            Some(p) => {
                let rt = ferrocat_link::real_time(p, cpu);
                let mut said =
                    rt.fifo_priority.map_or(String::from("normal scheduling"), |p| format!("SCHED_FIFO {p}"));
                if !rt.refused.is_empty() {
                    said.push_str(&format!(" (refused: {})", rt.refused.join("; ")));
                }
                said
            }
            None => String::from("normal scheduling"),
        };
        lock(&shared).real_time = rt;
        run(&state, &flag, &shared, &rx);
    })?;
    Ok(Running { stop, thread: Some(thread), stats, requests: tx })
}

/// The loop's counters and its wake-up samples since the last hand-over into `shared`.
fn publish(shared: &mut LoopStats, local: &LoopStats, pending: &mut Vec<u64>) {
    for late in pending.drain(..) {
        shared.add_wake(late);
    }
    shared.cycles = local.cycles;
    shared.short_wkc = local.short_wkc;
    shared.overruns = local.overruns;
    if local.error.is_some() {
        shared.error.clone_from(&local.error);
    }
}

fn lock<T>(m: &Mutex<T>) -> std::sync::MutexGuard<'_, T> {
    m.lock().unwrap_or_else(|p| p.into_inner())
}

fn run(state: &Mutex<State>, stop: &AtomicBool, stats: &Mutex<LoopStats>, rx: &mpsc::Receiver<(Request, Reply)>) {
    let mut waiting: Vec<(RequestId, Reply)> = Vec::new();
    // The first cycle on the grid from now: the real-time set-up (locking a Python process's
    // memory takes tens of ms) and the thread's start took time since the last cycle, which
    // is no lateness of the loop's.
    let mut next = {
        let mut s = lock(state);
        let (now, period) = (ferrocat_link::monotonic_ns(), s.cycle_ns.max(1));
        if s.next_ns < now {
            s.next_ns += (now - s.next_ns).div_ceil(period) * period;
        }
        s.next_ns
    };
    // The loop's figures, handed to the shared ones only when Python is not reading them
    // (`try_lock`): the loop never waits for a copy Python makes.
    let mut local = LoopStats::default();
    let mut pending: Vec<u64> = Vec::new();
    while !stop.load(Ordering::Relaxed) {
        // The sleep outside the lock: Python reads and writes the image meanwhile.
        let planned = next;
        ferrocat_link::sleep_until_ns(planned);
        let woke = ferrocat_link::monotonic_ns();
        let mut s = lock(state);
        let r = cycle(&mut s, rx, &mut waiting);
        next = s.next_ns;
        s.m.cyclic().io_mut().prepare_sleep(next);
        local.overruns = s.overruns;
        drop(s);
        pending.push(woke.saturating_sub(planned));
        match r {
            Ok(short) => {
                local.cycles += 1;
                local.short_wkc += u64::from(short);
            }
            Err(e) => {
                local.error = Some(e.to_string());
                break;
            }
        }
        if let Ok(mut st) = stats.try_lock() {
            publish(&mut st, &local, &mut pending);
        }
    }
    publish(&mut lock(stats), &local, &mut pending);
    for (_, reply) in waiting {
        let _ = reply.try_send(Err(ferrocat_master::MasterError::Io(std::io::Error::other("the cyclic loop stopped"))));
    }
}

/// One cycle, then the requests in its spare time (none in its last quarter). Returns
/// whether the working counter was short.
fn cycle(
    s: &mut State,
    rx: &mpsc::Receiver<(Request, Reply)>,
    waiting: &mut Vec<(RequestId, Reply)>,
) -> ferrocat_master::Result<bool> {
    let want = s.m.image().expected_wkc();
    let wkc = s.exchange()?;
    while let Ok((request, reply)) = rx.try_recv() {
        let id = s.m.acyclic().submit(request);
        waiting.push((id, reply));
    }
    if !waiting.is_empty() {
        let deadline = s.next_ns.saturating_sub(s.cycle_ns / 4);
        s.m.acyclic().serve_requests(deadline)?;
        for (id, answer) in s.m.acyclic().take_answers() {
            if let Some(k) = waiting.iter().position(|(w, _)| *w == id) {
                let (_, reply) = waiting.swap_remove(k);
                let _ = reply.try_send(answer);
            }
        }
    }
    Ok(wkc != want)
}
