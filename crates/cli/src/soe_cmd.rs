//! `ferrocat soe read|write|list`: a servo drive's IDNs over SoE (ETG.1000.6 §5.8), shown and
//! encoded as their attributes say (numbers with their decimals, texts, IDN lists).
use std::process::ExitCode;

use anyhow::{bail, Context};
use clap::Subcommand;
use ferrocat_master::wire::soe::{self, Attribute, DataType, Elements, Idn, ValueLength};

use crate::outln;
use crate::target::{finish, Target};

#[derive(Subcommand)]
pub enum SoeCmd {
    /// Read an IDN of the drive at POSITION: its value, decoded as its attribute says, or with
    /// --element another element or all of them.
    Read {
        /// The slave's position on the segment, counted from 0 (as `scan` shows it).
        #[arg(allow_negative_numbers = true, value_parser = crate::args::position)]
        position: u16,
        /// The IDN: S-0-0030, P-0-0001 (S or P, the parameter set 0–7, the block 0–4095), or
        /// its number (0x8001).
        idn: String,
        /// The drive (axis) of a multi-axis device, from 0.
        #[arg(long, default_value_t = 0)]
        drive: u8,
        /// The element: value, name, attribute, unit, min, max, default, data-state, or all
        /// (name, attribute, unit, minimum, maximum and value, each read alone).
        #[arg(long, default_value = "value")]
        element: String,
        #[command(flatten)]
        target: Target,
    },
    /// Write VALUE to an IDN's value: a number of the IDN's width (decimal with its decimals,
    /// or 0x hex), a text for a text, IDNs separated by commas for an IDN list, or with --hex
    /// the bytes as they go on the wire.
    Write {
        /// The slave's position on the segment, counted from 0 (as `scan` shows it).
        #[arg(allow_negative_numbers = true, value_parser = crate::args::position)]
        position: u16,
        /// The IDN: S-0-0030, P-0-0001 or its number.
        idn: String,
        /// The value, as the IDN's attribute reads it.
        #[arg(allow_negative_numbers = true)]
        value: String,
        /// The drive (axis) of a multi-axis device, from 0.
        #[arg(long, default_value_t = 0)]
        drive: u8,
        /// VALUE is hex bytes as they go on the wire (a list with its two length words).
        #[arg(long)]
        hex: bool,
        #[command(flatten)]
        target: Target,
    },
    /// List every IDN of the drive (S-0-0017) with its name and value.
    List {
        /// The slave's position on the segment, counted from 0 (as `scan` shows it).
        #[arg(allow_negative_numbers = true, value_parser = crate::args::position)]
        position: u16,
        /// The drive (axis) of a multi-axis device, from 0.
        #[arg(long, default_value_t = 0)]
        drive: u8,
        #[command(flatten)]
        target: Target,
    },
}

fn idn_arg(text: &str) -> anyhow::Result<Idn> {
    Idn::parse(text).with_context(|| {
        format!("IDN '{text}': give S-SET-BLOCK or P-SET-BLOCK (S-0-0030, P-0-0001; set 0 to 7, block 0 to 4095) or a number")
    })
}

/// Where the reads and writes go: a running master's socket (between its cycles), or a master
/// of this command's own.
trait SoeAccess {
    fn read(&mut self, position: u16, drive: u8, idn: Idn, elements: Elements) -> anyhow::Result<Vec<u8>>;
    fn write(&mut self, position: u16, drive: u8, idn: Idn, data: &[u8]) -> anyhow::Result<()>;
}

impl SoeAccess for ferrocat_master::Master<crate::target::CliIo> {
    fn read(&mut self, position: u16, drive: u8, idn: Idn, elements: Elements) -> anyhow::Result<Vec<u8>> {
        Ok(self.acyclic().soe().read(position, drive, idn, elements)?)
    }
    fn write(&mut self, position: u16, drive: u8, idn: Idn, data: &[u8]) -> anyhow::Result<()> {
        Ok(self.acyclic().soe().write(position, drive, idn, Elements::VALUE, data)?)
    }
}

