//! The one registry of experiments: it drives the smoke tests (`tests/experiments.rs`, every
//! entry on its `quick` preset), the reproduce-everything command (`reproduce`) and the
//! reports, and `table1` (every entry marked `in_table1` contributes its rows). Each binary in
//! `experiments/` parses its arguments and calls the same function.

use std::path::Path;

use crate::studies::ablations::{Ablation, run_ablation};
use crate::studies::emssl::table2::{IK_PRESETS, IkComparisonConfig, TABLE2_PRESETS};
use crate::studies::models::k3dgs_reports::RenderSpeedRow;
use crate::studies::models::run_studied;
use selfmodel::self_models::ffksm::{FfksmVariant, ffksm_run};
use selfmodel::self_models::k3dgs::{K3dgsVariant, k3dgs_run};
use selfmodel::self_models::link_splat::LinkSplatConfig;
use selfmodel::self_models::mean_silhouette::MeanSilhouette;
use selfmodel::self_models::neurokin::{
    NeuroKinConfig, neurokin_run, neurokin_tree_run, neurokin64_run,
};
use selfmodel::self_models::resneurokin_d::ResNeuroKinDConfig;
use selfmodel::self_models::run_config::SELF_MODEL_PRESETS;

use crate::studies::mesh_fidelity::{self, FidelityConfig};
pub use crate::studies::run::{Experiment, RunOptions, run_self_model, summary, write_rows};
use selfmodel::core::error::Result;
use selfmodel::core::preset::Preset;
use selfmodel::data::dataset::{DatasetConfig, build_and_save};

fn run_dataset(opts: &RunOptions, dir: &Path) -> Result<String> {
    let mut cfg = DatasetConfig::preset(if opts.preset == "short" {
        "paper"
    } else {
        &opts.preset
    })?;
    cfg.render.ground_artifact = opts.paper_compatible;
    let robot = selfmodel::sim::arm4::arm4();
    let out = dir.join("dataset.npz");
    let (data, report) = build_and_save(&robot, "arm4", &cfg, None, &out, false)?;
    selfmodel::report::dataset_preview::dataset_preview(&data, &report, &out)?;
    Ok(format!(
        "{} samples rendered in {:.3} s, mean occupancy {:.2}%",
        data.len(),
        report.render_seconds,
        100.0 * report.stats.occupancy.mean
    ))
}

fn run_mesh_fidelity(opts: &RunOptions, dir: &Path) -> Result<String> {
    let preset = if opts.preset == "short" {
        "quick"
    } else {
        &opts.preset
    };
    let rows = mesh_fidelity::run(&FidelityConfig::preset(preset)?, dir)?;
    Ok(format!(
        "arm4 vs mesh robot: mean IoU {:.4} over {} poses",
        rows[0].mean_iou, rows[0].poses
    ))
}

/// NeuroKin-64, the paper text's variant: on the clean data it collapses to an empty image (a
/// documented negative result, kept out of Table I); on the paper-compatible data it trains.
pub fn run_neurokin64(opts: &RunOptions, dir: &Path) -> Result<String> {
    let cfg = opts.apply(neurokin64_run(&opts.preset)?)?;
    let out = run_studied(&cfg, dir, opts.device, opts.resume)?;
    Ok(summary(std::slice::from_ref(&out.result)))
}

/// NeuroKin with the kinematic-tree encoder (Section VI-D4), at the flat encoder's size: for
/// robots of many joints, beside `neurokin` (`table1 --models` adds it to a Table I).
pub fn run_neurokin_tree(opts: &RunOptions, dir: &Path) -> Result<String> {
    let cfg = opts.apply(neurokin_tree_run(&opts.preset)?)?;
    let out = run_studied(&cfg, dir, opts.device, opts.resume)?;
    Ok(summary(std::slice::from_ref(&out.result)))
}

