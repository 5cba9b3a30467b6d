//! What it costs to hand work to a second core and have it back, once per frame: the least a
//! segment split over two threads would pay per cyclic frame before any work is saved
//! (docs/benchmarks.md, "Both cores"). `handoff [FRAMES]` prints the median and p90 of one
//! hand-off and return, by a `std::sync::Barrier` (the worker sleeps between frames) and by a
//! spinning worker on an atomic counter (it holds the second core all the time).
use std::sync::atomic::{AtomicU64, Ordering};
use std::sync::{Arc, Barrier};
use std::time::Instant;

fn quantiles(mut ns: Vec<u64>) -> (u64, u64) {
    ns.sort_unstable();
    (ns[ns.len() / 2], ns[ns.len() * 9 / 10])
}

/// Hand-offs through a barrier met twice per frame (work given, work done).
fn barrier(frames: usize) -> Vec<u64> {
    let b = Arc::new(Barrier::new(2));
    let w = b.clone();
    let worker = std::thread::spawn(move || {
        for _ in 0..frames {
            w.wait();
            w.wait();
        }
    });
    let out = (0..frames)
        .map(|_| {
            let t = Instant::now();
            b.wait();
            b.wait();
            t.elapsed().as_nanos() as u64
        })
        .collect();
    worker.join().expect("the worker ends");
    out
}

/// Hand-offs to a worker that spins on a counter: odd values are work given, even work done.
fn spin(frames: usize) -> Vec<u64> {
    let seq = Arc::new(AtomicU64::new(0));
    let s = seq.clone();
    let worker = std::thread::spawn(move || {
        for k in 0..frames as u64 {
            while s.load(Ordering::Acquire) != 2 * k + 1 {
                std::hint::spin_loop();
            }
            s.store(2 * k + 2, Ordering::Release);
        }
    });
    let out = (0..frames as u64)
        .map(|k| {
            let t = Instant::now();
            seq.store(2 * k + 1, Ordering::Release);
            while seq.load(Ordering::Acquire) != 2 * k + 2 {
                std::hint::spin_loop();
            }
            t.elapsed().as_nanos() as u64
        })
        .collect();
    worker.join().expect("the worker ends");
    out
}

fn main() {
    let frames = std::env::args().nth(1).and_then(|a| a.parse().ok()).unwrap_or(20_000usize).max(10);
    for (name, ns) in [("barrier", barrier(frames)), ("spinning worker", spin(frames))] {
        let (p50, p90) = quantiles(ns);
        println!(
            "{name}: hand-off and return median {:.2} µs, p90 {:.2} µs ({frames} frames)",
            p50 as f64 / 1e3,
            p90 as f64 / 1e3
        );
    }
}