impl SoeAccess for ferrocat_service::Client {
    fn read(&mut self, position: u16, drive: u8, idn: Idn, elements: Elements) -> anyhow::Result<Vec<u8>> {
        Ok(self.soe_read(position, drive, idn.0, elements.0)?)
    }
    fn write(&mut self, position: u16, drive: u8, idn: Idn, data: &[u8]) -> anyhow::Result<()> {
        Ok(self.soe_write(position, drive, idn.0, Elements::VALUE.0, data)?)
    }
}

pub fn run(cmd: SoeCmd) -> anyhow::Result<ExitCode> {
    let target = match &cmd {
        SoeCmd::Read { target, .. } | SoeCmd::Write { target, .. } | SoeCmd::List { target, .. } => target,
    };
    if let Some(mut c) = target.running_master()? {
        soe_with(&mut c, cmd)?;
        return Ok(ExitCode::SUCCESS);
    }
    let mut m = target.master()?;
    target.scan(&mut m)?;
    // PREOP: the mailbox set up.
    m.states().configure()?;
    soe_with(&mut m, cmd)?;
    finish(m)?;
    Ok(ExitCode::SUCCESS)
}

/// An element the drive may lack: `None` where it says so (an SoE error, in the words of
/// either path: the master's own error or the running master's reply carrying it), else what
/// it sent.
fn optional(a: &mut dyn SoeAccess, position: u16, drive: u8, idn: Idn, e: Elements) -> anyhow::Result<Option<Vec<u8>>> {
    match a.read(position, drive, idn, e) {
        Ok(v) => Ok(Some(v)),
        Err(err) if err.to_string().contains("SoE error 0x") => Ok(None),
        Err(err) => Err(err),
    }
}

fn soe_with(a: &mut dyn SoeAccess, cmd: SoeCmd) -> anyhow::Result<()> {
    match cmd {
        SoeCmd::Read { position, idn, drive, element, .. } => {
            let idn = idn_arg(&idn)?;
            if element == "all" {
                let attr = read_attribute(a, position, drive, idn)?;
                let name = optional(a, position, drive, idn, Elements::NAME)?.map(|v| text(&v));
                outln!("{idn}  {}", name.as_deref().unwrap_or("(no name)"));
                outln!("  attribute {:#010x}: {}", attr.0, attribute_text(attr));
                if let Some(u) = optional(a, position, drive, idn, Elements::UNIT)? {
                    outln!("  unit      {}", text(&u));
                }
                if matches!(attr.length(), ValueLength::Fixed(_)) {
                    for (e, label) in [(Elements::MIN, "min"), (Elements::MAX, "max")] {
                        if let Some(v) = optional(a, position, drive, idn, e)? {
                            outln!("  {label:<9} {}", show(attr, &v));
                        }
                    }
                }
                outln!("  value     {}", show(attr, &a.read(position, drive, idn, Elements::VALUE)?));
            } else {
                let e = Elements::by_name(&element).with_context(|| {
                    format!(
                        "--element '{element}': give {} or all",
                        Elements::NAMES.iter().map(|(n, _)| *n).collect::<Vec<_>>().join(", ")
                    )
                })?;
                let v = a.read(position, drive, idn, e)?;
                let shown = match e {
                    Elements::VALUE | Elements::MIN | Elements::MAX | Elements::DEFAULT => {
                        show(read_attribute(a, position, drive, idn)?, &v)
                    }
                    Elements::NAME | Elements::UNIT => text(&v),
                    Elements::ATTRIBUTE => {
                        let at = attribute_of(&v)?;
                        format!("{:#010x}: {}", at.0, attribute_text(at))
                    }
                    _ => hex(&v),
                };
                outln!("{shown}");
            }
        }
        SoeCmd::Write { position, idn, value, drive, hex: raw, .. } => {
            let idn = idn_arg(&idn)?;
            let bytes = if raw {
                ferrocat_service::protocol::unhex(&value).map_err(|e| anyhow::anyhow!("VALUE {e}"))?
            } else {
                let at = read_attribute(a, position, drive, idn)?;
                encode(at, &value).with_context(|| format!("VALUE '{value}' for {idn} ({})", attribute_text(at)))?
            };
            a.write(position, drive, idn, &bytes)?;
            eprintln!("wrote {} byte(s) to {idn} of slave {position} drive {drive}", bytes.len());
        }
        SoeCmd::List { position, drive, .. } => {
            let all = a.read(position, drive, Idn::ALL_IDNS, Elements::VALUE)?;
            let (items, _) = soe::list_items(&all).context("S-0-0017, the list of every IDN")?;
            let idns: Vec<Idn> = items.chunks_exact(2).map(|c| Idn(u16::from_le_bytes([c[0], c[1]]))).collect();
            for idn in idns {
                let attr = read_attribute(a, position, drive, idn)?;
                let name = optional(a, position, drive, idn, Elements::NAME)?.map(|v| text(&v)).unwrap_or_default();
                let unit = optional(a, position, drive, idn, Elements::UNIT)?.map(|v| format!(" {}", text(&v)));
                let value = a.read(position, drive, idn, Elements::VALUE)?;
                outln!("{idn}  {name:<32}  {}{}", show(attr, &value), unit.unwrap_or_default());
            }
        }
    }
    Ok(())
}

