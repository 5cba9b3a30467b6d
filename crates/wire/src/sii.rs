//! SII EEPROM images (esc-spec §5.4; ETG.1000.6 / ETG.2010): the 64-word header with its CRC
//! and the category list (strings, general, FMMU, SyncManager, TxPDO, RxPDO, DC, others).
//!
//! [`SiiImage`] reads an image without allocating. With the `alloc` feature, [`SiiInfo`] is
//! the owned description: `SiiInfo::from_image` and `SiiInfo::to_image` round-trip.
use crate::bytes::{need, slice_at, u16_at, u32_at, u8_at};
use crate::{Error, Result};

/// Bytes in the fixed header (64 words); categories start here.
pub const HEADER_LEN: usize = 128;
pub const CATEGORY_HEADER_LEN: usize = 4;

/// Category types (ETG.2010 Table 2).
pub mod category {
    pub const NOP: u16 = 0;
    pub const STRINGS: u16 = 10;
    pub const DATA_TYPES: u16 = 20;
    pub const GENERAL: u16 = 30;
    pub const FMMU: u16 = 40;
    pub const SYNC_MANAGER: u16 = 41;
    pub const FMMU_EXTENDED: u16 = 42;
    pub const SYNC_UNIT: u16 = 43;
    pub const TXPDO: u16 = 50;
    pub const RXPDO: u16 = 51;
    pub const DC: u16 = 60;
    pub const END: u16 = 0xFFFF;

    pub fn name(kind: u16) -> &'static str {
        match kind {
            NOP => "NOP",
            STRINGS => "Strings",
            DATA_TYPES => "DataTypes",
            GENERAL => "General",
            FMMU => "FMMU",
            SYNC_MANAGER => "SyncM",
            FMMU_EXTENDED => "FMMUX",
            SYNC_UNIT => "SyncUnit",
            TXPDO => "TxPDO",
            RXPDO => "RxPDO",
            DC => "DC",
            END => "End",
            _ => "vendor-specific",
        }
    }
}

/// Mailbox protocol bits of header word 0x1C.
pub mod mailbox_protocol {
    pub const AOE: u16 = 0x01;
    pub const EOE: u16 = 0x02;
    pub const COE: u16 = 0x04;
    pub const FOE: u16 = 0x08;
    pub const SOE: u16 = 0x10;
    pub const VOE: u16 = 0x20;
}

/// CRC-8 of the first 14 header bytes: polynomial x⁸+x²+x+1, initial 0xFF, MSB first
/// (ETG.1000.6; esc-spec §5.4).
pub fn header_crc(bytes: &[u8]) -> u8 {
    let mut crc = 0xFFu8;
    for &b in bytes.iter().take(14) {
        crc ^= b;
        for _ in 0..8 {
            crc = if crc & 0x80 != 0 { (crc << 1) ^ 0x07 } else { crc << 1 };
        }
    }
    crc
}

/// The fixed 64-word header, every word kept.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct SiiHeader {
    pub pdi_control: u16,
    pub pdi_config: u16,
    /// SYNC pulse length in 10 ns units (→ 0x0982).
    pub sync_impulse_len: u16,
    pub pdi_config2: u16,
    pub station_alias: u16,
    pub reserved_05: [u16; 2],
    pub checksum: u16,
    pub vendor_id: u32,
    pub product_code: u32,
    pub revision: u32,
    pub serial: u32,
    pub execution_delay: u16,
    pub port0_delay: u16,
    pub port1_delay: u16,
    pub reserved_13: u16,
    pub bootstrap_rx_offset: u16,
    pub bootstrap_rx_size: u16,
    pub bootstrap_tx_offset: u16,
    pub bootstrap_tx_size: u16,
    /// Standard mailbox, master → slave (SM0).
    pub mailbox_rx_offset: u16,
    pub mailbox_rx_size: u16,
    /// Standard mailbox, slave → master (SM1).
    pub mailbox_tx_offset: u16,
    pub mailbox_tx_size: u16,
    pub mailbox_protocols: u16,
    pub reserved_1d: [u16; 33],
    /// EEPROM size: (value + 1) KiBit.
    pub eeprom_size: u16,
    pub version: u16,
}

