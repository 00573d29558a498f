//! `groundcal serve --config FILE`: the daemon for the phone/pad terminal
//! (`crate::terminal`). Binds HTTP, opens the hardware once to check it (and
//! closes it), then tells systemd READY; prints `listening on ADDR` on stdout
//! once HTTP listens; SIGTERM or SIGINT aborts a running session (the robot
//! is halted and sent home) and then stops.

use std::io::Write;
use std::path::PathBuf;

use super::args::HardwareArgs;
use super::ExitStatus;
use crate::hardware::{self, Selection};
use crate::setup::config::Config;
use crate::terminal::{self, AppState};

/// The command's options.
#[derive(Debug, Clone, Default)]
pub struct ServeOptions {
    pub config: PathBuf,
    pub selection: Selection,
    /// Overrides `serve.listen`.
    pub listen: Option<String>,
}

/// SIGTERM or SIGINT, with the handlers installed now (when called, inside
/// the runtime) rather than when first polled: a signal while the hardware
/// is being checked still stops the service cleanly.
fn stop_signal() -> impl std::future::Future<Output = ()> + Send + 'static {
    use tokio::signal::unix::{signal, SignalKind};
    let terminate = signal(SignalKind::terminate());
    let interrupt = signal(SignalKind::interrupt());
    async move {
        match (terminate, interrupt) {
            (Ok(mut term), Ok(mut int)) => tokio::select! {
                _ = term.recv() => {}
                _ = int.recv() => {}
            },
            _ => {
                let _ = tokio::signal::ctrl_c().await;
            }
        }
    }
}

/// The arguments of `groundcal serve`: the configuration and the hardware.
#[derive(Debug, clap::Args)]
pub struct ServeArgs {
    /// The configuration ([serve]: listen, token_file, state_dir, allowed_hosts).
    #[arg(long)]
    pub config: PathBuf,
    #[command(flatten)]
    pub hardware: HardwareArgs,
    /// Overrides serve.listen (HOST:PORT; port 0 picks one).
    #[arg(long)]
    pub listen: Option<String>,
}

/// Runs the command with its arguments from the command line.
pub fn main(args: ServeArgs) -> ExitStatus {
    run(&ServeOptions {
        config: args.config,
        selection: args.hardware.into(),
        listen: args.listen,
    })
}

/// Runs the command.
pub fn run(options: &ServeOptions) -> ExitStatus {
    let (config, schedule) = match Config::load(&options.config) {
        Ok(c) => c,
        Err(e) => {
            eprintln!("groundcal serve: {e}");
            return ExitStatus::BadInput;
        }
    };
    let Some(serve) = config.serve.clone() else {
        eprintln!(
            "groundcal serve: {}: no [serve] table (listen, token_file, state_dir)",
            options.config.display()
        );
        return ExitStatus::BadInput;
    };
    let token = match terminal::read_token(&options.config, &serve.token_file) {
        Ok(t) => t,
        Err(e) => {
            eprintln!("groundcal serve: {e}");
            return ExitStatus::BadInput;
        }
    };
    let state_dir = crate::setup::config::resolve_from_config(&options.config, &serve.state_dir);
    let listen = options.listen.clone().unwrap_or(serve.listen);
    let runtime = match tokio::runtime::Builder::new_multi_thread()
        .enable_all()
        .build()
    {
        Ok(r) => r,
        Err(e) => {
            eprintln!("groundcal serve: cannot start the runtime: {e}");
            return ExitStatus::RuntimeFailure;
        }
    };
    runtime.block_on(async {
        let stop = stop_signal();
        let listener = match tokio::net::TcpListener::bind(&listen).await {
            Ok(l) => l,
            Err(e) => {
                eprintln!("groundcal serve: cannot listen on {listen}: {e}");
                return ExitStatus::RuntimeFailure;
            }
        };
        match listener.local_addr() {
            Ok(addr) => {
                println!("listening on {addr}");
                let _ = std::io::stdout().flush();
            }
            Err(e) => {
                eprintln!("groundcal serve: {e}");
                return ExitStatus::RuntimeFailure;
            }
        }
        // The hardware, opened once before READY: a missing Kinect or an
        // unresolvable lower computer shows on the page and in the journal at
        // once, not only when the operator presses Calibrate. It is closed
        // again (each calibration opens it), and a failure does not stop the
        // service: the page must stay up to say what is wrong.
        let check_at_start = config.verify.at_start;
        let mut opened_at_start = false;
        let hardware = match hardware::open(&config, &options.selection).await {
            Ok(opened) => {
                drop(opened);
                opened_at_start = true;
                // The link only binds its socket: the lower computer is first
                // spoken to (HELLO) when a calibration starts.
                let words = format!(
                    "opened: {}; lower computer at {} (first spoken to by a check or a calibration)",
                    options.selection.sensor(&config),
                    options.selection.robot(&config)
                );
                // Said where the operator looks, not only in the journal.
                match hardware::mismatch(&config, &options.selection) {
                    Some(warning) => format!("{words}; but {warning}"),
                    None => words,
                }
            }
            Err(e) => {
                tracing::warn!("the hardware did not open: {e}");
                eprintln!("groundcal serve: the hardware did not open: {e}");
                format!("not opened: {e}")
            }
        };
        let state = AppState::new(
            config,
            schedule,
            options.selection.clone(),
            token,
            &state_dir,
        );
        state.set_hardware(hardware);
        if check_at_start && opened_at_start {
            terminal::check_at_start(&state);
        } else if check_at_start {
            state.set_startup_check(terminal::api::StartupCheck::NotPossible);
        }
        match terminal::serve(listener, state, stop).await {
            Ok(()) => ExitStatus::Success,
            Err(e) => {
                eprintln!("groundcal serve: {e}");
                ExitStatus::RuntimeFailure
            }
        }
    })
}
