//! Table II's rows and tables: a method's row, the ratios to DRL, the compact `table2.md`
//! beside the paper's numbers (with the tail and, where `emssl_seeds` ran, the seed spread).

use std::path::{Path, PathBuf};

use selfmodel::core::error::{Error, Result};

use super::{
    config::IkComparisonConfig,
    predictions::{answers_file, read_reached},
};

/// One method in one joint range: a row of Table II.
#[derive(Clone, Debug, serde::Serialize, serde::Deserialize)]
pub struct IkRow {
    pub robot: String,
    pub range_deg: f64,
    pub method: String,
    pub mean_cm: f64,
    pub median_cm: f64,
    pub p95_cm: f64,
    pub max_cm: f64,
    /// Share of targets (%) more than 10 cm off; empty on rows from runs before it was
    /// counted.
    #[serde(default)]
    pub above_10cm_pct: Option<f64>,
    pub targets: usize,
    /// Mean error over DRL's (the sigmoid DRL of the same range and run).
    pub ratio_to_drl: Option<f64>,
    /// Share of targets within 0.01 mm (the solver's rows and every row, for comparison).
    pub within_0_01mm_pct: f64,
    /// Answers with a joint outside its range (the robot's limits, narrowed to the range):
    /// 0 is the goal. Empty in rows from before it was counted.
    #[serde(default)]
    pub outside_limits: Option<usize>,
    /// Mean distance (rad) between two of a target's k answers (the many-solution rows).
    pub diversity_rad: Option<f64>,
    /// Test targets answered per second, trained model given.
    pub solutions_per_s: f64,
    pub train_seconds: f64,
    /// Epochs (EMSSL: iterations) trained, where it applies.
    pub epochs: Option<usize>,
    /// The validation error (cm) of the kept model, where it trained to convergence.
    pub validation_cm: Option<f64>,
    /// Method-specific facts: how it stopped, the solver's convergence, the forward model's error.
    pub detail: String,
    /// The paper's Table II, for reference (its arm is unnamed; ours is `robot`).
    pub paper_mean_cm: Option<f64>,
    pub paper_ratio_to_drl: Option<f64>,
    pub git_revision: String,
    pub device: String,
    pub preset: String,
}

/// The paper's Table II mean errors (cm) of a method (its name without our suffixes).
pub(super) fn paper_reference(method: &str, range_deg: f64) -> Option<f64> {
    let column = match range_deg {
        r if r == 90.0 => 0,
        r if r == 180.0 => 1,
        _ => return None,
    };
    let values = match method {
        "EMSSL" => [0.28, 1.78],
        "DSL" => [0.39, 2.37],
        "CGAN" => [0.48, 2.57],
        "DRL" => [2.34, 31.69],
        _ => return None,
    };
    Some(values[column])
}

/// Every row's ratio to the sigmoid DRL of its range (where that row exists).
pub(super) fn set_ratios(rows: &mut [IkRow]) {
    let drl: Vec<(f64, f64)> = rows
        .iter()
        .filter(|r| r.method == "DRL")
        .map(|r| (r.range_deg, r.mean_cm))
        .collect();
    for r in rows.iter_mut() {
        r.ratio_to_drl = drl
            .iter()
            .find(|d| d.0 == r.range_deg)
            .map(|d| r.mean_cm / d.1);
    }
}

/// `table2.md`: the rows a reader compares, ours beside the paper's.
pub(super) fn write_table2(dir: &Path, cfg: &IkComparisonConfig, rows: &[IkRow]) -> Result<()> {
    selfmodel::core::atomic_file::write_bytes(
        &dir.join("table2.md"),
        table2_text(dir, cfg, rows)?.as_bytes(),
    )
}

/// `table2.md` as the rows of `dir/results.csv` and the run's `dir/config.json` make it
/// (`None` where either is missing): `reports` regenerates it, so the table follows the CSV.
pub fn table2_markdown(dir: &Path) -> Result<Option<String>> {
    let (config, results) = (dir.join("config.json"), dir.join("results.csv"));
    if !config.is_file() || !results.is_file() {
        return Ok(None);
    }
    let text = std::fs::read_to_string(&config).map_err(|e| Error::io(&config, e))?;
    let cfg: IkComparisonConfig = serde_json::from_str(&text)
        .map_err(|e| Error::data(&config, format!("not a Table II config: {e}")))?;
    let rows: Vec<IkRow> = selfmodel::report::table::read_csv(&results)?;
    Ok(Some(table2_text(dir, &cfg, &rows)?))
}

/// The columns of `emssl_seeds`' `summary.csv` Table II reads (that study builds on this one,
/// so the file, not its type, is what they share).
#[derive(serde::Deserialize)]
pub(super) struct SeedSpread {
    method: String,
    range: f64,
    seeds: usize,
    spread_pct: f64,
    robot: String,
    preset: String,
}

