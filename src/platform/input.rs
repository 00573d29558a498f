//! Bad input and how it is read: [`InputError`] names the file, the line
//! where known, and what was wrong (control characters escaped, so a name
//! read from a file cannot act on a terminal); input files are read whole
//! within a bound ([`read_bounded`]) and TOML parsed strictly
//! ([`parse_toml`]). The configuration, the schedules and the recordings
//! all read through here.

use std::fmt;
use std::path::{Path, PathBuf};

/// A defect in an input file.
#[derive(Debug, Clone, PartialEq)]
pub struct InputError {
    pub path: PathBuf,
    /// 1-based line, where known.
    pub line: Option<usize>,
    pub message: String,
}

impl InputError {
    pub fn new(path: &Path, line: Option<usize>, message: impl Into<String>) -> Self {
        Self {
            path: path.to_path_buf(),
            line,
            message: message.into(),
        }
    }
}

impl fmt::Display for InputError {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        // A message quotes what the file holds (a name in INDEX.txt, a key):
        // on a terminal its control characters would act, not show.
        let path = self.path.display().to_string();
        let (path, message) = (printable(&path), printable(&self.message));
        match self.line {
            Some(line) => write!(f, "{path}:{line}: {message}"),
            None => write!(f, "{path}: {message}"),
        }
    }
}

/// `text` with its control characters (ESC, NUL, a newline, …) written as
/// escapes (`\u{1b}`), so that text read from a file can be quoted on a
/// terminal without setting its title or clearing its screen; everything
/// else, non-ASCII letters and signs included, is left as it is.
pub fn printable(text: &str) -> std::borrow::Cow<'_, str> {
    if !text.chars().any(char::is_control) {
        return std::borrow::Cow::Borrowed(text);
    }
    let mut escaped = String::with_capacity(text.len() + 8);
    for c in text.chars() {
        if c.is_control() {
            escaped.extend(c.escape_default());
        } else {
            escaped.push(c);
        }
    }
    std::borrow::Cow::Owned(escaped)
}

impl std::error::Error for InputError {}

/// Parses strict TOML, turning toml's error into one that names the file and
/// the line (some of toml's errors carry no message of their own: the whole
/// report is used then).
pub fn parse_toml<T: serde::de::DeserializeOwned>(
    path: &Path,
    text: &str,
) -> Result<T, InputError> {
    toml::from_str(text).map_err(|e| {
        let line = e
            .span()
            .map(|span| text[..span.start.min(text.len())].lines().count().max(1));
        let message = if e.message().trim().is_empty() {
            e.to_string()
        } else {
            e.message().to_string()
        };
        InputError::new(path, line, message)
    })
}

/// Reads a whole file, refusing ones too large to be an input of this kind.
pub fn read_bounded(path: &Path, max_bytes: u64) -> Result<Vec<u8>, InputError> {
    let mut bytes = Vec::new();
    read_bounded_into(path, max_bytes, &mut bytes)?;
    Ok(bytes)
}

/// [`read_bounded`] into a buffer that is reused from file to file
/// ([`crate::platform::files::read_bounded_into`]), errors as the recording's.
pub fn read_bounded_into(
    path: &Path,
    max_bytes: u64,
    bytes: &mut Vec<u8>,
) -> Result<(), InputError> {
    use crate::platform::files::ReadError;
    crate::platform::files::read_bounded_into(path, max_bytes, bytes).map_err(|e| match e {
        ReadError::File(f) => {
            InputError::new(path, None, format!("cannot {}: {}", f.action, f.source))
        }
        ReadError::TooLarge { max_bytes, .. } => InputError::new(
            path,
            None,
            format!("larger than {max_bytes} bytes: not an input of this kind"),
        ),
    })
}
