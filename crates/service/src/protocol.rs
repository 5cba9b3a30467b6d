//! The control socket's protocol, version 1 (docs/service.md).
//!
//! A stream socket; UTF-8 JSON, one object per line, at most [`MAX_LINE`] bytes a line. On
//! connecting, the client reads the master's [`Hello`]. It then writes a [`Envelope`] (a
//! request with a number of its choosing) and reads one [`Reply`] under the same number,
//! one request at a time. Bytes go as hex text (`"78563412"`), numbers as JSON numbers.
use serde::{Deserialize, Serialize};

/// The protocol's version. A master refuses nothing by version: a client compares it with
/// the one it speaks and says so.
pub const VERSION: u32 = 1;
/// The longest line either side sends or takes, in bytes (a line longer is an error, and the
/// connection is closed).
pub const MAX_LINE: usize = 64 * 1024;
/// The longest value of an SDO write or a register write, in bytes.
pub const MAX_DATA: usize = 16 * 1024;
/// The longest file by FoE through the socket, bytes.
pub const MAX_FOE_FILE: usize = 64 << 20;
/// The most bytes of an SII a reply carries.
pub const SII_PART: usize = 16 * 1024;

/// What the master says first.
#[derive(Debug, Clone, PartialEq, Eq, Serialize, Deserialize)]
pub struct Hello {
    /// "ferrocat".
    pub service: String,
    /// The protocol's version ([`VERSION`]).
    pub protocol: u32,
    /// The master's process.
    pub pid: u32,
    /// What the master runs on: an interface's name, `udp:ADDR:PORT`, or `virtual`.
    pub target: String,
    /// Its cycle, µs (0: back to back).
    pub cycle_us: u64,
    /// Slaves on its segment.
    pub slaves: usize,
    /// Whether it takes register writes.
    pub register_writes: bool,
}

/// A request with the number its reply will carry (read by [`parse_request`]).
#[derive(Debug, Clone, PartialEq, Eq, Serialize)]
pub struct Envelope {
    /// Any number; the reply carries it back.
    pub id: u64,
    /// What is asked.
    #[serde(flatten)]
    pub request: Request,
}

