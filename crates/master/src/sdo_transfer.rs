//! SDO transfers and SDO information as steps without I/O: each takes the slave's CoE reply and
//! gives the next request, or its result. The blocking CoE client ([`crate::Coe`]) and the
//! acyclic side of a running master ([`crate::acyclic`]) drive the same steps, one waiting for
//! each reply, the other one datagram at a time in a cycle's spare time.
use ferrocat_wire::coe::{self, AbortCode, CoeHeader, CoeMessage, CoeService, Sdo, SdoInfo};

use crate::error::{MasterError, Result, SlaveError};

/// What a transfer wants after a reply.
#[derive(Debug)]
pub(crate) enum Step<T> {
    /// This CoE message (CoE header and service data) next.
    Send(Vec<u8>),
    /// Another reply to the same request (SDO information comes in fragments).
    Await,
    /// The transfer is over.
    Done(T),
}

/// The slave a transfer talks to, for its errors.
#[derive(Debug, Clone)]
pub(crate) struct Peer {
    pub position: u16,
    pub name: String,
    /// The receive mailbox's length: a segment fills it.
    pub mailbox_len: usize,
}

impl Peer {
    fn abort(&self, index: u16, subindex: u8, code: AbortCode) -> MasterError {
        let e = MasterError::Abort { position: self.position, name: self.name.clone(), index, subindex, code };
        tracing::debug!("{e}");
        e
    }

    fn error(&self, e: SlaveError) -> MasterError {
        MasterError::of(self.position, &self.name, e)
    }

    fn unexpected(&self, m: &CoeMessage<'_>) -> MasterError {
        self.error(SlaveError::UnexpectedReply(format!("{m:?}")))
    }

    /// `sdo` as a CoE SDO request.
    fn request(&self, sdo: Sdo<'_>) -> Result<Vec<u8>> {
        let mut b = vec![0u8; 2 + self.mailbox_len.max(64)];
        CoeHeader::new(CoeService::SDO_REQUEST).emit(&mut b)?;
        let n = sdo.emit(&mut b[2..])?;
        b.truncate(2 + n);
        Ok(b)
    }
}

/// An SDO upload (expedited, normal or segmented, as the slave answers) or download
/// (expedited up to 4 bytes, normal while it fits the mailbox, segmented beyond).
#[derive(Debug)]
pub(crate) struct SdoTransfer {
    peer: Peer,
    index: u16,
    subindex: u8,
    complete_access: bool,
    kind: Kind,
}

#[derive(Debug)]
enum Kind {
    Upload { total: usize, data: Vec<u8>, toggle: bool },
    Download { data: Vec<u8>, at: usize, toggle: bool },
}

impl SdoTransfer {
    /// A read of `index:subindex` (the whole object with `complete_access`).
    pub fn upload(peer: Peer, index: u16, subindex: u8, complete_access: bool) -> Self {
        let kind = Kind::Upload { total: 0, data: Vec::new(), toggle: false };
        SdoTransfer { peer, index, subindex, complete_access, kind }
    }

    /// A write of `data` to `index:subindex`.
    pub fn download(peer: Peer, index: u16, subindex: u8, complete_access: bool, data: Vec<u8>) -> Self {
        let kind = Kind::Download { data, at: 0, toggle: false };
        SdoTransfer { peer, index, subindex, complete_access, kind }
    }

    /// Whether it writes.
    pub fn is_download(&self) -> bool {
        matches!(self.kind, Kind::Download { .. })
    }

    /// The first request.
    pub fn start(&mut self) -> Result<Vec<u8>> {
        let (index, subindex, complete_access) = (self.index, self.subindex, self.complete_access);
        match &mut self.kind {
            Kind::Upload { .. } => {
                self.peer.request(Sdo::UploadRequest { index, subindex, complete_access, reserved: [0; 4] })
            }
            Kind::Download { data, at, .. } if (1..=4).contains(&data.len()) => {
                let mut four = [0u8; 4];
                four[..data.len()].copy_from_slice(data);
                *at = data.len();
                let size = Some(data.len() as u8);
                self.peer.request(Sdo::DownloadExpeditedRequest { index, subindex, complete_access, size, data: four })
            }
            Kind::Download { data, at, .. } => {
                // The mailbox less its header (6), the CoE header (2) and the SDO header with
                // the complete size (8).
                let first = data.len().min(self.peer.mailbox_len.saturating_sub(6 + 2 + 8));
                *at = first;
                let complete_size = data.len() as u32;
                self.peer.request(Sdo::DownloadNormalRequest {
                    index,
                    subindex,
                    complete_access,
                    complete_size,
                    data: &data[..first],
                })
            }
        }
    }

