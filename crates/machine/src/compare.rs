//! Compare network configuration (ETG.1500 item 302): the slaves a description expects against
//! the slaves a scan found, every difference named.
//!
//! The two lists are aligned by device (vendor and product code) with the fewest edits, as a
//! diff aligns lines: a slave left out shifts the rest by one and is one `Missing`, not a
//! wrong device at every later position. Two slaves each where the other belongs are
//! `Swapped`; a slave where another device belongs is `WrongDevice`; the right device with
//! another revision, serial number or alias is named as such.
use serde::Serialize;

/// What identifies a device: ETG.1000.6's identity object (0x1018), as the SII holds it.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash, Default, Serialize)]
pub struct Identity {
    /// Vendor ID (ETG-assigned).
    pub vendor_id: u32,
    /// Product code.
    pub product_code: u32,
    /// Revision number.
    pub revision: u32,
    /// Serial number (0: none).
    pub serial: u32,
}

impl std::fmt::Display for Identity {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        write!(f, "vendor {:#x} product {:#x} revision {:#x}", self.vendor_id, self.product_code, self.revision)?;
        if self.serial != 0 {
            write!(f, " serial {}", self.serial)?;
        }
        Ok(())
    }
}

/// Which revisions a slave may have.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize)]
pub enum RevisionCheck {
    /// Any.
    Any,
    /// Exactly the expected one.
    Exact,
    /// From `min` to `max`, both included.
    Range {
        /// Lowest accepted.
        min: u32,
        /// Highest accepted.
        max: u32,
    },
}

/// A slave the description expects.
#[derive(Debug, Clone, PartialEq, Eq, Serialize)]
pub struct Expected {
    /// Its position, from 0.
    pub position: u16,
    /// The name the description gives it.
    pub name: String,
    /// What it must be (its revision checked as `revision` says).
    pub identity: Identity,
    /// Which revisions pass.
    pub revision: RevisionCheck,
    /// The serial number must match too.
    pub check_serial: bool,
    /// The station alias it must have, if any.
    pub alias: Option<u16>,
    /// It may be absent (a hot-connect or optional device): missing, it is no mismatch.
    pub optional: bool,
}

/// A slave the scan found.
#[derive(Debug, Clone, PartialEq, Eq, Serialize)]
pub struct Found {
    /// Its position, from 0.
    pub position: u16,
    /// Its name from the SII.
    pub name: String,
    /// Its identity from the SII.
    pub identity: Identity,
    /// Its station alias (0: none).
    pub alias: u16,
}

/// One difference between the expected and the found network.
#[derive(Debug, Clone, PartialEq, Eq, Serialize)]
#[serde(tag = "kind", rename_all = "snake_case")]
pub enum Mismatch {
    /// An expected slave that is not there; `at` is where it was expected among the found.
    Missing {
        /// The expected slave.
        expected: Expected,
        /// The found position it would have had.
        at: u16,
    },
    /// A slave found that nothing expects.
    Extra {
        /// The slave.
        found: Found,
    },
    /// Two slaves each at the other's position.
    Swapped {
        /// The slave expected at the first position.
        first: Expected,
        /// The slave expected at the second position.
        second: Expected,
    },
    /// Another device where the expected one belongs.
    WrongDevice {
        /// What was expected.
        expected: Expected,
        /// What is there.
        found: Found,
    },
    /// The expected device with a revision outside what is accepted.
    WrongRevision {
        /// What was expected.
        expected: Expected,
        /// What is there.
        found: Found,
    },
    /// The expected device with another serial number.
    WrongSerial {
        /// What was expected.
        expected: Expected,
        /// What is there.
        found: Found,
    },
    /// The expected device with another station alias.
    WrongAlias {
        /// What was expected.
        expected: Expected,
        /// What is there.
        found: Found,
    },
}

