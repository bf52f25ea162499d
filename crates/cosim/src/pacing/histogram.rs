//! The pacer's histograms: log-linear buckets of nanoseconds, allocated once, read as
//! quantiles.

use super::Nanos;

/// The log-linear histogram's resolution: 2^SUB_BITS buckets per octave of lateness, so a
/// quantile read from it is within 1/64 (1.6 %) of the true one (values under 64 ns exact).
const SUB_BITS: u32 = 6;
const SUB: u64 = 1 << SUB_BITS;
/// Octaves up to 2^41 ns (about 37 min): a later step is counted in the last bucket (the
/// maximum is kept exactly besides).
const MAX_EXPONENT: u32 = 40;
pub(super) const BUCKETS: usize = (SUB * (MAX_EXPONENT - SUB_BITS + 2) as u64) as usize;

/// The bucket of a magnitude, ns.
pub(super) fn bucket(m: u64) -> usize {
    let m = m.min((1u64 << (MAX_EXPONENT + 1)) - 1);
    if m < SUB {
        return m as usize;
    }
    let e = 63 - m.leading_zeros();
    (SUB * u64::from(e - SUB_BITS + 1) + ((m >> (e - SUB_BITS)) - SUB)) as usize
}

/// The smallest and largest magnitude of a bucket, ns.
pub(super) fn bucket_range(i: usize) -> (u64, u64) {
    let i = i as u64;
    if i < SUB {
        return (i, i);
    }
    let e = i / SUB + u64::from(SUB_BITS) - 1;
    let low = (i % SUB + SUB) << (e - u64::from(SUB_BITS));
    (low, low + (1 << (e - u64::from(SUB_BITS))) - 1)
}

/// The summary's small histogram of lateness: steps with slack (lateness ≤ 0), then late
/// by up to 10 µs, 100 µs, 1 ms, and more.
#[derive(Clone, Debug, Default, PartialEq, serde::Serialize)]
pub struct LatenessHistogram {
    pub slack: u64,
    pub late_0_to_10us: u64,
    pub late_10_to_100us: u64,
    pub late_100us_to_1ms: u64,
    pub late_over_1ms: u64,
}

impl From<[u64; 5]> for LatenessHistogram {
    fn from(c: [u64; 5]) -> Self {
        LatenessHistogram {
            slack: c[0],
            late_0_to_10us: c[1],
            late_10_to_100us: c[2],
            late_100us_to_1ms: c[3],
            late_over_1ms: c[4],
        }
    }
}

impl LatenessHistogram {
    /// (label, count) in order, for text.
    pub fn bins(&self) -> [(&'static str, u64); 5] {
        [
            ("slack", self.slack),
            ("0-10 µs late", self.late_0_to_10us),
            ("10-100 µs", self.late_10_to_100us),
            ("0.1-1 ms", self.late_100us_to_1ms),
            ("> 1 ms", self.late_over_1ms),
        ]
    }
}

/// A distribution of signed durations (the steps' lateness, their execution time, the
/// sleeps' wake-up latency), kept without allocating per step: counts in preallocated
/// log-linear buckets (for the quantiles), the coarse lateness bins, the exact extremes.
pub struct Histogram {
    /// Values ≤ 0 (a step on time: its slack) by magnitude; values > 0 (late) by value.
    slack: Box<[u64]>,
    late: Box<[u64]>,
    coarse: [u64; 5],
    count: u64,
    max: Nanos,
    min: Nanos,
}

impl Default for Histogram {
    fn default() -> Self {
        Histogram {
            slack: vec![0; BUCKETS].into_boxed_slice(),
            late: vec![0; BUCKETS].into_boxed_slice(),
            coarse: [0; 5],
            count: 0,
            max: Nanos::MIN,
            min: Nanos::MAX,
        }
    }
}

impl Histogram {
    #[inline]
    pub fn add(&mut self, lateness: Nanos) {
        self.count += 1;
        self.max = self.max.max(lateness);
        self.min = self.min.min(lateness);
        let m = lateness.unsigned_abs();
        match lateness <= 0 {
            true => self.slack[bucket(m)] += 1,
            false => self.late[bucket(m)] += 1,
        }
        let bin = match lateness {
            ..=0 => 0,
            1..=10_000 => 1,
            10_001..=100_000 => 2,
            100_001..=1_000_000 => 3,
            _ => 4,
        };
        self.coarse[bin] += 1;
    }

    pub fn count(&self) -> u64 {
        self.count
    }

    /// The value at quantile `q` (0 to 1), ns: the largest value of its bucket, so never
    /// below the true quantile and at most 1.6 % later (bounded by the exact
    /// maximum). None without steps.
    pub fn quantile(&self, q: f64) -> Option<Nanos> {
        if self.count == 0 {
            return None;
        }
        // The rank (1-based) of the quantile's value in ascending order.
        let rank = ((q.clamp(0.0, 1.0) * self.count as f64).ceil() as u64).max(1);
        let mut seen = 0;
        // Ascending: the largest slack first, then the smallest lateness.
        let ascending = (self.slack.iter().enumerate().rev())
            .map(|(i, &n)| (n, -(bucket_range(i).0 as Nanos)))
            .chain((self.late.iter().enumerate()).map(|(i, &n)| (n, bucket_range(i).1 as Nanos)));
        for (n, latest) in ascending {
            seen += n;
            if seen >= rank {
                return Some(latest.min(self.max));
            }
        }
        Some(self.max)
    }

    pub fn max(&self) -> Option<Nanos> {
        (self.count > 0).then_some(self.max)
    }

    pub fn min(&self) -> Option<Nanos> {
        (self.count > 0).then_some(self.min)
    }

    /// The coarse bins' counts, in the order of [`LatenessHistogram`]'s fields.
    pub fn coarse(&self) -> [u64; 5] {
        self.coarse
    }
}
