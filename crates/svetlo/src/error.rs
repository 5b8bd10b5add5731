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
    #[error("invalid setting: {0}")]
    Settings(String),
    #[error("invalid scene: {0}")]
    Invalid(String),
    #[error("light path expression: {0}")]
    Lpe(#[from] crate::lpe::LpeError),
}

pub type Result<T> = std::result::Result<T, Error>;
