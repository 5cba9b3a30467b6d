//! ESI's numbers, read without the XML around them.

/// ESI numbers: `#x1A00` (hex), `0x1A00`, or decimal with an optional sign.
pub fn parse_number(s: &str) -> Option<i64> {
    let s = s.trim();
    let (neg, body) = match s.strip_prefix('-') {
        Some(b) => (true, b),
        None => (false, s),
    };
    let v = if let Some(h) =
        body.strip_prefix("#x").or_else(|| body.strip_prefix("0x")).or_else(|| body.strip_prefix("#X"))
    {
        i64::from_str_radix(h, 16).ok()?
    } else {
        body.parse::<i64>().ok()?
    };
    Some(if neg { -v } else { v })
}
