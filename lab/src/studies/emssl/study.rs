//! What limits EMSSL: one knob at a time from the schedule Table II ran with at 3bc9f24
//! (learning rate and exploration noise both decaying by 0.9 per iteration from 1.5e-3 and
//! 0.2, a random network, 10 epochs of batch 128 per iteration, each iteration's own pairs
//! only), then combinations. Every setting learns the UR5 in both joint ranges; the model is
//! picked by the reach error on the validation goals (self-supervised), and its test error is
//! what the table reports, beside the lowest test error anywhere on the curve (an oracle, for
//! reference only). Writes `reports/emssl_study/results.csv` (+ Markdown), `curves.csv` and
//! one figure per range.
//!
//! Rows are written as they finish; `--resume` keeps the rows of the same preset and settings
//! already in `results.csv` and runs the rest.
//!
//! The study runs at a smaller scale than Table II (its preset says how many goals) so that
//! every setting fits; Table II runs the chosen setting at the paper's scale.

use std::path::Path;

use selfmodel::core::atomic_file::write_json;
use selfmodel::core::device::DeviceChoice;
use selfmodel::core::error::{Error, Result};
use selfmodel::core::preset::Preset;
use selfmodel::ik::data::{IkData, IkDataConfig, JointOutput};
use selfmodel::ik::learning::FitConfig;
use selfmodel::ik::mlp::InverseModelConfig;
use selfmodel::ik::paper::emssl::{EmsslConfig, LrPlateau, emssl};
use selfmodel::sim::robot::Robot;

/// One setting of the study: what changed from the baseline, and the configs it runs.
#[derive(Clone, Debug, PartialEq, serde::Serialize, serde::Deserialize)]
pub struct Setting {
    pub name: String,
    pub fit: FitConfig,
    pub emssl: EmsslConfig,
    pub output: JointOutput,
    /// Joint ranges this setting runs in (the wrapped output matters at +-180 only).
    pub ranges_deg: Vec<f64>,
}

/// The study's data, network and settings.
#[derive(Clone, Debug, PartialEq, serde::Serialize, serde::Deserialize)]
pub struct StudyConfig {
    pub preset: String,
    pub ranges_deg: Vec<f64>,
    pub data: IkDataConfig,
    pub hidden: Vec<usize>,
    pub settings: Vec<Setting>,
}

