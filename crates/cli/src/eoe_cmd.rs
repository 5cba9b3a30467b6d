//! `ferrocat eoe`: a slave's IP parameters by EoE, and ping over EoE.
use std::net::Ipv4Addr;
use std::process::ExitCode;

use anyhow::{bail, Context};
use clap::{Args, Subcommand};
use ferrocat_master::EoePing;
use ferrocat_wire::eoe::IpParameters;
use serde_json::json;

use crate::outln;
use crate::target::{finish, Target};

#[derive(Subcommand)]
pub enum EoeCmd {
    /// Set the IP parameters of the slave at POSITION (those given; it keeps the others).
    SetIp {
        /// The slave's position on the segment, counted from 0 (as `scan` shows it).
        #[arg(allow_negative_numbers = true, value_parser = crate::args::position)]
        position: u16,
        #[command(flatten)]
        params: ParamArgs,
        #[command(flatten)]
        target: Target,
    },
    /// Print the IP parameters the slave at POSITION reports.
    GetIp {
        /// The slave's position on the segment, counted from 0 (as `scan` shows it).
        #[arg(allow_negative_numbers = true, value_parser = crate::args::position)]
        position: u16,
        /// Print JSON instead of text.
        #[arg(long)]
        json: bool,
        #[command(flatten)]
        target: Target,
    },
    /// Ping the slave at POSITION over EoE (ICMP echo), after setting the parameters given.
    Ping {
        /// The slave's position on the segment, counted from 0 (as `scan` shows it).
        #[arg(allow_negative_numbers = true, value_parser = crate::args::position)]
        position: u16,
        #[command(flatten)]
        params: ParamArgs,
        /// Echo requests to send (at least 1).
        #[arg(long, default_value_t = 4, value_parser = clap::value_parser!(u16).range(1..))]
        count: u16,
        /// Data bytes per request (1 472 fill a 1 514-byte frame).
        #[arg(long, default_value_t = 56)]
        size: usize,
        /// Wait for each reply at most this long.
        #[arg(long, default_value_t = 1000)]
        timeout_ms: u64,
        /// The master's address on the EoE network (default: the slave's gateway, else the first
        /// other host address of the slave's subnet, by its netmask or /24 without one).
        #[arg(long)]
        from: Option<Ipv4Addr>,
        /// The master's MAC address on the EoE network.
        #[arg(long, default_value = "02:00:00:00:00:01")]
        from_mac: String,
        #[command(flatten)]
        target: Target,
    },
    /// Bridge the slave at POSITION to a TAP interface of this host (as IgH's EoE devices do):
    /// what the host sends out of it goes to the slave by EoE, and back. Runs until SIGINT or
    /// SIGTERM, or for --seconds; the segment stays in PREOP.
    Bridge {
        /// The slave's position on the segment, counted from 0 (as `scan` shows it).
        #[arg(allow_negative_numbers = true, value_parser = crate::args::position)]
        position: u16,
        /// The TAP interface to create (give it an address and bring it up with `ip`).
        #[arg(long)]
        tap: String,
        #[command(flatten)]
        params: ParamArgs,
        /// How long to bridge (s; default: until SIGINT or SIGTERM).
        #[arg(long)]
        seconds: Option<f64>,
        #[command(flatten)]
        target: Target,
    },
}

#[derive(Args)]
pub struct ParamArgs {
    /// The slave's IP address.
    #[arg(long)]
    ip: Option<Ipv4Addr>,
    /// Its MAC address (aa:bb:cc:dd:ee:ff; default with --ip: 02:00:00:00 and its station
    /// address, locally administered and one per slave).
    #[arg(long)]
    mac: Option<String>,
    /// The subnet mask to set.
    #[arg(long)]
    netmask: Option<Ipv4Addr>,
    /// The default gateway to set.
    #[arg(long)]
    gateway: Option<Ipv4Addr>,
    /// The DNS server to set.
    #[arg(long)]
    dns: Option<Ipv4Addr>,
    /// Its DNS name (32 bytes at most).
    #[arg(long)]
    name: Option<String>,
}

