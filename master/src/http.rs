//! The master's HTTP side (`vtfarm master --http ADDR`): the dashboard page,
//! its live event stream, frames as PNG, `/api/status` and Prometheus
//! `/metrics`, the interactive view (`POST /api/view` moves the eye,
//! `/view/image.png` and `/view/objects.png` show its newest stage), each
//! kept frame's timeline (`/frames/SEQ.svg`), and the jobs: `GET /api/jobs`
//! lists them as `vtfarm jobs --all --json` does (a study as one row with
//! its variants), `GET /api/jobs/{id}` shows one, `POST
//! /api/jobs/{id}/cancel|pause|resume|requeue|priority` changes one
//! (`docs/http-api.md`).
//!
//! It reads the core's state through [`MasterHandle::inspect`] and wakes on
//! [`MasterHandle::changes`]; it owns no farm state, so the page, the
//! metrics and `vtfarm status` (which asks the same `MasterCore::status`)
//! cannot disagree.
//!
//! Peers on loopback are trusted unless the request was forwarded (it
//! carries `Forwarded`, `X-Forwarded-For` or `X-Real-IP`, as a same-host
//! proxy adds) or [`HttpAccess::require_token`] is set; any other peer must
//! send the cluster token as `Authorization: Bearer TOKEN`, or log in once
//! at `/login` (the token in a form), which sets a session cookie: a hash of
//! the token, so the cookie does not reveal the token, valid until the
//! token changes.
//!
//! Every request's `Host` must name this server (loopback names, the
//! listening address, or an [`HttpAccess::allowed_hosts`] name), so a page
//! of another site cannot reach it by DNS rebinding; and a request that can
//! change the farm must come from this server's own pages
//! ([`cross_origin`]: `Sec-Fetch-Site`, `Origin`) and, but for the login
//! form, be declared JSON, so that no page of another site can make one;
//! preflights are refused to other origins. These rules are layers on the
//! whole router, so every route inherits them.
//!
//! [`serve`] bounds every client ([`HttpLimits`]): connections beyond the
//! caps (in all, per address, the reserve for addresses holding few) and
//! event streams beyond theirs get 503; a connection that sends no
//! complete request head within the header timeout, or idles that long
//! between requests, is closed (hyper's `header_read_timeout`); a body is
//! read whole, within its own deadline, before the request is handled; a
//! client that does not read its event stream holds one coalesced view
//! and hyper's bounded write buffer, never a backlog: every stream follows
//! one shared view, computed once per change for all of them.

use std::collections::HashMap;
use std::convert::Infallible;
use std::net::{IpAddr, SocketAddr};
use std::sync::{Arc, OnceLock};
use std::time::Duration;
use vtfarm_proto::JobId;

use axum::Router;
use axum::extract::{ConnectInfo, Form, Path, Query, Request, State};
use axum::http::{HeaderMap, HeaderValue, Method, StatusCode, header};
use axum::middleware::{self, Next};
use axum::response::sse::{Event, Sse};
use axum::response::{Html, IntoResponse, Redirect, Response};
use axum::routing::{get, post};
use futures_util::stream;
use prometheus_client::encoding::{EncodeMetric, MetricEncoder, NoLabelSet};
use prometheus_client::metrics::MetricType;
use prometheus_client::metrics::counter::Counter;
use prometheus_client::metrics::family::Family;
use prometheus_client::metrics::gauge::Gauge;
use prometheus_client::registry::Registry;
use serde::Deserialize;
use sha2::{Digest, Sha256};
use tokio::io::AsyncWriteExt;
use tokio::net::TcpListener;
use tokio::sync::{OwnedSemaphorePermit, Semaphore, watch};
use vtfarm_imaging::Image;
use vtfarm_master_core::telemetry::{FRAME_SECONDS_BUCKETS, FrameDurations, WorkerTotals};
use vtfarm_master_core::view::{EYE_BOX, ViewRequest};
use vtfarm_master_core::{JobControlError, JobState, MasterCore};
use vtfarm_proto::{JobAction, WireImage, token_matches};

use crate::driver::MasterHandle;

mod json;
#[cfg(test)]
mod tests;

use json::ViewRequestBody;
pub use json::{
    CountersView, CurrentViewJson, DashboardView, FrameView, JobRowView, LatestView, LiveView,
    ViewOutcomeView, ViewSourceView, ViewState, WorkerTotalsView, WorkerView,
};

/// The dashboard, served from the binary.
const DASHBOARD: &str = include_str!("dashboard.html");

/// The login page for peers off loopback (`{message}` is filled in).
const LOGIN: &str = include_str!("login.html");

/// The login form's path: the one state-changing request that is a form, not JSON.
const LOGIN_PATH: &str = "/login";

/// The session cookie's name.
pub const SESSION_COOKIE: &str = "vtfarm_session";

/// Who may use the HTTP side.
#[derive(Clone, Debug)]
pub struct HttpAccess {
    /// The cluster token.
    pub token: String,
    /// Host names a browser may call the server by, besides `localhost`,
    /// loopback addresses and the listening address
    /// (`--http-allowed-host`, as a proxy in front of it is named).
    pub allowed_hosts: Vec<String>,
    /// Ask loopback peers for the token too (`--http-require-token`: a
    /// same-host proxy that adds no forwarding header).
    pub require_token: bool,
    /// The address the server listens on ([`serve`] fills it in).
    pub listen: Option<SocketAddr>,
}

impl HttpAccess {
    /// Loopback trusted, no extra host names.
    pub fn new(token: impl Into<String>) -> HttpAccess {
        HttpAccess {
            token: token.into(),
            allowed_hosts: Vec::new(),
            require_token: false,
            listen: None,
        }
    }
}

/// The bounds [`serve`] holds every client to.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct HttpLimits {
    /// A request's head must be in within this, and a kept-alive connection
    /// idles no longer between requests.
    pub header_read_timeout: Duration,
    /// A request's body must be in within this after its head, plus its
    /// length at [`HttpLimits::min_body_rate`]; else 408 and the connection
    /// is closed. Every body is read whole before the request is handled.
    pub body_read_timeout: Duration,
    /// The slowest a body may arrive beyond `body_read_timeout`, in bytes per second.
    pub min_body_rate: u64,
    /// The largest request body; a larger one gets 413 and the connection is closed.
    pub max_body_bytes: usize,
    /// Connections served at once; more get 503 and are closed.
    pub max_connections: usize,
    /// Connections served at once from one client address.
    pub max_connections_per_address: usize,
    /// The last of the `max_connections` slots, kept for addresses that
    /// hold fewer than [`FEW_CONNECTIONS`]: one address flooding the
    /// server, or a few, leave room for a dashboard elsewhere.
    pub reserved_connections: usize,
    /// Event streams (`/api/events`, one per open dashboard) at once; more get 503.
    pub max_event_streams: usize,
    /// The most a connection buffers for a client that does not read.
    pub write_buffer_bytes: usize,
}

