//! Table III and Figure 7 of the EMSSL paper (section IV-B): how long one EMSSL sampling pass
//! takes over the desired training positions (70,000 in the paper) under the four strategies
//! of [`selfmodel::ik::paper::sampling_pass`], and against the inference batch size (Figure 7a) and the
//! forward model's thread count (Figure 7b).
//!
//! Every time is the median of `repeats` full passes over the same targets after a warm-up
//! pass. The inverse model is the paper's network, freshly initialised: the time of a pass
//! does not depend on the weights. The forward model is the arm's kinematics with each
//! latency of the config ([`Latency`]); the paper's forward model (its 61.40 s and 57.84 s
//! differ by the 3.6 s the parallel forward model saved on 6 cores, about 50 us a call) is
//! what the 50 us latencies stand for.
//!
//! Beyond the paper: the arithmetic rate of the inference half (the inverse model's matrix
//! products, 2 FLOP per multiply-add) against the machine's peak ([`selfmodel::eval::compute_peak`]).

use std::path::Path;

use nalgebra::Point3;

use selfmodel::core::atomic_file::write_json;
use selfmodel::core::device::DeviceChoice;
use selfmodel::core::error::{Error, Result};
use selfmodel::core::preset::Preset;
use selfmodel::eval::compute_peak::{CpuPeak, matmul_gflops};
use selfmodel::ik::data::{IkData, IkDataConfig};
use selfmodel::ik::mlp::{InverseModelConfig, Mlp};
use selfmodel::ik::paper::sampling_pass::{
    ForwardModel, Latency, SamplingPass, Strategy, Workers, sampling_pass,
};
use selfmodel::sim::robot::Robot;

/// Everything the timing run depends on.
#[derive(Clone, Debug, PartialEq, serde::Serialize, serde::Deserialize)]
pub struct SamplingSpeedConfig {
    pub preset: String,
    /// The desired positions are the training positions of the IK data in this joint range.
    pub data: IkDataConfig,
    /// Hidden widths of the inverse model (3 -> hidden -> dof).
    pub hidden: Vec<usize>,
    /// The batch of the batch-inference strategies (the paper's 512).
    pub inference_batch: usize,
    /// Forward-model workers of the parallel strategies; 0: every core.
    pub threads: usize,
    /// Figure 7(a): inference batch sizes, forward model on `threads` workers.
    pub batch_sweep: Vec<usize>,
    /// Figure 7(b): forward-model workers at `inference_batch`; empty: 1 to twice the cores.
    pub thread_sweep: Vec<usize>,
    /// Each measurement is taken once per latency.
    pub latencies: Vec<Latency>,
    /// Timed full passes per measurement (the median is reported) ...
    pub repeats: usize,
    /// ... after one warm-up pass over this many targets.
    pub warmup_targets: usize,
    /// The side of the square matrix product that measures the backend's reachable rate.
    pub gemm_size: usize,
    pub seed: u64,
}

impl Preset for SamplingSpeedConfig {
    /// The paper's 70,000 desired positions (+-90 degrees) and network, batch 512, every
    /// core; batch sizes 1 to 4,096, threads 1 to twice the cores; the kinematics alone and
    /// with 50 us per call, sleeping and spinning; median of 3.
    fn paper() -> Self {
        SamplingSpeedConfig {
            preset: "paper".into(),
            data: IkDataConfig::paper(90.0),
            hidden: vec![1024, 512, 256, 128],
            inference_batch: 512,
            threads: 0,
            batch_sweep: (0..=12).map(|k| 1 << k).collect(),
            thread_sweep: Vec::new(),
            latencies: vec![
                Latency::None,
                Latency::Sleep { us: 50 },
                Latency::Spin { us: 50 },
            ],
            repeats: 3,
            warmup_targets: 2_000,
            gemm_size: 2048,
            seed: 0,
        }
    }

    /// 2,000 targets, a small network, three batch sizes, one repeat: about a second.
    fn quick() -> Self {
        SamplingSpeedConfig {
            preset: "quick".into(),
            data: IkDataConfig::quick(90.0),
            hidden: vec![128, 64],
            inference_batch: 256,
            threads: 0,
            batch_sweep: vec![1, 16, 256],
            thread_sweep: vec![1, 2],
            latencies: vec![Latency::None, Latency::Spin { us: 20 }],
            repeats: 1,
            warmup_targets: 100,
            gemm_size: 256,
            seed: 0,
        }
    }
}