impl ParamArgs {
    fn given(&self) -> bool {
        self.ip.is_some()
            || self.mac.is_some()
            || self.netmask.is_some()
            || self.gateway.is_some()
            || self.dns.is_some()
            || self.name.is_some()
    }

    fn to_params(&self, station: u16) -> anyhow::Result<IpParameters> {
        let mac = match &self.mac {
            Some(m) => Some(parse_mac(m).with_context(|| format!("--mac '{m}'"))?),
            None => self.ip.map(|_| {
                let [hi, lo] = station.to_be_bytes();
                [0x02, 0, 0, 0, hi, lo]
            }),
        };
        let name = match &self.name {
            Some(n) => Some(
                IpParameters::dns_name_field(n.as_bytes())
                    .map_err(|_| anyhow::anyhow!("--name '{n}' is longer than 32 bytes"))?,
            ),
            None => None,
        };
        Ok(IpParameters {
            mac,
            ip: self.ip.map(|a| a.octets()),
            subnet_mask: self.netmask.map(|a| a.octets()),
            gateway: self.gateway.map(|a| a.octets()),
            dns_server: self.dns.map(|a| a.octets()),
            dns_name: name,
        })
    }
}

/// Six hex bytes separated by ':' or '-'.
fn parse_mac(s: &str) -> anyhow::Result<[u8; 6]> {
    let parts: Vec<&str> = s.split([':', '-']).collect();
    if parts.len() != 6 {
        bail!("a MAC address is six hex bytes separated by ':' (found {} parts)", parts.len());
    }
    let mut mac = [0u8; 6];
    for (b, p) in mac.iter_mut().zip(&parts) {
        *b = u8::from_str_radix(p, 16).with_context(|| format!("'{p}' is not a hex byte"))?;
    }
    Ok(mac)
}

fn mac_text(m: [u8; 6]) -> String {
    m.iter().map(|b| format!("{b:02x}")).collect::<Vec<_>>().join(":")
}

fn show(p: &IpParameters, json: bool) {
    let ip = |a: Option<[u8; 4]>| a.map(|a| Ipv4Addr::from(a).to_string());
    let name = p.dns_name_bytes().map(|n| String::from_utf8_lossy(n).into_owned());
    if json {
        outln!(
            "{}",
            json!({"mac": p.mac.map(mac_text), "ip": ip(p.ip), "netmask": ip(p.subnet_mask), "gateway": ip(p.gateway),
                   "dns": ip(p.dns_server), "name": name})
        );
        return;
    }
    let or_unset = |v: Option<String>| v.unwrap_or_else(|| "(not set)".into());
    outln!("MAC      {}", or_unset(p.mac.map(mac_text)));
    outln!("IP       {}", or_unset(ip(p.ip)));
    outln!("netmask  {}", or_unset(ip(p.subnet_mask)));
    outln!("gateway  {}", or_unset(ip(p.gateway)));
    outln!("DNS      {}", or_unset(ip(p.dns_server)));
    outln!("name     {}", or_unset(name));
}

