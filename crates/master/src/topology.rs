//! Where each slave hangs, from what the master can read: the order in which the frame passes
//! the processing units (the positions), each slave's active ports and the port the frame
//! entered by.
//!
//! A frame entering an ESC on port `e` goes round the ring 0 → EPU → 3 → 1 → 2 → 0 from `e`,
//! out and back through every open port (esc-spec §2). With every entry on port 0 the
//! processing order is a pre-order walk of the tree and counting ports suffices (SOEM's way).
//! Reversed cabling puts the processing unit after some branches — a slave entered on port 1
//! is processed after the slaves behind its port 0 — so the order is parsed as a grammar:
//! a slave's subtree is its branches before the EPU, itself, its branches after.
//!
//! Ports and order alone can fit two trees (a slave entered on port 1 with a branch on port 0
//! looks the same whether the branch or the slave is nearer the master); the receive times
//! decide: the frame spends longer behind a port than anywhere inside what hangs on it.
use std::collections::HashMap;

/// What the master knows about one slave, by position.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct PortView {
    pub entry_port: u8,
    pub active_ports: [bool; 4],
    /// Ports the ESC has (0x0007); an inactive one the frame passes loops it back.
    pub present_ports: [bool; 4],
    /// The receive-time latches of ports 0–3 (local ns, low 32 bits), for a DC slave.
    pub receive_times: Option<[u32; 4]>,
    /// The processing unit's receive time (0x0918, low 32 bits) from the same frame.
    pub epu_time: Option<u32>,
}

/// Where a slave hangs: its parent's position and the parent's port.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct Link {
    pub parent: usize,
    pub port: u8,
}

/// The port after `p` in the processing order 0 → (EPU) → 3 → 1 → 2 → 0.
fn next(p: u8) -> u8 {
    [3, 2, 0, 1][(p & 3) as usize]
}

/// The ring of an ESC; `None` is the processing unit.
const RING: [Option<u8>; 5] = [Some(0), None, Some(3), Some(1), Some(2)];

impl PortView {
    /// The branches (active ports other than the entry) before and after the processing
    /// unit, in the order the frame takes them.
    fn branches(&self) -> (Vec<u8>, Vec<u8>) {
        let e = (self.entry_port & 3) as usize;
        let start = RING.iter().position(|&p| p == Some(e as u8)).unwrap_or(0);
        let (mut pre, mut post, mut seen_epu) = (Vec::new(), Vec::new(), false);
        for k in 1..RING.len() {
            match RING[(start + k) % RING.len()] {
                None => seen_epu = true,
                Some(p) if self.active_ports[p as usize] && p as usize != e => {
                    if seen_epu {
                        post.push(p)
                    } else {
                        pre.push(p)
                    }
                }
                Some(_) => {}
            }
        }
        (pre, post)
    }

    /// `b - a` of two latched times, across the 32-bit wrap.
    pub fn between(&self, a: u8, b: u8) -> Option<i64> {
        let t = self.receive_times?;
        Some(t[b as usize].wrapping_sub(t[a as usize]) as i32 as i64)
    }

    /// How long the frame spent in this slave and behind it: entry to the last return or to
    /// the processing unit, whichever is later (a slave entered elsewhere than on port 0 may
    /// reach its processing unit last, through closed ports).
    pub fn span_ns(&self) -> Option<i64> {
        let t = self.receive_times?;
        let entry = t[(self.entry_port & 3) as usize];
        let returns = (0..4u8).filter(|&p| self.active_ports[p as usize]).map(|p| self.between(self.entry_port & 3, p));
        let epu = self.epu_time.map(|e| e.wrapping_sub(entry) as i32 as i64);
        returns.chain([epu]).max()?
    }

    /// The port the frame came from before it left through `port`: in ring order the previous
    /// active one, or the entry.
    pub fn before(&self, port: u8) -> u8 {
        let e = self.entry_port & 3;
        let mut q = port & 3;
        for _ in 0..4 {
            q = [2, 3, 1, 0][q as usize];
            if self.active_ports[q as usize] || q == e {
                break;
            }
        }
        q
    }

