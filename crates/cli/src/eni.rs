//! `ferrocat eni`: what an ENI file describes, and the check of a scanned network against it.
use std::path::Path;
use std::process::ExitCode;

use anyhow::{bail, Context};
use ferrocat_machine::eni::{Eni, Target};
use ferrocat_machine::{Expected, Found, Identity, Machine, Mismatch};

use crate::outln;

/// Reads an ENI file, printing its warnings on stderr; `strict` refuses a file with any.
pub fn read(path: &Path, strict: bool) -> anyhow::Result<Eni> {
    let bytes = std::fs::read(path).with_context(|| format!("reading {}", path.display()))?;
    let eni = Eni::parse(&bytes).with_context(|| format!("{}", path.display()))?;
    let level = if strict { "error" } else { "warning" };
    for w in &eni.warnings {
        eprintln!("{level}: {}: {w}", path.display());
    }
    if strict && !eni.warnings.is_empty() {
        bail!(
            "{}: {} departure{} from ETG.2100 that configuration tools accept (--strict refuses them)",
            path.display(),
            eni.warnings.len(),
            if eni.warnings.len() == 1 { "" } else { "s" }
        );
    }
    Ok(eni)
}

fn target_text(t: &Target) -> String {
    match t {
        Target::Device { adp, ado } => format!("{adp:#06x}:{ado:#06x}"),
        Target::Logical(a) => format!("{a:#010x}"),
    }
}

/// `ferrocat eni FILE`.
pub fn run(path: &Path, json: bool, strict: bool) -> anyhow::Result<ExitCode> {
    let eni = read(path, strict)?;
    if json {
        outln!("{}", serde_json::to_string(&eni)?);
        return Ok(ExitCode::SUCCESS);
    }
    outln!(
        "{}: master '{}', {} slave{}, {} cyclic task{}",
        path.display(),
        eni.master.name,
        eni.slaves.len(),
        if eni.slaves.len() == 1 { "" } else { "s" },
        eni.cyclic.len(),
        if eni.cyclic.len() == 1 { "" } else { "s" }
    );
    outln!("pos  station  {:<24} {:<54} outputs  inputs  mailbox  init  DC", "name", "identity");
    for (k, s) in eni.slaves.iter().enumerate() {
        let bits = |r: Option<ferrocat_machine::eni::BitRange>| r.map_or("-".into(), |r| format!("{} b", r.length));
        outln!(
            "{k:3}  {:<7}  {:<24} {:<54} {:<8} {:<7} {:<8} {:<5} {}",
            s.station.map_or("-".into(), |a| a.to_string()),
            s.name,
            s.identity.to_string(),
            bits(s.process_data.send),
            bits(s.process_data.recv),
            s.mailbox.as_ref().map_or("-".into(), |m| m.protocols.join(",")),
            s.init_cmds.len() + s.mailbox.as_ref().map_or(0, |m| m.coe_init_cmds.len() + m.soe_init_cmds.len()),
            match s.dc {
                Some(dc) if dc.reference_clock => format!("reference, SYNC0 {} ns", dc.cycle_time0_ns),
                Some(dc) if dc.cycle_time0_ns > 0 => format!("SYNC0 {} ns", dc.cycle_time0_ns),
                Some(_) => "yes".into(),
                None => "-".into(),
            }
        );
    }
    for (t, c) in eni.cyclic.iter().enumerate() {
        outln!(
            "cyclic task {t}{}: {} frame{}",
            c.cycle_time_us.map_or(String::new(), |us| format!(" every {us} µs")),
            c.frames.len(),
            if c.frames.len() == 1 { "" } else { "s" }
        );
        for (f, frame) in c.frames.iter().enumerate() {
            for d in &frame.cmds {
                outln!(
                    "  frame {f}: {:<4} {:<13} {:>4} B  working counter {:<4} image offset {}",
                    d.command.name().unwrap_or("?"),
                    target_text(&d.target),
                    d.data_length,
                    d.cnt.map_or("-".into(), |c| c.to_string()),
                    d.input_offs.map_or("-".into(), |o| o.to_string())
                );
            }
        }
    }
    let pi = &eni.process_image;
    outln!(
        "process image: inputs {} B ({} variables), outputs {} B ({} variables)",
        pi.inputs.byte_size,
        pi.inputs.variables.len(),
        pi.outputs.byte_size,
        pi.outputs.variables.len()
    );
    Ok(ExitCode::SUCCESS)
}

/// The scanned slaves as the comparison takes them.
pub fn found(slaves: &[ferrocat_master::Slave]) -> Vec<Found> {
    slaves
        .iter()
        .map(|s| Found {
            position: s.position(),
            name: s.name().to_string(),
            identity: Identity {
                vendor_id: s.identity().vendor_id,
                product_code: s.identity().product_code,
                revision: s.identity().revision,
                serial: s.identity().serial,
            },
            alias: s.alias(),
        })
        .collect()
}

