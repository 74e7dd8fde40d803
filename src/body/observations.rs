//! The images the body is read from: silhouettes `[n, 1, H, W]` in [0, 1], checked before
//! any fit (the model's size, no empty image, finite values) and perturbed as a real camera
//! and scene would perturb them.

use burn::tensor::{Device, Tensor, TensorData};
use rand::rngs::StdRng;
use rand::{RngExt, SeedableRng};

use crate::core::error::{Error, Result};
use crate::data::dataset::Dataset;
use crate::self_models::model::Render;

/// What a fit to images looks through: the self-model that renders (differentiable, on the
/// autodiff `device`: [`Render::differentiable`]) `image`-sized silhouettes, and the
/// silhouettes `observed`.
#[derive(Clone, Copy)]
pub struct ImageFit<'a> {
    pub renderer: &'a dyn Render,
    pub device: &'a Device,
    pub image: [usize; 2],
    pub observed: &'a Observed,
}

impl<'a> ImageFit<'a> {
    /// The renderer, its device, the image size and the observed silhouettes.
    pub fn parts(self) -> (&'a dyn Render, &'a Device, [usize; 2], &'a Observed) {
        (self.renderer, self.device, self.image, self.observed)
    }
}

/// Observed silhouettes, on the host.
#[derive(Clone, Debug, PartialEq)]
pub struct Observed {
    /// `n * H * W` values in [0, 1] (1: the robot).
    pub pixels: Vec<f32>,
    pub n: usize,
    /// `[height, width]`.
    pub size: [usize; 2],
}

impl Observed {
    /// Silhouettes from raw pixels, checked: `n * H * W` finite values in [0, 1].
    pub fn new(pixels: Vec<f32>, n: usize, size: [usize; 2]) -> Result<Self> {
        let [h, w] = size;
        if pixels.len() != n * h * w {
            return Err(Error::Config(format!(
                "{} pixels are not {n} images of {h}x{w}",
                pixels.len()
            )));
        }
        if let Some(i) = pixels
            .iter()
            .position(|v| !v.is_finite() || !(0.0..=1.0).contains(v))
        {
            return Err(Error::Config(format!(
                "image {}: pixel value {} is not a silhouette value in [0, 1]",
                i / (h * w).max(1),
                pixels[i]
            )));
        }
        Ok(Observed { pixels, n, size })
    }

    /// The silhouettes of samples `samples` (indices) of a dataset.
    pub fn from_dataset(data: &Dataset, samples: &[usize]) -> Self {
        let px = data.width * data.height;
        let pixels = samples
            .iter()
            .flat_map(|&i| data.images[i * px..(i + 1) * px].iter())
            .map(|&v| v as f32 / 255.0)
            .collect();
        Observed {
            pixels,
            n: samples.len(),
            size: [data.height, data.width],
        }
    }

    fn pixels_per_image(&self) -> usize {
        self.size[0] * self.size[1]
    }

    /// Image `i`'s pixels.
    pub fn image(&self, i: usize) -> &[f32] {
        let px = self.pixels_per_image();
        &self.pixels[i * px..(i + 1) * px]
    }

    /// Images `range` only.
    pub fn select(&self, range: std::ops::Range<usize>) -> Observed {
        let px = self.pixels_per_image();
        Observed {
            pixels: self.pixels[range.start * px..range.end * px].to_vec(),
            n: range.len(),
            size: self.size,
        }
    }

    /// Reject what no fit can read: images of another size than the model renders
    /// (`image`, `[height, width]`), and empty silhouettes (no pixel of the robot).
    pub fn check_for(&self, image: [usize; 2]) -> Result<()> {
        if self.size != image {
            return Err(Error::Config(format!(
                "the images are {}x{} pixels but the self-model renders {}x{}: resize them or train the model at that size",
                self.size[0], self.size[1], image[0], image[1]
            )));
        }
        if self.n == 0 {
            return Err(Error::Config("no images to read".into()));
        }
        if let Some(i) = (0..self.n).find(|&i| self.image(i).iter().all(|&v| v < 0.5)) {
            return Err(Error::Config(format!(
                "image {i} is empty (no pixel of the robot): the arm is out of view, nothing to fit"
            )));
        }
        Ok(())
    }

    /// `[n, 1, H, W]` on `device`.
    pub fn tensor(&self, device: &Device) -> Tensor<4> {
        let [h, w] = self.size;
        Tensor::from_data(
            TensorData::new(self.pixels.clone(), [self.n, 1, h, w]),
            device,
        )
    }

