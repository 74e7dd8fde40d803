//! Write-then-rename: results appear whole or not at all.
//!
//! Every file the project writes goes through [`write_atomic`]: the content is written to a
//! hidden temporary name in the same folder and renamed over the target only once complete,
//! so an error or a killed run never leaves a partial file behind.

use std::fs;
use std::io::{BufWriter, Write};
use std::path::{Path, PathBuf};

use crate::core::error::{Error, Result};

/// The temporary name used while `path` is being written (`dir/.name.tmp-PID`).
fn temp_path(path: &Path) -> PathBuf {
    let name = path
        .file_name()
        .map(|n| n.to_string_lossy().into_owned())
        .unwrap_or_else(|| "out".into());
    path.with_file_name(format!(".{name}.tmp-{}", std::process::id()))
}

/// Remove the temporary files of `path` left by processes that no longer run (a run killed
/// with SIGKILL mid-write cannot remove its own).
fn remove_stale_temps(path: &Path) {
    let (Some(dir), Some(name)) = (path.parent(), path.file_name()) else {
        return;
    };
    let dir = if dir.as_os_str().is_empty() {
        Path::new(".")
    } else {
        dir
    };
    let prefix = format!(".{}.tmp-", name.to_string_lossy());
    for entry in fs::read_dir(dir).into_iter().flatten().flatten() {
        let file = entry.file_name().to_string_lossy().into_owned();
        let pid = file
            .strip_prefix(&prefix)
            .and_then(|p| p.parse::<u32>().ok());
        if let Some(pid) = pid
            && pid != std::process::id()
            && !process_runs(pid)
        {
            let _ = fs::remove_file(entry.path());
        }
    }
}

/// Create `path` atomically: `fill` writes the content into a buffered writer on a temporary
/// file, which is synced and renamed to `path` only if `fill` succeeds. Parent folders are
/// created. On any error the temporary file is removed and `path` is untouched.
pub fn write_atomic<F>(path: &Path, fill: F) -> Result<()>
where
    F: FnOnce(&mut BufWriter<fs::File>) -> Result<()>,
{
    if let Some(dir) = path.parent().filter(|d| !d.as_os_str().is_empty()) {
        fs::create_dir_all(dir).map_err(|e| Error::io(dir, e))?;
    }
    remove_stale_temps(path);
    let tmp = temp_path(path);
    let result = (|| {
        let file = fs::File::create(&tmp).map_err(|e| Error::io(&tmp, e))?;
        let mut w = BufWriter::new(file);
        fill(&mut w)?;
        let file = w
            .into_inner()
            .map_err(|e| Error::io(&tmp, e.into_error()))?;
        file.sync_all().map_err(|e| Error::io(&tmp, e))?;
        fs::rename(&tmp, path).map_err(|e| Error::io(path, e))
    })();
    if result.is_err() {
        let _ = fs::remove_file(&tmp);
    }
    result
}

/// Atomically write a byte string.
pub fn write_bytes(path: &Path, bytes: &[u8]) -> Result<()> {
    write_atomic(path, |w| w.write_all(bytes).map_err(|e| Error::io(path, e)))
}

/// Atomically write a value as pretty JSON.
pub fn write_json<T: serde::Serialize>(path: &Path, value: &T) -> Result<()> {
    let text = serde_json::to_string_pretty(value)
        .map_err(|e| Error::data(path, format!("cannot serialise JSON: {e}")))?;
    write_bytes(path, (text + "\n").as_bytes())
}

/// A claim on a piece of work shared by processes started with the same command: the file
/// `path` holds the claiming process's id and is removed when the claim is dropped. A claim
/// left by a process that no longer runs (killed) is taken over.
pub struct Claim {
    path: PathBuf,
}

/// What [`Claim::take`] found.
pub enum Claimed {
    /// This process holds the work now.
    Mine(Claim),
    /// Another running process holds it (its id).
    Other(u32),
}

impl Claim {
    /// Claim the work named by `path`.
    pub fn take(path: &Path) -> Result<Claimed> {
        if let Some(dir) = path.parent().filter(|d| !d.as_os_str().is_empty()) {
            fs::create_dir_all(dir).map_err(|e| Error::io(dir, e))?;
        }
        let me = std::process::id();
        for _ in 0..2 {
            match fs::OpenOptions::new()
                .write(true)
                .create_new(true)
                .open(path)
            {
                Ok(mut f) => {
                    write!(f, "{me}").map_err(|e| Error::io(path, e))?;
                    return Ok(Claimed::Mine(Claim {
                        path: path.to_path_buf(),
                    }));
                }
                Err(e) if e.kind() == std::io::ErrorKind::AlreadyExists => {
                    let holder = fs::read_to_string(path)
                        .ok()
                        .and_then(|t| t.trim().parse::<u32>().ok());
                    match holder {
                        Some(pid) if pid != me && process_runs(pid) => {
                            return Ok(Claimed::Other(pid));
                        }
                        // Stale (or ours): remove it and try once more.
                        _ => fs::remove_file(path).map_err(|e| Error::io(path, e))?,
                    }
                }
                Err(e) => return Err(Error::io(path, e)),
            }
        }
        Err(Error::io(
            path,
            std::io::Error::other("the claim file keeps reappearing"),
        ))
    }
}

impl Drop for Claim {
    fn drop(&mut self) {
        let _ = fs::remove_file(&self.path);
    }
}

