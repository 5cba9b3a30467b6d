//! Value parsers for numbers a user types where clap's would answer in its own words, or
//! take a leading minus for a flag: a slave's position and a number of seconds.

/// A slave's position on the segment: a number from 0, as `scan` shows it.
pub fn position(s: &str) -> Result<u16, String> {
    let t = s.trim();
    match t.parse::<i64>() {
        Ok(n) if n < 0 => Err(format!("positions count from 0 (the first slave is 0, as `scan` shows it), not {n}")),
        Ok(n) => u16::try_from(n).map_err(|_| format!("{n} is past the last position a segment can have (65535)")),
        Err(_) => Err(format!("'{t}' is not a slave's position (a number from 0, as `scan` shows it)")),
    }
}

/// A number of seconds, 0 or more.
pub fn seconds(s: &str) -> Result<f64, String> {
    match s.trim().parse::<f64>() {
        Ok(v) if v.is_finite() && v >= 0.0 => Ok(v),
        Ok(v) => Err(format!("{v} s: give 0 or more seconds")),
        Err(_) => Err(format!("'{}' is not a number of seconds", s.trim())),
    }
}

/// A cycle time in µs within `lo..=hi`, said in those words where it is not.
pub fn cycle_us(s: &str, lo: u64, hi: u64) -> Result<u64, String> {
    let t = s.trim();
    match t.parse::<i64>() {
        Ok(n) if (lo as i64..=hi as i64).contains(&n) => Ok(n as u64),
        Ok(n) => Err(format!("{n} µs: give a cycle time from {lo} to {hi} µs")),
        Err(_) => Err(format!("'{t}' is not a cycle time (a whole number of µs, {lo} to {hi})")),
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn positions_and_seconds_say_what_is_wrong() {
        assert_eq!(position("3"), Ok(3));
        assert!(position("-1").unwrap_err().contains("count from 0"));
        assert!(position("70000").unwrap_err().contains("65535"));
        assert!(position("x").unwrap_err().contains("not a slave's position"));
        assert_eq!(seconds("0"), Ok(0.0));
        assert!(seconds("-1").unwrap_err().contains("0 or more"));
        assert!(seconds("inf").unwrap_err().contains("0 or more"));
        assert!(seconds("soon").unwrap_err().contains("not a number of seconds"));
        assert_eq!(cycle_us("250", 10, 1000), Ok(250));
        assert!(cycle_us("5", 10, 1000).unwrap_err().contains("from 10 to 1000 µs"));
        assert!(cycle_us("-1", 10, 1000).unwrap_err().contains("from 10 to 1000 µs"));
        assert!(cycle_us("1ms", 10, 1000).unwrap_err().contains("not a cycle time"));
    }
}
