//! The `groundcal` subcommands, as library functions that return an exit status.
//!
//! `main.rs` only parses arguments and sets up logging; everything a command
//! does lives here so that tests can call it directly.

pub mod calibrate;
pub mod capture;
pub mod check_config;
pub mod export;
pub mod plan;
pub mod plane;
pub mod replay;
pub mod serve;
pub mod sim_robot;
pub mod solve;
pub mod verify;

/// Exit statuses of `shared/spec/cli.md`.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum ExitStatus {
    /// Done; for a calibration, accepted.
    Success = 0,
    /// Failed at run time: hardware, link, disk.
    RuntimeFailure = 1,
    /// Bad input or usage; the message names the file, line or flag.
    BadInput = 2,
    /// Solved but rejected; the output says why.
    Rejected = 3,
    /// `verify` only: the sensor no longer agrees with the calibration.
    Drift = 4,
}

impl ExitStatus {
    pub fn code(self) -> i32 {
        self as i32
    }
}

/// Parses `X,Y,Z`-style lists of numbers from a flag.
pub fn parse_numbers<const N: usize>(flag: &str, text: &str) -> Result<[f64; N], String> {
    let parts: Vec<&str> = text.split(',').map(str::trim).collect();
    if parts.len() != N {
        return Err(format!(
            "{flag} takes {N} comma-separated numbers, got \"{text}\""
        ));
    }
    let mut out = [0.0; N];
    for (slot, part) in out.iter_mut().zip(&parts) {
        *slot = part
            .parse::<f64>()
            .ok()
            .filter(|v| v.is_finite())
            .ok_or_else(|| format!("{flag}: \"{part}\" is not a finite number"))?;
    }
    Ok(out)
}

/// The end of every command that produces a result: the result on stdout
/// (JSON or the table), and the exit status its verdict calls for.
pub fn finish(command: &str, result: &crate::output::ResultJson, json: bool) -> ExitStatus {
    let printed = if json {
        print_json(result)
    } else {
        print!("{}", for_terminal(&result.to_table(), false));
        Ok(())
    };
    if let Err(e) = printed {
        eprintln!("groundcal {command}: {e}");
        return ExitStatus::RuntimeFailure;
    }
    if result.accepted() {
        ExitStatus::Success
    } else {
        ExitStatus::Rejected
    }
}

/// Text for stdout (or stderr), its long lines broken between words at the
/// terminal's width when it is a terminal; unchanged for a pipe or a file.
pub fn for_terminal(text: &str, stderr: bool) -> String {
    let term = if stderr {
        console::Term::stderr()
    } else {
        console::Term::stdout()
    };
    match term.size_checked() {
        Some((_, columns)) if term.is_term() => {
            crate::output::wrap_words(text, usize::from(columns))
        }
        _ => text.to_string(),
    }
}

/// Prints a JSON document on stdout (and nothing else there).
pub fn print_json<T: serde::Serialize>(value: &T) -> Result<(), String> {
    let text = serde_json::to_string_pretty(value)
        .map_err(|e| format!("cannot encode the result: {e}"))?;
    println!("{text}");
    Ok(())
}