pub fn run(cmd: EoeCmd) -> anyhow::Result<ExitCode> {
    match cmd {
        EoeCmd::SetIp { position, params, target } => {
            if !params.given() {
                bail!("eoe set-ip: give at least one of --ip, --mac, --netmask, --gateway, --dns, --name");
            }
            let mut m = preop_with(&target, position, &params)?;
            eprintln!("set the IP parameters of slave {position}");
            show(&m.acyclic().eoe().get_ip(position)?, false);
            finish(m)?;
        }
        EoeCmd::GetIp { position, json, target } => {
            let mut m = target.master()?;
            target.scan(&mut m)?;
            m.states().configure()?;
            show(&m.acyclic().eoe().get_ip(position)?, json);
            finish(m)?;
        }
        EoeCmd::Ping { position, params, count, size, timeout_ms, from, from_mac, target } => {
            let from_mac = parse_mac(&from_mac).with_context(|| format!("--from-mac '{from_mac}'"))?;
            if size > 1472 {
                bail!("--size {size}: at most 1 472 bytes fit one Ethernet frame");
            }
            let mut m = preop_with(&target, position, &params)?;
            let p = m.acyclic().eoe().get_ip(position)?;
            let (Some(to_mac), Some(to_ip)) = (p.mac, p.ip) else {
                bail!("slave {position} has no MAC or IP address: give --ip (and --mac)");
            };
            let from_ip = match (from, p.gateway) {
                (Some(f), _) => f.octets(),
                (None, Some(g)) if g != [0; 4] => g,
                _ => neighbour(to_ip, p.subnet_mask).with_context(|| {
                    format!(
                        "slave {position}'s subnet ({}) has no other host address: give --from",
                        Ipv4Addr::from(to_ip)
                    )
                })?,
            };
            let ping = EoePing { from_mac, from_ip, to_mac, to_ip };
            let to = Ipv4Addr::from(to_ip);
            outln!("PING {to} over EoE (slave {position}) from {}: {size} data bytes", Ipv4Addr::from(from_ip));
            let mut rtts = Vec::new();
            for seq in 0..count {
                match m.acyclic().eoe().ping(position, &ping, seq, size, timeout_ms.saturating_mul(1_000_000))? {
                    Some(ns) => {
                        outln!("{} bytes from {to}: seq={seq} time={:.3} ms", size + 8, ns as f64 / 1e6);
                        rtts.push(ns);
                    }
                    None => outln!("no reply from {to}: seq={seq} (within {timeout_ms} ms)"),
                }
            }
            rtts.sort_unstable();
            let lost = count as usize - rtts.len();
            outln!("{count} sent, {} received, {lost} lost", rtts.len());
            if let (Some(min), Some(max)) = (rtts.first(), rtts.last()) {
                let median = rtts[rtts.len() / 2];
                outln!(
                    "round trip min/median/max = {:.3}/{:.3}/{:.3} ms",
                    *min as f64 / 1e6,
                    median as f64 / 1e6,
                    *max as f64 / 1e6
                );
            }
            finish(m)?;
            if lost > 0 {
                return Ok(ExitCode::FAILURE);
            }
        }
        EoeCmd::Bridge { position, tap, params, seconds, target } => {
            return bridge(position, &tap, &params, seconds, target)
        }
    }
    Ok(ExitCode::SUCCESS)
}

/// An address for the master on the slave's subnet: its first host address other than the
/// slave's (a /24 where the slave reports no netmask).
fn neighbour(ip: [u8; 4], netmask: Option<[u8; 4]>) -> Option<[u8; 4]> {
    let mask = match netmask.map(u32::from_be_bytes) {
        Some(m) if m != 0 => m,
        _ => 0xFFFF_FF00,
    };
    let ip = u32::from_be_bytes(ip);
    let net = ip & mask;
    let broadcast = net | !mask;
    (net + 1..broadcast).find(|&a| a != ip).map(u32::to_be_bytes)
}

/// The segment in PREOP, the slave's IP parameters set where any were given.
fn preop_with(
    target: &Target,
    position: u16,
    params: &ParamArgs,
) -> anyhow::Result<ferrocat_master::Master<crate::target::CliIo>> {
    let mut m = target.master()?;
    target.scan(&mut m)?;
    m.states().configure()?;
    if params.given() {
        let p = params.to_params(m.slaves().at(position)?.station())?;
        m.acyclic().eoe().set_ip(position, &p)?;
    }
    Ok(m)
}

/// Frames between the TAP interface and the slave until stopped, in PREOP: the bridge's
/// steps back to back while anything moves, a short sleep when nothing did.
fn bridge(
    position: u16,
    tap: &str,
    params: &ParamArgs,
    seconds: Option<f64>,
    target: Target,
) -> anyhow::Result<ExitCode> {
    use std::sync::atomic::{AtomicBool, Ordering};
    use std::sync::Arc;
    if let Some(s) = seconds {
        if !(s > 0.0 && s < 1e7) {
            bail!("--seconds {s}: give a positive number of seconds");
        }
    }
    let stop = Arc::new(AtomicBool::new(false));
    for sig in [signal_hook::consts::SIGINT, signal_hook::consts::SIGTERM] {
        signal_hook::flag::register(sig, Arc::clone(&stop)).context("installing signal handlers")?;
    }
    let mut m = preop_with(&target, position, params)?;
    let mut b = TapBridge::open(position, tap)?;
    eprintln!("bridging slave {position} to {tap} (EoE)");
    let t0 = std::time::Instant::now();
    while !stop.load(Ordering::Relaxed) && seconds.is_none_or(|s| t0.elapsed().as_secs_f64() < s) {
        if !b.step(&mut m)? {
            std::thread::sleep(std::time::Duration::from_micros(200));
        }
    }
    eprintln!("bridge stopped: {}", b.summary(&mut m)?);
    finish(m)?;
    Ok(ExitCode::SUCCESS)
}

