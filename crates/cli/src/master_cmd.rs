//! Commands that run the master: scan, sdo, sii, run.
use std::process::ExitCode;
use std::sync::atomic::{AtomicBool, Ordering};
use std::sync::Arc;

use anyhow::{bail, Context};
use ferrocat_master::sync::{ClockSync, Coupling, Sync0Plan, SyncMethod};
use ferrocat_master::{Master, SyncState};
use serde_json::json;

use crate::outln;
use crate::target::{finish, CliIo, Target};
use crate::timing_stats::Histogram;

pub fn scan(t: &Target, json: bool, write_machine: Option<&std::path::Path>) -> anyhow::Result<ExitCode> {
    if let Some(out) = write_machine.filter(|p| p.exists()) {
        bail!("{} exists: a machine description is not overwritten (remove it, or give another name)", out.display());
    }
    let mut m = t.master()?;
    t.scan(&mut m)?;
    if let Some(out) = write_machine {
        let text = crate::eni::machine_from_scan(m.slaves(), &t.esi)?.to_toml();
        std::fs::write(out, text).with_context(|| format!("writing {}", out.display()))?;
        eprintln!("wrote {} ({} slaves): edit it, then give it to --machine", out.display(), m.slaves().len());
    }
    // A ring split from the start: the secondary's cable comes in at the far half's root.
    let split_root = m.dc().split_latch().map(|l| (l.root as u16, l.root_port));
    let relatched = m.dc().relatched().to_vec();
    let ring_port = m.dc().ring_port();
    if json {
        let v: Vec<_> = m
            .slaves()
            .iter()
            .map(|s| {
                json!({
                    "position": s.position(), "station_address": s.station(), "alias": s.alias(),
                    "name": s.name(), "description": s.sii().name().unwrap_or_default(),
                    "vendor_id": s.identity().vendor_id, "product_code": s.identity().product_code, "revision": s.identity().revision, "serial": s.identity().serial,
                    "esc_type": s.esc().kind, "fmmus": s.esc().fmmu_count, "sync_managers": s.esc().sm_count,
                    "has_dc": s.dc().supported, "system_time": s.dc().has_system_time, "dc_64bit": s.dc().is_64bit, "delay_ns": s.dc().delay_ns,
                    "parent": s.ports().parent, "parent_port": s.ports().parent_port, "entry_port": s.ports().entry,
                    "active_ports": s.ports().active, "eeprom_loaded": s.ports().dl_status.pdi_operational(), "relatched": relatched.contains(&(s.position() as usize)),
                    "ring_port": ring_port.or(split_root).filter(|r| r.0 == s.position()).map(|r| r.1),
                    "mailbox": s.mailbox().map(|mb| json!({"out": [mb.out.0, mb.out.1], "in": [mb.inp.0, mb.inp.1], "protocols": mb.protocols})),
                })
            })
            .collect();
        outln!("{}", serde_json::Value::Array(v));
    } else {
        outln!("{}", crate::count(m.slaves().len(), "slave", "found"));
        use ferrocat_master::io::Io;
        if m.cyclic().io_mut().has_secondary() {
            let far = m.dc().split_latch().and_then(|l| l.far_reference);
            outln!(
                "{}",
                match (m.diagnosis().ring_state(), far) {
                    (ferrocat_master::RingState::Intact, _) => "Ring intact: every slave on one pass".to_string(),
                    (ferrocat_master::RingState::Broken, Some(f)) => format!(
                        "Ring broken: the slaves behind the break answer from the secondary port; \
                         their delays are from slave {f}, the first clock behind the break"
                    ),
                    (ferrocat_master::RingState::Broken, None) => {
                        "Ring broken: the slaves behind the break answer from the secondary port".to_string()
                    }
                    _ => "Ring open: nothing answers on the secondary port".to_string(),
                }
            );
        }
        for s in m.slaves() {
            outln!("");
            outln!("Slave {}: {} ({})", s.position(), s.name(), s.sii().name().unwrap_or_default());
            outln!(" Configured address: {:04x}  alias {}", s.station(), s.alias());
            outln!(
                " Man: {:08x} ID: {:08x} Rev: {:08x} Serial: {:08x}",
                s.identity().vendor_id,
                s.identity().product_code,
                s.identity().revision,
                s.identity().serial
            );
            outln!(" ESC type {:#04x}, {} FMMUs, {} SMs", s.esc().kind, s.esc().fmmu_count, s.esc().sm_count);
            outln!(
                " Has DC: {}  Delay: {}[ns]  Activeports: {}",
                s.dc().supported as u8,
                s.dc().delay_ns,
                s.ports().active_text()
            );
            if let Some(problem) = s.esc().eeprom_problem() {
                outln!(" {problem}");
            }
            if s.dc().supported && !s.dc().has_system_time {
                outln!(" DC: receive times only (no system time)");
            }
            if s.ports().entry != 0 {
                outln!(" Entered on port {}", s.ports().entry);
            }
            if relatched.contains(&(s.position() as usize)) {
                outln!(" DC: latched again (its ports 1–3 take the frame after the write to 0x0900)");
            }
            if let Some((_, port)) = ring_port.or(split_root).filter(|r| r.0 == s.position()) {
                outln!(" Ring: port {port} leads back to the master's secondary port");
            }
            if let Some(mb) = &s.mailbox() {
                outln!(
                    " MBX out {:#06x}/{} in {:#06x}/{} protocols {:#04x}",
                    mb.out.0,
                    mb.out.1,
                    mb.inp.0,
                    mb.inp.1,
                    mb.protocols
                );
            }
            for (k, sm) in s.sii().sync_managers().iter().enumerate() {
                outln!(" SM{k} A:{:04x} L:{:4} C:{:02x} Type:{}", sm.start, sm.length, sm.control, sm.sm_type);
            }
        }
        outln!("");
        outln!("Topology:");
        fn tree(m: &Master<CliIo>, parent: Option<u16>, depth: usize) {
            for s in m.slaves().iter().filter(|s| s.ports().parent == parent) {
                outln!(
                    "{}{} {} (port {} of its parent, {} ns)",
                    "  ".repeat(depth + 1),
                    s.position(),
                    s.name(),
                    s.ports().parent_port,
                    s.dc().delay_ns
                );
                tree(m, Some(s.position()), depth + 1);
            }
        }
        tree(&m, None, 0);
    }
    finish(m)?;
    Ok(ExitCode::SUCCESS)
}

/// `INDEX[:SUB]` with numbers in hex (0x…, #x…) or decimal.
fn parse_object(s: &str) -> anyhow::Result<(u16, u8)> {
    let (i, sub) = s.split_once(':').unwrap_or((s, "0"));
    let n = |t: &str| {
        ferrocat_esi::parse_number(t).with_context(|| {
            format!("object '{s}': '{t}' is not a number (give INDEX or INDEX:SUB, decimal or 0x hex)")
        })
    };
    let index =
        u16::try_from(n(i)?).map_err(|_| anyhow::anyhow!("object '{s}': index '{i}' is more than 0xFFFF (65535)"))?;
    let sub =
        u8::try_from(n(sub)?).map_err(|_| anyhow::anyhow!("object '{s}': subindex '{sub}' is more than 0xFF (255)"))?;
    Ok((index, sub))
}

/// The type to encode a value for `index:sub` in, from the slave's SDO information (CiA 301's
/// data type codes, ETG.1000.6 Table 63).
fn object_type(m: &mut dyn CoeAccess, position: u16, index: u16, sub: u8, complete: bool) -> anyhow::Result<SdoType> {
    if complete {
        bail!("complete access writes the whole object: give --type hex (its bytes) or string");
    }
    let e = m.entry(position, index, sub).map_err(|e| {
        anyhow::anyhow!(
            "the slave does not say what type {index:#06x}:{sub:#04x} is ({e}): give --type (u8, i8, u16, …, string, hex)"
        )
    })?;
    use SdoType::*;
    Ok(match e.data_type {
        0x0001 | 0x0005 => U8,
        0x0002 => I8,
        0x0003 => I16,
        0x0004 => I32,
        0x0006 => U16,
        0x0007 => U32,
        0x0008 => F32,
        0x0009 => String,
        0x000A => Hex,
        0x0011 => F64,
        0x0015 => I64,
        0x001B => U64,
        code => bail!(
            "{index:#06x}:{sub:#04x} is of data type {code:#06x} ({} bits), which --type does not name: give --type hex",
            e.bit_length
        ),
    })
}