/// The settings: the baseline, one knob at a time, then combinations.
pub fn settings(fit: &FitConfig, base: &EmsslConfig, ranges: &[f64]) -> Vec<Setting> {
    let both = ranges.to_vec();
    let wide: Vec<f64> = ranges.iter().copied().filter(|&r| r >= 180.0).collect();
    let s = |name: &str, fit: FitConfig, emssl: EmsslConfig| Setting {
        name: name.into(),
        fit,
        emssl,
        output: JointOutput::Sigmoid,
        ranges_deg: both.clone(),
    };
    let plateau = EmsslConfig {
        learning_rate_decay: 1.0,
        lr_plateau: Some(LrPlateau {
            patience: 2,
            factor: 0.5,
        }),
        ..base.clone()
    };
    let fast_noise = EmsslConfig {
        exploration_decay: 0.8,
        ..base.clone()
    };
    // Noise decay 0.8, the cosine within iterations and a warm start together.
    let cosine_fit = FitConfig {
        cosine: true,
        ..fit.clone()
    };
    let combination = EmsslConfig {
        warm_start_epochs: 10,
        ..fast_noise.clone()
    };
    vec![
        s("baseline (3bc9f24)", fit.clone(), base.clone()),
        s("noise decay 0.8", fit.clone(), fast_noise.clone()),
        s(
            "learning rate annealed (cosine) within each iteration",
            FitConfig {
                cosine: true,
                ..fit.clone()
            },
            base.clone(),
        ),
        s(
            "learning rate halved on plateaus",
            fit.clone(),
            plateau.clone(),
        ),
        s(
            "warm start: 10 epochs of motor babbling",
            fit.clone(),
            EmsslConfig {
                warm_start_epochs: 10,
                ..base.clone()
            },
        ),
        s(
            "noise decay 0.8 + cosine within iterations + warm start",
            cosine_fit.clone(),
            combination.clone(),
        ),
        s(
            "noise decay 0.8 + 3 polishing rounds to convergence",
            fit.clone(),
            EmsslConfig {
                polish_rounds: 3,
                ..fast_noise.clone()
            },
        ),
        s(
            "noise decay 0.8 + cosine within iterations + warm start + 3 polishing rounds",
            cosine_fit.clone(),
            EmsslConfig {
                polish_rounds: 3,
                ..combination.clone()
            },
        ),
        Setting {
            output: JointOutput::Wrapped,
            ranges_deg: wide,
            ..s("wrapped output (cos, sin)", fit.clone(), base.clone())
        },
        s(
            "learning rate constant",
            fit.clone(),
            EmsslConfig {
                learning_rate_decay: 1.0,
                ..base.clone()
            },
        ),
        s(
            "noise floor 0.01",
            fit.clone(),
            EmsslConfig {
                exploration_floor: 0.01,
                ..base.clone()
            },
        ),
        s(
            "batch 512",
            FitConfig {
                batch: 512,
                ..fit.clone()
            },
            base.clone(),
        ),
        s(
            "3 epochs per iteration",
            FitConfig {
                epochs: 3,
                ..fit.clone()
            },
            base.clone(),
        ),
        s(
            "pairs of the last 2 iterations",
            fit.clone(),
            EmsslConfig {
                keep_iterations: 2,
                ..base.clone()
            },
        ),
    ]
}

impl Preset for StudyConfig {
    /// 22,000 goals (2,000 of them for validation), 30,000 test targets, the paper's network,
    /// up to 40 iterations, patience 8.
    fn paper() -> Self {
        let ranges = vec![90.0, 180.0];
        let base = EmsslConfig {
            max_iterations: 40,
            patience: 8,
            ..EmsslConfig::paper()
        };
        StudyConfig {
            preset: "paper".into(),
            ranges_deg: ranges.clone(),
            data: IkDataConfig {
                samples: 52_000,
                train: 22_000,
                range_deg: 0.0,
                seed: 0,
                validation: 2_000,
            },
            hidden: vec![1024, 512, 256, 128],
            settings: settings(&FitConfig::paper(), &base, &ranges),
        }
    }

    /// 2,500 goals, a small network, a few iterations: seconds.
    fn quick() -> Self {
        let ranges = vec![90.0, 180.0];
        let base = EmsslConfig {
            max_iterations: 4,
            patience: 3,
            ..EmsslConfig::paper()
        };
        let fit = FitConfig {
            epochs: 2,
            batch: 64,
            ..FitConfig::paper()
        };
        let mut settings = settings(&fit, &base, &ranges);
        settings.truncate(3);
        StudyConfig {
            preset: "quick".into(),
            ranges_deg: ranges,
            data: IkDataConfig {
                samples: 3_000,
                train: 2_500,
                range_deg: 0.0,
                seed: 0,
                validation: 300,
            },
            hidden: vec![64, 32],
            settings,
        }
    }
}

/// One setting in one range.
#[derive(Clone, Debug, serde::Serialize, serde::Deserialize)]
pub struct StudyRow {
    pub setting: String,
    pub range_deg: f64,
    /// Test mean (cm) of the model the validation goals picked.
    pub test_mean_cm: f64,
    pub test_median_cm: f64,
    /// The iteration that model came from, and how many ran.
    pub iteration: usize,
    pub iterations_run: usize,
    /// The lowest test mean anywhere on the curve (an oracle, for reference).
    pub lowest_test_mean_cm: f64,
    pub seconds: f64,
    pub git_revision: String,
    pub device: String,
    pub preset: String,
}

