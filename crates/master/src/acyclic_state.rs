//! What the acyclic side of a running master keeps between cycles, and what it is asked (the
//! master holds it; `acyclic` works on it).
use std::collections::VecDeque;

use ferrocat_wire::register::AlState;

use crate::coe::{EntryInfo, ObjectInfo};
use crate::error::Result;
use crate::foe_transfer::FoeTransfer;
use crate::sdo_transfer::{InfoTransfer, SdoTransfer};

/// The most requests that wait at once, the one being served included.
pub const QUEUE_LIMIT: usize = 64;
/// The longest register read or write (a datagram of its own in a frame of its own).
pub const REGISTER_MAX: usize = 1024;

/// A request's number, given by [`Acyclic::submit`](crate::part::Acyclic::submit), under which its answer comes.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash, PartialOrd, Ord)]
pub struct RequestId(pub u64);

/// What a running master is asked to do beside its cycle.
#[derive(Debug, Clone, PartialEq, Eq)]
pub enum Request {
    /// SDO upload of `index:subindex` (the whole object with `complete_access`).
    SdoRead {
        /// The slave's position, from 0.
        position: u16,
        /// The object.
        index: u16,
        /// The entry.
        subindex: u8,
        /// The whole object from `subindex` on.
        complete_access: bool,
    },
    /// SDO download of `data` to `index:subindex`.
    SdoWrite {
        /// The slave's position, from 0.
        position: u16,
        /// The object.
        index: u16,
        /// The entry.
        subindex: u8,
        /// The whole object from `subindex` on.
        complete_access: bool,
        /// The value, as it goes on the wire.
        data: Vec<u8>,
    },
    /// SDO information: every object's index.
    OdList {
        /// The slave's position, from 0.
        position: u16,
    },
    /// SDO information: an object's description.
    ObjectInfo {
        /// The slave's position, from 0.
        position: u16,
        /// The object.
        index: u16,
    },
    /// SDO information: an entry's description.
    EntryInfo {
        /// The slave's position, from 0.
        position: u16,
        /// The object.
        index: u16,
        /// The entry.
        subindex: u8,
    },
    /// `len` bytes of the ESC's registers from `register` (FPRD).
    RegisterRead {
        /// The slave's position, from 0.
        position: u16,
        /// The first register.
        register: u16,
        /// Bytes, 1 to [`REGISTER_MAX`].
        len: u16,
    },
    /// `data` to the ESC's registers from `register` (FPWR).
    RegisterWrite {
        /// The slave's position, from 0.
        position: u16,
        /// The first register.
        register: u16,
        /// Bytes, 1 to [`REGISTER_MAX`].
        data: Vec<u8>,
    },
    /// File `file` read from the slave by FoE, at most `max_bytes` of it.
    FoeRead {
        /// The slave's position, from 0.
        position: u16,
        /// The file's name on the slave.
        file: String,
        /// The password the slave asks for (0: none).
        password: u32,
        /// A longer file is an error (the transfer aborted), not a truncated one.
        max_bytes: usize,
    },
    /// `data` written to the slave as file `file` by FoE.
    FoeWrite {
        /// The slave's position, from 0.
        position: u16,
        /// The file's name on the slave.
        file: String,
        /// The password the slave asks for (0: none).
        password: u32,
        /// The file.
        data: Vec<u8>,
    },
    /// The slave to `state` (AL control), answered when its AL status says it is there. From
    /// then on the master keeps it there: supervision brings a slave back to the state last
    /// requested, not to OP.
    State {
        /// The slave's position, from 0.
        position: u16,
        /// INIT, PREOP, SAFEOP or OP.
        state: AlState,
    },
    /// SoE read of `elements` of `idn` of drive `drive`: the elements' data, in order.
    SoeRead {
        /// The slave's position, from 0.
        position: u16,
        /// The drive (axis) of the device.
        drive: u8,
        /// The IDN.
        idn: ferrocat_wire::soe::Idn,
        /// Which of its elements.
        elements: ferrocat_wire::soe::Elements,
    },
    /// SoE write of `data` to `elements` of `idn` of drive `drive`.
    SoeWrite {
        /// The slave's position, from 0.
        position: u16,
        /// The drive (axis) of the device.
        drive: u8,
        /// The IDN.
        idn: ferrocat_wire::soe::Idn,
        /// Which of its elements (the value, mostly).
        elements: ferrocat_wire::soe::Elements,
        /// The data as it goes on the wire.
        data: Vec<u8>,
    },
    /// One mailbox message of `mailbox_type` passed through as it is (a mailbox gateway's
    /// request): written under the master's next counter, and with `reply` the slave's next
    /// message of the same type answered ([`Answer::Mailbox`]).
    Mailbox {
        /// The slave's position, from 0.
        position: u16,
        /// The protocol (CoE, FoE, SoE, EoE, VoE …): the slave's SII must name it.
        mailbox_type: ferrocat_wire::mailbox::MailboxType,
        /// The message after the mailbox header.
        data: Vec<u8>,
        /// Whether a reply is awaited (an EoE fragment has none).
        reply: bool,
    },
}