/// How an SDO value is read from or written to its bytes (little-endian numbers).
#[derive(Debug, Clone, Copy, PartialEq, Eq, clap::ValueEnum)]
pub enum SdoType {
    U8,
    I8,
    U16,
    I16,
    U32,
    I32,
    U64,
    I64,
    F32,
    F64,
    String,
    Hex,
}

impl SdoType {
    /// The width of a number type in bytes.
    fn width(self) -> Option<usize> {
        use SdoType::*;
        match self {
            U8 | I8 => Some(1),
            U16 | I16 => Some(2),
            U32 | I32 | F32 => Some(4),
            U64 | I64 | F64 => Some(8),
            String | Hex => None,
        }
    }
    fn name(self) -> String {
        clap::ValueEnum::to_possible_value(&self).map(|v| v.get_name().to_string()).unwrap_or_default()
    }
}

fn encode(value: &str, ty: SdoType) -> anyhow::Result<Vec<u8>> {
    use SdoType::*;
    let name = ty.name();
    let int = || {
        let (neg, body) = value.trim().strip_prefix('-').map_or((false, value.trim()), |b| (true, b));
        let n = match body.strip_prefix("0x").or_else(|| body.strip_prefix("0X")) {
            Some(h) => i128::from_str_radix(h, 16),
            None => body.parse::<i128>(),
        };
        n.map(|n| if neg { -n } else { n })
            .with_context(|| format!("value '{value}' is not a number (decimal or 0x hex) for --type {name}"))
    };
    let range = match ty {
        U8 => "0 to 255",
        I8 => "-128 to 127",
        U16 => "0 to 65535",
        I16 => "-32768 to 32767",
        U32 => "0 to 4294967295",
        I32 => "-2147483648 to 2147483647",
        U64 => "0 to 18446744073709551615",
        _ => "-9223372036854775808 to 9223372036854775807",
    };
    let fit = |_| anyhow::anyhow!("value {value} is out of the range of --type {name} ({range})");
    let float = || value.parse::<f64>().with_context(|| format!("value '{value}' is not a number for --type {name}"));
    Ok(match ty {
        U8 => u8::try_from(int()?).map_err(fit)?.to_le_bytes().to_vec(),
        I8 => i8::try_from(int()?).map_err(fit)?.to_le_bytes().to_vec(),
        U16 => u16::try_from(int()?).map_err(fit)?.to_le_bytes().to_vec(),
        I16 => i16::try_from(int()?).map_err(fit)?.to_le_bytes().to_vec(),
        U32 => u32::try_from(int()?).map_err(fit)?.to_le_bytes().to_vec(),
        I32 => i32::try_from(int()?).map_err(fit)?.to_le_bytes().to_vec(),
        U64 => u64::try_from(int()?).map_err(fit)?.to_le_bytes().to_vec(),
        I64 => i64::try_from(int()?).map_err(fit)?.to_le_bytes().to_vec(),
        F32 => (float()? as f32).to_le_bytes().to_vec(),
        F64 => float()?.to_le_bytes().to_vec(),
        String => value.as_bytes().to_vec(),
        Hex => {
            // As the help says, "0x" may lead.
            let digits = value.trim().strip_prefix("0x").or_else(|| value.trim().strip_prefix("0X")).unwrap_or(value);
            ferrocat_wire::hex::decode(digits).map_err(|e| anyhow::anyhow!("hex value '{value}': {e}"))?
        }
    })
}

/// The value of an object's bytes as `ty`: a number type only where the object has exactly its
/// width (a wider object read as a narrower type would drop bytes unseen).
fn show(bytes: &[u8], ty: SdoType) -> anyhow::Result<String> {
    use SdoType::*;
    if let Some(w) = ty.width() {
        if bytes.len() != w {
            bail!(
                "the object holds {} byte(s) and --type {} reads {w}: read it with --type hex or string, or a type of its width",
                bytes.len(),
                ty.name()
            );
        }
    }
    let mut b = [0u8; 8];
    b[..bytes.len().min(8)].copy_from_slice(&bytes[..bytes.len().min(8)]);
    let u = u64::from_le_bytes(b);
    Ok(match ty {
        U8 | U16 | U32 | U64 => u.to_string(),
        I8 => (u as u8 as i8).to_string(),
        I16 => (u as u16 as i16).to_string(),
        I32 => (u as u32 as i32).to_string(),
        I64 => (u as i64).to_string(),
        F32 => f32::from_bits(u as u32).to_string(),
        F64 => f64::from_bits(u).to_string(),
        String => std::string::String::from_utf8_lossy(bytes).trim_end_matches('\0').to_string(),
        Hex => bytes.iter().map(|b| format!("{b:02x}")).collect::<Vec<_>>().join(" "),
    })
}

pub enum SdoAction {
    Read { object: String, complete: bool, ty: SdoType },
    Write { object: String, value: String, complete: bool, ty: Option<SdoType> },
    List,
}

/// The CoE services `sdo` uses: of a master of its own, or of the master running on the
/// target (through its control socket).
pub trait CoeAccess {
    fn upload(&mut self, position: u16, index: u16, sub: u8, complete: bool) -> anyhow::Result<Vec<u8>>;
    fn download(&mut self, position: u16, index: u16, sub: u8, complete: bool, data: &[u8]) -> anyhow::Result<()>;
    /// An entry's description.
    fn entry(&mut self, position: u16, index: u16, sub: u8) -> anyhow::Result<ferrocat_master::EntryInfo>;
    fn objects(&mut self, position: u16) -> anyhow::Result<Vec<u16>>;
    fn object(&mut self, position: u16, index: u16) -> anyhow::Result<ferrocat_master::ObjectInfo>;
}

impl CoeAccess for Master<CliIo> {
    fn upload(&mut self, position: u16, index: u16, sub: u8, complete: bool) -> anyhow::Result<Vec<u8>> {
        Ok(self.acyclic().coe().sdo_upload(position, index, sub, complete)?)
    }
    fn download(&mut self, position: u16, index: u16, sub: u8, complete: bool, data: &[u8]) -> anyhow::Result<()> {
        Ok(self.acyclic().coe().sdo_download(position, index, sub, complete, data)?)
    }
    fn entry(&mut self, position: u16, index: u16, sub: u8) -> anyhow::Result<ferrocat_master::EntryInfo> {
        Ok(self.acyclic().coe().entry_info(position, index, sub)?)
    }
    fn objects(&mut self, position: u16) -> anyhow::Result<Vec<u16>> {
        Ok(self.acyclic().coe().od_list(position)?)
    }
    fn object(&mut self, position: u16, index: u16) -> anyhow::Result<ferrocat_master::ObjectInfo> {
        Ok(self.acyclic().coe().object_info(position, index)?)
    }
}

pub fn sdo(t: &Target, position: u16, action: SdoAction) -> anyhow::Result<ExitCode> {
    if let Some(mut c) = t.running_master()? {
        return sdo_with(&mut c, position, action);
    }
    let mut m = t.master()?;
    t.scan(&mut m)?;
    m.states().configure()?;
    let code = sdo_with(&mut m, position, action)?;
    finish(m)?;
    Ok(code)
}

fn sdo_with(m: &mut dyn CoeAccess, position: u16, action: SdoAction) -> anyhow::Result<ExitCode> {
    match action {
        SdoAction::Read { object, complete, ty } => {
            let (i, s) = parse_object(&object)?;
            let v = m.upload(position, i, s, complete)?;
            outln!("{}", show(&v, ty)?);
        }
        SdoAction::Write { object, value, complete, ty } => {
            let (i, s) = parse_object(&object)?;
            let ty = match ty {
                Some(ty) => ty,
                None => object_type(m, position, i, s, complete)?,
            };
            let bytes = encode(&value, ty)?;
            m.download(position, i, s, complete, &bytes)?;
            eprintln!(
                "wrote {value} to {i:#06x}:{s:#04x} of slave {position} ({}, {} byte(s))",
                ty.name(),
                bytes.len()
            );
        }
        SdoAction::List => {
            for index in m.objects(position)? {
                let o = m.object(position, index)?;
                use ferrocat_wire::coe::{data_type_name, object_code_name};
                let ty = data_type_name(o.data_type).map_or(format!("{:#06x}", o.data_type), |n| n.to_string());
                let code = object_code_name(o.object_code).map_or(format!("{:#04x}", o.object_code), |n| n.to_string());
                outln!("{index:#06x} {:<40} {code:<6} {ty:<16} subindices 0 to {}", o.name, o.max_subindex);
            }
        }
    }
    Ok(ExitCode::SUCCESS)
}

pub enum FoeAction {
    Read { file: std::path::PathBuf, max_bytes: usize },
    Write { file: std::path::PathBuf },
}

