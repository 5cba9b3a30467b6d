//! EEPROM dump files: raw binary, Intel HEX, or whitespace-separated hex bytes (what tools
//! such as SOEM's eepromtool and vendor utilities write).
use alloc::vec::Vec;

use crate::{Error, Result};

/// How a dump was encoded.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum DumpFormat {
    Binary,
    IntelHex,
    HexText,
}

fn hex_val(b: u8) -> Option<u8> {
    (b as char).to_digit(16).map(|d| d as u8)
}

fn is_text(bytes: &[u8]) -> bool {
    !bytes.is_empty()
        && bytes
            .iter()
            .all(|&b| b.is_ascii_hexdigit() || b.is_ascii_whitespace() || b == b':' || b == b',' || b == b'x')
}

/// Decodes a dump into EEPROM bytes. Text is recognised only when every byte is a hex digit,
/// whitespace or Intel HEX punctuation; anything else is taken as binary.
pub fn parse_dump(bytes: &[u8]) -> Result<(Vec<u8>, DumpFormat)> {
    if !is_text(bytes) {
        return Ok((bytes.to_vec(), DumpFormat::Binary));
    }
    let first = bytes.iter().position(|b| !b.is_ascii_whitespace()).unwrap_or(0);
    if bytes[first] == b':' {
        return parse_intel_hex(bytes).map(|v| (v, DumpFormat::IntelHex));
    }
    // Hex text: pairs of digits, optionally "0x"-prefixed, separated by whitespace or commas.
    let mut out = Vec::new();
    let mut i = 0;
    while i < bytes.len() {
        let b = bytes[i];
        if b.is_ascii_whitespace() || b == b',' {
            i += 1;
            continue;
        }
        if b == b'0' && bytes.get(i + 1) == Some(&b'x') {
            i += 2;
            continue;
        }
        let hi = hex_val(b).ok_or(Error::BadValue { what: "hex dump character", offset: i, value: b as u32 })?;
        let lo = bytes.get(i + 1).and_then(|&c| hex_val(c)).ok_or(Error::Truncated {
            what: "hex dump byte (two digits)",
            offset: i,
            needed: 2,
            available: 1,
        })?;
        out.push(hi << 4 | lo);
        i += 2;
    }
    Ok((out, DumpFormat::HexText))
}

fn parse_intel_hex(bytes: &[u8]) -> Result<Vec<u8>> {
    let mut out: Vec<u8> = Vec::new();
    let mut base: u32 = 0;
    let mut offset = 0;
    for line in bytes.split(|&b| b == b'\n') {
        let start = offset;
        offset += line.len() + 1;
        let line = line.trim_ascii();
        if line.is_empty() {
            continue;
        }
        if line[0] != b':' || line.len() % 2 == 0 {
            return Err(Error::BadValue { what: "Intel HEX record start", offset: start, value: line[0] as u32 });
        }
        let mut rec = Vec::with_capacity(line.len() / 2);
        for (k, pair) in line[1..].chunks(2).enumerate() {
            match (hex_val(pair[0]), hex_val(pair[1])) {
                (Some(h), Some(l)) => rec.push(h << 4 | l),
                _ => {
                    return Err(Error::BadValue {
                        what: "Intel HEX digit",
                        offset: start + 1 + 2 * k,
                        value: pair[0] as u32,
                    })
                }
            }
        }
        if rec.len() < 5 || rec.len() != 5 + rec[0] as usize {
            return Err(Error::BadLength {
                what: "Intel HEX record",
                offset: start,
                claimed: rec.first().copied().unwrap_or(0) as usize,
                limit: rec.len().saturating_sub(5),
            });
        }
        let sum = rec.iter().fold(0u8, |a, &b| a.wrapping_add(b));
        if sum != 0 {
            return Err(Error::Checksum { what: "Intel HEX record", offset: start, expected: 0, actual: sum as u32 });
        }
        let n = rec[0] as usize;
        let addr = u16::from_be_bytes([rec[1], rec[2]]) as u32;
        let data = &rec[4..4 + n];
        match rec[3] {
            0 => {
                let at = (base + addr) as usize;
                // EEPROMs are at most a few hundred KiB; refuse absurd addresses instead of allocating.
                if at + n > 1 << 20 {
                    return Err(Error::BadValue { what: "Intel HEX address", offset: start, value: base + addr });
                }
                if out.len() < at + n {
                    out.resize(at + n, 0xFF);
                }
                out[at..at + n].copy_from_slice(data);
            }
            1 => break,
            2 if n == 2 => base = (u16::from_be_bytes([data[0], data[1]]) as u32) << 4,
            4 if n == 2 => base = (u16::from_be_bytes([data[0], data[1]]) as u32) << 16,
            3 | 5 => {}
            t => return Err(Error::BadValue { what: "Intel HEX record type", offset: start, value: t as u32 }),
        }
    }
    Ok(out)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn formats() {
        assert_eq!(parse_dump(&[0, 1, 0xFF]).unwrap(), (alloc::vec![0, 1, 0xFF], DumpFormat::Binary));
        assert_eq!(parse_dump(b"01 02\n0a ff").unwrap(), (alloc::vec![1, 2, 10, 255], DumpFormat::HexText));
        let ihex = b":0400000001020304F2\n:00000001FF\n";
        assert_eq!(parse_dump(ihex).unwrap(), (alloc::vec![1, 2, 3, 4], DumpFormat::IntelHex));
        assert!(matches!(parse_dump(b":0400000001020304F3\n"), Err(Error::Checksum { .. })));
        assert!(matches!(parse_dump(b"01 0"), Err(Error::Truncated { offset: 3, .. })));
    }
}
