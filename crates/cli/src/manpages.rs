//! `ferrocat manpages DIR`: the manual pages, made from the command line's own definitions so
//! that they cannot drift from it: ferrocat(1), and ferrocat-SUB(1) for every subcommand at
//! every depth (ferrocat-sdo-read(1), …).
use std::path::Path;
use std::process::ExitCode;

use anyhow::Context;
use clap::CommandFactory;

/// Every page as (file name, roff text), ferrocat.1 first.
pub fn pages() -> anyhow::Result<Vec<(String, Vec<u8>)>> {
    fn walk(cmd: clap::Command, path: Vec<String>, out: &mut Vec<(String, Vec<u8>)>) -> anyhow::Result<()> {
        let name = path.join("-");
        let mut cmd = cmd.name(name.clone()).bin_name(path.join(" "));
        if path.len() == 1 {
            cmd = cmd.version(env!("CARGO_PKG_VERSION"));
        }
        let mut roff = Vec::new();
        clap_mangen::Man::new(cmd.clone())
            .section("1")
            .source(format!("ferrocat {}", env!("CARGO_PKG_VERSION")))
            .manual("ferrocat manual")
            .render(&mut roff)
            .with_context(|| format!("rendering {name}(1)"))?;
        out.push((format!("{name}.1"), roff));
        for sub in cmd.get_subcommands().filter(|s| s.get_name() != "help") {
            let mut p = path.clone();
            p.push(sub.get_name().to_string());
            walk(sub.clone(), p, out)?;
        }
        Ok(())
    }
    let mut out = Vec::new();
    walk(crate::Cli::command(), vec!["ferrocat".into()], &mut out)?;
    Ok(out)
}

/// `ferrocat run`'s page as plain text (its long help), for reading where no `man` is.
pub fn run_page_text() -> String {
    let mut cmd = crate::Cli::command();
    let run = cmd.find_subcommand_mut("run").expect("ferrocat has a run subcommand");
    let mut run = run.clone().bin_name("ferrocat run");
    run.render_long_help().to_string()
}

pub fn write_all(dir: &Path) -> anyhow::Result<ExitCode> {
    std::fs::create_dir_all(dir).with_context(|| format!("creating {}", dir.display()))?;
    let pages = pages()?;
    for (name, roff) in &pages {
        let path = dir.join(name);
        std::fs::write(&path, roff).with_context(|| format!("writing {}", path.display()))?;
    }
    std::fs::write(dir.join("ferrocat-run.txt"), run_page_text())
        .with_context(|| format!("writing {}", dir.join("ferrocat-run.txt").display()))?;
    eprintln!("wrote {} manual pages and ferrocat-run.txt to {}", pages.len(), dir.display());
    Ok(ExitCode::SUCCESS)
}
