//! The web server: the page and its assets (embedded in the binary), the
//! state as JSON, live updates as server-sent events (each viewer at its
//! own pace, at most one event in flight: a slow one misses pictures,
//! never the counters or the history, which every event carries whole),
//! the requests to the sensor, and the part's lines for download.

use super::hub::Hub;
use axum::Router;
use axum::body::Body;
use axum::extract::{Query, State};
use axum::http::{HeaderMap, StatusCode, header};
use axum::response::sse::{Event, KeepAlive, Sse};
use axum::response::{IntoResponse, Response};
use axum::routing::{get, post};
use futures_util::stream::Stream;
use serde_json::{Value, json};
use std::collections::HashMap;
use std::convert::Infallible;
use std::sync::Arc;
use std::sync::atomic::Ordering;
use std::time::Duration;

/// Shortest time between two events to one viewer.
pub const EVENT_GAP: Duration = Duration::from_millis(100);

const INDEX: &str = include_str!("assets/index.html");
const APP_JS: &str = include_str!("assets/app.js");
const STYLE: &str = include_str!("assets/style.css");

pub fn router(hub: Arc<Hub>) -> Router {
    Router::new()
        .route(
            "/",
            get(|| async { asset("text/html; charset=utf-8", INDEX) }),
        )
        .route(
            "/app.js",
            get(|| async { asset("text/javascript; charset=utf-8", APP_JS) }),
        )
        .route(
            "/style.css",
            get(|| async { asset("text/css; charset=utf-8", STYLE) }),
        )
        .route("/api/state", get(state))
        .route("/api/events", get(events))
        .route("/api/request", post(request))
        .route("/api/lines", get(lines))
        .with_state(hub)
}

fn asset(kind: &'static str, body: &'static str) -> Response {
    (
        [
            (header::CONTENT_TYPE, kind),
            (header::CACHE_CONTROL, "no-cache"),
        ],
        body,
    )
        .into_response()
}

/// Which pictures a viewer already has.
#[derive(Default)]
struct Cursor {
    current: u64,
    rows_sent: usize,
    last: u64,
}

/// A connected viewer, counted while its stream lives.
struct Viewer(Arc<Hub>);

impl Viewer {
    fn new(hub: Arc<Hub>) -> Self {
        hub.viewers.fetch_add(1, Ordering::Relaxed);
        Viewer(hub)
    }
}

impl Drop for Viewer {
    fn drop(&mut self) {
        self.0.viewers.fetch_sub(1, Ordering::Relaxed);
    }
}

/// The state for one viewer: everything but the picture rows it has.
fn snapshot(hub: &Hub, cur: &mut Cursor) -> Value {
    let s = hub.state();
    let mut v = s.summary();
    v["viewers"] = hub.viewers.load(Ordering::Relaxed).into();
    v["current"] = match &s.current {
        Some(p) => {
            let from = if p.n == cur.current {
                cur.rows_sent.saturating_sub(1)
            } else {
                0
            };
            (cur.current, cur.rows_sent) = (p.n, p.rows_seen);
            p.json(Some(from))
        }
        None => Value::Null,
    };
    v["last"] = match &s.last {
        Some(p) => {
            let map = (p.n != cur.last).then_some(0);
            cur.last = p.n;
            p.json(map)
        }
        None => Value::Null,
    };
    v
}

async fn state(State(hub): State<Arc<Hub>>) -> Response {
    let v = snapshot(&hub, &mut Cursor::default());
    ([(header::CACHE_CONTROL, "no-cache")], axum::Json(v)).into_response()
}

async fn events(State(hub): State<Arc<Hub>>) -> Sse<impl Stream<Item = Result<Event, Infallible>>> {
    let rx = hub.tick.subscribe();
    let stream = futures_util::stream::unfold(
        (Viewer::new(hub), rx, Cursor::default(), true),
        |(viewer, mut rx, mut cur, first)| async move {
            if !first {
                tokio::time::sleep(EVENT_GAP).await;
                rx.changed().await.ok()?;
            }
            rx.borrow_and_update();
            let data = snapshot(&viewer.0, &mut cur).to_string();
            Some((
                Ok(Event::default().event("state").data(data)),
                (viewer, rx, cur, false),
            ))
        },
    );
    Sse::new(stream).keep_alive(KeepAlive::default())
}

fn refused(status: u16, reason: &str) -> Response {
    let code = StatusCode::from_u16(status).unwrap_or(StatusCode::BAD_REQUEST);
    (code, axum::Json(json!({"ok": false, "error": reason}))).into_response()
}

/// `POST /api/request` with `{"request": "set thr=100"}`: the words of
/// `dmap sensor`'s actions, checked as it checks them.
async fn request(State(hub): State<Arc<Hub>>, headers: HeaderMap, body: String) -> Response {
    let v: Value = match serde_json::from_str(&body) {
        Ok(v) => v,
        Err(e) => {
            return refused(
                400,
                &format!("the body is not JSON of the form {{\"request\": \"set thr=100\"}} ({e})"),
            );
        }
    };
    let Some(words) = v.get("request").and_then(Value::as_str) else {
        return refused(
            400,
            "the body has no \"request\" string (e.g. {\"request\": \"set thr=100\"})",
        );
    };
    let reads_only = matches!(words.split_whitespace().next(), Some("status" | "get"));
    if let Some(token) = &hub.token
        && !reads_only
    {
        let given = headers
            .get("x-console-token")
            .and_then(|h| h.to_str().ok())
            .unwrap_or("");
        if !super::token::same(given, token) {
            let why = if given.is_empty() {
                "a change of settings needs the token dmap console printed at start (header X-Console-Token; the page takes it from ?token=)"
            } else {
                "wrong token: a change of settings needs the token dmap console printed at start"
            };
            return refused(401, why);
        }
    }
    match hub.request(words).await {
        Ok(v) => axum::Json(json!({"ok": true, "result": v})).into_response(),
        Err(r) => refused(r.status, &r.reason),
    }
}

/// `GET /api/lines?part=last|current`: that part's lines, as they came.
async fn lines(State(hub): State<Arc<Hub>>, Query(q): Query<HashMap<String, String>>) -> Response {
    let which = q.get("part").map_or("last", String::as_str);
    let s = hub.state();
    let part = match which {
        "current" => s.current.as_ref(),
        "last" => s.last.as_ref(),
        _ => return refused(400, "part is `last` or `current`"),
    };
    let Some(p) = part else {
        return refused(404, &format!("no {which} part yet"));
    };
    let name = format!("attachment; filename=\"part-{}.txt\"", p.n);
    Response::builder()
        .header(header::CONTENT_TYPE, "text/plain; charset=utf-8")
        .header(header::CONTENT_DISPOSITION, name)
        .body(Body::from(p.lines.clone()))
        .unwrap_or_else(|_| refused(500, "could not build the response"))
}