/// One iteration of one setting, for `curves.csv`.
#[derive(Clone, Debug, serde::Serialize, serde::Deserialize)]
pub struct StudyCurveRow {
    pub setting: String,
    pub range_deg: f64,
    pub iteration: usize,
    pub learning_rate: f64,
    pub exploration: f64,
    pub validation_reach_cm: f64,
    pub test_mean_cm: f64,
}

/// Run every setting in every range (keeping finished rows when `resume`), writing the tables
/// and figures after each.
pub fn run(
    cfg: &StudyConfig,
    robot: &Robot,
    dir: &Path,
    device_choice: DeviceChoice,
    resume: bool,
) -> Result<String> {
    std::fs::create_dir_all(dir).map_err(|e| Error::io(dir, e))?;
    let results = dir.join("results.csv");
    let curves_path = dir.join("curves.csv");
    let (mut rows, mut curves): (Vec<StudyRow>, Vec<StudyCurveRow>) = if resume
        && results.exists()
        && curves_path.exists()
    {
        let old: StudyConfig = serde_json::from_str(
            &std::fs::read_to_string(dir.join("config.json"))
                .map_err(|e| Error::io(dir.join("config.json"), e))?,
        )
        .map_err(|e| Error::data(dir.join("config.json"), e.to_string()))?;
        if old.preset != cfg.preset || old.data != cfg.data || old.hidden != cfg.hidden {
            return Err(Error::Config(format!(
                "{} holds a study of other data or another network; drop --resume or choose another --out",
                dir.display()
            )));
        }
        // Keep only rows whose setting is unchanged.
        let same = |name: &str| {
            old.settings.iter().find(|s| s.name == name)
                == cfg.settings.iter().find(|s| s.name == name)
        };
        (
            selfmodel::report::table::read_csv::<StudyRow>(&results)?
                .into_iter()
                .filter(|r| same(&r.setting))
                .collect(),
            selfmodel::report::table::read_csv::<StudyCurveRow>(&curves_path)?
                .into_iter()
                .filter(|r| same(&r.setting))
                .collect(),
        )
    } else {
        (Vec::new(), Vec::new())
    };
    write_json(&dir.join("config.json"), cfg)?;
    let device = selfmodel::core::device::select(device_choice)?;
    let data: Vec<IkData> = cfg
        .ranges_deg
        .iter()
        .map(|&r| {
            IkData::generate(
                &robot.chain,
                &IkDataConfig {
                    range_deg: r,
                    ..cfg.data.clone()
                },
            )
        })
        .collect::<Result<_>>()?;
    // Setting by setting (both ranges of a setting before the next), so an interrupted study
    // has whole settings.
    for s in &cfg.settings {
        for (&range, data) in cfg.ranges_deg.iter().zip(&data) {
            if !s.ranges_deg.contains(&range) {
                continue;
            }
            if rows
                .iter()
                .any(|r| r.setting == s.name && r.range_deg == range)
            {
                continue;
            }
            eprintln!("emssl_study: +-{range:.0} deg, {}", s.name);
            let model = InverseModelConfig::inverse(cfg.hidden.clone(), robot.dof(), s.output);
            let t = std::time::Instant::now();
            let (_, curve) = emssl(&robot.chain, data, &model, &s.fit, &s.emssl, &device, None)?;
            let seconds = t.elapsed().as_secs_f64();
            let picked = curve
                .iter()
                .min_by(|a, b| a.selection_cm().total_cmp(&b.selection_cm()))
                .ok_or_else(|| Error::Training("EMSSL ran no iteration".into()))?;
            rows.retain(|r| !(r.setting == s.name && r.range_deg == range));
            rows.push(StudyRow {
                setting: s.name.clone(),
                range_deg: range,
                test_mean_cm: picked.test.mean_cm,
                test_median_cm: picked.test.median_cm,
                iteration: picked.iteration,
                iterations_run: curve.len(),
                lowest_test_mean_cm: curve
                    .iter()
                    .map(|c| c.test.mean_cm)
                    .fold(f64::INFINITY, f64::min),
                seconds,
                git_revision: selfmodel::core::provenance::git_revision(),
                device: device_choice.to_string(),
                preset: cfg.preset.clone(),
            });
            curves.retain(|r| !(r.setting == s.name && r.range_deg == range));
            curves.extend(curve.iter().map(|c| StudyCurveRow {
                setting: s.name.clone(),
                range_deg: range,
                iteration: c.iteration,
                learning_rate: c.learning_rate,
                exploration: c.exploration,
                validation_reach_cm: c.selection_cm(),
                test_mean_cm: c.test.mean_cm,
            }));
            write_outputs(cfg, dir, &rows, &curves)?;
        }
    }
    write_outputs(cfg, dir, &rows, &curves)?;
    Ok(rows
        .iter()
        .map(|r| {
            format!(
                "+-{:.0} {}: {:.2} cm (iteration {})",
                r.range_deg, r.setting, r.test_mean_cm, r.iteration
            )
        })
        .collect::<Vec<_>>()
        .join("; "))
}

