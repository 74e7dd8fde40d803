//! Joint angles from a silhouette: the mean training pose (a baseline), the amortised CNN, the
//! CNN refined through the self-model (and through K-3DGS), a search without a guess, and the
//! refined CNN on spoiled images (`results.csv`, `pose_grid.png`); the clean images' estimates
//! per joint group (`groups.csv`).

use std::path::Path;

use burn::tensor::{Tensor, TensorData};

use super::bench::{Bench, Ms, PoseRow, Seen};
use selfmodel::body::amortised::train_estimator;
use selfmodel::body::observations::{ImageFit, Observed, host};
use selfmodel::body::pose::pose_from_image;
use selfmodel::core::error::Result;
use selfmodel::core::timing::{Repeats, median_seconds};
use selfmodel::report::figures::{GridRow, image_grid};
use selfmodel::report::table::{write_csv, write_markdown_report};
use selfmodel::self_models::model::Render;
use selfmodel::sim::robot::Robot;

/// What the poses are read through: the self-model's name, and K-3DGS trained on the same
/// data (differentiable, on the autodiff device), if the study reads through it too.
pub struct Through<'a> {
    pub model: &'a str,
    pub k3dgs: Option<&'a dyn Render>,
}

/// The rows of `results.csv` for the test poses `truth` seen in `observed`, written with their
/// report, `groups.csv` and `pose_grid.png` into `out`; `seen` are the training poses (the
/// baseline's mean).
pub fn pose_rows(
    b: &Bench,
    through: Through,
    seen: &[Vec<f64>],
    observed: &Observed,
    truth: &[Vec<f64>],
    out: &Path,
) -> Result<Vec<PoseRow>> {
    let (cfg, device) = (b.cfg, b.device);
    let n = truth.len();
    let dof = truth[0].len();
    let clean = || Seen {
        label: "clean",
        observed,
    };
    let mean: Vec<f64> = (0..dof)
        .map(|j| seen.iter().map(|q| q[j]).sum::<f64>() / seen.len() as f64)
        .collect();
    let nk: (&dyn Render, &burn::tensor::Device) = (b.renderer, device);
    let mean = vec![mean; n];
    let mut rows = vec![b.row("mean training pose", &mean, truth, Ms::UNTIMED, clean(), nk)?];
    let estimator = train_estimator(&cfg.amortised, b.renderer, device, b.image, &b.ranges, seen)?;
    let t = std::time::Instant::now();
    let guesses = estimator.estimate(observed, device, 64)?;
    let cnn_batched = 1000.0 * t.elapsed().as_secs_f64() / n as f64;
    let one = observed.select(0..1);
    let cnn_b1 = 1000.0
        * median_seconds(Repeats::exactly(2, 10), || {
            let _ = estimator.estimate(&one, device, 1);
        });
    let cnn = Ms {
        b1: cnn_b1,
        batched: cnn_batched,
    };
    rows.push(b.row("amortised CNN", &guesses, truth, cnn, clean(), nk)?);
    let refined_label = format!("CNN + {} refinement steps", cfg.refine.steps);
    let t = std::time::Instant::now();
    let refined = b.refine(b.differentiable, observed, &guesses, &cfg.refine)?;
    let refine_batched = 1000.0 * t.elapsed().as_secs_f64() / n as f64 + cnn_batched;
    let refine_b1 = 1000.0
        * median_seconds(Repeats::exactly(1, 3), || {
            let g = estimator
                .estimate(&one, device, 1)
                .expect("estimated above");
            let _ = b.refine(b.differentiable, &one, &g, &cfg.refine);
        });
    let refine = Ms {
        b1: refine_b1,
        batched: refine_batched,
    };
    rows.push(b.row(&refined_label, &refined, truth, refine, clean(), nk)?);
    // The diagnostic: the same refinement started at the true angles. Where it walks away
    // from them, the self-model's optimum is not the truth (its own error, or what a
    // silhouette cannot show).
    let from_truth = b.refine(b.differentiable, observed, truth, &cfg.refine)?;
    let diagnostic = format!(
        "true angles + {} refinement steps (diagnostic)",
        cfg.refine.steps
    );
    rows.push(b.row(&diagnostic, &from_truth, truth, Ms::UNTIMED, clean(), nk)?);
    // The same refinement through K-3DGS (trained on the same data), from the same CNN.
    if let Some(k3dgs) = through.k3dgs {
        let t = std::time::Instant::now();
        let through_gaussians = b.refine(k3dgs, observed, &guesses, &cfg.refine)?;
        let gaussians = Ms {
            b1: f64::NAN,
            batched: 1000.0 * t.elapsed().as_secs_f64() / n as f64 + cnn_batched,
        };
        rows.push(b.row(
            &format!("{refined_label}, through K-3DGS"),
            &through_gaussians,
            truth,
            gaussians,
            clean(),
            (k3dgs, b.autodiff),
        )?);
    }
    let m = cfg.search_poses.min(n);
    let t = std::time::Instant::now();
    let searched = pose_from_image(
        ImageFit {
            renderer: b.differentiable,
            device: b.autodiff,
            image: b.image,
            observed: &observed.select(0..m),
        },
        &b.ranges,
        None,
        &cfg.search,
        |_| {},
    )?;
    let search = Ms {
        b1: f64::NAN,
        batched: 1000.0 * t.elapsed().as_secs_f64() / m as f64,
    };
    let label = format!(
        "search ({} starts, {} steps)",
        cfg.search.starts, cfg.search.steps
    );
    rows.push(b.row(&label, &searched.angles, &truth[..m], search, clean(), nk)?);
    for (i, p) in cfg.perturbations.iter().enumerate() {
        let spoiled = observed.perturbed(*p, cfg.seed + 1 + i as u64);
        let g = estimator.estimate(&spoiled, device, 64)?;
        let r = b.refine(b.differentiable, &spoiled, &g, &cfg.refine)?;
        let label = p.label();
        for (method, found) in [("amortised CNN", &g), (refined_label.as_str(), &r)] {
            let seen = Seen {
                label: &label,
                observed: &spoiled,
            };
            rows.push(b.row(method, found, truth, Ms::UNTIMED, seen, nk)?);
        }
    }
    // The clean images' estimates, scored per joint group (the diagnostic and K-3DGS rows
    // are not estimates a user would make).
    let estimates: [(&str, &[Vec<f64>]); 4] = [
        ("mean training pose", &mean),
        ("amortised CNN", &guesses),
        (&refined_label, &refined),
        (&label, &searched.angles),
    ];
    write_tables(b.robot, &rows, &through, &estimates, truth, out)?;
    pose_grid(b, observed, &refined, truth, &out.join("pose_grid.png"))?;
    Ok(rows)
}

