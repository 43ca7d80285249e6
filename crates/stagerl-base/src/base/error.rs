//! The library's error type.

use std::path::PathBuf;

/// Every failure the library reports. Messages name the field, joint, link or input at fault,
/// the offending value, and what would have been accepted.
#[derive(Debug, thiserror::Error)]
pub enum Error {
    /// A configuration value out of its allowed range.
    #[error("config: `{field}` = {value} is invalid: {allowed}")]
    Config { field: String, value: String, allowed: String },
    /// A configuration file that does not parse or has unknown fields or wrong types.
    #[error("config file {path}: {message}")]
    ConfigParse { path: PathBuf, message: String },
    /// A URDF that cannot be turned into a serial chain.
    #[error("URDF: {0}")]
    Urdf(String),
    /// Input to a function that is outside its domain (wrong length, non-finite value, ...).
    #[error("invalid input: {0}")]
    InvalidInput(String),
    /// Training stopped on request (SIGINT/SIGTERM); the state was saved to `checkpoint`.
    #[error("interrupted at episode {episode}; the run was saved to {checkpoint} and can be resumed")]
    Interrupted { episode: u64, checkpoint: PathBuf },
    /// A stop request (SIGINT/SIGTERM) ended `what` (an evaluation, say) before it finished;
    /// nothing of it was written.
    #[error("stopped during {what} on request; nothing of it was written")]
    Stopped { what: String },
    /// A loss, gradient or parameter became NaN or infinite.
    #[error("numerical fault: {0}")]
    NumericalFault(String),
    /// A run or sweep directory is being written by another process (it holds the directory's
    /// advisory lock, released when that process ends, even by SIGKILL).
    #[error(
        "{} is in use by another stagerl process{}: wait for it to finish or stop it (lock file {})",
        dir.display(),
        holder.map(|p| format!(" (pid {p})")).unwrap_or_default(),
        lock_file.display()
    )]
    Locked { dir: PathBuf, holder: Option<u32>, lock_file: PathBuf },
    /// A file could not be read or written. (The OS error is part of the message, not a chained
    /// source, so that `{:#}` does not print it twice.)
    #[error("{}: {error}", path.display())]
    Io { path: PathBuf, error: std::io::Error },
}

impl Error {
    /// Shorthand for [`Error::Config`].
    pub fn config(field: impl Into<String>, value: impl ToString, allowed: impl Into<String>) -> Self {
        // The value is echoed input: an excerpt of it.
        Error::Config {
            field: field.into(),
            value: crate::base::text::excerpt(&value.to_string()),
            allowed: allowed.into(),
        }
    }

    /// Shorthand for [`Error::Io`].
    pub fn io(path: impl Into<PathBuf>, error: std::io::Error) -> Self {
        Error::Io { path: path.into(), error }
    }
}

/// The library's result type.
pub type Result<T, E = Error> = std::result::Result<T, E>;
