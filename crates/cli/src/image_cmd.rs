//! The process image a running master shares (`run`'s side: its symbol table and the
//! application watchdog), and `ferrocat get` / `set`, which read and write it from another
//! process.
use std::process::ExitCode;

use anyhow::{bail, Context};
use ferrocat_master::io::Io;
use ferrocat_master::{AlState, Master, Request};
use ferrocat_service::image::{ImageClient, Variable};

use crate::outln;
use crate::target::Target;

/// Every variable of the image: each slave's mapped entries (`POS:ENTRY`; an entry name the
/// slave maps more than once in one direction, as an EL2004 does "Output", is `POS:ENTRY#K`,
/// K counting from 1 in image order), then an ENI's variables and a machine description's
/// `[[variable]]`s under their own names.
pub fn symbols<I: Io>(m: &mut Master<I>, names: crate::values::Names<'_>) -> Vec<Variable> {
    let eni = names.eni;
    let groups = m.config().groups().to_vec();
    let m = &*m;
    let group_of = |pos: u16| groups.iter().find(|g| g.positions.contains(&pos)).map(|g| g.name.clone());
    let mut vars = Vec::new();
    for s in m.slaves() {
        let map = s.mapping();
        for (output, entries) in [(true, &map.outputs), (false, &map.inputs)] {
            let mapped: Vec<_> = entries.iter().filter(|e| e.bits > 0).collect();
            for (k, e) in mapped.iter().enumerate() {
                let same = mapped.iter().filter(|o| o.name == e.name).count();
                let nth = mapped[..k].iter().filter(|o| o.name == e.name).count() + 1;
                let name = if same > 1 {
                    format!("{}:{}#{nth}", s.position(), e.name)
                } else {
                    format!("{}:{}", s.position(), e.name)
                };
                vars.push(Variable {
                    name,
                    position: s.position(),
                    slave: s.name().to_string(),
                    group: group_of(s.position()),
                    output,
                    bit: e.image_bit,
                    bits: e.bits,
                    index: e.index,
                    subindex: e.subindex,
                });
            }
        }
    }
    if let Some(e) = eni {
        let (out_bytes, in_bytes) = m.image().byte_counts();
        let pi = &e.process_image;
        for (output, area, base) in [(true, &pi.outputs, 0), (false, &pi.inputs, out_bytes * 8)] {
            for v in area.variables.iter().filter(|v| (1..=64).contains(&v.bit_size)) {
                let bit = base + v.bit_offs;
                let end = if output { out_bytes * 8 } else { (out_bytes + in_bytes) * 8 };
                if bit + v.bit_size > end {
                    continue;
                }
                vars.push(Variable {
                    name: v.name.clone(),
                    position: u16::MAX,
                    slave: String::new(),
                    group: None,
                    output,
                    bit,
                    bits: v.bit_size as u8,
                    index: 0,
                    subindex: 0,
                });
            }
        }
    }
    for v in names.machine.map_or(&[][..], |d| &d.variables[..]) {
        let Some(s) = m.slaves().get(v.position as usize) else { continue };
        let map = s.mapping();
        let found = map.outputs.iter().map(|e| (true, e)).chain(map.inputs.iter().map(|e| (false, e)));
        if let Some((output, e)) = found.filter(|(_, e)| e.bits > 0).find(|(_, e)| e.name == v.entry) {
            vars.push(Variable {
                name: v.name.clone(),
                position: v.position,
                slave: s.name().to_string(),
                group: group_of(v.position),
                output,
                bit: e.image_bit,
                bits: e.bits,
                index: e.index,
                subindex: e.subindex,
            });
        }
    }
    vars
}

/// What the application watchdog does when the clients stop writing outputs.
#[derive(clap::ValueEnum, Debug, Clone, Copy, PartialEq, Eq)]
pub enum AppWatchdogAction {
    /// Keep the last outputs the application wrote, and say so.
    Hold,
    /// Take every slave with outputs to SAFEOP (its outputs off), and back to OP once the
    /// application writes again.
    Safeop,
}

/// The application watchdog: a client that wrote outputs and then stops for `timeout_ns`.
pub struct AppWatchdog {
    pub timeout_ns: u64,
    pub action: AppWatchdogAction,
    commits: u64,
    changed_ns: u64,
    tripped: bool,
}

impl AppWatchdog {
    pub fn new(timeout_ns: u64, action: AppWatchdogAction) -> Self {
        AppWatchdog { timeout_ns, action, commits: 0, changed_ns: 0, tripped: false }
    }