/// One timed configuration.
#[derive(Clone, Debug, serde::Serialize, serde::Deserialize)]
pub struct SpeedRow {
    pub robot: String,
    /// `III` (the four strategies), `7a` (batch sweep) or `7b` (thread sweep).
    pub table: String,
    pub strategy: String,
    pub inference_batch: usize,
    pub threads: usize,
    pub latency: String,
    pub targets: usize,
    /// The median pass and its two halves (seconds).
    pub seconds: f64,
    pub inference_seconds: f64,
    pub forward_seconds: f64,
    /// The forward model's wall time per target in the median pass (us): the latency of one
    /// call on one worker, less where workers overlap.
    pub forward_us_per_target: f64,
    /// No acceleration's time over this one's, at the same latency (Table III only).
    pub speedup: Option<f64>,
    /// The inverse model's matrix products over the inference time, and that rate as a
    /// percentage of what a large matrix product reaches on the same backend and of the
    /// theoretical peak at the nominal clock (the cores boost above it: a large matrix
    /// product can exceed it).
    pub inference_gflops: f64,
    pub percent_of_gemm: f64,
    pub percent_of_nominal_peak: Option<f64>,
    /// The paper's Table III (6-core i7-8700 and a GPU; its forward model unnamed).
    pub paper_seconds: Option<f64>,
    pub repeats: usize,
    /// Cores of the machine the row was measured on.
    #[serde(default)]
    pub cores: usize,
    pub git_revision: String,
    pub device: String,
    pub preset: String,
}

/// The machine the times were taken on.
#[derive(Clone, Debug, serde::Serialize, serde::Deserialize)]
pub struct Hardware {
    pub cpu: Option<CpuPeak>,
    /// A `gemm_size`-square f32 matrix product on the run's burn backend (GFLOP/s).
    pub gemm_size: usize,
    pub gemm_gflops: f64,
    /// FLOP of the inverse model's matrix products per answered position.
    pub inverse_model_flop_per_target: f64,
    pub rayon_threads: usize,
}

/// The four strategies of Table III and the paper's times for them.
fn strategies(batch: usize, threads: usize) -> [(&'static str, Strategy, f64); 4] {
    let s = |inference_batch, threads| Strategy {
        inference_batch,
        threads,
    };
    [
        ("no acceleration", s(1, 1), 61.40),
        ("batch inference only", s(batch, 1), 5.10),
        ("parallel forward model only", s(1, threads), 57.84),
        (
            "batch inference + parallel forward model",
            s(batch, threads),
            2.02,
        ),
    ]
}

/// What one run measures with: the model, the targets and how to time a strategy.
struct Bench<'a> {
    model: Mlp,
    data: IkData,
    desired: Vec<Point3<f64>>,
    robot: &'a Robot,
    cfg: &'a SamplingSpeedConfig,
    device: burn::tensor::Device,
}

impl Bench<'_> {
    /// The median of `repeats` full passes after a warm-up pass.
    fn time(&self, strategy: Strategy, latency: Latency) -> Result<SamplingPass> {
        let forward = ForwardModel {
            chain: &self.robot.chain,
            latency,
        };
        let workers = Workers::new(strategy.threads)?;
        let pass = |targets: &[Point3<f64>]| {
            sampling_pass(
                &self.model,
                &self.data,
                targets,
                strategy.inference_batch,
                &forward,
                &workers,
                &self.device,
            )
        };
        pass(&self.desired[..self.cfg.warmup_targets.min(self.desired.len())])?;
        let mut passes = (0..self.cfg.repeats.max(1))
            .map(|_| pass(&self.desired))
            .collect::<Result<Vec<_>>>()?;
        passes.sort_by(|a, b| a.seconds().total_cmp(&b.seconds()));
        let n = passes.len();
        Ok(passes.swap_remove(n / 2))
    }
}

