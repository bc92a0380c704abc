//! Errors of the core. Every problem with user input is an [`InputError`]: it names the file
//! (or the scene key) and says what is wrong in one line, so the CLI can print it and exit 2
//! and the app can show it without losing anything the user made.

use std::path::{Path, PathBuf};
use std::sync::atomic::{AtomicBool, Ordering};

/// A problem with something the user supplied: a file, a folder or a value in one.
#[derive(Debug, Clone, thiserror::Error, PartialEq)]
#[error("{}: {problem}", path.display())]
pub struct InputError {
    /// The file (or folder) at fault, as the user would recognise it.
    pub path: PathBuf,
    /// What is wrong, in words, without the path.
    pub problem: String,
}

impl InputError {
    pub fn new(path: impl AsRef<Path>, problem: impl Into<String>) -> Self {
        Self {
            path: path.as_ref().to_path_buf(),
            problem: problem.into(),
        }
    }
}

/// Everything the core can fail with.
#[derive(Debug, thiserror::Error)]
pub enum Error {
    /// Bad input: exit code 2 at the CLI.
    #[error(transparent)]
    Input(#[from] InputError),
    /// Writing an output failed (disk full, permissions): not the input's fault.
    #[error("{}: cannot write: {source}", path.display())]
    Write {
        path: PathBuf,
        #[source]
        source: std::io::Error,
    },
    /// Removing a file failed (an autosave no longer needed).
    #[error("{}: cannot remove: {source}", path.display())]
    Remove {
        path: PathBuf,
        #[source]
        source: std::io::Error,
    },
    /// The user cancelled long work.
    #[error("cancelled")]
    Cancelled,
}

pub type Result<T, E = Error> = std::result::Result<T, E>;

/// Err(Cancelled) once the user set `cancel`: long work reads it between its pieces, and a
/// piece cut short is not a result.
pub fn stop_if_cancelled(cancel: Option<&AtomicBool>) -> Result<()> {
    if cancel.is_some_and(|c| c.load(Ordering::Relaxed)) {
        Err(Error::Cancelled)
    } else {
        Ok(())
    }
}

/// Shorthand for an [`InputError`] wrapped in [`Error`].
pub fn input_err(path: impl AsRef<Path>, problem: impl Into<String>) -> Error {
    Error::Input(InputError::new(path, problem))
}

/// Refuses what is not a regular file (after links): reading a named pipe blocks until
/// something writes to it, and a device such as /dev/zero never ends.
pub fn regular_file(path: &Path) -> std::io::Result<()> {
    let meta = std::fs::metadata(path)?;
    if meta.is_file() {
        return Ok(());
    }
    Err(std::io::Error::new(
        std::io::ErrorKind::InvalidInput,
        if meta.is_dir() {
            "is a folder, not a file"
        } else {
            "is not a regular file (a pipe or a device)"
        },
    ))
}

/// A text file's contents without a leading UTF-8 byte-order mark (some Windows tools write
/// one before JSON; CONTRACT §2 accepts it).
pub fn read_text(path: &Path) -> std::io::Result<String> {
    regular_file(path)?;
    let text = std::fs::read_to_string(path)?;
    Ok(match text.strip_prefix('\u{feff}') {
        Some(rest) => rest.to_string(),
        None => text,
    })
}
