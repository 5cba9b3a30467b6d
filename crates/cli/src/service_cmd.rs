//! The command line beside a running master: finding it (its lock and control socket), the
//! commands that reach it (`slaves`, `reg`, `state`, `stats`, and `sdo`), and the refusal of
//! a second master on its segment.
use std::path::PathBuf;
use std::process::ExitCode;

use anyhow::{bail, Context};
use ferrocat_service::{Client, ClientError, MasterLock};

use crate::outln;
use crate::target::Target;

impl Target {
    /// The name the master on this target is found by: the interface's, `udp-ADDR:PORT`, or
    /// none for the embedded virtual segment.
    pub fn service_name(&self) -> Option<String> {
        match (&self.udp, &self.iface) {
            (Some(a), _) => Some(format!("udp-{a}")),
            (None, Some(i)) if self.config.is_none() && self.device.is_empty() => Some(i.clone()),
            _ => None,
        }
    }

    /// Where `run` serves this target's control socket: --control-socket, or the target's own
    /// in the runtime directory.
    pub fn control_path(&self) -> Option<PathBuf> {
        self.control_socket.clone().or_else(|| self.service_name().map(|n| ferrocat_service::socket_path(&n)))
    }

    /// Where a master running on this target is reached: --control-socket, the runtime
    /// directory's socket, or a service's in the system's directory.
    pub fn running_path(&self) -> Option<PathBuf> {
        self.control_socket.clone().or_else(|| self.service_name().map(|n| ferrocat_service::find_socket(&n)))
    }

    /// The master running on this target, if one answers on its control socket (a socket
    /// given with --control-socket must answer).
    pub fn running_master(&self) -> anyhow::Result<Option<Client>> {
        let Some(path) = self.running_path() else { return Ok(None) };
        match Client::connect(&path) {
            Ok(c) => {
                let h = c.hello();
                eprintln!("through the master running on {} (process {}, {})", h.target, h.pid, path.display());
                Ok(Some(c))
            }
            Err(ClientError::Connect { .. }) if self.control_socket.is_none() => Ok(None),
            Err(e) => Err(e.into()),
        }
    }

    /// Takes the segment for this process: a master running on it is an error that says how
    /// to reach it. A lock that cannot be made (a directory not ours) is warned of.
    pub fn take_segment(&self) -> anyhow::Result<()> {
        let Some(name) = self.service_name() else { return Ok(()) };
        if self.lock.get().is_some() {
            return Ok(());
        }
        match MasterLock::take(&name) {
            Ok(Ok(l)) => {
                let _ = self.lock.set(std::rc::Rc::new(l));
                Ok(())
            }
            Ok(Err(held)) => bail!(
                "a master runs on {name} already ({}; socket {}): `ferrocat slaves`, `sdo`, `reg`, `state` and \
                 `stats` reach it there, and this command needs the segment to itself: stop that master first",
                held.pid.map_or(String::from("its process unknown"), |p| format!("process {p}")),
                ferrocat_service::find_socket(&name).display()
            ),
            Err(e) => {
                tracing::warn!(
                    "no lock for {name} ({}: {e}): a second master on it would not be refused",
                    ferrocat_service::lock_path(&name).display()
                );
                Ok(())
            }
        }
    }

    /// The running master, or an error saying none runs here.
    fn require_master(&self, what: &str) -> anyhow::Result<Client> {
        match self.running_master()? {
            Some(c) => Ok(c),
            None => bail!(
                "{what} needs a running master, and none answers on {} (start one with `ferrocat run`)",
                self.running_path().map_or(String::from("the embedded virtual segment: give --control-socket"), |p| p
                    .display()
                    .to_string())
            ),
        }
    }
}