/// FFKSM: the reimplementation, the original authors' model, and the reimplementation trained
/// with empty-space skipping, each rendered densely and with the accelerated marcher (two rows
/// each), novel views and depth.
pub fn run_ffksm(opts: &RunOptions, dir: &Path) -> Result<String> {
    let mut rows = Vec::new();
    let mut renderers = Vec::new();
    let mut novel = Vec::new();
    let dense = selfmodel::report::table::read_csv::<selfmodel::self_models::ffksm::RendererRow>;
    let novel_rows =
        selfmodel::report::table::read_csv::<selfmodel::self_models::ffksm::NovelViewRow>;
    // Every model's checkpoint is checked before the first one writes anything.
    let papers_arm = opts.dataset.is_none()
        && opts
            .robot_spec(selfmodel::sim::robots::BuiltinRobot::Arm4)
            .is_papers_arm();
    let runs: Vec<_> = FfksmVariant::of_run(&opts.preset, papers_arm)
        .iter()
        .map(|&(sub, variant)| Ok((sub, opts.apply(ffksm_run(&opts.preset, variant)?)?)))
        .collect::<Result<_>>()?;
    for (sub, cfg) in &runs {
        selfmodel::self_models::harness::check_resumable(cfg, &dir.join(sub), opts.resume)?;
    }
    for (sub, cfg) in runs {
        let out = run_studied(&cfg, &dir.join(sub), opts.device, opts.resume)?;
        rows.extend(out.rows);
        // Without the reference renderers (the short preset) there are no comparisons.
        if cfg.model.reference_renderers {
            renderers.extend(dense(&dir.join(sub).join("renderers.csv"))?);
            novel.extend(novel_rows(&dir.join(sub).join("novel_views.csv"))?);
        }
    }
    write_rows(
        dir,
        &rows,
        "FFKSM: the occupancy-field self-model, two implementations, two renderers",
        "One row per model and renderer (the same trained model renders both ways); `FFKSM (trained with skipping)` is the reimplementation trained on the samples of occupied grid cells only (beyond the paper); each folder holds its config, curve, figures, `renderers.csv` and `novel_views.csv`. `paper_*` columns are the paper's figures for reference: 17.35 dB at 5.22 FPS on a T4 for the reimplementation (its code logged 16.35 dB), about 23.4 dB for the original authors' model with 12,000 samples and far longer training.",
    )?;
    if renderers.is_empty() {
        return Ok(summary(&rows));
    }
    let path = dir.join("renderers.csv");
    selfmodel::report::table::write_table(
        &path,
        &renderers,
        "FFKSM: dense marching against the accelerated marcher",
        "Same models, same test images. `fewer_evaluations`: dense marching's network evaluations per image over this renderer's (grid probes included); `psnr_db_vs_dense`: the two renderers' images compared directly. Images/s: median per image after a warm-up image, batch 1.",
    )?;
    let path = dir.join("novel_views.csv");
    selfmodel::report::table::write_table(
        &path,
        &novel,
        "FFKSM: views it was never trained on",
        "Cameras orbited about the world z axis, against the simulator's images from there; `view_blind_*` offers the training camera's true silhouette as the prediction (the best a 2-D decoder can do).",
    )?;
    Ok(summary(&rows))
}

/// K-3DGS: isotropic Gaussians with the reimplementation's compositing and with alpha
/// compositing, one row each.
pub fn run_k3dgs(opts: &RunOptions, dir: &Path) -> Result<String> {
    let mut rows = Vec::new();
    let mut speed = Vec::new();
    for (sub, variant) in K3dgsVariant::ALL {
        let cfg = opts.apply(k3dgs_run(&opts.preset, variant)?)?;
        let out = run_studied(&cfg, &dir.join(sub), opts.device, opts.resume)?;
        rows.push(out.result);
        speed.extend(selfmodel::report::table::read_csv::<RenderSpeedRow>(
            &dir.join(sub).join("render_speed.csv"),
        )?);
    }
    write_rows(
        dir,
        &rows,
        "K-3DGS: Gaussians on the robot's kinematic chain",
        "One row per model; each folder holds its config, curve, `qualitative.png`, `gaussians.png` (centres over the true silhouette) and `render_speed.csv`. PSNR over all test images (the paper's 17.01 dB was over all 400). `paper_*` columns: the paper's figures on a T4, for reference.",
    )?;
    let path = dir.join("render_speed.csv");
    selfmodel::report::table::write_table(
        &path,
        &speed,
        "K-3DGS: culled against dense splatting",
        "Images/s, median of synchronised timed calls after warm-up. Dense evaluates every (Gaussian, pixel) pair (one timed call per batch size, 8 images at a time); culled only pairs within 3 standard deviations.",
    )?;
    Ok(summary(&rows))
}

