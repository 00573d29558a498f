//! Hardware abstraction for groundcal.
//!
//! The calibration session talks to hardware only through small traits, in the
//! manner of embedded-hal: a depth sensor (the Kinect) and a body controller (the
//! robot's lower computer). Each trait's error exposes a [`ErrorKind`] so that the
//! session can act on a failure (retry, abort and send the robot home, ask the
//! operator) without knowing which implementation produced it.
//!
//! This crate holds the vocabulary shared by every implementation. The traits and
//! their implementations (libfreenect, UDP, simulated, replayed) are the subject of
//! the hardware-layer issue and are added here as they land.

#![forbid(unsafe_code)]

pub mod depth;
pub mod geometry;

/// What went wrong with a piece of hardware, in terms a caller can act on.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash)]
#[non_exhaustive]
pub enum ErrorKind {
    /// No answer within the allowed time; the operation may be retried.
    Timeout,
    /// The link to the device is gone (retries exhausted, cable pulled).
    LinkLost,
    /// The device answered but refused the request (limits, state).
    Refused,
    /// The device, or the library that drives it, is not present.
    DeviceMissing,
    /// The device sent something that does not follow its protocol.
    Protocol,
    /// Anything else.
    Other,
}

impl ErrorKind {
    /// A short operator-facing description of the kind.
    pub fn describe(self) -> &'static str {
        match self {
            ErrorKind::Timeout => "no answer in time",
            ErrorKind::LinkLost => "link lost",
            ErrorKind::Refused => "request refused",
            ErrorKind::DeviceMissing => "device or driver missing",
            ErrorKind::Protocol => "protocol violation",
            ErrorKind::Other => "hardware error",
        }
    }
}

/// Implemented by every hardware error so that generic code can classify it.
pub trait Error: std::error::Error {
    /// The kind of this error.
    fn kind(&self) -> ErrorKind;
}

impl Error for std::convert::Infallible {
    fn kind(&self) -> ErrorKind {
        match *self {}
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn every_kind_has_distinct_words() {
        let kinds = [
            ErrorKind::Timeout,
            ErrorKind::LinkLost,
            ErrorKind::Refused,
            ErrorKind::DeviceMissing,
            ErrorKind::Protocol,
            ErrorKind::Other,
        ];
        let mut words: Vec<_> = kinds.iter().map(|k| k.describe()).collect();
        words.sort();
        words.dedup();
        assert_eq!(words.len(), kinds.len());
    }
}