impl std::fmt::Display for Mismatch {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        let e = |x: &Expected| format!("'{}' ({})", x.name, x.identity);
        let g = |x: &Found| format!("'{}' ({})", x.name, x.identity);
        match self {
            Mismatch::Missing { expected, at } => {
                write!(f, "position {}: {} missing (expected at found position {at})", expected.position, e(expected))
            }
            Mismatch::Extra { found } => write!(f, "position {}: {} found, not expected", found.position, g(found)),
            Mismatch::Swapped { first, second } => write!(
                f,
                "positions {} and {} swapped: {} and {} are each at the other's place",
                first.position,
                second.position,
                e(first),
                e(second)
            ),
            Mismatch::WrongDevice { expected, found } => {
                write!(f, "position {}: expected {}, found {}", expected.position, e(expected), g(found))
            }
            Mismatch::WrongRevision { expected, found } => write!(
                f,
                "position {}: '{}' has revision {:#x}, expected {}",
                found.position,
                expected.name,
                found.identity.revision,
                match expected.revision {
                    RevisionCheck::Range { min, max } => format!("{min:#x} to {max:#x}"),
                    _ => format!("{:#x}", expected.identity.revision),
                }
            ),
            Mismatch::WrongSerial { expected, found } => write!(
                f,
                "position {}: '{}' has serial number {}, expected {}",
                found.position, expected.name, found.identity.serial, expected.identity.serial
            ),
            Mismatch::WrongAlias { expected, found } => write!(
                f,
                "position {}: '{}' has station alias {:#06x}, expected {:#06x}",
                found.position,
                expected.name,
                found.alias,
                expected.alias.unwrap_or(0)
            ),
        }
    }
}

/// How the two lists line up.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
enum Step {
    /// The same device at both.
    Same(usize, usize),
    /// Different devices at both.
    Other(usize, usize),
    /// Expected, not found.
    Missing(usize),
    /// Found, not expected.
    Extra(usize),
}

fn device(i: &Identity) -> (u32, u32) {
    (i.vendor_id, i.product_code)
}

/// A slave missing or extra costs this much in the alignment ...
const GAP: u32 = 5;
/// ... and another device in place this much: less than a gap, so that two slaves each at the
/// other's place read as a swap (two in place, 8) rather than one missing and one extra (10),
/// but three in a row more than a missing and an extra slave (12), which is what a slave left
/// out early and one added late look like.
const OTHER: u32 = 4;

/// The cheapest alignment (Wagner–Fischer edit distance, with the costs above).
fn align(expected: &[Expected], found: &[Found]) -> Vec<Step> {
    let (n, m) = (expected.len(), found.len());
    // Beyond 16 M cells (4 096 slaves each way), position by position: the table would be
    // larger than a master should take for a check.
    if (n + 1).saturating_mul(m + 1) > 1 << 24 {
        return (0..n.max(m))
            .map(|k| match (k < n, k < m) {
                (true, true) if device(&expected[k].identity) == device(&found[k].identity) => Step::Same(k, k),
                (true, true) => Step::Other(k, k),
                (true, false) => Step::Missing(k),
                _ => Step::Extra(k),
            })
            .collect();
    }
    let mut cost = vec![vec![0u32; m + 1]; n + 1];
    for (i, row) in cost.iter_mut().enumerate() {
        row[0] = i as u32 * GAP;
    }
    for (j, c) in cost[0].iter_mut().enumerate() {
        *c = j as u32 * GAP;
    }
    for i in 1..=n {
        for j in 1..=m {
            let same = device(&expected[i - 1].identity) == device(&found[j - 1].identity);
            let diag = cost[i - 1][j - 1] + if same { 0 } else { OTHER };
            cost[i][j] = diag.min(cost[i - 1][j] + GAP).min(cost[i][j - 1] + GAP);
        }
    }
    let mut steps = Vec::with_capacity(n.max(m));
    let (mut i, mut j) = (n, m);
    // Traced back from the end, a gap before a step in place where both cost the same: the
    // differences land as late as they can, so that a short network reads "the last ones
    // missing" and each found slave is compared with the one expected at its own position.
    while i > 0 || j > 0 {
        if i > 0 && cost[i][j] == cost[i - 1][j] + GAP {
            steps.push(Step::Missing(i - 1));
            i -= 1;
        } else if j > 0 && cost[i][j] == cost[i][j - 1] + GAP {
            steps.push(Step::Extra(j - 1));
            j -= 1;
        } else {
            let same = device(&expected[i - 1].identity) == device(&found[j - 1].identity);
            steps.push(if same { Step::Same(i - 1, j - 1) } else { Step::Other(i - 1, j - 1) });
            i -= 1;
            j -= 1;
        }
    }
    steps.reverse();
    steps
}