/// What a client asks, by `op`.
#[derive(Debug, Clone, PartialEq, Eq, Serialize, Deserialize)]
#[serde(tag = "op", rename_all = "snake_case", deny_unknown_fields)]
pub enum Request {
    /// The slaves as the master knows them: [`SlaveInfo`] each, under `slaves`.
    Slaves,
    /// The cyclic loop's statistics ([`Stats`]).
    Stats,
    /// Read the machine description again and apply what can change without stopping the
    /// cycle (as SIGHUP does): `{"said": TEXT}`.
    Reload,
    /// The master's events from number `since` on ([`Events`]): slaves that left OP, came
    /// back or stopped answering, emergencies, sync errors, error counters that grew, the
    /// ring's changes. The master keeps the last 1 024.
    Events {
        /// The first event wanted (0: every one kept).
        #[serde(default)]
        since: u64,
    },
    /// A slave's SII (EEPROM) as the master read it at its start, in parts of at most
    /// [`SII_PART`] bytes from `offset`: `{"total": N, "offset": O, "data": HEX}`.
    SiiRead {
        /// The slave's position, from 0.
        position: u16,
        /// The first byte wanted.
        #[serde(default)]
        offset: usize,
    },
    /// The master's own object dictionary (ETG.1510) from object `from` on, every object with
    /// its entries' names, types and values, as many as fit a reply: `{"objects": [{"index",
    /// "name", "object_code", "entries": [{"subindex", "name", "data_type", "bit_length",
    /// "value": HEX}]}], "next": INDEX or null}`. Diagnosis objects carry the master's counters;
    /// their live registers are read over the mailbox gateway.
    MasterOd {
        /// The first index wanted.
        #[serde(default)]
        from: u16,
    },
    /// The process data a slave maps ([`Pdos`]).
    Pdos {
        /// The slave's position, from 0.
        position: u16,
    },
    /// SDO upload: the value under `data`.
    SdoRead {
        /// The slave's position, from 0.
        position: u16,
        /// The object.
        index: u16,
        /// The entry.
        subindex: u8,
        /// The whole object from `subindex` on.
        #[serde(default)]
        complete_access: bool,
    },
    /// SDO download of `data`.
    SdoWrite {
        /// The slave's position, from 0.
        position: u16,
        /// The object.
        index: u16,
        /// The entry.
        subindex: u8,
        /// The whole object from `subindex` on.
        #[serde(default)]
        complete_access: bool,
        /// The value as it goes on the wire, hex.
        data: String,
    },
    /// SDO information: every object's index, under `indices`.
    OdList {
        /// The slave's position, from 0.
        position: u16,
    },
    /// SDO information: an object's description ([`ObjectDescription`]).
    ObjectInfo {
        /// The slave's position, from 0.
        position: u16,
        /// The object.
        index: u16,
    },
    /// SDO information: an entry's description ([`EntryDescription`]).
    EntryInfo {
        /// The slave's position, from 0.
        position: u16,
        /// The object.
        index: u16,
        /// The entry.
        subindex: u8,
    },
    /// `len` bytes of the ESC's registers from `register`, under `data`.
    RegisterRead {
        /// The slave's position, from 0.
        position: u16,
        /// The first register.
        register: u16,
        /// Bytes, 1 to 1 024.
        len: u16,
    },
    /// `data` to the ESC's registers from `register`; only where the master was started to
    /// take register writes.
    RegisterWrite {
        /// The slave's position, from 0.
        position: u16,
        /// The first register.
        register: u16,
        /// The bytes, hex.
        data: String,
    },
    /// File `file` read from the slave by FoE (at most `max_bytes`, at most
    /// [`MAX_FOE_FILE`]): `{"total": N, "offset": O, "data": HEX}`, at most [`MAX_DATA`]
    /// bytes a reply. The ask from `offset` 0 reads the file; those after it (`offset` the
    /// bytes had so far) take the rest of what that read gave, on the same connection.
    FoeRead {
        /// The slave's position, from 0.
        position: u16,
        /// The file's name on the slave.
        file: String,
        /// The password the slave asks for.
        #[serde(default)]
        password: u32,
        /// A longer file is an error.
        #[serde(default = "max_foe_file")]
        max_bytes: usize,
        /// The first byte wanted of the file read.
        #[serde(default)]
        offset: usize,
    },
    /// A part of file `file` (hex, at most [`MAX_DATA`] bytes) for the slave by FoE: parts
    /// with `more` are kept on the connection (`{"buffered": N}`), and the part without
    /// writes the whole file (at most [`MAX_FOE_FILE`] bytes): `{}` once the slave took it.
    FoeWrite {
        /// The slave's position, from 0.
        position: u16,
        /// The file's name on the slave.
        file: String,
        /// The password the slave asks for.
        #[serde(default)]
        password: u32,
        /// This part, hex.
        data: String,
        /// More parts follow.
        #[serde(default)]
        more: bool,
    },
    /// The slave to `state` (INIT, PREOP, SAFEOP or OP); the master keeps it there.
    State {
        /// The slave's position, from 0.
        position: u16,
        /// The state's name.
        state: String,
    },
    /// SoE read of `elements` (the element bits, 0x40 the value) of IDN `idn` (its 16-bit
    /// number: 0x801E for P-0-0030) of drive `drive`: the elements' data under `data`.
    SoeRead {
        /// The slave's position, from 0.
        position: u16,
        /// The drive (axis) of the device.
        #[serde(default)]
        drive: u8,
        /// The IDN's number.
        idn: u16,
        /// The elements' bits.
        elements: u8,
    },
    /// SoE write of `data` (hex, as it goes on the wire) to `elements` of IDN `idn`: `{}`.
    SoeWrite {
        /// The slave's position, from 0.
        position: u16,
        /// The drive (axis) of the device.
        #[serde(default)]
        drive: u8,
        /// The IDN's number.
        idn: u16,
        /// The elements' bits.
        elements: u8,
        /// The data, hex.
        data: String,
    },
}

fn max_foe_file() -> usize {
    MAX_FOE_FILE
}

/// The master's answer to one request: `ok` with the result, or `error`.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct Reply {
    /// The request's number.
    pub id: u64,
    /// The result, as the request says.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub ok: Option<serde_json::Value>,
    /// Why there is none.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub error: Option<ErrorReply>,
}

/// A request that failed.
#[derive(Debug, Clone, PartialEq, Eq, Serialize, Deserialize)]
pub struct ErrorReply {
    /// What kind of failure.
    pub kind: ErrorKind,
    /// In words, naming the slave, object or register.
    pub message: String,
    /// The SDO abort code, for `abort`.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub abort_code: Option<u32>,
}

/// The kinds of failure.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum ErrorKind {
    /// The line is not a request of this protocol.
    BadRequest,
    /// The master does not take this request (register writes not allowed).
    Refused,
    /// Too many requests wait; try again.
    Busy,
    /// No slave at that position.
    NoSuchSlave,
    /// The slave aborted the SDO transfer (`abort_code`).
    Abort,
    /// The slave did not reach the state.
    State,
    /// The slave did not answer in time.
    Timeout,
    /// What the slave lacks or did wrong (no mailbox, no CoE, a malformed reply).
    Slave,
    /// The master's link failed, or it stopped.
    Master,
}

