//! A coarse occupancy grid in the camera's frustum, derived from the occupancy field for one
//! pose: the empty-space skipping structure of the accelerated ray marcher
//! ([`crate::self_models::ffksm::accelerated_marcher`]), in the spirit of nerfacc's occupancy grid.
//!
//! FFKSM's field depends on the joint angles, so a grid fixed in the world (nerfacc's, for a
//! static scene) would have to hold every pose the arm can take. This grid is rebuilt for each
//! rendered pose instead, and its cells are aligned with the rays: a cell is a `block x block`
//! block of pixels times `depth_cell` consecutive samples along their rays (the paper preset:
//! 4 x 4 pixels x 4 samples, 25 x 25 x 16 = 10,000 cells for a 100x100 image with 64 samples,
//! 1.6% of the 640,000 evaluations of dense marching). The field is probed once per cell, on
//! the ray through the block's centre at the middle of its depth range; a cell is occupied
//! when the probe's raw density exceeds `density_threshold` (a negative threshold keeps cells
//! near a surface, since the raw density is continuous and only its ReLU is zero), and the
//! occupied set is then dilated by `dilation` cells across the image, so thin parts that
//! fall between two probe rays are still marched, and by `depth_dilation` cells along the
//! rays.
//!
//! The paper preset dilates across the image only. On the densely trained reimplementation
//! (a sweep on 20 test images), a one-cell box in all three directions marched
//! 66,767 evaluations per image (9.6x fewer than dense marching); without the dilation along
//! the rays 48,321 (13.2x fewer) with the same PSNR (+0.029 dB against dense marching's, the
//! box's +0.027 dB); without the dilation across the image the PSNR fell 0.55 dB.

use burn::tensor::{Device, TensorData};

use crate::self_models::ffksm::field::OccupancyField;
use crate::self_models::ffksm::marcher::{MarchConfig, sample_points};
use crate::sim::camera::Camera;

/// How the grid is built.
#[derive(Clone, Debug, PartialEq, serde::Serialize, serde::Deserialize)]
pub struct GridConfig {
    /// Pixels per cell side.
    pub block: usize,
    /// Samples per cell along a ray.
    pub depth_cell: usize,
    /// A probe whose raw density exceeds this marks its cell occupied.
    pub density_threshold: f32,
    /// Cells added around every occupied cell across the image (rows and columns).
    pub dilation: usize,
    /// Cells added around every occupied cell along the rays (absent in configs from before
    /// the option: 1, the dilation those used in all three directions).
    #[serde(default = "one")]
    pub depth_dilation: usize,
    /// Probes evaluated per network call (memory bound).
    pub chunk: usize,
}

impl GridConfig {
    /// 4 x 4 pixels x 4 samples, threshold 0 on the raw density, dilation of one cell
    /// across the image and none along the rays.
    pub fn paper() -> Self {
        GridConfig {
            block: 4,
            depth_cell: 4,
            density_threshold: 0.0,
            dilation: 1,
            depth_dilation: 0,
            chunk: 1 << 16,
        }
    }
}

fn one() -> usize {
    1
}

/// Occupancy of the cells of one pose seen from one camera.
#[derive(Clone, Debug)]
pub struct FrustumGrid {
    /// Cells along the image rows, columns and the rays.
    pub dims: [usize; 3],
    pub block: usize,
    pub depth_cell: usize,
    /// `dims[0] * dims[1] * dims[2]` flags, depth fastest.
    pub occupied: Vec<bool>,
    /// Network evaluations spent on the probes.
    pub evaluations: usize,
}