impl Default for HttpLimits {
    fn default() -> Self {
        HttpLimits {
            header_read_timeout: Duration::from_secs(10),
            body_read_timeout: Duration::from_secs(10),
            min_body_rate: 16 * 1024,
            max_body_bytes: 64 * 1024,
            max_connections: 256,
            max_connections_per_address: 128,
            reserved_connections: 32,
            max_event_streams: 64,
            write_buffer_bytes: 64 * 1024,
        }
    }
}

/// How often the shared dashboard view may be computed again (changes in
/// between coalesce): the event streams cost the core one view per
/// interval however many follow it.
const VIEW_INTERVAL: Duration = Duration::from_millis(100);

/// Connections answered 503 at once beyond the caps; past them a
/// connection is closed unanswered.
const TURNED_AWAY: usize = 64;

/// Connections an address may hold and still be given a reserved slot: a
/// browser opens at most six to one server.
pub const FEW_CONNECTIONS: usize = 8;

#[derive(Clone)]
struct HttpState {
    master: MasterHandle,
    access: Arc<HttpAccess>,
    /// The session cookie's value for this token.
    session: Arc<str>,
    /// The event streams' permits.
    streams: Arc<Semaphore>,
    /// The dashboard view every event stream follows, started with the first.
    view_feed: Arc<OnceLock<watch::Receiver<Arc<str>>>>,
    /// The view's newest stage as PNG, encoded once for every request.
    /// The view's stages as PNG, newest last, at most [`VIEW_PNGS_KEPT`].
    view_pngs: Arc<std::sync::Mutex<Vec<ViewPng>>>,
}

