//! Hex text as bytes (`05060B0E`, whitespace ignored): an ESI file's `ConfigData`, a value on
//! the command line.
use alloc::vec::Vec;

/// Why hex text did not decode.
#[derive(Debug, Clone, PartialEq, Eq)]
pub enum HexError {
    /// A character that is not a hex digit, at this index among the non-whitespace ones.
    NotHex { index: usize, found: char },
    /// An odd number of digits.
    OddLength(usize),
}

impl core::fmt::Display for HexError {
    fn fmt(&self, f: &mut core::fmt::Formatter<'_>) -> core::fmt::Result {
        match self {
            HexError::NotHex { index, found } => write!(f, "{found:?} at character {index} is not a hex digit"),
            HexError::OddLength(n) => write!(f, "hex data of odd length {n}"),
        }
    }
}

/// Pairs of hex digits as bytes. Works on characters, not bytes: any text, however malformed,
/// gives bytes or an error.
pub fn decode(text: &str) -> Result<Vec<u8>, HexError> {
    let mut nibbles = Vec::with_capacity(text.len());
    for (index, found) in text.chars().filter(|c| !c.is_whitespace()).enumerate() {
        let d = found.to_digit(16).ok_or(HexError::NotHex { index, found })?;
        nibbles.push(d as u8);
    }
    if nibbles.len() % 2 != 0 {
        return Err(HexError::OddLength(nibbles.len()));
    }
    Ok(nibbles.chunks_exact(2).map(|p| (p[0] << 4) | p[1]).collect())
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn decodes_and_names_what_is_wrong() {
        assert_eq!(decode("05 06\n0b0E"), Ok(alloc::vec![0x05, 0x06, 0x0B, 0x0E]));
        assert_eq!(decode(""), Ok(alloc::vec![]));
        assert_eq!(decode("0a0"), Err(HexError::OddLength(3)));
        // A multi-byte character where a digit belongs (the `device` fuzz target's find: the
        // ESI parser sliced the text by bytes and panicked inside it).
        assert_eq!(decode("080ēments"), Err(HexError::NotHex { index: 3, found: 'ē' }));
        assert_eq!(decode("0x10"), Err(HexError::NotHex { index: 1, found: 'x' }));
    }
}
