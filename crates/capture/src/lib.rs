//! EtherCAT traffic in capture files: pcap and pcapng, read and written with the `pcap-file`
//! crate. Readers yield every packet with its 1-based frame number (the number Wireshark shows),
//! so that tools can name the frame an error is in.
use std::borrow::Cow;
use std::io::Write;
use std::time::Duration;

use pcap_file::pcap::{PcapHeader, PcapPacket, PcapReader, PcapWriter};
use pcap_file::pcapng::blocks::enhanced_packet::EnhancedPacketBlock;
use pcap_file::pcapng::blocks::interface_description::InterfaceDescriptionBlock;
use pcap_file::pcapng::{Block, PcapNgReader, PcapNgWriter};
use pcap_file::{DataLink, PcapError};

/// LINKTYPE_ETHERNET.
pub const LINKTYPE_ETHERNET: u32 = 1;

#[derive(Debug, thiserror::Error)]
pub enum CaptureError {
    #[error("not a pcap or pcapng file (first bytes {0:02x?})")]
    UnknownFormat(Vec<u8>),
    #[error("malformed capture at frame {frame}")]
    Format { frame: usize, source: PcapError },
    #[error("malformed capture file header")]
    Header { source: PcapError },
    #[error("frame {frame} refers to interface {interface}, which the file does not describe")]
    NoInterface { frame: usize, interface: u32 },
    #[error(
        "frame {frame}: its timestamp (with its interface's offset, if_tsoffset) lies beyond 2554-07-21, the last instant 64 bits of nanoseconds since 1970 hold"
    )]
    TimestampRange { frame: usize },
    #[error("writing capture: {0}")]
    Write(#[source] PcapError),
}

/// One captured packet.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct Packet<'a> {
    /// 1-based, counting every packet in the file.
    pub number: usize,
    /// Time since the Unix epoch.
    pub timestamp: Duration,
    pub link_type: u32,
    /// Length on the wire; larger than `data.len()` when the capture was truncated by a snaplen.
    pub original_len: u32,
    pub data: Cow<'a, [u8]>,
}

impl Packet<'_> {
    pub fn is_truncated(&self) -> bool {
        (self.data.len() as u64) < self.original_len as u64
    }
}

const PCAPNG_MAGIC: [u8; 4] = [0x0A, 0x0D, 0x0D, 0x0A];
/// pcap's magic numbers, microsecond and nanosecond, in either byte order.
const PCAP_MAGICS: [[u8; 4]; 4] =
    [[0xD4, 0xC3, 0xB2, 0xA1], [0xA1, 0xB2, 0xC3, 0xD4], [0x4D, 0x3C, 0xB2, 0xA1], [0xA1, 0xB2, 0x3C, 0x4D]];

/// Whether a file beginning with `first` (its first four bytes) can be a pcap or pcapng
/// capture: a reader can refuse anything else before it reads the rest.
pub fn begins_like_a_capture(first: &[u8]) -> bool {
    first.len() >= 4 && (first[..4] == PCAPNG_MAGIC || PCAP_MAGICS.iter().any(|m| first[..4] == m[..]))
}

/// Reads every packet of a pcap or pcapng file held in memory.
pub fn read_packets(bytes: &[u8]) -> Result<Vec<Packet<'static>>, CaptureError> {
    let mut out = Vec::new();
    for_each_packet(bytes, |p| {
        out.push(Packet { data: Cow::Owned(p.data.into_owned()), ..p });
        Ok(())
    })?;
    Ok(out)
}