/// Every difference between the slaves `expected` and those `found`, in network order; empty
/// when the network is as described.
pub fn compare(expected: &[Expected], found: &[Found]) -> Vec<Mismatch> {
    let steps = align(expected, found);
    let mut out = Vec::new();
    let mut paired = vec![false; steps.len()];
    for (k, step) in steps.iter().enumerate() {
        match *step {
            Step::Same(e, f) => {
                let (x, y) = (&expected[e], &found[f]);
                let rev = y.identity.revision;
                let rev_ok = match x.revision {
                    RevisionCheck::Any => true,
                    RevisionCheck::Exact => rev == x.identity.revision,
                    RevisionCheck::Range { min, max } => (min..=max).contains(&rev),
                };
                let pair = || (x.clone(), y.clone());
                if !rev_ok {
                    let (expected, found) = pair();
                    out.push(Mismatch::WrongRevision { expected, found });
                }
                if x.check_serial && x.identity.serial != y.identity.serial {
                    let (expected, found) = pair();
                    out.push(Mismatch::WrongSerial { expected, found });
                }
                if x.alias.is_some_and(|a| a != y.alias) {
                    let (expected, found) = pair();
                    out.push(Mismatch::WrongAlias { expected, found });
                }
            }
            Step::Other(e, f) if !paired[k] => {
                // Each where the other belongs: a swap.
                let partner = steps.iter().enumerate().skip(k + 1).find_map(|(k2, s)| match *s {
                    Step::Other(e2, f2)
                        if !paired[k2]
                            && device(&expected[e].identity) == device(&found[f2].identity)
                            && device(&expected[e2].identity) == device(&found[f].identity) =>
                    {
                        Some((k2, e2))
                    }
                    _ => None,
                });
                match partner {
                    Some((k2, e2)) => {
                        paired[k2] = true;
                        out.push(Mismatch::Swapped { first: expected[e].clone(), second: expected[e2].clone() });
                    }
                    None => out.push(Mismatch::WrongDevice { expected: expected[e].clone(), found: found[f].clone() }),
                }
            }
            Step::Other(..) => {}
            Step::Missing(e) if !expected[e].optional => {
                let at = steps[..k].iter().filter(|s| !matches!(s, Step::Missing(_))).count() as u16;
                out.push(Mismatch::Missing { expected: expected[e].clone(), at });
            }
            Step::Missing(_) => {}
            Step::Extra(f) => out.push(Mismatch::Extra { found: found[f].clone() }),
        }
    }
    out
}

#[cfg(test)]
mod tests {
    use super::*;

    fn id(product: u32, revision: u32) -> Identity {
        Identity { vendor_id: 2, product_code: product, revision, serial: 0 }
    }

    fn exp(list: &[(u32, u32)]) -> Vec<Expected> {
        list.iter()
            .enumerate()
            .map(|(k, &(p, r))| Expected {
                position: k as u16,
                name: format!("E{p}"),
                identity: id(p, r),
                revision: RevisionCheck::Exact,
                check_serial: false,
                alias: None,
                optional: false,
            })
            .collect()
    }

    fn found(list: &[(u32, u32)]) -> Vec<Found> {
        list.iter()
            .enumerate()
            .map(|(k, &(p, r))| Found { position: k as u16, name: format!("F{p}"), identity: id(p, r), alias: 0 })
            .collect()
    }

    fn kinds(m: &[Mismatch]) -> Vec<String> {
        m.iter().map(|m| serde_json::to_value(m).unwrap()["kind"].as_str().unwrap().to_string()).collect()
    }