impl crate::master_cmd::CoeAccess for Client {
    fn upload(&mut self, position: u16, index: u16, sub: u8, complete: bool) -> anyhow::Result<Vec<u8>> {
        Ok(self.sdo_upload(position, index, sub, complete)?)
    }
    fn download(&mut self, position: u16, index: u16, sub: u8, complete: bool, data: &[u8]) -> anyhow::Result<()> {
        Ok(self.sdo_download(position, index, sub, complete, data)?)
    }
    fn entry(&mut self, position: u16, index: u16, sub: u8) -> anyhow::Result<ferrocat_master::EntryInfo> {
        let e = self.entry_info(position, index, sub)?;
        Ok(ferrocat_master::EntryInfo {
            subindex: e.subindex,
            data_type: e.data_type,
            bit_length: e.bit_length,
            access: e.access,
            name: e.name,
        })
    }
    fn objects(&mut self, position: u16) -> anyhow::Result<Vec<u16>> {
        Ok(self.od_list(position)?)
    }
    fn object(&mut self, position: u16, index: u16) -> anyhow::Result<ferrocat_master::ObjectInfo> {
        let o = self.object_info(position, index)?;
        Ok(ferrocat_master::ObjectInfo {
            index: o.index,
            data_type: o.data_type,
            max_subindex: o.max_subindex,
            object_code: o.object_code,
            name: o.name,
        })
    }
}

/// AL status (0x0130) and AL status code (0x0134) as words.
fn al_text(status: &[u8]) -> (String, u16) {
    let s = u16::from_le_bytes([status[0], status[1]]);
    let code = u16::from_le_bytes([status[4], status[5]]);
    let state = ferrocat_master::AlState::from_bits(s as u8).map_or(format!("{:#x}?", s & 0x0F), |st| st.name().into());
    (if s & 0x10 != 0 { format!("{state}+ERR") } else { state }, code)
}

/// `ferrocat slaves`: the running master's slaves with their AL status read now; without a
/// running master, the slaves a scan finds (every one then in INIT).
pub fn slaves(t: &Target, json: bool) -> anyhow::Result<ExitCode> {
    let rows: Vec<serde_json::Value> = match t.running_master()? {
        Some(mut c) => {
            let list = c.slaves()?;
            let mut rows = Vec::new();
            for s in list {
                let (state, code) = match c.register_read(s.position, 0x0130, 6) {
                    Ok(b) => al_text(&b),
                    Err(e) => (format!("? ({e})"), 0),
                };
                rows.push(serde_json::json!({
                    "position": s.position, "station": s.station, "alias": s.alias, "name": s.name,
                    "vendor_id": s.vendor_id, "product_code": s.product_code, "revision": s.revision,
                    "state": state, "al_status_code": code, "kept_in": s.state, "health": s.health,
                }));
            }
            rows
        }
        None => {
            let mut m = t.master()?;
            t.scan(&mut m)?;
            eprintln!("no master runs here: the slaves a scan found (each now in INIT)");
            let rows = m
                .slaves()
                .iter()
                .map(|s| {
                    let id = s.identity();
                    serde_json::json!({
                        "position": s.position(), "station": s.station(), "alias": s.alias(), "name": s.name(),
                        "vendor_id": id.vendor_id, "product_code": id.product_code, "revision": id.revision,
                        "state": s.status().state().name(), "al_status_code": 0, "kept_in": null, "health": null,
                    })
                })
                .collect();
            crate::target::finish(m)?;
            rows
        }
    };
    if json {
        outln!("{}", serde_json::Value::Array(rows));
        return Ok(ExitCode::SUCCESS);
    }
    for r in &rows {
        let code = r["al_status_code"].as_u64().unwrap_or(0);
        outln!(
            "{:>3}  {:#06x}  {:<8} {:<28} vendor {:#010x} product {:#010x} rev {:#010x}{}",
            r["position"],
            r["station"].as_u64().unwrap_or(0),
            r["state"].as_str().unwrap_or("?"),
            r["name"].as_str().unwrap_or("?"),
            r["vendor_id"].as_u64().unwrap_or(0),
            r["product_code"].as_u64().unwrap_or(0),
            r["revision"].as_u64().unwrap_or(0),
            if code != 0 {
                format!("  AL status code {code:#06x} ({})", ferrocat_master::AlStatusCode(code as u16))
            } else {
                String::new()
            }
        );
    }
    Ok(ExitCode::SUCCESS)
}

/// A register's address: decimal or 0x hex, below 0x10000.
pub fn register(s: &str) -> Result<u16, String> {
    let n =
        ferrocat_esi::parse_number(s.trim()).ok_or_else(|| format!("'{s}' is not a register (decimal or 0x hex)"))?;
    u16::try_from(n).map_err(|_| format!("register '{s}' is past 0xFFFF"))
}