impl Default for SiiHeader {
    fn default() -> Self {
        SiiHeader {
            pdi_control: 0,
            pdi_config: 0,
            sync_impulse_len: 0,
            pdi_config2: 0,
            station_alias: 0,
            reserved_05: [0; 2],
            checksum: 0,
            vendor_id: 0,
            product_code: 0,
            revision: 0,
            serial: 0,
            execution_delay: 0,
            port0_delay: 0,
            port1_delay: 0,
            reserved_13: 0,
            bootstrap_rx_offset: 0,
            bootstrap_rx_size: 0,
            bootstrap_tx_offset: 0,
            bootstrap_tx_size: 0,
            mailbox_rx_offset: 0,
            mailbox_rx_size: 0,
            mailbox_tx_offset: 0,
            mailbox_tx_size: 0,
            mailbox_protocols: 0,
            reserved_1d: [0; 33],
            eeprom_size: 0,
            version: 0,
        }
    }
}

impl SiiHeader {
    pub fn parse(buf: &[u8]) -> Result<Self> {
        need(buf, 0, HEADER_LEN, "SII header")?;
        let w = |i: usize| u16::from_le_bytes([buf[2 * i], buf[2 * i + 1]]);
        let d = |i: usize| w(i) as u32 | (w(i + 1) as u32) << 16;
        let mut reserved_1d = [0u16; 33];
        for (k, r) in reserved_1d.iter_mut().enumerate() {
            *r = w(0x1D + k);
        }
        Ok(SiiHeader {
            pdi_control: w(0),
            pdi_config: w(1),
            sync_impulse_len: w(2),
            pdi_config2: w(3),
            station_alias: w(4),
            reserved_05: [w(5), w(6)],
            checksum: w(7),
            vendor_id: d(8),
            product_code: d(0xA),
            revision: d(0xC),
            serial: d(0xE),
            execution_delay: w(0x10),
            port0_delay: w(0x11),
            port1_delay: w(0x12),
            reserved_13: w(0x13),
            bootstrap_rx_offset: w(0x14),
            bootstrap_rx_size: w(0x15),
            bootstrap_tx_offset: w(0x16),
            bootstrap_tx_size: w(0x17),
            mailbox_rx_offset: w(0x18),
            mailbox_rx_size: w(0x19),
            mailbox_tx_offset: w(0x1A),
            mailbox_tx_size: w(0x1B),
            mailbox_protocols: w(0x1C),
            reserved_1d,
            eeprom_size: w(0x3E),
            version: w(0x3F),
        })
    }

    pub fn to_bytes(&self) -> [u8; HEADER_LEN] {
        let mut words = [0u16; 64];
        words[0] = self.pdi_control;
        words[1] = self.pdi_config;
        words[2] = self.sync_impulse_len;
        words[3] = self.pdi_config2;
        words[4] = self.station_alias;
        words[5] = self.reserved_05[0];
        words[6] = self.reserved_05[1];
        words[7] = self.checksum;
        for (i, v) in [self.vendor_id, self.product_code, self.revision, self.serial].into_iter().enumerate() {
            words[8 + 2 * i] = v as u16;
            words[9 + 2 * i] = (v >> 16) as u16;
        }
        words[0x10] = self.execution_delay;
        words[0x11] = self.port0_delay;
        words[0x12] = self.port1_delay;
        words[0x13] = self.reserved_13;
        words[0x14] = self.bootstrap_rx_offset;
        words[0x15] = self.bootstrap_rx_size;
        words[0x16] = self.bootstrap_tx_offset;
        words[0x17] = self.bootstrap_tx_size;
        words[0x18] = self.mailbox_rx_offset;
        words[0x19] = self.mailbox_rx_size;
        words[0x1A] = self.mailbox_tx_offset;
        words[0x1B] = self.mailbox_tx_size;
        words[0x1C] = self.mailbox_protocols;
        words[0x1D..0x3E].copy_from_slice(&self.reserved_1d);
        words[0x3E] = self.eeprom_size;
        words[0x3F] = self.version;
        let mut b = [0u8; HEADER_LEN];
        for (i, w) in words.iter().enumerate() {
            b[2 * i..2 * i + 2].copy_from_slice(&w.to_le_bytes());
        }
        b
    }