    /// Closed ports (present, inactive) the frame loops through after `from` until it reaches
    /// `to`, in ring order; `from == to` is the whole ring.
    pub fn loops_between(&self, from: u8, to: u8) -> i64 {
        let (mut q, mut n) = (next(from), 0);
        while q != to & 3 {
            n += (self.present_ports[q as usize] && !self.active_ports[q as usize]) as i64;
            q = next(q);
        }
        n
    }

    /// Closed ports the frame loops through after this slave's last event (its last returning
    /// branch, or the processing unit if that comes later) until it leaves by the entry port:
    /// time a child spends on the way back that its latches do not show.
    pub fn loops_after_last_event(&self) -> i64 {
        let e = self.entry_port & 3;
        let (mut q, mut last) = (next(e), e);
        while q != e {
            if self.active_ports[q as usize] || q == 0 {
                last = q;
            }
            q = next(q);
        }
        // The processing unit sits at port 0; with the entry on port 0 it is the entry itself.
        self.loops_between(last, e)
    }

    /// The port the frame goes to after returning through `port`: in ring order the next
    /// active one, or the entry.
    pub fn after(&self, port: u8) -> u8 {
        let e = self.entry_port & 3;
        let mut q = port & 3;
        for _ in 0..4 {
            q = next(q);
            if self.active_ports[q as usize] || q == e {
                break;
            }
        }
        q
    }

    /// When the frame left for `port` (ns after this slave's entry) and the closed ports it
    /// looped through on the way: from the return or entry before it, or from the processing
    /// unit where that lies between them and was latched later (a slave entered elsewhere
    /// than on port 0 may reach its processing unit only through closed ports, whose time
    /// 0x0918 shows).
    pub fn leaves_for(&self, port: u8) -> Option<(i64, i64)> {
        let (e, before) = (self.entry_port & 3, self.before(port));
        let at = self.between(e, before)?;
        // The processing unit sits between port 0 and port 3: on the way iff port 0 is.
        let mut q = before;
        let mut epu_on_way = false;
        while q != port & 3 {
            epu_on_way |= q == 0;
            q = next(q);
        }
        let epu = self.epu_time.zip(self.receive_times).map(|(epu, t)| epu.wrapping_sub(t[e as usize]) as i32 as i64);
        match epu {
            Some(epu) if epu_on_way && epu > at => Some((epu, self.loops_between(0, port))),
            _ => Some((at, self.loops_between(before, port))),
        }
    }

    /// How long the frame was out through `port`, from leaving `before(port)` to its return.
    fn loop_ns(&self, port: u8) -> Option<i64> {
        self.between(self.before(port), port)
    }
}

/// Parses the whole segment as one subtree hanging on the master; `None` when no tree fits the
/// ports (a link changed between reads, or a slave misreports) or the search would exceed its
/// budget, in which case the caller falls back to counting ports.
pub fn infer(view: &[PortView]) -> Option<Vec<Option<Link>>> {
    if view.is_empty() {
        return Some(Vec::new());
    }
    let mut p =
        Parser { view, branches: view.iter().map(|v| v.branches()).collect(), memo: HashMap::new(), budget: 1 << 20 };
    let mut links = vec![None; view.len()];
    p.subtree(0, view.len(), &mut links)?;
    Some(links)
}

struct Parser<'a> {
    view: &'a [PortView],
    branches: Vec<(Vec<u8>, Vec<u8>)>,
    /// Whether positions a..b form one subtree, and its root.
    memo: HashMap<(usize, usize), Option<usize>>,
    budget: u32,
}

