//! Errors are values. Every error names what was wrong and where.
//!
//! Exports: [`Error`] and [`Result`], and the checks of configuration values that fail with
//! an [`Error::Invalid`] naming the field: [`finite`], [`positive`], [`non_negative`],
//! [`unit`](fn@unit), [`all_finite`].

use std::path::PathBuf;

/// The library's error type.
#[derive(Debug, thiserror::Error)]
pub enum Error {
    /// The operating system refused a read or write.
    #[error("{path}: {source}")]
    Io {
        /// The file or directory.
        path: PathBuf,
        /// What the operating system said.
        #[source]
        source: std::io::Error,
    },
    /// A file (or a message inside a log) is not what its format says it must be.
    /// `location` says where: a byte offset, a header line, an element index, a topic.
    #[error("{path}: {location}: {message}")]
    Format {
        /// The file (or log) read.
        path: PathBuf,
        /// Where in it.
        location: String,
        /// What was wrong.
        message: String,
    },
    /// A parameter or configuration value that cannot be used (zero resolution, NaN pose...).
    #[error("invalid {what}: {message}")]
    Invalid {
        /// The parameter or value.
        what: String,
        /// Why it cannot be used.
        message: String,
    },
    /// A stop was requested (SIGINT, see [`crate::interrupt`]) while doing the named work;
    /// nothing was written.
    #[error("interrupted while {0}: the previous outputs are kept")]
    Interrupted(String),
}

impl Error {
    /// An [`Error::Io`] at `path`.
    pub fn io(path: impl Into<PathBuf>, source: std::io::Error) -> Self {
        Error::Io {
            path: path.into(),
            source,
        }
    }

    /// An [`Error::Format`] in `path` at `location`.
    pub fn format(
        path: impl Into<PathBuf>,
        location: impl Into<String>,
        message: impl Into<String>,
    ) -> Self {
        Error::Format {
            path: path.into(),
            location: location.into(),
            message: message.into(),
        }
    }

    /// An [`Error::Invalid`] of `what`.
    pub fn invalid(what: impl Into<String>, message: impl Into<String>) -> Self {
        Error::Invalid {
            what: what.into(),
            message: message.into(),
        }
    }
}

pub use check::{all_finite, finite, non_negative, positive, unit};

/// The library's result type.
pub type Result<T, E = Error> = std::result::Result<T, E>;

/// Checks of configuration values: each failure an [`Error::Invalid`] that names the field
/// (`what`) and says what the value must be. The crate calls them as `check::positive`; they
/// are public as `error::positive` and so on.
pub(crate) mod check {
    use super::{Error, Result};

    /// `v` is finite.
    pub fn finite(what: &str, v: f64) -> Result<()> {
        if v.is_finite() {
            Ok(())
        } else {
            Err(Error::invalid(what, format!("{v} is not finite")))
        }
    }

    /// `v` is finite and > 0.
    pub fn positive(what: &str, v: f64) -> Result<()> {
        if v.is_finite() && v > 0.0 {
            Ok(())
        } else {
            Err(Error::invalid(
                what,
                format!("{v} must be a finite number > 0"),
            ))
        }
    }

    /// `v` is finite and ≥ 0.
    pub fn non_negative(what: &str, v: f64) -> Result<()> {
        if v.is_finite() && v >= 0.0 {
            Ok(())
        } else {
            Err(Error::invalid(
                what,
                format!("{v} must be a finite number ≥ 0"),
            ))
        }
    }

    /// `v` is in 0..=1.
    pub fn unit(what: &str, v: f64) -> Result<()> {
        if (0.0..=1.0).contains(&v) {
            Ok(())
        } else {
            Err(Error::invalid(what, format!("{v} must be in 0..1")))
        }
    }

    /// Every value of `v` is finite.
    pub fn all_finite(what: &str, v: &[f64]) -> Result<()> {
        v.iter().try_for_each(|x| finite(what, *x))
    }
}
