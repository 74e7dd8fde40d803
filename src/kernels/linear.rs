//! A linear layer's product `x · W` for a few rows (one pose to a few dozen) on the CPU,
//! threads over blocks of output columns.
//!
//! flex hands a product to gemm on every thread only from 192³ multiply-adds, and gemm never
//! splits a single row: NeuroKin's seed layer at batch 1 (`[1, 1024] · [1024, 4096]`, 16 MB
//! of weights) ran on the calling thread, about a sixth of a batch-1 prediction on 2 threads
//! of an Xeon, and it would not shrink with more threads. Here each block of
//! [`COLUMNS`] output columns is one gemm call on one thread (measured on 2 threads: 0.56 ->
//! 0.32-0.42 ms for that layer). The blocks do not depend on the thread count, and each
//! output element is one gemm dot product over the same `k`, so the result does not either.

use rayon::prelude::*;

use crate::kernels::conv_gemm::{Layout, matmul};

/// Output columns per block.
pub const COLUMNS: usize = 64;

/// Whether [`matmul_by_columns`] is the product's better path: few rows, enough work to pay
/// for the threads (below, one thread; from 64 rows, gemm's own split).
pub fn by_columns_pays(m: usize, k: usize, n: usize) -> bool {
    m < 64 && n >= 2 * COLUMNS && m * k * n >= 1 << 20
}

/// `x` `[m, k]` · `w` `[k, n]`, both row-major, -> `[m, n]`.
pub fn matmul_by_columns(x: &[f32], w: &[f32], m: usize, k: usize, n: usize) -> Vec<f32> {
    assert_eq!(x.len(), m * k);
    assert_eq!(w.len(), k * n);
    let blocks: Vec<Vec<f32>> = (0..n.div_ceil(COLUMNS))
        .into_par_iter()
        .map(|b| {
            let (first, width) = (b * COLUMNS, COLUMNS.min(n - b * COLUMNS));
            let mut out = vec![0f32; m * width];
            matmul(
                (&mut out, Layout::row_major(m, width)),
                (x, Layout::row_major(m, k)),
                (&w[first..], Layout::row_major_block(k, width, n)),
                false,
                gemm::Parallelism::None,
            );
            out
        })
        .collect();
    let mut y = Vec::with_capacity(m * n);
    for row in 0..m {
        for block in &blocks {
            let width = block.len() / m;
            y.extend_from_slice(&block[row * width..(row + 1) * width]);
        }
    }
    y
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn blocks_of_columns_give_the_direct_product() {
        for (m, k, n) in [(1, 300, 1000), (5, 17, 130), (3, 64, 64)] {
            let x: Vec<f32> = (0..m * k).map(|i| ((i * 7) % 13) as f32 - 6.0).collect();
            let w: Vec<f32> = (0..k * n).map(|i| ((i * 5) % 11) as f32 - 5.0).collect();
            let y = matmul_by_columns(&x, &w, m, k, n);
            for i in 0..m {
                for j in 0..n {
                    let direct: f32 = (0..k).map(|p| x[i * k + p] * w[p * n + j]).sum();
                    // Small integers: every sum is exact in f32.
                    assert_eq!(y[i * n + j], direct, "{m}x{k}x{n} at ({i}, {j})");
                }
            }
        }
    }
}
