//! Who may write: every request that moves the robot or changes the active
//! calibration carries the token (`Authorization: Bearer TOKEN`). One layer on
//! the router checks it for every method but GET and HEAD, so a new write
//! endpoint is protected without anyone remembering to.

use std::path::Path;

use axum::extract::{Request, State};
use axum::http::{HeaderMap, Method, StatusCode};
use axum::middleware::Next;
use axum::response::{IntoResponse, Response};

use super::handlers::ApiError;
use super::state::AppState;
use crate::config::resolve_from_config;

/// Reads the token file (relative to the configuration's directory when relative).
pub fn read_token(config_path: &Path, token_file: &Path) -> Result<String, String> {
    let path = resolve_from_config(config_path, token_file);
    let text = std::fs::read_to_string(&path)
        .map_err(|e| format!("{}: cannot read the token: {e}", path.display()))?;
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

/// Whether the request carries the token, compared in constant time.
fn carries_token(headers: &HeaderMap, expected: &str) -> bool {
    let given = headers
        .get("authorization")
        .and_then(|v| v.to_str().ok())
        .and_then(|v| v.strip_prefix("Bearer "))
        .map(str::trim);
    let expected = expected.as_bytes();
    match given {
        Some(g) if !expected.is_empty() && g.len() == expected.len() => {
            g.bytes()
                .zip(expected)
                .fold(0u8, |acc, (a, b)| acc | (a ^ b))
                == 0
        }
        _ => false,
    }
}