    /// The checksum the header should carry.
    pub fn computed_checksum(&self) -> u16 {
        header_crc(&self.to_bytes()) as u16
    }

    /// Sets the checksum word from the other fields.
    pub fn with_checksum(mut self) -> Self {
        self.checksum = self.computed_checksum();
        self
    }

    pub fn checksum_ok(&self) -> bool {
        self.checksum & 0xFF == self.computed_checksum()
    }

    /// EEPROM size in bytes, from word 0x3E ((value + 1) KiBit).
    pub fn eeprom_size_bytes(&self) -> usize {
        (self.eeprom_size as usize + 1) * 128
    }
}

/// One category: type and data (whose length is the header's word count × 2).
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct Category<'a> {
    pub kind: u16,
    /// Byte offset of the category header in the image.
    pub offset: usize,
    pub data: &'a [u8],
}

/// A zero-copy view of an SII image.
#[derive(Debug, Clone, Copy)]
pub struct SiiImage<'a> {
    bytes: &'a [u8],
    header: SiiHeader,
}

impl<'a> SiiImage<'a> {
    /// Reads the header. Categories are read lazily by [`SiiImage::categories`]; the CRC is not
    /// enforced here (real devices ship images with bad CRCs) but reported by `check_crc`.
    pub fn parse(bytes: &'a [u8]) -> Result<Self> {
        let header = SiiHeader::parse(bytes)?;
        Ok(SiiImage { bytes, header })
    }

    pub fn header(&self) -> &SiiHeader {
        &self.header
    }

    pub fn bytes(&self) -> &'a [u8] {
        self.bytes
    }

    pub fn check_crc(&self) -> Result<()> {
        let expected = self.header.computed_checksum() as u32;
        let actual = (self.header.checksum & 0xFF) as u32;
        if expected == actual {
            Ok(())
        } else {
            Err(Error::Checksum { what: "SII header CRC (word 7)", offset: 14, expected, actual })
        }
    }

    /// The categories in image order, up to the end marker (0xFFFF) or the end of the image.
    pub fn categories(&self) -> Categories<'a> {
        Categories { bytes: self.bytes, offset: HEADER_LEN, done: false }
    }

    /// The first category of `kind`, if any (errors in earlier categories are returned).
    pub fn find(&self, kind: u16) -> Result<Option<Category<'a>>> {
        for c in self.categories() {
            let c = c?;
            if c.kind == kind {
                return Ok(Some(c));
            }
        }
        Ok(None)
    }

    pub fn strings(&self) -> Result<Strings<'a>> {
        match self.find(category::STRINGS)? {
            Some(c) => Strings::parse(c.data).map_err(|e| e.shifted(c.offset + CATEGORY_HEADER_LEN)),
            None => Ok(Strings::empty()),
        }
    }

    pub fn general(&self) -> Result<Option<General>> {
        match self.find(category::GENERAL)? {
            Some(c) => General::parse(c.data).map(Some).map_err(|e| e.shifted(c.offset + CATEGORY_HEADER_LEN)),
            None => Ok(None),
        }
    }
}

/// Iterator over categories; yields an error once and stops if a category overruns the image.
#[derive(Debug, Clone)]
pub struct Categories<'a> {
    bytes: &'a [u8],
    offset: usize,
    done: bool,
}

impl<'a> Iterator for Categories<'a> {
    type Item = Result<Category<'a>>;
    fn next(&mut self) -> Option<Self::Item> {
        if self.done || self.offset + 2 > self.bytes.len() {
            return None;
        }
        let kind = u16::from_le_bytes([self.bytes[self.offset], self.bytes[self.offset + 1]]);
        if kind == category::END {
            self.done = true;
            return None;
        }
        let at = self.offset;
        let words = match u16_at(self.bytes, at + 2, "SII category size") {
            Ok(w) => w as usize,
            Err(e) => {
                self.done = true;
                return Some(Err(e));
            }
        };
        let len = words * 2;
        let start = at + CATEGORY_HEADER_LEN;
        if start + len > self.bytes.len() {
            self.done = true;
            return Some(Err(Error::BadLength {
                what: "SII category size",
                offset: at + 2,
                claimed: len,
                limit: self.bytes.len() - start,
            }));
        }
        self.offset = start + len;
        Some(Ok(Category { kind, offset: at, data: &self.bytes[start..start + len] }))
    }
}

