//! The link's failures in the user's words, the same for every subcommand: what did not
//! answer, where, and what to check. A subcommand's first exchange with the segment is its
//! scan, so `Target::scan` puts its errors through [`first_contact`]; opening an interface
//! goes through [`opening`].
use ferrocat_master::MasterError;

/// Where the frames went, as the user named it.
#[derive(Debug, Clone, Copy)]
pub enum Place<'a> {
    Iface(&'a str),
    Udp(&'a str),
    Virtual,
}

impl std::fmt::Display for Place<'_> {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        match self {
            Place::Iface(i) => write!(f, "{i}"),
            Place::Udp(a) => write!(f, "{a} (UDP)"),
            Place::Virtual => write!(f, "the embedded virtual segment"),
        }
    }
}

/// An error met on the first frames sent to `place`, reworded where its cause is one a user
/// meets first: nothing answered, the interface is down, nothing listens at the UDP address.
/// Other errors are returned as they are.
pub fn first_contact(place: Place<'_>, e: anyhow::Error) -> anyhow::Error {
    let reason = format!("{e:#}");
    use std::io::ErrorKind;
    for cause in e.chain() {
        let io = match cause.downcast_ref::<MasterError>() {
            Some(MasterError::Timeout { .. }) => {
                return anyhow::anyhow!(
                    "no slave answered on {place}: is the segment connected to it and powered? ({reason})"
                );
            }
            Some(MasterError::Io(io)) => Some(io),
            _ => cause.downcast_ref::<std::io::Error>(),
        };
        let down =
            |io: &std::io::Error| io.kind() == ErrorKind::NetworkDown || io.raw_os_error() == Some(libc::ENETDOWN);
        match (io, place) {
            (Some(io), Place::Iface(i)) if down(io) => {
                return anyhow::anyhow!("{i} is down: bring it up (ip link set {i} up) and try again ({reason})");
            }
            (Some(io), Place::Udp(a)) if io.kind() == ErrorKind::ConnectionRefused => {
                return anyhow::anyhow!(
                    "nothing listens at {a} (UDP; connection refused): is the simulator or gateway running there? ({reason})"
                );
            }
            _ => {}
        }
    }
    e
}

/// An error met opening the interface `iface`, reworded where the process lacks the right to
/// raw frames (EPERM, EACCES); other errors are returned as they are.
pub fn opening(iface: &str, e: anyhow::Error) -> anyhow::Error {
    let denied = e.chain().filter_map(|c| c.downcast_ref::<std::io::Error>()).any(|io| {
        io.kind() == std::io::ErrorKind::PermissionDenied
            || matches!(io.raw_os_error(), Some(libc::EPERM | libc::EACCES))
    });
    if denied {
        return anyhow::anyhow!(
            "no permission to send raw frames on {iface}: run as root, or give the binary CAP_NET_RAW \
             (sudo setcap cap_net_raw,cap_sys_nice,cap_ipc_lock+ep \"$(command -v ferrocat)\"; docs/cli.md) ({e:#})"
        );
    }
    e
}