fn ablation(a: Ablation, opts: &RunOptions, dir: &Path) -> Result<String> {
    let base = opts.apply(neurokin_run(&opts.preset)?)?;
    let rows = run_ablation(a, &base, dir, opts.device, opts.resume)?;
    Ok(summary(&rows))
}

fn run_ablation_noise(opts: &RunOptions, dir: &Path) -> Result<String> {
    ablation(Ablation::Noise, opts, dir)
}
fn run_ablation_depth(opts: &RunOptions, dir: &Path) -> Result<String> {
    ablation(Ablation::Depth, opts, dir)
}
fn run_ablation_latent(opts: &RunOptions, dir: &Path) -> Result<String> {
    ablation(Ablation::Latent, opts, dir)
}
fn run_ablation_precision(opts: &RunOptions, dir: &Path) -> Result<String> {
    if !opts.precision.is_f32() {
        return Err(selfmodel::Error::Config(
            "--precision does not apply to ablation_precision: it trains in each precision the device computes in".into(),
        ));
    }
    ablation(Ablation::Precision, opts, dir)
}
fn run_ablation_data_scale(opts: &RunOptions, dir: &Path) -> Result<String> {
    let rows =
        crate::studies::data_scale::run(opts, opts.models.as_deref(), opts.sizes.as_deref(), dir)?;
    Ok(summary(&rows))
}

/// The inverse-kinematics experiments train no self-model: the dataset, step and resume
/// switches do not apply to them, and say so rather than being ignored.
fn reject_self_model_switches(opts: &RunOptions, name: &str) -> Result<()> {
    let given: Vec<&str> = [
        (opts.paper_compatible, "--paper-compatible"),
        (opts.resume, "--resume"),
        (opts.steps.is_some(), "--steps"),
        (!opts.schedule.is_constant(), "--schedule"),
        (opts.batch.is_some(), "--batch"),
        (opts.train_samples.is_some(), "--train-samples"),
        (
            opts.camera != selfmodel::data::dataset::CameraChoice::default(),
            "--eye, --target, --fov, --size and --view",
        ),
        (
            opts.geometry != selfmodel::sim::urdf_loader::GeometryKind::Visual,
            "--geometry",
        ),
        (opts.dataset.is_some(), "--dataset"),
    ]
    .into_iter()
    .filter_map(|(on, flag)| on.then_some(flag))
    .collect();
    if given.is_empty() {
        Ok(())
    } else {
        Err(selfmodel::Error::Config(format!(
            "{} does not apply to {name} (inverse kinematics renders nothing; its presets set the iterations and epochs)",
            given.join(", ")
        )))
    }
}

/// Table II of the EMSSL paper: every inverse-kinematics method in both joint ranges.
pub fn run_emssl_table2(opts: &RunOptions, dir: &Path) -> Result<String> {
    reject_self_model_switches(
        &RunOptions {
            resume: false,
            ..opts.clone()
        },
        "emssl_table2",
    )?;
    let cfg = IkComparisonConfig::named(&opts.preset)?;
    let robot = opts.ik_robot()?;
    let outcome = crate::studies::emssl::table2::run(&cfg, &robot, dir, opts.device, opts.resume)?;
    let rows = outcome
        .rows
        .iter()
        .map(|r| {
            format!(
                "+-{:.0} {}: {:.2} cm mean, {:.2} median, {:.0}/s",
                r.range_deg, r.method, r.mean_cm, r.median_cm, r.solutions_per_s
            )
        })
        .collect::<Vec<_>>()
        .join("; ");
    Ok(match outcome.partial_note() {
        Some(note) => format!("{rows}\n{note}"),
        None => rows,
    })
}

