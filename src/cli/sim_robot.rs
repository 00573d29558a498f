//! `groundcal sim-robot --listen ADDR [--seed N] [--time-scale X]`: the
//! simulated lower computer (`shared/spec/hexapod-udp.md`) as its own
//! process, for tests and demos of the UDP link.
//!
//! It prints one line `listening on IP:PORT` on stdout once the socket is
//! bound (so that `--listen 127.0.0.1:0` can be used and found), serves until
//! SIGINT or SIGTERM, then prints its counters on stderr as one line
//! `sim-robot: stats {...}` and exits 0. Fault injection and the receipts log
//! come from the environment (`GROUNDCAL_SIM_FAULTS`,
//! `GROUNDCAL_SIM_RECEIPTS`; see `groundcal_hal::udp::sim_server`): they are
//! for tests, not for operators.

use std::io::Write;
use std::net::{SocketAddr, ToSocketAddrs};
use std::path::PathBuf;

use groundcal_hal::udp::sim_server::{self, FaultInjection, SimOptions, RECEIPTS_ENV};

use super::ExitStatus;

/// Runs the simulated lower computer until a signal.
pub fn run(listen: &str, seed: u64, time_scale: f64) -> ExitStatus {
    let usage = |message: String| {
        eprintln!("groundcal: sim-robot: {message}");
        ExitStatus::BadInput
    };
    let address = match resolve(listen) {
        Ok(a) => a,
        Err(e) => return usage(format!("--listen \"{listen}\": {e}")),
    };
    if !(time_scale.is_finite() && time_scale > 0.0) {
        return usage(format!(
            "--time-scale {time_scale}: must be a positive number (50: motions 50× faster)"
        ));
    }
    let faults = match FaultInjection::from_env() {
        Ok(f) => f,
        Err(e) => return usage(e),
    };
    let options = SimOptions {
        faults,
        receipts: std::env::var_os(RECEIPTS_ENV).map(PathBuf::from),
        ..SimOptions::new(seed, time_scale)
    };
    let served = sim_server::run_until_signal(address, options, |bound| {
        let mut stdout = std::io::stdout().lock();
        // A test waits for this line; a closed stdout must not stop the server.
        let _ = writeln!(stdout, "listening on {bound}");
        let _ = stdout.flush();
    });
    match served {
        Ok(stats) => {
            match serde_json::to_string(&stats) {
                Ok(json) => eprintln!("sim-robot: stats {json}"),
                Err(e) => eprintln!("sim-robot: stats not encoded: {e}"),
            }
            ExitStatus::Success
        }
        Err(e) => {
            eprintln!("groundcal: sim-robot: {listen}: {e}");
            ExitStatus::RuntimeFailure
        }
    }
}

/// `host:port` to one socket address, IPv4 preferred.
fn resolve(listen: &str) -> Result<SocketAddr, String> {
    let addresses: Vec<SocketAddr> = listen
        .to_socket_addrs()
        .map_err(|e| format!("not a host:port ({e})"))?
        .collect();
    addresses
        .iter()
        .find(|a| a.is_ipv4())
        .or(addresses.first())
        .copied()
        .ok_or_else(|| "resolves to no address".to_string())
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn bad_flags_are_usage_errors() {
        assert_eq!(run("nonsense", 1, 1.0), ExitStatus::BadInput);
        assert_eq!(run("127.0.0.1:0", 1, 0.0), ExitStatus::BadInput);
        assert_eq!(run("127.0.0.1:0", 1, f64::NAN), ExitStatus::BadInput);
    }

    #[test]
    fn listen_addresses_resolve() {
        assert_eq!(
            resolve("127.0.0.1:7400").unwrap(),
            "127.0.0.1:7400".parse().unwrap()
        );
        assert!(resolve("localhost:0").is_ok());
        assert!(resolve("127.0.0.1").is_err());
    }
}
