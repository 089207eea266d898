//! `splatray view`: a scene or cloud in the browser, ray traced
//! progressively (`docs/viewer.md`).
//!
//! An HTTP server on tokio (axum) serves one page (plain HTML and
//! JavaScript, [`page`]) and a WebSocket per page. The page sends JSON
//! requests (a camera, a backend, a shading mode, an AOV, the key light, a
//! pick, a diff, "save scene"); the server answers with frames — a binary message: a
//! little-endian `u32` header length, a JSON header, PNG bytes — and JSON
//! messages. Each camera is rendered as a preview (a quarter of the
//! resolution, one sample), then the full-quality frame (the bytes
//! `splatray render` writes for the scene "save scene" gives), then a
//! refined frame with more samples; a newer request cancels the frame in
//! flight between bands of rows ([`worker`]).
//!
//! Safe by default: it binds the loopback address unless told otherwise;
//! the page names no file (the scene is the one given on the command line;
//! saved scenes and images are downloads); a request is at most
//! [`MAX_MESSAGE`] bytes; a bad message gets an error message and the
//! session goes on; a closed page's jobs are dropped; Ctrl-C stops the
//! server, its sessions and the worker.

pub mod source;
pub mod worker;

pub use source::{Overrides, Source, ViewCamera};

use crate::names::Named;
use crate::resolve::ShadingMode;
use crate::{Error, Result};
use axum::Router;
use axum::extract::ws::{Message, WebSocket, WebSocketUpgrade};
use axum::extract::{DefaultBodyLimit, State};
use axum::http::header;
use axum::response::{IntoResponse, Response};
use axum::routing::get;
use serde::Deserialize;
use serde_json::json;
use std::net::SocketAddr;
use std::sync::Arc;
use std::sync::atomic::{AtomicU64, AtomicUsize, Ordering};
use worker::{Job, Out, Queue, RenderRequest, Session, Show, Stats, Task, error_json};

/// The largest message a page may send, bytes.
pub const MAX_MESSAGE: usize = 16 * 1024;

/// The page, built into the binary.
pub mod page {
    /// `index.html`.
    pub const INDEX: &str = include_str!("page/index.html");
    /// `viewer.js`.
    pub const SCRIPT: &str = include_str!("page/viewer.js");
}

/// How the server runs.
#[derive(Clone, Debug)]
pub struct ServeOptions {
    /// Address to bind (loopback by default).
    pub host: String,
    /// Port (0: any free port).
    pub port: u16,
    /// Samples per pixel of the refined frame (none unless above the
    /// full frame's).
    pub refine_spp: u32,
}

/// Shared by the server's handlers.
struct App {
    source: Arc<Source>,
    queue: Arc<Queue>,
    stats: Arc<Stats>,
    sessions: AtomicUsize,
    refine_spp: u32,
    shutdown: tokio::sync::watch::Receiver<bool>,
}

/// A page's request.
#[derive(Debug, Deserialize)]
#[serde(tag = "type", rename_all = "snake_case", deny_unknown_fields)]
enum Request {
    /// A new camera.
    Camera { id: u64, camera: ViewCamera },
    /// A backend by name.
    Backend { name: String },
    /// A shading mode, or `scene` for the scene's own.
    Shading { mode: String },
    /// What to show: rgb, depth, normal, splat, albedo.
    Show { show: Show },
    /// The key light's direction of travel (`null`: the scene's own).
    Light { direction: Option<[f64; 3]> },
    /// The backends' full frames compared.
    Diff,
    /// One pixel of the full frame.
    Pick { x: u32, y: u32 },
    /// The scene text of the current view, rendered with `spp` samples
    /// (default: the full frame's).
    SaveScene { spp: Option<u32> },
}

/// A page's view.
#[derive(Clone, Debug)]
struct ViewState {
    camera_id: u64,
    camera: ViewCamera,
    backend: String,
    shading: Option<ShadingMode>,
    key: Option<[f64; 3]>,
    show: Show,
}

