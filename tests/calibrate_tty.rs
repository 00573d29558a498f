//! `groundcal calibrate` as a technician sees it on a terminal: the README's
//! simulated calibration under a real pseudo-terminal of 80 columns
//! (util-linux `script`), its output played into a terminal emulator (the
//! `vt100` crate). The progress line must never wrap, and the screen must end
//! with the verdict and the six values, not the per-pose table.

use std::process::Command;

const COLUMNS: u16 = 80;
/// Tall enough that nothing scrolls away: the whole output stays on screen.
const ROWS: u16 = 200;

/// Every text segment the terminal drew: the output split where the cursor
/// returns to the line's start, without escape sequences.
fn drawn_segments(raw: &str) -> Vec<String> {
    let mut plain = String::new();
    let mut chars = raw.chars().peekable();
    while let Some(c) = chars.next() {
        if c == '\u{1b}' {
            // CSI: ESC [ parameters final-byte.
            if chars.peek() == Some(&'[') {
                chars.next();
                for c in chars.by_ref() {
                    if ('@'..='~').contains(&c) {
                        break;
                    }
                }
            } else {
                chars.next();
            }
        } else {
            plain.push(c);
        }
    }
    plain
        .split(['\n', '\r'])
        .map(str::to_string)
        .filter(|s| !s.trim().is_empty())
        .collect()
}

#[test]
fn on_an_80_column_terminal_the_progress_never_wraps_and_the_verdict_comes_last() {
    let command = format!(
        "exec '{}' calibrate --robot sim --sensor sim",
        env!("CARGO_BIN_EXE_groundcal")
    );
    let Some((code, raw, contents)) = under_a_terminal(&command) else {
        eprintln!("calibrate_tty: skipped, no `script` here");
        return;
    };
    assert_eq!(code, 0, "{raw}");

    // The progress bar was drawn (a terminal gets the bar, not log lines).
    assert!(
        raw.contains(" left"),
        "no progress bar on a terminal: {raw}"
    );
    assert!(
        !raw.contains("groundcal calibrate: pose"),
        "a terminal got the piped log lines: {raw}"
    );
    for segment in drawn_segments(&raw) {
        assert!(
            segment.chars().count() <= usize::from(COLUMNS),
            "a line wider than {COLUMNS} columns: {segment:?}"
        );
    }
    let lines: Vec<&str> = contents.lines().filter(|l| !l.trim().is_empty()).collect();
    let last_six: Vec<&str> = lines.iter().rev().take(6).rev().copied().collect();
    for (line, name) in last_six
        .iter()
        .zip(["alpha", "beta", "gamma", "px", "py", "pz"])
    {
        assert!(
            line.trim_start().starts_with(name),
            "the screen does not end with the six values:\n{contents}"
        );
    }
    let verdict = lines
        .iter()
        .rposition(|l| l.starts_with("verdict: passed its checks"))
        .expect("the verdict on screen");
    assert!(
        verdict + 10 >= lines.len(),
        "the verdict is not among the last lines:\n{contents}"
    );
    // The step log above it: the last step stays on screen.
    assert!(
        lines
            .iter()
            .position(|l| l.contains("52 of 52 poses used"))
            .is_some_and(|summary| summary < verdict),
        "{contents}"
    );
}

/// `command` (a shell line) under a pseudo-terminal of 80 columns; returns
/// its exit status and everything it drew. None without `script`.
fn under_a_terminal(command: &str) -> Option<(i32, String, String)> {
    if Command::new("script").arg("--version").output().is_err() {
        assert!(
            std::env::var("CI").as_deref() != Ok("true"),
            "util-linux `script` is needed for the pseudo-terminal (apt install bsdutils)"
        );
        return None;
    }
    let line = format!("stty cols {COLUMNS} rows {ROWS}; {command}");
    let output = Command::new("script")
        .args([
            "--quiet",
            "--return",
            "--flush",
            "--command",
            &line,
            "/dev/null",
        ])
        .env("TERM", "xterm-256color")
        .env_remove("NO_COLOR")
        .output()
        .expect("script runs");
    let raw = String::from_utf8_lossy(&output.stdout).into_owned();
    let mut terminal = vt100::Parser::new(ROWS, COLUMNS, 0);
    terminal.process(output.stdout.as_slice());
    let screen = terminal.screen();
    for row in 0..ROWS {
        assert!(
            !screen.row_wrapped(row),
            "row {row} wrapped (a line broken by the terminal, maybe mid-word):\n{}",
            screen.contents()
        );
    }
    Some((output.status.code().unwrap_or(-1), raw, screen.contents()))
}

