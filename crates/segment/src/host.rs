//! Models of the master's host: how long its network stack and timer take, and what
//! timestamps its link gives.
use rand::Rng;
use rand_chacha::ChaCha8Rng;
use rand_distr::{Distribution, Normal};

/// A latency distribution: normal, clipped below, with rare outliers.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Latency {
    pub mean_ns: f64,
    pub sd_ns: f64,
    pub min_ns: f64,
    /// Probability of an outlier, and its extra delay (uniform up to this).
    pub outlier_p: f64,
    pub outlier_ns: f64,
}

impl Latency {
    pub const ZERO: Latency = Latency { mean_ns: 0.0, sd_ns: 0.0, min_ns: 0.0, outlier_p: 0.0, outlier_ns: 0.0 };

    pub fn fixed(ns: f64) -> Self {
        Latency { mean_ns: ns, min_ns: ns, ..Latency::ZERO }
    }

    pub fn sample(&self, rng: &mut ChaCha8Rng) -> u64 {
        let mut v = if self.sd_ns > 0.0 {
            Normal::new(self.mean_ns, self.sd_ns).map(|n| n.sample(rng)).unwrap_or(self.mean_ns)
        } else {
            self.mean_ns
        };
        if self.outlier_p > 0.0 && rng.gen_bool(self.outlier_p.clamp(0.0, 1.0)) {
            v += rng.gen_range(0.0..=self.outlier_ns.max(0.0));
        }
        v.max(self.min_ns).max(0.0) as u64
    }
}

/// How long the master's own host takes: to hand a frame to the wire, to deliver a received
/// frame to the master, and how late its timer wakes it.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct HostModel {
    pub name: &'static str,
    pub send: Latency,
    pub recv: Latency,
    pub wake: Latency,
    /// What the link tells about when frames really left and arrived.
    pub stamps: Stamps,
    /// The timer wakes only on multiples of this (0: any ns), as RTX's 10 µs timer in Chen 2016.
    pub timer_resolution_ns: u64,
    /// A general-purpose output, and how long after the program writes it its pin changes
    /// (None: the host has none).
    pub gpio: Option<Latency>,
}

/// Timestamps the link gives the master.
#[derive(Debug, Clone, Copy, PartialEq)]
pub enum Stamps {
    /// None: the master knows only when it handed a frame over and when it had the reply.
    None,
    /// The kernel's (SO_TIMESTAMPING software): transmit taken this long before the frame
    /// leaves, receive this long after its last byte arrived.
    Software { tx_early: Latency, rx_late: Latency },
    /// The NIC's: the start of each frame, both ways, exactly.
    Hardware,
}

impl HostModel {
    /// No host at all: frames leave and arrive instantly, timers are exact.
    pub fn ideal() -> Self {
        HostModel {
            name: "ideal",
            send: Latency::ZERO,
            recv: Latency::ZERO,
            wake: Latency::ZERO,
            stamps: Stamps::None,
            timer_resolution_ns: 0,
            gpio: None,
        }
    }

    /// A PC with a PREEMPT_RT kernel and a raw socket: a few µs through the stack, timer
    /// latency of a few µs with rare tens of µs.
    pub fn pc_rt() -> Self {
        HostModel {
            name: "pc-rt",
            send: Latency { mean_ns: 4_000.0, sd_ns: 1_000.0, min_ns: 2_000.0, outlier_p: 0.001, outlier_ns: 20_000.0 },
            recv: Latency { mean_ns: 5_000.0, sd_ns: 1_500.0, min_ns: 2_500.0, outlier_p: 0.001, outlier_ns: 20_000.0 },
            wake: Latency { mean_ns: 3_000.0, sd_ns: 1_500.0, min_ns: 1_000.0, outlier_p: 0.001, outlier_ns: 30_000.0 },
            stamps: Stamps::Software {
                tx_early: Latency { mean_ns: 1_000.0, sd_ns: 300.0, min_ns: 400.0, ..Latency::ZERO },
                rx_late: Latency { mean_ns: 1_500.0, sd_ns: 400.0, min_ns: 500.0, ..Latency::ZERO },
            },
            timer_resolution_ns: 0,
            gpio: Some(HostModel::PARALLEL_PORT),
        }
    }

    /// `pc_rt` with a NIC that stamps each frame's departure and arrival in hardware.
    pub fn nic_hwts() -> Self {
        HostModel { name: "nic-hwts", stamps: Stamps::Hardware, ..HostModel::pc_rt() }
    }