/// `ferrocat foe read|write`: one file by FoE, the segment in PREOP, or (`boot`) the slave in
/// BOOT and back to INIT afterwards.
pub fn foe(
    t: &Target,
    position: u16,
    name: &str,
    password: &str,
    boot: bool,
    action: FoeAction,
) -> anyhow::Result<ExitCode> {
    let password = ferrocat_esi::parse_number(password)
        .and_then(|p| u32::try_from(p).ok())
        .with_context(|| format!("--password '{password}' is not a 32-bit number"))?;
    // The file first: a missing one, or a folder that cannot take one, should not cost a
    // bring-up. A read goes to FILE.part, renamed to FILE once whole: a file already there is
    // kept until then.
    let (data, part) = match &action {
        FoeAction::Write { file } => {
            (Some(std::fs::read(file).with_context(|| format!("reading {}", file.display()))?), None)
        }
        // Not a regular file (/dev/null, a pipe): written to as it is, never replaced.
        FoeAction::Read { file, .. } if std::fs::metadata(file).is_ok_and(|m| !m.is_file()) => {
            let f = std::fs::OpenOptions::new()
                .write(true)
                .open(file)
                .with_context(|| format!("opening {}", file.display()))?;
            (None, Some((None, f)))
        }
        FoeAction::Read { file, .. } => {
            let mut name = file.file_name().unwrap_or_default().to_os_string();
            name.push(".part");
            let part = file.with_file_name(name);
            let f = std::fs::File::create(&part).with_context(|| format!("creating {}", part.display()))?;
            (None, Some((Some(part), f)))
        }
    };
    let result = foe_transfer(t, position, name, password, boot, action, data, part.as_ref());
    if let (Some((Some(part), _)), Err(_)) = (&part, &result) {
        let _ = std::fs::remove_file(part);
    }
    result
}

#[allow(clippy::too_many_arguments)]
fn foe_transfer(
    t: &Target,
    position: u16,
    name: &str,
    password: u32,
    boot: bool,
    action: FoeAction,
    data: Option<Vec<u8>>,
    part: Option<&(Option<std::path::PathBuf>, std::fs::File)>,
) -> anyhow::Result<ExitCode> {
    let data = data.unwrap_or_default();
    // Beside a running master: through its socket, in its cycle's spare time.
    let read = match t.running_master()? {
        Some(_) if boot => bail!(
            "--boot takes the slave to BOOT, out of the running master's cycle: stop that master first (a firmware is \
             written with the segment to this command alone)"
        ),
        Some(mut c) => match &action {
            FoeAction::Write { .. } => {
                c.foe_write(position, name, password, &data)?;
                None
            }
            FoeAction::Read { max_bytes, .. } => Some(c.foe_read(position, name, password, *max_bytes)?),
        },
        None => {
            let mut m = t.master()?;
            t.scan(&mut m)?;
            if boot {
                m.states().enter_bootstrap(position)?;
            } else {
                m.states().configure()?;
            }
            let read = match &action {
                FoeAction::Write { .. } => {
                    m.acyclic().foe().write(position, name, password, &data)?;
                    None
                }
                FoeAction::Read { max_bytes, .. } => {
                    Some(m.acyclic().foe().read(position, name, password, *max_bytes)?)
                }
            };
            if boot {
                m.states().leave_bootstrap(position)?;
            }
            finish(m)?;
            read
        }
    };
    match (action, read) {
        (FoeAction::Write { file }, _) => {
            eprintln!("wrote {} ({} bytes) to slave {position} as '{name}'", file.display(), data.len());
        }
        (FoeAction::Read { file, .. }, data) => {
            let data = data.unwrap_or_default();
            if let Some((part_path, f)) = part {
                use std::io::Write;
                let mut f: &std::fs::File = f;
                let written = part_path.as_deref().unwrap_or(&file);
                f.write_all(&data).with_context(|| format!("writing {}", written.display()))?;
                if let Some(p) = part_path {
                    f.sync_all().with_context(|| format!("writing {}", p.display()))?;
                    std::fs::rename(p, &file)
                        .with_context(|| format!("renaming {} to {}", p.display(), file.display()))?;
                }
            }
            eprintln!("read '{name}' ({} bytes) from slave {position} into {}", data.len(), file.display());
        }
    }
    Ok(ExitCode::SUCCESS)
}

pub fn sii_read(t: &Target, position: u16, out: Option<&std::path::Path>) -> anyhow::Result<ExitCode> {
    // Beside a running master: the SII it read at its start.
    let (img, m) = match t.running_master()? {
        Some(mut c) => (c.sii_read(position)?, None),
        None => {
            let mut m = t.master()?;
            t.scan(&mut m)?;
            (m.slaves().at(position)?.sii().to_image(), Some(m))
        }
    };
    match out {
        Some(p) => {
            std::fs::write(p, &img).with_context(|| format!("writing {}", p.display()))?;
            eprintln!("wrote {} bytes of slave {position}'s SII to {}", img.len(), p.display());
        }
        None => {
            // As xxd and hexdump -C show it: byte offsets, 16 bytes a line, and the printable
            // bytes (SII word N is at byte 2N).
            for (k, c) in img.chunks(16).enumerate() {
                let bytes: Vec<String> = c.iter().map(|b| format!("{b:02x}")).collect();
                let text: String =
                    c.iter().map(|&b| if b.is_ascii_graphic() || b == b' ' { b as char } else { '.' }).collect();
                outln!("{:08x}: {:<47}  {text}", k * 16, bytes.join(" "));
            }
        }
    }
    if let Some(m) = m {
        finish(m)?;
    }
    Ok(ExitCode::SUCCESS)
}

/// `sii write`: refused before anything is written where the image is of another device
/// (unless `overwrite_identity`) or larger than the slave's EEPROM; the EEPROM as it was saved
/// first; read back and compared after.
pub fn sii_write(
    t: &Target,
    position: u16,
    file: &std::path::Path,
    overwrite_identity: bool,
    backup: Option<&std::path::Path>,
) -> anyhow::Result<ExitCode> {
    let img = crate::sii::load(file)?;
    let info = ferrocat_wire::sii::SiiInfo::from_image(&img)
        .with_context(|| format!("{}: not an SII image", file.display()))?;
    if let Some(b) = backup.filter(|b| b.exists()) {
        bail!("--backup {}: exists; a backup is not overwritten", b.display());
    }
    let mut m = t.master()?;
    t.scan(&mut m)?;
    let s = m.slaves().at(position)?;
    let (h, mine) = (&info.header, &s.sii().header);
    if (h.vendor_id, h.product_code) != (s.identity().vendor_id, s.identity().product_code) && !overwrite_identity {
        bail!(
            "{} is vendor {:#x} product {:#x} ({}); slave {position} is vendor {:#x} product {:#x} ({}): nothing written \
             (--overwrite-identity programs it anyway)",
            file.display(),
            h.vendor_id,
            h.product_code,
            info.string(1).unwrap_or_else(|| "no name".into()),
            s.identity().vendor_id,
            s.identity().product_code,
            s.name()
        );
    }
    let data_len = img.iter().rposition(|b| *b != 0xFF).map_or(0, |i| i + 1);
    if data_len > mine.eeprom_size_bytes() {
        bail!(
            "{} holds {data_len} bytes of data; slave {position}'s EEPROM holds {} (its SII word 0x3E): nothing written",
            file.display(),
            mine.eeprom_size_bytes()
        );
    }
    let before = s.sii().to_image();
    let backup = match backup {
        Some(b) => b.to_path_buf(),
        None => (0..)
            .map(|k| match k {
                0 => std::path::PathBuf::from(format!("sii-backup-slave{position}.bin")),
                k => std::path::PathBuf::from(format!("sii-backup-slave{position}.{k}.bin")),
            })
            .find(|p| !p.exists())
            .unwrap_or_default(),
    };
    std::fs::write(&backup, &before).with_context(|| format!("writing the backup {}", backup.display()))?;
    eprintln!("slave {position}'s EEPROM as it was ({} bytes) is in {}", before.len(), backup.display());
    let words = m.acyclic().sii().write(position, &img)?;
    // Read back (the master reloads and reads the SII after writing) and compared.
    let after = m.slaves().at(position)?.sii().to_image();
    let used = data_len.min(after.len());
    if let Some(at) = (0..used).find(|&k| after.get(k) != img.get(k)) {
        bail!(
            "slave {position}'s EEPROM reads back other than {} from byte {at:#x}: the old contents are in {}",
            file.display(),
            backup.display()
        );
    }
    eprintln!("wrote {words} words to slave {position}'s EEPROM and read them back");
    finish(m)?;
    Ok(ExitCode::SUCCESS)
}