    /// Each image `times` times in a row (image 0 `times` times, then image 1, ...).
    pub fn repeated(&self, times: usize) -> Observed {
        let mut pixels = Vec::with_capacity(self.pixels.len() * times);
        for i in 0..self.n {
            for _ in 0..times {
                pixels.extend_from_slice(self.image(i));
            }
        }
        Observed {
            pixels,
            n: self.n * times,
            size: self.size,
        }
    }

    /// The same images as a camera and scene would spoil them (`seed`: which pixels).
    pub fn perturbed(&self, p: Perturbation, seed: u64) -> Observed {
        let [h, w] = self.size;
        let px = h * w;
        let mut out = self.clone();
        let mut rng = StdRng::seed_from_u64(seed);
        for i in 0..self.n {
            let img = &mut out.pixels[i * px..(i + 1) * px];
            match p {
                Perturbation::Clean => {}
                Perturbation::FlipPixels(share) => {
                    for v in img.iter_mut() {
                        if rng.random::<f64>() < share {
                            *v = if *v >= 0.5 { 0.0 } else { 1.0 };
                        }
                    }
                }
                Perturbation::Occlude(share) => occlude(img, [h, w], share, &mut rng),
                Perturbation::Shift(dx, dy) => {
                    let src = img.to_vec();
                    for y in 0..h as isize {
                        for x in 0..w as isize {
                            let (sx, sy) = (x - dx as isize, y - dy as isize);
                            img[y as usize * w + x as usize] =
                                if (0..w as isize).contains(&sx) && (0..h as isize).contains(&sy) {
                                    src[sy as usize * w + sx as usize]
                                } else {
                                    0.0
                                };
                        }
                    }
                }
            }
        }
        out
    }
}

/// How the observed images are spoiled in the robustness rows.
#[derive(Clone, Copy, Debug, PartialEq, serde::Serialize, serde::Deserialize)]
pub enum Perturbation {
    Clean,
    /// This share of all pixels flipped (robot <-> background).
    FlipPixels(f64),
    /// A box placed on the arm hides about this share of its pixels (they read as background).
    Occlude(f64),
    /// The image moved by (dx, dy) pixels, background coming in at the edge.
    Shift(i32, i32),
}

impl Perturbation {
    /// The row label: "clean", "5% pixels flipped", "box over 10% of the arm", "shifted 1 px".
    pub fn label(&self) -> String {
        match *self {
            Perturbation::Clean => "clean".into(),
            Perturbation::FlipPixels(s) => format!("{:.0}% pixels flipped", 100.0 * s),
            Perturbation::Occlude(s) => format!("box over {:.0}% of the arm", 100.0 * s),
            Perturbation::Shift(dx, dy) => {
                let d = dx.abs().max(dy.abs());
                format!("shifted {d} px")
            }
        }
    }
}

/// Hide about `share` of the robot's pixels under a square centred on one of them.
fn occlude(img: &mut [f32], [h, w]: [usize; 2], share: f64, rng: &mut StdRng) {
    let robot: Vec<usize> = (0..img.len()).filter(|&k| img[k] >= 0.5).collect();
    if robot.is_empty() {
        return;
    }
    let centre = robot[rng.random_range(0..robot.len())];
    let (cy, cx) = ((centre / w) as isize, (centre % w) as isize);
    let want = (share * robot.len() as f64).ceil() as usize;
    let covered = |r: isize| {
        robot
            .iter()
            .filter(|&&k| {
                let (y, x) = ((k / w) as isize, (k % w) as isize);
                (y - cy).abs() <= r && (x - cx).abs() <= r
            })
            .count()
    };
    let mut r = 0;
    while covered(r) < want && r < h.max(w) as isize {
        r += 1;
    }
    for y in (cy - r).max(0)..=(cy + r).min(h as isize - 1) {
        for x in (cx - r).max(0)..=(cx + r).min(w as isize - 1) {
            img[y as usize * w + x as usize] = 0.0;
        }
    }
}

/// A tensor's values on the host as `f32`.
pub fn host<const D: usize>(t: Tensor<D>) -> Result<Vec<f32>> {
    t.into_data()
        .convert::<f32>()
        .try_into_vec::<f32>()
        .map_err(|e| Error::Training(format!("reading a tensor back: {e:?}")))
}

/// Reject joint angles that are not numbers (NaN or infinite), naming the first.
pub fn check_angles(angles: &[Vec<f64>], dof: usize, what: &str) -> Result<()> {
    for (i, q) in angles.iter().enumerate() {
        if q.len() != dof {
            return Err(Error::Config(format!(
                "{what} {i} has {} joint values, the robot has {dof}",
                q.len()
            )));
        }
        if let Some(v) = q.iter().find(|v| !v.is_finite()) {
            return Err(Error::Config(format!(
                "{what} {i} holds {v}, not a joint angle"
            )));
        }
    }
    Ok(())
}