/// Calls `f` for every packet, in file order, without collecting them.
pub fn for_each_packet(
    bytes: &[u8],
    mut f: impl FnMut(Packet<'_>) -> Result<(), CaptureError>,
) -> Result<(), CaptureError> {
    if bytes.len() < 4 {
        return Err(CaptureError::UnknownFormat(bytes.to_vec()));
    }
    let fmt = |frame| move |source| CaptureError::Format { frame, source };
    if bytes[..4] == PCAPNG_MAGIC {
        let mut reader = PcapNgReader::new(bytes).map_err(|source| CaptureError::Header { source })?;
        // Link type and clock of the interfaces of the current section, in block order.
        let mut interfaces: Vec<(u32, InterfaceClock)> = Vec::new();
        let mut number = 0;
        while let Some(block) = reader.next_block() {
            let block = block.map_err(fmt(number + 1))?;
            // pcap-file 2 hands the timestamp's raw units over as nanoseconds; the interface's
            // if_tsresol says what they are (microseconds unless it says otherwise).
            let (interface, raw, original_len, data) = match block {
                Block::SectionHeader(_) => {
                    interfaces.clear();
                    continue;
                }
                Block::InterfaceDescription(i) => {
                    interfaces.push((u32::from(i.linktype), InterfaceClock::of(&i)));
                    continue;
                }
                Block::EnhancedPacket(p) => {
                    (p.interface_id, Some(p.timestamp.as_nanos() as u64), p.original_len, p.data)
                }
                Block::SimplePacket(p) => (0, None, p.original_len, p.data),
                Block::Packet(p) => (p.interface_id as u32, Some(p.timestamp), p.original_len, p.data),
                _ => continue,
            };
            number += 1;
            let (link_type, clock) =
                *interfaces.get(interface as usize).ok_or(CaptureError::NoInterface { frame: number, interface })?;
            let timestamp = match raw {
                Some(raw) => clock.time(raw).ok_or(CaptureError::TimestampRange { frame: number })?,
                None => Duration::ZERO,
            };
            f(Packet { number, timestamp, link_type, original_len, data })?;
        }
        Ok(())
    } else {
        let mut reader = PcapReader::new(bytes).map_err(|e| match e {
            PcapError::InvalidField(_) => CaptureError::UnknownFormat(bytes[..4].to_vec()),
            source => CaptureError::Header { source },
        })?;
        let header = reader.header();
        let link_type = u32::from(header.datalink);
        let nanos = header.ts_resolution == pcap_file::TsResolution::NanoSecond;
        let mut number = 0;
        // Raw records: pcap-file's checked ones reject a packet longer on the wire than the
        // file's snap length, which is every packet a `tcpdump -s N` cut; such a packet keeps
        // its original length and reads as truncated.
        while let Some(p) = reader.next_raw_packet() {
            number += 1;
            let p = p.map_err(fmt(number))?;
            let frac = if nanos { p.ts_frac as u64 } else { p.ts_frac as u64 * 1_000 };
            let timestamp = Duration::from_secs(p.ts_sec as u64) + Duration::from_nanos(frac);
            let original_len = p.orig_len.max(p.data.len() as u32);
            f(Packet { number, timestamp, link_type, original_len, data: p.data })?;
        }
        Ok(())
    }
}

/// How a pcapng interface counts time: the unit of its timestamps (if_tsresol) and the seconds
/// added to them (if_tsoffset).
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
struct InterfaceClock {
    resolution: u8,
    offset_s: u64,
}

impl InterfaceClock {
    /// The pcapng default when the interface names no resolution: microseconds.
    const DEFAULT_RESOLUTION: u8 = 6;

    fn of(idb: &InterfaceDescriptionBlock<'_>) -> Self {
        use pcap_file::pcapng::blocks::interface_description::InterfaceDescriptionOption as Opt;
        let mut clock = InterfaceClock { resolution: Self::DEFAULT_RESOLUTION, offset_s: 0 };
        for option in &idb.options {
            match option {
                Opt::IfTsResol(r) => clock.resolution = *r,
                Opt::IfTsOffset(s) => clock.offset_s = *s,
                _ => {}
            }
        }
        clock
    }

    /// The time of `raw` units since the epoch. Bit 7 of the resolution set: units of 2⁻ⁿ s,
    /// else 10⁻ⁿ s; what is finer than a nanosecond is dropped (a `Duration` counts
    /// nanoseconds). `None` beyond 2⁶⁴ − 1 ns: every tool takes the time as u64 nanoseconds.
    fn time(self, raw: u64) -> Option<Duration> {
        const NS_PER_S: u128 = 1_000_000_000;
        let n = (self.resolution & 0x7F) as u32;
        let ns: u128 = if self.resolution & 0x80 != 0 {
            (raw as u128 * NS_PER_S) >> n
        } else if n <= 9 {
            raw as u128 * 10u128.pow(9 - n)
        } else {
            // 10^(n−9) beyond 10³⁸ exceeds every u64: the time is below a nanosecond.
            10u128.checked_pow(n - 9).map_or(0, |d| raw as u128 / d)
        };
        let ns = ns.checked_add(self.offset_s as u128 * NS_PER_S)?;
        u64::try_from(ns).ok().map(Duration::from_nanos)
    }
}

/// Which container to write.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Format {
    Pcap,
    PcapNg,
}

