//! The monitor's HTTP side (axum on a tokio runtime of its own thread): the page
//! (`GET /`, one file of inline HTML, SVG and script built into the binary: no CDN,
//! works offline), the picture as JSON (`GET /state`) and live updates as server-sent
//! events (`GET /events`, the same JSON ten times a second).

use std::convert::Infallible;
use std::net::SocketAddr;
use std::sync::{Arc, Mutex};
use std::time::Duration;

use anyhow::{Context, Result};
use axum::response::sse::{Event, KeepAlive, Sse};
use axum::response::{Html, IntoResponse};
use axum::routing::get;
use axum::{Json, Router};

use super::model::Model;

/// The page, built into the binary.
pub const PAGE: &str = include_str!("web/index.html");

/// How often the page is sent a new picture.
pub const UPDATE_PERIOD: Duration = Duration::from_millis(100);

/// The model as the server and its source share it.
pub type Shared = Arc<Mutex<Model>>;

fn snapshot(model: &Shared) -> serde_json::Value {
    // A source that panicked mid-update leaves a picture worth showing still.
    match model.lock() {
        Ok(m) => m.state(),
        Err(poisoned) => poisoned.into_inner().state(),
    }
}

/// Binds `addr` now (so a taken port is an error at once) and serves the monitor on a
/// thread of its own until the process ends. Returns the address bound.
pub fn spawn(addr: SocketAddr, model: Shared) -> Result<SocketAddr> {
    let listener = std::net::TcpListener::bind(addr)
        .with_context(|| format!("cannot serve the monitor on {addr}"))?;
    listener.set_nonblocking(true)?;
    let bound = listener.local_addr()?;
    std::thread::Builder::new()
        .name("monitor-http".into())
        .spawn(move || {
            let rt = match tokio::runtime::Builder::new_current_thread()
                .enable_all()
                .build()
            {
                Ok(rt) => rt,
                Err(e) => return tracing::error!("monitor: no runtime: {e}"),
            };
            rt.block_on(async move {
                let listener = match tokio::net::TcpListener::from_std(listener) {
                    Ok(l) => l,
                    Err(e) => return tracing::error!("monitor: {e}"),
                };
                if let Err(e) = axum::serve(listener, router(model)).await {
                    tracing::error!("monitor: {e}");
                }
            });
        })?;
    tracing::info!("team monitor on http://{bound}/ (state as JSON: http://{bound}/state)");
    Ok(bound)
}

/// The routes.
pub fn router(model: Shared) -> Router {
    let state_model = model.clone();
    let events_model = model;
    Router::new()
        .route("/", get(|| async { Html(PAGE) }))
        .route(
            "/state",
            get(move || {
                let m = state_model.clone();
                async move { Json(snapshot(&m)) }
            }),
        )
        .route(
            "/events",
            get(move || {
                let m = events_model.clone();
                async move { events(m).into_response() }
            }),
        )
}

fn events(model: Shared) -> Sse<impl futures_util::Stream<Item = Result<Event, Infallible>>> {
    let ticks = tokio::time::interval(UPDATE_PERIOD);
    let stream = futures_util::stream::unfold((ticks, model), |(mut ticks, model)| async move {
        ticks.tick().await;
        let event = Event::default()
            .event("state")
            .data(snapshot(&model).to_string());
        Some((Ok(event), (ticks, model)))
    });
    Sse::new(stream).keep_alive(KeepAlive::default())
}
