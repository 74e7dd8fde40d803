//! The one timer: warm-up calls, then timed calls until both a count and a duration are
//! reached; the median of them. Every speed the project reports goes through it (the caller's
//! closure synchronises the device where it runs asynchronously).

use std::time::Instant;

/// How long to measure.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Repeats {
    /// Untimed calls first.
    pub warmup: usize,
    /// Timed calls at least this many...
    pub min_repeats: usize,
    /// ...and until this many seconds have passed.
    pub min_seconds: f64,
}

impl Repeats {
    /// `warmup` untimed calls, then exactly `repeats` timed ones.
    pub fn exactly(warmup: usize, repeats: usize) -> Self {
        Repeats {
            warmup,
            min_repeats: repeats.max(1),
            min_seconds: 0.0,
        }
    }
}

/// Seconds of each timed call of `f`.
pub fn time_calls(r: Repeats, mut f: impl FnMut()) -> Vec<f64> {
    for _ in 0..r.warmup {
        f();
    }
    let start = Instant::now();
    let mut times = Vec::new();
    while times.len() < r.min_repeats.max(1) || start.elapsed().as_secs_f64() < r.min_seconds {
        let t = Instant::now();
        f();
        times.push(t.elapsed().as_secs_f64());
    }
    times
}

/// The median of `times` (the upper one of an even count).
pub fn median(times: &[f64]) -> f64 {
    let mut t = times.to_vec();
    t.sort_by(f64::total_cmp);
    t.get(t.len() / 2).copied().unwrap_or(f64::NAN)
}

/// The median seconds of a call of `f`.
pub fn median_seconds(r: Repeats, f: impl FnMut()) -> f64 {
    median(&time_calls(r, f))
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn the_median_is_the_middle_call_and_warmup_is_not_timed() {
        assert_eq!(median(&[3.0, 1.0, 2.0]), 2.0);
        assert_eq!(median(&[4.0, 1.0, 3.0, 2.0]), 3.0);
        let mut calls = 0;
        let times = time_calls(Repeats::exactly(2, 3), || calls += 1);
        assert_eq!((calls, times.len()), (5, 3));
    }
}
