//! `run`'s reload (SIGHUP, or the control socket's `reload`): the machine description read
//! again, and what of it can change while the cycle goes on applied without stopping it.
use ferrocat_machine::Machine;
use ferrocat_master::Master;

use crate::target::{CliIo, Target};

/// Reads `--machine` again and applies what may change while cyclic: each slave's process-data
/// watchdog (written by requests in the cycles' spare time) and the slave-to-slave copies
/// (with `copy_flags`, `run --copy`'s); the network is compared with the description again
/// (its differences reported, not acted on). What needs the slaves back in PREOP (PDO
/// assignments, groups) is named, for the next start. `last` is the description in force,
/// replaced when the file reads. Returns what was done, in words.
pub fn reload(
    t: &Target,
    m: &mut Master<CliIo>,
    eni: Option<&ferrocat_machine::eni::Eni>,
    copy_flags: &[String],
    last: &mut Option<Machine>,
) -> Result<String, String> {
    let Some(path) = t.machine.as_deref() else {
        return Err(String::from("nothing to reload: run was started without --machine"));
    };
    let new = crate::eni::read_machine(path).map_err(|e| format!("{e:#}; the description in force is kept"))?;
    let mut done = Vec::new();
    let mut restart = Vec::new();
    let old = last.as_ref();
    let changed = |f: &dyn Fn(&Machine) -> String| old.is_none_or(|o| f(o) != f(&new));
    if changed(&|d| format!("{:?}", d.expected())) {
        let differs = ferrocat_machine::compare(&new.expected(), &crate::eni::found(m.slaves()));
        done.push(if differs.is_empty() {
            String::from("the network matches the new description")
        } else {
            let list: Vec<String> = differs.iter().map(|d| d.to_string()).collect();
            format!("the network differs from the new description ({}): the running segment is kept", list.join("; "))
        });
    }
    let found = m.slaves().len();
    for (k, s) in new.slaves.iter().enumerate().filter(|(k, _)| *k < found) {
        let was = old.and_then(|o| o.slaves.get(k));
        if was.map(|w| w.watchdog_us) != Some(s.watchdog_us) {
            if let Some(us) = s.watchdog_us {
                m.acyclic()
                    .submit_process_data_watchdog(k as u16, us as u64 * 1000)
                    .map_err(|e| format!("slave {k} ({})'s watchdog_us: {e}", s.name))?;
                done.push(format!("slave {k}'s process-data watchdog to {us} µs"));
            }
        }
        if was.is_some_and(|w| w.rx_pdos != s.rx_pdos || w.tx_pdos != s.tx_pdos) {
            restart.push(format!("slave {k}'s PDO assignment"));
        }
        if was.is_some_and(|w| w.init != s.init) {
            restart.push(format!("slave {k}'s init commands"));
        }
    }
    if changed(&|d| format!("{:?}", d.groups)) {
        restart.push(String::from("the process-data groups"));
    }
    if changed(&|d| format!("{:?}", d.variables)) {
        restart.push(String::from("the variables (the shared image's names)"));
    }
    let names = crate::values::Names { eni, machine: Some(&new) };
    let copies = crate::values::copies(m, names, copy_flags).map_err(|e| format!("copies: {e:#}"))?;
    let n = copies.len();
    m.cyclic().set_copies(copies).map_err(|e| format!("copies: {e}"))?;
    done.push(format!("{n} slave-to-slave cop{}", if n == 1 { "y" } else { "ies" }));
    *last = Some(new);
    let mut said = format!("{} read again: {}", path.display(), done.join("; "));
    if !restart.is_empty() {
        said.push_str(&format!("; {} changed: in force from the next start", restart.join(", ")));
    }
    Ok(said)
}
