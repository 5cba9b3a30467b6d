//! An XML file's bytes as text: UTF-8 (with or without a BOM), UTF-16 by its BOM, or the 8-bit
//! encoding its XML declaration names. The ESI and ENI readers both take their files so.

/// The text of `bytes`, and a note when it was not UTF-8. XML files say their encoding in the
/// declaration (`<?xml version="1.0" encoding="ISO-8859-1"?>`); TwinCAT and many vendors'
/// tools write ISO-8859-1, whose bytes are read as windows-1252 (its superset, as the WHATWG
/// encoding standard maps the label).
pub fn decode(bytes: &[u8]) -> Result<(std::borrow::Cow<'_, str>, Option<String>), String> {
    for (bom, enc) in [(&b"\xFF\xFE"[..], encoding_rs::UTF_16LE), (&b"\xFE\xFF"[..], encoding_rs::UTF_16BE)] {
        if bytes.starts_with(bom) {
            let (text, had_errors) = enc.decode_without_bom_handling(&bytes[2..]);
            if had_errors {
                return Err(format!("not valid {} text", enc.name()));
            }
            return Ok((text, Some(format!("read as {} (its byte-order mark)", enc.name()))));
        }
    }
    let bytes = bytes.strip_prefix(b"\xEF\xBB\xBF").unwrap_or(bytes);
    if let Ok(s) = std::str::from_utf8(bytes) {
        return Ok((s.into(), None));
    }
    let label = declared_encoding(bytes);
    let Some(enc) = label.as_deref().and_then(|l| encoding_rs::Encoding::for_label(l.as_bytes())) else {
        let at = std::str::from_utf8(bytes).err().map_or(0, |e| e.valid_up_to());
        return Err(match label {
            Some(l) => format!("declares encoding '{l}', which is not one this reader knows"),
            None => format!("not UTF-8 text (byte {at}) and its XML declaration names no encoding"),
        });
    };
    let (text, _, had_errors) = enc.decode(bytes);
    if had_errors {
        return Err(format!("not valid {} text", enc.name()));
    }
    Ok((text, Some(format!("read as {} (its declaration)", enc.name()))))
}

/// The `encoding="…"` of the XML declaration at the start of `bytes`, if any.
fn declared_encoding(bytes: &[u8]) -> Option<String> {
    let head = &bytes[..bytes.len().min(200)];
    let end = head.windows(2).position(|w| w == b"?>")?;
    let decl = std::str::from_utf8(&head[..end]).ok()?;
    let rest = &decl[decl.find("encoding")? + "encoding".len()..];
    let rest = rest.trim_start().strip_prefix('=')?.trim_start();
    let quote = rest.chars().next().filter(|c| *c == '"' || *c == '\'')?;
    let value = &rest[1..];
    Some(value[..value.find(quote)?].to_string())
}

#[cfg(test)]
mod tests {
    use super::decode;

    #[test]
    fn utf8_latin1_and_unknown_encodings() {
        assert_eq!(decode(b"<a>\xC3\xA9</a>").unwrap().0, "<a>\u{e9}</a>");
        let latin = b"<?xml version=\"1.0\" encoding=\"ISO-8859-1\"?><a>\xE9</a>";
        let (text, note) = decode(latin).unwrap();
        assert!(text.ends_with("<a>\u{e9}</a>") && note.unwrap().contains("windows-1252"));
        let err = decode(b"<?xml version='1.0' encoding='klingon'?><a>\xE9</a>").unwrap_err();
        assert!(err.contains("'klingon'"), "{err}");
        let err = decode(b"<a>\xE9</a>").unwrap_err();
        assert!(err.contains("byte 3"), "{err}");
        // UTF-8 with a BOM, and UTF-16 by its BOM.
        assert_eq!(decode(b"\xEF\xBB\xBF<a/>").unwrap().0, "<a/>");
        let utf16: Vec<u8> =
            [0xFF, 0xFE].into_iter().chain("<a>\u{e9}</a>".encode_utf16().flat_map(u16::to_le_bytes)).collect();
        assert_eq!(decode(&utf16).unwrap().0, "<a>\u{e9}</a>");
    }
}