pub fn sii_alias(t: &Target, position: u16, alias: &str) -> anyhow::Result<ExitCode> {
    let value = ferrocat_esi::parse_number(alias)
        .and_then(|v| u16::try_from(v).ok())
        .with_context(|| format!("alias '{alias}' is not a 16-bit number"))?;
    let mut m = t.master()?;
    t.scan(&mut m)?;
    let words = m.acyclic().sii().set_alias(position, value)?;
    let name = &m.slaves()[position as usize].name();
    eprintln!(
        "slave {position} ({name}): alias {value:#06x} in its EEPROM ({words} words written); \
         its ESC takes it at the next power-on"
    );
    finish(m)?;
    Ok(ExitCode::SUCCESS)
}

/// User + system CPU time of this process, in ns.
fn cpu_ns() -> u64 {
    // SAFETY: getrusage fills the struct we own.
    let mut u: libc::rusage = unsafe { std::mem::zeroed() };
    unsafe { libc::getrusage(libc::RUSAGE_SELF, &mut u) };
    let t = |tv: libc::timeval| tv.tv_sec as u64 * 1_000_000_000 + tv.tv_usec as u64 * 1000;
    t(u.ru_utime) + t(u.ru_stime)
}

/// What `ferrocat run` was asked for.
pub struct RunOptions<'a> {
    pub seconds: f64,
    pub cycle_us: u64,
    /// With DC: how the clocks are brought together and kept so.
    pub dc: Option<DcOptions>,
    pub max_rate: bool,
    /// The cyclic frames' timeout; `None`: [`frame_timeout_us`]'s default.
    pub frame_timeout_us: Option<u64>,
    pub eoe_taps: &'a [String],
    /// How often each slave's error counters are read while cyclic, ms (`None`: no diagnosis).
    pub diagnosis_ms: Option<u64>,
    /// How long a TxPDO Toggle may stand still, ms.
    pub txpdo_stale_ms: u64,
    /// Outputs to write before OP (`NAME=VALUE`), and values to show at the end.
    pub set: &'a [String],
    pub show: &'a [String],
    /// Slave-to-slave copies (`FROM=TO`) besides a description's.
    pub copy: &'a [String],
    pub json: bool,
    /// The control socket (`None`: none).
    pub control: Option<ControlOptions>,
    /// Leave the slaves in OP at the end instead of stepping them down.
    pub keep_state: bool,
}

/// How `run` serves its control socket.
pub struct ControlOptions {
    /// The socket file's mode.
    pub mode: u32,
    /// Its group.
    pub group: Option<String>,
    /// Whether register writes are taken.
    pub register_writes: bool,
    /// The mailbox gateway, where one is asked for.
    pub gateway: Option<ferrocat_service::GatewayOptions>,
    /// The application watchdog on the shared image's outputs.
    pub app_watchdog: Option<crate::image_cmd::AppWatchdog>,
}

/// Where the cyclic frames passed the reference on the DC cycle, as time after the SYNC0
/// before: a frame aimed the shift before SYNC0 passes `cycle − shift` after the one before.
/// One that passed near either end came close to reaching a DC-synchronous slave in the
/// wrong SYNC0 interval, and two such intervals without outputs take a drive out of OP
/// (0x001A).
struct Sync0Passage {
    sync0_phase_ns: u64,
    after_sync0: Histogram,
}

impl Sync0Passage {
    /// SYNC0 at `sync0_phase_ns` modulo the cycle, in system time.
    fn new(sync0_phase_ns: u64) -> Self {
        Sync0Passage { sync0_phase_ns, after_sync0: Histogram::default() }
    }

    /// A frame that passed the reference when its system time read `at_ns`.
    fn add(&mut self, at_ns: u64, cycle_ns: u64) {
        let d = (at_ns as i128 - self.sync0_phase_ns as i128).rem_euclid(cycle_ns.max(1) as i128) as u64;
        self.after_sync0.add(d);
    }
}

/// `ferrocat run --dc`'s settings.
pub struct DcOptions {
    /// The static drift compensation's frames at most.
    pub static_frames: u32,
    /// The clock-sync preset.
    pub sync: String,
    /// SYNC0 after the frame leaves, µs (`None`: half the cycle).
    pub sync0_shift_us: Option<u64>,
    /// SYNC1 after SYNC0, µs (0: none).
    pub sync1_us: u32,
    /// Slaves whose SYNC0 is started (`true`) or not (`false`) whatever their SII says.
    pub sync0_overrides: Vec<(u16, bool)>,
    /// Assign-activate words of the description's, by position.
    pub assign_activate: Vec<(u16, u16)>,
    /// Probing's time per cycle, µs (`None`: from the loop's measured cost).
    pub probe_budget_us: Option<u64>,
}

/// The DC flags of `run` as given (`None`: not given).
pub struct DcFlags {
    pub static_frames: Option<u32>,
    pub sync: Option<String>,
    pub sync0_shift_us: Option<u64>,
    pub probe_budget_us: Option<u64>,
}

impl DcOptions {
    /// DC as `--dc` and the machine description's `[dc]` ask for it, the flags over the
    /// description; `None` without either. A DC flag without DC is an error.
    pub fn merged(t: &Target, dc: bool, flags: DcFlags) -> anyhow::Result<Option<DcOptions>> {
        let machine = t.machine_file()?;
        let desc = machine.and_then(|d| d.dc.clone());
        let file = t.machine.as_deref().map(|p| p.display().to_string()).unwrap_or_default();
        if !dc && desc.is_none() {
            let given = [
                ("--dc-static-frames", flags.static_frames.is_some()),
                ("--sync", flags.sync.is_some()),
                ("--sync0-shift-us", flags.sync0_shift_us.is_some()),
                ("--probe-budget-us", flags.probe_budget_us.is_some()),
            ];
            if let Some((flag, _)) = given.iter().find(|(_, g)| *g) {
                bail!("{flag} goes with --dc (or a machine description's [dc])");
            }
            return Ok(None);
        }
        let desc = desc.unwrap_or_default();
        let sync = match (flags.sync, &desc.sync) {
            (Some(s), _) => s,
            (None, Some(s)) if SyncMethod::PRESETS.contains(&s.as_str()) => s.clone(),
            (None, Some(s)) => {
                bail!("{file}: [dc] sync = '{s}': not a method ({})", SyncMethod::PRESETS.join(", "))
            }
            (None, None) => String::from("ferrocat"),
        };
        // `sync0` where given; else a slave given an assign-activate word that activates
        // anything (its high byte, 0x0981) is started.
        let slaves = machine.map_or(&[][..], |d| &d.slaves[..]);
        let sync0_overrides = slaves
            .iter()
            .enumerate()
            .filter_map(|(k, s)| Some((k as u16, s.sync0.or(s.assign_activate.map(|w| w >> 8 != 0))?)))
            .collect();
        let assign_activate =
            slaves.iter().enumerate().filter_map(|(k, s)| Some((k as u16, s.assign_activate?))).collect();
        Ok(Some(DcOptions {
            static_frames: flags.static_frames.or(desc.static_frames).unwrap_or(15_000),
            sync,
            sync0_shift_us: flags.sync0_shift_us.or(desc.sync0_shift_us.map(u64::from)),
            sync1_us: desc.sync1_us,
            sync0_overrides,
            assign_activate,
            probe_budget_us: flags.probe_budget_us.or(desc.probe_budget_us.map(u64::from)),
        }))
    }
}

/// The cycles at the start of a run that measure the loop's own cost, without probes: 0.2 s,
/// at least 200.
fn measuring_cycles(cycle_us: u64) -> u64 {
    (200_000 / cycle_us.max(1)).max(200)
}

/// The cyclic frames' timeout unless told: ¾ of the cycle, so that the wait for a lost frame
/// ends before the next cycle is due, and at most the library's 1 ms; on a segment whose round
/// trip (`round_trip_us`, once measured) leaves less than that room, the round trip and half
/// of what the cycle has left after it, so that a frame a little slower than usual is not lost.
pub fn frame_timeout_us(cycle_us: u64, max_rate: bool, round_trip_us: Option<u64>) -> u64 {
    const MAX_US: u64 = 1000;
    let usual = if max_rate { MAX_US } else { (cycle_us * 3 / 4).clamp(1, MAX_US) };
    match round_trip_us {
        Some(rtt) if max_rate => usual.max(2 * rtt),
        Some(rtt) => usual.max(rtt + cycle_us.saturating_sub(rtt) / 2),
        None => usual,
    }
}

