//! What the master reports to the application during operation.
use crate::error::code_text;
use ferrocat_wire::register::{AlStatus, AlStatusCode};

/// Something that happened to a slave during operation, reported once.
#[derive(Debug, Clone, PartialEq, Eq)]
pub enum MasterEvent {
    /// The slave left OP (its AL status and code).
    LeftOp {
        /// Position on the segment.
        position: u16,
        /// Name from the SII.
        name: String,
        /// AL status read.
        status: AlStatus,
        /// AL status code read.
        code: AlStatusCode,
    },
    /// The slave stopped answering (link lost or powered off).
    Lost {
        /// Position on the segment.
        position: u16,
        /// Name from the SII.
        name: String,
    },
    /// The slave is back in OP.
    Recovered {
        /// Position on the segment.
        position: u16,
        /// Name from the SII.
        name: String,
    },
    /// A CoE emergency.
    Emergency {
        /// Position on the segment.
        position: u16,
        /// Name from the SII.
        name: String,
        /// The emergency error code.
        error_code: u16,
        /// The error register (0x1001).
        error_register: u8,
        /// The manufacturer-specific bytes.
        data: [u8; 5],
    },
    /// An SoE drive's own message (ETG.1000.6 §5.8): a notification that an IDN's element
    /// changed, or an emergency (its diagnosis).
    Soe {
        /// Position on the segment.
        position: u16,
        /// Name from the SII.
        name: String,
        /// The drive (axis) of the device.
        drive: u8,
        /// An emergency, else a notification.
        emergency: bool,
        /// The IDN the message names.
        idn: ferrocat_wire::soe::Idn,
        /// What it carries.
        data: Vec<u8>,
    },
    /// A mapped TxPDO State entry was found set: the slave says those inputs are invalid.
    InputsInvalid {
        /// Position on the segment.
        position: u16,
        /// Name from the SII.
        name: String,
        /// The entry's name and object (`Status__TxPDO State (0x6000:0x0f)`).
        entry: String,
    },
    /// A mapped TxPDO Toggle entry stood still for `Settings::txpdo_stale_ns`: the slave did
    /// not refresh those inputs.
    InputsStale {
        /// Position on the segment.
        position: u16,
        /// Name from the SII.
        name: String,
        /// The entry's name and object (`Status__TxPDO Toggle (0x6000:0x10)`).
        entry: String,
        /// How long it had not changed, ns.
        unchanged_ns: u64,
    },
    /// A synchronised slave's sync-error flag (0x1C32:20 for its outputs, 0x1C33:20 for its
    /// inputs, ETG.1020) was found set: it missed SM events past its limit (0x10F1:02).
    SyncError {
        /// Position on the segment.
        position: u16,
        /// Name from the SII.
        name: String,
        /// The SM parameter object whose flag was set: 0x1C32 or 0x1C33.
        index: u16,
    },
    /// One of the slave's error counters (0x0300–0x0313) grew since diagnosis last read it.
    ErrorCounters {
        /// Position on the segment.
        position: u16,
        /// Name from the SII.
        name: String,
        /// Which counter.
        kind: ferrocat_wire::register::ErrorCounterKind,
        /// Its port, for a port's counter.
        port: Option<u8>,
        /// By how much.
        grown: u8,
        /// Its value now (it stops at 255).
        total: u8,
    },
    /// An init command of the slave's ESI description was not sent: the slave has no such
    /// object or subindex (abort 0x06020000 or 0x06090011). A vendor's file describes a family
    /// and its revisions; the command has nothing to act on in this one.
    InitCommandSkipped {
        /// Position on the segment.
        position: u16,
        /// Name from the SII.
        name: String,
        /// The transition it was for ("PS", …).
        transition: String,
        /// The object.
        index: u16,
        /// The subindex.
        subindex: u8,
        /// Its comment in the file.
        comment: String,
        /// Its line in the file.
        line: u32,
        /// What the slave answered.
        code: ferrocat_wire::coe::AbortCode,
    },
    /// An SoE init command of the slave's ESI description was not sent: the drive has no such
    /// IDN (SoE error 0x1001), as [`MasterEvent::InitCommandSkipped`] for CoE.
    SoeInitCommandSkipped {
        /// Position on the segment.
        position: u16,
        /// Name from the SII.
        name: String,
        /// The transition it was for ("PS", …).
        transition: String,
        /// The drive (axis) of the device.
        drive: u8,
        /// The IDN.
        idn: ferrocat_wire::soe::Idn,
        /// Its comment in the file.
        comment: String,
        /// Its line in the file.
        line: u32,
        /// What the drive answered.
        error: ferrocat_wire::soe::SoeError,
    },
    /// Init commands of the slave's ESI description were not sent: they are for a mailbox
    /// protocol the slave's SII does not name (a family's file for a revision without it).
    InitCommandsNotSent {
        /// Position on the segment.
        position: u16,
        /// Name from the SII.
        name: String,
        /// The transition they were for ("PS", …).
        transition: String,
        /// Their protocol (CoE or SoE).
        protocol: ferrocat_wire::mailbox::MailboxType,
        /// How many.
        count: usize,
    },
    /// Cable redundancy: the ring broke, closed again, or lost its secondary side.
    Ring {
        /// The ring's state now.
        state: crate::engine::RingState,
    },
}

