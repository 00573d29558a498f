//! The `groundcal` subcommands, as library functions that return an exit status.
//!
//! `main.rs` only parses arguments and sets up logging; each command's
//! arguments (`SolveArgs`, …) and everything it does live here, its `main`
//! taking the arguments and its `run` the options, so that tests can call it
//! directly.

pub mod args;
pub mod calibrate;
pub mod capture;
pub mod check_config;
pub mod export;
pub mod plan;
pub mod plane;
pub mod reference;
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

/// A usage error: said on standard error, exit status 2.
pub fn usage_error(message: String) -> ExitStatus {
    eprintln!("groundcal: {message}");
    ExitStatus::BadInput
}

impl ExitStatus {
    pub fn code(self) -> i32 {
        self as i32
    }
}

/// A command that reads, prints and ends is ended quietly by the system
/// when the reader of its output goes away (`groundcal replay --json |
/// head`), as `cat` and `grep` are: SIGPIPE's default action, exit by
/// signal 13 (status 141 in a shell). Rust's runtime ignores SIGPIPE, so
/// that every print to a closed pipe would panic instead.
///
/// Not for the commands that drive hardware or serve (`calibrate`,
/// `verify`, `capture`, `serve`, `sim-robot`): a closed pipe must never
/// end them while the robot stands mid-schedule; their progress printer
/// outlives a failed write.
pub fn ends_quietly_on_a_closed_pipe() {
    #[cfg(unix)]
    // SAFETY: `signal` with SIG_DFL installs no handler; it is called on
    // the main thread before any other thread starts.
    #[allow(unsafe_code)]
    unsafe {
        libc::signal(libc::SIGPIPE, libc::SIG_DFL);
    }
}

/// Whether standard output was closed when the process started (`>&-`):
/// set by [`note_whether_stdout_is_closed`].
static STDOUT_WAS_CLOSED: std::sync::atomic::AtomicBool = std::sync::atomic::AtomicBool::new(false);

/// Notes whether standard output is closed (`>&-`), from the constructor
/// `main.rs` registers, which the C library runs before Rust's runtime
/// starts. The runtime then gives a closed standard descriptor `/dev/null`,
/// opened for reading and writing (so that no file opened later takes its
/// number), and its stdout reports every print as written; after that, a
/// closed output and a `/dev/null` a caller opened for reading and writing
/// (a shell's `<>`, Python's `subprocess.DEVNULL`) cannot be told apart,
/// and taking the second for the first failed every such caller.
pub fn note_whether_stdout_is_closed() {
    // SAFETY: F_GETFD reads descriptor 1's flags; no memory is passed.
    #[allow(unsafe_code)]
    let flags = unsafe { libc::fcntl(libc::STDOUT_FILENO, libc::F_GETFD) };
    if flags == -1 {
        STDOUT_WAS_CLOSED.store(true, std::sync::atomic::Ordering::Relaxed);
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
pub fn finish(
    command: &str,
    result: &crate::formats::output::ResultJson,
    json: bool,
) -> ExitStatus {
    let printed = if json {
        print_json(result)
    } else {
        print_stdout(&for_terminal(&result.to_table(), false))
    };
    if let Err(e) = printed {
        // stderr may be gone with stdout: said if it can be, never a panic.
        use std::io::Write;
        let _ = writeln!(std::io::stderr(), "groundcal {command}: {e}");
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
            crate::formats::output::wrap_words(text, usize::from(columns))
        }
        _ => text.to_string(),
    }
}

/// Prints a JSON document on stdout (and nothing else there).
pub fn print_json<T: serde::Serialize>(value: &T) -> Result<(), String> {
    let text = serde_json::to_string_pretty(value)
        .map_err(|e| format!("cannot encode the result: {e}"))?;
    print_stdout(&format!("{text}\n"))
}

/// Writes `text` on stdout; an error (the reader gone, a full disk) is
/// returned, not a panic as `print!`'s would be.
pub fn print_stdout(text: &str) -> Result<(), String> {
    use std::io::Write;
    // Rust's stdout takes a closed descriptor (`>&-`) for a sink and
    // reports success: a result written nowhere must be a failure.
    if STDOUT_WAS_CLOSED.load(std::sync::atomic::Ordering::Relaxed) {
        return Err("cannot print the result: standard output is closed".into());
    }
    let mut stdout = std::io::stdout().lock();
    stdout
        .write_all(text.as_bytes())
        .and_then(|()| stdout.flush())
        .map_err(|e| format!("cannot print the result: {e}"))
}