impl Request {
    /// The slave the request is for.
    pub fn position(&self) -> u16 {
        match *self {
            Request::SdoRead { position, .. }
            | Request::SdoWrite { position, .. }
            | Request::OdList { position }
            | Request::ObjectInfo { position, .. }
            | Request::EntryInfo { position, .. }
            | Request::RegisterRead { position, .. }
            | Request::RegisterWrite { position, .. }
            | Request::FoeRead { position, .. }
            | Request::FoeWrite { position, .. }
            | Request::State { position, .. }
            | Request::SoeRead { position, .. }
            | Request::SoeWrite { position, .. }
            | Request::Mailbox { position, .. } => position,
        }
    }

    pub(crate) fn uses_mailbox(&self) -> bool {
        matches!(
            self,
            Request::SdoRead { .. }
                | Request::SdoWrite { .. }
                | Request::OdList { .. }
                | Request::ObjectInfo { .. }
                | Request::EntryInfo { .. }
                | Request::FoeRead { .. }
                | Request::FoeWrite { .. }
                | Request::SoeRead { .. }
                | Request::SoeWrite { .. }
                | Request::Mailbox { .. }
        )
    }
}

/// A request's answer.
#[derive(Debug, Clone, PartialEq, Eq)]
pub enum Answer {
    /// What an SDO or register read gave.
    Data(Vec<u8>),
    /// An SDO or register write was taken.
    Written,
    /// Every object's index.
    List(Vec<u16>),
    /// An object's description.
    Object(ObjectInfo),
    /// An entry's description.
    Entry(EntryInfo),
    /// The slave reached this state.
    State(AlState),
    /// A passed-through mailbox message's reply: the slave's message after its mailbox header
    /// (empty where none was awaited).
    Mailbox(Vec<u8>),
}

/// What the acyclic side did so far.
#[derive(Debug, Clone, Copy, Default, PartialEq, Eq)]
pub struct AcyclicStats {
    /// Requests taken into the queue.
    pub submitted: u64,
    /// Requests answered, with data or with an error.
    pub answered: u64,
    /// Of those, answered with an error.
    pub failed: u64,
    /// Datagrams sent for them.
    pub datagrams: u64,
    /// Datagrams whose answer did not come before the spare time's end (sent again, or the
    /// mailbox polled again, at the next call).
    pub given_up: u64,
    /// Calls in which a request waited and no datagram of it fitted before the deadline.
    pub starved: u64,
    /// Datagrams sent past the deadline, in the cycle's last sixteenth, for a request that had
    /// found no room for [`STARVED_CALLS`] calls in a row.
    pub relieved: u64,
}

/// Calls of `serve_requests` in a row without room after which a waiting request is given one
/// datagram up to a sixteenth of the period before the next cycle.
pub const STARVED_CALLS: u32 = 8;

/// The acyclic side's state (the master holds it).
#[derive(Debug, Default)]
pub(crate) struct Acyclic {
    pub(crate) queue: VecDeque<(RequestId, Request)>,
    pub(crate) active: Option<Active>,
    pub(crate) answers: Vec<(RequestId, Result<Answer>)>,
    pub(crate) next_id: u64,
    pub(crate) stats: AcyclicStats,
    /// Calls in a row in which a request waited and found no room.
    pub(crate) starved_calls: u32,
}

impl Acyclic {
    /// Whether a request being served holds `position`'s mailbox: diagnosis leaves it alone.
    pub(crate) fn holds_mailbox(&self, position: u16) -> bool {
        self.active.as_ref().is_some_and(|a| a.job.uses_mailbox() && a.position == position)
    }
}

#[derive(Debug)]
pub(crate) struct Active {
    pub(crate) id: RequestId,
    pub(crate) position: u16,
    pub(crate) job: Job,
    /// When it started, or last made progress (the master's clock).
    pub(crate) since_ns: u64,
}

#[derive(Debug)]
pub(crate) enum Job {
    /// A mailbox conversation: its message to write next, or (None) its reply awaited.
    Sdo(SdoTransfer, Option<Vec<u8>>),
    Info(InfoTransfer, InfoWanted, Option<Vec<u8>>),
    /// An FoE transfer: its message to write next (or its reply awaited), and after the last
    /// message (no reply awaited) the transfer's end; whether it writes.
    Foe(FoeTransfer, Option<Vec<u8>>, Option<Result<Vec<u8>>>, bool),
    RegisterRead {
        register: u16,
        len: u16,
    },
    RegisterWrite {
        register: u16,
        data: Vec<u8>,
    },
    State {
        state: AlState,
        written: bool,
    },
    /// An SoE read or write: its message to write next, or (None) its reply awaited; whether
    /// it writes.
    Soe(crate::soe_transfer::SoeTransfer, Option<Vec<u8>>, bool),
    /// A passed-through message: its type, the message to write (None: the reply awaited),
    /// and whether a reply is awaited.
    Mailbox(ferrocat_wire::mailbox::MailboxType, Option<Vec<u8>>, bool),
}

#[derive(Debug, Clone, Copy)]
pub(crate) enum InfoWanted {
    List,
    Object,
    Entry,
}

impl Job {
    fn uses_mailbox(&self) -> bool {
        matches!(self, Job::Sdo(..) | Job::Info(..) | Job::Foe(..) | Job::Soe(..) | Job::Mailbox(..))
    }
}

impl Acyclic {
    pub(crate) fn answer(&mut self, id: RequestId, answer: Result<Answer>) {
        self.stats.answered += 1;
        self.stats.failed += u64::from(answer.is_err());
        self.answers.push((id, answer));
    }
}
