//! Errors of hardware, classified so that generic code can act on them.

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
