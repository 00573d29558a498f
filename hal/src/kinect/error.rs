//! The Kinect's errors: a kind the session acts on, and a message for people.

use std::fmt;

use crate::error::{Error, ErrorKind};

/// Debian's package that ships libfreenect (and its fakenect build).
pub const LIBFREENECT_PACKAGE: &str = "libfreenect0.5";

/// What went wrong with the Kinect or libfreenect.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct KinectError {
    kind: ErrorKind,
    message: String,
    library_missing: bool,
}

impl KinectError {
    pub(crate) fn new(kind: ErrorKind, message: impl Into<String>) -> Self {
        Self {
            kind,
            message: message.into(),
            library_missing: false,
        }
    }

    /// libfreenect itself could not be loaded (kind [`ErrorKind::DeviceMissing`]).
    pub(crate) fn missing_library(message: impl Into<String>) -> Self {
        Self {
            library_missing: true,
            ..Self::new(ErrorKind::DeviceMissing, message)
        }
    }

    /// Whether libfreenect could not be loaded (rather than the Kinect
    /// being absent or failing).
    pub fn is_library_missing(&self) -> bool {
        self.library_missing
    }

    /// The operator-facing message.
    pub fn message(&self) -> &str {
        &self.message
    }

    /// libfreenect's event loop has ended (the Kinect is gone, or a fakenect
    /// dump has been played to its end).
    pub(crate) fn link_lost(message: impl Into<String>) -> Self {
        Self::new(ErrorKind::LinkLost, message)
    }

    /// A libfreenect call returned an error code.
    pub(crate) fn call(kind: ErrorKind, function: &str, code: i32, what: &str) -> Self {
        Self::new(kind, format!("{what}: {function} returned {code}"))
    }
}

impl fmt::Display for KinectError {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        f.write_str(&self.message)
    }
}

impl std::error::Error for KinectError {}

impl Error for KinectError {
    fn kind(&self) -> ErrorKind {
        self.kind
    }
}
