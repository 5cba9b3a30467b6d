//! Owned SII description: read from an image, edited or built from an ESI file, written back.
use alloc::string::String;
use alloc::vec::Vec;

use super::*;

/// A PDO of a TxPDO/RxPDO category with its entries.
#[derive(Debug, Clone, PartialEq, Eq, Default)]
pub struct Pdo {
    pub index: u16,
    pub sync_manager: u8,
    pub synchronization: u8,
    pub name_idx: u8,
    pub flags: u16,
    pub entries: Vec<PdoEntry>,
}

impl Pdo {
    pub fn bit_len(&self) -> u32 {
        self.entries.iter().map(|e| e.bit_len as u32).sum()
    }
}

/// One category, typed where the type is known. Categories whose bytes would not re-encode
/// identically from the typed form (odd padding, vendor types) are kept as `Other`.
#[derive(Debug, Clone, PartialEq, Eq)]
pub enum CategoryRepr {
    Strings(Vec<Vec<u8>>),
    General(General),
    /// One usage byte per FMMU (see [`fmmu_usage`]).
    Fmmu(Vec<u8>),
    SyncManagers(Vec<SmEntry>),
    TxPdos(Vec<Pdo>),
    RxPdos(Vec<Pdo>),
    Dc(Vec<DcOpMode>),
    Other {
        kind: u16,
        data: Vec<u8>,
    },
}

impl CategoryRepr {
    pub fn kind(&self) -> u16 {
        match self {
            CategoryRepr::Strings(_) => category::STRINGS,
            CategoryRepr::General(_) => category::GENERAL,
            CategoryRepr::Fmmu(_) => category::FMMU,
            CategoryRepr::SyncManagers(_) => category::SYNC_MANAGER,
            CategoryRepr::TxPdos(_) => category::TXPDO,
            CategoryRepr::RxPdos(_) => category::RXPDO,
            CategoryRepr::Dc(_) => category::DC,
            CategoryRepr::Other { kind, .. } => *kind,
        }
    }

    /// The category's data as the typed form encodes it (before padding).
    pub fn data_bytes(&self) -> Vec<u8> {
        let mut d = Vec::new();
        match self {
            CategoryRepr::Strings(list) => {
                d.push(list.len() as u8);
                for s in list {
                    d.push(s.len() as u8);
                    d.extend_from_slice(s);
                }
            }
            CategoryRepr::General(g) => d.extend_from_slice(&g.to_bytes()),
            CategoryRepr::Fmmu(f) => {
                d.extend_from_slice(f);
                // Pad to a whole word with 0xFF ("unused"), as Beckhoff images do.
                if f.len() % 2 == 1 {
                    d.push(fmmu_usage::PAD);
                }
            }
            CategoryRepr::SyncManagers(s) => s.iter().for_each(|e| d.extend_from_slice(&e.to_bytes())),
            CategoryRepr::TxPdos(p) | CategoryRepr::RxPdos(p) => {
                for pdo in p {
                    let h = PdoHeader {
                        index: pdo.index,
                        entry_count: pdo.entries.len() as u8,
                        sync_manager: pdo.sync_manager,
                        synchronization: pdo.synchronization,
                        name_idx: pdo.name_idx,
                        flags: pdo.flags,
                    };
                    d.extend_from_slice(&h.to_bytes());
                    pdo.entries.iter().for_each(|e| d.extend_from_slice(&e.to_bytes()));
                }
            }
            CategoryRepr::Dc(m) => m.iter().for_each(|e| d.extend_from_slice(&e.to_bytes())),
            CategoryRepr::Other { data, .. } => d.extend_from_slice(data),
        }
        d
    }

