//! `ferrocat run`'s cyclic frame timeout, on the embedded virtual segment, whose time is
//! simulated: the same seed loses the same frames, and a wait is exactly as long as it is.
use std::process::Command;

/// The summary of a 1 s run at 1 ms cycles on a segment that loses 5 % of its frames.
fn run_losing_frames(extra: &[&str]) -> serde_json::Value {
    let seg = std::env::temp_dir().join(format!("ferrocat-timeout-{}-{}.toml", std::process::id(), extra.len()));
    std::fs::write(
        &seg,
        "seed = 3\nloss_probability = 0.05\n[[device]]\nbuiltin = 'EK1100'\n[[device]]\nbuiltin = 'EL2004'\n",
    )
    .unwrap();
    let out = Command::new(env!("CARGO_BIN_EXE_ferrocat"))
        .args(["run", "--config", seg.to_str().unwrap(), "--cycle-us", "1000", "--seconds", "1", "--json"])
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
    let default = run_losing_frames(&[]);
    let whole_cycle = run_losing_frames(&["--frame-timeout-us", "1000"]);
    println!("default: {default}\n--frame-timeout-us 1000: {whole_cycle}");
    assert_eq!(default["frame_timeout_us"], 750);
    assert_eq!(whole_cycle["frame_timeout_us"], 1000);
    let lost = default["frames_lost"].as_u64().unwrap();
    assert!(lost >= 20, "5 % of 1000 cycles should lose some frames: {default}");
    assert_eq!(default["overruns"], 0, "{default}");
    assert_eq!(whole_cycle["frames_lost"], lost, "same seed, same losses: {whole_cycle}");
    assert_eq!(whole_cycle["overruns"], lost, "{whole_cycle}");
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
