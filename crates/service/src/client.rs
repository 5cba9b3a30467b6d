//! A client of a running master's control socket.
use std::io::{BufRead, BufReader, Read, Write};
use std::os::unix::net::UnixStream;
use std::path::{Path, PathBuf};
use std::time::Duration;

use crate::protocol::{
    self, EntryDescription, Envelope, ErrorKind, ErrorReply, Events, Hello, ObjectDescription, Pdos, Reply, Request,
    SlaveInfo, Stats, MAX_LINE,
};

/// How long a reply may take: longer than any request's own time limit on the master's side
/// (a state change, 10 s by default).
const REPLY_TIMEOUT: Duration = Duration::from_secs(30);

/// What went wrong talking to a master.
#[derive(Debug, thiserror::Error)]
pub enum ClientError {
    /// No master listens there.
    #[error("no master answers on {path}: {error}")]
    Connect {
        /// The socket.
        path: PathBuf,
        /// Why.
        error: std::io::Error,
    },
    /// The connection failed, or the reply did not come in time.
    #[error("the master on {path}: {error}")]
    Io {
        /// The socket.
        path: PathBuf,
        /// Why.
        error: std::io::Error,
    },
    /// The master said something that is not this protocol.
    #[error("the master on {path} speaks another protocol: {what}")]
    Protocol {
        /// The socket.
        path: PathBuf,
        /// What was wrong.
        what: String,
    },
    /// The master answered the request with an error.
    #[error("{}", .0.message)]
    Remote(ErrorReply),
}

impl ClientError {
    /// The master's error, if it answered with one.
    pub fn remote(&self) -> Option<&ErrorReply> {
        match self {
            ClientError::Remote(e) => Some(e),
            _ => None,
        }
    }
}

/// A connection to a running master.
#[derive(Debug)]
pub struct Client {
    reader: BufReader<UnixStream>,
    writer: UnixStream,
    path: PathBuf,
    hello: Hello,
    next_id: u64,
}

impl Client {
    /// Connects to the master on `path` and reads what it says first.
    pub fn connect(path: impl AsRef<Path>) -> Result<Client, ClientError> {
        let path = path.as_ref().to_path_buf();
        let stream = UnixStream::connect(&path).map_err(|error| ClientError::Connect { path: path.clone(), error })?;
        let io = |error| ClientError::Io { path: path.clone(), error };
        stream.set_read_timeout(Some(REPLY_TIMEOUT)).map_err(io)?;
        let writer = stream.try_clone().map_err(io)?;
        let mut c = Client {
            reader: BufReader::new(stream),
            writer,
            path: path.clone(),
            hello: Hello {
                service: String::new(),
                protocol: 0,
                pid: 0,
                target: String::new(),
                cycle_us: 0,
                slaves: 0,
                register_writes: false,
            },
            next_id: 1,
        };
        let line = c.read_line()?;
        let v: serde_json::Value = serde_json::from_slice(&line).map_err(|e| c.protocol_error(e.to_string()))?;
        if let Some(e) = v.get("error").and_then(|e| serde_json::from_value::<ErrorReply>(e.clone()).ok()) {
            return Err(ClientError::Remote(e));
        }
        let hello = v.get("hello").cloned().ok_or_else(|| c.protocol_error(String::from("no hello")))?;
        c.hello = serde_json::from_value(hello).map_err(|e| c.protocol_error(e.to_string()))?;
        if c.hello.protocol != protocol::VERSION {
            return Err(c.protocol_error(format!(
                "version {}, this client speaks {}",
                c.hello.protocol,
                protocol::VERSION
            )));
        }
        Ok(c)
    }

    /// What the master said on connecting: its process, target, cycle and slaves.
    pub fn hello(&self) -> &Hello {
        &self.hello
    }

    /// The socket.
    pub fn path(&self) -> &Path {
        &self.path
    }

    fn protocol_error(&self, what: String) -> ClientError {
        ClientError::Protocol { path: self.path.clone(), what }
    }

    fn read_line(&mut self) -> Result<Vec<u8>, ClientError> {
        let mut line = Vec::new();
        let n = (&mut self.reader)
            .take(MAX_LINE as u64 + 1)
            .read_until(b'\n', &mut line)
            .map_err(|error| ClientError::Io { path: self.path.clone(), error })?;
        if n == 0 {
            let e = std::io::Error::new(std::io::ErrorKind::UnexpectedEof, "the master closed the connection");
            return Err(ClientError::Io { path: self.path.clone(), error: e });
        }
        if line.last() != Some(&b'\n') {
            return Err(self.protocol_error(format!("a line longer than {MAX_LINE} bytes")));
        }
        Ok(line)
    }

