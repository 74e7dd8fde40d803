//! Typed errors of the library. Every variant names the file (or the input) and what is
//! wrong, so the binaries can print one line and exit non-zero.

use std::path::PathBuf;

/// Everything the library can fail with.
#[derive(Debug, thiserror::Error)]
pub enum Error {
    /// Reading or writing a file failed at the operating-system level.
    #[error("{}: {}", one_line(&path.display().to_string()), one_line(&source.to_string()))]
    Io {
        path: PathBuf,
        #[source]
        source: std::io::Error,
    },
    /// A URDF that cannot be used: bad XML, an unsupported joint type, a broken tree.
    /// `element` names the offending element (`joint "L1_L2"`, `link "base"`, ...).
    #[error("{}: {}: {}", one_line(&path.display().to_string()), one_line(element), one_line(msg))]
    Urdf {
        path: PathBuf,
        element: String,
        msg: String,
    },
    /// A mesh file that is missing or cannot be parsed.
    #[error("{}: {}", one_line(&path.display().to_string()), one_line(msg))]
    Mesh { path: PathBuf, msg: String },
    /// A data file (npz, CSV) whose content is wrong: missing keys, shapes, dtypes, NaNs.
    #[error("{}: {}", one_line(&path.display().to_string()), one_line(msg))]
    Data { path: PathBuf, msg: String },
    /// An impossible configuration or argument (zero samples, a split larger than the data).
    #[error("{}", one_line(.0))]
    Config(String),
    /// A `device` that was not compiled in or cannot start.
    #[error("{}", one_line(.0))]
    Device(String),
    /// Training that cannot go on (a loss that became NaN or infinite).
    #[error("{}", one_line(.0))]
    Training(String),
    /// Training that collapsed to a trivial solution (FFKSM's all-black image) at `step`;
    /// the caller may restart with a fresh model.
    #[error("training collapsed to an all-black image at step {step}")]
    Collapsed { step: usize },
    /// Stopped by Ctrl-C: what was saved and how to continue.
    #[error("{}", one_line(.0))]
    Interrupted(String),
}

/// `text` on one line: line breaks and other control characters (a user's file quoted in
/// a message may hold any) escaped as `\n`, `\u{0}`, ...
pub fn one_line(text: &str) -> String {
    let mut out = String::with_capacity(text.len());
    for c in text.chars() {
        if c.is_control() {
            out.extend(c.escape_default());
        } else {
            out.push(c);
        }
    }
    out
}

/// The library's result type.
pub type Result<T, E = Error> = std::result::Result<T, E>;

impl Error {
    /// Wrap an I/O error with the path it happened on.
    pub fn io(path: impl Into<PathBuf>, source: std::io::Error) -> Self {
        Error::Io {
            path: path.into(),
            source,
        }
    }

    /// A content error in a data file.
    pub fn data(path: impl Into<PathBuf>, msg: impl Into<String>) -> Self {
        Error::Data {
            path: path.into(),
            msg: msg.into(),
        }
    }
}

/// A number as a message shows it: as written for ordinary sizes, in scientific notation where
/// it would run to many digits (`1e300` rather than 301 digits, `-1` rather than `-1e0`).
pub fn short_number(v: f64) -> String {
    if v != 0.0 && v.is_finite() && !(1e-4..1e6).contains(&v.abs()) {
        format!("{v:e}")
    } else {
        format!("{v}")
    }
}
