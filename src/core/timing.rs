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

/// Seconds of each timed call of `f`; Ctrl-C ([`crate::core::interrupt`]) ends the repeats
/// after the call it lands in (the caller then says it was stopped).
pub fn time_calls(r: Repeats, mut f: impl FnMut()) -> Vec<f64> {
    for _ in 0..r.warmup {
        f();
    }
    let start = Instant::now();
    let mut times = Vec::new();
    while (times.len() < r.min_repeats.max(1) || start.elapsed().as_secs_f64() < r.min_seconds)
        && !(crate::core::interrupt::requested() && !times.is_empty())
    {
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

/// Seconds the calling thread has run on a CPU since it started (Linux's
/// `/proc/thread-self/schedstat`, nanoseconds); `None` elsewhere.
pub fn thread_cpu_seconds() -> Option<f64> {
    let text = std::fs::read_to_string("/proc/thread-self/schedstat").ok()?;
    let ns: f64 = text.split_whitespace().next()?.parse().ok()?;
    Some(ns * 1e-9)
}

/// `f()`, and the share of its wall time the calling thread spent on a CPU (`None` where
/// [`thread_cpu_seconds`] is). The work a caller does alone while rayon's workers wait is what
/// more threads cannot shorten: with parallel kernels the caller mostly sleeps until they end,
/// so this share bounds the speed-up more threads can give (Amdahl).
pub fn with_caller_share<T>(f: impl FnOnce() -> T) -> (T, Option<f64>) {
    let (cpu, wall) = (thread_cpu_seconds(), Instant::now());
    let out = f();
    let share = match (cpu, thread_cpu_seconds()) {
        (Some(a), Some(b)) => Some((b - a) / wall.elapsed().as_secs_f64().max(1e-9)),
        _ => None,
    };
    (out, share)
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

    #[test]
    fn the_caller_share_tells_work_from_waiting() {
        let ms = std::time::Duration::from_millis(80);
        let (_, busy) = with_caller_share(|| {
            let t = Instant::now();
            while t.elapsed() < ms {
                std::hint::black_box(t.elapsed());
            }
        });
        let (_, idle) = with_caller_share(|| std::thread::sleep(ms));
        if cfg!(target_os = "linux") {
            let (busy, idle) = (busy.unwrap(), idle.unwrap());
            assert!(busy > 0.3 && idle < 0.2, "busy {busy}, sleeping {idle}");
        }
    }
}
