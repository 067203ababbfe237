//! The web server: the page and its assets (embedded), one WebSocket per
//! open page, the console's tick, and one zenoh driver per robot.

use std::sync::{Arc, Mutex, MutexGuard};
use std::time::{Duration, Instant};

use axum::Router;
use axum::extract::ws::{Message as WsMessage, WebSocket, WebSocketUpgrade};
use axum::extract::{Path, Query, State};
use axum::http::header::{CACHE_CONTROL, CONTENT_SECURITY_POLICY, CONTENT_TYPE, SET_COOKIE};
use axum::http::{HeaderMap, StatusCode};
use axum::response::{Html, IntoResponse, Response};
use axum::routing::get;
use serde::Deserialize;
use serde_json::json;
use tokio::sync::watch;

use crate::auth::Access;
use crate::core::{Applied, Core, Frame};
use crate::protocol;

const INDEX_HTML: &str = include_str!("../web/index.html");
const ASSETS: [(&str, &str, &[u8]); 6] = [
    (
        "app.js",
        "text/javascript; charset=utf-8",
        include_bytes!("../web/app.js"),
    ),
    (
        "map.js",
        "text/javascript; charset=utf-8",
        include_bytes!("../web/map.js"),
    ),
    (
        "style.css",
        "text/css; charset=utf-8",
        include_bytes!("../web/style.css"),
    ),
    (
        "uPlot.iife.min.js",
        "text/javascript; charset=utf-8",
        include_bytes!(concat!(env!("OUT_DIR"), "/vendor/uPlot.iife.min.js")),
    ),
    (
        "uPlot.min.css",
        "text/css; charset=utf-8",
        include_bytes!(concat!(env!("OUT_DIR"), "/vendor/uPlot.min.css")),
    ),
    (
        "favicon.svg",
        "image/svg+xml",
        include_bytes!("../web/favicon.svg"),
    ),
];

const REFUSED: &str = "<!doctype html><meta charset=utf-8><title>twindrive console</title>\
<h1>Access token needed</h1><p>Open the address the console printed when it started \
(it ends in <code>?token=…</code>); the token is also in the console's output directory, \
in <code>console.token</code>.</p>";

/// The page's security policy: nothing from elsewhere.
const CSP: &str = "default-src 'self'; connect-src 'self'; img-src 'self' data: blob:; \
style-src 'self' 'unsafe-inline'; script-src 'self'; frame-ancestors 'none'";

/// What every handler shares.
#[derive(Clone)]
pub struct App {
    pub core: Arc<Mutex<Core>>,
    pub frames: watch::Receiver<Arc<Frame>>,
    pub access: Arc<Access>,
    /// The console clock's zero.
    pub zero: Instant,
}

impl App {
    fn core(&self) -> MutexGuard<'_, Core> {
        self.core.lock().unwrap_or_else(|e| e.into_inner())
    }

    fn now_ns(&self) -> u64 {
        self.zero.elapsed().as_nanos() as u64
    }
}

#[derive(Deserialize)]
pub struct TokenQuery {
    token: Option<String>,
}

pub fn router(app: App) -> Router {
    Router::new()
        .route("/", get(index))
        .route("/assets/{name}", get(asset))
        .route("/ws", get(websocket))
        .route("/api/state", get(api_state))
        .route_layer(axum::middleware::from_fn_with_state(
            app.clone(),
            require_token,
        ))
        .with_state(app)
}

/// Every route needs the token (`?token=`, the cookie or a bearer header).
async fn require_token(
    State(app): State<App>,
    Query(q): Query<TokenQuery>,
    request: axum::extract::Request,
    next: axum::middleware::Next,
) -> Response {
    if !app.access.token_ok(request.headers(), q.token.as_deref()) {
        return refused();
    }
    next.run(request).await
}

fn refused() -> Response {
    (StatusCode::UNAUTHORIZED, Html(REFUSED)).into_response()
}

async fn index(State(app): State<App>) -> Response {
    (
        [
            (SET_COOKIE, app.access.cookie()),
            (CACHE_CONTROL, "no-store".into()),
            (CONTENT_SECURITY_POLICY, CSP.into()),
        ],
        Html(INDEX_HTML),
    )
        .into_response()
}

async fn asset(Path(name): Path<String>) -> Response {
    match ASSETS.iter().find(|(n, _, _)| *n == name) {
        Some((_, kind, bytes)) => {
            ([(CONTENT_TYPE, *kind), (CACHE_CONTROL, "no-cache")], *bytes).into_response()
        }
        None => (StatusCode::NOT_FOUND, format!("no asset `{name}`")).into_response(),
    }
}

async fn api_state(State(app): State<App>) -> Response {
    let state = app.frames.borrow().state.clone();
    ([(CONTENT_TYPE, "application/json")], state.to_string()).into_response()
}

async fn websocket(
    State(app): State<App>,
    headers: HeaderMap,
    upgrade: WebSocketUpgrade,
) -> Response {
    if !app.access.origin_ok(&headers) {
        tracing::warn!(
            origin = ?headers.get(axum::http::header::ORIGIN),
            "refused a WebSocket from another origin"
        );
        return (
            StatusCode::FORBIDDEN,
            "this origin may not open the console",
        )
            .into_response();
    }
    upgrade
        .max_message_size(1 << 20)
        .on_upgrade(move |socket| connection(socket, app))
}

