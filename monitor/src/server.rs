//! The monitor's HTTP side (axum on a tokio runtime of its own thread): the page
//! (`GET /`, one file of inline HTML, SVG and script built into the binary: no CDN,
//! works offline), the picture as JSON (`GET /state`) and live updates as server-sent
//! events (`GET /events`, the same JSON ten times a second).
//!
//! What a hostile client (or a spoofer filling the board) can cost it, bounded:
//! - connections: at most [`MAX_CONNECTIONS`]; at the cap a new one closes the oldest
//!   that has not sent a whole request yet (half-open or silent), or is refused when every
//!   one has; request headers must arrive within [`HEADER_TIMEOUT`], which is also how
//!   long a keep-alive connection may idle between requests;
//! - event streams: at most [`MAX_EVENT_STREAMS`] (503 beyond);
//! - work: the picture is built at most once per [`UPDATE_PERIOD`], whatever the number
//!   of clients, and shared by all of them as one string; it shows at most
//!   [`super::model::BOARD_SHOWN`] bindings of the board (`board_total` says how many
//!   there are), so its cost and the time the model's lock is held are bounded by what
//!   is shown, not by what a spoofer stored.

use std::collections::BTreeMap;
use std::convert::Infallible;
use std::net::SocketAddr;
use std::sync::atomic::{AtomicU64, AtomicUsize, Ordering};
use std::sync::{Arc, Mutex};
use std::time::Duration;

use tokio::time::Instant;

use anyhow::{Context, Result};
use axum::http::{header, StatusCode};
use axum::response::sse::{Event, KeepAlive, Sse};
use axum::response::{Html, IntoResponse, Response};
use axum::routing::get;
use axum::Router;
use hyper_util::rt::{TokioIo, TokioTimer};
use tokio::sync::Notify;

use crate::model::Model;

/// The page, built into the binary.
pub const PAGE: &str = include_str!("web/index.html");

/// How often the page is sent a new picture (and at most how often it is built).
pub const UPDATE_PERIOD: Duration = Duration::from_millis(100);

/// Open connections at most.
pub const MAX_CONNECTIONS: usize = 256;

/// Time a client has to send a request's headers, and the longest a keep-alive
/// connection idles between requests.
pub const HEADER_TIMEOUT: Duration = Duration::from_secs(5);

/// Event streams (`GET /events`) open at most.
pub const MAX_EVENT_STREAMS: usize = 64;

/// The model as the server and its source share it.
pub type Shared = Arc<Mutex<Model>>;

/// The picture as last built, shared by every client until it is [`UPDATE_PERIOD`] old.
#[derive(Default)]
struct Cache {
    built: Option<(Instant, Arc<str>)>,
}

/// What the routes share.
#[derive(Clone)]
struct Served {
    model: Shared,
    cache: Arc<Mutex<Cache>>,
    streams: Arc<AtomicUsize>,
}

impl Served {
    /// The picture as JSON text, built at most once per [`UPDATE_PERIOD`].
    fn snapshot(&self) -> Arc<str> {
        let mut cache = self.cache.lock().unwrap_or_else(|p| p.into_inner());
        if let Some((at, text)) = &cache.built {
            if at.elapsed() < UPDATE_PERIOD {
                return text.clone();
            }
        }
        // A source that panicked mid-update leaves a picture worth showing still.
        let state = match self.model.lock() {
            Ok(m) => m.state(),
            Err(poisoned) => poisoned.into_inner().state(),
        };
        let text: Arc<str> = state.to_string().into();
        cache.built = Some((Instant::now(), text.clone()));
        text
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
                serve(listener, router(model)).await;
            });
        })?;
    tracing::info!("team monitor on http://{bound}/ (state as JSON: http://{bound}/state)");
    Ok(bound)
}

/// One open connection, as the accept loop sees it.
struct Conn {
    /// It sent a whole request (it is not half-open or silent).
    proved: Arc<std::sync::atomic::AtomicBool>,
    close: Arc<Notify>,
}

/// Counters of the accept loop (logged at debug level when they change).
#[derive(Default)]
struct Refusals {
    evicted: AtomicU64,
    refused: AtomicU64,
}

