//! The packet ring on a veth pair in two namespaces this test makes and removes (root).
use std::process::Command;

use ferrocat_link::{enter_netns, monotonic_ns, RawSocket, RingSocket};

fn ip(args: &[&str]) {
    let out = Command::new("ip").args(args).output().expect("the ip command (iproute2) is needed");
    assert!(out.status.success(), "ip {}: {}", args.join(" "), String::from_utf8_lossy(&out.stderr));
}

struct Pair {
    ns: [String; 2],
    ifs: [String; 2],
}

impl Pair {
    fn new(tag: &str) -> Self {
        let id = std::process::id() % 100_000;
        let p = Pair {
            ns: [format!("fcl{tag}{id}a"), format!("fcl{tag}{id}b")],
            ifs: [format!("fcl{tag}{id}a"), format!("fcl{tag}{id}b")],
        };
        for ns in &p.ns {
            let _ = Command::new("ip").args(["netns", "del", ns]).output();
            ip(&["netns", "add", ns]);
            // No IPv6 on the pair: the kernel's own router solicitations and MLD reports,
            // sent a moment after a link comes up, would reach a socket that takes every
            // frame (once, in CI, one came where the test waits for silence). A kernel
            // without IPv6 has nothing to turn off.
            for conf in ["default", "all"] {
                let _ = Command::new("ip")
                    .args(["netns", "exec", ns, "sh", "-c"])
                    .arg(format!("echo 1 > /proc/sys/net/ipv6/conf/{conf}/disable_ipv6"))
                    .output();
            }
        }
        ip(&["link", "add", &p.ifs[0], "type", "veth", "peer", "name", &p.ifs[1]]);
        for k in 0..2 {
            ip(&["link", "set", &p.ifs[k], "netns", &p.ns[k]]);
            // Room for a frame longer than a ring slot.
            ip(&["-n", &p.ns[k], "link", "set", &p.ifs[k], "mtu", "9000", "up"]);
        }
        p
    }

    /// A socket on side `k`, opened from inside its namespace (on a thread of its own, which
    /// the namespace change is confined to).
    fn open(&self, k: usize) -> RawSocket {
        let (ns, ifc) = (self.ns[k].clone(), self.ifs[k].clone());
        std::thread::spawn(move || {
            enter_netns(&ns).unwrap();
            RawSocket::open(&ifc).unwrap()
        })
        .join()
        .unwrap()
    }
}

impl Drop for Pair {
    fn drop(&mut self) {
        for ns in &self.ns {
            let _ = Command::new("ip").args(["netns", "del", ns]).output();
        }
    }
}

fn frame(len: usize, tag: u8) -> Vec<u8> {
    let mut f = vec![tag; len];
    f[..6].fill(0xFF);
    f[6..12].copy_from_slice(&[2, 0, 0, 0, 0, 1]);
    f[12..14].copy_from_slice(&0x88A4u16.to_be_bytes());
    f
}

#[test]
fn frames_and_stamps_cross_the_ring_and_a_frame_too_long_is_counted_not_cut() {
    let pair = Pair::new("r");
    let mut ring = RingSocket::new(pair.open(0), 50_000).expect("a packet ring on a veth");
    let plain = pair.open(1);
    plain.set_timeout_ns(500_000_000).unwrap();
    let mut buf = vec![0u8; 9216];

    // Sent: the other end gets the same bytes, and the transmit stamp lies between the send
    // call and the other end's receive stamp.
    for (len, tag) in [(60, 1u8), (1514, 2), (60, 3)] {
        let before = monotonic_ns();
        ring.send(&frame(len, tag)).unwrap();
        let (n, rx) = plain.recv_stamped(&mut buf).unwrap().expect("the frame sent through the ring");
        assert_eq!(&buf[..n], &frame(len, tag)[..], "{len} bytes");
        let tx = ring.tx_timestamp().expect("a transmit stamp");
        let rx = rx.expect("a receive stamp");
        // The transmit stamp can come after the peer's receive stamp (1.2 µs after it once,
        // with the whole suite running); a stale stamp would lie before the send.
        assert!(before <= tx && tx <= rx + 100_000, "send at {before}, stamped {tx}, received {rx}");
    }

    // Received through the ring: a frame longer than a slot is dropped and counted;
    // the frames around it arrive whole, in order, with stamps from their send.
    let t0 = monotonic_ns();
    for (len, tag) in [(60, 6u8), (4000, 7), (1514, 8)] {
        plain.send(&frame(len, tag)).unwrap();
    }
    for (len, tag) in [(60, 6u8), (1514, 8)] {
        let (n, stamp) = ring.recv(&mut buf, monotonic_ns() + 500_000_000).unwrap().expect("a frame");
        assert_eq!(&buf[..n], &frame(len, tag)[..], "{len} bytes");
        let stamp = stamp.expect("a receive stamp");
        assert!(t0 <= stamp && stamp <= monotonic_ns(), "stamp {stamp} outside the exchange from {t0}");
    }
    assert_eq!(ring.truncated_frames(), 1);

    // Nothing more comes: the receive returns at its deadline, having slept after its spin.
    let deadline = monotonic_ns() + 20_000_000;
    assert!(ring.recv(&mut buf, deadline).unwrap().is_none());
    assert!(monotonic_ns() >= deadline);
    assert!(ring.sleeps() >= 1);
}

/// An io_uring socket whose receive was armed by a thread that has since ended (an
/// application's cyclic thread, stopped): the kernel cancels that thread's requests, and the
/// socket goes on receiving in the thread that uses it now.
#[test]
fn an_io_uring_socket_outlives_the_thread_that_armed_its_receive() {
    let pair = Pair::new("u");
    let Ok(mut uring) = ferrocat_link::UringSocket::new(pair.open(0)) else {
        eprintln!("SKIPPED: this kernel gives no io_uring");
        return;
    };
    let plain = pair.open(1);
    let mut buf = vec![0u8; 2048];
    // Armed and left waiting by another thread, which ends.
    uring = std::thread::spawn(move || {
        let mut b = vec![0u8; 2048];
        assert!(uring.recv(&mut b, monotonic_ns() + 1_000_000).unwrap().is_none());
        uring
    })
    .join()
    .unwrap();
    plain.send(&frame(60, 9)).unwrap();
    let (n, _) =
        uring.recv(&mut buf, monotonic_ns() + 500_000_000).unwrap().expect("the frame, after the thread ended");
    assert_eq!(&buf[..n], &frame(60, 9)[..]);
    // Sending works from here too.
    uring.send(&frame(60, 10)).unwrap();
    uring.flush().unwrap();
    plain.set_timeout_ns(500_000_000).unwrap();
    let (n, _) = plain.recv_stamped(&mut buf).unwrap().expect("the frame sent after the thread ended");
    assert_eq!(&buf[..n], &frame(60, 10)[..]);
}
