use super::*;
use proptest::prelude::*;

fn any_sample() -> impl Strategy<Value = Sample> {
    (
        any::<u64>(),
        any::<u64>(),
        any::<Option<u64>>(),
        any::<u64>(),
        any::<u64>(),
        any::<i64>(),
        any::<u64>(),
        any::<u64>(),
        any::<u64>(),
        any::<Option<u64>>(),
    )
        .prop_map(
            |(cycle, built_ns, tx_ns, rx_ns, reference_ns, difference_ns, loop_ns, frame_ns, data_ns, offset)| Sample {
                cycle,
                built_ns,
                tx_ns,
                rx_ns,
                reference_ns,
                reference_offset_ns: offset,
                difference_ns,
                loop_ns,
                frame_ns,
                data_ns,
                follower: None,
            },
        )
}

proptest! {
    // Whatever the wire and the clocks say, across every wrap: no overflow, no panic.
    #[test]
    fn no_method_panics_on_any_sample(samples in proptest::collection::vec(any_sample(), 1..40),
                                      built in any::<u64>(), cycle_ns in any::<u64>(), res in any::<u64>()) {
        let mut methods: Vec<Box<dyn ClockSync>> = vec![
            Box::new(Conventional),
            Box::new(Park2020::new(samples[0].difference_ns)),
            Box::new(Chen2016::new(cycle_ns, 3, res)),
            Box::new(SoemPi::new(cycle_ns, samples[0].difference_ns)),
            Box::new(Ferrocat::new(Coupling::ReferenceFollowsMaster, cycle_ns)),
            Box::new({
                Ferrocat::new(Coupling::ReferenceFollowsMaster, cycle_ns).with_steering(Steering::TimeControlLoop)
            }),
            Box::new(Ferrocat::new(Coupling::MasterFollowsReference, cycle_ns)),
            Box::new({
                let mut f = Ferrocat::new(Coupling::MasterFollowsReference, cycle_ns);
                f.set_sync0_phase_ns(Some(built));
                f
            }),
        ];
        for m in methods.iter_mut() {
            for (k, s) in samples.iter().enumerate() {
                let _ = m.reference_time(built);
                let _ = m.plan(k as u64);
                let _ = m.reference_steering().and_then(|s| s.reference_offset(built, None));
                let c = m.update(if k % 7 == 3 { None } else { Some(s) });
                if let Some(p) = c.next_period_ns {
                    prop_assert!(p >= 1);
                }
            }
        }
    }

    #[test]
    fn the_lead_is_the_same_across_a_wrap(base in any::<u64>(), send in 0u64..1_000_000, rtt in 0u64..10_000_000,
                                          loop_ns in 0u64..1_000_000) {
        let s = |b: u64| Sample {
            cycle: 0, built_ns: b, tx_ns: Some(b.wrapping_add(send)), rx_ns: b.wrapping_add(send).wrapping_add(rtt),
            reference_ns: 0, reference_offset_ns: None, difference_ns: 0, loop_ns, frame_ns: 0, data_ns: 0, follower: None,
        };
        prop_assert_eq!(s(base).lead_ns(), s(0).lead_ns());
    }
}

pub(super) fn sample(cycle: u64, reference_ns: u64, difference_ns: i64) -> Sample {
    Sample {
        cycle,
        built_ns: cycle * 1_000_000,
        tx_ns: None,
        rx_ns: cycle * 1_000_000 + 20_000,
        reference_ns,
        reference_offset_ns: None,
        difference_ns,
        loop_ns: 4_000,
        frame_ns: 6_000,
        data_ns: 0,
        follower: None,
    }
}

#[test]
fn park_ema_follows_eq4_and_shifts_by_eq5_every_period() {
    let mut p = Park2020::new(3_000);
    p.period_ns = 2_000_000;
    assert_eq!(p.reference_time(10), 3_010);
    // ΔT⁰ = Δt⁰ = 400 → offsets −400.
    assert_eq!(p.update(Some(&sample(1, 0, 400))).shift_offsets_ns, -400);
    // Within the period: nothing.
    assert_eq!(p.update(Some(&sample(2, 0, 800))).shift_offsets_ns, 0);
    // ΔT¹ = 0.25·800 + 0.75·400 = 500.
    assert_eq!(p.update(Some(&sample(3, 0, 800))).shift_offsets_ns, -500);
    assert_eq!(Park2020::delay_from(&[(10_000, 4_000), (12_000, 4_000)]), 3_500);
}

#[test]
fn chen_truncation_carries_the_error_over() {
    let mut c = Chen2016::new(1_000_000, 10, 10_000);
    // 1 003 333.3 ns on a 10 µs timer: mostly 1 000 000, one step up every third cycle.
    let periods: Vec<u64> = (0..300).map(|_| c.truncate(1_003_333.3)).collect();
    assert!(periods.iter().all(|&p| p == 1_000_000 || p == 1_010_000));
    let mean = periods.iter().sum::<u64>() as f64 / 300.0;
    assert!((mean - 1_003_333.3).abs() < 100.0, "{mean}");
}

#[test]
fn chen_rescales_by_the_reference_speed() {
    // The reference runs 100 ppm fast: each master millisecond is 1 000 100 ns of it.
    let mut c = Chen2016::new(1_000_000, 10, 1);
    let mut last = None;
    for k in 0..=10 {
        last = c.update(Some(&sample(k, k * 1_000_100, 0))).next_period_ns;
    }
    let p = last.unwrap() as f64;
    assert!((p - 1_000_000.0 * 1_000_000.0 / 1_000_100.0).abs() < 2.0, "{p}");
}

#[test]
fn soem_pi_shortens_the_period_when_the_reference_is_late_in_its_cycle() {
    let mut pi = SoemPi::new(1_000_000, 0);
    let p = pi.update(Some(&sample(1, 5_000_000 + 20_000, 0))).next_period_ns.unwrap();
    assert_eq!(p, 1_000_000 - 200);
    let p = pi.update(Some(&sample(2, 5_000_000 - 20_000, 0))).next_period_ns.unwrap();
    assert_eq!(p, 1_000_000 + 200);
}
