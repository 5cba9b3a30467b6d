//! `ferrocat run`'s cyclic frame timeout, on the embedded virtual segment, whose time is
//! simulated: the same seed loses the same frames, and a wait is exactly as long as it is.
use std::process::Command;

const EL2004_LINE: &str = "[[device]]\nbuiltin = 'EK1100'\n[[device]]\nbuiltin = 'EL2004'\n";

/// The summary of a run of `seconds` at 1 ms cycles on `devices`, losing 5 % of the frames.
fn run_losing_frames(devices: &str, seconds: &str, extra: &[&str]) -> serde_json::Value {
    static RUNS: std::sync::atomic::AtomicUsize = std::sync::atomic::AtomicUsize::new(0);
    let k = RUNS.fetch_add(1, std::sync::atomic::Ordering::Relaxed);
    let seg = std::env::temp_dir().join(format!("ferrocat-timeout-{}-{k}.toml", std::process::id()));
    std::fs::write(&seg, format!("seed = 3\nloss_probability = 0.05\n{devices}")).unwrap();
    let out = Command::new(env!("CARGO_BIN_EXE_ferrocat"))
        .args(["run", "--config", seg.to_str().unwrap(), "--cycle-us", "1000", "--seconds", seconds, "--json"])
        .args(extra)
        .output()
        .unwrap();
    std::fs::remove_file(&seg).ok();
    assert!(out.status.success(), "{}", String::from_utf8_lossy(&out.stderr));
    serde_json::from_slice(&out.stdout).unwrap()
}

/// By default a frame is given up at ¾ of the cycle, so that its loss costs its own cycle and
/// not the next one; waited for a whole cycle (the library's 1 ms), every loss is an overrun.
#[test]
fn a_lost_frame_does_not_make_the_next_cycle_late() {
    let default = run_losing_frames(EL2004_LINE, "1", &[]);
    let whole_cycle = run_losing_frames(EL2004_LINE, "1", &["--frame-timeout-us", "1000"]);
    println!("default: {default}\n--frame-timeout-us 1000: {whole_cycle}");
    assert_eq!(default["frame_timeout_us"], 750);
    assert_eq!(whole_cycle["frame_timeout_us"], 1000);
    let lost = default["frames_lost"].as_u64().unwrap();
    assert!(lost >= 20, "5 % of 1000 cycles should lose some frames: {default}");
    assert_eq!(default["overruns"], 0, "{default}");
    assert_eq!(whole_cycle["frames_lost"], lost, "same seed, same losses: {whole_cycle}");
    assert_eq!(whole_cycle["overruns"], lost, "{whole_cycle}");
}

/// A wait longer than the cycle (a 3 ms timeout at 1 ms cycles, each lost frame a stall of
/// three cycles): the cycles it missed are skipped on the same grid, not run back to back,
/// so that one stall makes one cycle late, not a run of them.
#[test]
fn a_stall_longer_than_a_cycle_skips_the_cycles_it_missed() {
    let r = run_losing_frames(EL2004_LINE, "1", &["--frame-timeout-us", "3000"]);
    println!("{r}");
    let lost = r["frames_lost"].as_u64().unwrap();
    assert!(lost >= 20, "{r}");
    assert_eq!(r["overruns"], lost, "{r}");
    assert_eq!(r["cycles_skipped"], 2 * lost, "{r}");
    assert_eq!(r["cycles"].as_u64().unwrap() + 2 * lost, 1000, "every cycle of the second run or skipped: {r}");
}

#[test]
fn the_frame_timeout_is_bounded() {
    for bad in ["0", "9", "1000001", "-5", "1ms"] {
        let out = Command::new(env!("CARGO_BIN_EXE_ferrocat"))
            .args(["run", "--device", "EK1100", "--seconds", "0.1", &format!("--frame-timeout-us={bad}")])
            .output()
            .unwrap();
        let err = String::from_utf8_lossy(&out.stderr);
        assert!(!out.status.success() && err.contains("--frame-timeout-us"), "{bad}: {err}");
        assert!(!err.contains("panicked"), "{err}");
    }
}

/// A segment without process data has nothing to run: said so, and no summary of cycles that
/// never were (it once reported 0 cycles with a mean period of 2 s and exited 0).
#[test]
fn a_segment_without_process_data_is_refused() {
    let out = Command::new(env!("CARGO_BIN_EXE_ferrocat"))
        .args(["run", "--device", "EK1100", "--seconds", "0.2", "--json"])
        .output()
        .unwrap();
    let err = String::from_utf8_lossy(&out.stderr);
    assert!(!out.status.success() && err.contains("no slave maps process data (1 slave found)"), "{err}");
    assert!(out.stdout.is_empty());
    // With DC there is a frame each cycle: the reference's time distributed.
    let out = Command::new(env!("CARGO_BIN_EXE_ferrocat"))
        .args(["run", "--device", "EK1100", "--seconds", "0.2", "--json", "--dc", "--sync", "none"])
        .output()
        .unwrap();
    assert!(out.status.success(), "{}", String::from_utf8_lossy(&out.stderr));
}
