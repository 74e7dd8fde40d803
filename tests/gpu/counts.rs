//! What one NeuroKin training step asks of a GPU, counted on wgpu (lavapipe in CI): kernel
//! launches (at most [`MOST_LAUNCHES`]; `SELFMODEL_PRINT_LAUNCHES=1` prints the last step's
//! in order, each with the operations it ran for), host reads and uploads per step (`eval::device_counts`, through
//! `self_models::step_counts::neurokin_step_counts`, which the lab's `gpu_check` reports on a GPU). A host
//! read inside a step makes the step wait for the device, so the losses are read only at log
//! intervals: this test fails when a read appears in any other step. Part of `tests/gpu.rs`:
//! `cargo test --release --features wgpu --test gpu -- counts --nocapture` prints the counts.

use selfmodel::core::device::DeviceChoice;
use selfmodel::self_models::step_counts::neurokin_step_counts;

/// Launches a NeuroKin step may take here (the log intervals' loss read included): issue 58's
/// target of 100 (99 were reached), the 14 finishing passes of the sums by channel and one of
/// the gradients' norm that issue 71 added so that those sums fill the GPU (a launch costs ~5 µs
/// where a sum on one workgroup a channel took up to 7 ms on an H200), and a margin of 5 for
/// burn's autotune: it picks a matmul's kernel, whether a matmul runs its elementwise epilogue
/// in the same kernel, and a reduction's strategy by timing them on the machine at hand, and
/// some picks take a second launch. The same commit counted 113 a step (114 at a log step) on
/// a Zen 4 and 115 (116) on CI's machine.
const MOST_LAUNCHES: u64 = 120;

#[test]
fn a_neurokin_training_step_reads_nothing_back() {
    // The paper preset's step at the quick preset's size: input noise, clipping; batches of
    // 16 (the quick preset's, as the equivalence test trains), an epoch every 4 steps.
    let (log_every, steps) = (4, 12);
    selfmodel::eval::device_counts::log_launches();
    let (per_step, log) =
        neurokin_step_counts(DeviceChoice::Wgpu, "quick", 16, steps, log_every).unwrap();
    let over = per_step.iter().skip(1).any(|c| c.launches > MOST_LAUNCHES);
    if over || std::env::var_os("SELFMODEL_PRINT_LAUNCHES").is_some() {
        // The last step's launches in order.
        let all = selfmodel::eval::device_counts::launch_log();
        let last = per_step.last().map_or(0, |c| c.launches as usize);
        for (i, l) in all[all.len().saturating_sub(last)..].iter().enumerate() {
            eprintln!("launch {i:>3}: {l}");
        }
    }
    assert_eq!(log.curve.len(), steps / log_every, "{:?}", log.curve);
    assert_eq!(per_step.len(), steps);
    for (i, c) in per_step.iter().enumerate() {
        let step = i + 1;
        eprintln!(
            "step {step:>2}: {:>4} kernel launches, {} host reads, {} uploads",
            c.launches, c.reads, c.uploads
        );
    }
    let mut kernels: Vec<_> = per_step[1].kernels.iter().collect();
    kernels.sort_by(|a, b| b.1.cmp(a.1));
    eprintln!("step 2's kernels, most launched first:");
    for (name, count) in kernels.iter().take(12) {
        eprintln!("  {count:>4} x {name}");
    }
    let mut sources: Vec<_> = per_step[1].sources.iter().collect();
    sources.sort_by(|a, b| b.1.cmp(a.1));
    eprintln!("step 2's kernels by the operations they ran for:");
    for (name, count) in &sources {
        eprintln!("  {count:>4} x {name}");
    }
    // The first step compiles and tunes its kernels; from the second on, a step is what
    // every later step will be.
    for (i, c) in per_step.iter().enumerate().skip(1) {
        let step = i + 1;
        let expected = u64::from(step % log_every == 0);
        assert_eq!(
            c.reads, expected,
            "step {step}: {} host reads where {expected} was expected (the losses are read every {log_every} steps, nothing else)",
            c.reads
        );
        assert!(c.launches > 0, "step {step}: no kernel launch counted");
        // 310 launches a step before our fused kernels (Adam and the clipping, batch norm,
        // the loss, the transposed convolutions, the head's convolutions); 99 with them here,
        // 100 at a log step; 113 and 114 with issue 71's two-pass sums (115 and 116 on CI's machine).
        assert!(
            c.launches <= MOST_LAUNCHES,
            "step {step}: {} kernel launches, more than the {MOST_LAUNCHES} allowed",
            c.launches
        );
    }
}

/// Elements above which a kernel must fill the GPU (issue 71's guard).
const LARGE: u64 = 1 << 20;
/// The workgroups such a kernel must launch at least: several per multiprocessor of an H100
/// or H200 (132), where a workgroup a channel ran 16 to 128.
const FILLING: u64 = 1024;

#[test]
fn a_neurokin_step_at_batch_256_fills_the_gpu_with_every_large_kernel() {
    // The quick model at batch 256: its last layers' tensors hold millions of elements.
    let (log_every, steps) = (3, 3);
    selfmodel::eval::device_counts::log_launches();
    let before = selfmodel::eval::device_counts::launch_log().len();
    let (per_step, _) =
        neurokin_step_counts(DeviceChoice::Wgpu, "quick", 256, steps, log_every).unwrap();
    let all = selfmodel::eval::device_counts::launch_log();
    // The steps after the first (which compiles and tunes).
    let first = per_step[0].launches as usize;
    let counted = &all[before + first..];
    assert!(!counted.is_empty(), "no launch logged");
    let measured: Vec<_> = counted.iter().filter(|l| l.elements.is_some()).collect();
    assert!(
        measured.len() >= 20,
        "only {} of {} launches say their elements: our kernels' launchers name them",
        measured.len(),
        counted.len()
    );
    let mut large: Vec<_> = measured
        .iter()
        .filter(|l| l.elements.unwrap_or(0) > LARGE)
        .collect();
    large.sort_by_key(|l| l.workgroups);
    eprintln!(
        "{} launches of our kernels over more than 2^20 elements, fewest workgroups first:",
        large.len()
    );
    for l in large.iter().take(12) {
        eprintln!("  {l}");
    }
    assert!(
        large.len() >= 10,
        "only {} large launches: the step is smaller than this guard needs",
        large.len()
    );
    let short: Vec<String> = large
        .iter()
        .filter(|l| l.workgroups.is_none_or(|w| w < FILLING))
        .map(|l| l.to_string())
        .collect();
    assert!(
        short.is_empty(),
        "kernels over more than 2^20 elements launched fewer than {FILLING} workgroups (or an unknown count):\n{}",
        short.join("\n")
    );
}

#[test]
fn a_launch_count_is_read_as_cubecl_prints_it() {
    use selfmodel::eval::device_counts::workgroups;
    assert_eq!(workgroups("(16, 2, 1)"), Some(32));
    assert_eq!(workgroups("(2048, 1, 1)"), Some(2048));
    assert_eq!(workgroups("binding"), None);
}