impl FrustumGrid {
    /// Probe `field` in pose `angles` (radians) from `camera` on `march`'s samples.
    pub fn build(
        field: &OccupancyField,
        (camera, angles): (&Camera, &[f64]),
        march: &MarchConfig,
        cfg: &GridConfig,
        device: &Device,
    ) -> FrustumGrid {
        let block = cfg.block.max(1);
        let depth_cell = cfg.depth_cell.max(1);
        let dims = [
            camera.height.div_ceil(block),
            camera.width.div_ceil(block),
            march.samples.div_ceil(depth_cell),
        ];
        let step = (march.far - march.near) / march.samples as f64;
        // The probe of cell (i, j, k): the pixel nearest the block's centre, at the centre of
        // the cell's depth range (clipped to the image and the ray).
        let mut pixels = Vec::with_capacity(dims[0] * dims[1]);
        for i in 0..dims[0] {
            for j in 0..dims[1] {
                let row = (i * block + block / 2).min(camera.height - 1);
                let col = (j * block + block / 2).min(camera.width - 1);
                pixels.push(row * camera.width + col);
            }
        }
        let probe_depths: Vec<f64> = (0..dims[2])
            .map(|k| {
                let first = k * depth_cell;
                let last = ((k + 1) * depth_cell).min(march.samples);
                march.near + (first + last) as f64 / 2.0 * step
            })
            .collect();
        let mut density = Vec::with_capacity(pixels.len() * dims[2]);
        let rays_per_chunk = (cfg.chunk / dims[2]).max(1);
        let pose = &angles.iter().map(|&v| v as f32).collect::<Vec<f32>>();
        for part in pixels.chunks(rays_per_chunk) {
            let depths: Vec<f64> = part.iter().flat_map(|_| probe_depths.clone()).collect();
            let points = sample_points(camera, part, &depths, device);
            let raw: TensorData = field.forward_pose(points, pose).into_data();
            let raw = raw.try_into_vec::<f32>().expect("float tensor");
            density.extend(raw.chunks(2).map(|r| r[0]));
        }
        let evaluations = density.len();
        let seeds: Vec<bool> = density.iter().map(|&d| d > cfg.density_threshold).collect();
        FrustumGrid {
            dims,
            block,
            depth_cell,
            occupied: dilate(
                &seeds,
                dims,
                [cfg.dilation, cfg.dilation, cfg.depth_dilation],
            ),
            evaluations,
        }
    }

    /// Whether sample `k` of the ray through pixel (`row`, `col`) lies in an occupied cell.
    pub fn contains(&self, row: usize, col: usize, k: usize) -> bool {
        let [_, w, d] = self.dims;
        self.occupied[((row / self.block) * w + col / self.block) * d + k / self.depth_cell]
    }

    /// Fraction of cells occupied.
    pub fn occupancy(&self) -> f64 {
        self.occupied.iter().filter(|&&o| o).count() as f64 / self.occupied.len().max(1) as f64
    }
}

/// Grow the occupied set by `radius[axis]` cells along each axis (rows, columns, depth): a
/// box dilation, separable.
fn dilate(occupied: &[bool], dims: [usize; 3], radius: [usize; 3]) -> Vec<bool> {
    let mut cur = occupied.to_vec();
    let strides = [dims[1] * dims[2], dims[2], 1];
    for axis in 0..3 {
        let r = radius[axis];
        if r == 0 {
            continue;
        }
        let mut next = cur.clone();
        for (idx, flag) in next.iter_mut().enumerate() {
            if *flag {
                continue;
            }
            let pos = (idx / strides[axis]) % dims[axis];
            let lo = pos.saturating_sub(r);
            let hi = (pos + r).min(dims[axis] - 1);
            *flag = (lo..=hi).any(|p| cur[idx - pos * strides[axis] + p * strides[axis]]);
        }
        cur = next;
    }
    cur
}

#[cfg(test)]
mod tests {
    use super::dilate;

    #[test]
    fn dilation_grows_a_cell_into_a_box_clipped_at_the_edges() {
        let dims = [4, 5, 3];
        let mut seeds = vec![false; 60];
        seeds[(5 + 4) * 3] = true; // (1, 4, 0)
        let grown = dilate(&seeds, dims, [1, 1, 1]);
        let on: Vec<[usize; 3]> = (0..60)
            .filter(|&i| grown[i])
            .map(|i| [i / 15, (i / 3) % 5, i % 3])
            .collect();
        assert_eq!(on.len(), 3 * 2 * 2);
        assert!(on.iter().all(|c| c[0] <= 2 && c[1] >= 3 && c[2] <= 1));
        // Across the image only (the paper preset): the depth cell stays 0.
        let flat = dilate(&seeds, dims, [1, 1, 0]);
        let on: Vec<usize> = (0..60).filter(|&i| flat[i]).collect();
        assert_eq!(on.len(), 3 * 2);
        assert!(on.iter().all(|&i| i % 3 == 0));
    }
}
