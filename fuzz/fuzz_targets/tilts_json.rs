//! A recording at several tilts: `tilts.json` (`tilts::parse_tilts_file`).
#![no_main]

use groundcal::solving::tilts::parse_tilts_file;
use groundcal_fuzz::{check_input_error, path, text_of};
use libfuzzer_sys::fuzz_target;

fuzz_target!(|data: &[u8]| {
    let text = text_of(data);
    let file = match parse_tilts_file(path(), &text) {
        Err(e) => return check_input_error(&e, &text),
        Ok(file) => file,
    };
    // What parse promises about a file it returns.
    assert_eq!(file.format, "groundcal-tilts");
    // Within the bound (`tilts::MAX_TILTS`), each tilt in the motor's range,
    // 1° or more from the others, in a directory of its own.
    assert!((2..=groundcal::solving::tilts::MAX_TILTS).contains(&file.tilts.len()));
    for (k, t) in file.tilts.iter().enumerate() {
        assert!(t.tilt_deg.is_finite() && t.tilt_deg.abs() <= 27.0);
        assert!(!t.dir.is_empty() && !t.dir.contains('/') && t.dir != "..");
        for u in &file.tilts[..k] {
            assert!((u.tilt_deg - t.tilt_deg).abs() >= 1.0 && u.dir != t.dir);
        }
    }
    // Written back out it reads back the same: the same directories, and
    // the same tilts to the last bit or two (serde_json's float parsing is
    // not correctly rounded for every decimal, e.g. "-50.330000002e-30";
    // the reproducer is kept in the corpus).
    let written = serde_json::to_string(&file).expect("a tilts file serialises");
    let again = parse_tilts_file(path(), &written)
        .unwrap_or_else(|e| panic!("a written tilts file does not read back: {e}\n{written}"));
    assert_eq!(file.tilts.len(), again.tilts.len());
    for (a, b) in file.tilts.iter().zip(&again.tilts) {
        assert_eq!(a.dir, b.dir);
        assert!((a.tilt_deg - b.tilt_deg).abs() <= 1e-12 * a.tilt_deg.abs().max(1e-300));
    }
});