/// Writes Ethernet frames to a pcap or pcapng stream.
pub enum CaptureWriter<W: Write> {
    Pcap(PcapWriter<W>),
    PcapNg(PcapNgWriter<W>),
}

impl<W: Write> std::fmt::Debug for CaptureWriter<W> {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.write_str(match self {
            CaptureWriter::Pcap(_) => "CaptureWriter::Pcap",
            CaptureWriter::PcapNg(_) => "CaptureWriter::PcapNg",
        })
    }
}

impl<W: Write> CaptureWriter<W> {
    /// Starts a file of Ethernet frames with nanosecond timestamps.
    pub fn new(out: W, format: Format) -> Result<Self, CaptureError> {
        Ok(match format {
            Format::Pcap => {
                let header = PcapHeader {
                    datalink: DataLink::ETHERNET,
                    ts_resolution: pcap_file::TsResolution::NanoSecond,
                    ..Default::default()
                };
                CaptureWriter::Pcap(PcapWriter::with_header(out, header).map_err(CaptureError::Write)?)
            }
            Format::PcapNg => {
                let mut w = PcapNgWriter::new(out).map_err(CaptureError::Write)?;
                let idb = InterfaceDescriptionBlock {
                    linktype: DataLink::ETHERNET,
                    snaplen: 0,
                    // if_tsresol = 9: nanoseconds.
                    options: vec![
                        pcap_file::pcapng::blocks::interface_description::InterfaceDescriptionOption::IfTsResol(9),
                    ],
                };
                w.write_pcapng_block(idb).map_err(CaptureError::Write)?;
                CaptureWriter::PcapNg(w)
            }
        })
    }

    /// Appends one frame (without FCS) captured at `timestamp` since the Unix epoch.
    pub fn write(&mut self, timestamp: Duration, frame: &[u8]) -> Result<(), CaptureError> {
        match self {
            CaptureWriter::Pcap(w) => w
                .write_packet(&PcapPacket::new(timestamp, frame.len() as u32, frame))
                .map(|_| ())
                .map_err(CaptureError::Write),
            CaptureWriter::PcapNg(w) => {
                let epb = EnhancedPacketBlock {
                    interface_id: 0,
                    timestamp,
                    original_len: frame.len() as u32,
                    data: Cow::Borrowed(frame),
                    options: vec![],
                };
                w.write_pcapng_block(epb).map(|_| ()).map_err(CaptureError::Write)
            }
        }
    }