    fn parse_typed(c: &Category<'_>) -> Result<CategoryRepr> {
        let at = c.offset + CATEGORY_HEADER_LEN;
        let d = c.data;
        Ok(match c.kind {
            category::STRINGS => {
                let s = Strings::parse(d).map_err(|e| e.shifted(at))?;
                CategoryRepr::Strings(s.iter().map(|x| x.to_vec()).collect())
            }
            category::GENERAL => CategoryRepr::General(General::parse(d).map_err(|e| e.shifted(at))?),
            category::FMMU => {
                // A final 0xFF in an even-sized list is the word padding, not a fifth FMMU.
                let n = if d.len() % 2 == 0 && d.last() == Some(&fmmu_usage::PAD) { d.len() - 1 } else { d.len() };
                CategoryRepr::Fmmu(d[..n].to_vec())
            }
            category::SYNC_MANAGER => {
                CategoryRepr::SyncManagers(records(d, SmEntry::LEN).map(SmEntry::parse).collect::<Result<_>>()?)
            }
            category::TXPDO | category::RXPDO => {
                let mut pdos = Vec::new();
                for p in Pdos::new(d) {
                    let (h, entries) = p.map_err(|e| e.shifted(at))?;
                    pdos.push(Pdo {
                        index: h.index,
                        sync_manager: h.sync_manager,
                        synchronization: h.synchronization,
                        name_idx: h.name_idx,
                        flags: h.flags,
                        entries: records(entries, PdoEntry::LEN).map(PdoEntry::parse).collect::<Result<_>>()?,
                    });
                }
                if c.kind == category::TXPDO {
                    CategoryRepr::TxPdos(pdos)
                } else {
                    CategoryRepr::RxPdos(pdos)
                }
            }
            category::DC => CategoryRepr::Dc(records(d, DcOpMode::LEN).map(DcOpMode::parse).collect::<Result<_>>()?),
            kind => CategoryRepr::Other { kind, data: d.to_vec() },
        })
    }
}

/// A category and the bytes its size covers beyond the typed content (padding, which real
/// images fill with 0x00 or 0xFF, or vendor data), so that images re-encode byte for byte.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct SiiCategory {
    pub repr: CategoryRepr,
    pub trailing: Vec<u8>,
}

impl SiiCategory {
    pub fn new(repr: CategoryRepr) -> Self {
        SiiCategory { repr, trailing: Vec::new() }
    }

    /// The category's data: typed content, trailing bytes, and a zero byte if needed to fill
    /// the last word.
    pub fn data(&self) -> Vec<u8> {
        let mut d = self.repr.data_bytes();
        d.extend_from_slice(&self.trailing);
        if d.len() % 2 == 1 {
            d.push(0);
        }
        d
    }
}

/// The owned description of an SII image.
#[derive(Debug, Clone, PartialEq, Eq, Default)]
pub struct SiiInfo {
    pub header: SiiHeader,
    pub categories: Vec<SiiCategory>,
}

impl SiiInfo {
    /// Reads a whole image. Malformed known categories are errors naming the byte offset.
    /// A typed category keeps the bytes after its content; one whose typed form would not
    /// reproduce its bytes is kept raw.
    pub fn from_image(bytes: &[u8]) -> Result<Self> {
        let image = SiiImage::parse(bytes)?;
        let mut categories = Vec::new();
        for c in image.categories() {
            let c = c?;
            let typed = CategoryRepr::parse_typed(&c)?;
            let encoded = typed.data_bytes();
            categories.push(match c.data.strip_prefix(&encoded[..]) {
                Some(rest) if encoded.len() <= c.data.len() => SiiCategory { repr: typed, trailing: rest.to_vec() },
                _ => SiiCategory::new(CategoryRepr::Other { kind: c.kind, data: c.data.to_vec() }),
            });
        }
        Ok(SiiInfo { header: *image.header(), categories })
    }

    /// Header, categories and the end marker; no fill after it.
    pub fn to_image(&self) -> Vec<u8> {
        let mut out = Vec::from(self.header.to_bytes());
        for c in &self.categories {
            let d = c.data();
            out.extend_from_slice(&c.repr.kind().to_le_bytes());
            out.extend_from_slice(&((d.len() / 2) as u16).to_le_bytes());
            out.extend_from_slice(&d);
        }
        out.extend_from_slice(&category::END.to_le_bytes());
        out
    }