/// The strings category: 1-based indices, index 0 means "no string".
#[derive(Debug, Clone, Copy)]
pub struct Strings<'a> {
    data: &'a [u8],
    count: u8,
}

impl<'a> Strings<'a> {
    pub fn empty() -> Self {
        Strings { data: &[], count: 0 }
    }

    /// Validates the whole list once so that lookups cannot fail later.
    pub fn parse(data: &'a [u8]) -> Result<Self> {
        let count = u8_at(data, 0, "SII string count")?;
        let mut off = 1;
        for _ in 0..count {
            let len = u8_at(data, off, "SII string length")? as usize;
            slice_at(data, off + 1, len, "SII string")?;
            off += 1 + len;
        }
        Ok(Strings { data, count })
    }

    pub fn len(&self) -> usize {
        self.count as usize
    }

    pub fn is_empty(&self) -> bool {
        self.count == 0
    }

    /// String `index` (1-based) as raw bytes.
    pub fn get(&self, index: u8) -> Option<&'a [u8]> {
        if index == 0 || index > self.count {
            return None;
        }
        let mut off = 1;
        for i in 1..=self.count {
            let len = *self.data.get(off)? as usize;
            if i == index {
                return self.data.get(off + 1..off + 1 + len);
            }
            off += 1 + len;
        }
        None
    }

    pub fn iter(&self) -> impl Iterator<Item = &'a [u8]> + '_ {
        (1..=self.count).filter_map(|i| self.get(i))
    }

    /// Bytes the list occupies (count byte + strings), without padding.
    pub fn used_len(&self) -> usize {
        1 + self.iter().map(|s| 1 + s.len()).sum::<usize>()
    }
}

/// The general category (type 30), 32 bytes.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
pub struct General {
    pub group_idx: u8,
    pub image_idx: u8,
    pub order_idx: u8,
    pub name_idx: u8,
    pub reserved_4: u8,
    pub coe_details: u8,
    pub foe_details: u8,
    pub eoe_details: u8,
    pub soe_channels: u8,
    pub ds402_channels: u8,
    pub sysman_class: u8,
    pub flags: u8,
    /// Current consumption on E-Bus in mA; negative values are what a coupler feeds in.
    pub current_on_ebus_ma: i16,
    pub group_idx_dup: u8,
    pub reserved_15: u8,
    /// Physical port types, 4 bits per port.
    pub physical_ports: u16,
    pub physical_memory_address: u16,
    pub reserved_20: [u8; 12],
}

impl General {
    pub const LEN: usize = 32;

    pub fn parse(d: &[u8]) -> Result<Self> {
        need(d, 0, Self::LEN, "SII general category")?;
        let mut reserved_20 = [0; 12];
        reserved_20.copy_from_slice(&d[20..32]);
        Ok(General {
            group_idx: d[0],
            image_idx: d[1],
            order_idx: d[2],
            name_idx: d[3],
            reserved_4: d[4],
            coe_details: d[5],
            foe_details: d[6],
            eoe_details: d[7],
            soe_channels: d[8],
            ds402_channels: d[9],
            sysman_class: d[10],
            flags: d[11],
            current_on_ebus_ma: i16::from_le_bytes([d[12], d[13]]),
            group_idx_dup: d[14],
            reserved_15: d[15],
            physical_ports: u16::from_le_bytes([d[16], d[17]]),
            physical_memory_address: u16::from_le_bytes([d[18], d[19]]),
            reserved_20,
        })
    }