/// Serves `source` until Ctrl-C: prints the URL on standard output, then
/// blocks.
///
/// # Errors
/// The address cannot be bound, or the default backend does not build.
pub fn serve(source: Source, scene: crate::scene::Scene, opts: &ServeOptions) -> Result<()> {
    let source = Arc::new(source);
    let stats = Arc::new(Stats::default());
    let queue = Arc::new(Queue::default());
    let default = registry_default();
    let mut w = worker::Worker::new(source.clone(), scene, stats.clone());
    w.prepare(&default)?;
    let rt = tokio::runtime::Builder::new_multi_thread()
        .worker_threads(1)
        .enable_all()
        .build()
        .map_err(Error::other)?;
    let (stop_tx, stop_rx) = tokio::sync::watch::channel(false);
    let app = Arc::new(App {
        source,
        queue: queue.clone(),
        stats,
        sessions: AtomicUsize::new(0),
        refine_spp: opts.refine_spp,
        shutdown: stop_rx,
    });
    let q = queue.clone();
    let worker = std::thread::Builder::new()
        .name("splatray-view-render".into())
        .spawn(move || w.run(&q))
        .map_err(Error::other)?;
    let (host_name, port) = (opts.host.clone(), opts.port);
    let addr = format!("{host_name} port {port}");
    let result = rt.block_on(async move {
        let listener = tokio::net::TcpListener::bind((host_name.as_str(), port))
            .await
            .map_err(|e| Error::other(e).context(format_args!("cannot listen on {addr}")))?;
        let local: SocketAddr = listener.local_addr().map_err(Error::other)?;
        let host = if local.ip().is_unspecified() {
            "localhost".to_string()
        } else if local.is_ipv6() {
            format!("[{}]", local.ip())
        } else {
            local.ip().to_string()
        };
        {
            use std::io::Write as _;
            let mut out = std::io::stdout();
            let _ = writeln!(
                out,
                "splatray view: http://{host}:{}/ (Ctrl-C to stop)",
                local.port()
            );
            let _ = out.flush();
        }
        let router = Router::new()
            .route("/", get(index))
            .route("/viewer.js", get(script))
            .route("/ws", get(ws))
            .route("/stats", get(stats_json))
            .layer(DefaultBodyLimit::max(MAX_MESSAGE))
            .with_state(app);
        axum::serve(listener, router)
            .with_graceful_shutdown(async move {
                let _ = tokio::signal::ctrl_c().await;
                let _ = stop_tx.send(true);
            })
            .await
            .map_err(Error::other)
    });
    queue.stop();
    let _ = worker.join();
    rt.shutdown_timeout(std::time::Duration::from_secs(2));
    eprintln!("splatray view: stopped");
    result
}

/// The default backend: the registry's first renderer.
fn registry_default() -> String {
    crate::accel::registry::renderers()
        .first()
        .map_or_else(|| "octree".into(), |b| b.name.to_string())
}

async fn index() -> Response {
    (
        [
            (header::CONTENT_TYPE, "text/html; charset=utf-8"),
            (header::CACHE_CONTROL, "no-store"),
        ],
        page::INDEX,
    )
        .into_response()
}

async fn script() -> Response {
    (
        [
            (header::CONTENT_TYPE, "text/javascript; charset=utf-8"),
            (header::CACHE_CONTROL, "no-store"),
        ],
        page::SCRIPT,
    )
        .into_response()
}

async fn stats_json(State(app): State<Arc<App>>) -> Response {
    let s = &app.stats;
    (
        [(header::CONTENT_TYPE, "application/json")],
        json!({
            "sessions": app.sessions.load(Ordering::SeqCst),
            "busy": s.busy.load(Ordering::SeqCst),
            "bands": s.bands.load(Ordering::SeqCst),
            "frames": s.frames.load(Ordering::SeqCst),
            "cancelled": s.cancelled.load(Ordering::SeqCst),
        })
        .to_string(),
    )
        .into_response()
}

async fn ws(upgrade: WebSocketUpgrade, State(app): State<Arc<App>>) -> Response {
    upgrade
        .max_message_size(MAX_MESSAGE)
        .max_frame_size(MAX_MESSAGE)
        .on_upgrade(move |socket| session(socket, app))
}

/// One page's session: its requests in, its frames and messages out.
async fn session(mut socket: WebSocket, app: Arc<App>) {
    app.sessions.fetch_add(1, Ordering::SeqCst);
    let (tx, mut rx) = tokio::sync::mpsc::unbounded_channel::<Out>();
    let sess = Arc::new(Session {
        generation: AtomicU64::new(0),
        closed: std::sync::atomic::AtomicBool::new(false),
        tx,
    });
    let src = &app.source;
    let (width, height) = (src.width, src.height);
    let mut state = ViewState {
        camera_id: 0,
        camera: src.initial,
        backend: registry_default(),
        shading: None,
        key: None,
        show: Show::Rgb,
    };
    let names: Vec<&str> = crate::accel::registry::renderers()
        .iter()
        .map(|b| b.name)
        .collect();
    let bounds = src
        .bounds
        .map(|(lo, hi)| json!([lo.to_array(), hi.to_array()]));
    let hello = json!({
        "type": "hello",
        "name": src.path.display().to_string(),
        "splats": src.splats,
        "width": width,
        "height": height,
        "spp": src.spp(),
        "camera": worker::camera_json(&src.initial),
        "sensor": src.sensor.as_ref().map(worker::camera_json),
        "backends": names,
        "backend": state.backend,
        "shading": src.shading.0.name(),
        "bounds": bounds,
        "max_message": MAX_MESSAGE,
    });
    let mut shutdown = app.shutdown.clone();
    let mut ok = socket
        .send(Message::Text(hello.to_string().into()))
        .await
        .is_ok();
    if ok {
        // The first frame, unasked.
        queue_render(&app, &sess, &state, Kind::Render);
    }
    while ok {
        tokio::select! {
            msg = socket.recv() => {
                let reply = match msg {
                    Some(Ok(Message::Text(t))) => handle(&app, &sess, &mut state, t.as_str()),
                    Some(Ok(Message::Binary(_))) => Err(Error::invalid("binary messages are not requests")),
                    Some(Ok(Message::Ping(_) | Message::Pong(_))) => Ok(None),
                    Some(Ok(Message::Close(_)) | Err(_)) | None => break,
                };
                let text = match reply {
                    Ok(Some(t)) => t,
                    Ok(None) => continue,
                    Err(e) => error_json(&e.to_string()),
                };
                ok = socket.send(Message::Text(text.into())).await.is_ok();
            }
            out = rx.recv() => {
                let m = match out {
                    Some(Out::Text(t)) => Message::Text(t.into()),
                    Some(Out::Frame(h, png)) => {
                        let mut b = Vec::with_capacity(4 + h.len() + png.len());
                        b.extend_from_slice(&(h.len() as u32).to_le_bytes());
                        b.extend_from_slice(h.as_bytes());
                        b.extend_from_slice(&png);
                        Message::Binary(b.into())
                    }
                    None => break,
                };
                ok = socket.send(m).await.is_ok();
            }
            _ = shutdown.changed() => {
                let _ = socket.send(Message::Close(None)).await;
                break;
            }
        }
    }
    sess.closed.store(true, Ordering::SeqCst);
    app.sessions.fetch_sub(1, Ordering::SeqCst);
}

