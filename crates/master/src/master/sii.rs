//! The slaves' SII EEPROMs: read, all slaves' at once, or written.
use ferrocat_wire::register::addr;
use ferrocat_wire::sii::{SiiHeader, SiiInfo, CATEGORY_HEADER_LEN, HEADER_LEN as SII_HEADER};
use ferrocat_wire::{Address, Command};

use super::Master;
use crate::engine::Pdu;
use crate::error::{ConfigError, MasterError, Result, SlaveError};
use crate::io::Io;

impl<I: Io> Master<I> {
    /// Reads every slave's whole SII at once: each read command goes to all slaves in one frame,
    /// each status-and-data read in another, so the time does not grow with the slave count.
    pub(super) fn read_all_sii(&mut self, stations: &[u16]) -> Result<Vec<Vec<u8>>> {
        let n = stations.len();
        self.engine.one(Command::BWR, Address::Device { adp: 0, ado: addr::SII_CONFIG }, &mut [0])?;
        let mut imgs: Vec<Vec<u8>> = vec![Vec::with_capacity(2048); n];
        let mut done = vec![false; n];
        let mut ctl = vec![[0u8; 2]; n];
        {
            let mut p: Vec<Pdu<'_>> = stations
                .iter()
                .zip(ctl.iter_mut())
                .map(|(&st, c)| Pdu::new(Command::FPRD, Address::Device { adp: st, ado: addr::SII_CONTROL }, c))
                .collect();
            self.engine.transact(&mut p)?;
        }
        let eight: Vec<bool> = ctl
            .iter()
            .map(|c| u16::from_le_bytes(*c) & ferrocat_wire::register::SiiControl::READ_8_BYTES != 0)
            .collect();
        let deadline = self.engine.io.now_ns() + 10_000_000_000;
        // The shortest read seen so far, command to data: real EEPROMs take ≈ 0.7 ms a read
        // (docs/esc-model.md), so after the first round the master sleeps most of that before
        // it polls, rather than polling every round trip (≈ 70 frames a read on a short line).
        let mut read_ns: Option<u64> = None;
        while done.iter().any(|d| !d) {
            let active: Vec<usize> = (0..n).filter(|&k| !done[k]).collect();
            let mut cmds: Vec<[u8; 6]> = active
                .iter()
                .map(|&k| {
                    let mut c = [0x00, 0x01, 0, 0, 0, 0];
                    c[2..6].copy_from_slice(&((imgs[k].len() / 2) as u32).to_le_bytes());
                    c
                })
                .collect();
            {
                let mut p: Vec<Pdu<'_>> = active
                    .iter()
                    .zip(cmds.iter_mut())
                    .map(|(&k, c)| {
                        Pdu::new(Command::FPWR, Address::Device { adp: stations[k], ado: addr::SII_CONTROL }, c)
                    })
                    .collect();
                self.engine.transact(&mut p)?;
            }
            let commanded = self.engine.io.now_ns();
            if let Some(ns) = read_ns {
                self.engine.io.sleep_until(commanded + ns * 7 / 8);
            }
            // Status, address and data in one read; poll again only those still busy.
            let mut pending = active.clone();
            while !pending.is_empty() {
                let mut regs: Vec<[u8; 14]> = vec![[0; 14]; pending.len()];
                {
                    let mut p: Vec<Pdu<'_>> = pending
                        .iter()
                        .zip(regs.iter_mut())
                        .map(|(&k, r)| {
                            Pdu::new(Command::FPRD, Address::Device { adp: stations[k], ado: addr::SII_CONTROL }, r)
                        })
                        .collect();
                    self.engine.transact(&mut p)?;
                }
                let mut still = Vec::new();
                for (&k, r) in pending.iter().zip(&regs) {
                    let c = u16::from_le_bytes([r[0], r[1]]);
                    if c & 0x8000 != 0 {
                        still.push(k);
                        continue;
                    }
                    if c & 0x2000 != 0 {
                        return Err(MasterError::of(k as u16, "?", SlaveError::SiiNotAcknowledged));
                    }
                    imgs[k].extend_from_slice(&r[6..if eight[k] { 14 } else { 10 }]);
                    done[k] = sii_complete(&imgs[k]);
                }
                if still.len() < pending.len() {
                    let took = self.engine.io.now_ns().saturating_sub(commanded);
                    read_ns = Some(read_ns.map_or(took, |r| r.min(took)));
                }
                pending = still;
                if self.engine.io.now_ns() > deadline {
                    return Err(MasterError::of(pending.first().map_or(0, |&k| k as u16), "?", SlaveError::EepromBusy));
                }
            }
        }
        for img in &mut imgs {
            let len = sii_used_len(img);
            img.truncate(len);
        }
        Ok(imgs)
    }
}

/// Bytes of an SII image up to and including its end marker (or the whole of it).
fn sii_used_len(img: &[u8]) -> usize {
    if img.len() < SII_HEADER {
        return img.len();
    }
    let max = SiiHeader::parse(img).map(|h| h.eeprom_size_bytes()).unwrap_or(img.len()).clamp(SII_HEADER, 65536);
    let mut at = SII_HEADER;
    while at + 2 <= img.len().min(max) {
        let kind = u16::from_le_bytes([img[at], img[at + 1]]);
        if kind == 0xFFFF {
            return at + 2;
        }
        if at + CATEGORY_HEADER_LEN > img.len() {
            return img.len();
        }
        at += CATEGORY_HEADER_LEN + u16::from_le_bytes([img[at + 2], img[at + 3]]) as usize * 2;
    }
    img.len().min(max)
}