/// EMSSL against DSL over seeds, with DSL at EMSSL's budget and through the exact forward
/// kinematics (reports/emssl_seeds).
pub fn run_emssl_seeds(opts: &RunOptions, dir: &Path) -> Result<String> {
    reject_self_model_switches(
        &RunOptions {
            resume: false,
            ..opts.clone()
        },
        "emssl_seeds",
    )?;
    let cfg = crate::studies::emssl::seeds::SeedsConfig::preset(&opts.preset)?;
    let robot = opts.ik_robot()?;
    crate::studies::emssl::seeds::run(&cfg, &robot, dir, opts.device, opts.resume)
}

/// What limits EMSSL: one knob at a time, both ranges (reports/emssl_study).
pub fn run_emssl_study(opts: &RunOptions, dir: &Path) -> Result<String> {
    reject_self_model_switches(
        &RunOptions {
            resume: false,
            ..opts.clone()
        },
        "emssl_study",
    )?;
    let cfg = crate::studies::emssl::study::StudyConfig::preset(&opts.preset)?;
    let robot = opts.ik_robot()?;
    crate::studies::emssl::study::run(&cfg, &robot, dir, opts.device, opts.resume)
}

/// Figure 6 of the EMSSL paper: EMSSL's test error against iteration, stopping off.
pub fn run_emssl_learning_curve(opts: &RunOptions, dir: &Path) -> Result<String> {
    reject_self_model_switches(opts, "emssl_learning_curve")?;
    let base = IkComparisonConfig::preset(&opts.preset)?;
    let iterations = if opts.preset == "quick" { 8 } else { 40 };
    let cfg = crate::studies::emssl::learning_curve::config(&base, iterations);
    let robot = opts.ik_robot()?;
    crate::studies::emssl::learning_curve::run(&cfg, &base.emssl, &robot, dir, opts.device)
}

/// Table III and Figure 7 of the EMSSL paper: the sampling phase's time under each strategy.
pub fn run_emssl_sampling_speed(opts: &RunOptions, dir: &Path) -> Result<String> {
    reject_self_model_switches(opts, "emssl_sampling_speed")?;
    let mut cfg = crate::studies::emssl::sampling_speed::SamplingSpeedConfig::preset(&opts.preset)?;
    if let Some(l) = &opts.latencies {
        cfg.latencies = l.clone();
    }
    let robot = opts.ik_robot()?;
    crate::studies::emssl::sampling_speed::run(&cfg, &robot, dir, opts.device)
}

/// Table IV of the EMSSL paper: adapting the inverse model to a changed arm, two approaches.
pub fn run_emssl_adaptation(opts: &RunOptions, dir: &Path) -> Result<String> {
    reject_self_model_switches(opts, "emssl_adaptation")?;
    let cfg = crate::studies::emssl::adaptation::AdaptationConfig::preset(&opts.preset)?;
    let robot = if opts.robot.is_some() || opts.urdf.is_some() {
        Some(opts.ik_robot()?)
    } else {
        None
    };
    crate::studies::emssl::adaptation::run(&cfg, robot, dir, opts.device)
}