impl ErrorReply {
    /// An error of `kind` saying `message`.
    pub fn new(kind: ErrorKind, message: impl Into<String>) -> Self {
        ErrorReply { kind, message: message.into(), abort_code: None }
    }
}

/// A slave as the master knows it.
#[derive(Debug, Clone, PartialEq, Eq, Serialize, Deserialize)]
pub struct SlaveInfo {
    /// Position on the segment, from 0.
    pub position: u16,
    /// Its configured station address.
    pub station: u16,
    /// Its station alias (0: none).
    pub alias: u16,
    /// Its name from the SII.
    pub name: String,
    /// Vendor ID.
    pub vendor_id: u32,
    /// Product code.
    pub product_code: u32,
    /// Revision number.
    pub revision: u32,
    /// Serial number.
    pub serial: u32,
    /// The state the master keeps it in.
    pub state: String,
    /// Whether it is there: `operational` (in the state the master keeps it in),
    /// `recovering` or `lost`.
    pub health: String,
    /// Whether it has a mailbox with CoE.
    pub coe: bool,
}

/// The cyclic loop's statistics.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct Stats {
    /// Cycles so far.
    pub cycles: u64,
    /// Cycles whose working counter was not the expected one.
    pub wkc_errors: u64,
    /// The working counter a whole cycle gives.
    pub expected_wkc: u16,
    /// The last cycle's.
    pub last_wkc: u16,
    /// The last cycle's round trip, ns.
    pub last_round_trip_ns: u64,
    /// Requests answered and failed on the acyclic side.
    pub requests_answered: u64,
    /// Of those, failed.
    pub requests_failed: u64,
    /// What the application adds (`ferrocat run`: the clock sync's lock and offset).
    #[serde(default)]
    pub extra: serde_json::Value,
}

/// Events from a number on.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct Events {
    /// Where the next ask starts: after the last event given (a reply carries as many as fit
    /// its line; ask again until one comes empty), or the number the next event will have.
    pub next: u64,
    /// Events asked for that the master no longer keeps.
    pub missed: u64,
    /// The events, oldest first.
    pub events: Vec<Event>,
}

/// One event of the master.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct Event {
    /// Its number, from 0.
    pub seq: u64,
    /// `left_op`, `lost`, `recovered`, `emergency`, `sync_error`, `error_counters` or `ring`.
    pub kind: String,
    /// The slave's position, where it is a slave's.
    #[serde(default)]
    pub position: Option<u16>,
    /// In words, as `ferrocat run` prints it.
    pub text: String,
    /// When the loop took it, seconds since the master's cyclic loop started.
    pub at_s: f64,
}

/// One mapped entry of a slave's process data.
#[derive(Debug, Clone, PartialEq, Eq, Serialize, Deserialize)]
pub struct PdoEntry {
    /// The object's index.
    pub index: u16,
    /// Its subindex.
    pub subindex: u8,
    /// Its width in bits.
    pub bits: u8,
    /// Its name.
    pub name: String,
    /// Its first bit in the whole image.
    pub image_bit: u32,
}

/// A slave's process data as mapped.
#[derive(Debug, Clone, PartialEq, Eq, Serialize, Deserialize)]
pub struct Pdos {
    /// The slave's position.
    pub position: u16,
    /// Its outputs, in image order.
    pub outputs: Vec<PdoEntry>,
    /// Its inputs, in image order.
    pub inputs: Vec<PdoEntry>,
}

/// An object's description.
#[derive(Debug, Clone, PartialEq, Eq, Serialize, Deserialize)]
pub struct ObjectDescription {
    /// The object's index.
    pub index: u16,
    /// Its data type.
    pub data_type: u16,
    /// Its highest subindex.
    pub max_subindex: u8,
    /// 7 VAR, 8 ARRAY, 9 RECORD.
    pub object_code: u8,
    /// Its name.
    pub name: String,
}

/// An entry's description.
#[derive(Debug, Clone, PartialEq, Eq, Serialize, Deserialize)]
pub struct EntryDescription {
    /// The entry's subindex.
    pub subindex: u8,
    /// Its data type.
    pub data_type: u16,
    /// Its size in bits.
    pub bit_length: u16,
    /// Its access bits.
    pub access: u16,
    /// Its name.
    pub name: String,
}

/// `bytes` as hex text.
pub fn hex(bytes: &[u8]) -> String {
    bytes.iter().map(|b| format!("{b:02x}")).collect()
}