#[derive(Clone, Copy)]
enum Kind {
    Render,
    Diff,
    Pick(u32, u32),
}

/// Queues a job for the page's current view; a render supersedes the
/// page's jobs before it.
fn queue_render(app: &App, sess: &Arc<Session>, state: &ViewState, kind: Kind) {
    let req = match request(app, state) {
        Ok(r) => r,
        Err(e) => {
            let _ = sess.tx.send(Out::Text(error_json(&e.to_string())));
            return;
        }
    };
    let generation = match kind {
        Kind::Render | Kind::Diff => sess.generation.fetch_add(1, Ordering::SeqCst) + 1,
        Kind::Pick(..) => sess.generation.load(Ordering::SeqCst),
    };
    let task = match kind {
        Kind::Render => Task::Render(req),
        Kind::Diff => Task::Diff(req),
        Kind::Pick(x, y) => Task::Pick(req, x, y),
    };
    app.queue.push(Job {
        session: sess.clone(),
        generation,
        task,
    });
}

fn request(app: &App, s: &ViewState) -> Result<RenderRequest> {
    let spp = app.source.spp();
    Ok(RenderRequest {
        camera_id: s.camera_id,
        text: app.source.text(&s.camera, spp, s.shading, s.key)?,
        backend: s.backend.clone(),
        shading: s.shading,
        show: s.show,
        refine_spp: app.refine_spp,
    })
}

/// Handles one request: the state changed and a job queued, or a reply.
fn handle(
    app: &App,
    sess: &Arc<Session>,
    state: &mut ViewState,
    text: &str,
) -> Result<Option<String>> {
    let req: Request =
        serde_json::from_str(text).map_err(|e| Error::invalid(format!("bad request: {e}")))?;
    match req {
        Request::Camera { id, camera } => {
            camera.check()?;
            state.camera_id = id;
            state.camera = camera;
        }
        Request::Backend { name } => {
            if !crate::accel::registry::renderers()
                .iter()
                .any(|b| b.name == name)
            {
                return Err(Error::invalid(format!("unknown backend '{name}'")));
            }
            state.backend = name;
        }
        Request::Shading { mode } => {
            state.shading = match mode.as_str() {
                "scene" => None,
                m => Some(
                    crate::names::parse::<ShadingMode>(m)
                        .map_err(|e| Error::invalid(format!("shading '{m}': {e}")))?,
                ),
            };
        }
        Request::Show { show } => state.show = show,
        Request::Light { direction } => {
            // Checked before it is kept: a bad one leaves the view as it was.
            app.source
                .text(&state.camera, app.source.spp(), state.shading, direction)?;
            state.key = direction;
        }
        Request::Diff => {
            queue_render(app, sess, state, Kind::Diff);
            return Ok(None);
        }
        Request::Pick { x, y } => {
            queue_render(app, sess, state, Kind::Pick(x, y));
            return Ok(None);
        }
        Request::SaveScene { spp } => {
            let spp = spp.unwrap_or(app.source.spp());
            if spp == 0 || spp > 4096 {
                return Err(Error::invalid(format!("spp {spp} must be in 1..=4096")));
            }
            let text = app
                .source
                .text(&state.camera, spp, state.shading, state.key)?;
            return Ok(Some(
                json!({"type": "scene", "camera": state.camera_id, "text": text}).to_string(),
            ));
        }
    }
    queue_render(app, sess, state, Kind::Render);
    Ok(None)
}