/// The studies whose presets set the self-models they train or read through (`why`): the
/// switches that would change those models are refused, not ignored (those models train in
/// f32 only, so `--precision` too).
fn reject_model_switches(opts: &RunOptions, name: &str, why: &str) -> Result<()> {
    let given: Vec<String> = [
        (opts.paper_compatible, "--paper-compatible".to_string()),
        (opts.steps.is_some(), "--steps".to_string()),
        (!opts.schedule.is_constant(), "--schedule".to_string()),
        (
            !opts.precision.is_f32(),
            format!("--precision {}", opts.precision),
        ),
    ]
    .into_iter()
    .filter_map(|(on, flag)| on.then_some(flag))
    .collect();
    if given.is_empty() {
        return Ok(());
    }
    Err(selfmodel::Error::Config(format!(
        "{} does not apply to {name} ({why}, in f32)",
        given.join(" and ")
    )))
}

/// Reading the body from images through the trained NeuroKin: joint angles and encoder drift.
fn run_body_from_image(opts: &RunOptions, dir: &Path) -> Result<String> {
    let why = "its presets set the self-model it reads through";
    reject_model_switches(opts, "body_from_image", why)?;
    let cfg = crate::studies::body_from_image::BodyFromImageConfig::preset(&opts.preset)?;
    crate::studies::body_from_image::run(&cfg, opts, dir)
}

fn run_damage(opts: &RunOptions, dir: &Path) -> Result<String> {
    let why = "its presets set the self-model it reads through";
    reject_model_switches(opts, "damage", why)?;
    let cfg = crate::studies::damage::DamageConfig::preset(&opts.preset)?;
    crate::studies::damage::run(&cfg, opts, dir)
}

fn run_multiview(opts: &RunOptions, dir: &Path) -> Result<String> {
    let why = "its presets set the self-models' training";
    reject_model_switches(opts, "multiview", why)?;
    let cfg = crate::studies::multiview::MultiviewConfig::preset(&opts.preset)?;
    crate::studies::multiview::run(&cfg, opts, dir)
}

fn run_table1(opts: &RunOptions, dir: &Path) -> Result<String> {
    let rows = crate::studies::table1::run(opts, dir, EXPERIMENTS)?;
    Ok(summary(&rows))
}

/// Look an experiment up by name.
pub fn find(name: &str) -> Result<&'static Experiment> {
    EXPERIMENTS.iter().find(|e| e.name == name).ok_or_else(|| {
        selfmodel::Error::Config(format!(
            "no experiment named \"{name}\" (known: {})",
            EXPERIMENTS
                .iter()
                .map(|e| e.name)
                .collect::<Vec<_>>()
                .join(", ")
        ))
    })
}

