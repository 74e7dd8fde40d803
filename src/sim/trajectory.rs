//! Joint-space samplers: how the robot moves while it records its dataset.
//!
//! - [`lorenz`]: the self-modeling paper's smooth chaotic trajectories (section IV-A).
//! - [`babbling`]: uniform motor babbling within the joint ranges.
//! - [`grid`]: the original FFKSM's regular grid (9 degree steps).
//!
//! All return joint vectors in user units (degrees for rotational joints), one row a sample.

use rand::rngs::StdRng;
use rand::seq::index::sample;
use rand::{RngExt, SeedableRng};
use serde::{Deserialize, Serialize};

use crate::core::error::{Error, Result};

/// Which sampler, with its parameters.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[cfg_attr(feature = "clap", derive(clap::ValueEnum))]
#[serde(rename_all = "lowercase")]
pub enum SamplerKind {
    /// Two Lorenz-attractor trajectories squashed into the joint ranges (the paper).
    Lorenz,
    /// Independent uniform samples within the joint ranges.
    Babbling,
    /// A regular grid with a fixed step, subsampled at random if it is larger than asked.
    Grid,
}

/// Lorenz system parameters of the paper: sigma 10, rho 28, beta 8/3.
pub const LORENZ_SIGMA: f64 = 10.0;
pub const LORENZ_RHO: f64 = 28.0;
pub const LORENZ_BETA: f64 = 8.0 / 3.0;

/// One Lorenz trajectory: RK4 from [1, 1, 1] with step `dt`, one step per sample, each state
/// squashed as tanh(scale * state). Returns `n` rows of 3 values in (-1, 1).
pub fn lorenz_trajectory(n: usize, dt: f64, scale: f64) -> Vec<[f64; 3]> {
    lorenz_trajectory_from(n, dt, scale, [1.0, 1.0, 1.0])
}

/// [`lorenz_trajectory`] from the state `start`.
pub fn lorenz_trajectory_from(n: usize, dt: f64, scale: f64, start: [f64; 3]) -> Vec<[f64; 3]> {
    let f = |s: [f64; 3]| {
        [
            LORENZ_SIGMA * (s[1] - s[0]),
            s[0] * (LORENZ_RHO - s[2]) - s[1],
            s[0] * s[1] - LORENZ_BETA * s[2],
        ]
    };
    let add =
        |s: [f64; 3], k: [f64; 3], h: f64| [s[0] + h * k[0], s[1] + h * k[1], s[2] + h * k[2]];
    let mut s = start;
    (0..n)
        .map(|_| {
            let k1 = f(s);
            let k2 = f(add(s, k1, dt / 2.0));
            let k3 = f(add(s, k2, dt / 2.0));
            let k4 = f(add(s, k3, dt));
            s = std::array::from_fn(|i| {
                s[i] + dt / 6.0 * (k1[i] + 2.0 * k2[i] + 2.0 * k3[i] + k4[i])
            });
            s.map(|v| (scale * v).tanh())
        })
        .collect()
}

/// The paper's joint trajectories: trajectory 1 (dt 0.01, scale 0.025) and trajectory 2
/// (dt 0.012, scale 0.022); joint channels [t1.x, t1.y, t2.x, t2.z] (then t1.z, t2.y for a
/// 5th and 6th joint), each mapped from (-1, 1) onto the joint's range (for the papers'
/// +-90 degree range: 90 * value). `ranges` are in user units.
///
/// Beyond six joints (beyond the paper), every further three joints take the x, y and z of one
/// more trajectory, the k-th (k = 3, 4, ...) started from [1, 1, 1 + k] with scale 0.025 and
/// dt 0.01 + 0.001 ((k - 3) mod 20 + 3) (0.013 to 0.032: RK4 integrates the Lorenz system
/// stably there, where a step growing with k diverged past ~377 joints), so no two joints
/// share a channel; a robot with n joints draws ceil(n / 3) trajectories beyond the first two
/// only when n > 6. A trajectory that is not finite anyway is an error, never a NaN angle.
pub fn lorenz(n: usize, ranges: &[[f64; 2]]) -> Result<Vec<Vec<f64>>> {
    let t1 = lorenz_trajectory(n, 0.01, 0.025);
    let t2 = lorenz_trajectory(n, 0.012, 0.022);
    let extra: Vec<Vec<[f64; 3]>> = (0..ranges.len().saturating_sub(6).div_ceil(3))
        .map(|i| {
            let dt = 0.01 + 0.001 * ((i % 20) + 3) as f64;
            let k = (i + 3) as f64;
            lorenz_trajectory_from(n, dt, 0.025, [1.0, 1.0, 1.0 + k])
        })
        .collect();
    if let Some(k) = extra
        .iter()
        .position(|t| t.iter().flatten().any(|v| !v.is_finite()))
    {
        return Err(Error::Config(format!(
            "the Lorenz sampler's trajectory {} is not finite: use `sampler` babbling for this robot",
            k + 3
        )));
    }
    Ok((0..n)
        .map(|i| {
            let channels = [t1[i][0], t1[i][1], t2[i][0], t2[i][2], t1[i][2], t2[i][1]]
                .into_iter()
                .chain(extra.iter().flat_map(|t| t[i]));
            ranges
                .iter()
                .zip(channels)
                .map(|(r, v)| (r[0] + r[1]) / 2.0 + v * (r[1] - r[0]) / 2.0)
                .collect()
        })
        .collect())
}

