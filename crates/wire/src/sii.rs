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

/// Where each field of the SII header lies, as 16-bit word addresses (ETG.2010, the SII's
/// first 64 words); a 32-bit field takes its word and the next.
mod header_word {
    pub const PDI_CONTROL: usize = 0x00;
    pub const PDI_CONFIG: usize = 0x01;
    pub const SYNC_IMPULSE_LEN: usize = 0x02;
    pub const PDI_CONFIG2: usize = 0x03;
    pub const STATION_ALIAS: usize = 0x04;
    pub const RESERVED_05: usize = 0x05;
    pub const CHECKSUM: usize = 0x07;
    pub const VENDOR_ID: usize = 0x08;
    pub const PRODUCT_CODE: usize = 0x0A;
    pub const REVISION: usize = 0x0C;
    pub const SERIAL: usize = 0x0E;
    pub const EXECUTION_DELAY: usize = 0x10;
    pub const PORT0_DELAY: usize = 0x11;
    pub const PORT1_DELAY: usize = 0x12;
    pub const RESERVED_13: usize = 0x13;
    pub const BOOTSTRAP_RX_OFFSET: usize = 0x14;
    pub const BOOTSTRAP_RX_SIZE: usize = 0x15;
    pub const BOOTSTRAP_TX_OFFSET: usize = 0x16;
    pub const BOOTSTRAP_TX_SIZE: usize = 0x17;
    pub const MAILBOX_RX_OFFSET: usize = 0x18;
    pub const MAILBOX_RX_SIZE: usize = 0x19;
    pub const MAILBOX_TX_OFFSET: usize = 0x1A;
    pub const MAILBOX_TX_SIZE: usize = 0x1B;
    pub const MAILBOX_PROTOCOLS: usize = 0x1C;
    pub const RESERVED_1D: core::ops::Range<usize> = 0x1D..0x3E;
    pub const EEPROM_SIZE: usize = 0x3E;
    pub const VERSION: usize = 0x3F;
}

impl SiiHeader {
    pub fn parse(buf: &[u8]) -> Result<Self> {
        use header_word as f;
        need(buf, 0, HEADER_LEN, "SII header")?;
        let w = |i: usize| u16::from_le_bytes([buf[2 * i], buf[2 * i + 1]]);
        let d = |i: usize| w(i) as u32 | (w(i + 1) as u32) << 16;
        let mut reserved_1d = [0u16; 33];
        for (r, i) in reserved_1d.iter_mut().zip(f::RESERVED_1D) {
            *r = w(i);
        }
        Ok(SiiHeader {
            pdi_control: w(f::PDI_CONTROL),
            pdi_config: w(f::PDI_CONFIG),
            sync_impulse_len: w(f::SYNC_IMPULSE_LEN),
            pdi_config2: w(f::PDI_CONFIG2),
            station_alias: w(f::STATION_ALIAS),
            reserved_05: [w(f::RESERVED_05), w(f::RESERVED_05 + 1)],
            checksum: w(f::CHECKSUM),
            vendor_id: d(f::VENDOR_ID),
            product_code: d(f::PRODUCT_CODE),
            revision: d(f::REVISION),
            serial: d(f::SERIAL),
            execution_delay: w(f::EXECUTION_DELAY),
            port0_delay: w(f::PORT0_DELAY),
            port1_delay: w(f::PORT1_DELAY),
            reserved_13: w(f::RESERVED_13),
            bootstrap_rx_offset: w(f::BOOTSTRAP_RX_OFFSET),
            bootstrap_rx_size: w(f::BOOTSTRAP_RX_SIZE),
            bootstrap_tx_offset: w(f::BOOTSTRAP_TX_OFFSET),
            bootstrap_tx_size: w(f::BOOTSTRAP_TX_SIZE),
            mailbox_rx_offset: w(f::MAILBOX_RX_OFFSET),
            mailbox_rx_size: w(f::MAILBOX_RX_SIZE),
            mailbox_tx_offset: w(f::MAILBOX_TX_OFFSET),
            mailbox_tx_size: w(f::MAILBOX_TX_SIZE),
            mailbox_protocols: w(f::MAILBOX_PROTOCOLS),
            reserved_1d,
            eeprom_size: w(f::EEPROM_SIZE),
            version: w(f::VERSION),
        })
    }