fn read_attribute(a: &mut dyn SoeAccess, position: u16, drive: u8, idn: Idn) -> anyhow::Result<Attribute> {
    let v = a.read(position, drive, idn, Elements::ATTRIBUTE)?;
    attribute_of(&v)
}

fn attribute_of(v: &[u8]) -> anyhow::Result<Attribute> {
    let b: [u8; 4] =
        v.get(..4).and_then(|b| b.try_into().ok()).with_context(|| format!("an attribute of {} bytes", v.len()))?;
    Ok(Attribute(u32::from_le_bytes(b)))
}

fn attribute_text(a: Attribute) -> String {
    let len = match a.length() {
        ValueLength::Fixed(n) => format!("{n} bytes"),
        ValueLength::List(n) => format!("a list of {n}-byte items"),
    };
    let protected: Vec<&str> = [(2, "PREOP"), (3, "SAFEOP"), (4, "OP")]
        .iter()
        .filter(|(p, _)| a.write_protected_in(*p))
        .map(|(_, n)| *n)
        .collect();
    format!(
        "{len}, {:?}{}{}{}",
        a.data_type(),
        if a.decimals() > 0 { format!(", {} decimals", a.decimals()) } else { String::new() },
        if a.is_command() { ", a procedure command" } else { "" },
        if protected.is_empty() { String::new() } else { format!(", write protected in {}", protected.join(", ")) }
    )
}

fn hex(v: &[u8]) -> String {
    v.iter().map(|b| format!("{b:02x}")).collect::<Vec<_>>().join(" ")
}

fn text(v: &[u8]) -> String {
    match soe::list_items(v) {
        Ok((items, _)) => String::from_utf8_lossy(items).into_owned(),
        Err(_) => hex(v),
    }
}

/// A value as its attribute reads it; what does not fit it, in hex.
fn show(a: Attribute, v: &[u8]) -> String {
    match a.length() {
        ValueLength::Fixed(n) if v.len() == n as usize && n <= 8 => {
            let mut b = [0u8; 8];
            b[..v.len()].copy_from_slice(v);
            let u = u64::from_le_bytes(b);
            let signed = || {
                let shift = 64 - 8 * n as u32;
                ((u << shift) as i64) >> shift
            };
            let scaled = |x: i128| {
                let d = a.decimals() as u32;
                if d == 0 {
                    x.to_string()
                } else {
                    let p = 10i128.pow(d);
                    format!("{}{}.{:0w$}", if x < 0 { "-" } else { "" }, x.abs() / p, x.abs() % p, w = d as usize)
                }
            };
            match a.data_type() {
                DataType::Unsigned => scaled(u as i128),
                DataType::Signed => scaled(signed() as i128),
                DataType::Float if n == 4 => f32::from_bits(u as u32).to_string(),
                DataType::Float if n == 8 => f64::from_bits(u).to_string(),
                DataType::Idn if n == 2 => Idn(u as u16).to_string(),
                DataType::Binary => format!("{u:#0w$b}", w = 2 + 8 * n as usize),
                _ => format!("{u:#0w$x}", w = 2 + 2 * n as usize),
            }
        }
        ValueLength::List(item) => match soe::list_items(v) {
            Ok((items, _)) => match a.data_type() {
                DataType::Text => format!("\"{}\"", String::from_utf8_lossy(items)),
                DataType::Idn if item == 2 => items
                    .chunks_exact(2)
                    .map(|c| Idn(u16::from_le_bytes([c[0], c[1]])).to_string())
                    .collect::<Vec<_>>()
                    .join(", "),
                _ => hex(items),
            },
            Err(_) => hex(v),
        },
        _ => hex(v),
    }
}

