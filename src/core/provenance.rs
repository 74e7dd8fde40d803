//! Where a result came from: the code revision every result row records.

/// The code a run started from: `git describe --always` of the working tree when this process
/// first asked, with `-dirty` when the code differs from that commit (the sources, the
/// experiments, the manifest and lock file; not `reports/`, which other runs write while this
/// one trains), or "unknown". Read once; binaries ask at start. The working tree is the one
/// the binary was built from (`CARGO_MANIFEST_DIR`): a long run from a copy of a binary while
/// that tree moves on records the tree's revision at the run's start, not the binary's; build
/// such a run's binary in a `git worktree` of its commit, which stays put.
pub fn git_revision() -> String {
    static REVISION: std::sync::OnceLock<String> = std::sync::OnceLock::new();
    REVISION
        .get_or_init(|| {
            let git = |args: &[&str]| {
                std::process::Command::new("git")
                    .args(args)
                    .current_dir(env!("CARGO_MANIFEST_DIR"))
                    .output()
                    .ok()
                    .filter(|o| o.status.success())
                    .map(|o| String::from_utf8_lossy(&o.stdout).trim().to_string())
            };
            let Some(revision) = git(&["describe", "--always", "--abbrev=10"]) else {
                return "unknown".into();
            };
            let changed = git(&["status", "--porcelain", "--"]
                .into_iter()
                .chain(CODE_PATHS)
                .collect::<Vec<_>>())
            .is_none_or(|s| !s.is_empty());
            if changed {
                format!("{revision}-dirty")
            } else {
                revision
            }
        })
        .clone()
}

/// What a result depends on: a change here marks a run's revision `-dirty`.
pub const CODE_PATHS: [&str; 5] = ["src", "lab", "experiments", "Cargo.toml", "Cargo.lock"];