/// The tables and one figure per range (test error against iteration, a line per setting).
fn write_outputs(
    cfg: &StudyConfig,
    dir: &Path,
    rows: &[StudyRow],
    curves: &[StudyCurveRow],
) -> Result<()> {
    // Rows in the order of the settings, range by range.
    let mut ordered: Vec<StudyRow> = Vec::new();
    for &range in &cfg.ranges_deg {
        for s in &cfg.settings {
            ordered.extend(
                rows.iter()
                    .filter(|r| r.setting == s.name && r.range_deg == range)
                    .cloned(),
            );
        }
    }
    let d = &cfg.data;
    selfmodel::report::table::write_table(
        &dir.join("results.csv"),
        &ordered,
        "EMSSL study: what limits it (UR5, one knob at a time, then combinations)",
        &format!(
            "{} goals ({} of them held out for validation), {} test targets. `test_mean_cm`: the test error of the model the validation goals picked (self-supervised: goals and the forward model only); `lowest_test_mean_cm`: the lowest test error on the whole curve (an oracle, for reference). `baseline (3bc9f24)` is the schedule Table II ran before this study: learning rate 1.5e-3 and exploration noise 0.2, both multiplied by 0.9 per iteration, a random network, 10 epochs of batch 128 per iteration on that iteration's own pairs. Each other row changes what its name says. Generated by `cargo run --release --bin emssl_study`.",
            d.train,
            d.validation,
            d.samples - d.train
        ),
    )?;
    selfmodel::report::table::write_csv(&dir.join("curves.csv"), curves)?;
    draw_figures(dir)
}

/// The study's figures from `curves.csv` in `dir`: `curves_<range>.png`, one line per setting
/// (in the order the CSV first names them).
pub fn draw_figures(dir: &Path) -> Result<()> {
    let curves: Vec<StudyCurveRow> = selfmodel::report::table::read_csv(&dir.join("curves.csv"))?;
    let mut ranges: Vec<f64> = Vec::new();
    let mut settings: Vec<String> = Vec::new();
    for c in &curves {
        if !ranges.contains(&c.range_deg) {
            ranges.push(c.range_deg);
        }
        if !settings.contains(&c.setting) {
            settings.push(c.setting.clone());
        }
    }
    for range in ranges {
        let runs: Vec<(String, Vec<(usize, f64)>)> = settings
            .iter()
            .filter_map(|s| {
                let c: Vec<(usize, f64)> = curves
                    .iter()
                    .filter(|c| &c.setting == s && c.range_deg == range)
                    .map(|c| (c.iteration, c.test_mean_cm))
                    .collect();
                (!c.is_empty()).then(|| (s.clone(), c))
            })
            .collect();
        selfmodel::report::figures::curves(
            &dir.join(format!("curves_{range:.0}.png")),
            &format!("EMSSL study, UR5 +-{range:.0} deg: test error per iteration"),
            "EMSSL iteration",
            "test distance error (cm, log)",
            &runs,
        )?;
    }
    Ok(())
}