    /// Once a cycle: `commits` the clients' writes so far, `now_ns` the master's clock. A trip
    /// or a recovery is said, and with `safeop` requested of the master.
    pub fn check<I: Io>(&mut self, m: &mut Master<I>, commits: u64, now_ns: u64) {
        if commits != self.commits {
            self.commits = commits;
            self.changed_ns = now_ns;
            if self.tripped {
                self.tripped = false;
                eprintln!("application watchdog: the application writes again");
                if self.action == AppWatchdogAction::Safeop {
                    self.request_all(m, AlState::Op);
                }
            }
            return;
        }
        if commits == 0 || self.tripped || now_ns.saturating_sub(self.changed_ns) < self.timeout_ns {
            return;
        }
        self.tripped = true;
        eprintln!(
            "application watchdog: no output written for {} ms: {}",
            self.timeout_ns / 1_000_000,
            match self.action {
                AppWatchdogAction::Hold => "its last outputs held",
                AppWatchdogAction::Safeop => "the slaves with outputs to SAFEOP until it writes again",
            }
        );
        if self.action == AppWatchdogAction::Safeop {
            self.request_all(m, AlState::SafeOp);
        }
    }

    fn request_all<I: Io>(&self, m: &mut Master<I>, state: AlState) {
        let with_outputs: Vec<u16> =
            m.slaves().iter().filter(|s| s.mapping().output_bits() > 0).map(|s| s.position()).collect();
        for position in with_outputs {
            m.acyclic().submit(Request::State { position, state });
        }
    }

    pub fn tripped(&self) -> bool {
        self.tripped
    }
}

/// The image of the master running on `t`.
fn attach(t: &Target) -> anyhow::Result<ImageClient> {
    let Some(socket) = t.running_path() else {
        bail!(
            "the embedded virtual segment has no shared image unless run was given --control-socket: give it here too"
        );
    };
    let path = socket.with_extension("image");
    ImageClient::attach(&path)
        .with_context(|| format!("no running master's image at {} (start one with `ferrocat run`)", path.display()))
}

/// `ferrocat get [NAME…]`: variables of the running master's image (every one without names).
pub fn get(t: &Target, names: &[String], json: bool) -> anyhow::Result<ExitCode> {
    let c = attach(t)?;
    let snap = c.read()?;
    let chosen: Vec<&Variable> = if names.is_empty() {
        c.variables().iter().collect()
    } else {
        names.iter().map(|n| c.variable(n)).collect::<Result<_, _>>()?
    };
    if json {
        let values: serde_json::Map<String, serde_json::Value> =
            chosen.iter().map(|v| (v.name.clone(), snap.get(v).into())).collect();
        outln!(
            "{}",
            serde_json::json!({ "cycle": snap.cycle, "wkc": snap.wkc, "expected_wkc": snap.expected_wkc,
                "running": snap.running, "values": values })
        );
        return Ok(ExitCode::SUCCESS);
    }
    eprintln!(
        "cycle {} of the master (process {}), wkc {}/{}{}",
        snap.cycle,
        c.master_pid(),
        snap.wkc,
        snap.expected_wkc,
        if snap.running { "" } else { " — it has stopped" }
    );
    for v in chosen {
        outln!(
            "{:<40} {:>20}  ({}, {} bit{})",
            v.name,
            snap.get(v),
            if v.output { "output" } else { "input" },
            v.bits,
            if v.bits == 1 { "" } else { "s" }
        );
    }
    Ok(ExitCode::SUCCESS)
}

/// `ferrocat set NAME=VALUE…`: outputs of the running master's image, as one write; waits
/// (up to 1 s) until a cycle has sent it.
pub fn set(t: &Target, specs: &[String]) -> anyhow::Result<ExitCode> {
    let mut c = attach(t)?;
    let mut values = Vec::new();
    for spec in specs {
        let (name, value) = spec.rsplit_once('=').with_context(|| format!("'{spec}': give NAME=VALUE"))?;
        let v = c.variable(name.trim())?;
        let n =
            ferrocat_esi::parse_number(value.trim()).with_context(|| format!("'{spec}': '{value}' is not a number"))?;
        let bits = v.bits;
        let fits = bits == 64 || (n >= -(1i64 << (bits - 1)) && n < (1i64 << bits));
        if !fits {
            bail!("'{spec}': {n} does not fit {bits} bits");
        }
        let raw = if bits == 64 { n as u64 } else { n as u64 & ((1u64 << bits) - 1) };
        values.push((name.trim().to_string(), raw));
    }
    let pairs: Vec<(&str, u64)> = values.iter().map(|(n, v)| (n.as_str(), *v)).collect();
    let commit = c.write(&pairs)?;
    let t0 = std::time::Instant::now();
    loop {
        let (applied, cycle) = c.applied();
        if applied >= commit {
            eprintln!("written; first sent by cycle {cycle}");
            return Ok(ExitCode::SUCCESS);
        }
        if t0.elapsed() > std::time::Duration::from_secs(1) || !c.read()?.running {
            bail!("written, but no cycle has sent it within 1 s (is the master still running?)");
        }
        std::thread::sleep(std::time::Duration::from_micros(200));
    }
}
