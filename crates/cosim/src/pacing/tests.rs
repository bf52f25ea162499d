//! The pacer on a fake clock, its histograms, the policies.

use super::histogram::{bucket, bucket_range, BUCKETS};
use super::system::cpu_list;
use super::*;

/// A clock that advances only when told: a step "takes" what the test says, a sleep
/// jumps to its deadline (or is interrupted when the test asks).
#[derive(Default)]
struct FakeClock {
    now: Nanos,
    sleeps: Vec<Nanos>,
    /// The next sleeps return Interrupted without advancing (a signal).
    interrupts: u32,
}

impl Clock for &mut FakeClock {
    fn now(&mut self) -> Nanos {
        self.now
    }
    fn sleep_until(&mut self, deadline: Nanos) -> Wake {
        self.sleeps.push(deadline);
        if self.interrupts > 0 {
            self.interrupts -= 1;
            return Wake::Interrupted;
        }
        self.now = self.now.max(deadline);
        Wake::Reached
    }
}

const MS: Nanos = 1_000_000;

fn factor(f: f64) -> RealTimeFactor {
    RealTimeFactor::new(f).unwrap()
}

#[test]
fn a_factor_is_finite_and_above_zero() {
    for bad in [0.0, -1.0, f64::NAN, f64::INFINITY, -0.0] {
        assert!(RealTimeFactor::new(bad).is_err(), "{bad}");
    }
    assert_eq!(RealTimeFactor::new(2.0).unwrap().get(), 2.0);
    assert!(OverrunPolicy::from_name("skip").is_ok());
    assert!(OverrunPolicy::from_name("drop").is_err());
}

/// Steps that take 0.2 ms of a 1 ms period sleep to absolute deadlines: the schedule
/// does not drift with the steps' cost.
#[test]
fn steps_with_slack_sleep_to_absolute_deadlines() {
    let mut clock = FakeClock {
        now: 5 * MS,
        ..FakeClock::default()
    };
    let mut p = Pacer::new(&mut clock, factor(1.0), OverrunPolicy::Continue);
    p.start(10.0);
    for k in 1..=3 {
        p.clock.now += MS / 5;
        assert_eq!(
            p.step_done(10.0 + k as f64 * 1e-3),
            ControlFlow::Continue(())
        );
    }
    let r = p.report();
    assert_eq!(r.steps, 3);
    assert_eq!(r.overruns, 0);
    assert_eq!(r.histogram.slack, 3);
    assert_eq!(r.lateness.max, Some(-0.8e-3));
    assert!((r.wall_time - 3e-3).abs() < 1e-12, "{}", r.wall_time);
    assert_eq!(r.step_time.max, Some(0.2e-3));
    assert_eq!(r.wake_up_latency.max, Some(0.0));
    drop(p);
    assert_eq!(clock.sleeps, vec![6 * MS, 7 * MS, 8 * MS]);
}

/// Factor 2: a 1 ms step has 0.5 ms of wall time.
#[test]
fn the_factor_scales_the_deadlines() {
    let mut clock = FakeClock::default();
    let mut p = Pacer::new(&mut clock, factor(2.0), OverrunPolicy::Continue);
    p.start(0.0);
    let _ = p.step_done(1e-3);
    let _ = p.step_done(2e-3);
    assert!((p.report().scheduled_wall_time - 1e-3).abs() < 1e-15);
    drop(p);
    assert_eq!(clock.sleeps, vec![MS / 2, MS]);
}

/// Continue: a late step does not move the later deadlines; the next steps run at once
/// until one is early again.
#[test]
fn continue_catches_up_on_the_original_schedule() {
    let mut clock = FakeClock::default();
    let mut p = Pacer::new(&mut clock, factor(1.0), OverrunPolicy::Continue);
    p.start(0.0);
    p.clock.now += 2_500_000; // the first step takes 2.5 ms
    assert_eq!(p.step_done(1e-3), ControlFlow::Continue(()));
    p.clock.now += 100_000;
    let _ = p.step_done(2e-3); // finished at 2.6 ms: 0.6 ms late, no sleep
    p.clock.now += 100_000;
    let _ = p.step_done(3e-3); // 2.7 ms: 0.3 ms of slack, sleeps to 3 ms
    let r = p.report();
    assert_eq!((r.overruns, r.frames_lost), (2, 0));
    assert_eq!(r.first_overrun.as_ref().unwrap().time, 1e-3);
    assert!((r.first_overrun.unwrap().lateness - 1.5e-3).abs() < 1e-12);
    assert_eq!(r.histogram.late_over_1ms, 1);
    assert_eq!(r.histogram.late_100us_to_1ms, 1);
    assert_eq!(r.histogram.slack, 1);
    drop(p);
    assert_eq!(clock.sleeps, vec![3 * MS]);
}

