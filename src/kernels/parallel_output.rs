//! A kernel's output buffer, zeroed and written chunk by chunk on the threads that compute it.
//!
//! `vec![0f32; n]` zeroes the whole buffer on the calling thread before any worker starts:
//! for a batch of activations (tens of megabytes) that is a `memset` plus the kernel's
//! page faults (fresh pages are cleared by the kernel), all on one thread. Measured on
//! `bench_decoders` (2 threads of an Xeon), the main thread spent about a third of its time
//! there while the workers waited: serial work that more threads cannot shorten. Here each
//! chunk is zeroed by the worker that then writes it, so the faults and the zeroing run in
//! parallel and the chunk is in that core's cache when the kernel writes it.

use std::mem::MaybeUninit;

use rayon::prelude::*;

/// A buffer of `len` floats in chunks of `chunk` (the last may be shorter): each chunk is
/// zeroed, then `f(state, index, chunk)` runs on it, chunks in parallel, `state` from `init`
/// once per rayon job (a scratch buffer), as `for_each_init` does.
pub fn zeroed_in_parallel<S>(
    len: usize,
    chunk: usize,
    init: impl Fn() -> S + Sync + Send,
    f: impl Fn(&mut S, usize, &mut [f32]) + Sync + Send,
) -> Vec<f32> {
    let mut out: Vec<f32> = Vec::with_capacity(len);
    out.spare_capacity_mut()[..len]
        .par_chunks_mut(chunk.max(1))
        .enumerate()
        .for_each_init(init, |state, (index, part)| {
            let part = zero(part);
            f(state, index, part);
        });
    // SAFETY: the chunks cover `0..len` of the capacity, and `zero` wrote every element of
    // each before `f` saw it; if any `f` panicked, the panic goes on through `for_each_init`
    // and this line is not reached (the buffer is dropped with length 0).
    unsafe { out.set_len(len) };
    out
}

/// `len` zeros, written in parallel (for buffers that a kernel adds into).
pub fn zeros(len: usize) -> Vec<f32> {
    const CHUNK: usize = 1 << 16;
    zeroed_in_parallel(len, CHUNK, || (), |_, _, _| {})
}

/// Write 0.0 to every element and view them as initialised floats.
fn zero(part: &mut [MaybeUninit<f32>]) -> &mut [f32] {
    for v in part.iter_mut() {
        v.write(0.0);
    }
    // SAFETY: every element was written just above; `MaybeUninit<f32>` has the layout of `f32`.
    unsafe { &mut *(part as *mut [MaybeUninit<f32>] as *mut [f32]) }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn every_chunk_is_zeroed_then_written_once_with_its_index() {
        let out = zeroed_in_parallel(
            10,
            3,
            || 0usize,
            |calls, index, part| {
                *calls += 1;
                assert!(part.iter().all(|&v| v == 0.0));
                part[0] = index as f32 + 1.0;
            },
        );
        assert_eq!(out, vec![1.0, 0.0, 0.0, 2.0, 0.0, 0.0, 3.0, 0.0, 0.0, 4.0]);
        assert_eq!(zeros(70_000), vec![0.0; 70_000]);
        assert!(zeros(0).is_empty());
    }
}