/// Run Table III and both sweeps; write `results.csv` (Table III), `batch_sweep.csv`,
/// `thread_sweep.csv` (+ Markdown), `sampling_time.png` (Figure 7), `hardware.json` and
/// `config.json`. Returns a one-line summary.
pub fn run(
    cfg: &SamplingSpeedConfig,
    robot: &Robot,
    dir: &Path,
    device_choice: DeviceChoice,
) -> Result<String> {
    let robot_name = robot.label.as_str();
    if cfg.latencies.is_empty() || cfg.inference_batch == 0 || cfg.batch_sweep.contains(&0) {
        return Err(Error::Config(
            "sampling speed: give at least one latency and positive batch sizes".into(),
        ));
    }
    std::fs::create_dir_all(dir).map_err(|e| Error::io(dir, e))?;
    write_json(&dir.join("config.json"), cfg)?;
    let device = selfmodel::core::device::select(device_choice)?;
    let cores = std::thread::available_parallelism().map_or(1, |n| n.get());
    let threads = if cfg.threads == 0 { cores } else { cfg.threads };
    let data = IkData::generate(&robot.chain, &cfg.data)?;
    let model_cfg = InverseModelConfig::paper(robot.dof());
    let model_cfg = InverseModelConfig {
        hidden: cfg.hidden.clone(),
        ..model_cfg
    };
    let bench = Bench {
        model: model_cfg.init(&device, cfg.seed)?,
        desired: data.positions[data.train()].to_vec(),
        data,
        robot,
        cfg,
        device: device.clone(),
    };
    let flop_per_target = model_cfg.flop_per_row();
    let cpu = CpuPeak::detect();
    let hardware = Hardware {
        gemm_size: cfg.gemm_size,
        gemm_gflops: matmul_gflops(&device, cfg.gemm_size, cfg.repeats.max(3)),
        inverse_model_flop_per_target: flop_per_target,
        rayon_threads: rayon::current_num_threads(),
        cpu: cpu.clone(),
    };
    write_json(&dir.join("hardware.json"), &hardware)?;
    let targets = bench.desired.len();
    let hardware = &hardware;
    let row = |table: &str,
               name: &str,
               strategy: Strategy,
               latency: Latency,
               pass: &SamplingPass,
               speedup: Option<f64>,
               paper: Option<f64>| {
        let gflops = flop_per_target * targets as f64 / pass.inference_seconds.max(1e-12) / 1e9;
        SpeedRow {
            robot: robot_name.to_string(),
            table: table.to_string(),
            strategy: name.to_string(),
            inference_batch: strategy.inference_batch,
            threads: strategy.threads,
            latency: latency.label(),
            targets,
            seconds: pass.seconds(),
            inference_seconds: pass.inference_seconds,
            forward_seconds: pass.forward_seconds,
            forward_us_per_target: pass.forward_seconds * 1e6 / targets.max(1) as f64,
            speedup,
            inference_gflops: gflops,
            percent_of_gemm: 100.0 * gflops / hardware.gemm_gflops,
            percent_of_nominal_peak: cpu.as_ref().map(|c| 100.0 * gflops / c.theoretical_gflops),
            paper_seconds: paper,
            repeats: cfg.repeats,
            cores,
            git_revision: selfmodel::core::provenance::git_revision(),
            device: device_choice.to_string(),
            preset: cfg.preset.clone(),
        }
    };
    let thread_sweep: Vec<usize> = if cfg.thread_sweep.is_empty() {
        (1..=2 * cores).collect()
    } else {
        cfg.thread_sweep.clone()
    };
    let total = cfg.latencies.len() * (4 + cfg.batch_sweep.len() + thread_sweep.len());
    let bar = selfmodel::core::progress::progress_bar(total as u64, "sampling speed", "passes");
    let step = |what: String| {
        bar.set_message(what);
        bar.inc(1);
    };

    // Table III.
    let mut table = Vec::new();
    for &latency in &cfg.latencies {
        let mut base = None;
        for (name, strategy, paper) in strategies(cfg.inference_batch, threads) {
            let pass = bench.time(strategy, latency)?;
            let none = *base.get_or_insert(pass.seconds());
            table.push(row(
                "III",
                name,
                strategy,
                latency,
                &pass,
                Some(none / pass.seconds().max(1e-12)),
                Some(paper),
            ));
            step(format!("{name}, {}", latency.label()));
        }
    }
    // Figure 7.
    let mut batch_rows = Vec::new();
    let mut thread_rows = Vec::new();
    for &latency in &cfg.latencies {
        for &b in &cfg.batch_sweep {
            let strategy = Strategy {
                inference_batch: b,
                threads,
            };
            let pass = bench.time(strategy, latency)?;
            batch_rows.push(row(
                "7a",
                "batch sweep",
                strategy,
                latency,
                &pass,
                None,
                None,
            ));
            step(format!("batch {b}, {}", latency.label()));
        }
        for &t in &thread_sweep {
            let strategy = Strategy {
                inference_batch: cfg.inference_batch,
                threads: t,
            };
            let pass = bench.time(strategy, latency)?;
            thread_rows.push(row(
                "7b",
                "thread sweep",
                strategy,
                latency,
                &pass,
                None,
                None,
            ));
            step(format!("{t} threads, {}", latency.label()));
        }
    }
    bar.finish_and_clear();
    write_reports(dir, &table, &batch_rows, &thread_rows, hardware, cores)?;
    Ok(summary(&table, &batch_rows, hardware))
}

