//! Who may ask:
//! - every request that moves the robot or changes the active calibration
//!   carries the token (`Authorization: Bearer TOKEN`). One layer on the
//!   router checks it for every method but GET and HEAD, so a new write
//!   endpoint is protected without anyone remembering to;
//! - every request names this daemon in its `Host` (an address, `localhost`,
//!   the machine's name, or a name of `serve.allowed_hosts`), so that a web
//!   page elsewhere cannot read the daemon through a name of its own that
//!   resolves here (DNS rebinding);
//! - a write from a browser comes from a page of this daemon (`Origin`).

use std::path::Path;

use axum::extract::{Request, State};
use axum::http::{header, HeaderMap, Method, StatusCode};
use axum::middleware::Next;
use axum::response::{IntoResponse, Response};

use super::handlers::ApiError;
use super::state::AppState;
use crate::setup::config::resolve_from_config;

/// The largest token file read: the package writes 64 characters, a person
/// a passphrase; anything larger is not a token.
pub const MAX_TOKEN_FILE_BYTES: u64 = 4096;

/// Reads the token file (relative to the configuration's directory when
/// relative): a regular file of at most [`MAX_TOKEN_FILE_BYTES`] of UTF-8, so
/// that a wrong path (`/dev/zero`, a FIFO) is refused at once rather than read
/// until the memory runs out or waited on for ever.
pub fn read_token(config_path: &Path, token_file: &Path) -> Result<String, String> {
    use crate::platform::files::ReadError;
    let path = resolve_from_config(config_path, token_file);
    let mut bytes = Vec::new();
    crate::platform::files::read_bounded_into(&path, MAX_TOKEN_FILE_BYTES, &mut bytes).map_err(
        |e| match e {
            ReadError::File(f) => format!(
                "{}: cannot read the token: cannot {}: {}",
                path.display(),
                f.action,
                f.source
            ),
            ReadError::TooLarge { max_bytes, .. } => format!(
                "{}: the token file is larger than {max_bytes} bytes: not a token file",
                path.display()
            ),
        },
    )?;
    let text = String::from_utf8(bytes)
        .map_err(|_| format!("{}: the token file is not UTF-8 text", path.display()))?;
    let token = text.trim().to_string();
    if token.is_empty() {
        return Err(format!("{}: the token file is empty", path.display()));
    }
    Ok(token)
}

/// The layer: reads pass, writes need the token.
pub async fn require_token_for_writes(
    State(state): State<AppState>,
    request: Request,
    next: Next,
) -> Response {
    let reads = [Method::GET, Method::HEAD];
    if reads.contains(request.method()) || carries_token(request.headers(), state.token()) {
        next.run(request).await
    } else {
        ApiError(
            StatusCode::UNAUTHORIZED,
            "a valid token is required: send `Authorization: Bearer TOKEN` (the token is in the file serve.token_file)".into(),
        )
        .into_response()
    }
}

/// Whether the request carries the token. The scheme is matched without
/// regard to case (RFC 7235); the token is compared by the digests of both,
/// in constant time, so that neither its bytes nor its length can be timed.
fn carries_token(headers: &HeaderMap, expected: &str) -> bool {
    let given = headers
        .get("authorization")
        .and_then(|v| v.to_str().ok())
        .and_then(bearer_token);
    match given {
        Some(g) if !expected.is_empty() => {
            let (g, e) = (
                blake3::hash(g.as_bytes()),
                blake3::hash(expected.as_bytes()),
            );
            g.as_bytes()
                .iter()
                .zip(e.as_bytes())
                .fold(0u8, |acc, (a, b)| acc | (a ^ b))
                == 0
        }
        _ => false,
    }
}

/// The credentials of an `Authorization: Bearer TOKEN` value, whatever the
/// case of the scheme.
fn bearer_token(value: &str) -> Option<&str> {
    let (scheme, token) = value.trim_start().split_once(' ')?;
    scheme.eq_ignore_ascii_case("bearer").then(|| token.trim())
}