/// Whether process `pid` runs (Linux: /proc; elsewhere every claim is taken as live).
fn process_runs(pid: u32) -> bool {
    let proc = Path::new("/proc");
    !proc.exists() || proc.join(pid.to_string()).exists()
}

/// A label as a file name: lower case, runs of anything but ASCII letters and digits as one
/// `_` ("EMSSL + DLS" -> "emssl_dls").
pub fn file_name(label: &str) -> String {
    label
        .to_lowercase()
        .split(|c: char| !c.is_ascii_alphanumeric())
        .filter(|w| !w.is_empty())
        .collect::<Vec<_>>()
        .join("_")
}

/// Refuse an `out` that cannot be written, before any work: one whose nearest existing
/// ancestor is a file (it cannot hold a folder), or, where `kind` is a file, an existing
/// folder or a path ending in `/`.
pub fn check_out(out: &Path, kind: OutKind) -> Result<()> {
    let shown = out.display();
    if kind == OutKind::File && (out.is_dir() || out.as_os_str().to_string_lossy().ends_with('/')) {
        return Err(Error::Config(format!(
            "`out` {shown} is a folder; give a file in it (e.g. {}/dataset.npz)",
            shown.to_string().trim_end_matches('/')
        )));
    }
    if kind == OutKind::File
        && let Ok(meta) = fs::metadata(out)
        && !meta.is_file()
    {
        return Err(Error::Config(format!(
            "`out` {shown} is a device, FIFO or socket, not a file: give a file to write"
        )));
    }
    if kind == OutKind::Folder && out.exists() && !out.is_dir() {
        return Err(Error::Config(format!(
            "`out` {shown} is a file; give a folder"
        )));
    }
    let mut parent = out.parent();
    while let Some(p) = parent.filter(|p| !p.as_os_str().is_empty()) {
        if p.exists() {
            if !p.is_dir() {
                return Err(Error::Config(format!(
                    "`out` {shown}: {} is a file, not a folder; choose another `out`",
                    p.display()
                )));
            }
            break;
        }
        parent = p.parent();
    }
    Ok(())
}

/// What an `out` names.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum OutKind {
    File,
    Folder,
}

/// `p` as it resolves: every link followed where it exists, else its folder resolved and its
/// name joined (an output need not exist yet).
fn resolved(p: &Path) -> Option<PathBuf> {
    if let Ok(path) = fs::canonicalize(p) {
        return Some(path);
    }
    let parent = p
        .parent()
        .filter(|d| !d.as_os_str().is_empty())
        .unwrap_or(Path::new("."));
    fs::canonicalize(parent)
        .ok()
        .map(|d| d.join(p.file_name().unwrap_or_default()))
}

/// Whether `a` and `b` are one file: the same path once resolved, or (both existing) the
/// same file under two names (a hard link).
fn same_file(a: &Path, b: &Path) -> bool {
    if resolved(a).is_some_and(|x| resolved(b).is_some_and(|y| x == y)) {
        return true;
    }
    #[cfg(unix)]
    {
        use std::os::unix::fs::MetadataExt;
        if let (Ok(x), Ok(y)) = (fs::metadata(a), fs::metadata(b)) {
            return x.dev() == y.dev() && x.ino() == y.ino();
        }
    }
    false
}

/// Refuse an output path that is one of a run's `inputs` (through symbolic and hard links)
/// or lies inside a folder it reads from (`protected`, a saved model's): a run never
/// overwrites what it reads.
pub fn refuse_overwrite(out: &Path, inputs: &[&Path], protected: Option<&Path>) -> Result<()> {
    if let Some(input) = inputs.iter().find(|i| same_file(out, i)) {
        return Err(Error::Config(format!(
            "`out` {} is the file it reads ({}): choose another `out`",
            out.display(),
            input.display()
        )));
    }
    if let (Some(dir), Some(target)) = (
        protected.and_then(|d| fs::canonicalize(d).ok()),
        resolved(out),
    ) && target.starts_with(&dir)
    {
        return Err(Error::Config(format!(
            "`out` {} lies inside the model's folder {}: choose another `out`",
            out.display(),
            dir.display()
        )));
    }
    Ok(())
}

/// `run`, which writes the files named `written` into the folder `out`; where it fails (or is
/// stopped), those files are removed, and the folder too if `run` made it: nothing of a run
/// that did not finish is left.
pub fn nothing_left_on_failure<T>(
    out: &Path,
    written: &[&str],
    run: impl FnOnce() -> Result<T>,
) -> Result<T> {
    let fresh = !out.exists();
    let result = run();
    if result.is_err() {
        for name in written {
            let _ = std::fs::remove_file(out.join(name));
        }
        if fresh {
            let _ = std::fs::remove_dir(out);
        }
    }
    result
}

/// Refuse a folder `out` a run writes the files `written` into (names in it; a name ending
/// in `/` a folder of its own) where one of them is one of `inputs`: `ik train --out F`
/// with `F/collision.json` the scene it reads would replace the scene.
pub fn refuse_writing_over(out: &Path, written: &[&str], inputs: &[&Path]) -> Result<()> {
    for name in written {
        let file = out.join(name.trim_end_matches('/'));
        for input in inputs {
            let inside = name.ends_with('/')
                && (resolved(input).zip(resolved(&file))).is_some_and(|(i, f)| i.starts_with(f));
            if inside || same_file(&file, input) {
                return Err(Error::Config(format!(
                    "`out` {}: the run writes {} there, which is a file it reads ({}): choose another `out` or move the file",
                    out.display(),
                    file.display(),
                    input.display()
                )));
            }
        }
    }
    Ok(())
}
