//! Typed errors of the library. Every variant names the file (or the input) and what is
//! wrong, so the binaries can print one line and exit non-zero.

use std::path::PathBuf;

/// Everything the library can fail with.
#[derive(Debug, thiserror::Error)]
pub enum Error {
    /// Reading or writing a file failed at the operating-system level.
    #[error("{path}: {source}")]
    Io {
        path: PathBuf,
        #[source]
        source: std::io::Error,
    },
    /// A URDF that cannot be used: bad XML, an unsupported joint type, a broken tree.
    /// `element` names the offending element (`joint "L1_L2"`, `link "base"`, ...).
    #[error("{path}: {element}: {msg}")]
    Urdf {
        path: PathBuf,
        element: String,
        msg: String,
    },
    /// A mesh file that is missing or cannot be parsed.
    #[error("{path}: {msg}")]
    Mesh { path: PathBuf, msg: String },
    /// A data file (npz, CSV) whose content is wrong: missing keys, shapes, dtypes, NaNs.
    #[error("{path}: {msg}")]
    Data { path: PathBuf, msg: String },
    /// An impossible configuration or argument (zero samples, a split larger than the data).
    #[error("{0}")]
    Config(String),
    /// A `--device` that was not compiled in or cannot start.
    #[error("{0}")]
    Device(String),
    /// Training that cannot go on (a loss that became NaN or infinite).
    #[error("{0}")]
    Training(String),
    /// Training that collapsed to a trivial solution (FFKSM's all-black image) at `step`;
    /// the caller may restart with a fresh model.
    #[error("training collapsed to an all-black image at step {step}")]
    Collapsed { step: usize },
    /// Stopped by Ctrl-C: what was saved and how to continue.
    #[error("{0}")]
    Interrupted(String),
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
