//! Reading groundcal's input files (`shared/spec/recording.md`).
//!
//! Readers are strict: every defect is an [`InputError`] naming the file, the
//! line where known, and what was expected. Nothing half-read is returned.

pub mod planes;

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
        match self.line {
            Some(line) => write!(f, "{}:{}: {}", self.path.display(), line, self.message),
            None => write!(f, "{}: {}", self.path.display(), self.message),
        }
    }
}

impl std::error::Error for InputError {}

/// Reads a whole file, refusing ones too large to be an input of this kind.
pub fn read_bounded(path: &Path, max_bytes: u64) -> Result<Vec<u8>, InputError> {
    use std::io::Read;
    let file = std::fs::File::open(path)
        .map_err(|e| InputError::new(path, None, format!("cannot open: {e}")))?;
    let mut bytes = Vec::new();
    file.take(max_bytes + 1)
        .read_to_end(&mut bytes)
        .map_err(|e| InputError::new(path, None, format!("cannot read: {e}")))?;
    if bytes.len() as u64 > max_bytes {
        return Err(InputError::new(
            path,
            None,
            format!("larger than {max_bytes} bytes: not an input of this kind"),
        ));
    }
    Ok(bytes)
}