    pub fn to_bytes(&self) -> [u8; 32] {
        let mut d = [0u8; 32];
        d[..12].copy_from_slice(&[
            self.group_idx,
            self.image_idx,
            self.order_idx,
            self.name_idx,
            self.reserved_4,
            self.coe_details,
            self.foe_details,
            self.eoe_details,
            self.soe_channels,
            self.ds402_channels,
            self.sysman_class,
            self.flags,
        ]);
        d[12..14].copy_from_slice(&self.current_on_ebus_ma.to_le_bytes());
        d[14] = self.group_idx_dup;
        d[15] = self.reserved_15;
        d[16..18].copy_from_slice(&self.physical_ports.to_le_bytes());
        d[18..20].copy_from_slice(&self.physical_memory_address.to_le_bytes());
        d[20..].copy_from_slice(&self.reserved_20);
        d
    }
}

/// FMMU usage bytes of category 40.
pub mod fmmu_usage {
    pub const UNUSED: u8 = 0;
    pub const OUTPUTS: u8 = 1;
    pub const INPUTS: u8 = 2;
    pub const SM_STATUS: u8 = 3;
    /// Fill byte of an odd-length list; reads as "unused".
    pub const PAD: u8 = 0xFF;
}

/// One SyncManager entry of category 41 (8 bytes).
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
pub struct SmEntry {
    pub start: u16,
    pub length: u16,
    pub control: u8,
    pub status: u8,
    pub enable: u8,
    /// 0 unused, 1 mailbox out, 2 mailbox in, 3 outputs, 4 inputs.
    pub sm_type: u8,
}

impl SmEntry {
    pub const LEN: usize = 8;
    pub const TYPE_MBX_OUT: u8 = 1;
    pub const TYPE_MBX_IN: u8 = 2;
    pub const TYPE_OUTPUTS: u8 = 3;
    pub const TYPE_INPUTS: u8 = 4;

    pub fn parse(d: &[u8]) -> Result<Self> {
        need(d, 0, Self::LEN, "SII SyncManager entry")?;
        Ok(SmEntry {
            start: u16::from_le_bytes([d[0], d[1]]),
            length: u16::from_le_bytes([d[2], d[3]]),
            control: d[4],
            status: d[5],
            enable: d[6],
            sm_type: d[7],
        })
    }

    pub fn to_bytes(&self) -> [u8; 8] {
        let s = self.start.to_le_bytes();
        let l = self.length.to_le_bytes();
        [s[0], s[1], l[0], l[1], self.control, self.status, self.enable, self.sm_type]
    }
}

/// Iterates fixed-size records of a category (a trailing partial record is padding).
pub fn records(data: &[u8], size: usize) -> impl Iterator<Item = &[u8]> {
    data.chunks_exact(size)
}

/// A PDO header of categories 50/51 (8 bytes) followed by its entries.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
pub struct PdoHeader {
    pub index: u16,
    pub entry_count: u8,
    pub sync_manager: u8,
    pub synchronization: u8,
    pub name_idx: u8,
    pub flags: u16,
}

/// One PDO entry (8 bytes).
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
pub struct PdoEntry {
    pub index: u16,
    pub subindex: u8,
    pub name_idx: u8,
    pub data_type: u8,
    pub bit_len: u8,
    pub flags: u16,
}

impl PdoEntry {
    pub const LEN: usize = 8;
    pub fn parse(d: &[u8]) -> Result<Self> {
        need(d, 0, Self::LEN, "SII PDO entry")?;
        Ok(PdoEntry {
            index: u16::from_le_bytes([d[0], d[1]]),
            subindex: d[2],
            name_idx: d[3],
            data_type: d[4],
            bit_len: d[5],
            flags: u16::from_le_bytes([d[6], d[7]]),
        })
    }
    pub fn to_bytes(&self) -> [u8; 8] {
        let i = self.index.to_le_bytes();
        let f = self.flags.to_le_bytes();
        [i[0], i[1], self.subindex, self.name_idx, self.data_type, self.bit_len, f[0], f[1]]
    }
}

