//! Table I's Pareto plot from its rows: each row's test PSNR against its batch-1 inference
//! speed, the paper's figures beside them as references, and the lower bounds as lines.

use selfmodel::self_models::result::ModelResult;

/// The points of a Pareto plot: each row's test PSNR against its batch-1 inference speed, and
/// beside it the paper's figures for that row (as references) where the paper printed them.
pub fn pareto_points(
    rows: &[ModelResult],
    label: impl Fn(&str) -> String,
) -> Vec<selfmodel::report::figures::ParetoPoint> {
    use selfmodel::report::figures::ParetoPoint;
    let ours = rows.iter().filter(|r| !r.lower_bound).map(|r| ParetoPoint {
        label: label(&r.model),
        fps: r.infer_b1_img_per_s,
        quality: r.psnr_db_test,
        reference: false,
    });
    // One point per paper figure, however many of our rows it stands beside, named by what
    // those rows' names share ("FFKSM (dense marching)", "FFKSM (accelerated)": "FFKSM").
    let mut paper: Vec<(f64, f64, Vec<String>)> = Vec::new();
    for r in rows {
        let (Some(fps), Some(q)) = (r.paper_fps, r.paper_psnr_db) else {
            continue;
        };
        match paper.iter_mut().find(|p| p.0 == fps && p.1 == q) {
            Some(p) => p.2.push(label(&r.model)),
            None => paper.push((fps, q, vec![label(&r.model)])),
        }
    }
    let paper = paper.into_iter().map(|(fps, quality, names)| ParetoPoint {
        label: format!("paper: {}", common_name(&names)),
        fps,
        quality,
        reference: true,
    });
    ours.chain(paper).collect()
}

/// What `names` share: their common prefix, cut back to a whole word and stripped of an
/// opened parenthesis ("K-3DGS (isotropic)", "K-3DGS (anisotropic, alpha)": "K-3DGS").
fn common_name(names: &[String]) -> String {
    let first = names.first().map(String::as_str).unwrap_or("");
    let mut n = first.len();
    for other in names {
        n = n.min(
            first
                .chars()
                .zip(other.chars())
                .take_while(|(a, b)| a == b)
                .count(),
        );
    }
    let mut prefix: String = first.chars().take(n).collect();
    if n < first.chars().count() {
        // Cut back to the last whole word.
        let cut = prefix.rfind([' ', '(']).unwrap_or(prefix.len());
        prefix.truncate(cut);
    }
    let trimmed = prefix.trim_end_matches([' ', '(', ',']).trim();
    if trimmed.is_empty() {
        first.to_string()
    } else {
        trimmed.to_string()
    }
}

/// The lower bounds among `rows` (label, test PSNR), for [`selfmodel::report::figures::pareto_plot`].
pub fn pareto_floors(rows: &[ModelResult]) -> Vec<(String, f64)> {
    rows.iter()
        .filter(|r| r.lower_bound)
        .map(|r| {
            (
                format!("{}: the best constant image", r.model),
                r.psnr_db_test,
            )
        })
        .collect()
}