/// Accepts connections and serves `app` on each (HTTP/1.1, header timeout, capped).
async fn serve(listener: tokio::net::TcpListener, app: Router) {
    let conns: Arc<Mutex<BTreeMap<u64, Conn>>> = Arc::default();
    let refusals = Arc::new(Refusals::default());
    let mut next_id = 0u64;
    loop {
        let (stream, _) = match listener.accept().await {
            Ok(s) => s,
            Err(e) => {
                // Out of descriptors and the like: wait a little rather than spin.
                tracing::debug!("monitor: accept: {e}");
                tokio::time::sleep(Duration::from_millis(10)).await;
                continue;
            }
        };
        {
            let mut open = conns.lock().unwrap_or_else(|p| p.into_inner());
            if open.len() >= MAX_CONNECTIONS {
                // The oldest that has not sent a request yet gives way; if every one
                // has, the newcomer is refused.
                let idle = open
                    .iter()
                    .find(|(_, c)| !c.proved.load(Ordering::Relaxed))
                    .map(|(&id, _)| id);
                match idle.and_then(|id| open.remove(&id)) {
                    Some(c) => {
                        c.close.notify_one();
                        refusals.evicted.fetch_add(1, Ordering::Relaxed);
                    }
                    None => {
                        refusals.refused.fetch_add(1, Ordering::Relaxed);
                        continue; // dropped: closed
                    }
                }
            }
            next_id += 1;
            let conn = Conn {
                proved: Arc::default(),
                close: Arc::new(Notify::new()),
            };
            let (proved, close) = (conn.proved.clone(), conn.close.clone());
            open.insert(next_id, conn);
            let id = next_id;
            let conns = conns.clone();
            let app = app.clone();
            tokio::spawn(async move {
                let service = hyper::service::service_fn(move |req| {
                    proved.store(true, Ordering::Relaxed);
                    let mut app = app.clone();
                    async move {
                        use tower::Service as _;
                        app.call(req).await
                    }
                });
                let conn = hyper::server::conn::http1::Builder::new()
                    .timer(TokioTimer::new())
                    .header_read_timeout(HEADER_TIMEOUT)
                    .serve_connection(TokioIo::new(stream), service);
                tokio::select! {
                    _ = conn => {}
                    _ = close.notified() => {}
                }
                conns.lock().unwrap_or_else(|p| p.into_inner()).remove(&id);
            });
        }
    }
}

/// The routes.
pub fn router(model: Shared) -> Router {
    let served = Served {
        model,
        cache: Arc::default(),
        streams: Arc::default(),
    };
    let state_served = served.clone();
    let events_served = served;
    Router::new()
        .route("/", get(|| async { Html(PAGE) }))
        .route(
            "/state",
            get(move || {
                let s = state_served.clone();
                async move { json_response(s.snapshot()) }
            }),
        )
        .route(
            "/events",
            get(move || {
                let s = events_served.clone();
                async move { events(s) }
            }),
        )
}

fn json_response(text: Arc<str>) -> Response {
    (
        [(header::CONTENT_TYPE, "application/json")],
        text.to_string(),
    )
        .into_response()
}

/// Counts an open event stream; released when the stream is dropped.
struct StreamSlot(Arc<AtomicUsize>);
impl Drop for StreamSlot {
    fn drop(&mut self) {
        self.0.fetch_sub(1, Ordering::Relaxed);
    }
}

fn events(served: Served) -> Response {
    if served.streams.fetch_add(1, Ordering::Relaxed) >= MAX_EVENT_STREAMS {
        served.streams.fetch_sub(1, Ordering::Relaxed);
        return (StatusCode::SERVICE_UNAVAILABLE, "too many event streams").into_response();
    }
    let slot = StreamSlot(served.streams.clone());
    let ticks = tokio::time::interval(UPDATE_PERIOD);
    let stream = futures_util::stream::unfold(
        (ticks, served, slot),
        |(mut ticks, served, slot)| async move {
            ticks.tick().await;
            let event = Event::default().event("state").data(&*served.snapshot());
            Some((Ok::<_, Infallible>(event), (ticks, served, slot)))
        },
    );
    Sse::new(stream)
        .keep_alive(KeepAlive::default())
        .into_response()
}
