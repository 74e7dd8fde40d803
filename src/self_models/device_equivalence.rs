//! A self-model trained from the same seed on the CPU (`flex`) and on a GPU (`wgpu`): its
//! losses step by step and its rendered images, compared. `tests/gpu/equivalence.rs` asserts
//! tolerances on lavapipe; the lab's `gpu_check` reports the same comparison on a real GPU.

use std::path::Path;

use burn::tensor::Tensor;

use crate::core::device::DeviceChoice;
use crate::core::error::Result;
use crate::self_models::{
    harness::{Fitted, fit_run},
    model::{Render, SelfModel},
    run_config::SelfModelRun,
};

/// Test poses rendered by both devices.
const POSES: usize = 4;

/// The largest difference between the two devices, for one model.
#[derive(Clone, Debug, serde::Serialize)]
pub struct Equivalence {
    pub model: String,
    pub steps: usize,
    /// The largest `|cpu - gpu| / |cpu|` over the logged losses.
    pub max_loss_rel: f64,
    /// The largest `|cpu - gpu|` over every pixel of every image (silhouettes, depth).
    pub max_image_abs: f64,
    /// The image where it occurs.
    pub worst_image: String,
    /// The logged losses, `(step, cpu, gpu)`.
    #[serde(skip)]
    pub losses: Vec<(usize, f64, f64)>,
}

fn host(t: Tensor<4>) -> Vec<f32> {
    t.into_data()
        .convert::<f32>()
        .try_into_vec::<f32>()
        .expect("float")
}

/// Every renderer's images (silhouettes, then depth where it has one) of the first test poses.
fn images<R: Render>(f: &Fitted<R>) -> Vec<(String, Vec<f32>)> {
    let q = f.test_set.inputs.clone().slice([0..POSES]);
    f.trained
        .renderers
        .iter()
        .flat_map(|(label, r)| {
            let (s, d) = r.render(q.clone());
            let mut v = vec![(format!("{label} silhouette").trim().to_string(), host(s))];
            if let Some(d) = d {
                v.push((format!("{label} depth").trim().to_string(), host(d)));
            }
            v
        })
        .collect()
}

/// Train `cfg` for `steps` steps (no checkpoints, under `dir`) on the CPU and on `gpu`, and
/// compare.
pub fn compare<M: SelfModel>(
    mut cfg: SelfModelRun<M>,
    steps: usize,
    gpu: DeviceChoice,
    dir: &Path,
) -> Result<Equivalence> {
    cfg.train.steps = steps;
    cfg.train.checkpoint_every = 0;
    let fit = |d: DeviceChoice| fit_run(&cfg, &dir.join(d.to_string()), d, false);
    let (cpu, other) = (fit(DeviceChoice::Cpu)?, fit(gpu)?);
    let (a, b) = (&cpu.trained.log.curve, &other.trained.log.curve);
    if a.len() != b.len() || a.is_empty() {
        return Err(crate::Error::Training(format!(
            "{}: {} losses logged on the CPU, {} on {gpu}",
            cfg.name,
            a.len(),
            b.len()
        )));
    }
    let losses: Vec<(usize, f64, f64)> = a.iter().zip(b).map(|(x, y)| (x.0, x.1, y.1)).collect();
    let max_loss_rel = losses
        .iter()
        .map(|(_, x, y)| (x - y).abs() / x.abs().max(1e-6))
        .fold(0.0, f64::max);
    let mut worst = (0.0f64, String::new());
    for ((name, x), (_, y)) in images(&cpu).iter().zip(images(&other)) {
        let max = x
            .iter()
            .zip(&y)
            .map(|(p, q)| (p - q).abs() as f64)
            .fold(0.0, f64::max);
        if max >= worst.0 {
            worst = (max, name.clone());
        }
    }
    let _ = std::fs::remove_dir_all(dir);
    Ok(Equivalence {
        model: cfg.name.clone(),
        steps,
        max_loss_rel,
        max_image_abs: worst.0,
        worst_image: worst.1,
        losses,
    })
}