    /// A stock (non-RT) kernel: tens of µs through the stack and timer, rare hundreds.
    pub fn pc_stock() -> Self {
        HostModel {
            name: "pc-stock",
            send: Latency {
                mean_ns: 15_000.0,
                sd_ns: 6_000.0,
                min_ns: 5_000.0,
                outlier_p: 0.01,
                outlier_ns: 200_000.0,
            },
            recv: Latency {
                mean_ns: 20_000.0,
                sd_ns: 8_000.0,
                min_ns: 6_000.0,
                outlier_p: 0.01,
                outlier_ns: 200_000.0,
            },
            wake: Latency {
                mean_ns: 50_000.0,
                sd_ns: 25_000.0,
                min_ns: 5_000.0,
                outlier_p: 0.01,
                outlier_ns: 500_000.0,
            },
            stamps: Stamps::Software {
                tx_early: Latency {
                    mean_ns: 2_000.0,
                    sd_ns: 1_000.0,
                    min_ns: 500.0,
                    outlier_p: 0.01,
                    outlier_ns: 50_000.0,
                },
                rx_late: Latency {
                    mean_ns: 3_000.0,
                    sd_ns: 1_500.0,
                    min_ns: 500.0,
                    outlier_p: 0.01,
                    outlier_ns: 50_000.0,
                },
            },
            timer_resolution_ns: 0,
            // The same port, but the process may be preempted between reading its clock and
            // writing the pin.
            gpio: Some(Latency { outlier_p: 0.01, outlier_ns: 200_000.0, ..HostModel::PARALLEL_PORT }),
        }
    }

    /// The BeagleBone Green of Park 2020 (AM335x, RT kernel 4.9, IgH). The send and receive
    /// paths' means are fitted on Table 1's 2-slave rows (`ferrocat lab park2020 --fit`,
    /// docs/lab.md): the send path, from the master's clock read to the frame's first bit on
    /// the wire, sets `conventional`'s bias; the receive path, from the frame's last bit to the
    /// master's clock read, sets with it `park2020`'s (eq. 3 halves a round trip whose host
    /// paths differ). Spreads, outliers and stamps are assumed, not fitted.
    pub fn beaglebone_rt() -> Self {
        HostModel {
            name: "beaglebone-rt",
            send: Latency {
                mean_ns: 10_010.0,
                sd_ns: 2_500.0,
                min_ns: 4_310.0,
                outlier_p: 0.002,
                outlier_ns: 40_000.0,
            },
            recv: Latency {
                mean_ns: 12_160.0,
                sd_ns: 3_000.0,
                min_ns: 6_160.0,
                outlier_p: 0.002,
                outlier_ns: 40_000.0,
            },
            wake: Latency {
                mean_ns: 10_000.0,
                sd_ns: 4_000.0,
                min_ns: 3_000.0,
                outlier_p: 0.002,
                outlier_ns: 60_000.0,
            },
            stamps: Stamps::Software {
                tx_early: Latency { mean_ns: 2_000.0, sd_ns: 600.0, min_ns: 800.0, ..Latency::ZERO },
                rx_late: Latency { mean_ns: 3_000.0, sd_ns: 800.0, min_ns: 1_000.0, ..Latency::ZERO },
            },
            timer_resolution_ns: 0,
            // An AM335x GPIO register written through a mapping from the RT thread: a posted
            // write over the L4 interconnect, a few hundred ns (assumed; measure it with a scope).
            gpio: Some(Latency { mean_ns: 300.0, sd_ns: 40.0, min_ns: 200.0, outlier_p: 0.002, outlier_ns: 40_000.0 }),
        }
    }

    /// Chen 2016's master: Windows with the RTX real-time extension, its timer set to a 10 µs
    /// resolution (their §5.2), latencies as a PC with an RT kernel but for one parameter
    /// fitted on Table 2 (`ferrocat lab chen2016 --fit`, docs/lab.md): a late wake-up (0.1 %
    /// of cycles) comes up to 49.3 µs late, which sets the 500 µs row's latest frame.
    pub fn rtx_10us() -> Self {
        let pc = HostModel::pc_rt();
        HostModel {
            name: "rtx-10us",
            timer_resolution_ns: 10_000,
            stamps: Stamps::None,
            wake: Latency { outlier_ns: 49_340.0, ..pc.wake },
            ..pc
        }
    }

    /// A PC's calibration output: a parallel-port data pin written with `outb`, about 1 µs
    /// per ISA-style I/O cycle (assumed; measure it with a scope), rarely delayed by an
    /// interrupt between the clock read and the write.
    pub const PARALLEL_PORT: Latency =
        Latency { mean_ns: 1_000.0, sd_ns: 100.0, min_ns: 700.0, outlier_p: 0.001, outlier_ns: 20_000.0 };

    /// The presets by name, for the command line and scenarios.
    pub const PRESETS: [&'static str; 6] = ["ideal", "pc-rt", "pc-stock", "nic-hwts", "beaglebone-rt", "rtx-10us"];

    pub fn preset(name: &str) -> Option<Self> {
        Some(match name {
            "ideal" => HostModel::ideal(),
            "pc-rt" => HostModel::pc_rt(),
            "pc-stock" => HostModel::pc_stock(),
            "nic-hwts" => HostModel::nic_hwts(),
            "beaglebone-rt" => HostModel::beaglebone_rt(),
            "rtx-10us" => HostModel::rtx_10us(),
            _ => return None,
        })
    }
}
