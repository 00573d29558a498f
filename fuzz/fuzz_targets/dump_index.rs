//! The fakenect dump: `kinect/INDEX.txt` (`recording::dump::parse_index`), the
//! file names in it (`parse_entry_name`) and the accelerometer/tilt state files
//! (`RawTiltState::parse`).
#![no_main]

use groundcal::formats::recording::dump::{
    parse_entry_name, parse_index, DumpEntry, EntryKind, RawTiltState, RAW_TILT_STATE_BYTES,
};
use groundcal::formats::recording::writer::entry_name;
use groundcal_fuzz::{check_input_error, path, text_of};
use libfuzzer_sys::fuzz_target;

/// What every parsed name must satisfy, and that the name the recorder would
/// write for the same entry (`%c-%f-%u.%s`) parses to the same entry.
fn check_entry(entry: &DumpEntry) {
    let (letter, extension) = match entry.kind {
        EntryKind::Depth => ('d', "pgm"),
        EntryKind::Rgb => ('r', "ppm"),
        EntryKind::Accelerometer => ('a', "dump"),
    };
    assert!(
        entry.name.starts_with(letter) && entry.name.ends_with(extension),
        "{:?} parsed as {:?}",
        entry.name,
        entry.kind
    );
    assert!(
        entry.time.is_finite() && entry.time >= 0.0,
        "{:?}: time {}",
        entry.name,
        entry.time
    );
    let written = entry_name(letter, entry.time, entry.timestamp, extension);
    let again = parse_entry_name(&written).unwrap_or_else(|e| {
        panic!(
            "{:?} written as {written:?} does not parse: {e}",
            entry.name
        )
    });
    assert_eq!(again.kind, entry.kind);
    assert_eq!(again.timestamp, entry.timestamp);
    // `%f` keeps six decimals.
    assert!(
        (again.time - entry.time).abs() <= 5.000_001e-7 + entry.time * f64::EPSILON,
        "{:?}: time {} written as {written:?} reads {}",
        entry.name,
        entry.time,
        again.time
    );
}

fuzz_target!(|data: &[u8]| {
    let text = text_of(data);

    match parse_index(path(), &text) {
        Err(e) => check_input_error(&e, &text),
        Ok(entries) => {
            let lines: Vec<&str> = text.split('\n').collect();
            assert!(entries.len() <= lines.len());
            for entry in &entries {
                assert!(
                    lines.contains(&entry.name.as_str()),
                    "{:?} is not a line of the index",
                    entry.name
                );
                check_entry(entry);
            }
        }
    }

    // The whole input as one name.
    if let Ok(entry) = parse_entry_name(&text) {
        assert_eq!(entry.name, text);
        check_entry(&entry);
    }

    // The bytes as a tilt state dump: exactly 12 bytes, whose encoding is the
    // same bytes with the padding byte (7) zeroed.
    match RawTiltState::parse(path(), data) {
        Ok(state) => {
            assert_eq!(data.len(), RAW_TILT_STATE_BYTES);
            let mut expected = [0u8; RAW_TILT_STATE_BYTES];
            expected.copy_from_slice(data);
            expected[7] = 0;
            assert_eq!(state.encode(), expected);
            assert_eq!(RawTiltState::parse(path(), &state.encode()).unwrap(), state);
        }
        Err(e) => {
            assert_ne!(data.len(), RAW_TILT_STATE_BYTES, "12 bytes refused: {e}");
            assert_eq!(e.path, path());
        }
    }
});