/// A slave bridged to a TAP interface by EoE: each step queues the host's frames and runs
/// one step of the pump (a fragment written, the mailbox read once) — after each cycle in
/// `run`, back to back in `eoe bridge`.
pub struct TapBridge {
    position: u16,
    tap: ferrocat_link::Tap,
    buf: Vec<u8>,
    to_slave: u64,
    to_host: u64,
    host_down: u64,
    refused: u64,
    unanswered: u64,
}

impl TapBridge {
    /// Creates the TAP interface `name` for the slave at `position`.
    pub fn open(position: u16, name: &str) -> anyhow::Result<Self> {
        let tap = ferrocat_link::Tap::open(name)
            .with_context(|| format!("creating TAP interface '{name}' (needs CAP_NET_ADMIN)"))?;
        Ok(TapBridge {
            position,
            tap,
            buf: vec![0u8; 65536],
            to_slave: 0,
            to_host: 0,
            host_down: 0,
            refused: 0,
            unanswered: 0,
        })
    }

    /// One step; whether anything moved or is still on its way.
    pub fn step(&mut self, m: &mut ferrocat_master::Master<crate::target::CliIo>) -> anyhow::Result<bool> {
        let mut moved = false;
        while let Some(n) = self.tap.try_read(&mut self.buf)? {
            moved = true;
            // A frame with no EoE form, or one more than the queue holds, is dropped.
            match m.acyclic().eoe().queue(self.position, &self.buf[..n]) {
                Ok(true) => self.to_slave += 1,
                Ok(false) | Err(_) => self.refused += 1,
            }
        }
        // A mailbox datagram that went unanswered through its retries (a stalled host, a lost
        // frame) is tried again at the next step: the cyclic run goes on.
        let pumped = match m.acyclic().eoe().pump(self.position) {
            Err(ferrocat_master::MasterError::Timeout { .. }) => {
                self.unanswered += 1;
                None
            }
            r => r?,
        };
        if let Some(f) = pumped {
            moved = true;
            if self.tap.write(&f).with_context(|| format!("writing to {}", self.tap.name()))? {
                self.to_host += 1;
            } else {
                self.host_down += 1;
            }
        }
        let sending = m.acyclic().eoe().link(self.position)?.sending();
        Ok(moved || sending)
    }

    pub fn summary(&self, m: &mut ferrocat_master::Master<crate::target::CliIo>) -> anyhow::Result<String> {
        let link = m.acyclic().eoe().link(self.position)?.clone();
        Ok(format!(
            "EoE bridge of slave {} to {}: {} frames to the slave ({} refused), {} to the host ({} while it was down), {} dropped, {} fragments that did not fit, {} mailbox datagrams unanswered (tried again)",
            self.position,
            self.tap.name(),
            self.to_slave,
            self.refused,
            self.to_host,
            self.host_down,
            link.dropped,
            link.fragment_errors,
            self.unanswered
        ))
    }
}

#[cfg(test)]
mod tests {
    #[test]
    fn the_master_takes_the_first_other_host_of_the_slaves_subnet() {
        use super::neighbour;
        assert_eq!(neighbour([192, 168, 9, 20], Some([255, 255, 255, 0])), Some([192, 168, 9, 1]));
        assert_eq!(neighbour([192, 168, 9, 1], None), Some([192, 168, 9, 2]));
        assert_eq!(neighbour([10, 0, 0, 5], Some([255, 255, 255, 252])), Some([10, 0, 0, 6]));
        // A /31 or /32 has no other host address.
        assert_eq!(neighbour([10, 0, 0, 5], Some([255, 255, 255, 255])), None);
    }
}