    /// [`to_image`](Self::to_image) filled with 0xFF (erased EEPROM) up to `size` bytes, or an
    /// error if the description does not fit.
    pub fn to_image_sized(&self, size: usize) -> Result<Vec<u8>> {
        let mut img = self.to_image();
        if img.len() > size {
            return Err(Error::BufferTooSmall { what: "SII EEPROM", needed: img.len(), available: size });
        }
        img.resize(size, 0xFF);
        Ok(img)
    }

    fn find(&self, kind: u16) -> Option<&CategoryRepr> {
        self.categories.iter().map(|c| &c.repr).find(|c| c.kind() == kind)
    }

    /// Appends a category.
    pub fn push(&mut self, repr: CategoryRepr) {
        self.categories.push(SiiCategory::new(repr));
    }

    pub fn strings(&self) -> &[Vec<u8>] {
        match self.find(category::STRINGS) {
            Some(CategoryRepr::Strings(s)) => s,
            _ => &[],
        }
    }

    /// String `index` (1-based), decoded as ISO-8859-1 (what Beckhoff images use).
    pub fn string(&self, index: u8) -> Option<String> {
        let s = self.strings().get((index as usize).checked_sub(1)?)?;
        Some(s.iter().map(|&b| b as char).collect())
    }

    /// Adds a string and returns its index (reusing an equal one); 0 for the empty string.
    pub fn intern(&mut self, s: &str) -> u8 {
        if s.is_empty() {
            return 0;
        }
        // ISO-8859-1 where possible; other characters become '?'. Strings are capped at 255 bytes.
        let bytes: Vec<u8> = s.chars().map(|c| if (c as u32) < 256 { c as u8 } else { b'?' }).take(255).collect();
        let pos = self.categories.iter().position(|c| matches!(c.repr, CategoryRepr::Strings(_)));
        let idx = pos.unwrap_or_else(|| {
            self.categories.insert(0, SiiCategory::new(CategoryRepr::Strings(Vec::new())));
            0
        });
        let CategoryRepr::Strings(list) = &mut self.categories[idx].repr else { return 0 };
        if let Some(i) = list.iter().position(|x| *x == bytes) {
            return (i + 1) as u8;
        }
        if list.len() >= 255 {
            return 0;
        }
        list.push(bytes);
        list.len() as u8
    }

    pub fn general(&self) -> Option<&General> {
        match self.find(category::GENERAL) {
            Some(CategoryRepr::General(g)) => Some(g),
            _ => None,
        }
    }

    pub fn fmmus(&self) -> &[u8] {
        match self.find(category::FMMU) {
            Some(CategoryRepr::Fmmu(f)) => f,
            _ => &[],
        }
    }

    pub fn sync_managers(&self) -> &[SmEntry] {
        match self.find(category::SYNC_MANAGER) {
            Some(CategoryRepr::SyncManagers(s)) => s,
            _ => &[],
        }
    }

    pub fn tx_pdos(&self) -> &[Pdo] {
        match self.find(category::TXPDO) {
            Some(CategoryRepr::TxPdos(p)) => p,
            _ => &[],
        }
    }

    pub fn rx_pdos(&self) -> &[Pdo] {
        match self.find(category::RXPDO) {
            Some(CategoryRepr::RxPdos(p)) => p,
            _ => &[],
        }
    }

    pub fn dc_op_modes(&self) -> &[DcOpMode] {
        match self.find(category::DC) {
            Some(CategoryRepr::Dc(m)) => m,
            _ => &[],
        }
    }

    /// The device name: the general category's name string.
    pub fn name(&self) -> Option<String> {
        self.string(self.general()?.name_idx)
    }
}