    /// Sends `request` and waits for its reply: the result as the protocol gives it.
    pub fn call(&mut self, request: Request) -> Result<serde_json::Value, ClientError> {
        let id = self.next_id;
        self.next_id += 1;
        let mut line = serde_json::to_vec(&Envelope { id, request }).map_err(|e| self.protocol_error(e.to_string()))?;
        line.push(b'\n');
        self.writer.write_all(&line).map_err(|error| ClientError::Io { path: self.path.clone(), error })?;
        let line = self.read_line()?;
        let reply: Reply = serde_json::from_slice(&line).map_err(|e| self.protocol_error(e.to_string()))?;
        if reply.id != id {
            return Err(self.protocol_error(format!("a reply to request {} where {id} was asked", reply.id)));
        }
        match (reply.ok, reply.error) {
            (_, Some(e)) => Err(ClientError::Remote(e)),
            (Some(v), None) => Ok(v),
            (None, None) => Err(self.protocol_error(String::from("a reply with neither ok nor error"))),
        }
    }

    fn field<T: serde::de::DeserializeOwned>(&self, v: serde_json::Value, key: &str) -> Result<T, ClientError> {
        let part = if key.is_empty() { v } else { v.get(key).cloned().unwrap_or_default() };
        serde_json::from_value(part).map_err(|e| self.protocol_error(format!("{key}: {e}")))
    }

    fn bytes(&self, v: serde_json::Value) -> Result<Vec<u8>, ClientError> {
        let text: String = self.field(v, "data")?;
        protocol::unhex(&text).map_err(|e| self.protocol_error(e))
    }

    /// The slaves as the master knows them.
    pub fn slaves(&mut self) -> Result<Vec<SlaveInfo>, ClientError> {
        let v = self.call(Request::Slaves)?;
        self.field(v, "slaves")
    }

    /// The cyclic loop's statistics.
    pub fn stats(&mut self) -> Result<Stats, ClientError> {
        let v = self.call(Request::Stats)?;
        self.field(v, "")
    }

    /// Asks the master to read its machine description again and apply what can change while
    /// it cycles: what it did, in words.
    pub fn reload(&mut self) -> Result<String, ClientError> {
        let v = self.call(Request::Reload)?;
        self.field(v, "said")
    }

    /// The master's events from number `since` on (0: every one it keeps).
    pub fn events(&mut self, since: u64) -> Result<Events, ClientError> {
        let v = self.call(Request::Events { since })?;
        self.field(v, "")
    }

    /// The SII (EEPROM image) of the slave at `position`, as the master read it at its start.
    pub fn sii_read(&mut self, position: u16) -> Result<Vec<u8>, ClientError> {
        let mut image = Vec::new();
        loop {
            let v = self.call(Request::SiiRead { position, offset: image.len() })?;
            let total: usize = self.field(v.clone(), "total")?;
            let part = self.bytes(v)?;
            if part.is_empty() || total > 1 << 24 {
                return Err(self.protocol_error(format!("an SII part of 0 bytes at {} of {total}", image.len())));
            }
            image.extend_from_slice(&part);
            if image.len() >= total {
                image.truncate(total);
                return Ok(image);
            }
        }
    }

    /// The master's own object dictionary (ETG.1510): every object, each as the protocol's
    /// JSON gives it (`index`, `name`, `object_code`, `entries`).
    pub fn master_od(&mut self) -> Result<Vec<serde_json::Value>, ClientError> {
        let (mut all, mut from) = (Vec::new(), 0u16);
        loop {
            let v = self.call(Request::MasterOd { from })?;
            let objects: Vec<serde_json::Value> = self.field(v.clone(), "objects")?;
            all.extend(objects);
            match v.get("next").and_then(serde_json::Value::as_u64) {
                Some(n) if n > u64::from(from) && n <= u64::from(u16::MAX) => from = n as u16,
                _ => return Ok(all),
            }
        }
    }

    /// The process data the slave at `position` maps.
    pub fn pdos(&mut self, position: u16) -> Result<Pdos, ClientError> {
        let v = self.call(Request::Pdos { position })?;
        self.field(v, "")
    }

    /// SDO upload of `index:subindex` of the slave at `position`.
    pub fn sdo_read(&mut self, position: u16, index: u16, subindex: u8) -> Result<Vec<u8>, ClientError> {
        self.sdo_upload(position, index, subindex, false)
    }

    /// SDO upload, the whole object with `complete_access`.
    pub fn sdo_upload(
        &mut self,
        position: u16,
        index: u16,
        subindex: u8,
        complete_access: bool,
    ) -> Result<Vec<u8>, ClientError> {
        let v = self.call(Request::SdoRead { position, index, subindex, complete_access })?;
        self.bytes(v)
    }

    /// SDO download of `data`, the whole object with `complete_access`.
    pub fn sdo_download(
        &mut self,
        position: u16,
        index: u16,
        subindex: u8,
        complete_access: bool,
        data: &[u8],
    ) -> Result<(), ClientError> {
        self.call(Request::SdoWrite { position, index, subindex, complete_access, data: protocol::hex(data) }).map(drop)
    }