/// `ferrocat reg read`: `len` bytes of the slave's registers from `register`, as hex.
pub fn reg_read(t: &Target, position: u16, register: u16, len: u16) -> anyhow::Result<ExitCode> {
    let bytes = match t.running_master()? {
        Some(mut c) => c.register_read(position, register, len)?,
        None => {
            let mut m = t.master()?;
            t.scan(&mut m)?;
            let station = m.slaves().at(position)?.station();
            let mut b = vec![0u8; len as usize];
            let a = ferrocat_master::Address::Device { adp: station, ado: register };
            m.cyclic().expect_datagram(ferrocat_master::Command::FPRD, a, &mut b, 1)?;
            crate::target::finish(m)?;
            b
        }
    };
    outln!("{}", bytes.iter().map(|b| format!("{b:02x}")).collect::<Vec<_>>().join(" "));
    Ok(ExitCode::SUCCESS)
}

/// `ferrocat reg write`: `data` (hex) to the slave's registers from `register`.
pub fn reg_write(t: &Target, position: u16, register: u16, data: &str) -> anyhow::Result<ExitCode> {
    let text: String = data.chars().filter(|c| !c.is_whitespace()).collect();
    let text = text.strip_prefix("0x").unwrap_or(&text);
    let bytes = ferrocat_service::protocol::unhex(text).map_err(|e| anyhow::anyhow!("data {e}"))?;
    if bytes.is_empty() {
        bail!("data '': give the bytes as hex, e.g. 0201");
    }
    match t.running_master()? {
        Some(mut c) => c.register_write(position, register, &bytes)?,
        None => {
            let mut m = t.master()?;
            t.scan(&mut m)?;
            let station = m.slaves().at(position)?.station();
            let a = ferrocat_master::Address::Device { adp: station, ado: register };
            let mut b = bytes.clone();
            m.cyclic().expect_datagram(ferrocat_master::Command::FPWR, a, &mut b, 1)?;
            crate::target::finish(m)?;
        }
    }
    eprintln!("wrote {} byte(s) to {register:#06x} of slave {position}", bytes.len());
    Ok(ExitCode::SUCCESS)
}

/// `ferrocat state`: the slave of the running master to `state`.
pub fn state(t: &Target, position: u16, state: &str) -> anyhow::Result<ExitCode> {
    let mut c = t.require_master("`state`")?;
    let reached = c.request_state(position, state).with_context(|| format!("slave {position} to {state}"))?;
    eprintln!("slave {position} is in {reached}; the master keeps it there");
    Ok(ExitCode::SUCCESS)
}

/// `ferrocat stats`: the running master's statistics.
pub fn stats(t: &Target, json: bool) -> anyhow::Result<ExitCode> {
    let mut c = t.require_master("`stats`")?;
    let s = c.stats()?;
    if json {
        outln!("{}", serde_json::to_value(&s)?);
        return Ok(ExitCode::SUCCESS);
    }
    outln!(
        "cycles {}  wkc {}/{} ({} short)  round trip {:.1} µs  requests {} answered, {} failed",
        s.cycles,
        s.last_wkc,
        s.expected_wkc,
        s.wkc_errors,
        s.last_round_trip_ns as f64 / 1e3,
        s.requests_answered,
        s.requests_failed
    );
    if let Some(cs) = s.extra.get("clock_sync").filter(|v| !v.is_null()) {
        outln!(
            "clock sync {}: {}, offset {} ns",
            cs["method"].as_str().unwrap_or("?"),
            cs["lock"].as_str().unwrap_or("?"),
            cs["offset_ns"]
        );
    }
    if let Some(d) = s.extra.get("diagnosis").filter(|v| !v.is_null()) {
        outln!(
            "diagnosis: {} error-counter reads, {} mailbox polls, {} counters grew, {} emergencies, {} sync-error flags found set",
            d["counter_reads"],
            d["mailbox_polls"],
            d["counters_grown"],
            d["emergencies"],
            d["sync_errors"]
        );
        for c in d["error_counters"].as_array().into_iter().flatten() {
            outln!("  slave {} ({}): {}", c["position"], c["name"].as_str().unwrap_or("?"), c["counters"]);
        }
    }
    Ok(ExitCode::SUCCESS)
}