    /// The slave's reply (a CoE message): the next request, or the data read (empty after a
    /// download).
    pub fn on_reply(&mut self, reply: &[u8]) -> Result<Step<Vec<u8>>> {
        let (_, msg) = coe::parse(reply)?;
        if let CoeMessage::Sdo(Sdo::Abort { code, .. }) = msg {
            return Err(self.peer.abort(self.index, self.subindex, code));
        }
        match &mut self.kind {
            Kind::Upload { total, data, toggle } => match msg {
                CoeMessage::Sdo(Sdo::UploadExpeditedResponse { size, data: d, .. }) if data.is_empty() => {
                    Ok(Step::Done(d[..size.unwrap_or(4) as usize].to_vec()))
                }
                CoeMessage::Sdo(Sdo::UploadNormalResponse { complete_size, data: d, .. }) if data.is_empty() => {
                    *total = complete_size as usize;
                    data.extend_from_slice(&d[..d.len().min(*total)]);
                    if data.len() >= *total {
                        return Ok(Step::Done(std::mem::take(data)));
                    }
                    self.peer.request(Sdo::UploadSegmentRequest { toggle: *toggle, reserved: [0; 7] }).map(Step::Send)
                }
                CoeMessage::Sdo(s @ Sdo::UploadSegmentResponse { toggle: t, last, .. }) if *total > 0 => {
                    if t != *toggle {
                        return Err(self.peer.error(SlaveError::ToggleOutOfStep));
                    }
                    data.extend_from_slice(s.segment_data().unwrap_or(&[]));
                    *toggle = !*toggle;
                    if last || data.len() >= *total {
                        data.truncate(*total);
                        return Ok(Step::Done(std::mem::take(data)));
                    }
                    self.peer.request(Sdo::UploadSegmentRequest { toggle: *toggle, reserved: [0; 7] }).map(Step::Send)
                }
                other => Err(self.peer.unexpected(&other)),
            },
            Kind::Download { data, at, toggle } => {
                match msg {
                    CoeMessage::Sdo(Sdo::DownloadResponse { .. } | Sdo::DownloadSegmentResponse { .. }) => {}
                    other => return Err(self.peer.unexpected(&other)),
                }
                if *at >= data.len() {
                    return Ok(Step::Done(Vec::new()));
                }
                // The mailbox less its header (6), the CoE header (2) and the segment's (1).
                let n = (data.len() - *at).min(self.peer.mailbox_len.saturating_sub(6 + 2 + 1)).max(1);
                let mut seg = data[*at..*at + n].to_vec();
                let unused = 7usize.saturating_sub(n) as u8;
                seg.resize(n.max(7), 0);
                *at += n;
                let last = *at >= data.len();
                let t = *toggle;
                *toggle = !*toggle;
                self.peer
                    .request(Sdo::DownloadSegmentRequest { toggle: t, last, unused, segment: &seg })
                    .map(Step::Send)
            }
        }
    }
}

/// An SDO information request and its reply's fragments.
#[derive(Debug)]
pub(crate) struct InfoTransfer {
    peer: Peer,
    /// The object asked about, for an error reply (0 for the list).
    index: u16,
    request: Vec<u8>,
    parts: Vec<Vec<u8>>,
}

impl InfoTransfer {
    /// `req` to the slave.
    pub fn new(peer: Peer, req: SdoInfo<'_>) -> Result<Self> {
        let index = match req {
            SdoInfo::ObjectDescriptionRequest { index, .. } | SdoInfo::EntryDescriptionRequest { index, .. } => index,
            _ => 0,
        };
        let mut b = vec![0u8; 64];
        CoeHeader::new(CoeService::SDO_INFORMATION).emit(&mut b)?;
        let n = req.emit(&mut b[2..])?;
        b.truncate(2 + n);
        Ok(InfoTransfer { peer, index, request: b, parts: Vec::new() })
    }

    /// The slave asked.
    pub fn peer(&self) -> &Peer {
        &self.peer
    }

    /// The request.
    pub fn start(&mut self) -> Result<Vec<u8>> {
        Ok(self.request.clone())
    }

    /// A reply: another fragment awaited, or every fragment (each a whole CoE message).
    pub fn on_reply(&mut self, reply: &[u8]) -> Result<Step<Vec<Vec<u8>>>> {
        let fragments_left = match coe::parse(reply)?.1 {
            CoeMessage::Information(SdoInfo::Error { code, .. }) => {
                return Err(self.peer.abort(self.index, 0, code));
            }
            CoeMessage::Information(i) => i.header().fragments_left,
            other => return Err(self.peer.unexpected(&other)),
        };
        self.parts.push(reply.to_vec());
        if fragments_left == 0 {
            return Ok(Step::Done(std::mem::take(&mut self.parts)));
        }
        Ok(Step::Await)
    }
}