/// What one page has been sent of the heavy parts.
#[derive(Default)]
struct Sent {
    world: bool,
    plan: u64,
    verify: u64,
    rehearsal: u64,
}

async fn send_frame(socket: &mut WebSocket, frame: &Frame, sent: &mut Sent) -> Result<(), ()> {
    let mut out: Vec<Arc<str>> = Vec::new();
    if !sent.world {
        out.push(frame.world.clone());
        sent.world = true;
    }
    for (have, part) in [
        (&mut sent.plan, &frame.plan),
        (&mut sent.verify, &frame.verify),
        (&mut sent.rehearsal, &frame.rehearsal),
    ] {
        if let Some((rev, text)) = part
            && *rev != *have
        {
            out.push(text.clone());
            *have = *rev;
        }
    }
    out.push(frame.state.clone());
    for text in out {
        socket
            .send(WsMessage::Text(text.to_string().into()))
            .await
            .map_err(|_| ())?;
    }
    Ok(())
}

/// One open page: the latest frame whenever there is a new one (a page
/// that falls behind skips frames; it never gets a backlog), commands in.
async fn connection(mut socket: WebSocket, app: App) {
    let mut frames = app.frames.clone();
    let mut sent = Sent::default();
    let mut focus: Option<String> = None;
    let mut focus_revs: Option<(u64, u64)> = None;
    let mut last_detail: Option<Instant> = None;
    let first = frames.borrow_and_update().clone();
    if send_frame(&mut socket, &first, &mut sent).await.is_err() {
        return;
    }
    loop {
        tokio::select! {
            changed = frames.changed() => {
                if changed.is_err() {
                    break;
                }
                let frame = frames.borrow_and_update().clone();
                if send_frame(&mut socket, &frame, &mut sent).await.is_err() {
                    break;
                }
                if let Some(id) = &focus {
                    let due = last_detail.is_none_or(|t| t.elapsed() >= Duration::from_millis(500));
                    let revs = app.core().robot_revs(id);
                    if due && revs != focus_revs {
                        let detail = app.core().robot_detail(id);
                        if let Some(d) = detail
                            && socket.send(WsMessage::Text(d.to_string().into())).await.is_err()
                        {
                            break;
                        }
                        focus_revs = revs;
                        last_detail = Some(Instant::now());
                    }
                }
            }
            message = socket.recv() => {
                let text = match message {
                    None | Some(Err(_)) | Some(Ok(WsMessage::Close(_))) => break,
                    Some(Ok(WsMessage::Text(t))) => t.to_string(),
                    Some(Ok(WsMessage::Binary(_))) => {
                        let e = json!({"type": "error", "message": "binary messages are not console commands; send JSON text"});
                        if socket.send(WsMessage::Text(e.to_string().into())).await.is_err() {
                            break;
                        }
                        continue;
                    }
                    Some(Ok(_)) => continue,
                };
                if let Err((e, logged)) = command(&app, &text, &mut focus) {
                    tracing::warn!("a page's command: {e}");
                    // Which command (the page shows the refusal beside its
                    // control), and whether the event list has it.
                    let cmd = serde_json::from_str::<serde_json::Value>(&text)
                        .ok()
                        .and_then(|v| v.get("cmd")?.as_str().map(str::to_owned));
                    let e = json!({"type": "error", "message": e, "cmd": cmd, "logged": logged});
                    if socket.send(WsMessage::Text(e.to_string().into())).await.is_err() {
                        break;
                    }
                }
                if focus.is_none() {
                    focus_revs = None;
                }
            }
        }
    }
}

/// Carries out one command; slow work goes to a blocking thread and
/// reports in the event list. A refusal of a command from a control of the
/// page ([`crate::core::spot`]) goes into the event list too (`true`); a
/// message that is no command goes back to its page only.
fn command(app: &App, text: &str, focus: &mut Option<String>) -> Result<(), (String, bool)> {
    let cmd = protocol::parse(text).map_err(|e| (e, false))?;
    if let protocol::Command::Focus { robot } = &cmd {
        *focus = robot.clone();
    }
    let now = app.now_ns();
    let logged = crate::core::spot(&cmd).is_some();
    let applied = {
        let mut core = app.core();
        core.apply(cmd, now).inspect_err(|e| {
            if logged {
                core.event("error", e.clone());
            }
        })
    }
    .map_err(|e| (e, logged))?;
    match applied {
        Applied::Done(Some(line)) => app.core().event("info", line),
        Applied::Done(None) => {}
        Applied::Job(job) => {
            let core = app.core.clone();
            tokio::spawn(async move {
                let result = tokio::task::spawn_blocking(move || job.run()).await;
                let mut core = core.lock().unwrap_or_else(|e| e.into_inner());
                match result {
                    Ok(r) => match core.finish(r) {
                        Ok(line) => core.event("info", line),
                        Err(e) => core.event("error", e),
                    },
                    Err(e) => {
                        core.finish(crate::core::JobResult::Plan(Err(format!(
                            "the job failed: {e}"
                        ))))
                        .ok();
                        core.event("error", format!("the job failed: {e}"));
                    }
                }
            });
        }
    }
    Ok(())
}