    pub fn into_inner(self) -> W {
        match self {
            CaptureWriter::Pcap(w) => w.into_writer(),
            CaptureWriter::PcapNg(w) => w.into_inner(),
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn write_then_read_both_formats() {
        for format in [Format::Pcap, Format::PcapNg] {
            let mut w = CaptureWriter::new(Vec::new(), format).unwrap();
            let t0 = Duration::new(1_700_000_000, 123_456_789);
            w.write(t0, &[0xAA; 60]).unwrap();
            w.write(t0 + Duration::from_nanos(1), &[0xBB; 64]).unwrap();
            let bytes = w.into_inner();
            let p = read_packets(&bytes).unwrap();
            assert_eq!(p.len(), 2, "{format:?}");
            assert_eq!(p[0].number, 1);
            assert_eq!(p[0].timestamp, t0, "{format:?}");
            assert_eq!(p[1].timestamp, t0 + Duration::from_nanos(1), "{format:?}");
            assert_eq!(p[1].link_type, LINKTYPE_ETHERNET);
            assert_eq!(&*p[1].data, &[0xBB; 64]);
        }
    }

    /// A pcapng file of one interface with `options`, and one packet of `raw` timestamp units.
    fn pcapng_with_clock(options: Vec<InterfaceDescriptionOption>, raw: u64) -> Vec<u8> {
        let mut w = PcapNgWriter::new(Vec::new()).unwrap();
        w.write_pcapng_block(InterfaceDescriptionBlock { linktype: DataLink::ETHERNET, snaplen: 0, options }).unwrap();
        // pcap-file 2 writes a `Duration`'s nanoseconds as the raw units.
        let epb = EnhancedPacketBlock {
            interface_id: 0,
            timestamp: Duration::from_nanos(raw),
            original_len: 60,
            data: Cow::Borrowed(&[0; 60]),
            options: vec![],
        };
        w.write_pcapng_block(epb).unwrap();
        w.into_inner()
    }

    use pcap_file::pcapng::blocks::interface_description::InterfaceDescriptionOption;

    #[test]
    fn pcapng_timestamps_are_in_the_interfaces_units() {
        use InterfaceDescriptionOption::{IfTsOffset, IfTsResol};
        let t = |options, raw| read_packets(&pcapng_with_clock(options, raw)).unwrap()[0].timestamp;
        // No if_tsresol: microseconds (pcapng's default; Wireshark on Windows and Linux writes
        // such files). 1 657 036 734 840 250 µs is 2022-07-05 15:58:54.840250 UTC.
        assert_eq!(t(vec![], 1_657_036_734_840_250), Duration::new(1_657_036_734, 840_250_000));
        assert_eq!(t(vec![IfTsResol(6)], 1_500_001), Duration::new(1, 500_001_000));
        assert_eq!(t(vec![IfTsResol(9)], 1_500_000_001), Duration::new(1, 500_000_001));
        assert_eq!(t(vec![IfTsResol(3)], 2_001), Duration::new(2, 1_000_000));
        assert_eq!(t(vec![IfTsResol(0)], 7), Duration::from_secs(7));
        // Picoseconds: what is below a nanosecond is dropped.
        assert_eq!(t(vec![IfTsResol(12)], 1_000_000_001_999), Duration::new(1, 1));
        assert_eq!(t(vec![IfTsResol(127)], u64::MAX), Duration::ZERO);
        // Bit 7: powers of two. 2⁻²⁰ s units, 3·2²⁰ + 2¹⁹ of them = 3.5 s.
        assert_eq!(t(vec![IfTsResol(0x80 | 20)], 3 << 20 | 1 << 19), Duration::new(3, 500_000_000));
        assert_eq!(t(vec![IfTsResol(0x80)], 5), Duration::from_secs(5));
        // Whole seconds of if_tsoffset are added.
        assert_eq!(t(vec![IfTsResol(9), IfTsOffset(100)], 5), Duration::new(100, 5));
        // Up to 2⁶⁴ − 1 ns, the last instant the tools' u64 nanoseconds hold.
        assert_eq!(t(vec![IfTsResol(9)], u64::MAX), Duration::from_nanos(u64::MAX));
        let secs = u64::MAX / 1_000_000_000;
        assert_eq!(t(vec![IfTsResol(0)], secs), Duration::from_secs(secs));
    }

    #[test]
    fn a_timestamp_beyond_u64_nanoseconds_is_an_error_naming_the_frame() {
        use InterfaceDescriptionOption::{IfTsOffset, IfTsResol};
        let secs = u64::MAX / 1_000_000_000;
        for (options, raw) in [
            (vec![IfTsResol(0)], secs + 1),
            (vec![IfTsResol(0)], u64::MAX),
            (vec![IfTsResol(9), IfTsOffset(1)], u64::MAX),
            (vec![IfTsResol(9), IfTsOffset(u64::MAX)], 0),
        ] {
            let bytes = pcapng_with_clock(options.clone(), raw);
            assert!(matches!(read_packets(&bytes), Err(CaptureError::TimestampRange { frame: 1 })), "{options:?}");
        }
        let bytes = pcapng_with_clock(vec![IfTsResol(0)], u64::MAX);
        assert_eq!(
            read_packets(&bytes).unwrap_err().to_string(),
            "frame 1: its timestamp (with its interface's offset, if_tsoffset) lies beyond 2554-07-21, the last instant 64 bits of nanoseconds since 1970 hold"
        );
    }

    #[test]
    fn garbage_is_an_error_not_a_panic() {
        assert!(matches!(read_packets(b"hi"), Err(CaptureError::UnknownFormat(_))));
        assert!(read_packets(b"this is not a capture file").is_err());
        let mut w = CaptureWriter::new(Vec::new(), Format::PcapNg).unwrap();
        w.write(Duration::ZERO, &[1; 60]).unwrap();
        let bytes = w.into_inner();
        for cut in 1..bytes.len() {
            let _ = read_packets(&bytes[..cut]);
        }
    }
}