/// Every experiment, in the order `reproduce` runs them.
pub const EXPERIMENTS: &[Experiment] = &[
    Experiment {
        name: "dataset",
        about: "the papers' 2,000-sample Lorenz dataset of the 4-DOF arm (silhouettes, depth, angles)",
        default_dir: "data",
        presets: &["paper", "quick"],
        in_table1: false,
        takes_robot: false,
        shares_output: false,
        run: run_dataset,
    },
    Experiment {
        name: "mesh_fidelity",
        about: "silhouette IoU of the built-in arm4 against the mesh robot (and PyBullet)",
        default_dir: "reports/mesh_fidelity",
        presets: &["paper", "quick"],
        in_table1: false,
        takes_robot: false,
        shares_output: false,
        run: run_mesh_fidelity,
    },
    Experiment::self_model(
        "neurokin",
        "NeuroKin, the direct joint-angle-to-silhouette decoder (the notebook's architecture)",
        "reports/neurokin",
        run_self_model::<NeuroKinConfig>,
    ),
    Experiment {
        name: "neurokin64",
        about: "NeuroKin-64, the paper text's 64x64 variant (MSE): collapses to an empty image on the clean data, a negative result kept out of Table I",
        default_dir: "reports/neurokin64",
        presets: SELF_MODEL_PRESETS,
        in_table1: false,
        takes_robot: true,
        shares_output: false,
        run: run_neurokin64,
    },
    Experiment {
        name: "neurokin_tree",
        about: "NeuroKin with a kinematic-tree encoder (message passing down the robot's joints, at the flat encoder's parameter count; the paper's Section VI-D4 proposal for robots of many joints)",
        default_dir: "reports/neurokin_tree",
        presets: SELF_MODEL_PRESETS,
        in_table1: false,
        takes_robot: true,
        shares_output: false,
        run: run_neurokin_tree,
    },
    Experiment {
        name: "link_splat",
        about: "LinkSplat: a direct decoder that sees where each link is (anchors on every link placed by forward kinematics, splatted with learned features, decoded by a CNN), for robots of many joints",
        default_dir: "reports/link_splat",
        presets: SELF_MODEL_PRESETS,
        in_table1: false,
        takes_robot: true,
        shares_output: false,
        run: run_self_model::<LinkSplatConfig>,
    },
    Experiment::self_model(
        "resneurokin_d",
        "ResNeuroKin-D: residual decoder with a metric depth head",
        "reports/resneurokin_d",
        run_self_model::<ResNeuroKinDConfig>,
    ),
    Experiment::self_model(
        "nearest_pose",
        "a lookup table: the training images of the nearest training pose (a baseline of Table I)",
        "reports/nearest_pose",
        run_self_model::<selfmodel::self_models::nearest_pose::NearestPose>,
    ),
    Experiment::self_model(
        "mean_silhouette",
        "the best constant image (mean training silhouette): the lower bound of Table I",
        "reports/mean_silhouette",
        run_self_model::<MeanSilhouette>,
    ),
    Experiment {
        name: "ffksm",
        about: "FFKSM, the occupancy-field self-model: both implementations, dense and accelerated ray marching, novel views",
        default_dir: "reports/ffksm",
        presets: SELF_MODEL_PRESETS,
        in_table1: true,
        takes_robot: true,
        shares_output: false,
        run: run_ffksm,
    },
    Experiment {
        name: "k3dgs",
        about: "K-3DGS: Gaussians on the kinematic chain, splatted (culled and dense), two compositing rules",
        default_dir: "reports/k3dgs",
        presets: SELF_MODEL_PRESETS,
        in_table1: true,
        takes_robot: true,
        shares_output: false,
        run: run_k3dgs,
    },
    Experiment {
        name: "ablation_noise",
        about: "NeuroKin ablation: input noise sigma 0 vs 0.01",
        default_dir: "reports/ablation_noise",
        presets: SELF_MODEL_PRESETS,
        in_table1: false,
        takes_robot: true,
        shares_output: false,
        run: run_ablation_noise,
    },
    Experiment {
        name: "ablation_depth",
        about: "NeuroKin ablation: 2, 4 and 6 transposed convolutions",
        default_dir: "reports/ablation_depth",
        presets: SELF_MODEL_PRESETS,
        in_table1: false,
        takes_robot: true,
        shares_output: false,
        run: run_ablation_depth,
    },
    Experiment {
        name: "ablation_latent",
        about: "NeuroKin ablation: latent width 256, 512, 1024, 2048",
        default_dir: "reports/ablation_latent",
        presets: SELF_MODEL_PRESETS,
        in_table1: false,
        takes_robot: true,
        shares_output: false,
        run: run_ablation_latent,
    },
    Experiment {
        name: "ablation_data_scale",
        about: "NeuroKin ablation: 400, 2,000 and 12,000 samples",
        default_dir: "reports/ablation_data_scale",
        presets: SELF_MODEL_PRESETS,
        in_table1: false,
        takes_robot: true,
        shares_output: false,
        run: run_ablation_data_scale,
    },
    Experiment {
        name: "ablation_precision",
        about: "NeuroKin trained in f32, bf16, f16 and flex32 (autocast; those the device computes in)",
        default_dir: "reports/ablation_precision",
        presets: SELF_MODEL_PRESETS,
        in_table1: false,
        takes_robot: true,
        shares_output: false,
        run: run_ablation_precision,
    },
    Experiment {
        name: "emssl_table2",
        about: "EMSSL paper Table II: learned inverse kinematics (EMSSL, DRL, DSL, CGAN) trained to convergence (preset paper-schedule: fixed epochs), a many-solution flow and a numerical solver, two joint ranges (--resume reuses finished methods)",
        default_dir: "reports/emssl_table2",
        presets: TABLE2_PRESETS,
        in_table1: false,
        takes_robot: true,
        shares_output: true,
        run: run_emssl_table2,
    },
    Experiment {
        name: "emssl_seeds",
        about: "Table II settled: EMSSL and DSL over 3 seeds at +-90 deg, DSL at EMSSL's optimiser steps and through the exact forward kinematics (--resume continues)",
        default_dir: "reports/emssl_seeds",
        presets: IK_PRESETS,
        in_table1: false,
        takes_robot: true,
        shares_output: true,
        run: run_emssl_seeds,
    },
    Experiment {
        name: "emssl_learning_curve",
        about: "EMSSL paper Figure 6: EMSSL's test error against iteration (stopping off), two joint ranges",
        default_dir: "reports/emssl_learning_curve",
        presets: IK_PRESETS,
        in_table1: false,
        takes_robot: true,
        shares_output: false,
        run: run_emssl_learning_curve,
    },
    Experiment {
        name: "emssl_study",
        about: "What limits EMSSL: learning-rate schedule, exploration noise, warm start, batch, epochs, data kept, wrapped output; one knob at a time, both ranges (--resume keeps finished rows)",
        default_dir: "reports/emssl_study",
        presets: IK_PRESETS,
        in_table1: false,
        takes_robot: true,
        shares_output: false,
        run: run_emssl_study,
    },
    Experiment {
        name: "emssl_sampling_speed",
        about: "EMSSL paper Table III and Figure 7: the sampling phase under batch inference and a parallel forward model, against the machine's peak",
        default_dir: "reports/emssl_sampling_speed",
        presets: IK_PRESETS,
        in_table1: false,
        takes_robot: true,
        shares_output: false,
        run: run_emssl_sampling_speed,
    },
    Experiment {
        name: "emssl_adaptation",
        about: "EMSSL paper Table IV: fast adaptation to lengthened links (and a bent link) by learned link parameters or the changed arm itself, UR5 and arm4",
        default_dir: "reports/emssl_adaptation",
        presets: IK_PRESETS,
        in_table1: false,
        takes_robot: true,
        shares_output: false,
        run: run_emssl_adaptation,
    },
    Experiment {
        name: "body_from_image",
        about: "the self-model read backwards: joint angles from a silhouette (amortised CNN, refinement through NeuroKin, search) and encoder drift from k images",
        default_dir: "reports/body_from_image",
        presets: &["paper", "quick", "large", "humanoid"],
        in_table1: false,
        takes_robot: true,
        shares_output: false,
        run: run_body_from_image,
    },
    Experiment {
        name: "damage",
        about: "damage to the arm detected, localised and recovered from (a link bent, longer, shorter, part missing; k images through NeuroKin trained on the healthy arm; fine-tuning, replay, EWC and gated experts against a model from scratch)",
        default_dir: "reports/damage",
        presets: &["paper", "quick"],
        in_table1: false,
        takes_robot: true,
        shares_output: false,
        run: run_damage,
    },
    Experiment {
        name: "multiview",
        about: "beyond one camera: NeuroKin camera-conditioned and multi-head on N cameras (tested on cameras never trained on, against FFKSM, K-3DGS and the view-blind bound)",
        default_dir: "reports/multiview",
        presets: &["paper", "quick"],
        in_table1: false,
        takes_robot: true,
        shares_output: false,
        run: run_multiview,
    },
    Experiment {
        name: "table1",
        about: "Table I: every self-model on the same dataset, quality against speed, Pareto plot",
        default_dir: "reports/table1",
        presets: SELF_MODEL_PRESETS,
        in_table1: false,
        takes_robot: true,
        shares_output: false,
        run: run_table1,
    },
];
