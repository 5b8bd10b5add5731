//! Typed errors of the library. Every error that user input can cause names where it came from.

use std::path::PathBuf;

#[derive(Debug, thiserror::Error)]
pub enum Error {
    #[error("{file}: {msg}")]
    Scene { file: PathBuf, msg: String },
    #[error("{file}:{line}:{col}: {msg}")]
    SceneAt { file: PathBuf, line: u32, col: u32, msg: String },
    #[error("{file}: cannot read: {source}")]
    Io { file: PathBuf, source: std::io::Error },
    #[error("{file}: {msg}")]
    Mesh { file: PathBuf, msg: String },
    #[error("{file}: {msg}")]
    Image { file: PathBuf, msg: String },
    /// A luminaire file (IES, EULUMDAT) or its tilt file; `line` is 1-based.
    #[error("{file}:{line}: {msg}")]
    Photometry { file: PathBuf, line: u32, msg: String },
    #[error("invalid setting: {0}")]
    Settings(String),
    #[error("invalid scene: {0}")]
    Invalid(String),
    /// Something would need more memory than the budget allows (`limits::max_memory`).
    #[error("{what} would need {} of memory, over the budget of {} (raise it with --max-memory)", crate::limits::human(*bytes), crate::limits::human(*limit))]
    TooLarge { what: String, bytes: u64, limit: u64 },
    #[error("light path expression: {0}")]
    Lpe(#[from] crate::lpe::LpeError),
}

pub type Result<T> = std::result::Result<T, Error>;