/// `n` uniform samples within `ranges` (user units), seeded.
pub fn babbling(n: usize, ranges: &[[f64; 2]], seed: u64) -> Vec<Vec<f64>> {
    babbling_rows(ranges, seed).take(n).collect()
}

/// [`babbling`]'s samples one at a time, drawn as they are asked for (ten million rows are
/// streamed, never held).
pub fn babbling_rows(ranges: &[[f64; 2]], seed: u64) -> impl Iterator<Item = Vec<f64>> + '_ {
    let mut rng = StdRng::seed_from_u64(seed);
    std::iter::repeat_with(move || uniform_in(&mut rng, ranges))
}

/// One joint vector drawn uniformly within `ranges` (each joint's `[lo, hi]`, ends included),
/// joint by joint from `rng`: the one draw every sampler, random start and restart makes.
pub fn uniform_in<R: RngExt + ?Sized>(rng: &mut R, ranges: &[[f64; 2]]) -> Vec<f64> {
    ranges
        .iter()
        .map(|&[lo, hi]| rng.random_range(lo..=hi))
        .collect()
}

/// The most grid points along one joint.
const MAX_GRID_POINTS: usize = 1_000_000;

/// The grid with spacing `steps[j]` over each joint's range (ends included), in
/// lexicographic order (last joint fastest). If it has more than `n` points, `n` of them are
/// drawn at random without replacement (seeded) and kept in grid order.
pub fn grid(n: usize, ranges: &[[f64; 2]], steps: &[f64], seed: u64) -> Result<Vec<Vec<f64>>> {
    if let Some(step) = steps.iter().find(|s| !(**s > 0.0)) {
        return Err(Error::Config(format!(
            "grid step must be positive, got {step}"
        )));
    }
    let axes: Vec<Vec<f64>> = ranges
        .iter()
        .zip(steps)
        .map(|(r, &step)| {
            let m = ((r[1] - r[0]) / step + 1e-9).floor();
            if !(m <= MAX_GRID_POINTS as f64) {
                return Err(Error::Config(format!(
                    "a grid step of {step} gives {m:.3e} points along a joint's range of {}; at most {MAX_GRID_POINTS} (raise `grid_step`)",
                    r[1] - r[0]
                )));
            }
            Ok((0..=m as usize).map(|i| r[0] + i as f64 * step).collect())
        })
        .collect::<Result<_>>()?;
    let total: usize = axes
        .iter()
        .map(Vec::len)
        .fold(1usize, |a, b| a.saturating_mul(b));
    let point = |mut i: usize| {
        let mut q = vec![0.0; axes.len()];
        for (a, axis) in axes.iter().enumerate().rev() {
            q[a] = axis[i % axis.len()];
            i /= axis.len();
        }
        q
    };
    if n >= total {
        return Ok((0..total).map(point).collect());
    }
    let mut rng = StdRng::seed_from_u64(seed);
    let mut picked = sample(&mut rng, total, n).into_vec();
    picked.sort_unstable();
    Ok(picked.into_iter().map(point).collect())
}
