//! Subnormal floats flushed to zero on the threads that compute (x86-64's FTZ and DAZ bits).
//!
//! Gradients of a trained network drift into the subnormal range (below 1.2e-38 in f32), and an
//! x86 core computes with subnormal operands through microcode assists, tens of times slower:
//! measured on NeuroKin-64's training step (2 cores of an AVX-512 Xeon), the GEMMs that
//! multiply output gradients ran at 4-8 GFLOP/s against 150 for the same shapes on normal
//! numbers, and the step took 4.4x longer. With subnormals read and written as zero, the step
//! is GEMM-bound again; a value that would have been subnormal differs from zero by less than
//! 1.2e-38, and the same seed still gives the same numbers on the same machine.
//!
//! Every binary flushes on its main thread and on the rayon workers ([`flush_everywhere`],
//! from [`crate::cli::run_main`]); the library flushes on the rayon workers only, where its
//! kernels run ([`flush_in_workers`], from [`crate::core::device::select`]), so a host
//! program's own thread (Python's, with NumPy) keeps its floating-point environment. Other
//! architectures keep theirs (no flag is set there).

use std::sync::Once;

/// FTZ (bit 15: results that would be subnormal are zero) and DAZ (bit 6: subnormal operands
/// read as zero) of MXCSR.
#[cfg(target_arch = "x86_64")]
const FTZ_DAZ: u32 = (1 << 15) | (1 << 6);

/// Set FTZ and DAZ on the calling thread; returns whether they are set.
pub fn flush_on_this_thread() -> bool {
    #[cfg(target_arch = "x86_64")]
    {
        let mut csr: u32 = 0;
        // SAFETY: stmxcsr/ldmxcsr read and write the thread's MXCSR through a valid pointer to
        // a local u32; only the FTZ and DAZ bits change.
        unsafe {
            std::arch::asm!("stmxcsr [{}]", in(reg) &mut csr, options(nostack, preserves_flags));
            csr |= FTZ_DAZ;
            std::arch::asm!("ldmxcsr [{}]", in(reg) &csr, options(nostack, preserves_flags));
        }
        true
    }
    #[cfg(not(target_arch = "x86_64"))]
    false
}

/// Whether FTZ and DAZ are set on the calling thread.
pub fn flushed_on_this_thread() -> bool {
    #[cfg(target_arch = "x86_64")]
    {
        let mut csr: u32 = 0;
        // SAFETY: as in `flush_on_this_thread`, reading only.
        unsafe {
            std::arch::asm!("stmxcsr [{}]", in(reg) &mut csr, options(nostack, preserves_flags));
        }
        csr & FTZ_DAZ == FTZ_DAZ
    }
    #[cfg(not(target_arch = "x86_64"))]
    false
}

/// Set FTZ and DAZ on every thread of rayon's global pool (once per process).
pub fn flush_in_workers() {
    static ONCE: Once = Once::new();
    ONCE.call_once(|| {
        rayon::broadcast(|_| flush_on_this_thread());
    });
}

/// [`flush_on_this_thread`] and [`flush_in_workers`]: a binary's whole process.
pub fn flush_everywhere() {
    flush_on_this_thread();
    flush_in_workers();
}

/// A rayon pool of `threads` threads that flush subnormals (for the studies that time a
/// solver at several thread counts).
pub fn thread_pool(threads: usize) -> Result<rayon::ThreadPool, rayon::ThreadPoolBuildError> {
    rayon::ThreadPoolBuilder::new()
        .num_threads(threads)
        .start_handler(|_| {
            flush_on_this_thread();
        })
        .build()
}
