//! `run --set NAME=VALUE` and `--show NAME`: process-image values by name, an ENI's variable
//! (`Term 2 (EL2008).Channel 1.Output`), a machine description's `[[variable]]` (`lamp`), or a
//! slave's entry by position or by its name in the description (`1:Output`, `coupler:Output`).
use anyhow::{bail, Context};
use ferrocat_machine::eni::Eni;
use ferrocat_machine::Machine;
use ferrocat_master::io::Io;
use ferrocat_master::Handle;
use ferrocat_master::Master;

/// What gives the image's variables their names besides the slaves' own entries.
#[derive(Clone, Copy, Default)]
pub struct Names<'a> {
    pub eni: Option<&'a Eni>,
    pub machine: Option<&'a Machine>,
}

/// Where `name` sits in the image; `output` for a value to write (an input cannot be).
pub fn handle<I: Io>(m: &Master<I>, names: Names<'_>, name: &str, output: bool) -> anyhow::Result<Handle> {
    if let Some(e) = names.eni {
        let pi = &e.process_image;
        let found = pi.outputs.variables.iter().find(|v| v.name == name).map(|v| (v, 0)).or_else(|| {
            (!output)
                .then(|| {
                    pi.inputs.variables.iter().find(|v| v.name == name).map(|v| (v, m.image().byte_counts().0 * 8))
                })
                .flatten()
        });
        if let Some((v, base)) = found {
            if v.bit_size > 64 {
                bail!("'{name}' has {} bits: values of at most 64 bits are read and written", v.bit_size);
            }
            let h = Handle { bit: base + v.bit_offs, bits: v.bit_size as u8 };
            if (h.bit as u64 + h.bits as u64).div_ceil(8) > m.image().bytes().len() as u64 {
                bail!("'{name}' lies past the process image (a variable no cyclic frame carries)");
            }
            return Ok(h);
        }
        if pi.inputs.variables.iter().any(|v| v.name == name) {
            bail!("'{name}' is an input: it cannot be set");
        }
    }
    let entry_of = |pos: u16, entry: &str| -> anyhow::Result<Handle> {
        Ok(if output {
            m.image().output(pos, entry)?
        } else {
            m.image().input(pos, entry).or_else(|_| m.image().output(pos, entry))?
        })
    };
    if let Some(v) = names.machine.and_then(|d| d.variables.iter().find(|v| v.name == name.trim())) {
        return entry_of(v.position, &v.entry)
            .with_context(|| format!("variable '{}' ({}:{})", v.name, v.position, v.entry));
    }
    let Some((slave, entry)) = name.split_once(':') else {
        bail!(
            "'{name}': give POS:ENTRY (a slave's position and one of its entries){}{}",
            if names.machine.is_some() {
                ", a slave's name in the description for POS, or one of its variables"
            } else {
                ""
            },
            if names.eni.is_some() { ", or a variable of the ENI's process image" } else { "" }
        );
    };
    let by_name = names.machine.and_then(|d| d.slaves.iter().position(|s| s.name == slave.trim()));
    let pos: u16 = match by_name {
        Some(p) => p as u16,
        None => slave.trim().parse().with_context(|| format!("'{name}': '{slave}' is not a slave position"))?,
    };
    entry_of(pos, entry)
}

/// `NAME=VALUE`: the handle and the value (decimal, 0x hex, or negative: two's complement in
/// its bits).
pub fn assignment<I: Io>(m: &Master<I>, names: Names<'_>, spec: &str) -> anyhow::Result<(Handle, u64)> {
    let (name, value) = spec.rsplit_once('=').with_context(|| format!("--set '{spec}': give NAME=VALUE"))?;
    let h = handle(m, names, name.trim(), true).with_context(|| format!("--set '{spec}'"))?;
    let v = ferrocat_esi::parse_number(value.trim())
        .with_context(|| format!("--set '{spec}': '{value}' is not a number"))?;
    let fits = match h.bits {
        64 => true,
        b => v >= -(1i64 << (b - 1)) && v < (1i64 << b),
    };
    if !fits {
        bail!("--set '{spec}': {v} does not fit {} bits", h.bits);
    }
    Ok((h, v as u64))
}

/// Every slave-to-slave copy a run makes: an ENI's `CopyInfos` (by bit, split into pieces of at
/// most 64 bits), a machine description's `[[copy]]` (its slaves by name or position), and
/// `--copy FROM=TO` (named as `--set` names them).
pub fn copies<I: Io>(m: &Master<I>, names: Names<'_>, flags: &[String]) -> anyhow::Result<Vec<(Handle, Handle)>> {
    let mut out = Vec::new();
    if let Some(e) = names.eni {
        for c in e.cyclic.iter().flat_map(|c| &c.frames).flat_map(|f| &f.cmds).flat_map(|d| &d.copies) {
            let mut done = 0;
            while done < c.bits {
                let bits = (c.bits - done).min(64) as u8;
                out.push((
                    Handle { bit: m.image().byte_counts().0 * 8 + c.src_bit + done, bits },
                    Handle { bit: c.dst_bit + done, bits },
                ));
                done += bits as u32;
            }
        }
    }
    let mut named: Vec<(String, String, String)> = Vec::new();
    if let Some(d) = names.machine {
        for (from, to) in &d.copies {
            named.push((from.clone(), to.clone(), format!("[[copy]] {from} -> {to}")));
        }
    }
    for f in flags {
        let (from, to) = f.split_once('=').with_context(|| format!("--copy '{f}': give FROM=TO"))?;
        named.push((from.trim().into(), to.trim().into(), format!("--copy '{f}'")));
    }
    for (from, to, what) in named {
        let src = handle(m, names, &from, false).with_context(|| what.clone())?;
        let dst = handle(m, names, &to, true).with_context(|| what.clone())?;
        if src.bits != dst.bits {
            bail!("{what}: {} bits into {} bits", src.bits, dst.bits);
        }
        out.push((src, dst));
    }
    Ok(out)
}
