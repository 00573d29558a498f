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
    if Command::new("script").arg("--version").output().is_err() {
        assert!(
            std::env::var("CI").as_deref() != Ok("true"),
            "util-linux `script` is needed for the pseudo-terminal (apt install bsdutils)"
        );
        eprintln!("calibrate_tty: skipped, no `script` here");
        return;
    }
    let command = format!(
        "stty cols {COLUMNS} rows {ROWS}; exec '{}' calibrate --robot sim --sensor sim",
        env!("CARGO_BIN_EXE_groundcal")
    );
    let output = Command::new("script")
        .args([
            "--quiet",
            "--return",
            "--flush",
            "--command",
            &command,
            "/dev/null",
        ])
        .env("TERM", "xterm-256color")
        .env_remove("NO_COLOR")
        .output()
        .expect("script runs");
    let raw = String::from_utf8_lossy(&output.stdout).into_owned();
    assert_eq!(output.status.code(), Some(0), "{raw}");

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

    let mut terminal = vt100::Parser::new(ROWS, COLUMNS, 0);
    terminal.process(output.stdout.as_slice());
    let screen = terminal.screen();
    for row in 0..ROWS {
        assert!(
            !screen.row_wrapped(row),
            "row {row} wrapped:\n{}",
            screen.contents()
        );
    }
    let contents = screen.contents();
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
        .rposition(|l| l.starts_with("status: ACCEPTED"))
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
