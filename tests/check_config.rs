//! `groundcal check-config` on every shipped configuration, and on broken ones.

mod common;

use common::groundcal;

/// A shipped configuration as installed: beside its schedules, with its
/// token file (which the package creates) present.
fn installed_copy(path: &std::path::Path, dir: &std::path::Path) -> std::path::PathBuf {
    let root = std::path::Path::new(env!("CARGO_MANIFEST_DIR"));
    let token = dir.join("token");
    std::fs::write(&token, "a-token\n").unwrap();
    let text: String = std::fs::read_to_string(path)
        .unwrap()
        .lines()
        .map(|line| {
            if line.starts_with("token_file") {
                format!("token_file = \"{}\"", token.display())
            } else if line.starts_with("schedule = \"schedules/") {
                line.replace(
                    "schedules/",
                    &format!("{}/config/schedules/", root.display()),
                )
            } else {
                line.to_string()
            }
        })
        .map(|line| line + "\n")
        .collect();
    let copy = dir.join(path.file_name().unwrap());
    std::fs::write(&copy, text).unwrap();
    copy
}

#[test]
fn every_shipped_configuration_passes_check_config() {
    let dir = std::path::Path::new(env!("CARGO_MANIFEST_DIR")).join("config");
    let scratch = common::TempDir::new("check-config-shipped");
    let mut checked = 0;
    for entry in std::fs::read_dir(&dir).unwrap() {
        let path = entry.unwrap().path();
        if path.extension().is_some_and(|e| e == "toml") {
            let path = installed_copy(&path, scratch.path());
            let (code, stdout, stderr) = groundcal(&["check-config", path.to_str().unwrap()]);
            assert_eq!(code, 0, "{}: {stderr}", path.display());
            assert!(stdout.contains("valid"));
            checked += 1;
        }
    }
    assert!(checked >= 2);
}

/// `serve` refuses a configuration whose token it cannot read, so
/// `check-config` does too, naming the key and the file.
#[test]
fn a_configuration_that_serves_without_a_readable_token_is_refused() {
    let scratch = common::TempDir::new("check-config-token");
    let shipped = std::path::Path::new(env!("CARGO_MANIFEST_DIR")).join("config/groundcal.toml");
    let config = installed_copy(&shipped, scratch.path());
    let token = scratch.path().join("token");
    for (what, setup) in [("missing", None), ("empty", Some(" \n"))] {
        match setup {
            None => std::fs::remove_file(&token).unwrap(),
            Some(text) => std::fs::write(&token, text).unwrap(),
        }
        let (code, stdout, stderr) = groundcal(&["check-config", config.to_str().unwrap()]);
        assert_eq!(code, 2, "{what}: {stdout}");
        assert!(
            stderr.contains("serve.token_file") && stderr.contains(token.to_str().unwrap()),
            "{what}: {stderr}"
        );
    }
}

/// The token file is read with a bound and only as a regular file: a
/// device that never ends (`/dev/zero` grew `check-config` to 24 GB before
/// the kernel killed it) or a FIFO that never opens is refused at once,
/// named, with exit 2; so is a file too large to be a token.
#[test]
fn a_token_file_that_is_not_a_small_regular_file_is_refused_at_once() {
    let scratch = common::TempDir::new("check-config-token-kinds");
    let shipped = std::path::Path::new(env!("CARGO_MANIFEST_DIR")).join("config/groundcal.toml");
    let config = installed_copy(&shipped, scratch.path());
    let fifo = scratch.path().join("token-fifo");
    assert!(std::process::Command::new("mkfifo")
        .arg(&fifo)
        .status()
        .unwrap()
        .success());
    let large = scratch.path().join("token-large");
    std::fs::write(&large, vec![b'a'; 1 << 20]).unwrap();
    let text = std::fs::read_to_string(&config).unwrap();
    for (token_file, expected) in [
        ("/dev/zero".to_string(), "a character device"),
        (fifo.display().to_string(), "a FIFO"),
        (large.display().to_string(), "larger than 4096 bytes"),
    ] {
        let text: String = text
            .lines()
            .map(|line| {
                if line.starts_with("token_file") {
                    format!("token_file = \"{token_file}\"\n")
                } else {
                    format!("{line}\n")
                }
            })
            .collect();
        std::fs::write(&config, text).unwrap();
        let (code, _, stderr) = common::groundcal_within(
            &["check-config", config.to_str().unwrap()],
            std::time::Duration::from_secs(10),
        );
        assert_eq!(code, 2, "{token_file} (-1: killed after 10 s): {stderr}");
        assert!(
            stderr.contains("serve.token_file")
                && stderr.contains(&token_file)
                && stderr.contains(expected),
            "{token_file}: {stderr}"
        );
    }
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
