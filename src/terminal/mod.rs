//! `groundcal serve`: the daemon behind the phone/pad terminal on the robot's
//! Wi-Fi. An HTTP API (docs/api.md) and one embedded page; one calibration at
//! a time, run by the same session as `groundcal calibrate`; results kept in
//! the calibration store.
//!
//! - [`api`]: the status and event documents the API sends;
//! - [`state`]: what every request and the session thread share;
//! - [`auth`]: the token, one layer for every write;
//! - [`connections`]: few and short connections, so a flood cannot lock the operator out;
//! - [`handlers`]: the endpoints;
//! - [`worker`]: the session thread;
//! - [`preview`]: the live picture of what the camera sees while no session runs.
//!
//! The session runs on a thread of its own (with its own single-threaded
//! runtime) so that the hardware never has to cross threads; the HTTP side
//! sees it through the shared status, a broadcast of its events (server-sent
//! events) and an abort channel. The systemd watchdog is fed from the
//! session's heartbeat (`crate::platform::systemd`).

pub mod api;
pub mod auth;
pub mod connections;
pub mod handlers;
pub mod preview;
pub mod state;
pub mod worker;

pub use api::{EventJson, RunState, Status};
pub use auth::read_token;
pub use connections::{ConnectionLimits, Connections};
pub use state::AppState;

use std::future::Future;
use std::sync::Arc;
use std::time::Duration;

use axum::http::{header, StatusCode};
use axum::response::{Html, Response};
use axum::routing::{get, post};
use axum::Router;

/// The page, embedded: no CDN, works offline. Its style and script are
/// files of their own, so that the page's policy can forbid inline code.
pub const PAGE: &str = include_str!("page.html");
/// The page's style.
pub const PAGE_CSS: &str = include_str!("page.css");
/// The page's script.
pub const PAGE_JS: &str = include_str!("page.js");
/// The page's words in every language it speaks.
pub const PAGE_WORDS_JS: &str = include_str!("page-words.js");

/// What a page of this daemon may load and do: its own style, script and
/// API, nothing inline, nothing from elsewhere, and it may not be framed
/// (where a click on it could be a click on Calibrate).
pub const CONTENT_SECURITY_POLICY: &str = "frame-ancestors 'none'; default-src 'none'; \
script-src 'self'; style-src 'self'; connect-src 'self'; img-src 'self' data:; \
base-uri 'none'; form-action 'none'";

/// The router of the API and the page.
pub fn router(state: AppState) -> Router {
    use handlers::*;
    Router::new()
        .route("/", get(|| async { Html(PAGE) }))
        .route(
            "/page.css",
            get(|| async {
                (
                    [(header::CONTENT_TYPE, "text/css; charset=utf-8")],
                    PAGE_CSS,
                )
            }),
        )
        .route(
            "/page.js",
            get(|| async {
                (
                    [(header::CONTENT_TYPE, "text/javascript; charset=utf-8")],
                    PAGE_JS,
                )
            }),
        )
        .route(
            "/page-words.js",
            get(|| async {
                (
                    [(header::CONTENT_TYPE, "text/javascript; charset=utf-8")],
                    PAGE_WORDS_JS,
                )
            }),
        )
        .route("/api/status", get(get_status))
        .route("/api/events", get(get_events))
        .route("/api/stream-ticket", post(post_stream_ticket))
        .route("/api/calibrations", get(get_history).post(post_start))
        .route("/api/calibrations/current/abort", post(post_abort))
        .route("/api/calibrations/{id}", get(get_calibration))
        .route("/api/calibrations/{id}/accept", post(post_activate))
        .route("/api/calibrations/{id}/reject", post(post_reject))
        .route("/api/rollback/{id}", post(post_activate))
        .route("/api/active", get(get_active))
        .route("/api/check", post(post_check))
        .route("/api/view", get(get_view))
        // Only the routes above: an unknown endpoint is a 404 to anyone.
        .route_layer(axum::middleware::from_fn_with_state(
            state.clone(),
            auth::require_token_for_writes,
        ))
        .fallback(|| async {
            ApiError(
                StatusCode::NOT_FOUND,
                "no such endpoint (see docs/api.md)".into(),
            )
        })
        .layer(axum::middleware::from_fn_with_state(
            state.clone(),
            auth::same_site_only,
        ))
        .layer(axum::middleware::map_response(protective_headers))
        .with_state(state)
}