/// A calibration that fails its checks: the reasons, long sentences, are
/// broken between words at 80 columns, never inside one.
#[test]
fn a_rejection_on_an_80_column_terminal_breaks_its_reasons_between_words() {
    let dir = std::env::temp_dir().join(format!("groundcal-tty-rejected-{}", std::process::id()));
    std::fs::create_dir_all(&dir).unwrap();
    let config = std::fs::read_to_string(concat!(env!("CARGO_MANIFEST_DIR"), "/config/sim.toml"))
        .unwrap()
        .replace(
            "schedule = \"schedules/octopus-52.toml\"",
            concat!(
                "schedule = \"",
                env!("CARGO_MANIFEST_DIR"),
                "/config/schedules/octopus-52.toml\""
            ),
        )
        .replace("theta_max_deg = 1.0", "theta_max_deg = 0.008")
        .replace("sigma_angle_max_deg = 0.1", "sigma_angle_max_deg = 0.0001");
    let path = dir.join("strict.toml");
    std::fs::write(&path, config).unwrap();
    let command = format!(
        "exec '{}' calibrate --config '{}'",
        env!("CARGO_BIN_EXE_groundcal"),
        path.display()
    );
    let Some((code, _, screen)) = under_a_terminal(&command) else {
        return;
    };
    assert_eq!(code, 3, "{screen}");
    assert!(screen.contains("verdict: failed its checks"), "{screen}");
    // A reason broken over lines, its continuation under its text.
    let reasons: Vec<&str> = screen
        .lines()
        .skip_while(|l| !l.starts_with("verdict:"))
        .skip(1)
        .take_while(|l| l.starts_with("  "))
        .collect();
    assert!(
        reasons
            .iter()
            .any(|l| l.starts_with("  - the measured ground disagrees")),
        "{screen}"
    );
    assert!(
        reasons.iter().any(|l| l.starts_with("    ")),
        "no reason was broken over lines:\n{screen}"
    );
    // The figures at the precision that makes the comparison true.
    assert!(screen.contains("more than the 0.008° allowed"), "{screen}");
    let _ = std::fs::remove_dir_all(&dir);
}

/// Ctrl-C during a calibration on a terminal: the screen says that the
/// robot is halting and walking home, ends with where it was left (broken
/// between words), and the bar stays where the run stopped.
#[test]
fn ctrl_c_on_a_terminal_says_halting_and_walking_home() {
    let command = format!(
        "'{}' calibrate --robot sim --sensor sim & p=$!; sleep 1.2; kill -INT $p; wait $p",
        env!("CARGO_BIN_EXE_groundcal")
    );
    let Some((code, raw, screen)) = under_a_terminal(&command) else {
        return;
    };
    assert_eq!(code, 1, "{screen}");
    assert!(raw.contains("halting the robot…"), "{raw}");
    assert!(raw.contains("walking home…"), "{raw}");
    assert!(
        screen.contains("groundcal calibrate: aborted: interrupted (SIGINT); halted and sent"),
        "{screen}"
    );
    assert!(screen.contains("home stance"), "{screen}");
    // The bar as it was drawn last: not full.
    let bar = drawn_segments(&raw)
        .into_iter()
        .rev()
        .find(|s| s.contains(" left"))
        .expect("the bar");
    let inside = bar
        .split('[')
        .nth(1)
        .and_then(|b| b.split(']').next())
        .unwrap_or_default();
    assert!(
        inside.contains(' ') || inside.contains('-') || inside.contains('░'),
        "a full bar after Ctrl-C: {bar}"
    );
}