impl std::fmt::Display for MasterEvent {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        match self {
            MasterEvent::LeftOp { position, name, status, code } => {
                let st = status.state().map(|s| s.name()).unwrap_or("?");
                write!(
                    f,
                    "slave {position} ({name}) left OP: now {st}{}{}",
                    if status.error() { " with an error" } else { "" },
                    code_text(*code)
                )
            }
            MasterEvent::Lost { position, name } => write!(f, "slave {position} ({name}) is not answering"),
            MasterEvent::Recovered { position, name } => write!(f, "slave {position} ({name}) is back in OP"),
            MasterEvent::Emergency { position, name, error_code, error_register, data } => {
                write!(
                    f,
                    "slave {position} ({name}): emergency {error_code:#06x} ({}), error register {error_register:#04x}, data {data:02x?}",
                    ferrocat_wire::coe::emergency_text(*error_code)
                )
            }
            MasterEvent::Soe { position, name, drive, emergency, idn, data } => {
                let text = String::from_utf8_lossy(data);
                let shown = if !data.is_empty() && text.chars().all(|c| !c.is_control()) {
                    format!("\"{text}\"")
                } else {
                    format!("{data:02x?}")
                };
                let what = if *emergency { "emergency" } else { "notification" };
                write!(f, "slave {position} ({name}) drive {drive}: SoE {what} for {idn}: {shown}")
            }
            MasterEvent::InitCommandSkipped { position, name, transition, index, subindex, comment, line, code } => {
                write!(
                    f,
                    "slave {position} ({name}): ESI init command {transition} {index:#06x}:{subindex:02x} (\"{comment}\", line {line}) not sent: {code}"
                )
            }
            MasterEvent::SoeInitCommandSkipped { position, name, transition, drive, idn, comment, line, error } => {
                write!(
                    f,
                    "slave {position} ({name}): ESI SoE init command {transition} {idn} drive {drive} (\"{comment}\", line {line}) not sent: {error}"
                )
            }
            MasterEvent::InitCommandsNotSent { position, name, transition, protocol, count } => {
                let p = protocol.name();
                write!(f, "slave {position} ({name}): {count} ESI {p} init command(s) for {transition} not sent: its mailbox has no {p}")
            }
            MasterEvent::InputsInvalid { position, name, entry } => {
                write!(f, "slave {position} ({name}): {entry} set: the slave says those inputs are invalid")
            }
            MasterEvent::InputsStale { position, name, entry, unchanged_ns } => write!(
                f,
                "slave {position} ({name}): {entry} unchanged for {} ms: those inputs are not refreshed",
                unchanged_ns / 1_000_000
            ),
            MasterEvent::SyncError { position, name, index } => write!(
                f,
                "slave {position} ({name}): sync error ({index:#06X}:0x20 set, its {}): it missed SM events past its limit (0x10F1:0x02)",
                if *index == 0x1C33 { "inputs" } else { "outputs" }
            ),
            MasterEvent::ErrorCounters { position, name, kind, port, grown, total } => {
                let port = port.map_or(String::new(), |p| format!("port {p} "));
                write!(f, "slave {position} ({name}): {port}{} +{grown} (now {total})", kind.name())
            }
            MasterEvent::Ring { state } => f.write_str(match state {
                crate::engine::RingState::Broken => {
                    "ring broken: the slaves behind the break are served from the secondary port"
                }
                crate::engine::RingState::Intact => "ring closed again",
                crate::engine::RingState::Line => "ring open: nothing answers on the secondary port",
                crate::engine::RingState::Unknown => "ring state unknown",
            }),
        }
    }
}