/// Which stage of which move is on view, and whether its figures are in.
type ViewKey = (u64, &'static str, bool);

/// The stage on view, if any.
fn view_key(core: &MasterCore) -> Option<ViewKey> {
    let latest = core.views().latest()?;
    Some((
        latest.generation,
        latest.quality.name(),
        latest.figures.is_some(),
    ))
}

/// Why the HTTP server could not start.
#[derive(Debug, thiserror::Error)]
#[error("cannot listen for HTTP on {address}: {source}")]
pub struct HttpBindError {
    address: SocketAddr,
    source: std::io::Error,
}

/// Binds the HTTP listener.
pub async fn bind(address: SocketAddr) -> Result<TcpListener, HttpBindError> {
    TcpListener::bind(address)
        .await
        .map_err(|source| HttpBindError { address, source })
}

/// Serves the dashboard, API and metrics until the listener fails, each
/// connection within `limits`.
pub async fn serve(
    listener: TcpListener,
    master: MasterHandle,
    mut access: HttpAccess,
    limits: HttpLimits,
) {
    access.listen = listener.local_addr().ok();
    let app = router_with(master, access, limits.max_event_streams);
    let slots = Arc::new(Slots::new(limits));
    let turned_away = Arc::new(Semaphore::new(TURNED_AWAY));
    let mut http = hyper::server::conn::http1::Builder::new();
    http.timer(hyper_util::rt::TokioTimer::new())
        .header_read_timeout(limits.header_read_timeout)
        .max_buf_size(limits.write_buffer_bytes);
    loop {
        let (stream, peer) = match listener.accept().await {
            Ok(accepted) => accepted,
            Err(e) => {
                // Out of file descriptors, say: wait for some to close.
                tracing::warn!("HTTP accept failed: {e}");
                tokio::time::sleep(Duration::from_millis(100)).await;
                continue;
            }
        };
        let Some(slot) = slots.take(peer.ip()) else {
            if let Ok(permit) = turned_away.clone().try_acquire_owned() {
                let timeout = limits.header_read_timeout;
                tokio::spawn(turn_away(stream, timeout, permit));
            }
            continue;
        };
        let service = hyper::service::service_fn({
            let app = app.clone();
            move |request: hyper::Request<hyper::body::Incoming>| {
                let app = app.clone();
                async move {
                    let mut request = match whole_request(request, &limits).await {
                        Ok(request) => request,
                        Err(refusal) => return Ok::<_, Infallible>(refusal),
                    };
                    request.extensions_mut().insert(ConnectInfo(peer));
                    tower::ServiceExt::oneshot(app, request).await
                }
            }
        });
        let connection = http
            .serve_connection(hyper_util::rt::TokioIo::new(stream), service)
            .with_upgrades();
        tokio::spawn(async move {
            let _ = connection.await;
            drop(slot);
        });
    }
}

/// The connections being served, counted per client address.
struct Slots {
    limits: HttpLimits,
    held: std::sync::Mutex<SlotCounts>,
}

#[derive(Default)]
struct SlotCounts {
    total: usize,
    per_address: HashMap<IpAddr, usize>,
}

/// A served connection's slot, given back when dropped.
struct Slot {
    slots: Arc<Slots>,
    address: IpAddr,
}

impl Slots {
    fn new(limits: HttpLimits) -> Slots {
        Slots {
            limits,
            held: std::sync::Mutex::default(),
        }
    }

    /// A slot for a connection from `address`, if the caps leave one: the
    /// address holds fewer than its cap, and the open slots are not all
    /// taken or it holds only a few.
    fn take(self: &Arc<Self>, address: IpAddr) -> Option<Slot> {
        let address = address.to_canonical();
        let limits = &self.limits;
        let mut held = self.held.lock().unwrap_or_else(|p| p.into_inner());
        let mine = held.per_address.get(&address).copied().unwrap_or(0);
        let open = (limits.max_connections).saturating_sub(limits.reserved_connections);
        let admitted = mine < limits.max_connections_per_address
            && (held.total < open
                || (held.total < limits.max_connections && mine < FEW_CONNECTIONS));
        if !admitted {
            return None;
        }
        held.total += 1;
        *held.per_address.entry(address).or_default() += 1;
        Some(Slot {
            slots: self.clone(),
            address,
        })
    }
}

impl Drop for Slot {
    fn drop(&mut self) {
        let mut held = (self.slots.held.lock()).unwrap_or_else(|p| p.into_inner());
        held.total -= 1;
        if let Some(n) = held.per_address.get_mut(&self.address) {
            *n -= 1;
            if *n == 0 {
                held.per_address.remove(&self.address);
            }
        }
    }
}

/// The request with its body read whole, within
/// [`HttpLimits::body_read_timeout`] plus its length at
/// [`HttpLimits::min_body_rate`] and at most [`HttpLimits::max_body_bytes`]
/// long: a client that trickles a body holds its connection that long at
/// most. Else the refusal, which closes the connection.
async fn whole_request(
    request: hyper::Request<hyper::body::Incoming>,
    limits: &HttpLimits,
) -> Result<Request, Response> {
    use hyper::body::Body as _;
    let (parts, body) = request.into_parts();
    if body.is_end_stream() {
        return Ok(Request::from_parts(parts, axum::body::Body::empty()));
    }
    let max = limits.max_body_bytes;
    let announced = body.size_hint().exact();
    if announced.is_some_and(|n| n > max as u64) {
        let message = format!("request bodies are at most {max} bytes\n");
        return Err(closing(StatusCode::PAYLOAD_TOO_LARGE, message));
    }
    let length = announced.unwrap_or(max as u64);
    let bound = limits.body_read_timeout
        + Duration::from_secs_f64(length as f64 / limits.min_body_rate.max(1) as f64);
    let read = axum::body::to_bytes(axum::body::Body::new(body), max);
    match tokio::time::timeout(bound, read).await {
        Ok(Ok(bytes)) => Ok(Request::from_parts(parts, axum::body::Body::from(bytes))),
        Ok(Err(e)) => Err(closing(
            StatusCode::BAD_REQUEST,
            format!("the request body could not be read: {e}\n"),
        )),
        Err(_) => Err(closing(
            StatusCode::REQUEST_TIMEOUT,
            format!(
                "the request body did not arrive within {:.1} s\n",
                bound.as_secs_f64()
            ),
        )),
    }
}

/// A refusal after which the connection is closed (its request was not
/// read to the end).
fn closing(status: StatusCode, message: String) -> Response {
    (status, [(header::CONNECTION, "close")], message).into_response()
}

/// Answers a connection beyond the cap with 503 and closes it.
async fn turn_away(
    mut stream: tokio::net::TcpStream,
    timeout: Duration,
    _permit: OwnedSemaphorePermit,
) {
    let body = "too many connections to the dashboard; try again shortly\n";
    let response = format!(
        "HTTP/1.1 503 Service Unavailable\r\ncontent-type: text/plain\r\nretry-after: 1\r\nconnection: close\r\ncontent-length: {}\r\n\r\n{body}",
        body.len()
    );
    let _ = tokio::time::timeout(timeout, async {
        stream.write_all(response.as_bytes()).await?;
        stream.shutdown().await
    })
    .await;
}

/// The routes, behind the host and token checks, with the default cap on
/// event streams. Requests need a `ConnectInfo<SocketAddr>` (the peer).
pub fn router(master: MasterHandle, access: HttpAccess) -> Router {
    router_with(master, access, HttpLimits::default().max_event_streams)
}

fn router_with(master: MasterHandle, access: HttpAccess, max_event_streams: usize) -> Router {
    let state = HttpState {
        master,
        session: session_value(&access.token).into(),
        access: Arc::new(access),
        streams: Arc::new(Semaphore::new(max_event_streams)),
        view_feed: Arc::new(OnceLock::new()),
        view_pngs: Arc::default(),
    };
    Router::new()
        .route("/", get(|| async { Html(DASHBOARD) }))
        .route(LOGIN_PATH, get(login_page).post(login))
        .route("/api/view", post(steer_view))
        .route("/api/jobs", get(list_jobs))
        .route("/api/jobs/{id}", get(show_job))
        .route("/api/jobs/{id}/{action}", post(control_job))
        .route("/view/image.png", get(view_png))
        .route("/view/objects.png", get(view_objects_png))
        .route("/metrics", get(metrics))
        .route("/api/status", get(status))
        .route("/api/dashboard", get(dashboard))
        .route("/api/events", get(events))
        .route("/frames/live.png", get(live_png))
        .route("/frames/{seq}", get(frame_png))
        .merge(crate::view_http::routes::<HttpState>(state.master.clone()))
        .layer(middleware::from_fn_with_state(state.clone(), require_token))
        .layer(middleware::from_fn(require_same_origin))
        .layer(middleware::from_fn_with_state(state.clone(), require_host))
        .layer(middleware::map_response(own_pages_only))
        .with_state(state)
}

/// Headers a proxy adds: a request with one is not the loopback peer's own.
const FORWARDING_HEADERS: [&str; 3] = ["forwarded", "x-forwarded-for", "x-real-ip"];

/// Whether a request from `peer` may be served: loopback unless forwarded
/// or the token is always required, anyone else with the cluster token as
/// a bearer token or the session cookie that `/login` sets.
pub fn authorized(peer: IpAddr, headers: &HeaderMap, access: &HttpAccess) -> bool {
    let forwarded = FORWARDING_HEADERS.iter().any(|h| headers.contains_key(*h));
    if peer.to_canonical().is_loopback() && !forwarded && !access.require_token {
        return true;
    }
    let token = access.token.as_str();
    let bearer = (headers.get(header::AUTHORIZATION))
        .and_then(|v| v.to_str().ok())
        .and_then(|v| v.strip_prefix("Bearer "));
    bearer.is_some_and(|t| token_matches(token, t))
        || session_cookie(headers).is_some_and(|c| token_matches(&session_value(token), c))
}

/// Whether `host` (a `Host` header: a name or address, maybe with a port)
/// names this server: `localhost`, a loopback address, the listening
/// address (any address when it listens on all), or an allowed name.
pub fn host_allowed(host: &str, access: &HttpAccess) -> bool {
    let name = match host.strip_prefix('[') {
        // [v6]:port
        Some(rest) => rest.split_once(']').map_or(rest, |(v6, _)| v6),
        None => host.rsplit_once(':').map_or(host, |(name, _)| name),
    };
    let name = name.trim_end_matches('.').to_ascii_lowercase();
    if name == "localhost" || name.ends_with(".localhost") {
        return true;
    }
    if let Ok(ip) = name.parse::<IpAddr>() {
        let listen = access.listen.map(|a| a.ip().to_canonical());
        return ip.to_canonical().is_loopback()
            || listen.is_some_and(|l| l.is_unspecified() || l == ip.to_canonical());
    }
    (access.allowed_hosts.iter())
        .any(|allowed| allowed.trim_end_matches('.').eq_ignore_ascii_case(&name))
}

/// Refuses a request whose `Host` names another site (DNS rebinding). A
/// request without one (no browser sends such) passes on to the token check.
async fn require_host(State(state): State<HttpState>, request: Request, next: Next) -> Response {
    let host = request.headers().get(header::HOST).map(|h| h.to_str());
    match host {
        None => next.run(request).await,
        Some(Ok(host)) if host_allowed(host, &state.access) => next.run(request).await,
        Some(host) => {
            let host = host.unwrap_or("(not text)");
            let message = format!(
                "this server is not {host}: call it by its address, localhost, or a name given with --http-allowed-host\n"
            );
            (StatusCode::FORBIDDEN, message).into_response()
        }
    }
}

/// Whether a request can change the farm: any method but GET, HEAD and
/// OPTIONS, and any protocol upgrade (a WebSocket is not bound by CORS).
fn changes_state(request: &Request) -> bool {
    let method = request.method();
    !matches!(*method, Method::GET | Method::HEAD | Method::OPTIONS)
        || request.headers().contains_key(header::UPGRADE)
}

/// Why a request does not come from this server's own pages, if a browser
/// says so: its `Sec-Fetch-Site` is not `same-origin` (or `none`, a typed
/// address), or its `Origin` is not this server's: `http` or `https` and
/// the request's own `Host`. A request with neither (not a browser's, or an
/// old browser's) passes; [`require_same_origin`] asks it for JSON.
pub fn cross_origin(headers: &HeaderMap) -> Option<String> {
    let text = |name| {
        headers
            .get(name)
            .map(|v: &HeaderValue| v.to_str().unwrap_or("(not text)"))
    };
    if let Some(site) = text(header::HeaderName::from_static("sec-fetch-site"))
        && !matches!(site, "same-origin" | "none")
    {
        return Some(format!("Sec-Fetch-Site: {site}"));
    }
    if let Some(origin) = text(header::ORIGIN) {
        let authority =
            (origin.strip_prefix("http://")).or_else(|| origin.strip_prefix("https://"));
        let host = text(header::HOST);
        let own = authority
            .zip(host)
            .is_some_and(|(a, h)| a.eq_ignore_ascii_case(h));
        if !own {
            return Some(format!("Origin: {origin}"));
        }
    }
    None
}

/// Whether the request's body is declared JSON (a type no page of another
/// site may send without a preflight, which [`require_same_origin`] refuses).
fn is_json(headers: &HeaderMap) -> bool {
    (headers.get(header::CONTENT_TYPE))
        .and_then(|v| v.to_str().ok())
        .and_then(|v| v.split(';').next())
        .is_some_and(|essence| essence.trim().eq_ignore_ascii_case("application/json"))
}

/// Lets a request change the farm only from this server's own pages
/// (cross-site request forgery): one a browser marks as from another
/// origin gets 403, and every one but the login form must be declared
/// JSON (else 415). A CORS preflight is answered only for this origin, so a
/// page of another site (a public one reaching this private address
/// included) is never let through.
async fn require_same_origin(request: Request, next: Next) -> Response {
    let headers = request.headers();
    if request.method() == Method::OPTIONS {
        return preflight(headers);
    }
    if changes_state(&request) {
        if let Some(why) = cross_origin(headers) {
            let message = format!(
                "only this server's own pages may change the farm (this request's {why})\n"
            );
            return (StatusCode::FORBIDDEN, message).into_response();
        }
        let upgrade = headers.contains_key(header::UPGRADE);
        if request.uri().path() != LOGIN_PATH && !upgrade && !is_json(headers) {
            let message =
                "requests that change the farm are sent as Content-Type: application/json\n";
            return (StatusCode::UNSUPPORTED_MEDIA_TYPE, message).into_response();
        }
    }
    next.run(request).await
}

/// A CORS preflight: refused (403, no `Access-Control-Allow-*`) unless it
/// comes from this server's own origin, which browsers never preflight;
/// that one is allowed, a private-network request included.
fn preflight(headers: &HeaderMap) -> Response {
    let vary = (header::VARY, HeaderValue::from_static("Origin"));
    let own = (headers.get(header::ORIGIN)).filter(|_| cross_origin(headers).is_none());
    let Some(origin) = own else {
        let message = "this server answers requests from its own pages only\n";
        return (StatusCode::FORBIDDEN, [vary], message).into_response();
    };
    let mut response = (StatusCode::NO_CONTENT, [vary]).into_response();
    let answer = response.headers_mut();
    answer.insert(header::ACCESS_CONTROL_ALLOW_ORIGIN, origin.clone());
    answer.insert(
        header::ACCESS_CONTROL_ALLOW_METHODS,
        HeaderValue::from_static("GET, POST"),
    );
    answer.insert(
        header::ACCESS_CONTROL_ALLOW_HEADERS,
        HeaderValue::from_static("content-type, authorization"),
    );
    if headers.contains_key(REQUEST_PRIVATE_NETWORK) {
        answer.insert(ALLOW_PRIVATE_NETWORK, HeaderValue::from_static("true"));
    }
    response
}

/// Private Network Access: a preflight asking whether a page may reach this
/// (private) address, and the answer that allows it.
const REQUEST_PRIVATE_NETWORK: &str = "access-control-request-private-network";
const ALLOW_PRIVATE_NETWORK: &str = "access-control-allow-private-network";

/// Every response may be shown, embedded or read by this server's own pages
/// only: no framing by another site (clickjacking the buttons), no image or
/// script loads from another site, no content sniffing.
async fn own_pages_only(mut response: Response) -> Response {
    let headers = response.headers_mut();
    for (name, value) in [
        (header::X_FRAME_OPTIONS, "DENY"),
        (header::CONTENT_SECURITY_POLICY, "frame-ancestors 'none'"),
        (
            header::HeaderName::from_static("cross-origin-resource-policy"),
            "same-origin",
        ),
        (header::X_CONTENT_TYPE_OPTIONS, "nosniff"),
    ] {
        headers.insert(name, HeaderValue::from_static(value));
    }
    response
}

/// The session cookie's value for `token`: a hash, so that a stolen cookie
/// does not give the token (which also admits workers).
fn session_value(token: &str) -> String {
    hex::encode(Sha256::digest(format!("vtfarm dashboard session\n{token}")))
}

/// The session cookie of a request, if it sent one.
fn session_cookie(headers: &HeaderMap) -> Option<&str> {
    (headers.get_all(header::COOKIE).iter())
        .filter_map(|v| v.to_str().ok())
        .flat_map(|v| v.split(';'))
        .filter_map(|pair| pair.trim().split_once('='))
        .find(|(name, _)| *name == SESSION_COOKIE)
        .map(|(_, value)| value)
}

async fn require_token(
    State(state): State<HttpState>,
    ConnectInfo(peer): ConnectInfo<SocketAddr>,
    request: Request,
    next: Next,
) -> Response {
    if request.uri().path() == LOGIN_PATH || authorized(peer.ip(), request.headers(), &state.access)
    {
        return next.run(request).await;
    }
    let wants_page = (request.headers().get(header::ACCEPT))
        .and_then(|v| v.to_str().ok())
        .is_some_and(|v| v.contains("text/html"));
    if wants_page {
        // A browser: log in first.
        return Redirect::to(LOGIN_PATH).into_response();
    }
    let challenge = [(header::WWW_AUTHENTICATE, "Bearer")];
    let message =
        "the cluster token is required (Authorization: Bearer TOKEN, or log in at /login)\n";
    (StatusCode::UNAUTHORIZED, challenge, message).into_response()
}

async fn login_page() -> Html<String> {
    Html(LOGIN.replace("{message}", ""))
}

#[derive(Deserialize)]
struct LoginForm {
    token: String,
}

/// The token entered once: the session cookie, then the dashboard.
async fn login(State(state): State<HttpState>, Form(form): Form<LoginForm>) -> Response {
    if !token_matches(&state.access.token, &form.token) {
        let page = LOGIN.replace("{message}", "That is not the cluster token.");
        return (StatusCode::UNAUTHORIZED, Html(page)).into_response();
    }
    let cookie = format!(
        "{SESSION_COOKIE}={}; Path=/; HttpOnly; SameSite=Strict",
        state.session
    );
    ([(header::SET_COOKIE, cookie)], Redirect::to("/")).into_response()
}

fn unavailable() -> Response {
    (StatusCode::SERVICE_UNAVAILABLE, "the master has stopped\n").into_response()
}

/// `MasterCore::status`, the reply `vtfarm status` prints.
async fn status(State(state): State<HttpState>) -> Response {
    match state.master.inspect(MasterCore::status).await {
        Some(reply) => axum::Json(reply).into_response(),
        None => unavailable(),
    }
}

/// Every job the master lists (finished ones kept too), oldest first: what
/// `vtfarm jobs --all --json` prints.
async fn list_jobs(State(state): State<HttpState>) -> Response {
    match state.master.inspect(job_rows).await {
        Some(jobs) => axum::Json(jobs).into_response(),
        None => unavailable(),
    }
}

/// One job (a study with its variants): 404 for a job the master does
/// not list (a variant is listed under its study).
async fn show_job(State(state): State<HttpState>, Path(id): Path<JobId>) -> Response {
    let row = state.master.inspect(move |core| {
        let jobs = core.jobs();
        let entry = jobs.get(id)?;
        Some(JobRowView::from(jobs.row(entry)))
    });
    match row.await {
        Some(Some(row)) => axum::Json(row).into_response(),
        Some(None) => (StatusCode::NOT_FOUND, format!("no job {id}\n")).into_response(),
        None => unavailable(),
    }
}

fn job_rows(core: &MasterCore) -> Vec<JobRowView> {
    (core.jobs().rows(true).into_iter())
        .map(JobRowView::from)
        .collect()
}

/// The body `POST /api/jobs/{id}/requeue` and `…/priority` may carry.
#[derive(Deserialize, Default)]
struct ControlBody {
    /// requeue: only the frames the job did not finish.
    #[serde(default)]
    failed: bool,
    /// priority: the new priority.
    priority: Option<i32>,
}

/// Cancels, pauses, resumes, requeues or re-prioritises a job: answers the
/// job as it is afterwards, 404 for an unknown job, 409 when its state
/// does not allow it, 400 for an unknown action or a bad body.
async fn control_job(
    State(state): State<HttpState>,
    ConnectInfo(peer): ConnectInfo<SocketAddr>,
    Path((id, action)): Path<(JobId, String)>,
    body: axum::body::Bytes,
) -> Response {
    let bad = |message: String| (StatusCode::BAD_REQUEST, message + "\n").into_response();
    let body: ControlBody = match body.is_empty() {
        true => ControlBody::default(),
        false => match serde_json::from_slice(&body) {
            Ok(body) => body,
            Err(e) => return bad(format!("bad body: {e}")),
        },
    };
    let action = match action.as_str() {
        "cancel" => JobAction::Cancel,
        "pause" => JobAction::Pause,
        "resume" => JobAction::Resume,
        "requeue" => JobAction::Requeue {
            failed_only: body.failed,
        },
        "priority" => match body.priority {
            Some(priority) => JobAction::SetPriority(priority),
            None => return bad("priority needs {\"priority\": N}".into()),
        },
        other => {
            return bad(format!(
                "unknown action {other:?}: cancel, pause, resume, requeue or priority"
            ));
        }
    };
    let who = format!("the dashboard ({peer})");
    match state.master.control_job(id, action, who).await {
        Some(Ok(summary)) => axum::Json(summary).into_response(),
        Some(Err(e)) => {
            let status = match e {
                JobControlError::UnknownJob(_) => StatusCode::NOT_FOUND,
                _ => StatusCode::CONFLICT,
            };
            (status, format!("{e}\n")).into_response()
        }
        None => unavailable(),
    }
}

fn dashboard_view(core: &MasterCore) -> DashboardView {
    let telemetry = core.telemetry();
    let mut packages = core.packages_by_worker();
    let status = core.status();
    let names = (status.workers.iter().map(|w| w.name.clone()))
        .chain(telemetry.workers.keys().cloned())
        .collect::<std::collections::BTreeSet<_>>();
    let workers = names
        .into_iter()
        .map(|name| {
            let view = WorkerView {
                totals: (telemetry.workers.get(&name).cloned().unwrap_or_default()).into(),
                packages: packages.remove(&name).unwrap_or_default(),
            };
            (name, view)
        })
        .collect();
    DashboardView {
        status,
        jobs: job_rows(core),
        counters: CountersView::from(&telemetry.counters),
        workers,
        live: core.live_frame().map(|f| LiveView {
            job: f.job,
            frame: f.frame,
            triangles_done: f.triangles_done,
            triangles_total: f.triangles_total,
        }),
        frames: (telemetry.frames())
            .map(|f| FrameView {
                seq: f.seq,
                job: f.job,
                frame: f.frame,
                stats: f.stats.clone(),
            })
            .collect(),
        view: view_state(core),
    }
}

fn view_state(core: &MasterCore) -> ViewState {
    let views = core.views();
    ViewState {
        sources: (views.sources())
            .map(|(job, name)| ViewSourceView {
                job,
                name: name.to_owned(),
            })
            .collect(),
        eye_box: EYE_BOX,
        current: views.current().map(CurrentViewJson::from),
        latest: views.latest().map(|v| LatestView {
            generation: v.generation,
            quality: v.quality.name(),
            glare: v.figures.as_ref().map(|f| f.glare.clone()),
            object_colors: (v.figures.iter())
                .flat_map(|f| 0..f.glare.objects.len())
                .map(|rank| {
                    let [r, g, b] = vtfarm_glare::object_color_srgb(rank);
                    format!("#{r:02x}{g:02x}{b:02x}")
                })
                .collect(),
        }),
        outcomes: views
            .outcomes()
            .copied()
            .map(ViewOutcomeView::from)
            .collect(),
    }
}

/// Moves the view's eye: `{"job": ID, "offset": [x, y, z]}` in metres,
/// with `"page_draws_scene": true` from a page that draws the scene itself
/// and `"preview_only": true` for a move it shows only the preview of;
/// answers the view's farm job and the move's number (`generation`).
async fn steer_view(
    State(state): State<HttpState>,
    axum::Json(body): axum::Json<ViewRequestBody>,
) -> Response {
    let request = ViewRequest {
        job: body.job,
        offset: body.offset,
        page_draws_scene: body.page_draws_scene,
        preview_only: body.preview_only,
    };
    match state.master.steer_view(request).await {
        Some(Ok(job)) => {
            // The move's number, which its stage messages carry.
            let generation = (state.master)
                .inspect(move |c| {
                    c.views()
                        .current()
                        .filter(|v| v.job == job)
                        .map(|v| v.generation)
                })
                .await
                .flatten();
            axum::Json(serde_json::json!({ "job": job, "generation": generation })).into_response()
        }
        Some(Err(e)) => (StatusCode::BAD_REQUEST, format!("{e}\n")).into_response(),
        None => unavailable(),
    }
}

/// A stage of the view encoded for a display: the stage, the factor its
/// image was reduced by, the PNG.
#[derive(Clone)]
struct ViewPng {
    generation: u64,
    quality: &'static str,
    factor: u32,
    png: axum::body::Bytes,
}

/// Encoded view stages kept, the oldest encoded first out: a few display
/// sizes (a dashboard and a bench, a phone's and a desktop's) of the
/// stages on view.
const VIEW_PNGS_KEPT: usize = 4;

/// `/view/image.png`'s query: `width`, the display's width in pixels, asks
/// for the image reduced to fit it (the stage's own pixels when it is at
/// least as wide as the image).
#[derive(Deserialize)]
struct ViewImageQuery {
    width: Option<u32>,
}

/// The view's newest finished stage as PNG, reduced by a whole factor to
/// the display's `width` if given (`Image::reduced`), encoded once per
/// stage and size: the dashboard shows it at a few hundred pixels, and a
/// 1080p frame costs some 10 ms to encode where its reduction to the
/// display costs a few.
async fn view_png(State(state): State<HttpState>, query: Query<ViewImageQuery>) -> Response {
    if query.width == Some(0) {
        return (StatusCode::BAD_REQUEST, "width must be at least 1 pixel\n").into_response();
    }
    let latest = state.master.inspect(|c| {
        let latest = c.views().latest()?;
        Some((
            latest.generation,
            latest.quality.name(),
            latest.frame.clone(),
        ))
    });
    let Some(latest) = latest.await else {
        return unavailable();
    };
    let Some((generation, quality, frame)) = latest else {
        return (StatusCode::NOT_FOUND, "no such image (yet)\n").into_response();
    };
    let factor = query
        .width
        .map_or(1, |w| frame.color.width.div_ceil(w).max(1));
    let is_this =
        |p: &ViewPng| (p.generation, p.quality, p.factor) == (generation, quality, factor);
    let cached =
        (state.view_pngs.lock().ok()).and_then(|kept| kept.iter().find(|p| is_this(p)).cloned());
    let png = match cached {
        Some(kept) => kept.png,
        None => {
            let encoded = tokio::task::spawn_blocking(move || {
                // The stage's own pixels where no reduction is asked for
                // (no copy of a 1080p frame).
                let reduced = (factor > 1).then(|| frame.color.reduced(factor));
                let image = reduced.as_ref().unwrap_or(&frame.color);
                let mut png = Vec::new();
                vtfarm_imaging::encode_srgb8_png(
                    &mut png,
                    image.width,
                    image.height,
                    &image.to_srgb8(),
                )
                .map(|()| png)
            })
            .await;
            let png = match encoded {
                Ok(Ok(png)) => axum::body::Bytes::from(png),
                Ok(Err(e)) => return png_error(PngError::from(e)),
                Err(e) => return png_error(PngError::from(e)),
            };
            if let Ok(mut kept) = state.view_pngs.lock() {
                kept.push(ViewPng {
                    generation,
                    quality,
                    factor,
                    png: png.clone(),
                });
                if kept.len() > VIEW_PNGS_KEPT {
                    kept.remove(0);
                }
            }
            png
        }
    };
    (
        [
            (header::CONTENT_TYPE, "image/png"),
            (header::CACHE_CONTROL, "no-store"),
        ],
        png,
    )
        .into_response()
}

fn png_error(error: PngError) -> Response {
    (StatusCode::INTERNAL_SERVER_ERROR, format!("{error}\n")).into_response()
}

/// The reflected-object map of the view's newest finished stage, once its
/// figures are computed (404 until then).
async fn view_objects_png(State(state): State<HttpState>) -> Response {
    let image = (state.master).inspect(|c| {
        let figures = c.views().latest()?.figures.clone()?;
        Some(Arc::new(figures.object_map.clone()))
    });
    kept_png(image.await, linear_srgb8).await
}

/// 8-bit sRGB pixels, RGB interleaved: width, height and the bytes.
type Srgb8 = (u32, u32, Vec<u8>);

/// Why a kept image could not be served as PNG.
#[derive(Debug, thiserror::Error)]
enum PngError {
    #[error("the kept frame does not decode: {0}")]
    Decode(#[from] vtfarm_proto::WireError),
    #[error("PNG encoding: {0}")]
    Encode(#[from] image::ImageError),
    #[error("PNG encoding stopped: {0}")]
    Task(#[from] tokio::task::JoinError),
}

/// A kept image as PNG of its `srgb8` pixels; 404 when there is none, 503
/// once the master stopped.
async fn kept_png<T: Send + 'static>(
    image: Option<Option<T>>,
    srgb8: fn(T) -> Result<Srgb8, PngError>,
) -> Response {
    match image {
        Some(Some(image)) => png_response(move || srgb8(image)).await,
        Some(None) => (StatusCode::NOT_FOUND, "no such image (yet)\n").into_response(),
        None => unavailable(),
    }
}

async fn dashboard(State(state): State<HttpState>) -> Response {
    match state.master.inspect(dashboard_view).await {
        Some(view) => axum::Json(view).into_response(),
        None => unavailable(),
    }
}

/// Server-sent events: the dashboard view now, then again whenever the
/// master's state moves (changes in between coalesce: a client that reads
/// slowly gets the newest view when it reads again). 503 beyond
/// [`HttpLimits::max_event_streams`].
async fn events(State(state): State<HttpState>) -> Response {
    let Ok(permit) = state.streams.clone().try_acquire_owned() else {
        let message = "too many dashboards follow this master; close one and try again\n";
        return (StatusCode::SERVICE_UNAVAILABLE, message).into_response();
    };
    let Some(first) = state.master.inspect(dashboard_json).await else {
        return unavailable();
    };
    let feed = (state.view_feed)
        .get_or_init(|| view_feed(state.master.clone()))
        .clone();
    let stream = stream::unfold(
        (Some(first), feed, permit),
        |(first, mut feed, permit)| async move {
            let json = match first {
                Some(json) => json,
                None => {
                    feed.changed().await.ok()?;
                    feed.borrow_and_update().clone()
                }
            };
            let event = Event::default().event("farm").data(&*json);
            Some((Ok::<_, Infallible>(event), (None, feed, permit)))
        },
    );
    Sse::new(stream).into_response()
}

fn dashboard_json(core: &MasterCore) -> Arc<str> {
    serde_json::to_string(&dashboard_view(core))
        .unwrap_or_default()
        .into()
}

/// The dashboard view as JSON, computed again (at most every
/// [`VIEW_INTERVAL`]) when the master's state moved and someone follows
/// it; ends with the master.
///
/// A new stage of the interactive view (or its glare figures) goes out at
/// once, not at the end of the interval: the view's latency is what its
/// user feels.
fn view_feed(master: MasterHandle) -> watch::Receiver<Arc<str>> {
    let (publish, feed) = watch::channel(Arc::<str>::from(""));
    let mut changes = master.changes();
    tokio::spawn(async move {
        // A change seen during the last interval, not published yet.
        let mut pending = false;
        loop {
            if !pending && changes.changed().await.is_err() {
                return;
            }
            changes.mark_unchanged();
            pending = false;
            let mut published = None;
            // The feed kept by the router is one receiver; streams are the rest.
            if publish.receiver_count() > 1 {
                let read = |c: &MasterCore| (dashboard_json(c), view_key(c));
                let Some((json, key)) = master.inspect(read).await else {
                    return;
                };
                publish.send_replace(json);
                published = key;
            }
            let until = tokio::time::Instant::now() + VIEW_INTERVAL;
            loop {
                tokio::select! {
                    () = tokio::time::sleep_until(until) => break,
                    changed = changes.changed() => {
                        if changed.is_err() {
                            return;
                        }
                        changes.mark_unchanged();
                        pending = true;
                        let Some(key) = master.inspect(view_key).await else {
                            return;
                        };
                        if key != published {
                            break;
                        }
                    }
                }
            }
        }
    });
    feed
}

/// The frame being assembled, as far as it got.
async fn live_png(State(state): State<HttpState>) -> Response {
    let image = state
        .master
        .inspect(|c| c.live_frame().map(|f| f.image.clone()));
    match image.await {
        Some(Some(image)) => png_response(move || linear_srgb8(Arc::new(image))).await,
        Some(None) => (StatusCode::NOT_FOUND, "no frame is being rendered\n").into_response(),
        None => unavailable(),
    }
}

/// A kept finished frame, `/frames/SEQ.png`, or its timeline, `/frames/SEQ.svg`.
async fn frame_png(State(state): State<HttpState>, Path(name): Path<String>) -> Response {
    let parsed =
        (name.rsplit_once('.')).and_then(|(seq, kind)| Some((seq.parse::<u64>().ok()?, kind)));
    match parsed {
        Some((seq, "png")) => {
            let image =
                (state.master).inspect(move |c| c.telemetry().frame(seq).map(|f| f.image.clone()));
            kept_png(image.await, wire_srgb8).await
        }
        Some((seq, "svg")) => {
            let svg = (state.master).inspect(move |c| {
                (c.telemetry().frame(seq)).map(|f| crate::timeline::timeline_svg(&f.stats))
            });
            match svg.await {
                Some(Some(svg)) => ([(header::CONTENT_TYPE, "image/svg+xml")], svg).into_response(),
                Some(None) => (StatusCode::NOT_FOUND, "that frame is not kept\n").into_response(),
                None => unavailable(),
            }
        }
        _ => (
            StatusCode::NOT_FOUND,
            "frames are /frames/SEQ.png and /frames/SEQ.svg\n",
        )
            .into_response(),
    }
}

fn linear_srgb8(image: Arc<Image>) -> Result<Srgb8, PngError> {
    Ok((image.width, image.height, image.to_srgb8()))
}

/// A finished frame as kept: compressed, linear or sRGB.
fn wire_srgb8(image: Arc<WireImage>) -> Result<Srgb8, PngError> {
    Ok(Arc::unwrap_or_clone(image).into_srgb8()?)
}

/// The `srgb8` pixels as a PNG, made and encoded off the async threads.
async fn png_response(
    srgb8: impl FnOnce() -> Result<Srgb8, PngError> + Send + 'static,
) -> Response {
    let encoded = tokio::task::spawn_blocking(move || {
        let (width, height, pixels) = srgb8()?;
        let mut png = Vec::new();
        vtfarm_imaging::encode_srgb8_png(&mut png, width, height, &pixels)?;
        Ok::<_, PngError>(png)
    })
    .await
    .unwrap_or_else(|e| Err(PngError::from(e)));
    match encoded {
        Ok(png) => (
            [
                (header::CONTENT_TYPE, "image/png"),
                (header::CACHE_CONTROL, "no-store"),
            ],
            png,
        )
            .into_response(),
        Err(e) => png_error(e),
    }
}

/// The farm's metrics in the Prometheus (OpenMetrics) text format.
async fn metrics(State(state): State<HttpState>) -> Response {
    let Some(registry) = state.master.inspect(metrics_registry).await else {
        return unavailable();
    };
    let mut text = String::new();
    if let Err(e) = prometheus_client::encoding::text::encode(&mut text, &registry) {
        return (StatusCode::INTERNAL_SERVER_ERROR, format!("metrics: {e}\n")).into_response();
    }
    let content_type = "application/openmetrics-text; version=1.0.0; charset=utf-8";
    ([(header::CONTENT_TYPE, content_type)], text).into_response()
}

type Labels = Vec<(&'static str, String)>;

fn counter_family(registry: &mut Registry, name: &str, help: &str, values: &[(Labels, u64)]) {
    let family = Family::<Labels, Counter>::default();
    for (labels, value) in values {
        family.get_or_create(labels).inc_by(*value);
    }
    registry.register(name, help, family);
}

fn gauge_family(registry: &mut Registry, name: &str, help: &str, values: &[(Labels, f64)]) {
    let family = Family::<Labels, Gauge<f64, std::sync::atomic::AtomicU64>>::default();
    for (labels, value) in values {
        family.get_or_create(labels).set(*value);
    }
    registry.register(name, help, family);
}

/// A metric without labels.
fn counter(registry: &mut Registry, name: &str, help: &str, value: u64) {
    let counter = Counter::<u64>::default();
    counter.inc_by(value);
    registry.register(name, help, counter);
}

fn gauge(registry: &mut Registry, name: &str, help: &str, value: f64) {
    let gauge = Gauge::<f64, std::sync::atomic::AtomicU64>::default();
    gauge.set(value);
    registry.register(name, help, gauge);
}

fn label(key: &'static str, value: impl Into<String>) -> Labels {
    vec![(key, value.into())]
}

/// A registry holding the core's figures right now.
fn metrics_registry(core: &MasterCore) -> Registry {
    let status = core.status();
    let telemetry = core.telemetry();
    let c = &telemetry.counters;
    let mut r = Registry::with_prefix("vtfarm");
    counter_family(
        &mut r,
        "jobs",
        "Jobs that reached each state since the master started",
        &[
            (label("state", "submitted"), c.jobs_submitted),
            (label("state", "completed"), c.jobs_completed),
            (label("state", "failed"), c.jobs_failed),
            (label("state", "cancelled"), c.jobs_cancelled),
        ],
    );
    // The listing's states, as `vtfarm jobs --all` counts them.
    let jobs = core.jobs();
    let per_state: Vec<(Labels, f64)> = (JobState::ALL.into_iter())
        .map(|s| (label("state", s.name()), jobs.count(s) as f64))
        .collect();
    gauge_family(
        &mut r,
        "jobs_now",
        "Jobs the master lists now, by state (finished ones while it keeps them)",
        &per_state,
    );
    counter(&mut r, "frames", "Frames completed", c.frames_completed);
    counter_family(
        &mut r,
        "packages",
        "Packages by outcome: done, failed attempts, requeued from lost workers, straggler copies",
        &[
            (label("state", "done"), c.packages_done),
            (label("state", "failed"), c.packages_failed),
            (label("state", "requeued"), c.packages_requeued),
            (label("state", "duplicated"), c.packages_duplicated),
        ],
    );
    let running: u64 = status
        .workers
        .iter()
        .map(|w| u64::from(w.packages_running))
        .sum();
    gauge(
        &mut r,
        "packages_running",
        "Packages out at workers now",
        running as f64,
    );
    let per_worker = |f: &dyn Fn(&vtfarm_proto::WorkerStatus) -> f64| -> Vec<(Labels, f64)> {
        (status.workers.iter())
            .map(|w| (label("worker", w.name.clone()), f(w)))
            .collect()
    };
    gauge_family(
        &mut r,
        "worker_busy_seconds",
        "Seconds each connected worker spent on packages",
        &per_worker(&|w| w.busy_micros as f64 / 1e6),
    );
    gauge_family(
        &mut r,
        "worker_throughput",
        "Each connected worker's measured throughput (work units per second)",
        &per_worker(&|w| w.throughput),
    );
    gauge_family(
        &mut r,
        "worker_failures",
        "Failed packages of each connected worker",
        &per_worker(&|w| w.failures as f64),
    );
    let states: Vec<(Labels, f64)> = ["idle", "waiting", "busy"]
        .into_iter()
        .map(|s| {
            let n = status.workers.iter().filter(|w| w.state == s).count();
            (label("state", s), n as f64)
        })
        .collect();
    gauge_family(&mut r, "workers", "Connected workers by state", &states);
    let totals = |f: &dyn Fn(&WorkerTotals) -> u64| -> Vec<(Labels, u64)> {
        (telemetry.workers.iter())
            .map(|(name, t)| (label("worker", name.clone()), f(t)))
            .collect()
    };
    counter_family(
        &mut r,
        "worker_samples",
        "Samples (rays) each worker traced in accepted results",
        &totals(&|t| t.samples),
    );
    let bytes: Vec<(Labels, u64)> = (telemetry.workers.iter())
        .flat_map(|(name, t)| {
            [("in", t.bytes_in), ("out", t.bytes_out)].map(|(direction, n)| {
                (
                    vec![
                        ("worker", name.clone()),
                        ("direction", direction.to_owned()),
                    ],
                    n,
                )
            })
        })
        .collect();
    counter_family(
        &mut r,
        "worker_bytes",
        "Package (in) and result (out) bytes of each worker's accepted results",
        &bytes,
    );
    counter(
        &mut r,
        "journal_write_failures",
        "Journal records that could not be written (a full disk, say)",
        c.journal_write_failures,
    );
    counter(
        &mut r,
        "frames_rendered_again",
        "Finished frames the journal could not give back, rendered again",
        c.frames_rendered_again,
    );
    counter(
        &mut r,
        "scene_bytes_sent",
        "Scene bytes sent to workers",
        status.scene_bytes_sent,
    );
    r.register_with_unit(
        "frame_duration",
        "Wall time of each completed frame",
        prometheus_client::registry::Unit::Seconds,
        FrameDurationMetric(telemetry.frame_durations.clone()),
    );
    r
}

/// The core's frame-duration histogram as a Prometheus histogram.
#[derive(Debug)]
struct FrameDurationMetric(FrameDurations);

impl EncodeMetric for FrameDurationMetric {
    fn encode(&self, mut encoder: MetricEncoder) -> Result<(), std::fmt::Error> {
        let bounds = FRAME_SECONDS_BUCKETS.iter().copied().chain([f64::MAX]);
        let buckets: Vec<(f64, u64)> = bounds.zip(self.0.counts).collect();
        encoder.encode_histogram::<NoLabelSet>(self.0.sum_seconds, self.0.count, &buckets, None)
    }

    fn metric_type(&self) -> MetricType {
        MetricType::Histogram
    }
}
