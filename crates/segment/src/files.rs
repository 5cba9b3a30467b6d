//! Reading the files a user names (segment and scenario descriptions, EEPROM dumps, ESI files,
//! captures) with an upper bound: a file larger than any of its kind, or an endless one such as
//! `/dev/zero`, is an error naming it, not an allocation that takes the machine's memory.
use std::io::{self, Read};
use std::path::Path;

/// An SII EEPROM holds at most 4 Mbit (512 KiB, ESC datasheet 0x0502 bit 7); a text dump of it
/// takes about three characters per byte.
pub const MAX_EEPROM_FILE_BYTES: u64 = 4 << 20;
/// Vendors' ESI files run to tens of MB (one file for a whole product family).
pub const MAX_ESI_FILE_BYTES: u64 = 256 << 20;
/// Segment and scenario descriptions.
pub const MAX_TOML_FILE_BYTES: u64 = 16 << 20;
/// A capture is read whole; larger ones can be split (`editcap -c`).
pub const MAX_CAPTURE_FILE_BYTES: u64 = 1 << 30;

/// The whole file, if it has at most `max_bytes` (whole MiB); `what` names the kind and its
/// limit's reason in the error.
pub fn read_bounded(path: &Path, max_bytes: u64, what: &str) -> io::Result<Vec<u8>> {
    let mut bytes = Vec::new();
    std::fs::File::open(path)?.take(max_bytes.saturating_add(1)).read_to_end(&mut bytes)?;
    if bytes.len() as u64 > max_bytes {
        return Err(io::Error::new(
            io::ErrorKind::InvalidData,
            format!("larger than {} MiB, the limit for {what}", max_bytes >> 20),
        ));
    }
    Ok(bytes)
}

/// As [`read_bounded`], for a text file: invalid UTF-8 is an error giving its byte offset.
pub fn read_bounded_text(path: &Path, max_bytes: u64, what: &str) -> io::Result<String> {
    String::from_utf8(read_bounded(path, max_bytes, what)?).map_err(|e| {
        io::Error::new(
            io::ErrorKind::InvalidData,
            format!("not UTF-8 text: invalid byte at offset {}", e.utf8_error().valid_up_to()),
        )
    })
}

/// An EEPROM dump (binary or text), bounded by [`MAX_EEPROM_FILE_BYTES`].
pub fn read_eeprom_dump(path: &Path) -> io::Result<Vec<u8>> {
    read_bounded(path, MAX_EEPROM_FILE_BYTES, "an EEPROM dump (an SII EEPROM holds at most 512 KiB)")
}

/// An ESI file's text, bounded by [`MAX_ESI_FILE_BYTES`].
pub fn read_esi(path: &Path) -> io::Result<String> {
    // In the encoding the file declares (most of Beckhoff's are ISO-8859-1), UTF-8 or UTF-16.
    let bytes = read_bounded(path, MAX_ESI_FILE_BYTES, "an ESI file")?;
    match ferrocat_esi::text::decode(&bytes) {
        Ok((text, _)) => Ok(text.into_owned()),
        Err(message) => Err(io::Error::new(io::ErrorKind::InvalidData, message)),
    }
}

/// Where `file` (read from `path`) has modular devices whose slots name modules it does not
/// describe, the modules of the `<EtherCATModule>` files beside it (`*.xml` in the same
/// folder, as a configuration tool reads the whole folder of ESI files) of its vendor or none:
/// added to `file.modules`, the file's own first. Returns the module files read. A sibling
/// that cannot be read or parsed is skipped: it is not the file asked for.
pub fn add_module_files(path: &Path, file: &mut ferrocat_esi::EsiFile) -> Vec<std::path::PathBuf> {
    let named: Vec<u32> = file
        .devices
        .iter()
        .filter_map(|d| d.slots.as_ref())
        .flat_map(|s| s.slots.iter())
        .flat_map(|s| s.module_idents.iter().copied().chain(s.default_module))
        .collect();
    let missing = named.iter().any(|i| !file.modules.iter().any(|m| m.ident == *i));
    let Some(dir) = path.parent().filter(|_| missing) else { return Vec::new() };
    let dir = if dir.as_os_str().is_empty() { Path::new(".") } else { dir };
    let Ok(entries) = std::fs::read_dir(dir) else { return Vec::new() };
    let mut siblings: Vec<std::path::PathBuf> = entries
        .filter_map(|e| e.ok().map(|e| e.path()))
        .filter(|p| p.extension().is_some_and(|x| x.eq_ignore_ascii_case("xml")))
        .filter(|p| p.file_name() != path.file_name())
        .collect();
    siblings.sort();
    let mut used = Vec::new();
    for sibling in siblings {
        // The root element is near the start; a file without it there is no module file.
        let head = first_bytes(&sibling, 4096).unwrap_or_default();
        if !String::from_utf8_lossy(&head).contains("<EtherCATModule") {
            continue;
        }
        let Ok(Ok(more)) = read_esi(&sibling).map(|xml| ferrocat_esi::EsiFile::parse(&xml)) else { continue };
        if more.vendor_id != 0 && more.vendor_id != file.vendor_id {
            continue;
        }
        let before = file.modules.len();
        for m in more.modules {
            if !file.modules.iter().any(|o| o.ident == m.ident) {
                file.modules.push(m);
            }
        }
        if file.modules.len() > before {
            used.push(sibling);
        }
    }
    used
}

/// A TOML description's text (`what`: "a segment description", "a scenario"), bounded by
/// [`MAX_TOML_FILE_BYTES`].
pub fn read_toml(path: &Path, what: &str) -> io::Result<String> {
    read_bounded_text(path, MAX_TOML_FILE_BYTES, what)
}

/// A capture, bounded by [`MAX_CAPTURE_FILE_BYTES`].
pub fn read_capture(path: &Path) -> io::Result<Vec<u8>> {
    read_bounded(path, MAX_CAPTURE_FILE_BYTES, "a capture (split larger ones with `editcap -c`)")
}

/// The first `n` bytes of a file (fewer where it is shorter): enough to refuse one that does
/// not begin as its kind does before reading the rest.
pub fn first_bytes(path: &Path, n: u64) -> io::Result<Vec<u8>> {
    let mut first = Vec::new();
    std::fs::File::open(path)?.take(n).read_to_end(&mut first)?;
    Ok(first)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn an_endless_file_is_an_error_not_an_allocation() {
        let e = read_bounded(Path::new("/dev/zero"), 1 << 20, "a test file").unwrap_err();
        assert_eq!(e.kind(), io::ErrorKind::InvalidData);
        assert_eq!(e.to_string(), "larger than 1 MiB, the limit for a test file");
    }

    #[test]
    fn a_file_of_the_bound_is_read_whole_and_text_is_checked() {
        let path = std::env::temp_dir().join(format!("ferrocat-files-{}.txt", std::process::id()));
        std::fs::write(&path, b"ab\xffcd").unwrap();
        assert_eq!(read_bounded(&path, 5, "a test file").unwrap(), b"ab\xffcd");
        assert!(read_bounded(&path, 4, "a test file").is_err());
        let e = read_bounded_text(&path, 5, "a test file").unwrap_err();
        assert!(e.to_string().contains("offset 2"), "{e}");
        std::fs::remove_file(&path).unwrap();
    }
}
