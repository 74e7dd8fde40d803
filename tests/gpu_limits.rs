//! No dispatch beyond the device's workgroup limit (65,535 a dimension): a matrix product whose
//! naive kernel would launch (1, 131072, 1) workgroups, the shape that stopped the decoder
//! benchmark's GPU-filling batches on an H200 (`Cube count too big (16, 131072, 1)`), runs under
//! burn's fullest autotune, which tries that kernel, and gives the CPU's product. Its own test
//! binary: the autotune level is set before the device starts (CI runs the other GPU tests at
//! the minimal level). Behind the `wgpu` feature:
//! `cargo test --release --features wgpu --test gpu_limits`.
#![cfg(feature = "wgpu")]

use burn::tensor::{Distribution, Tensor};
use cubecl::config::{CubeClRuntimeConfig, RuntimeConfig};
use selfmodel::core::device::{DeviceChoice, select, with_seed};

#[test]
fn a_product_beyond_65535_workgroups_runs_under_the_fullest_autotune() {
    let mut config = CubeClRuntimeConfig::default();
    config.autotune.level = cubecl::config::autotune::AutotuneLevel::Full;
    // Tuned here, not read from an earlier run's cache (which would skip the naive kernel).
    config.autotune.disable_cache = true;
    assert!(
        CubeClRuntimeConfig::try_set(config),
        "the configuration was read before this test set it"
    );
    let device = select(DeviceChoice::Wgpu).unwrap();
    // 2^21 rows: 131,072 workgroups of 16 rows, 64 MiB a side (lavapipe binds at most 128 MiB).
    let (m, k, n) = (1 << 21, 8, 8);
    let (a, b) = with_seed(&device, 3, || {
        (
            Tensor::<2>::random([m, k], Distribution::Default, &device),
            Tensor::<2>::random([k, n], Distribution::Default, &device),
        )
    });
    let c: Vec<f32> = a
        .clone()
        .matmul(b.clone())
        .into_data()
        .try_to_vec::<f32>()
        .unwrap();
    let a: Vec<f32> = a.into_data().try_to_vec::<f32>().unwrap();
    let b: Vec<f32> = b.into_data().try_to_vec::<f32>().unwrap();
    assert_eq!(c.len(), m * n);
    // Rows across the whole range, the last workgroups' included.
    for row in (0..m).step_by(4099).chain([m - 1]) {
        for col in 0..n {
            let want: f32 = (0..k).map(|i| a[row * k + i] * b[i * n + col]).sum();
            let got = c[row * n + col];
            assert!(
                (got - want).abs() <= 1e-5 * (1.0 + want.abs()),
                "c[{row}, {col}] = {got}, not {want}"
            );
        }
    }
}
