//! The fakenect dump (`kinect/`), as written by libfreenect's `fakenect-record`
//! (its `fakenect/record.c`): `INDEX.txt` and one file per frame or state.

use std::path::Path;

use super::InputError;

/// What a dump file holds, from the first letter of its name.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum EntryKind {
    Depth,
    Rgb,
    Accelerometer,
}

/// One file named in `INDEX.txt`: `<type>-<time>-<timestamp>.<ext>`.
#[derive(Debug, Clone, PartialEq)]
pub struct DumpEntry {
    pub name: String,
    pub kind: EntryKind,
    /// Seconds, as printed by `%f`; playback waits for the differences.
    pub time: f64,
    /// The Kinect's frame timestamp.
    pub timestamp: u32,
}

/// Parses a dump file name.
pub fn parse_entry_name(name: &str) -> Result<DumpEntry, String> {
    let (stem, ext) = name
        .rsplit_once('.')
        .ok_or_else(|| format!("\"{name}\" has no extension"))?;
    let mut parts = stem.splitn(3, '-');
    let (kind, time, timestamp) = match (parts.next(), parts.next(), parts.next()) {
        (Some(k), Some(t), Some(s)) => (k, t, s),
        _ => return Err(format!("\"{name}\" is not <type>-<time>-<timestamp>.<ext>")),
    };
    let kind = match (kind, ext) {
        ("d", "pgm") => EntryKind::Depth,
        ("r", "ppm") => EntryKind::Rgb,
        ("a", "dump") => EntryKind::Accelerometer,
        _ => return Err(format!("\"{name}\": type \"{kind}\" with extension \".{ext}\" is not d/.pgm, r/.ppm or a/.dump")),
    };
    let time: f64 = time
        .parse()
        .ok()
        .filter(|t: &f64| t.is_finite() && *t >= 0.0)
        .ok_or_else(|| format!("\"{name}\": time \"{time}\" is not a number of seconds"))?;
    let timestamp: u32 = timestamp
        .parse()
        .map_err(|_| format!("\"{name}\": timestamp \"{timestamp}\" is not an unsigned integer"))?;
    Ok(DumpEntry {
        name: name.to_string(),
        kind,
        time,
        timestamp,
    })
}

/// The most files an `INDEX.txt` may name: as many as [`MAX_POSES`] poses
/// of 30 depth frames and 10 accelerometer readings name, and as many colour
/// frames again (fakenect records those too), with room to spare.
///
/// [`MAX_POSES`]: super::poses::MAX_POSES
pub const MAX_INDEX_ENTRIES: usize = 200_000;

/// Parses `INDEX.txt`: one file name per line, in capture order.
///
/// A recorder appends a name after its file is written, so a last line cut
/// off by power loss (no newline, not a valid name) is left out rather than
/// condemning the whole recording.
pub fn parse_index(path: &Path, text: &str) -> Result<Vec<DumpEntry>, InputError> {
    let mut entries = Vec::new();
    // Lines are not collected: a file of newlines would cost 16 bytes a line.
    let mut lines = text.split_inclusive('\n').enumerate().peekable();
    while let Some((k, raw)) = lines.next() {
        let last = lines.peek().is_none();
        let line = raw.trim_end_matches('\n');
        if line.is_empty() {
            continue;
        }
        if entries.len() == MAX_INDEX_ENTRIES {
            return Err(InputError::new(
                path,
                Some(k + 1),
                format!(
                    "more than {MAX_INDEX_ENTRIES} files: a recording's poses name at most {} (its depth frames and accelerometer readings), and a dump of that length holds about as many colour frames",
                    MAX_INDEX_ENTRIES / 2
                ),
            ));
        }
        match parse_entry_name(line) {
            Ok(entry) => entries.push(entry),
            Err(_) if last && !raw.ends_with('\n') => break,
            Err(e) => return Err(InputError::new(path, Some(k + 1), e)),
        }
    }
    Ok(entries)
}

/// `freenect_raw_tilt_state`: the accelerometer and tilt motor (12 bytes,
/// little-endian).
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct RawTiltState {
    /// 819 counts are 1 g.
    pub accelerometer: [i16; 3],
    /// Tilt angle in half degrees.
    pub tilt_angle: i8,
    /// 0 stopped, 1 at limit, 4 moving.
    pub tilt_status: i32,
}

/// Size of a `freenect_raw_tilt_state` dump.
pub const RAW_TILT_STATE_BYTES: usize = 12;

