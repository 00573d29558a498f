//! The calibration report in a real browser: headless Chromium, driven by
//! Playwright (`tests/browser/report.mjs`), opens the page written for the
//! paper's Table 2 as a phone and as a laptop would, and must see the verdict
//! and the charts with no console error, no script error and no network
//! request. Screenshots land in `target/test-screenshots/` for a person to look at.
//!
//! Needs Node.js ≥ 20, `npm ci` in `tests/browser` and Debian's chromium. Under
//! `CI=true` a missing one fails the test; elsewhere the test warns and returns.

mod common;

use std::fs;

use groundcal::calib::calibrate::{calibrate, CalibrationSettings};
use groundcal::output::ResultJson;
use groundcal::recording::planes::read_planes;
use groundcal::report::{write_report, Provenance};

#[test]
fn report_opens_cleanly_in_chromium_on_a_phone_and_a_laptop() {
    if !common::browser_ready("report_browser") {
        return;
    }

    let input = common::test_data("paper-table2-printed.json");
    let observations = read_planes(&input).expect("Table 2 reads");
    let calibration =
        calibrate(&observations, &CalibrationSettings::default()).expect("Table 2 solves");
    let result = ResultJson::from_calibration(&calibration);
    // The report labels the digest BLAKE3, as `replay` computes it.
    let digest = blake3::hash(&fs::read(&input).unwrap())
        .to_hex()
        .to_string();
    let provenance = Provenance::now("tests/data/paper-table2-printed.json", digest);

    let dir = common::temp_dir("report-browser");
    let html = write_report(&dir.join("report"), &result, &provenance).expect("report written");

    let shots = common::root().join("target/test-screenshots");
    fs::create_dir_all(&shots).expect("screenshot directory");
    let png = shots.join("report.png");
    let _ = fs::remove_file(&png);

    let seen = common::run_browser_script("report.mjs", &[html.as_os_str(), png.as_os_str()]);
    let views = seen["seen"].as_array().expect("views");
    assert_eq!(views.len(), 2, "{seen}");
    for view in views {
        assert_eq!(view["verdict"], "REJECTED", "{view}");
        assert!(view["rendered"].as_u64().unwrap() >= 4, "{view}");
    }
    for name in ["report.png", "report-desktop.png"] {
        let bytes = fs::read(shots.join(name)).expect("screenshot saved");
        assert!(
            bytes.len() > 1000 && bytes.starts_with(b"\x89PNG\r\n\x1a\n"),
            "{name} is not a PNG with content"
        );
    }
    fs::remove_dir_all(&dir).unwrap();
}