    /// SoE read of `elements` (the element bits, 0x40 the value) of IDN number `idn` of drive
    /// `drive`: the elements' data.
    pub fn soe_read(&mut self, position: u16, drive: u8, idn: u16, elements: u8) -> Result<Vec<u8>, ClientError> {
        let v = self.call(Request::SoeRead { position, drive, idn, elements })?;
        self.bytes(v)
    }

    /// SoE write of `data` (as it goes on the wire) to `elements` of IDN number `idn`.
    pub fn soe_write(
        &mut self,
        position: u16,
        drive: u8,
        idn: u16,
        elements: u8,
        data: &[u8],
    ) -> Result<(), ClientError> {
        self.call(Request::SoeWrite { position, drive, idn, elements, data: protocol::hex(data) }).map(drop)
    }

    /// Every object's index (SDO information).
    pub fn od_list(&mut self, position: u16) -> Result<Vec<u16>, ClientError> {
        let v = self.call(Request::OdList { position })?;
        self.field(v, "indices")
    }

    /// An object's description (SDO information).
    pub fn object_info(&mut self, position: u16, index: u16) -> Result<ObjectDescription, ClientError> {
        let v = self.call(Request::ObjectInfo { position, index })?;
        self.field(v, "")
    }

    /// An entry's description (SDO information).
    pub fn entry_info(&mut self, position: u16, index: u16, subindex: u8) -> Result<EntryDescription, ClientError> {
        let v = self.call(Request::EntryInfo { position, index, subindex })?;
        self.field(v, "")
    }

    /// `len` bytes of registers from `register`.
    pub fn register_read(&mut self, position: u16, register: u16, len: u16) -> Result<Vec<u8>, ClientError> {
        let v = self.call(Request::RegisterRead { position, register, len })?;
        self.bytes(v)
    }

    /// `data` to registers from `register` (a master started to take them).
    pub fn register_write(&mut self, position: u16, register: u16, data: &[u8]) -> Result<(), ClientError> {
        self.call(Request::RegisterWrite { position, register, data: protocol::hex(data) }).map(drop)
    }

    /// File `file` of the slave at `position` by FoE, at most `max_bytes` (at most
    /// [`protocol::MAX_FOE_FILE`]; a longer file is an error, not a truncated one), in parts.
    pub fn foe_read(
        &mut self,
        position: u16,
        file: &str,
        password: u32,
        max_bytes: usize,
    ) -> Result<Vec<u8>, ClientError> {
        let max_bytes = max_bytes.min(protocol::MAX_FOE_FILE);
        let mut data = Vec::new();
        loop {
            let offset = data.len();
            let request = Request::FoeRead { position, file: file.to_string(), password, max_bytes, offset };
            // The first part waits for the whole file to come from the slave.
            let v = self.call_long(request)?;
            let total: usize = self.field(v.clone(), "total")?;
            let part = self.bytes(v)?;
            if total > protocol::MAX_FOE_FILE || (part.is_empty() && data.len() < total) {
                return Err(self.protocol_error(format!("a part of {} bytes at {offset} of {total}", part.len())));
            }
            data.extend_from_slice(&part);
            if data.len() >= total {
                data.truncate(total);
                return Ok(data);
            }
        }
    }

    /// `data` written to the slave at `position` as file `file` by FoE (at most
    /// [`protocol::MAX_FOE_FILE`] bytes), in parts; returns once the slave took the last.
    pub fn foe_write(&mut self, position: u16, file: &str, password: u32, data: &[u8]) -> Result<(), ClientError> {
        let mut parts = data.chunks(protocol::MAX_DATA).peekable();
        if data.is_empty() {
            let request =
                Request::FoeWrite { position, file: file.to_string(), password, data: String::new(), more: false };
            return self.call_long(request).map(drop);
        }
        while let Some(part) = parts.next() {
            let more = parts.peek().is_some();
            let request =
                Request::FoeWrite { position, file: file.to_string(), password, data: protocol::hex(part), more };
            self.call_long(request)?;
        }
        Ok(())
    }

    /// [`call`](Self::call) for a file by FoE, waiting up to an hour for the reply (the
    /// master ends a transfer that makes no progress for its mailbox timeout).
    fn call_long(&mut self, request: Request) -> Result<serde_json::Value, ClientError> {
        let io = |error| ClientError::Io { path: self.path.clone(), error };
        self.writer.set_read_timeout(Some(std::time::Duration::from_secs(3600))).map_err(io)?;
        let r = self.call(request);
        let _ = self.writer.set_read_timeout(Some(REPLY_TIMEOUT));
        r
    }

    /// The slave to `state` (INIT, PREOP, SAFEOP, OP), answered once it is there.
    pub fn request_state(&mut self, position: u16, state: &str) -> Result<String, ClientError> {
        let v = self.call(Request::State { position, state: state.to_string() })?;
        self.field(v, "state")
    }
}

/// Whether `e` is the master saying the request is not its to take (and which kind).
pub fn kind_of(e: &ClientError) -> Option<ErrorKind> {
    e.remote().map(|r| r.kind)
}