/// Where `emssl_seeds` writes its summary, beside Table II's folder (`reports/emssl_seeds`).
pub(super) fn seeds_summary(dir: &Path) -> Option<PathBuf> {
    let path = dir.parent()?.join("emssl_seeds").join("summary.csv");
    path.is_file().then_some(path)
}

/// The share of targets more than 10 cm off, for a row from before the share was recorded:
/// from its answers in this checkout (`Some((share %, answers, from the sample))`).
pub(super) fn tail_from_answers(dir: &Path, r: &IkRow) -> Result<Option<(f64, usize, bool)>> {
    let Some((path, sample)) = answers_file(dir, r.range_deg, &r.method) else {
        return Ok(None);
    };
    let pairs = read_reached(&path)?;
    let above = pairs.iter().filter(|(t, q)| (t - q).norm() > 0.1).count();
    Ok(Some((
        100.0 * above as f64 / pairs.len().max(1) as f64,
        pairs.len(),
        sample,
    )))
}

/// The compact Table II: ours beside the paper's, absolute and as ratios to DRL, with the
/// tail (95th percentile, share above 10 cm) and, where `emssl_seeds` has run beside it on
/// the same robot, range and preset, the seed spread of its methods; partial until every range
/// has its last unit (EMSSL + DLS).
pub(super) fn table2_text(dir: &Path, cfg: &IkComparisonConfig, rows: &[IkRow]) -> Result<String> {
    let partial = !cfg.ranges_deg.iter().all(|&r| {
        rows.iter()
            .any(|x| x.range_deg == r && x.method == "EMSSL + DLS")
    });
    let seeds: Vec<SeedSpread> = match seeds_summary(dir) {
        Some(p) => selfmodel::report::table::read_csv(&p)?,
        None => Vec::new(),
    };
    let opt =
        |v: Option<f64>, digits: usize| v.map_or("-".to_string(), |x| format!("{x:.digits$}"));
    let mut text = format!(
        "# Table II ({} preset{}): mean distance error on {} test targets\n\nGenerated from `results.csv` (by `emssl_table2`, and by `reports` from the CSV); do not edit by hand. Ratio: the mean over the sigmoid DRL's of the same range (the paper's arm is unnamed, so its absolute numbers are for another arm: absolute centimetres scale with the arm's size, ratios compare). Ours / paper: our mean over the paper's (above 1: our error is larger). p95: the 95th percentile of the error; > 10 cm: the share of targets more than 10 cm off{}. Seed sd: the standard deviation of the mean over seeds as a share of it (`reports/emssl_seeds`, its own protocol; the number of seeds in brackets), where that study has run. Epochs: DRL, DSL (inverse), CGAN and the flow stop on a {}-target validation split when `converge` is set; EMSSL counts iterations.\n\n| range | method | ours mean cm | median cm | p95 cm | > 10 cm | seed sd | ratio to DRL | paper mean cm | paper ratio | ours / paper | within 0.01 mm | outside limits | answers/s | epochs | train s |\n|---|---|---|---|---|---|---|---|---|---|---|---|---|---|---|---|\n",
        cfg.preset,
        if partial {
            ", partial: the run has not finished"
        } else {
            ""
        },
        cfg.samples - cfg.train,
        if rows.iter().any(|r| r.above_10cm_pct.is_none()) {
            " (marked ~: a row from before the share was recorded, counted on the first answers committed under `predictions_sample/`, their number in brackets)"
        } else {
            ""
        },
        cfg.validation
    );
    for r in rows {
        let above = match r.above_10cm_pct {
            Some(v) => format!("{v:.2}%"),
            None => match tail_from_answers(dir, r)? {
                Some((v, n, true)) => format!("~{v:.1}% ({n})"),
                Some((v, _, false)) => format!("{v:.2}%"),
                None => "-".into(),
            },
        };
        let spread = seeds
            .iter()
            .find(|s| {
                s.method == r.method.to_lowercase()
                    && s.range == r.range_deg
                    && s.robot == r.robot
                    && s.preset == r.preset
                    && s.seeds > 1
            })
            .map_or("-".into(), |s| {
                format!("{:.1}% ({})", s.spread_pct, s.seeds)
            });
        text += &format!(
            "| +-{:.0} | {} | {:.3} | {:.3} | {:.2} | {} | {} | {} | {} | {} | {} | {:.2}% | {} | {:.0} | {} | {:.0} |\n",
            r.range_deg,
            r.method,
            r.mean_cm,
            r.median_cm,
            r.p95_cm,
            above,
            spread,
            opt(r.ratio_to_drl, 3),
            opt(r.paper_mean_cm, 2),
            opt(r.paper_ratio_to_drl, 3),
            r.paper_mean_cm
                .map_or("-".into(), |p| format!("{:.2}x", r.mean_cm / p)),
            r.within_0_01mm_pct,
            r.outside_limits.map_or("-".into(), |n| n.to_string()),
            r.solutions_per_s,
            r.epochs.map_or("-".into(), |e| e.to_string()),
            r.train_seconds
        );
    }
    Ok(text)
}