/// Skip: the schedule restarts from the late step; the frames it slipped are counted.
#[test]
fn skip_re_anchors_the_schedule_one_step_after_now() {
    let mut clock = FakeClock::default();
    let mut p = Pacer::new(&mut clock, factor(1.0), OverrunPolicy::Skip);
    p.start(0.0);
    p.clock.now += 2_500_000; // 1.5 ms late: two frames lost
    let _ = p.step_done(1e-3);
    p.clock.now += 100_000;
    let _ = p.step_done(2e-3); // deadline 2.5 + 1 = 3.5 ms
    let r = p.report();
    assert_eq!((r.overruns, r.frames_lost), (1, 2));
    drop(p);
    assert_eq!(clock.sleeps, vec![3_500_000]);
}

/// Stop: the first late step ends the run with its reason.
#[test]
fn stop_ends_at_the_first_overrun() {
    let mut clock = FakeClock::default();
    let mut p = Pacer::new(&mut clock, factor(1.0), OverrunPolicy::Stop);
    p.start(0.0);
    p.clock.now += MS / 2;
    assert_eq!(p.step_done(1e-3), ControlFlow::Continue(()));
    p.clock.now += 1_250_000;
    let ControlFlow::Break(why) = p.step_done(2e-3) else {
        panic!("no stop at an overrun")
    };
    assert_eq!(
        why,
        "overrun at t = 0.002 s: the step finished 250.0 µs after its deadline (overrun policy stop)"
    );
    assert!(p.report().stopped_at_overrun);
}

/// A signal resumes the sleep to the same deadline; with Ctrl-C's flag set it ends it.
#[test]
fn a_sleep_a_signal_interrupts_resumes_unless_ctrl_c() {
    let mut clock = FakeClock {
        interrupts: 2,
        ..FakeClock::default()
    };
    let mut p = Pacer::new(&mut clock, factor(1.0), OverrunPolicy::Continue);
    p.start(0.0);
    let _ = p.step_done(1e-3);
    drop(p);
    assert_eq!(clock.sleeps, vec![MS; 3]);
    assert_eq!(clock.now, MS);

    let flag = Arc::new(AtomicBool::new(false));
    let mut clock = FakeClock {
        interrupts: 1,
        ..FakeClock::default()
    };
    let mut p =
        Pacer::new(&mut clock, factor(1.0), OverrunPolicy::Continue).with_interrupt(flag.clone());
    p.start(0.0);
    flag.store(true, Ordering::Relaxed);
    let _ = p.step_done(1e-3);
    drop(p);
    // Set before the sleep: no sleep at all.
    assert!(clock.sleeps.is_empty());
}

/// A slowed-down run (factor < 1) sleeps in slices, looking at Ctrl-C's flag between.
#[test]
fn a_long_wait_is_cut_into_slices() {
    let mut clock = FakeClock::default();
    let mut p = Pacer::new(&mut clock, factor(0.01), OverrunPolicy::Continue);
    p.start(0.0);
    let _ = p.step_done(1e-3); // 100 ms of wall time
    drop(p);
    assert_eq!(clock.sleeps, vec![50 * MS, 100 * MS]);
}

#[test]
fn quantiles_are_within_the_histograms_resolution_and_never_early() {
    let mut l = Histogram::default();
    // 1000 steps: slack from -999 µs to 0 in 1 µs steps.
    let values: Vec<Nanos> = (0..1000).map(|k| -(k as Nanos) * 1000).collect();
    for &v in &values {
        l.add(v);
    }
    l.add(3_000_000); // one step 3 ms late
    let mut sorted = values.clone();
    sorted.push(3_000_000);
    sorted.sort();
    for q in [0.5, 0.99, 0.999] {
        let exact = sorted[((q * sorted.len() as f64).ceil() as usize).max(1) - 1];
        let got = l.quantile(q).unwrap();
        assert!(got >= exact, "q {q}: {got} < {exact}");
        assert!(
            (got - exact) as f64 <= exact.unsigned_abs() as f64 / 64.0 + 1.0,
            "q {q}: {got} vs {exact}"
        );
    }
    assert_eq!(l.max(), Some(3_000_000));
    assert_eq!(l.quantile(1.0), Some(3_000_000));
    assert_eq!(l.min(), Some(-999_000));
    assert_eq!(l.coarse(), [1000, 0, 0, 0, 1]);
}

#[test]
fn buckets_cover_their_ranges_in_order() {
    let mut last = None;
    for m in (0..5000u64).chain([1 << 20, (1 << 20) + 1, 1 << 40, u64::MAX]) {
        let b = bucket(m);
        assert!(b < BUCKETS, "{m}");
        let (lo, hi) = bucket_range(b);
        if m < 1 << 41 {
            assert!(lo <= m && m <= hi, "{m}: {lo}..{hi}");
        }
        if let Some(l) = last {
            assert!(b >= l);
        }
        last = Some(b);
    }
    assert_eq!(bucket_range(BUCKETS - 1).1, (1 << 41) - 1);
}

#[test]
fn durations_in_words() {
    assert_eq!(duration_words(-987_600), "-987.6 µs");
    assert_eq!(duration_words(12), "12 ns");
    assert_eq!(duration_words(1_250_000), "1.25 ms");
    assert_eq!(cpu_list(&[0, 1, 2, 5, 7, 8]), "0-2,5,7-8");
}