/// A method's lock state and filtered offset, in words.
fn lock_text(method: &dyn ClockSync, st: &SyncState) -> String {
    match st.lock.offset_ns() {
        Some(o) => {
            let (lock_ns, unlock_ns) = st.lock.bounds_ns();
            format!(
                "{}: {}, offset {o} ns (locks within {lock_ns} ns, unlocks beyond {unlock_ns} ns; noise {} ns)",
                method.name(),
                st.lock.state(),
                st.lock.noise_ns()
            )
        }
        None => format!("{}: {}", method.name(), st.lock.state()),
    }
}

pub fn run(t: &Target, o: &mut RunOptions<'_>) -> anyhow::Result<ExitCode> {
    let RunOptions { seconds, cycle_us, max_rate, eoe_taps, json, .. } = *o;
    let mut frame_timeout_us = o.frame_timeout_us.unwrap_or_else(|| frame_timeout_us(cycle_us, max_rate, None));
    let dc = o.dc.is_some();
    if let Some(shift) = o.dc.as_ref().and_then(|d| d.sync0_shift_us).filter(|&s| s >= cycle_us) {
        bail!("--sync0-shift-us {shift}: give a shift below the cycle ({cycle_us} µs)");
    }
    if !(0.0..1e6).contains(&seconds) {
        bail!("--seconds {seconds}: give 0 (until SIGINT or SIGTERM) or a time below 1 000 000 s");
    }
    let stop = Arc::new(AtomicBool::new(false));
    for sig in [signal_hook::consts::SIGINT, signal_hook::consts::SIGTERM] {
        signal_hook::flag::register(sig, Arc::clone(&stop)).context("installing signal handlers")?;
    }
    // SIGHUP: the machine description read again (crate::reload).
    let sighup = Arc::new(AtomicBool::new(false));
    signal_hook::flag::register(signal_hook::consts::SIGHUP, Arc::clone(&sighup))
        .context("installing signal handlers")?;
    let eoe_taps = eoe_taps
        .iter()
        .map(|v| {
            let (pos, name) = v.split_once(':').with_context(|| format!("--eoe-tap '{v}': give POS:TAP"))?;
            let pos: u16 = pos.parse().with_context(|| format!("--eoe-tap '{v}': '{pos}' is not a slave position"))?;
            Ok((pos, name))
        })
        .collect::<anyhow::Result<Vec<_>>>()?;
    let mut m = t.master()?;
    m.config().settings_mut().cyclic_timeout_ns = frame_timeout_us * 1000;
    m.config().settings_mut().txpdo_stale_ns = o.txpdo_stale_ms.saturating_mul(1_000_000);
    if !m.cyclic().io_mut().is_virtual() {
        crate::target::go_real_time();
    }
    eprintln!("timestamps: {}; frames through {}", m.cyclic().io_mut().timestamps(), m.cyclic().io_mut().path());
    let t_start = { m.cyclic().now_ns() };
    t.scan(&mut m)?;
    t.configure(&mut m)?;
    // Nothing to exchange: no frame would go out, and the summary would count none.
    if m.image().bytes().is_empty() && !dc {
        bail!(
            "no slave maps process data ({}): nothing to exchange cyclically (--dc runs the clock distribution alone)",
            crate::count(m.slaves().len(), "slave", "found")
        );
    }
    // The segment's round trip, for the frame timeout and SYNC0's place.
    let round_trip_ns = (m.dc().median_round_trip_ns(16)?).max(0) as u64;
    let round_trip_us = round_trip_ns.div_ceil(1000);
    if o.frame_timeout_us.is_none() {
        frame_timeout_us = self::frame_timeout_us(cycle_us, max_rate, Some(round_trip_us));
        m.config().settings_mut().cyclic_timeout_ns = frame_timeout_us * 1000;
    }
    if !max_rate && round_trip_us * 10 > cycle_us * 8 {
        tracing::warn!(
            "the segment's round trip ({round_trip_us} µs) is {} % of the {cycle_us} µs cycle: a frame more than \
             {} µs late counts as lost, and the next cycle starts late; a longer cycle gives it room",
            round_trip_us * 100 / cycle_us.max(1),
            frame_timeout_us.saturating_sub(round_trip_us)
        );
    }
    let mut sync: Option<(Box<dyn ClockSync>, SyncState)> = None;
    // Where the master's cycles start on the DC cycle's grid, and SYNC0 on it, with DC.
    let mut grid_ns = None;
    let mut sync0 = None;
    if let Some(d) = &o.dc {
        let name = d.sync.as_str();
        let method = SyncMethod::preset(name, Coupling::ReferenceFollowsMaster)
            .with_context(|| format!("--sync {name}: not a method ({})", SyncMethod::PRESETS.join(", ")))?;
        let plan = Sync0Plan::new(&method, cycle_us * 1000, round_trip_ns, d.sync0_shift_us.map(|us| us * 1000));
        // In PREOP, before SAFEOP: delays, offsets, static drift compensation, SYNC0.
        // The SII's choice of SYNC0 slaves, with a description's `sync0` over it.
        let sync0_slaves = (!d.sync0_overrides.is_empty()).then(|| {
            let mut on = ferrocat_master::sync0_by_sii(m.slaves());
            for &(k, wanted) in &d.sync0_overrides {
                on.retain(|&p| p != k);
                if wanted && (k as usize) < m.slaves().len() {
                    on.push(k);
                }
            }
            on.sort_unstable();
            on
        });
        let cfg = ferrocat_master::DcConfig {
            sync0_cycle_ns: (cycle_us * 1000).min(u32::MAX as u64) as u32,
            sync0_shift_ns: plan.shift_ns as i32,
            sync1_ns: d.sync1_us.saturating_mul(1000),
            max_frames: d.static_frames,
            sync0_slaves,
            assign_activate: d.assign_activate.clone(),
            ..Default::default()
        };
        let (s, r, st) = m.clock().start_clock_sync(&cfg, &method, cycle_us * 1000)?;
        sync = Some((s, st));
        grid_ns = r.sync0_start.map(|t| t.wrapping_sub(plan.shift_ns));
        sync0 = Some(plan);
        eprintln!(
            "DC: reference slave {}; static drift compensation {} frames, {} (max |0x092C| {} ns); SYNC0 on {}",
            r.reference,
            r.static_frames,
            if r.converged { "converged" } else { "not converged" },
            r.max_difference_ns,
            match r.sync0_slaves.as_slice() {
                [] => String::from("no slave"),
                [one] => format!("slave {one}"),
                many => format!("slaves {}", many.iter().map(|p| p.to_string()).collect::<Vec<_>>().join(", ")),
            }
        );
        if let Some((l, lag)) = m.dc().split_latch().and_then(|l| Some((l, l.far_lag_ns()?))) {
            eprintln!(
                "DC: ring split from the start: the far half (from slave {}) latched {:.1} µs after the reference, \
                 its clocks set for that instant",
                l.first_far,
                lag as f64 / 1e3
            );
        }
    }
    let eni = t.eni_file()?;
    let names = crate::values::Names { eni, machine: t.machine_file()? };
    // Every variable the description names is an entry the slave maps, checked before OP.
    for v in names.machine.map_or(&[][..], |d| &d.variables[..]) {
        crate::values::handle(&m, names, &v.name, false).with_context(|| {
            format!("{}: [[variable]] '{}'", t.machine.as_deref().unwrap_or(std::path::Path::new("")).display(), v.name)
        })?;
    }
    for spec in o.set {
        let (h, v) = crate::values::assignment(&m, names, spec)?;
        m.cyclic().set(h, v);
    }
    let shown = o
        .show
        .iter()
        .map(|n| {
            crate::values::handle(&m, names, n, false).map(|h| (n.as_str(), h)).with_context(|| format!("--show '{n}'"))
        })
        .collect::<anyhow::Result<Vec<_>>>()?;
    let copies = crate::values::copies(&m, names, o.copy)?;
    if !copies.is_empty() {
        eprintln!(
            "{} slave-to-slave cop{} after every cycle",
            copies.len(),
            if copies.len() == 1 { "y" } else { "ies" }
        );
    }
    m.cyclic().set_copies(copies)?;
    m.states().start()?;
    let mut bridges = Vec::new();
    for &(pos, name) in &eoe_taps {
        m.acyclic().eoe().link(pos)?;
        bridges.push(crate::eoe_cmd::TapBridge::open(pos, name)?);
        eprintln!("bridging slave {pos} to {name} (EoE between cycles)");
    }
    let mut control = match (&o.control, t.control_path()) {
        (Some(c), Some(path)) => {
            let hello = ferrocat_service::protocol::Hello {
                service: String::from("ferrocat"),
                protocol: ferrocat_service::protocol::VERSION,
                pid: std::process::id(),
                target: t.service_name().unwrap_or_else(|| String::from("virtual")),
                cycle_us: if max_rate { 0 } else { cycle_us },
                slaves: m.slaves().len(),
                register_writes: c.register_writes,
            };
            let options = ferrocat_service::ServerOptions {
                path: path.clone(),
                mode: c.mode,
                group: c.group.clone(),
                register_writes: c.register_writes,
                hello,
            };
            let mut server = ferrocat_service::Server::start(options)
                .with_context(|| format!("control socket {}", path.display()))?;
            eprintln!("control socket {}", path.display());
            if let Some(g) = &c.gateway {
                let at =
                    server.start_gateway(g.clone()).with_context(|| format!("mailbox gateway on udp {}", g.bind))?;
                eprintln!("mailbox gateway on udp {at}");
            }
            Some(server)
        }
        _ => None,
    };
    // The process image shared with other processes, beside the socket.
    let mut shared = match (&control, t.control_path()) {
        (Some(_), Some(socket)) => {
            let path = socket.with_extension("image");
            let (out_bytes, in_bytes) = m.image().byte_counts();
            let vars = crate::image_cmd::symbols(&mut m, names);
            let mode = o.control.as_ref().map_or(0o660, |c| c.mode);
            let image = ferrocat_service::SharedImage::create(
                &path,
                out_bytes as usize,
                in_bytes as usize,
                &vars,
                if max_rate { 0 } else { cycle_us * 1000 },
                mode,
            )
            .with_context(|| format!("shared image {}", path.display()))?;
            eprintln!("shared image {} ({} variables)", path.display(), vars.len());
            Some(image)
        }
        _ => None,
    };
    let mut app_watchdog = o.control.as_mut().and_then(|c| c.app_watchdog.take());
    let mut machine_in_force = t.machine_file()?.cloned();
    let t_op = { m.cyclic().now_ns() };
    eprintln!("bring-up to OP: {:.1} ms", (t_op - t_start) as f64 / 1e6);
    let period = if max_rate { 0 } else { cycle_us * 1000 };
    m.cyclic().set_period_ns(period);
    m.diagnosis().reset_cycle_stats();
    use ferrocat_master::io::Io;
    // Each frame leaves the shift before SYNC0 (the master-following methods then keep that
    // phase themselves): a frame leaving at a random phase could pass the slaves at their SYNC0,
    // and with a host's jitter reach them in one SYNC0 interval or the next, which a drive's
    // SM-synchronisation supervision takes for missed outputs (0x001A).
    if let Some(grid) = grid_ns.filter(|_| !max_rate) {
        let first = m.clock().next_on_grid_ns(grid, cycle_us * 1000);
        m.cyclic().sleep_until(first);
    }
    let cpu0 = cpu_ns();
    let start = m.cyclic().now_ns();
    let end = if seconds == 0.0 { u64::MAX } else { start + (seconds * 1e9) as u64 };
    let mut next = start;
    let mut report = start + 1_000_000_000;
    // The events are taken as they come (a long run would otherwise keep every one) and
    // counted for the summary.
    let mut tally = SlaveTally::default();
    for e in m.diagnosis().take_events() {
        tally.count(&e);
    }
    let mut next_period = period;
    let mut told_no_room = false;
    // The loop's quality: how late each wake-up came, how far each period strayed from the
    // one planned, and the cycles whose work ran past the next cycle's start.
    let (mut wake_late, mut jitter) = (Histogram::default(), Histogram::default());
    let (mut overruns, mut skipped) = (0u64, 0u64);
    // Where each answered frame passed the reference, after its cycle's start on the DC grid;
    // SYNC0 comes the shift after that start.
    let mut passage = grid_ns.zip(sync0).map(|(grid, plan)| Sync0Passage::new(grid + plan.shift_ns));
    let mut last_wake: Option<u64> = None;
    // Probing waits until the loop's own cost is known, unless its budget was given.
    let probe_budget_us = o.dc.as_ref().and_then(|d| d.probe_budget_us);
    let mut measuring = None;
    if let Some((_, st)) = sync.as_mut() {
        // A virtual segment's host is a model: its CPU is not the loop's, and a budget from it
        // would make the run depend on the machine that simulates it.
        let virtual_host = m.cyclic().io_mut().is_virtual();
        match probe_budget_us {
            Some(us) => st.probing.budget_ns = Some(us * 1000),
            None if !max_rate && !virtual_host => {
                st.probing.off = true;
                measuring = Some(measuring_cycles(cycle_us));
            }
            None => {}
        }
        st.probing.off |= probe_budget_us == Some(0);
    }
    while m.cyclic().now_ns() < end && !stop.load(Ordering::Relaxed) {
        let planned_period = next_period;
        next += next_period;
        // The clients' outputs, whole or not at all, into this cycle's frame.
        if let Some(image) = shared.as_mut() {
            image.apply_outputs(m.cyclic().outputs_mut());
        }
        next_period = match sync.as_mut() {
            Some((method, st)) => {
                let (lost_before, lock_before) = (st.lost, st.lock.state());
                let (_, c) = m.cyclic().cycle_sync(method.as_mut(), st)?;
                if st.lock.state() != lock_before {
                    eprintln!(
                        "t={:7.3} s  clock sync {lock_before} -> {} (offset {} ns; {} frames lost so far)",
                        (m.cyclic().now_ns() - start) as f64 * 1e-9,
                        st.lock.state(),
                        st.lock.offset_ns().unwrap_or(0),
                        st.lost
                    );
                }
                if let (Some(p), Some(at), false) = (passage.as_mut(), st.reference_ns, st.lost > lost_before) {
                    p.add(at, cycle_us * 1000);
                }
                if max_rate {
                    0
                } else {
                    c.next_period_ns.unwrap_or(period)
                }
            }
            None => {
                m.cyclic().cycle()?;
                period
            }
        };
        if let (Some(n), Some((_, st))) = (measuring, sync.as_mut()) {
            if m.diagnosis().cycle_stats().cycles >= n {
                measuring = None;
                let cpu_per_cycle_ns = (cpu_ns() - cpu0) / n;
                st.probing.budget_ns = Some(cpu_per_cycle_ns / 2);
                st.probing.off = false;
                eprintln!(
                    "host: the loop took {:.1} µs of CPU a cycle over its first {n} cycles ({:.1} % of a core at {cycle_us} µs); \
                     wake-ups late by {}; clock-sync probes get {:.1} µs a cycle",
                    cpu_per_cycle_ns as f64 / 1e3,
                    cpu_per_cycle_ns as f64 / (cycle_us * 10) as f64,
                    wake_late.summary(),
                    cpu_per_cycle_ns as f64 / 2e3
                );
            }
        }
        if let Some(image) = shared.as_mut() {
            let (s, now) = (m.diagnosis().cycle_stats(), m.cyclic().now_ns());
            image.publish(m.image().bytes(), s.cycles, now, s.last_wkc as u32, m.image().expected_wkc() as u32);
            if let Some(w) = app_watchdog.as_mut() {
                w.check(&mut m, image.commits(), now);
            }
        }
        for b in bridges.iter_mut() {
            b.step(&mut m)?;
        }
        // Diagnosis in the cycle's spare time, none in its last quarter: error counters, one
        // slave a datagram, every `diagnosis_ms`; emergencies from the mailboxes between.
        if let (Some(ms), false) = (o.diagnosis_ms, max_rate) {
            m.diagnosis().diagnose(next.saturating_sub(next_period / 4), ms * 1_000_000)?;
        }
        // Requests from other processes, in the same spare time (back to back: a millisecond
        // after the cycle, while any wait).
        if let Some(server) = control.as_mut() {
            let deadline =
                if max_rate { m.cyclic().now_ns() + 1_000_000 } else { next.saturating_sub(next_period / 4) };
            let extra = |m: &mut Master<CliIo>| {
                json!({
                    "clock_sync": sync.as_ref().map(|(method, st)| json!({
                        "method": method.name(),
                        "lock": st.lock.state().name(),
                        "offset_ns": st.lock.offset_ns(),
                    })),
                    "diagnosis": diagnosis_json(m, &tally, o.diagnosis_ms),
                })
            };
            server.serve(&mut m, deadline, &extra)?;
            let a = m.acyclic().acyclic_stats();
            if a.starved >= u64::from(ferrocat_master::acyclic::STARVED_CALLS) && !told_no_room {
                told_no_room = true;
                eprintln!(
                    "warning: requests found no room for {} cycles in a row: a round trip of {} µs does not fit \
                     after the cyclic frame in ¾ of the cycle; each now gets one datagram a cycle, until a \
                     sixteenth before the next (a longer --cycle-us leaves them more)",
                    ferrocat_master::acyclic::STARVED_CALLS,
                    m.diagnosis().cycle_stats().last_round_trip_ns / 1000
                );
            }
        }
        let t_s = (m.cyclic().now_ns() - start) as f64 * 1e-9;
        let events = m.diagnosis().take_events();
        for e in &events {
            eprintln!("t={t_s:7.3} s  {e}");
            tally.count(e);
        }
        if let (Some(server), false) = (control.as_mut(), events.is_empty()) {
            server.note_events(&events, t_s);
        }
        // A reload between two cycles: what it changes goes out by requests of the acyclic
        // side, in later cycles' spare time.
        if sighup.swap(false, Ordering::Relaxed) || control.as_ref().is_some_and(|s| s.reload_asked()) {
            let r = crate::reload::reload(t, &mut m, eni, o.copy, &mut machine_in_force);
            match &r {
                Ok(said) => eprintln!("t={t_s:7.3} s  reload: {said}"),
                Err(e) => eprintln!("t={t_s:7.3} s  reload: {e}"),
            }
            if let Some(server) = control.as_mut() {
                server.reloaded(&r);
            }
        }
        if m.cyclic().now_ns() >= report {
            let s = m.diagnosis().cycle_stats();
            let lock = sync.as_ref().map_or(String::new(), |(method, st)| format!("  {}", lock_text(&**method, st)));
            eprintln!(
                "t={:5.1} s  cycles {}  wkc {}/{} ({})  max jitter {:.1} µs  round trip {:.1} µs (max {:.1}){lock}",
                (m.cyclic().now_ns() - start) as f64 * 1e-9,
                s.cycles,
                s.last_wkc,
                m.image().expected_wkc(),
                crate::count(s.wkc_errors as usize, "error", "").trim_end(),
                s.max_jitter_ns as f64 / 1000.0,
                s.last_round_trip_ns as f64 / 1000.0,
                s.max_round_trip_ns as f64 / 1000.0
            );
            // The values asked for with --show, at the report's rate.
            if !shown.is_empty() {
                let values: Vec<String> = shown.iter().map(|(n, h)| format!("{n} = {}", m.image().get(*h))).collect();
                eprintln!("          {}", values.join("; "));
            }
            report += 1_000_000_000;
        }
        if !max_rate {
            let now = m.cyclic().now_ns();
            if now > next {
                overruns += 1;
                // A whole cycle or more behind (a stall): the cycles missed are skipped, on the
                // same grid, rather than run back to back; a cycle that fills its period (DC
                // probes) never caught up, and every cycle after one stall counted late.
                if next_period > 0 && now - next >= next_period {
                    let missed = (now - next) / next_period;
                    next += missed * next_period;
                    skipped += missed;
                }
            }
            m.cyclic().sleep_until(next);
            let woke = m.cyclic().now_ns();
            wake_late.add(woke.saturating_sub(next));
            if let Some(prev) = last_wake {
                jitter.add((woke - prev).abs_diff(planned_period));
            }
            last_wake = Some(woke);
        }
    }
    let cpu = cpu_ns() - cpu0;
    for b in &bridges {
        eprintln!("{}", b.summary(&mut m)?);
    }
    if dc {
        eprintln!("DC monitor (BRD 0x092C, upper bound): {} ns", m.dc().dc_monitor()?);
    }
    let wall = m.cyclic().now_ns() - start;
    let s = m.diagnosis().cycle_stats();
    eprintln!(
        "cyclic rate {:.0} cycles/s; master CPU time {:.2} µs per cycle",
        s.cycles as f64 / (wall as f64 * 1e-9),
        cpu as f64 / 1000.0 / s.cycles.max(1) as f64
    );
    if stop.load(Ordering::Relaxed) {
        eprintln!("stopped by a signal after {:.3} s", wall as f64 * 1e-9);
    }
    let mean_period_us = wall as f64 / 1000.0 / s.cycles.max(1) as f64;
    let cycles = match (max_rate, s.cycles) {
        (true, 1) => String::from("1 cycle back to back"),
        (true, n) => format!("{n} cycles back to back"),
        (false, 1) => format!("1 cycle of {cycle_us} µs"),
        (false, n) => format!("{n} cycles of {cycle_us} µs"),
    };
    // Where the simulator knows the truth: the reference's true time less the method's belief
    // of it now, for a method that keeps one (the reference following the master, or a master
    // clock of its own).
    let true_offset_ns = match (&sync, m.dc().dc_reference()) {
        (Some((method, _)), Some(station)) => {
            let t = m.cyclic().now_ns();
            let own = m.clock().master_system_time_at(t);
            let keeps_clock =
                method.coupling() == Coupling::ReferenceFollowsMaster || method.master_time(own).is_some();
            m.cyclic()
                .io_mut()
                .true_system_time(station, t)
                .filter(|_| keeps_clock)
                .map(|truth| truth.wrapping_sub(method.reference_belief_ns(own)) as i64)
        }
        _ => None,
    };
    // What the control socket and the shared image served (they go now).
    let image_stats = shared.take().map(|i| i.stats());
    let control_json = control.take().map(|server| {
        let a = m.acyclic().acyclic_stats();
        let path = server.path().display().to_string();
        drop(server);
        json!({
            "path": path,
            "requests_answered": a.answered,
            "requests_failed": a.failed,
            "calls_without_room": a.starved,
            "datagrams_in_last_sixteenth": a.relieved,
            "image": image_stats.map(|i| json!({
                "writes_taken": i.writes_taken,
                "cycles_busy": i.busy,
                "writes_dropped_half_done": i.recovered,
            })),
            "app_watchdog_tripped": app_watchdog.as_ref().map(|w| w.tripped()),
        })
    });
    if let Some(c) = &control_json {
        eprintln!(
            "control socket: {} requests answered, {} of them with an error",
            c["requests_answered"], c["requests_failed"]
        );
    }
    let clock_sync = sync.as_ref().map(|(method, st)| {
        serde_json::json!({
            "method": method.name(),
            "lock": st.lock.state().name(),
            "offset_ns": st.lock.offset_ns(),
            "frames_lost": st.lost,
            "true_offset_ns": true_offset_ns,
            "lock_changes": st.lock.changes(),
            "lock_left_out": st.lock.left_out(),
            // The bounds in force (the thresholds, widened by the offsets' noise) and the noise.
            "lock_bounds_ns": st.lock.bounds_ns(),
            "lock_noise_ns": st.lock.noise_ns(),
            "locked_after_s": st.lock.first_locked_cycle().map(|c| c as f64 * cycle_us as f64 * 1e-6),
            "probes": st.probing.sent,
            "probes_lost": st.probing.lost,
            "probes_cut": st.probing.cut,
            "probe_mean_us": st.probing.mean_ns as f64 / 1000.0,
            "probes_unfunded": st.probing.unfunded,
            "probe_budget_us": st.probing.budget_ns.map(|b| b as f64 / 1000.0),
            "sync0_shift_us": sync0.map(|p| p.shift_ns as f64 / 1e3),
            "passage_aimed_us": sync0.map(|p| p.aimed_ns as f64 / 1e3),
            "passage_after_sync0": passage.as_ref().map(|p| p.after_sync0.to_json()),
        })
    });
    if json {
        outln!(
            "{}",
            serde_json::json!({
                "cycles": s.cycles,
                "cycle_us": if max_rate { None } else { Some(cycle_us) },
                "frame_timeout_us": frame_timeout_us,
                "segment_round_trip_us": round_trip_ns as f64 / 1000.0,
                "image_bytes": { "outputs": m.image().byte_counts().0, "inputs": m.image().byte_counts().1 },
                "mean_period_us": mean_period_us,
                "wkc_errors": s.wkc_errors,
                "max_jitter_us": s.max_jitter_ns as f64 / 1000.0,
                "max_round_trip_us": s.max_round_trip_ns as f64 / 1000.0,
                "frames_lost": m.cyclic().frame_stats().lost,
                "overruns": overruns,
                "cycles_skipped": skipped,
                "wake_latency": wake_late.to_json(),
                "period_jitter": jitter.to_json(),
                "clock_sync": clock_sync,
                "slaves": tally.to_json(m.slaves().iter().filter(|s| s.status().state() == ferrocat_wire::register::AlState::Op).count(), m.slaves().len()),
                "values": shown.iter().map(|(n, h)| (n.to_string(), serde_json::json!(m.image().get(*h)))).collect::<serde_json::Map<_, _>>(),
                "diagnosis": diagnosis_json(&mut m, &tally, o.diagnosis_ms),
                "groups": groups_json(&mut m),
                "control": control_json,
            })
        );
    } else {
        outln!(
            "{cycles} (mean period {mean_period_us:.1} µs); {} working-counter errors; max jitter {:.1} µs; max round trip {:.1} µs; frames lost {}",
            s.wkc_errors,
            s.max_jitter_ns as f64 / 1000.0,
            s.max_round_trip_ns as f64 / 1000.0,
            m.cyclic().frame_stats().lost
        );
        if !max_rate {
            outln!(
                "wake-up latency {}; period jitter {}; {} overruns, {} cycles skipped",
                wake_late.summary(),
                jitter.summary(),
                overruns,
                skipped
            );
        }
        if let Some((method, st)) = &sync {
            outln!("clock sync {}", lock_text(&**method, st));
        }
        if let Some(o) = true_offset_ns {
            outln!("true offset at the end (from the virtual segment): {o} ns");
        }
        if let (Some(p), Some(plan)) = (&passage, sync0) {
            let h = &p.after_sync0;
            if let (Some(min), Some(p50), Some(max)) = (h.min_us(), h.quantile_us(0.5), h.max_us()) {
                outln!(
                    "frames passed the reference {min:.0} to {max:.0} µs after a SYNC0 (p50 {p50:.0} µs; aimed at {:.0} µs)",
                    plan.aimed_ns as f64 / 1e3
                );
            }
        }
        for (n, h) in &shown {
            let v = m.image().get(*h);
            outln!("{n} = {v} ({v:#x})");
        }
        let frame_stats = m.diagnosis().plan_frame_stats();
        if let Some(plan) = m.config().plan() {
            for (f, s) in frame_stats.iter().enumerate() {
                let name = plan.frame_names.get(f).cloned().unwrap_or_else(|| format!("frame {f}"));
                let every = match plan.every(f) {
                    1 => String::from("every cycle"),
                    n => format!("every {n} cycles"),
                };
                outln!(
                    "{name} ({every}): {} sent, {} lost, {} with a working counter short of {}",
                    s.sent,
                    s.lost,
                    s.short,
                    s.expected_wkc
                );
            }
        }
        if o.diagnosis_ms.is_some() {
            let d = m.diagnosis().diagnosis_stats();
            outln!(
                "diagnosis: {} error-counter reads, {} mailbox polls ({} given up at the cycle's spare time's end); {} counters grew, {} emergencies, {} SoE notifications and emergencies; {} sync-error flag reads, {} found set",
                d.counter_reads,
                d.mailbox_polls,
                d.given_up,
                d.counters_grown,
                tally.emergencies,
                tally.soe_messages,
                d.sync_flag_reads,
                d.sync_errors
            );
            if d.txpdo_watched > 0 {
                outln!(
                    "TxPDO status: {} entries watched; {} times inputs said invalid (TxPDO State), {} times not refreshed (TxPDO Toggle)",
                    d.txpdo_watched,
                    d.inputs_invalid,
                    d.inputs_stale
                );
            }
        }
    }
    if m.cyclic().io_mut().has_secondary() {
        let ring = match m.diagnosis().ring_state() {
            ferrocat_master::RingState::Intact => "intact",
            ferrocat_master::RingState::Broken => "broken",
            ferrocat_master::RingState::Line => "open (no answer on the secondary port)",
            ferrocat_master::RingState::Unknown => "unknown",
        };
        outln!("ring {ring} at the end; {} frames sent round the far half again", m.cyclic().frame_stats().resent);
        if let Some(f) = m.dc().far_reference() {
            outln!(
                "far reference: {} samples taken, {} left out (their passes took over twice the floor), \
                 its offset moved by {:.1} µs in all",
                f.samples_taken,
                f.samples_left_out,
                f.offset_ns as f64 / 1e3
            );
        }
    }
    // A master that stops takes its slaves down in order (outputs to their safe state, then
    // process data and mailboxes off), as a service stopped by SIGTERM must.
    if !o.keep_state {
        let t0 = m.cyclic().now_ns();
        match m.states().shut_down() {
            Ok(()) => eprintln!(
                "slaves stepped down to SAFEOP, then INIT ({:.1} ms)",
                (m.cyclic().now_ns() - t0) as f64 / 1e6
            ),
            Err(e) => eprintln!("ferrocat: warning: stepping the slaves down to INIT: {e}"),
        }
    }
    finish(m)?;
    Ok(ExitCode::SUCCESS)
}

