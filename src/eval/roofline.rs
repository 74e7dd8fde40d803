//! Each kernel of a training step against what the GPU could do (the GPU check's `roofline`):
//! its time from cubecl's profile (`CUBECL_DEBUG_OPTION=profile`), the bytes and flops of the
//! fusion block it ran for (`eval::device_counts::block_work`, kept per launch in the check's
//! `launches.csv`), and the bound of those at the bandwidth and the matrix-product rate the check
//! measured on the same GPU (`peak.csv`): `ratio = time / bound`, 1 at the hardware's limit.
//!
//! The profile lists every launch of the process in order; the step's launches (from the
//! launch log) are found in it as the last run of kernels with the same names.

use std::path::Path;

use crate::core::error::{Error, Result};

/// One launch of a step, in order, as the GPU check's counts part writes it (`launches.csv`).
#[derive(Clone, Debug, PartialEq, serde::Serialize, serde::Deserialize)]
pub struct StepLaunch {
    pub batch: usize,
    pub index: usize,
    pub kernel: String,
    pub operations: String,
    pub workgroups: Option<u64>,
    pub elements: Option<u64>,
    /// The fusion block it ran for; empty outside one.
    pub block: Option<u64>,
    /// The block's bytes and flops (shared by its launches).
    pub block_bytes: u64,
    pub block_flops: u64,
}

/// What the GPU measured it can do.
#[derive(Clone, Copy, Debug, PartialEq, serde::Serialize, serde::Deserialize)]
pub struct Peak {
    /// An elementwise pass over a large tensor (read and write), GB/s.
    pub gbytes_per_s: f64,
    /// A large f32 matrix product, GFLOP/s.
    pub gflops: f64,
}

/// One fusion block of the step (a launch where it ran outside one): a row of `kernels.csv`.
#[derive(Clone, Debug, PartialEq, serde::Serialize)]
pub struct KernelRow {
    /// Its kernels' names, in order.
    pub kernels: String,
    pub operations: String,
    pub launches: usize,
    pub time_us: f64,
    pub bytes: u64,
    pub flops: u64,
    /// `max(bytes / bandwidth, flops / rate)`.
    pub bound_us: f64,
    /// `memory` or `compute`: which of the two sets the bound.
    pub bound_by: String,
    /// `time / bound`: 1 at the hardware's limit.
    pub ratio: f64,
}

/// A kernel's name without its hash and type parameters, as both the profile and the launch
/// log can be compared by: `ElemwiseFuse_e82051e4` -> `ElemwiseFuse`,
/// `KernelBinop<AddOp>` -> `KernelBinop`.
pub fn plain_name(name: &str) -> &str {
    let name = name.split('<').next().unwrap_or(name).trim();
    match name.rsplit_once('_') {
        Some((head, hash)) if hash.len() == 8 && hash.chars().all(|c| c.is_ascii_hexdigit()) => {
            head
        }
        _ => name,
    }
}

/// Microseconds of a profile duration (`9.216µs`, `1.2ms`, `850ns`, `1.5s`).
fn micros(text: &str) -> Option<f64> {
    let text = text.trim();
    let (number, unit) = text.split_at(text.find(|c: char| c.is_alphabetic() || c == 'µ')?);
    let v: f64 = number.parse().ok()?;
    let scale = match unit {
        "ns" => 1e-3,
        "µs" | "us" => 1.0,
        "ms" => 1e3,
        "s" => 1e6,
        _ => return None,
    };
    Some(v * scale)
}

/// The launches of a cubecl profile in order: `(name, µs)` from its lines `| 9.216µs | Name |
/// ...` (the summary tables, whose lines begin with a name, are skipped).
pub fn profile_launches(text: &str) -> Vec<(String, f64)> {
    text.lines()
        .filter_map(|line| {
            let mut fields = line.strip_prefix('|')?.split('|');
            let us = micros(fields.next()?)?;
            let name = fields.next()?.trim();
            Some((plain_name(name).to_string(), us))
        })
        .collect()
}

/// Where `step` (kernel names in order) ran last in `profile`: the start of the last window
/// whose names all match, else of the window that matches most (at least 90%).
pub fn align(profile: &[(String, f64)], step: &[&str]) -> Option<usize> {
    let n = step.len();
    if n == 0 || profile.len() < n {
        return None;
    }
    let score = |start: usize| {
        step.iter()
            .zip(&profile[start..start + n])
            .filter(|(a, b)| plain_name(a) == b.0)
            .count()
    };
    let mut best = (0, None);
    for start in (0..=profile.len() - n).rev() {
        let s = score(start);
        if s == n {
            return Some(start);
        }
        if s > best.0 {
            best = (s, Some(start));
        }
    }
    (best.0 * 10 >= n * 9).then_some(best.1).flatten()
}