    #[test]
    fn each_kind_of_difference_is_named() {
        let line = [(1, 1), (2, 1), (3, 1), (4, 1)];
        assert!(compare(&exp(&line), &found(&line)).is_empty());
        // One left out: the rest shift, one missing.
        let m = compare(&exp(&line), &found(&[(1, 1), (3, 1), (4, 1)]));
        assert_eq!(kinds(&m), ["missing"]);
        assert!(
            m[0].to_string().starts_with("position 1: 'E2' (vendor 0x2 product 0x2 revision 0x1) missing"),
            "{}",
            m[0]
        );
        // One more at the end, and one in the middle.
        assert_eq!(kinds(&compare(&exp(&line), &found(&[(1, 1), (2, 1), (3, 1), (4, 1), (9, 1)]))), ["extra"]);
        assert_eq!(kinds(&compare(&exp(&line), &found(&[(1, 1), (9, 1), (2, 1), (3, 1), (4, 1)]))), ["extra"]);
        // Two each at the other's place.
        let m = compare(&exp(&line), &found(&[(1, 1), (3, 1), (2, 1), (4, 1)]));
        assert_eq!(kinds(&m), ["swapped"]);
        assert!(m[0].to_string().starts_with("positions 1 and 2 swapped"), "{}", m[0]);
        // Two fewer, one of them another device: the device in place, the last ones missing.
        let m = compare(&exp(&line), &found(&[(1, 1), (7, 1)]));
        assert_eq!(kinds(&m), ["wrong_device", "missing", "missing"]);
        assert!(m[0].to_string().starts_with("position 1: expected 'E2'"), "{}", m[0]);
        // One left out early, one added late: so named, not three wrong devices.
        let m = compare(&exp(&line), &found(&[(1, 1), (3, 1), (4, 1), (9, 1)]));
        assert_eq!(kinds(&m), ["missing", "extra"]);
        // Another device in place.
        let m = compare(&exp(&line), &found(&[(1, 1), (2, 1), (7, 1), (4, 1)]));
        assert_eq!(kinds(&m), ["wrong_device"]);
        assert!(m[0].to_string().contains("position 2: expected 'E3'") && m[0].to_string().contains("found 'F7'"));
        // The right device, another revision: exact refuses, a range or any accepts.
        let newer = found(&[(1, 1), (2, 5), (3, 1), (4, 1)]);
        assert_eq!(kinds(&compare(&exp(&line), &newer)), ["wrong_revision"]);
        let mut ranged = exp(&line);
        ranged[1].revision = RevisionCheck::Range { min: 1, max: 5 };
        assert!(compare(&ranged, &newer).is_empty());
        ranged[1].revision = RevisionCheck::Range { min: 1, max: 4 };
        assert_eq!(kinds(&compare(&ranged, &newer)), ["wrong_revision"]);
        ranged[1].revision = RevisionCheck::Any;
        assert!(compare(&ranged, &newer).is_empty());
        // Serial number and alias, where the description asks for them.
        let mut strict = exp(&line);
        strict[3].check_serial = true;
        strict[3].identity.serial = 42;
        strict[0].alias = Some(0x10);
        assert_eq!(kinds(&compare(&strict, &found(&line))), ["wrong_alias", "wrong_serial"]);
        // An optional slave may be absent; not so a required one.
        let mut optional = exp(&line);
        optional[3].optional = true;
        assert!(compare(&optional, &found(&[(1, 1), (2, 1), (3, 1)])).is_empty());
        assert_eq!(kinds(&compare(&exp(&line), &found(&[]))), ["missing"; 4]);
        assert_eq!(kinds(&compare(&[], &found(&line))), ["extra"; 4]);
        // Past the alignment's size, position by position.
        let many: Vec<(u32, u32)> = (0..5000).map(|k| (k % 7, 1)).collect();
        let mut fewer = many.clone();
        fewer[10].0 = 99;
        fewer.truncate(4100);
        let m = compare(&exp(&many), &found(&fewer));
        assert_eq!(m.len(), 1 + 900);
        assert_eq!(kinds(&m[..1]), ["wrong_device"]);
    }
}