/// The layer: a request must name this daemon as its host (a missing or
/// empty `Host` is refused), and a browser's write must come from one of its
/// pages: origin `http://` and that host, scheme included.
pub async fn same_site_only(
    State(state): State<AppState>,
    request: Request,
    next: Next,
) -> Response {
    let allowed = state
        .config()
        .serve
        .as_ref()
        .map(|s| s.allowed_hosts.as_slice())
        .unwrap_or_default();
    let host = request
        .headers()
        .get(header::HOST)
        .and_then(|h| h.to_str().ok())
        .unwrap_or_default()
        .to_string();
    if host.trim().is_empty() {
        return ApiError(
            StatusCode::BAD_REQUEST,
            "a request must name this daemon in its Host header (HTTP/1.1)".into(),
        )
        .into_response();
    }
    if !names_this_daemon(&host, allowed, machine_name()) {
        return ApiError(
            StatusCode::MISDIRECTED_REQUEST,
            format!(
                "this daemon answers to its address or its own names, not to \"{host}\" (add the name to serve.allowed_hosts)"
            ),
        )
        .into_response();
    }
    let writes = ![Method::GET, Method::HEAD].contains(request.method());
    if let Some(origin) = request.headers().get(header::ORIGIN) {
        let origin = origin.to_str().unwrap_or_default();
        // The daemon speaks plain HTTP: its pages' origin is `http://` and
        // its host; `https://` on the same host is another origin.
        let same = origin
            .strip_prefix("http://")
            .is_some_and(|o| o.eq_ignore_ascii_case(&host));
        if writes && !same {
            return ApiError(
                StatusCode::FORBIDDEN,
                format!(
                    "a write from another site ({origin}) is refused: use this daemon's own page"
                ),
            )
            .into_response();
        }
    }
    next.run(request).await
}

/// This machine's name, read once (`/proc/sys/kernel/hostname`).
fn machine_name() -> &'static str {
    static NAME: std::sync::OnceLock<String> = std::sync::OnceLock::new();
    NAME.get_or_init(|| {
        std::fs::read_to_string("/proc/sys/kernel/hostname")
            .map(|n| n.trim().to_ascii_lowercase())
            .unwrap_or_default()
    })
}

/// Whether a `Host` header (`name[:port]`, `[v6]:port`) names this daemon:
/// an IP address, `localhost`, the machine's name (also with `.local`, as
/// mDNS announces it), or a configured name.
fn names_this_daemon(host: &str, allowed: &[String], machine: &str) -> bool {
    let name = match host.strip_prefix('[') {
        Some(v6) => v6.split(']').next().unwrap_or_default(),
        None => host.rsplit_once(':').map_or(host, |(name, port)| {
            if port.chars().all(|c| c.is_ascii_digit()) {
                name
            } else {
                host
            }
        }),
    };
    let name = name.trim_end_matches('.').to_ascii_lowercase();
    name.parse::<std::net::IpAddr>().is_ok()
        || name == "localhost"
        || (!machine.is_empty() && (name == machine || name == format!("{machine}.local")))
        || allowed.iter().any(|a| a.eq_ignore_ascii_case(&name))
}

#[cfg(test)]
mod tests {
    use super::*;

    fn with_authorization(value: &str) -> HeaderMap {
        let mut headers = HeaderMap::new();
        headers.insert("authorization", value.parse().unwrap());
        headers
    }

    #[test]
    fn the_bearer_scheme_is_matched_in_any_case() {
        for value in [
            "Bearer s3cret",
            "bearer s3cret",
            "BEARER s3cret",
            "  BeArEr   s3cret ",
        ] {
            assert!(
                carries_token(&with_authorization(value), "s3cret"),
                "{value}"
            );
        }
        for value in [
            "Basic s3cret",
            "Bearer",
            "Bearers3cret",
            "Bearer s3cre",
            "Bearer s3cret2",
            "Bearer ",
        ] {
            assert!(
                !carries_token(&with_authorization(value), "s3cret"),
                "{value}"
            );
        }
        assert!(!carries_token(&HeaderMap::new(), "s3cret"));
        assert!(!carries_token(&with_authorization("Bearer "), ""));
    }

    #[test]
    fn a_host_must_name_this_daemon() {
        let allowed = ["octopus-upper".to_string()];
        for host in [
            "127.0.0.1:8080",
            "192.168.4.1",
            "[::1]:8080",
            "localhost:8080",
            "robot:8080",
            "robot.local",
            "ROBOT.local.:8080",
            "octopus-upper:8080",
        ] {
            assert!(names_this_daemon(host, &allowed, "robot"), "{host}");
        }
        for host in [
            "evil.example",
            "evil.example:8080",
            "robot.evil.example",
            "localhost.evil",
        ] {
            assert!(!names_this_daemon(host, &allowed, "robot"), "{host}");
        }
    }
}
