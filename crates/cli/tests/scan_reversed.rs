//! `ferrocat scan` on the simulated segment with an ET1200 terminal entered on port 1: it says
//! so and that the terminal was latched again (with the terminal before it, whose port 1 leads
//! there: every ET1200 with a port besides port 0 in use is), and the tree is the one wired.
use std::process::Command;

#[test]
fn scan_names_a_reversed_terminal_and_its_second_latch() {
    let seg = std::env::temp_dir().join(format!("ferrocat-reversed-{}.toml", std::process::id()));
    std::fs::write(
        &seg,
        "seed = 4\n[[device]]\nbuiltin = 'EK1100'\n[[device]]\nbuiltin = 'EL2004'\n\
         [[device]]\nbuiltin = 'EL1004'\nport = 1\n[[device]]\nbuiltin = 'EL2004'\n",
    )
    .unwrap();
    let scan = |json: bool| {
        let mut args = vec!["scan", "--config", seg.to_str().unwrap()];
        if json {
            args.push("--json");
        }
        let out = Command::new(env!("CARGO_BIN_EXE_ferrocat")).args(&args).output().unwrap();
        assert!(out.status.success(), "{}", String::from_utf8_lossy(&out.stderr));
        String::from_utf8_lossy(&out.stdout).into_owned()
    };
    let (text, json) = (scan(false), scan(true));
    std::fs::remove_file(&seg).ok();
    // Processing order: coupler, first terminal, the terminal behind the reversed one, it.
    let slave4 = text.split("Slave 3:").nth(1).expect("four slaves, counted from 0");
    assert!(slave4.contains("EL1004") && slave4.contains("Entered on port 1"), "{text}");
    assert!(slave4.contains("latched again"), "{text}");
    let v: serde_json::Value = serde_json::from_str(&json).unwrap();
    let field = |k: &str| v.as_array().unwrap().iter().map(|s| s[k].clone()).collect::<Vec<_>>();
    assert_eq!(field("relatched"), [false, true, false, true].map(serde_json::Value::from));
    assert_eq!(field("entry_port"), [0, 0, 0, 1].map(serde_json::Value::from));
    assert_eq!(field("parent"), [serde_json::Value::Null, 0.into(), 3.into(), 1.into()]);
}