/// Headers on every response: no other site may show the page in a frame
/// (where a click on it could be a click on Calibrate), browsers must not
/// guess content types, and no address leaks to other sites.
async fn protective_headers(mut response: Response) -> Response {
    use axum::http::header::{
        HeaderValue, REFERRER_POLICY, X_CONTENT_TYPE_OPTIONS, X_FRAME_OPTIONS,
    };
    let headers = response.headers_mut();
    headers.insert(X_FRAME_OPTIONS, HeaderValue::from_static("DENY"));
    headers.insert(
        header::CONTENT_SECURITY_POLICY,
        HeaderValue::from_static(CONTENT_SECURITY_POLICY),
    );
    headers.insert(X_CONTENT_TYPE_OPTIONS, HeaderValue::from_static("nosniff"));
    headers.insert(REFERRER_POLICY, HeaderValue::from_static("no-referrer"));
    response
}

/// Checks the active calibration against the sensor once, as the service
/// starts (when one is active): on the session's thread, so that systemd's
/// READY is not delayed by it. The outcome goes to the journal, the status
/// and, when it is a verdict, the store.
///
/// It moves nothing: nobody asked for it, and nobody may be near the robot
/// at power-on. It reads the stance the robot already stands in, when the
/// lower computer reports it at home, with the Kinect's motor at the
/// calibration's tilt; otherwise it waits for a person (Check on the page,
/// which asks to keep clear first). Nor does it run after a run was cut off:
/// the robot may stand anywhere, and a person must see that first.
pub fn check_at_start(state: &AppState) {
    if let Some(cut_off) = state.status().interrupted {
        tracing::warn!(
            "not checking the active calibration at start: the calibration started by {} at {} was interrupted, so the robot moves only when a person presses Check on the page",
            cut_off.by,
            cut_off.started
        );
        state.set_startup_check(api::StartupCheck::HeldForAPerson);
        return;
    }
    match state.store().active() {
        Ok(Some(_)) => {
            match handlers::start(state, handlers::Starter::ServiceStart, api::Task::Check) {
                Ok(_) => {
                    state.set_startup_check(api::StartupCheck::Started);
                    tracing::info!("checking the active calibration against the sensor")
                }
                Err(handlers::ApiError(_, e)) => {
                    state.set_startup_check(api::StartupCheck::NotPossible);
                    tracing::warn!("cannot check the active calibration at start: {e}")
                }
            }
        }
        Ok(None) => {
            state.set_startup_check(api::StartupCheck::NotPossible);
            tracing::info!("no calibration is active yet: nothing to check at start")
        }
        Err(e) => {
            state.set_startup_check(api::StartupCheck::NotPossible);
            tracing::warn!("cannot read the active calibration to check it: {e}")
        }
    }
}

/// Serves until `shutdown` completes; then aborts a running session, waits
/// for it to stop the robot, and returns once the connections have closed
/// (at most a request timeout later). Notifies systemd (READY, WATCHDOG,
/// STOPPING) when it is listening.
pub async fn serve(
    listener: tokio::net::TcpListener,
    state: AppState,
    shutdown: impl Future<Output = ()> + Send + 'static,
) -> std::io::Result<()> {
    let limits = ConnectionLimits::default();
    let notifier = crate::platform::systemd::Notifier::from_env();
    let address = listener.local_addr()?;
    notifier.ready(&format!("listening on {address}"));
    let beating = state.clone();
    let watchdog = crate::platform::systemd::spawn_watchdog_feed(move || beating.last_beat());
    // The live picture, unless the start-up check runs (it starts the
    // picture when it ends).
    state.start_preview();
    let app = router(state.clone());
    let connections = Arc::new(Connections::default());
    let (closing, closing_seen) = tokio::sync::watch::channel(false);
    // Connections are accepted until the session has stopped the robot, so
    // that the page can watch it stop.
    let stopping = state.clone();
    let graceful = async move {
        shutdown.await;
        crate::platform::systemd::Notifier::from_env().stopping();
        stopping.stop_session("the service is stopping").await;
        stopping.mark_stopping();
        let preview = stopping.clone();
        let _ = tokio::task::spawn_blocking(move || preview.stop_preview()).await;
    };
    let mut graceful = std::pin::pin!(graceful);
    loop {
        tokio::select! {
            () = graceful.as_mut() => break,
            accepted = listener.accept() => match accepted {
                Ok((stream, peer)) => connections::spawn(
                    stream,
                    peer,
                    app.clone(),
                    connections.clone(),
                    limits,
                    closing_seen.clone(),
                ),
                Err(e) => {
                    // Out of descriptors (or a connection reset before it was
                    // accepted): wait for some to close rather than spin.
                    tracing::warn!("cannot accept a connection: {e}");
                    tokio::time::sleep(Duration::from_millis(100)).await;
                }
            },
        }
    }
    drop(listener);
    let _ = closing.send(true);
    let wait = limits.request_timeout + Duration::from_secs(1);
    if tokio::time::timeout(wait, connections.all_closed())
        .await
        .is_err()
    {
        tracing::warn!(
            "{} connections still open {wait:?} after the service stopped",
            connections.count()
        );
    }
    if let Some(w) = watchdog {
        w.abort();
    }
    Ok(())
}