impl Parser<'_> {
    /// Positions a..b as one subtree: returns its root and records every link inside it.
    fn subtree(&mut self, a: usize, b: usize, links: &mut [Option<Link>]) -> Option<usize> {
        let r = self.root_of(a, b)?;
        let (pre, post) = self.branches[r].clone();
        let mut starts = self.split(a, r, pre.len())?;
        starts.push(r);
        let mut after = self.split(r + 1, b, post.len())?;
        after.push(b);
        for (k, &port) in pre.iter().enumerate() {
            let child = self.subtree(starts[k], starts[k + 1], links)?;
            links[child] = Some(Link { parent: r, port });
        }
        for (k, &port) in post.iter().enumerate() {
            let child = self.subtree(after[k], after[k + 1], links)?;
            links[child] = Some(Link { parent: r, port });
        }
        Some(r)
    }

    /// The root of a..b if it is one subtree. A root with no branch before its processing
    /// unit is the first of the range; any other stands after its earlier branches.
    fn root_of(&mut self, a: usize, b: usize) -> Option<usize> {
        if a >= b {
            return None;
        }
        if let Some(&r) = self.memo.get(&(a, b)) {
            return r;
        }
        let mut found = None;
        for r in a..b {
            self.budget = self.budget.checked_sub(1)?;
            let (pre, post) = (self.branches[r].0.len(), self.branches[r].1.len());
            if (pre == 0) != (r == a) || (pre == 0 && post == 0 && b != a + 1) {
                continue;
            }
            if self.fits(a, b, r) {
                found = Some(r);
                break;
            }
        }
        self.memo.insert((a, b), found);
        found
    }

    /// Whether `r` can be the root of a..b: its branches split the rest, and each branch's
    /// subtree took less time than the frame spent behind that port.
    fn fits(&mut self, a: usize, b: usize, r: usize) -> bool {
        let (pre, post) = self.branches[r].clone();
        let (Some(mut starts), Some(mut after)) = (self.split(a, r, pre.len()), self.split(r + 1, b, post.len()))
        else {
            return false;
        };
        starts.push(r);
        after.push(b);
        let ranges = starts.windows(2).chain(after.windows(2)).map(|w| (w[0], w[1])).collect::<Vec<_>>();
        for (&port, (x, y)) in pre.iter().chain(&post).zip(ranges) {
            let Some(child) = self.root_of(x, y) else { return false };
            if let (Some(out), Some(inside)) = (self.view[r].loop_ns(port), self.view[child].span_ns()) {
                if out <= inside {
                    return false;
                }
            }
        }
        true
    }

    /// Where a..b splits into `k` consecutive subtrees: their first positions.
    fn split(&mut self, a: usize, b: usize, k: usize) -> Option<Vec<usize>> {
        if k == 0 {
            return (a == b).then(Vec::new);
        }
        if b - a < k {
            return None;
        }
        if k == 1 {
            return self.root_of(a, b).map(|_| vec![a]);
        }
        for m in a + 1..=b - (k - 1) {
            if self.root_of(a, m).is_some() {
                if let Some(mut rest) = self.split(m, b, k - 1) {
                    rest.insert(0, a);
                    return Some(rest);
                }
            }
        }
        None
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn v(entry_port: u8, ports: &[u8]) -> PortView {
        let mut active_ports = [false; 4];
        for &p in ports {
            active_ports[p as usize] = true;
        }
        PortView { entry_port, active_ports, present_ports: [true; 4], receive_times: None, epu_time: None }
    }

    #[test]
    fn closed_ports_on_the_way_out_and_back() {
        // An EK1100 (ports 0, 1, 2; no 3) entered on 0: ring 0 → EPU → 3 → 1 → 2 → 0.
        let ek = |ports: &[u8]| PortView { present_ports: [true, true, true, false], ..v(0, ports) };
        assert_eq!(ek(&[0, 1]).loops_between(0, 1), 0, "port 3 is absent");
        assert_eq!(ek(&[0, 2]).loops_between(0, 2), 1, "closed port 1 before port 2");
        assert_eq!(ek(&[0, 1]).loops_after_last_event(), 1, "closed port 2 after the child on 1");
        assert_eq!(ek(&[0]).loops_after_last_event(), 2, "a leaf loops at 1 and 2");
        assert_eq!(ek(&[0, 1]).after(1), 0);
        // Entered on port 1 with nothing else: 1 → 2 → 0 (EPU) → 3 → 1; 3 comes after the EPU.
        assert_eq!(v(1, &[1]).loops_after_last_event(), 1);
        assert_eq!(v(1, &[1, 3]).loops_after_last_event(), 0);
    }

    /// With receive times: (port, ns after entry) for every active port but the entry.
    fn t(entry_port: u8, ports: &[(u8, u32)], local: u32) -> PortView {
        let mut times = [local; 4];
        let mut view = v(entry_port, &[entry_port]);
        for &(p, dt) in ports {
            view.active_ports[p as usize] = true;
            times[p as usize] = local.wrapping_add(dt);
        }
        PortView { receive_times: Some(times), epu_time: Some(times[0]), ..view }
    }

    #[test]
    fn a_port_after_the_processing_unit_is_left_for_once_the_frame_has_passed_it() {
        // An EK1100 entered on port 2 (a ring's far coupler seen from the secondary), port 0
        // closed: 2 → 0 (loop-back) → EPU 90 ns after entry → 1, where a terminal answers at
        // +400. The frame left for port 1 at the EPU, not at the entry.
        let mut far = t(2, &[(1, 400)], 1_000);
        far.present_ports = [true, true, true, false];
        far.epu_time = Some(1_090);
        assert_eq!(far.leaves_for(1), Some((90, 0)));
        // Entered on port 0 the EPU is the entry: nothing changes (closed port 3 on the way).
        let line = t(0, &[(1, 310)], 5);
        assert_eq!(line.leaves_for(1), Some((0, 1)));
        // A branch before the EPU (entered on 1, a branch on 0): left for at the entry.
        let reversed = PortView { epu_time: Some(7 + 500), ..t(1, &[(0, 400)], 7) };
        assert_eq!(reversed.leaves_for(0), Some((0, 1)), "closed port 2 on the way");
        // After that branch and the EPU, port 3: from the EPU, which came after port 0's return.
        let with_3 = PortView { epu_time: Some(7 + 420), ..t(1, &[(0, 400), (3, 700)], 7) };
        assert_eq!(with_3.leaves_for(3), Some((420, 0)));
    }

    fn links(view: &[PortView]) -> Vec<Option<(usize, u8)>> {
        infer(view).expect("a tree").into_iter().map(|l| l.map(|l| (l.parent, l.port))).collect()
    }

    #[test]
    fn a_line_is_a_chain_on_port_1() {
        let view = [v(0, &[0, 1]), v(0, &[0, 1]), v(0, &[0])];
        assert_eq!(links(&view), [None, Some((0, 1)), Some((1, 1))]);
    }

    #[test]
    fn a_junction_takes_port_3_before_1_and_2() {
        // EK1122-like: ports 0, 3, 1; a terminal on 3, a line of two on 1.
        let view = [v(0, &[0, 1, 3]), v(0, &[0]), v(0, &[0, 1]), v(0, &[0])];
        assert_eq!(links(&view), [None, Some((0, 3)), Some((0, 1)), Some((2, 1))]);
    }

    #[test]
    fn a_slave_entered_on_port_1_comes_after_what_hangs_on_its_port_0() {
        // Master → A(0) ─p1→ B (entered on 1) ─p0→ C. Processing order A, C, B.
        let view = [v(0, &[0, 1]), v(0, &[0]), v(1, &[0, 1])];
        assert_eq!(links(&view), [None, Some((2, 0)), Some((0, 1))]);
    }

    #[test]
    fn receive_times_decide_between_two_trees_that_fit_the_ports() {
        // Order A, C, B with A (0; 0, 1), C a leaf, B (entered on 1; 0, 1) fits
        // master → A ─p1→ B ─p0→ C as well as master → B ─p0→ A ─p1→ C.
        // Local clocks far apart and across the 32-bit wrap: only differences count.
        let a_outer = [t(0, &[(1, 900)], u32::MAX - 100), t(0, &[], 7), t(1, &[(0, 400)], 123_456)];
        assert_eq!(links(&a_outer), [None, Some((2, 0)), Some((0, 1))]);
        let b_outer = [t(0, &[(1, 400)], 5), t(0, &[], 7), t(1, &[(0, 900)], u32::MAX - 10)];
        assert_eq!(links(&b_outer), [Some((2, 0)), Some((0, 1)), None]);
    }

    #[test]
    fn ports_that_fit_no_tree_are_refused() {
        // Two leaves with nothing to hang the second on.
        assert!(infer(&[v(0, &[0]), v(0, &[0])]).is_none());
    }
}