/// VALUE as the attribute wants it on the wire.
fn encode(a: Attribute, value: &str) -> anyhow::Result<Vec<u8>> {
    match a.length() {
        ValueLength::Fixed(n) => {
            let n = n as usize;
            let v = value.trim();
            let raw: i128 = if let Some(h) = v.strip_prefix("0x") {
                i128::from_str_radix(h, 16).context("not a hex number")?
            } else if matches!(a.data_type(), DataType::Idn) {
                idn_arg(v)?.0 as i128
            } else {
                // Decimals: "12.5" with 3 decimals is 12500.
                let d = a.decimals() as usize;
                let (int, frac) = v.split_once('.').unwrap_or((v, ""));
                if frac.len() > d {
                    bail!("more than {d} decimals");
                }
                let digits = format!("{int}{frac:0<d$}");
                digits.parse::<i128>().context("not a number")?
            };
            let bits = 8 * n as u32;
            let signed = a.data_type() == DataType::Signed;
            let (lo, hi) =
                if signed { (-(1i128 << (bits - 1)), (1i128 << (bits - 1)) - 1) } else { (0, (1i128 << bits) - 1) };
            if raw < lo || raw > hi {
                bail!("out of range for {n} bytes ({lo} to {hi})");
            }
            Ok((raw as i64).to_le_bytes()[..n].to_vec())
        }
        ValueLength::List(item) => {
            let items: Vec<u8> = match a.data_type() {
                DataType::Text => value.as_bytes().to_vec(),
                DataType::Idn if item == 2 => value
                    .split(',')
                    .filter(|s| !s.trim().is_empty())
                    .map(|s| idn_arg(s).map(|i| i.0.to_le_bytes()))
                    .collect::<anyhow::Result<Vec<_>>>()?
                    .concat(),
                _ => bail!("a list of {item}-byte items: give it with --hex"),
            };
            let mut v = vec![0u8; 4 + items.len()];
            let n = soe::emit_list(&items, items.len() as u16, &mut v)?;
            v.truncate(n);
            Ok(v)
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn values_are_shown_and_encoded_as_their_attributes_say() {
        let signed3 = Attribute::new(ValueLength::Fixed(4), DataType::Signed, 3);
        assert_eq!(show(signed3, &(-12500i32).to_le_bytes()), "-12.500");
        assert_eq!(encode(signed3, "-12.5").unwrap(), (-12500i32).to_le_bytes());
        assert!(encode(signed3, "1.2345").is_err(), "4 decimals");
        let u16_ = Attribute::new(ValueLength::Fixed(2), DataType::Unsigned, 0);
        assert_eq!(encode(u16_, "0x1234").unwrap(), [0x34, 0x12]);
        assert!(encode(u16_, "65536").is_err());
        assert!(encode(u16_, "-1").is_err());
        let text = Attribute::new(ValueLength::List(1), DataType::Text, 0);
        assert_eq!(encode(text, "V1").unwrap(), [2, 0, 2, 0, b'V', b'1']);
        assert_eq!(show(text, &[2, 0, 8, 0, b'V', b'1']), "\"V1\"");
        let idns = Attribute::new(ValueLength::List(2), DataType::Idn, 0);
        assert_eq!(encode(idns, "S-0-0051,P-0-0001").unwrap(), [4, 0, 4, 0, 51, 0, 0x01, 0x80]);
        assert_eq!(show(idns, &[4, 0, 4, 0, 51, 0, 0x01, 0x80]), "S-0-0051, P-0-0001");
        assert_eq!(show(u16_, &[1]), "01", "a value not of its width: hex");
    }
}