/// `ferrocat events`: the running master's events (the last 1 024 it keeps), and with
/// `follow` each new one as it comes, until SIGINT or SIGTERM.
pub fn events(t: &Target, follow: bool, json: bool) -> anyhow::Result<ExitCode> {
    let mut c = t.require_master("`events`")?;
    let stop = std::sync::Arc::new(std::sync::atomic::AtomicBool::new(false));
    for sig in [signal_hook::consts::SIGINT, signal_hook::consts::SIGTERM] {
        signal_hook::flag::register(sig, std::sync::Arc::clone(&stop)).context("installing signal handlers")?;
    }
    let mut since = 0;
    loop {
        let batch = c.events(since)?;
        if batch.missed > 0 {
            eprintln!("({} events the master no longer keeps)", batch.missed);
        }
        for e in &batch.events {
            if json {
                outln!("{}", serde_json::to_value(e)?);
            } else {
                outln!("t={:9.3} s  {}", e.at_s, e.text);
            }
        }
        since = batch.next;
        if stop.load(std::sync::atomic::Ordering::Relaxed) {
            return Ok(ExitCode::SUCCESS);
        }
        // A reply carries as many as fit its line: ask again at once while they come.
        if batch.events.is_empty() {
            if !follow {
                return Ok(ExitCode::SUCCESS);
            }
            std::thread::sleep(std::time::Duration::from_millis(100));
        }
    }
}

/// `ferrocat pdos`: the process data a slave maps, as the running master (or a scan and
/// configuration of this command's own) has it.
pub fn pdos(t: &Target, position: u16, json: bool) -> anyhow::Result<ExitCode> {
    let p = match t.running_master()? {
        Some(mut c) => c.pdos(position)?,
        None => {
            let mut m = t.master()?;
            t.scan(&mut m)?;
            t.configure(&mut m)?;
            let p = ferrocat_service::pdos_of(m.slaves().at(position)?);
            crate::target::finish(m)?;
            p
        }
    };
    if json {
        outln!("{}", serde_json::to_value(&p)?);
        return Ok(ExitCode::SUCCESS);
    }
    for (title, list) in [("outputs", &p.outputs), ("inputs", &p.inputs)] {
        outln!("{title}:");
        for e in list {
            outln!(
                "  {:#06x}:{:#04x}  {:>2} bit{}  image bit {:>6}  {}",
                e.index,
                e.subindex,
                e.bits,
                if e.bits == 1 { " " } else { "s" },
                e.image_bit,
                e.name
            );
        }
    }
    Ok(ExitCode::SUCCESS)
}

/// `ferrocat reload`: the running master reads its machine description again.
pub fn reload(t: &Target) -> anyhow::Result<ExitCode> {
    let mut c = t.require_master("`reload`")?;
    let said = c.reload()?;
    eprintln!("{said}");
    Ok(ExitCode::SUCCESS)
}

/// `ferrocat master-od`: the running master's own object dictionary, an entry a line (text
/// values where the type is a string, numbers in decimal and hex, octet strings in hex).
pub fn master_od(t: &Target, json: bool) -> anyhow::Result<ExitCode> {
    let mut c = t.require_master("`master-od`")?;
    for o in c.master_od()? {
        if json {
            outln!("{o}");
            continue;
        }
        let index = o["index"].as_u64().unwrap_or(0);
        outln!("{index:#06x}  {}", o["name"].as_str().unwrap_or(""));
        for e in o["entries"].as_array().map(Vec::as_slice).unwrap_or(&[]) {
            let bytes = ferrocat_service::protocol::unhex(e["value"].as_str().unwrap_or("")).unwrap_or_default();
            let value = match e["data_type"].as_u64() {
                Some(0x0009) => format!("\"{}\"", String::from_utf8_lossy(&bytes).trim_end_matches('\0')),
                Some(0x000A) => ferrocat_service::protocol::hex(&bytes),
                _ if bytes.len() <= 8 => {
                    let mut w = [0u8; 8];
                    w[..bytes.len()].copy_from_slice(&bytes);
                    let v = u64::from_le_bytes(w);
                    format!("{v} ({v:#x})")
                }
                _ => ferrocat_service::protocol::hex(&bytes),
            };
            outln!(
                "  {index:#06x}:{:02}  {:<40} {value}",
                e["subindex"].as_u64().unwrap_or(0),
                e["name"].as_str().unwrap_or("")
            );
        }
    }
    Ok(ExitCode::SUCCESS)
}