/// The roofline of `step`'s launches timed by `profile` (aligned by [`align`]) at `peak`: a
/// row a block, slowest first.
pub fn rows(profile: &[(String, f64)], step: &[StepLaunch], peak: Peak) -> Result<Vec<KernelRow>> {
    let names: Vec<&str> = step.iter().map(|l| l.kernel.as_str()).collect();
    let start = align(profile, &names).ok_or_else(|| {
        Error::Config(format!(
            "the step's {} launches are not in the profile's {} (its kernels' names differ)",
            step.len(),
            profile.len()
        ))
    })?;
    let times = &profile[start..start + step.len()];
    let mut rows: Vec<KernelRow> = Vec::new();
    let mut last_block = None;
    for (launch, (_, us)) in step.iter().zip(times) {
        let same = launch.block.is_some() && launch.block == last_block;
        last_block = launch.block;
        if same && let Some(row) = rows.last_mut() {
            row.kernels = format!("{}+{}", row.kernels, plain_name(&launch.kernel));
            row.launches += 1;
            row.time_us += us;
            continue;
        }
        rows.push(KernelRow {
            kernels: plain_name(&launch.kernel).to_string(),
            operations: launch.operations.clone(),
            launches: 1,
            time_us: *us,
            bytes: launch.block_bytes,
            flops: launch.block_flops,
            bound_us: 0.0,
            bound_by: String::new(),
            ratio: 0.0,
        });
    }
    for row in &mut rows {
        let memory = row.bytes as f64 / (peak.gbytes_per_s * 1e3);
        let compute = row.flops as f64 / (peak.gflops * 1e3);
        row.bound_us = memory.max(compute);
        row.bound_by = if compute > memory {
            "compute"
        } else {
            "memory"
        }
        .into();
        row.ratio = if row.bound_us > 0.0 {
            row.time_us / row.bound_us
        } else {
            f64::INFINITY
        };
    }
    rows.sort_by(|a, b| b.time_us.total_cmp(&a.time_us));
    Ok(rows)
}

/// The profile at `path` (cubecl's log, or the check's `profile.txt`).
pub fn read_profile(path: &Path) -> Result<Vec<(String, f64)>> {
    let text = std::fs::read_to_string(path).map_err(|e| Error::io(path, e))?;
    Ok(profile_launches(&text))
}

#[cfg(test)]
mod tests {
    use super::*;

    fn launch(kernel: &str, block: Option<u64>, bytes: u64, flops: u64) -> StepLaunch {
        StepLaunch {
            batch: 256,
            index: 0,
            kernel: kernel.into(),
            operations: "?".into(),
            workgroups: Some(1),
            elements: None,
            block,
            block_bytes: bytes,
            block_flops: flops,
        }
    }

    #[test]
    fn a_profile_is_read_launch_by_launch() {
        let text = "| 9.216µs | PrngKernel | NormalFamily_54b1b449\n\
                    | Name | Duration | Num Computed | Ratio |\n\
                    | PrngKernel | NormalFamily_54b1b449 | 9.216µs | 1 | 27 % |\n\
                    | 1.5ms | ElemwiseFuse_e82051e4\n\
                    | 850ns | KernelBinop | AddOp_3ca751bf\n";
        let p = profile_launches(text);
        assert_eq!(
            p,
            vec![
                ("PrngKernel".to_string(), 9.216),
                ("ElemwiseFuse".to_string(), 1500.0),
                ("KernelBinop".to_string(), 0.85)
            ]
        );
        assert_eq!(plain_name("KernelBinop<AddOp>"), "KernelBinop");
        assert_eq!(plain_name("Col2im"), "Col2im");
    }

    #[test]
    fn the_step_is_found_as_the_last_run_of_its_kernels() {
        let p: Vec<(String, f64)> = ["A", "B", "C", "A", "B", "C", "D"]
            .iter()
            .enumerate()
            .map(|(i, n)| (n.to_string(), i as f64))
            .collect();
        assert_eq!(align(&p, &["A", "B", "C"]), Some(3));
        assert_eq!(align(&p, &["C", "D"]), Some(5));
        assert_eq!(align(&p, &["X", "Y"]), None);
    }

    #[test]
    fn a_block_is_bound_by_its_bytes_or_its_flops() {
        let profile = vec![
            ("MatmulEntry".to_string(), 20.0),
            ("ElemwiseFuse".to_string(), 5.0),
            ("PartialSums".to_string(), 3.0),
            ("FinishSums".to_string(), 2.0),
        ];
        let step = vec![
            launch("MatmulEntry", Some(1), 1_000_000, 2_000_000_000),
            launch("ElemwiseFuse", Some(2), 4_000_000, 0),
            launch("PartialSums", Some(3), 8_000_000, 0),
            launch("FinishSums", Some(3), 8_000_000, 0),
        ];
        let peak = Peak {
            gbytes_per_s: 4000.0,
            gflops: 400_000.0,
        };
        let rows = rows(&profile, &step, peak).unwrap();
        assert_eq!(rows.len(), 3);
        // 2 GFLOP at 400 TFLOP/s: 5 µs, against 20 µs.
        assert_eq!(rows[0].kernels, "MatmulEntry");
        assert_eq!(rows[0].bound_by, "compute");
        assert!((rows[0].ratio - 4.0).abs() < 1e-9);
        // A block of two launches: 8 MB at 4 TB/s is 2 µs, against 3 + 2.
        let sums = rows.iter().find(|r| r.launches == 2).unwrap();
        assert_eq!(sums.kernels, "PartialSums+FinishSums");
        assert!((sums.ratio - 2.5).abs() < 1e-9);
        assert_eq!(sums.bound_by, "memory");
    }
}