/// Whether `img` holds the whole SII: the end marker, or as much as the EEPROM is large.
fn sii_complete(img: &[u8]) -> bool {
    if img.len() < SII_HEADER {
        return false;
    }
    let max = SiiHeader::parse(img).map(|h| h.eeprom_size_bytes()).unwrap_or(2048).clamp(SII_HEADER, 65536);
    if img.len() >= max {
        return true;
    }
    let mut at = SII_HEADER;
    loop {
        if at + 2 > img.len() {
            return false;
        }
        if u16::from_le_bytes([img[at], img[at + 1]]) == 0xFFFF {
            return true;
        }
        if at + CATEGORY_HEADER_LEN > img.len() {
            return false;
        }
        at += CATEGORY_HEADER_LEN + u16::from_le_bytes([img[at + 2], img[at + 3]]) as usize * 2;
        if at >= max {
            return true;
        }
    }
}

/// A slave's EEPROM, programmed through its ESC (see [`Acyclic::sii`](crate::part::Acyclic::sii)).
pub struct Eeprom<'a, I: Io> {
    m: &'a mut Master<I>,
}

impl<'a, I: Io> crate::master::part::Acyclic<'a, I> {
    /// The slaves' EEPROMs: an image programmed, an alias set.
    pub fn sii(self) -> Eeprom<'a, I> {
        Eeprom { m: self.m }
    }
}

impl<I: Io> Eeprom<'_, I> {
    /// Writes a configured station alias into the slave's EEPROM: word 4 and, with it, the
    /// checksum word 7 (as IgH's `ethercat alias` does). The ESC takes an alias from its
    /// EEPROM only at power-on, never at a reload. Returns the number of words written.
    pub fn set_alias(&mut self, position: u16, alias: u16) -> Result<usize> {
        let mut image = self.m.slave(position)?.sii.to_image();
        image[8..10].copy_from_slice(&alias.to_le_bytes());
        image[14] = ferrocat_wire::sii::header_crc(&image);
        self.write(position, &image)
    }

    /// Programs the slave's EEPROM with `image`, word by word where it differs, and reloads it.
    /// Returns the number of words written.
    pub fn write(&mut self, position: u16, image: &[u8]) -> Result<usize> {
        // An ESC does not load a header whose CRC is wrong: refuse to brick the slave.
        if image.len() < 16 {
            return Err(ConfigError::SiiImageTooShort(image.len()).into());
        }
        let crc = ferrocat_wire::sii::header_crc(image);
        if image[14] != crc {
            return Err(ConfigError::SiiHeaderCrc { found: image[14], computed: crc }.into());
        }
        let (st, current, capacity) = {
            let s = self.m.slave(position)?;
            (s.station, s.sii.to_image(), s.sii.header.eeprom_size_bytes())
        };
        // Nothing past the EEPROM's end (its own word 0x3E): a write there fails half-way,
        // the slave left with part of another image.
        let data_len = image.iter().rposition(|b| *b != 0xFF).map_or(0, |i| i + 1);
        if data_len > capacity {
            let name = self.m.slaves[position as usize].name.clone();
            return Err(MasterError::of(
                position,
                &name,
                SlaveError::EepromTooSmall { image: data_len, eeprom: capacity },
            ));
        }
        let image = &image[..image.len().min(capacity)];
        self.m.fpwr(st, addr::SII_CONFIG, &[0])?;
        let mut written = 0;
        for (w, pair) in image.chunks(2).enumerate() {
            let v = u16::from_le_bytes([pair[0], *pair.get(1).unwrap_or(&0xFF)]);
            let old = current.get(2 * w..2 * w + 2).map(|b| u16::from_le_bytes([b[0], b[1]]));
            if old == Some(v) {
                continue;
            }
            // The data first, then "write" with write enable and the word address.
            self.m.fpwr(st, addr::SII_DATA, &v.to_le_bytes())?;
            let mut cmd = [0u8; 6];
            cmd[0..2].copy_from_slice(&0x0201u16.to_le_bytes());
            cmd[2..6].copy_from_slice(&(w as u32).to_le_bytes());
            self.m.fpwr(st, addr::SII_CONTROL, &cmd)?;
            let deadline = self.m.engine.io.now_ns() + 100_000_000;
            loop {
                let mut ctl = [0u8; 2];
                self.m.fprd(st, addr::SII_CONTROL, &mut ctl)?;
                let c = u16::from_le_bytes(ctl);
                if c & 0x8000 == 0 {
                    if c & 0x6000 != 0 {
                        let name = self.m.slaves[position as usize].name.clone();
                        return Err(MasterError::of(
                            position,
                            &name,
                            SlaveError::EepromWrite { word: w as u32, status: c },
                        ));
                    }
                    break;
                }
                if self.m.engine.io.now_ns() > deadline {
                    let name = self.m.slaves[position as usize].name.clone();
                    return Err(MasterError::of(position, &name, SlaveError::EepromBusy));
                }
                let now = self.m.engine.io.now_ns();
                self.m.engine.io.sleep_until(now + 500_000);
            }
            written += 1;
        }
        let sii = self.m.read_all_sii(&[st])?.pop().unwrap_or_default();
        if let Ok(info) = SiiInfo::from_image(&sii) {
            self.m.slaves[position as usize].sii = info;
        }
        Ok(written)
    }
}