/// Hex text as bytes: an even number of hex digits, at most [`MAX_DATA`] bytes.
pub fn unhex(text: &str) -> Result<Vec<u8>, String> {
    if !text.is_ascii() || text.len() % 2 != 0 {
        return Err(format!("'{}': give an even number of hex digits", clip(text)));
    }
    if text.len() / 2 > MAX_DATA {
        return Err(format!("{} bytes: at most {MAX_DATA}", text.len() / 2));
    }
    (0..text.len())
        .step_by(2)
        .map(|i| u8::from_str_radix(&text[i..i + 2], 16).map_err(|_| format!("'{}': not hex", clip(text))))
        .collect()
}

/// At most 40 characters of `text`, for an error.
fn clip(text: &str) -> String {
    let mut s: String = text.chars().take(40).collect();
    if text.chars().count() > 40 {
        s.push('…');
    }
    s
}

/// Parses a request line: the request, or the reply that says what is wrong with it (under
/// the line's `id` where one could be read, else 0).
pub fn parse_request(line: &[u8]) -> Result<Envelope, Reply> {
    let bad =
        |id, message: String| Reply { id, ok: None, error: Some(ErrorReply::new(ErrorKind::BadRequest, message)) };
    let text = std::str::from_utf8(line).map_err(|e| bad(0, format!("not UTF-8 text ({e})")))?;
    let not_ours = |id, e: String| bad(id, format!("not a request of protocol {VERSION}: {e}"));
    let mut v: serde_json::Map<String, serde_json::Value> =
        serde_json::from_str(text).map_err(|e| not_ours(0, e.to_string()))?;
    let id = match v.remove("id") {
        Some(serde_json::Value::Number(n)) if n.as_u64().is_some() => n.as_u64().unwrap_or(0),
        Some(other) => return Err(not_ours(0, format!("id {other}: give a number from 0"))),
        None => return Err(not_ours(0, String::from("no id"))),
    };
    // Whatever the request's own fields are not is refused, as `deny_unknown_fields` would
    // (it does not reach the fields of a variant without any).
    let op = v.get("op").and_then(|o| o.as_str()).unwrap_or_default();
    if matches!(op, "slaves" | "stats" | "reload") {
        if let Some(extra) = v.keys().find(|k| *k != "op") {
            return Err(not_ours(id, format!("unknown field `{extra}`")));
        }
    }
    let request = serde_json::from_value(serde_json::Value::Object(v)).map_err(|e| not_ours(id, e.to_string()))?;
    Ok(Envelope { id, request })
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_request_goes_as_one_line_and_comes_back_the_same() {
        let e = Envelope {
            id: 7,
            request: Request::SdoWrite {
                position: 2,
                index: 0x6060,
                subindex: 0,
                complete_access: false,
                data: hex(&[8]),
            },
        };
        let line = serde_json::to_string(&e).unwrap();
        assert_eq!(
            line,
            r#"{"id":7,"op":"sdo_write","position":2,"index":24672,"subindex":0,"complete_access":false,"data":"08"}"#
        );
        assert_eq!(parse_request(line.as_bytes()).unwrap(), e);
        let slaves = parse_request(br#"{"id":1,"op":"slaves"}"#).unwrap();
        assert_eq!(slaves.request, Request::Slaves);
    }

    #[test]
    fn bad_lines_are_answered_in_words_under_their_number() {
        for (line, id, says) in [
            (&b"\xff\xfe"[..], 0, "not UTF-8"),
            (b"{\"id\":3,\"op\":\"format_disk\"}", 3, "unknown variant `format_disk`"),
            (b"{\"id\":4,\"op\":\"sdo_read\",\"position\":70000,\"index\":1,\"subindex\":0}", 4, "70000"),
            (b"{\"id\":5,\"op\":\"slaves\",\"extra\":1}", 5, "unknown field `extra`"),
            (b"[]", 0, "not a request"),
        ] {
            let r = parse_request(line).unwrap_err();
            let e = r.error.unwrap();
            assert_eq!((r.id, e.kind), (id, ErrorKind::BadRequest));
            assert!(e.message.contains(says), "{}", e.message);
        }
    }

    #[test]
    fn hex_takes_pairs_of_digits_only() {
        assert_eq!(unhex("0aFF").unwrap(), vec![0x0a, 0xff]);
        assert!(unhex("abc").unwrap_err().contains("even number"));
        assert!(unhex("zz").unwrap_err().contains("not hex"));
        assert!(unhex("é1").unwrap_err().contains("even number"));
        assert!(unhex(&"00".repeat(MAX_DATA + 1)).unwrap_err().contains("at most"));
        assert_eq!(hex(&[1, 0xab]), "01ab");
    }
}
