//! selfmodel-lab: the studies that reproduce and extend the two papers, on the `selfmodel`
//! library. `experiments/` holds one thin binary per study (this crate's binaries), `studies`
//! what they run, `cli` what every binary shares. See `ARCHITECTURE.md`.

pub mod cli;
pub mod studies;

pub use crate::studies::registry::{EXPERIMENTS, Experiment, RunOptions};

/// mimalloc instead of the system allocator, for the lab's binaries and tests (the library
/// leaves the allocator to whoever links it): training allocates and frees buffers of tens of
/// megabytes every step, which glibc returns to the kernel and faults back in (page faults
/// and TLB shootdowns were ~12% of a NeuroKin training step in `perf`).
#[global_allocator]
static ALLOCATOR: mimalloc::MiMalloc = mimalloc::MiMalloc;

/// The workspace's root (the repository: `data/`, `reports/`, `scripts/`, the library's
/// `Cargo.toml`), the folder above this crate's.
pub fn workspace() -> std::path::PathBuf {
    let lab = std::path::Path::new(env!("CARGO_MANIFEST_DIR"));
    lab.parent().unwrap_or(lab).to_path_buf()
}