fn write_reports(
    dir: &Path,
    table: &[SpeedRow],
    batch_rows: &[SpeedRow],
    thread_rows: &[SpeedRow],
    hardware: &Hardware,
    cores: usize,
) -> Result<()> {
    let machine = match &hardware.cpu {
        Some(c) => format!(
            "{} cores of a {} at {:.2} GHz ({}; theoretical f32 peak {:.0} GFLOP/s); a {}-square matrix product reaches {:.0} GFLOP/s on this backend",
            c.cores,
            c.model,
            c.ghz,
            c.vector_units,
            c.theoretical_gflops,
            hardware.gemm_size,
            hardware.gemm_gflops
        ),
        None => format!(
            "{cores} cores; a {}-square matrix product reaches {:.0} GFLOP/s",
            hardware.gemm_size, hardware.gemm_gflops
        ),
    };
    selfmodel::report::table::write_table(
        &dir.join("results.csv"),
        table,
        "Table III: time of one EMSSL sampling pass under four strategies",
        &format!(
            "Seconds for the inverse model to answer every desired training position and the forward model to say where each answer goes: the median of {} passes after a warm-up. Machine: {machine}. `paper_seconds`: the paper's Table III (6-core i7-8700 with a GPU, its forward model not named), for reference. `inference_gflops`: the inverse model's matrix products ({:.2} MFLOP per target) over the inference time, as a percentage of the large matrix product's rate (`percent_of_gemm`) and of the theoretical peak at the nominal clock (`percent_of_nominal_peak`; the cores boost above the nominal clock, so this can pass 100).",
            table.first().map_or(0, |r| r.repeats),
            hardware.inverse_model_flop_per_target / 1e6
        ),
    )?;
    selfmodel::report::table::write_table(
        &dir.join("batch_sweep.csv"),
        batch_rows,
        "Figure 7(a): sampling time against the inference batch size",
        &format!("Forward model on every core. Machine: {machine}."),
    )?;
    selfmodel::report::table::write_table(
        &dir.join("thread_sweep.csv"),
        thread_rows,
        "Figure 7(b): sampling time against the forward model's threads",
        &format!(
            "This machine has {cores} cores; the sweep goes to twice that. Machine: {machine}."
        ),
    )?;
    draw_figures(dir)
}

/// Figure 7 from the sweeps' CSV files in `dir`: `sampling_time_vs_batch.png` and
/// `sampling_time_vs_threads.png`, one line per forward-model latency.
pub fn draw_figures(dir: &Path) -> Result<()> {
    let read = |file: &str| -> Result<Vec<SpeedRow>> {
        selfmodel::report::table::read_csv(&dir.join(file))
    };
    let (batch_rows, thread_rows) = (read("batch_sweep.csv")?, read("thread_sweep.csv")?);
    let lines = |rows: &[SpeedRow], x: fn(&SpeedRow) -> usize| {
        let mut labels: Vec<String> = rows.iter().map(|r| r.latency.clone()).collect();
        labels.dedup();
        labels
            .into_iter()
            .map(|l| {
                let pts = rows
                    .iter()
                    .filter(|r| r.latency == l)
                    .map(|r| (x(r) as f64, r.seconds))
                    .collect();
                (format!("forward model latency: {l}"), pts)
            })
            .collect::<Vec<_>>()
    };
    let targets = batch_rows.first().map_or(0, |r| r.targets);
    // Rows written before the `cores` column were measured here.
    let cores = thread_rows
        .iter()
        .map(|r| r.cores)
        .find(|&c| c > 0)
        .unwrap_or_else(|| std::thread::available_parallelism().map_or(1, |n| n.get()));
    selfmodel::report::figures::line_plot(
        &dir.join("sampling_time_vs_batch.png"),
        &format!(
            "Figure 7(a): sampling {targets} targets against inference batch size ({cores}-core CPU)"
        ),
        ("inference batch size", "seconds per sampling pass (log)"),
        &lines(&batch_rows, |r| r.inference_batch),
        selfmodel::report::figures::LinePlot::LOG_LOG,
    )?;
    selfmodel::report::figures::line_plot(
        &dir.join("sampling_time_vs_threads.png"),
        &format!(
            "Figure 7(b): sampling time against forward-model threads (this CPU has {cores} cores)"
        ),
        ("forward-model threads", "seconds per sampling pass (log)"),
        &lines(&thread_rows, |r| r.threads),
        selfmodel::report::figures::LinePlot::LOG_LOG,
    )
}

fn summary(table: &[SpeedRow], batch_rows: &[SpeedRow], hardware: &Hardware) -> String {
    let mut parts: Vec<String> = table
        .iter()
        .filter(|r| r.strategy.starts_with("batch inference +"))
        .map(|r| {
            format!(
                "latency {}: {:.2} s accelerated, {:.1}x faster than none",
                r.latency,
                r.seconds,
                r.speedup.unwrap_or(f64::NAN)
            )
        })
        .collect();
    if let Some(best) = batch_rows
        .iter()
        .max_by(|a, b| a.inference_gflops.total_cmp(&b.inference_gflops))
    {
        parts.push(format!(
            "inference peaks at {:.0} GFLOP/s at batch {}, {:.0}% of a large matrix product's {:.0} GFLOP/s",
            best.inference_gflops,
            best.inference_batch,
            best.percent_of_gemm,
            hardware.gemm_gflops
        ));
    }
    parts.join("; ")
}