impl PdoHeader {
    pub const LEN: usize = 8;
    pub fn parse(d: &[u8]) -> Result<Self> {
        need(d, 0, Self::LEN, "SII PDO header")?;
        Ok(PdoHeader {
            index: u16::from_le_bytes([d[0], d[1]]),
            entry_count: d[2],
            sync_manager: d[3],
            synchronization: d[4],
            name_idx: d[5],
            flags: u16::from_le_bytes([d[6], d[7]]),
        })
    }
    pub fn to_bytes(&self) -> [u8; 8] {
        let i = self.index.to_le_bytes();
        let f = self.flags.to_le_bytes();
        [i[0], i[1], self.entry_count, self.sync_manager, self.synchronization, self.name_idx, f[0], f[1]]
    }
}

/// Iterator over the PDOs of a TxPDO/RxPDO category: each item is a header and its entries' bytes.
#[derive(Debug, Clone)]
pub struct Pdos<'a> {
    data: &'a [u8],
    offset: usize,
}

impl<'a> Pdos<'a> {
    pub fn new(data: &'a [u8]) -> Self {
        Pdos { data, offset: 0 }
    }
}

impl<'a> Iterator for Pdos<'a> {
    type Item = Result<(PdoHeader, &'a [u8])>;
    fn next(&mut self) -> Option<Self::Item> {
        // Fewer than 8 bytes left can only be category padding.
        if self.offset + PdoHeader::LEN > self.data.len() {
            return None;
        }
        let at = self.offset;
        let h = match PdoHeader::parse(&self.data[at..]) {
            Ok(h) => h,
            Err(e) => return Some(Err(e.shifted(at))),
        };
        let n = h.entry_count as usize * PdoEntry::LEN;
        let start = at + PdoHeader::LEN;
        if start + n > self.data.len() {
            self.offset = self.data.len();
            return Some(Err(Error::BadLength {
                what: "SII PDO entry count",
                offset: at + 2,
                claimed: h.entry_count as usize,
                limit: (self.data.len() - start) / PdoEntry::LEN,
            }));
        }
        self.offset = start + n;
        Some(Ok((h, &self.data[start..start + n])))
    }
}

/// One DC operation mode of category 60 (24 bytes).
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
pub struct DcOpMode {
    pub cycle_time0: u32,
    pub shift_time0: i32,
    pub shift_time1: i32,
    pub sync1_cycle_factor: i16,
    pub assign_activate: u16,
    pub sync0_cycle_factor: i16,
    pub name_idx: u8,
    pub desc_idx: u8,
    pub reserved: [u8; 4],
}

impl DcOpMode {
    pub const LEN: usize = 24;
    pub fn parse(d: &[u8]) -> Result<Self> {
        need(d, 0, Self::LEN, "SII DC op-mode")?;
        Ok(DcOpMode {
            cycle_time0: u32_at(d, 0, "")?,
            shift_time0: u32_at(d, 4, "")? as i32,
            shift_time1: u32_at(d, 8, "")? as i32,
            sync1_cycle_factor: u16_at(d, 12, "")? as i16,
            assign_activate: u16_at(d, 14, "")?,
            sync0_cycle_factor: u16_at(d, 16, "")? as i16,
            name_idx: d[18],
            desc_idx: d[19],
            reserved: [d[20], d[21], d[22], d[23]],
        })
    }
    pub fn to_bytes(&self) -> [u8; 24] {
        let mut d = [0u8; 24];
        d[0..4].copy_from_slice(&self.cycle_time0.to_le_bytes());
        d[4..8].copy_from_slice(&self.shift_time0.to_le_bytes());
        d[8..12].copy_from_slice(&self.shift_time1.to_le_bytes());
        d[12..14].copy_from_slice(&self.sync1_cycle_factor.to_le_bytes());
        d[14..16].copy_from_slice(&self.assign_activate.to_le_bytes());
        d[16..18].copy_from_slice(&self.sync0_cycle_factor.to_le_bytes());
        d[18] = self.name_idx;
        d[19] = self.desc_idx;
        d[20..24].copy_from_slice(&self.reserved);
        d
    }
}

#[cfg(feature = "alloc")]
pub mod dump;
#[cfg(feature = "alloc")]
mod owned;
#[cfg(feature = "alloc")]
pub use owned::{CategoryRepr, Pdo, SiiCategory, SiiInfo};