/// The machine description of the slaves found; a slave that one of the ESI files describes
/// (by product code and revision) gets it as its `device`, so that a simulator can serve it.
pub fn machine_from_scan(slaves: &[ferrocat_master::Slave], esi: &[std::path::PathBuf]) -> anyhow::Result<Machine> {
    let mut m = Machine::from_found(None, &found(slaves));
    for path in esi {
        let xml = ferrocat_segment::files::read_esi(path).with_context(|| format!("reading {}", path.display()))?;
        let file = ferrocat_esi::EsiFile::parse(&xml).with_context(|| format!("{}", path.display()))?;
        for (d, s) in m.slaves.iter_mut().zip(slaves) {
            let described = file.vendor_id == s.identity().vendor_id
                && file
                    .devices
                    .iter()
                    .any(|x| x.product_code == s.identity().product_code && x.revision == s.identity().revision);
            if d.device.is_none() && described {
                d.device = Some(format!("{}:#x{:x}", path.display(), s.identity().product_code));
            }
        }
    }
    Ok(m)
}

/// Reads a machine description (TOML).
pub fn read_machine(path: &Path) -> anyhow::Result<Machine> {
    let text = std::fs::read_to_string(path).with_context(|| format!("reading {}", path.display()))?;
    Machine::parse(&text).with_context(|| format!("{}", path.display()))
}

/// Compares the scanned network with the one `path` describes (`expected`): the differences on
/// stderr; an error naming them unless `allow_mismatch`.
pub fn check(
    path: &Path,
    expected: &[Expected],
    slaves: &[ferrocat_master::Slave],
    allow_mismatch: bool,
) -> anyhow::Result<()> {
    let diffs: Vec<Mismatch> = ferrocat_machine::compare(expected, &found(slaves));
    if diffs.is_empty() {
        let n = slaves.len();
        eprintln!("network as {} describes it: {n} slave{}", path.display(), if n == 1 { "" } else { "s" });
        return Ok(());
    }
    let list: Vec<String> = diffs.iter().map(|d| format!("  {d}")).collect();
    if allow_mismatch {
        eprintln!(
            "warning: the network differs from {} (--allow-mismatch: going on):\n{}",
            path.display(),
            list.join("\n")
        );
        return Ok(());
    }
    bail!(
        "the network differs from {} in {} place{} (found {} slaves, expected {}); nothing went past INIT \
         (--allow-mismatch goes on regardless):\n{}",
        path.display(),
        diffs.len(),
        if diffs.len() == 1 { "" } else { "s" },
        slaves.len(),
        expected.len(),
        list.join("\n")
    )
}