    pub fn to_bytes(&self) -> [u8; HEADER_LEN] {
        use header_word as f;
        let mut words = [0u16; HEADER_LEN / 2];
        let mut put = |i: usize, v: u16| words[i] = v;
        put(f::PDI_CONTROL, self.pdi_control);
        put(f::PDI_CONFIG, self.pdi_config);
        put(f::SYNC_IMPULSE_LEN, self.sync_impulse_len);
        put(f::PDI_CONFIG2, self.pdi_config2);
        put(f::STATION_ALIAS, self.station_alias);
        put(f::RESERVED_05, self.reserved_05[0]);
        put(f::RESERVED_05 + 1, self.reserved_05[1]);
        put(f::CHECKSUM, self.checksum);
        for (at, v) in [
            (f::VENDOR_ID, self.vendor_id),
            (f::PRODUCT_CODE, self.product_code),
            (f::REVISION, self.revision),
            (f::SERIAL, self.serial),
        ] {
            put(at, v as u16);
            put(at + 1, (v >> 16) as u16);
        }
        put(f::EXECUTION_DELAY, self.execution_delay);
        put(f::PORT0_DELAY, self.port0_delay);
        put(f::PORT1_DELAY, self.port1_delay);
        put(f::RESERVED_13, self.reserved_13);
        put(f::BOOTSTRAP_RX_OFFSET, self.bootstrap_rx_offset);
        put(f::BOOTSTRAP_RX_SIZE, self.bootstrap_rx_size);
        put(f::BOOTSTRAP_TX_OFFSET, self.bootstrap_tx_offset);
        put(f::BOOTSTRAP_TX_SIZE, self.bootstrap_tx_size);
        put(f::MAILBOX_RX_OFFSET, self.mailbox_rx_offset);
        put(f::MAILBOX_RX_SIZE, self.mailbox_rx_size);
        put(f::MAILBOX_TX_OFFSET, self.mailbox_tx_offset);
        put(f::MAILBOX_TX_SIZE, self.mailbox_tx_size);
        put(f::MAILBOX_PROTOCOLS, self.mailbox_protocols);
        for (i, v) in f::RESERVED_1D.zip(self.reserved_1d) {
            put(i, v);
        }
        put(f::EEPROM_SIZE, self.eeprom_size);
        put(f::VERSION, self.version);
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

/// Where each field of the general category lies (ETG.2010 Table 5), in bytes.
mod general_field {
    use core::ops::Range;
    pub const GROUP_IDX: usize = 0;
    pub const IMAGE_IDX: usize = 1;
    pub const ORDER_IDX: usize = 2;
    pub const NAME_IDX: usize = 3;
    pub const RESERVED_4: usize = 4;
    pub const COE_DETAILS: usize = 5;
    pub const FOE_DETAILS: usize = 6;
    pub const EOE_DETAILS: usize = 7;
    pub const SOE_CHANNELS: usize = 8;
    pub const DS402_CHANNELS: usize = 9;
    pub const SYSMAN_CLASS: usize = 10;
    pub const FLAGS: usize = 11;
    pub const CURRENT_ON_EBUS: Range<usize> = 12..14;
    pub const GROUP_IDX_DUP: usize = 14;
    pub const RESERVED_15: usize = 15;
    pub const PHYSICAL_PORTS: Range<usize> = 16..18;
    pub const PHYSICAL_MEMORY_ADDRESS: Range<usize> = 18..20;
    pub const RESERVED_20: Range<usize> = 20..32;
}

/// The little-endian 16 bits at `at` of a record whose length was checked.
fn le16(d: &[u8], at: core::ops::Range<usize>) -> u16 {
    u16::from_le_bytes([d[at.start], d[at.start + 1]])
}

impl General {
    pub const LEN: usize = 32;

    pub fn parse(d: &[u8]) -> Result<Self> {
        use general_field as f;
        need(d, 0, Self::LEN, "SII general category")?;
        let mut reserved_20 = [0; 12];
        reserved_20.copy_from_slice(&d[f::RESERVED_20]);
        Ok(General {
            group_idx: d[f::GROUP_IDX],
            image_idx: d[f::IMAGE_IDX],
            order_idx: d[f::ORDER_IDX],
            name_idx: d[f::NAME_IDX],
            reserved_4: d[f::RESERVED_4],
            coe_details: d[f::COE_DETAILS],
            foe_details: d[f::FOE_DETAILS],
            eoe_details: d[f::EOE_DETAILS],
            soe_channels: d[f::SOE_CHANNELS],
            ds402_channels: d[f::DS402_CHANNELS],
            sysman_class: d[f::SYSMAN_CLASS],
            flags: d[f::FLAGS],
            current_on_ebus_ma: le16(d, f::CURRENT_ON_EBUS) as i16,
            group_idx_dup: d[f::GROUP_IDX_DUP],
            reserved_15: d[f::RESERVED_15],
            physical_ports: le16(d, f::PHYSICAL_PORTS),
            physical_memory_address: le16(d, f::PHYSICAL_MEMORY_ADDRESS),
            reserved_20,
        })
    }

    pub fn to_bytes(&self) -> [u8; 32] {
        use general_field as f;
        let mut d = [0u8; 32];
        for (at, v) in [
            (f::GROUP_IDX, self.group_idx),
            (f::IMAGE_IDX, self.image_idx),
            (f::ORDER_IDX, self.order_idx),
            (f::NAME_IDX, self.name_idx),
            (f::RESERVED_4, self.reserved_4),
            (f::COE_DETAILS, self.coe_details),
            (f::FOE_DETAILS, self.foe_details),
            (f::EOE_DETAILS, self.eoe_details),
            (f::SOE_CHANNELS, self.soe_channels),
            (f::DS402_CHANNELS, self.ds402_channels),
            (f::SYSMAN_CLASS, self.sysman_class),
            (f::FLAGS, self.flags),
            (f::GROUP_IDX_DUP, self.group_idx_dup),
            (f::RESERVED_15, self.reserved_15),
        ] {
            d[at] = v;
        }
        d[f::CURRENT_ON_EBUS].copy_from_slice(&self.current_on_ebus_ma.to_le_bytes());
        d[f::PHYSICAL_PORTS].copy_from_slice(&self.physical_ports.to_le_bytes());
        d[f::PHYSICAL_MEMORY_ADDRESS].copy_from_slice(&self.physical_memory_address.to_le_bytes());
        d[f::RESERVED_20].copy_from_slice(&self.reserved_20);
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
        use sm_field as f;
        need(d, 0, Self::LEN, "SII SyncManager entry")?;
        Ok(SmEntry {
            start: le16(d, f::START),
            length: le16(d, f::LENGTH),
            control: d[f::CONTROL],
            status: d[f::STATUS],
            enable: d[f::ENABLE],
            sm_type: d[f::TYPE],
        })
    }

    pub fn to_bytes(&self) -> [u8; 8] {
        use sm_field as f;
        let mut d = [0u8; 8];
        d[f::START].copy_from_slice(&self.start.to_le_bytes());
        d[f::LENGTH].copy_from_slice(&self.length.to_le_bytes());
        (d[f::CONTROL], d[f::STATUS], d[f::ENABLE], d[f::TYPE]) =
            (self.control, self.status, self.enable, self.sm_type);
        d
    }
}

/// Where each field of a SyncManager entry (category 41) lies, in bytes.
mod sm_field {
    use core::ops::Range;
    pub const START: Range<usize> = 0..2;
    pub const LENGTH: Range<usize> = 2..4;
    pub const CONTROL: usize = 4;
    pub const STATUS: usize = 5;
    pub const ENABLE: usize = 6;
    pub const TYPE: usize = 7;
}

/// Where each field of a PDO header and of a PDO entry (categories 50, 51) lies, in bytes.
mod pdo_field {
    use core::ops::Range;
    pub const INDEX: Range<usize> = 0..2;
    pub const FLAGS: Range<usize> = 6..8;
    /// Header.
    pub const ENTRY_COUNT: usize = 2;
    pub const SYNC_MANAGER: usize = 3;
    pub const SYNCHRONIZATION: usize = 4;
    pub const HEADER_NAME_IDX: usize = 5;
    /// Entry.
    pub const SUBINDEX: usize = 2;
    pub const ENTRY_NAME_IDX: usize = 3;
    pub const DATA_TYPE: usize = 4;
    pub const BIT_LEN: usize = 5;
}

/// Where each field of a DC operation mode (category 60) lies, in bytes.
mod dc_field {
    use core::ops::Range;
    pub const CYCLE_TIME0: usize = 0;
    pub const SHIFT_TIME0: usize = 4;
    pub const SHIFT_TIME1: usize = 8;
    pub const SYNC1_CYCLE_FACTOR: usize = 12;
    pub const ASSIGN_ACTIVATE: usize = 14;
    pub const SYNC0_CYCLE_FACTOR: usize = 16;
    pub const NAME_IDX: usize = 18;
    pub const DESC_IDX: usize = 19;
    pub const RESERVED: Range<usize> = 20..24;
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
        use pdo_field as f;
        need(d, 0, Self::LEN, "SII PDO entry")?;
        Ok(PdoEntry {
            index: le16(d, f::INDEX),
            subindex: d[f::SUBINDEX],
            name_idx: d[f::ENTRY_NAME_IDX],
            data_type: d[f::DATA_TYPE],
            bit_len: d[f::BIT_LEN],
            flags: le16(d, f::FLAGS),
        })
    }
    pub fn to_bytes(&self) -> [u8; 8] {
        use pdo_field as f;
        let mut d = [0u8; 8];
        d[f::INDEX].copy_from_slice(&self.index.to_le_bytes());
        d[f::FLAGS].copy_from_slice(&self.flags.to_le_bytes());
        (d[f::SUBINDEX], d[f::ENTRY_NAME_IDX], d[f::DATA_TYPE], d[f::BIT_LEN]) =
            (self.subindex, self.name_idx, self.data_type, self.bit_len);
        d
    }
}

impl PdoHeader {
    pub const LEN: usize = 8;
    pub fn parse(d: &[u8]) -> Result<Self> {
        use pdo_field as f;
        need(d, 0, Self::LEN, "SII PDO header")?;
        Ok(PdoHeader {
            index: le16(d, f::INDEX),
            entry_count: d[f::ENTRY_COUNT],
            sync_manager: d[f::SYNC_MANAGER],
            synchronization: d[f::SYNCHRONIZATION],
            name_idx: d[f::HEADER_NAME_IDX],
            flags: le16(d, f::FLAGS),
        })
    }
    pub fn to_bytes(&self) -> [u8; 8] {
        use pdo_field as f;
        let mut d = [0u8; 8];
        d[f::INDEX].copy_from_slice(&self.index.to_le_bytes());
        d[f::FLAGS].copy_from_slice(&self.flags.to_le_bytes());
        (d[f::ENTRY_COUNT], d[f::SYNC_MANAGER], d[f::SYNCHRONIZATION], d[f::HEADER_NAME_IDX]) =
            (self.entry_count, self.sync_manager, self.synchronization, self.name_idx);
        d
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
        use dc_field as f;
        need(d, 0, Self::LEN, "SII DC op-mode")?;
        let mut reserved = [0u8; 4];
        reserved.copy_from_slice(&d[f::RESERVED]);
        Ok(DcOpMode {
            cycle_time0: u32_at(d, f::CYCLE_TIME0, "")?,
            shift_time0: u32_at(d, f::SHIFT_TIME0, "")? as i32,
            shift_time1: u32_at(d, f::SHIFT_TIME1, "")? as i32,
            sync1_cycle_factor: u16_at(d, f::SYNC1_CYCLE_FACTOR, "")? as i16,
            assign_activate: u16_at(d, f::ASSIGN_ACTIVATE, "")?,
            sync0_cycle_factor: u16_at(d, f::SYNC0_CYCLE_FACTOR, "")? as i16,
            name_idx: d[f::NAME_IDX],
            desc_idx: d[f::DESC_IDX],
            reserved,
        })
    }
    pub fn to_bytes(&self) -> [u8; 24] {
        use dc_field as f;
        let mut d = [0u8; 24];
        let mut put = |at: usize, b: &[u8]| d[at..at + b.len()].copy_from_slice(b);
        put(f::CYCLE_TIME0, &self.cycle_time0.to_le_bytes());
        put(f::SHIFT_TIME0, &self.shift_time0.to_le_bytes());
        put(f::SHIFT_TIME1, &self.shift_time1.to_le_bytes());
        put(f::SYNC1_CYCLE_FACTOR, &self.sync1_cycle_factor.to_le_bytes());
        put(f::ASSIGN_ACTIVATE, &self.assign_activate.to_le_bytes());
        put(f::SYNC0_CYCLE_FACTOR, &self.sync0_cycle_factor.to_le_bytes());
        put(f::NAME_IDX, &[self.name_idx]);
        put(f::DESC_IDX, &[self.desc_idx]);
        put(f::RESERVED.start, &self.reserved);
        d
    }
}

#[cfg(feature = "alloc")]
pub mod dump;
#[cfg(feature = "alloc")]
mod owned;
#[cfg(feature = "alloc")]
pub use owned::{CategoryRepr, Pdo, SiiCategory, SiiInfo};
