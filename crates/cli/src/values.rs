//! `run --set NAME=VALUE` and `--show NAME`: process-image values by name, an ENI's variable
//! (`Term 2 (EL2008).Channel 1.Output`) or a slave's entry by position (`1:Output`).
use anyhow::{bail, Context};
use ferrocat_machine::eni::Eni;
use ferrocat_master::io::Io;
use ferrocat_master::Handle;
use ferrocat_master::Master;

/// Where `name` sits in the image; `output` for a value to write (an input cannot be).
pub fn handle<I: Io>(m: &Master<I>, eni: Option<&Eni>, name: &str, output: bool) -> anyhow::Result<Handle> {
    if let Some(e) = eni {
        let pi = &e.process_image;
        let found = pi.outputs.variables.iter().find(|v| v.name == name).map(|v| (v, 0)).or_else(|| {
            (!output)
                .then(|| pi.inputs.variables.iter().find(|v| v.name == name).map(|v| (v, m.out_bytes * 8)))
                .flatten()
        });
        if let Some((v, base)) = found {
            if v.bit_size > 64 {
                bail!("'{name}' has {} bits: values of at most 64 bits are read and written", v.bit_size);
            }
            let h = Handle { bit: base + v.bit_offs, bits: v.bit_size as u8 };
            if (h.bit as u64 + h.bits as u64).div_ceil(8) > m.image.len() as u64 {
                bail!("'{name}' lies past the process image (a variable no cyclic frame carries)");
            }
            return Ok(h);
        }
        if pi.inputs.variables.iter().any(|v| v.name == name) {
            bail!("'{name}' is an input: it cannot be set");
        }
    }
    let Some((pos, entry)) = name.split_once(':') else {
        bail!(
            "'{name}': give POS:ENTRY (a slave's position and one of its entries){}",
            if eni.is_some() { ", or a variable of the ENI's process image" } else { "" }
        );
    };
    let pos: u16 = pos.trim().parse().with_context(|| format!("'{name}': '{pos}' is not a slave position"))?;
    Ok(if output { m.output(pos, entry)? } else { m.input(pos, entry).or_else(|_| m.output(pos, entry))? })
}

/// `NAME=VALUE`: the handle and the value (decimal, 0x hex, or negative: two's complement in
/// its bits).
pub fn assignment<I: Io>(m: &Master<I>, eni: Option<&Eni>, spec: &str) -> anyhow::Result<(Handle, u64)> {
    let (name, value) = spec.rsplit_once('=').with_context(|| format!("--set '{spec}': give NAME=VALUE"))?;
    let h = handle(m, eni, name.trim(), true).with_context(|| format!("--set '{spec}'"))?;
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