/// The master's plan for an ENI: its station addresses, each slave's FMMU and process-data
/// SyncManager writes (its register init commands for PREOP → SAFEOP and SAFEOP → OP, the
/// mailbox's SyncManagers left to the master), its CoE init commands for INIT → PREOP and
/// PREOP → SAFEOP and its SoE ones (IDN writes) for the same, where its entries start, and the
/// cyclic frames of every task.
pub fn plan(eni: &Eni) -> ferrocat_master::plan::Plan {
    use ferrocat_machine::eni::Transition;
    use ferrocat_master::plan::{Plan, PlanDatagram, PlanIdn, PlanSdo};
    use ferrocat_master::{AlState, Command};
    let any = |ts: &[Transition], wanted: &[(AlState, AlState)]| ts.iter().any(|t| wanted.contains(&(t.from, t.to)));
    let (ip, ps, so) =
        ((AlState::Init, AlState::PreOp), (AlState::PreOp, AlState::SafeOp), (AlState::SafeOp, AlState::Op));
    let address = |t: &Target| match *t {
        Target::Device { adp, ado } => ferrocat_master::Address::Device { adp, ado },
        Target::Logical(a) => ferrocat_master::Address::Logical(a),
    };
    let stations: Vec<u16> = eni.slaves.iter().filter_map(|s| s.station).collect();
    let registers = eni
        .slaves
        .iter()
        .map(|s| {
            s.init_cmds
                .iter()
                .filter(|c| matches!(c.command, Command::APWR | Command::FPWR))
                .filter_map(|c| match c.target {
                    Target::Device { ado, .. } => Some((ado, c.data.clone(), &c.transitions)),
                    Target::Logical(_) => None,
                })
                .filter(|(ado, _, ts)| {
                    let fmmu = (0x0600..0x0700).contains(ado);
                    // SM0 and SM1 of a slave with a mailbox are its mailbox: the master's.
                    let sm = (0x0800..0x0880).contains(ado) && !(s.mailbox.is_some() && *ado < 0x0810);
                    // The watchdog divider and times (0x0400, 0x0410, 0x0420), set by TwinCAT
                    // at INIT → PREOP.
                    let watchdog = (0x0400..0x0430).contains(ado);
                    ((fmmu || sm) && any(ts, &[ps, so])) || (watchdog && any(ts, &[ip, ps]))
                })
                .map(|(ado, data, _)| (ado, data))
                .collect()
        })
        .collect();
    let sdos = eni
        .slaves
        .iter()
        .map(|s| {
            s.mailbox
                .iter()
                .flat_map(|m| &m.coe_init_cmds)
                .filter(|c| c.ccs == 1 && any(&c.transitions, &[ip, ps]))
                .map(|c| PlanSdo {
                    index: c.index,
                    subindex: c.subindex,
                    complete_access: c.complete_access,
                    data: c.data.clone(),
                    comment: c.comment.clone(),
                })
                .collect()
        })
        .collect();
    let idns = eni
        .slaves
        .iter()
        .map(|s| {
            s.mailbox
                .iter()
                .flat_map(|m| &m.soe_init_cmds)
                .filter(|c| any(&c.transitions, &[ip, ps]))
                .map(|c| PlanIdn {
                    drive: c.drive,
                    idn: ferrocat_master::wire::soe::Idn(c.idn),
                    elements: ferrocat_master::wire::soe::Elements(c.elements),
                    data: c.data.clone(),
                    timeout_ms: c.timeout_ms.filter(|&ms| ms > 0),
                    comment: c.comment.clone(),
                })
                .collect()
        })
        .collect();
    let frames = eni
        .cyclic
        .iter()
        .flat_map(|c| &c.frames)
        .map(|f| {
            f.cmds
                .iter()
                .map(|d| PlanDatagram {
                    command: d.command,
                    address: address(&d.target),
                    length: d.data_length,
                    output_offset: d.output_offs,
                    input_offset: d.input_offs,
                    expected_wkc: d.cnt,
                })
                .collect()
        })
        .collect();
    // Each task's frames every as many base cycles as its cycle is a multiple of the fastest
    // task's (a task that gives no cycle: every cycle).
    let fastest = eni.cyclic.iter().filter_map(|c| c.cycle_time_us).filter(|&t| t > 0).min();
    let frame_every = eni
        .cyclic
        .iter()
        .flat_map(|c| {
            let every = match (c.cycle_time_us, fastest) {
                (Some(t), Some(f)) if t > 0 => ((t + f / 2) / f).max(1),
                _ => 1,
            };
            std::iter::repeat_n(every, c.frames.len())
        })
        .collect();
    // Without a <ProcessImage>, images as large as the frames they mirror.
    let reach = |pick: fn(&ferrocat_machine::eni::CyclicCmd) -> Option<u32>| {
        eni.cyclic
            .iter()
            .flat_map(|c| &c.frames)
            .flat_map(|f| &f.cmds)
            .filter_map(|d| pick(d).map(|o| o + 12 + d.data_length as u32))
            .max()
            .unwrap_or(0)
    };
    let size = |given: u32, reach: u32| if given > 0 { given } else { reach };
    Plan {
        stations: if stations.len() == eni.slaves.len() { stations } else { Vec::new() },
        registers,
        sdos,
        idns,
        entries_at: eni
            .slaves
            .iter()
            .map(|s| (s.process_data.send.map(|r| r.start), s.process_data.recv.map(|r| r.start)))
            .collect(),
        frames,
        frame_every,
        frame_names: eni
            .cyclic
            .iter()
            .enumerate()
            .flat_map(|(t, c)| (0..c.frames.len()).map(move |f| format!("task {t} frame {f}")))
            .collect(),
        output_bytes: size(eni.process_image.outputs.byte_size, reach(|d| d.output_offs)),
        input_bytes: size(eni.process_image.inputs.byte_size, reach(|d| d.input_offs)),
    }
}

#[cfg(test)]
mod tests {
    #[test]
    fn needs_shared_twincat_s_watchdog_fmmus_and_sms_make_the_plan() {
        let path = ferrocat_testdata::shared("eni/test_eni.xml");
        let eni = ferrocat_machine::eni::Eni::parse(&std::fs::read(path).unwrap()).unwrap();
        let plan = super::plan(&eni);
        // A drive: its watchdog divider and SM watchdog, its process data's SMs and FMMUs; not
        // its mailbox's SMs.
        let drive: Vec<u16> = plan.registers[1].iter().map(|(ado, _)| *ado).collect();
        assert!(drive.contains(&0x0400) && drive.contains(&0x0420), "{drive:#06x?}");
        assert!(drive.iter().any(|a| (0x0600..0x0700).contains(a)), "{drive:#06x?}");
        assert!(drive.iter().all(|a| !(0x0800..0x0810).contains(a)), "{drive:#06x?}");
        assert_eq!(plan.stations, [1001, 1002, 1003, 1004, 1005]);
        assert_eq!(plan.frames[0].len(), 6);
    }
}