/// `results.csv` (`rows`) with its report, and `groups.csv` for the clean images' `estimates`
/// (each its method and its poses, the first of `truth`) on `robot`'s joint groups, into
/// `out`.
fn write_tables(
    robot: &Robot,
    rows: &[PoseRow],
    through: &Through,
    estimates: &[(&str, &[Vec<f64>])],
    truth: &[Vec<f64>],
    out: &Path,
) -> Result<()> {
    let pose_csv = out.join("results.csv");
    write_csv(&pose_csv, rows)?;
    let k3dgs_row = if through.k3dgs.is_some() {
        " (one row: through K-3DGS, isotropic with alpha compositing, from the same CNN answers)"
    } else {
        ""
    };
    write_markdown_report(
        &pose_csv,
        "Joint angles from a silhouette",
        &format!(
            "The test poses' silhouettes read back through the trained {}{k3dgs_row}. Errors are absolute joint \
         errors in degrees (mean and median over every joint of every pose), the end effector's \
         distance in mm, and the share of poses with every joint within 2 degrees. The CNN is trained \
         on the self-model's own renderings; the refinement descends the silhouette's cross-entropy \
         through the model from the CNN's answer; the search starts from poses drawn within the \
         training poses' range, keeping the start with the lowest loss. The diagnostic row starts the \
         refinement at the true angles. `loss_below_truth_share`: the poses whose estimate the model \
         scores better than the truth (the model's optimum is elsewhere). Milliseconds on this \
         machine's CPU, one image at a time (b1) and per pose over a batch.",
            through.model
        ),
    )?;
    let groups = super::groups::groups(robot);
    let group_rows: Vec<_> = estimates
        .iter()
        .flat_map(|(method, found)| {
            super::groups::group_rows(method, &groups, found, &truth[..found.len()])
        })
        .collect();
    super::groups::write(&group_rows, through.model, out)
}

/// Observed silhouettes, the self-model's rendering at the estimate and their difference,
/// for up to 8 test poses, each captioned with its mean joint error.
fn pose_grid(
    b: &Bench,
    observed: &Observed,
    found: &[Vec<f64>],
    truth: &[Vec<f64>],
    path: &Path,
) -> Result<()> {
    // Eight poses spread over the test trajectory (neighbours on it look alike).
    let n = observed.n.min(8);
    let picks: Vec<usize> = (0..n).map(|i| i * observed.n / n).collect();
    let observed = Observed::new(
        picks
            .iter()
            .flat_map(|&i| observed.image(i).iter().copied())
            .collect(),
        n,
        observed.size,
    )?;
    let found: Vec<Vec<f64>> = picks.iter().map(|&i| found[i].clone()).collect();
    let truth: Vec<Vec<f64>> = picks.iter().map(|&i| truth[i].clone()).collect();
    let dof = found[0].len();
    let q: Vec<f32> = found.iter().flatten().map(|&v| v as f32).collect();
    let rendered = host(
        b.renderer
            .render(Tensor::from_data(TensorData::new(q, [n, dof]), b.device))
            .0,
    )?;
    let px = b.image[0] * b.image[1];
    let obs: Vec<&[f32]> = (0..n).map(|i| observed.image(i)).collect();
    let ren: Vec<&[f32]> = (0..n).map(|i| &rendered[i * px..(i + 1) * px]).collect();
    let err: Vec<Vec<f32>> = obs
        .iter()
        .zip(&ren)
        .map(|(o, r)| o.iter().zip(r.iter()).map(|(a, b)| (a - b).abs()).collect())
        .collect();
    let captions: Vec<String> = (0..n)
        .map(|i| {
            let e = found[i]
                .iter()
                .zip(&truth[i])
                .map(|(a, b)| (a - b).abs())
                .sum::<f64>()
                / dof as f64;
            format!("{e:.2} deg")
        })
        .collect();
    image_grid(
        path,
        &[GridRow::Grey(obs), GridRow::Grey(ren), GridRow::Error(err)],
        &["observed", "rendered at estimate", "|difference|"],
        &captions,
        b.image[1],
        b.image[0],
        2,
    )
}