/// The summary's `groups`: each frame of a plan (a process-data group's, an ENI's), or null.
fn groups_json(m: &mut ferrocat_master::Master<crate::target::CliIo>) -> serde_json::Value {
    let stats = m.diagnosis().plan_frame_stats();
    let Some(plan) = m.config().plan() else { return serde_json::Value::Null };
    stats
        .iter()
        .enumerate()
        .map(|(f, s)| {
            serde_json::json!({
                "name": plan.frame_names.get(f).cloned().unwrap_or_else(|| format!("frame {f}")),
                "every": plan.every(f),
                "sent": s.sent,
                "lost": s.lost,
                "short": s.short,
                "expected_wkc": s.expected_wkc,
                "last_wkc": s.last_wkc,
            })
        })
        .collect()
}

/// The summary's `diagnosis`: what was read, and each slave's error counters that are not 0.
fn diagnosis_json(
    m: &mut ferrocat_master::Master<crate::target::CliIo>,
    tally: &SlaveTally,
    period_ms: Option<u64>,
) -> serde_json::Value {
    let Some(ms) = period_ms else { return serde_json::Value::Null };
    let d = m.diagnosis().diagnosis_stats();
    let sync_error_flags = m.diagnosis().sync_error_flags().to_vec();
    let error_counters = m.diagnosis().error_counters().to_vec();
    let counters: Vec<serde_json::Value> = error_counters
        .iter()
        .enumerate()
        .filter_map(|(k, c)| {
            let c = c.as_ref()?;
            let nonzero: serde_json::Map<String, serde_json::Value> = c
                .each()
                .filter(|(_, _, v)| *v > 0)
                .map(|(kind, port, v)| {
                    (
                        port.map_or(kind.name().to_string(), |p| format!("port {p} {}", kind.name())),
                        serde_json::json!(v),
                    )
                })
                .collect();
            (!nonzero.is_empty())
                .then(|| serde_json::json!({"position": k, "name": m.slaves()[k].name(), "counters": nonzero}))
        })
        .collect();
    serde_json::json!({
        "counters_period_ms": ms,
        "counter_reads": d.counter_reads,
        "mailbox_polls": d.mailbox_polls,
        "given_up": d.given_up,
        "counters_grown": d.counters_grown,
        "emergencies": tally.emergencies,
        "soe_messages": tally.soe_messages,
        "sync_flag_reads": d.sync_flag_reads,
        "sync_errors": d.sync_errors,
        "txpdo_watched": d.txpdo_watched,
        "inputs_invalid": d.inputs_invalid,
        "inputs_stale": d.inputs_stale,
        "sync_error_flags": sync_error_flags
            .iter()
            .enumerate()
            .filter(|(_, f)| f.outputs.is_some() || f.inputs.is_some())
            .map(|(k, f)| serde_json::json!({"position": k, "outputs": f.outputs, "inputs": f.inputs}))
            .collect::<Vec<_>>(),
        "error_counters": counters,
    })
}

/// What happened to the slaves over a run: how often one left OP or stopped answering, how
/// often the master brought one back.
#[derive(Debug, Default)]
struct SlaveTally {
    left_op: u64,
    lost: u64,
    recovered: u64,
    emergencies: u64,
    /// SoE notifications and emergencies.
    soe_messages: u64,
}

impl SlaveTally {
    fn count(&mut self, e: &ferrocat_master::MasterEvent) {
        use ferrocat_master::MasterEvent as E;
        match e {
            E::LeftOp { .. } => self.left_op += 1,
            E::Lost { .. } => self.lost += 1,
            E::Recovered { .. } => self.recovered += 1,
            E::Emergency { .. } => self.emergencies += 1,
            E::Soe { .. } => self.soe_messages += 1,
            _ => {}
        }
    }

    /// With how many of `of` slaves are in OP at the end.
    fn to_json(&self, in_op: usize, of: usize) -> serde_json::Value {
        serde_json::json!({
            "left_op": self.left_op,
            "lost": self.lost,
            "recovered": self.recovered,
            "in_op_at_end": in_op,
            "count": of,
        })
    }
}