impl RawTiltState {
    /// Parses a 12-byte state dump.
    pub fn parse(path: &Path, bytes: &[u8]) -> Result<Self, InputError> {
        let b: [u8; RAW_TILT_STATE_BYTES] = bytes.try_into().map_err(|_| {
            InputError::new(
                path,
                None,
                format!(
                    "a tilt state is {RAW_TILT_STATE_BYTES} bytes, this file has {}",
                    bytes.len()
                ),
            )
        })?;
        Ok(Self {
            accelerometer: [
                i16::from_le_bytes([b[0], b[1]]),
                i16::from_le_bytes([b[2], b[3]]),
                i16::from_le_bytes([b[4], b[5]]),
            ],
            tilt_angle: i8::from_le_bytes([b[6]]),
            tilt_status: i32::from_le_bytes([b[8], b[9], b[10], b[11]]),
        })
    }

    /// The raw state `fakenect-record` would have written for `state` (819
    /// counts per g, half degrees, 0 stopped / 4 moving).
    pub fn from_state(state: &groundcal_hal::TiltState) -> Self {
        let counts = |g: f64| (g * 819.0).round().clamp(-32768.0, 32767.0) as i16;
        RawTiltState {
            accelerometer: state.accelerometer_g.map(counts),
            tilt_angle: (state.tilt_deg * 2.0).round().clamp(-128.0, 127.0) as i8,
            tilt_status: if state.stopped { 0 } else { 4 },
        }
    }

    /// The state as the sensor reports it (g, degrees).
    pub fn state(&self) -> groundcal_hal::TiltState {
        groundcal_hal::TiltState {
            tilt_deg: f64::from(self.tilt_angle) / 2.0,
            accelerometer_g: self.accelerometer.map(|c| f64::from(c) / 819.0),
            stopped: self.tilt_status != 4,
        }
    }

    /// The 12 bytes of the state (padding byte 0).
    pub fn encode(&self) -> [u8; RAW_TILT_STATE_BYTES] {
        let mut b = [0u8; RAW_TILT_STATE_BYTES];
        for (k, a) in self.accelerometer.iter().enumerate() {
            b[2 * k..2 * k + 2].copy_from_slice(&a.to_le_bytes());
        }
        b[6] = self.tilt_angle.to_le_bytes()[0];
        b[8..12].copy_from_slice(&self.tilt_status.to_le_bytes());
        b
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn names_of_the_sample_dump_parse() {
        let e = parse_entry_name("d-1700000000.001000-2001000.pgm").unwrap();
        assert_eq!(e.kind, EntryKind::Depth);
        assert!((e.time - 1700000000.001).abs() < 1e-6);
        assert_eq!(e.timestamp, 2001000);
        assert_eq!(
            parse_entry_name("a-1.5-7.dump").unwrap().kind,
            EntryKind::Accelerometer
        );
        assert!(parse_entry_name("d-1-2.ppm").is_err());
        assert!(parse_entry_name("x-1-2.pgm").is_err());
        assert!(parse_entry_name("d-abc-2.pgm").is_err());
        assert!(parse_entry_name("d-1--2.pgm").is_err());
        assert!(parse_entry_name("d-1.pgm").is_err());
    }

    #[test]
    fn index_errors_name_the_line() {
        let err = parse_index(Path::new("INDEX.txt"), "d-1-2.pgm\nbogus\n").unwrap_err();
        assert_eq!(err.line, Some(2));
    }

    /// An INDEX longer than any recording's is refused at the line past the
    /// bound, before its entries fill the memory; blank lines cost nothing.
    #[test]
    fn an_index_longer_than_any_recordings_is_refused() {
        let line = "d-1-2.pgm\n";
        let mut text = line.repeat(MAX_INDEX_ENTRIES);
        assert_eq!(
            parse_index(Path::new("INDEX.txt"), &text).unwrap().len(),
            MAX_INDEX_ENTRIES
        );
        text.push_str(&"\n".repeat(1000));
        text.push_str(line);
        let err = parse_index(Path::new("INDEX.txt"), &text).unwrap_err();
        assert_eq!(err.line, Some(MAX_INDEX_ENTRIES + 1001), "{err}");
        assert!(err.message.contains("more than 200000 files"), "{err}");
    }

    #[test]
    fn a_torn_last_index_line_is_left_out() {
        let entries = parse_index(Path::new("INDEX.txt"), "d-1-2.pgm\nd-1.5-3.p").unwrap();
        assert_eq!(entries.len(), 1);
    }

    #[test]
    fn tilt_state_round_trips() {
        let s = RawTiltState {
            accelerometer: [0, 819, -3],
            tilt_angle: -40,
            tilt_status: 4,
        };
        assert_eq!(RawTiltState::parse(Path::new("a"), &s.encode()).unwrap(), s);
        assert!(RawTiltState::parse(Path::new("a"), &[0; 11]).is_err());
    }
}
