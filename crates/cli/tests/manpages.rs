//! The manual pages in docs/man/ are the ones the command line makes now, and the shell
//! completions it prints are scripts the shells take.
use std::process::Command;

#[test]
fn the_manual_pages_in_docs_are_current() {
    let dir = std::env::temp_dir().join(format!("ferrocat-man-{}", std::process::id()));
    let out = Command::new(env!("CARGO_BIN_EXE_ferrocat")).arg("manpages").arg(&dir).output().unwrap();
    assert!(out.status.success(), "{}", String::from_utf8_lossy(&out.stderr));
    let committed = std::path::Path::new(concat!(env!("CARGO_MANIFEST_DIR"), "/../../docs/man"));
    let names = |d: &std::path::Path| {
        let mut v: Vec<String> =
            std::fs::read_dir(d).unwrap().map(|e| e.unwrap().file_name().into_string().unwrap()).collect();
        v.sort();
        v
    };
    let (now, then) = (names(&dir), names(committed));
    assert_eq!(now, then, "regenerate with `cargo run -p ferrocat -- manpages docs/man`");
    assert!(now.len() > 30 && now.contains(&"ferrocat-run.1".to_string()), "{now:?}");
    for n in &now {
        let (a, b) = (std::fs::read(dir.join(n)).unwrap(), std::fs::read(committed.join(n)).unwrap());
        assert!(a == b, "docs/man/{n} is stale: regenerate with `cargo run -p ferrocat -- manpages docs/man`");
    }
    // Every option of `run` is on its page, with its default where it has one.
    let run = String::from_utf8(std::fs::read(dir.join("ferrocat-run.1")).unwrap()).unwrap();
    for opt in ["cycle\\-us", "seconds", "dc\\-static\\-frames", "max\\-rate", "eoe\\-tap"] {
        assert!(run.contains(&format!("\\-\\-{opt}")), "{opt} missing from ferrocat-run.1");
    }
    assert!(run.contains("[default: 1000]"), "the cycle's default on the page");
    std::fs::remove_dir_all(&dir).ok();
}

#[test]
fn the_completion_scripts_parse_and_know_the_subcommands() {
    let out = Command::new(env!("CARGO_BIN_EXE_ferrocat")).args(["completions", "bash"]).output().unwrap();
    assert!(out.status.success());
    let script = String::from_utf8(out.stdout).unwrap();
    for sub in ["scan", "run", "sdo", "lab", "rtt", "manpages"] {
        assert!(script.contains(sub), "{sub} missing from the bash completion");
    }
    let path = std::env::temp_dir().join(format!("ferrocat-completion-{}.bash", std::process::id()));
    std::fs::write(&path, &script).unwrap();
    let syntax = Command::new("bash").arg("-n").arg(&path).output().unwrap();
    std::fs::remove_file(&path).ok();
    assert!(syntax.status.success(), "bash -n: {}", String::from_utf8_lossy(&syntax.stderr));
    for shell in ["zsh", "fish"] {
        let out = Command::new(env!("CARGO_BIN_EXE_ferrocat")).args(["completions", shell]).output().unwrap();
        assert!(out.status.success() && out.stdout.len() > 1000, "{shell}");
    }
}
