//! `groundcal check-config` on every shipped configuration, and on broken ones.

mod common;

use common::groundcal;

#[test]
fn every_shipped_configuration_passes_check_config() {
    let dir = std::path::Path::new(env!("CARGO_MANIFEST_DIR")).join("config");
    let mut checked = 0;
    for entry in std::fs::read_dir(&dir).unwrap() {
        let path = entry.unwrap().path();
        if path.extension().is_some_and(|e| e == "toml") {
            let (code, stdout, stderr) = groundcal(&["check-config", path.to_str().unwrap()]);
            assert_eq!(code, 0, "{}: {stderr}", path.display());
            assert!(stdout.contains("valid"));
            checked += 1;
        }
    }
    assert!(checked >= 2);
}

#[test]
fn a_broken_configuration_is_named_with_its_line() {
    let path =
        std::env::temp_dir().join(format!("groundcal-bad-config-{}.toml", std::process::id()));
    let good = std::fs::read_to_string(
        std::path::Path::new(env!("CARGO_MANIFEST_DIR")).join("config/sim.toml"),
    )
    .unwrap();
    std::fs::write(
        &path,
        good.replace("settle_ms = 300", "settle_ms = 300\nsettle_time = 3"),
    )
    .unwrap();
    let (code, _, stderr) = groundcal(&["check-config", path.to_str().unwrap()]);
    let _ = std::fs::remove_file(&path);
    assert_eq!(code, 2);
    assert!(
        stderr.contains("settle_time") && stderr.contains(&format!("{}:", path.display())),
        "{stderr}"
    );
}
