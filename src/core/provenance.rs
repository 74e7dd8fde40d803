//! Where a result came from: the code revision every result row records.

/// `git describe --always --dirty` of the working tree when this process first asked, or
/// "unknown": the code a run started from. Read once, so the files a run writes (its own
/// `config.json` over a committed report) never mark it dirty; binaries ask at start.
pub fn git_revision() -> String {
    static REVISION: std::sync::OnceLock<String> = std::sync::OnceLock::new();
    REVISION
        .get_or_init(|| {
            std::process::Command::new("git")
                .args(["describe", "--always", "--dirty", "--abbrev=10"])
                .current_dir(env!("CARGO_MANIFEST_DIR"))
                .output()
                .ok()
                .filter(|o| o.status.success())
                .map(|o| String::from_utf8_lossy(&o.stdout).trim().to_string())
                .unwrap_or_else(|| "unknown".into())
        })
        .clone()
}
