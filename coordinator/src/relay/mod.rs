//! `coordinator relay`: one upstream client for many local workers, like a node of an MPI
//! reduction tree.
//!
//! Why: the coordinator's cost is per result (reading, decoding and storing a whole image's
//! sums), not per pass. A relay leases batches upstream on behalf of its workers (asking for
//! one pass per worker at first, so the coordinator's batch sizing sees it as one fast
//! worker), hands them parts of each batch through the same worker API, adds their exact
//! sums (integers, so the bits do not depend on the order) and forwards one result per
//! batch. A relay with F workers cuts the coordinator's results by about F. Relays can be
//! stacked: a relay's upstream may be another relay.
//!
//! What it keeps: the parts' sums in memory until their batch is complete (one image sum per
//! batch in progress). If the relay dies, its upstream leases expire and the coordinator
//! hands their passes out again, as for a dead worker: work is lost, never counted twice or
//! wrong. Workers' bundles are fetched through it from upstream (not cached).

pub mod book;

use std::sync::{Arc, Mutex};
use std::time::{Duration, Instant};

use anyhow::{Context, bail};
use axum::body::{Body, Bytes};
use axum::extract::{Path, Request, State};
use axum::http::{HeaderMap, StatusCode, header};
use axum::response::{IntoResponse, Response};
use axum::routing::{get, post, put};
use axum::{Json, Router};
use photonfarm::compression::{self, CompressionError};
use photonfarm::protocol::{
    Endpoint, HeartbeatReply, LEASE_KEY_HEADER, Lease, LeaseRequest, Release, decode_result, encode_batch,
    encode_result, max_encoded_batch, routes,
};
use serde_json::json;
use sha2::{Digest, Sha256};

use crate::cli::RelayArgs;
use crate::serving::ServingLimits;
use crate::serving::result_body::{BodyError, lease_key, read_result_body, result_encoding};
use book::{Book, PartError};

/// Shared by the relay's handlers and loops.
pub struct Relay {
    book: Mutex<Book>,
    epoch: Instant,
    upstream: Endpoint,
    local_token: Option<String>,
    name: String,
    /// One upstream lease request at a time: workers asking together share the batch it gets.
    leasing: tokio::sync::Mutex<()>,
    /// Local results read at once (each may be a whole image's sums).
    uploads: tokio::sync::Semaphore,
    serving: ServingLimits,
}

/// Relay settings.
#[derive(Clone, Debug)]
pub struct RelayConfig {
    /// The upstream's base URL.
    pub upstream: String,
    /// The upstream's workers' token.
    pub token: Option<String>,
    /// The local workers' token.
    pub local_token: Option<String>,
    /// This relay's worker name upstream.
    pub name: String,
    /// A part without a heartbeat for this long goes to another local worker.
    pub lease_timeout_ms: u64,
    /// Local results read at once.
    pub max_uploads: usize,
    /// What local clients are allowed (as the coordinator's).
    pub serving: ServingLimits,
}

struct RelayError(StatusCode, String);

impl IntoResponse for RelayError {
    fn into_response(self) -> Response {
        (self.0, Json(json!({ "error": self.1 }))).into_response()
    }
}

impl From<PartError> for RelayError {
    fn from(e: PartError) -> RelayError {
        let status = match e {
            PartError::NotActive(_) => StatusCode::CONFLICT,
            PartError::Gone(_) => StatusCode::GONE,
            PartError::NotYours(_) => StatusCode::FORBIDDEN,
        };
        RelayError(status, e.to_string())
    }
}

type RelayResult<T> = Result<T, RelayError>;

fn bad_gateway(e: impl std::fmt::Display) -> RelayError {
    RelayError(StatusCode::BAD_GATEWAY, format!("upstream: {e}"))
}

impl Relay {
    /// A relay (nothing leased yet).
    pub fn new(config: RelayConfig) -> anyhow::Result<Arc<Relay>> {
        crate::client::check_address(&config.upstream)?;
        Ok(Arc::new(Relay {
            book: Mutex::new(Book::new(config.lease_timeout_ms)),
            epoch: Instant::now(),
            upstream: Endpoint::new(
                &config.upstream,
                config.token,
                reqwest::Client::builder()
                    .timeout(Duration::from_secs(600))
                    .build()?,
            ),
            local_token: config.local_token,
            name: config.name,
            leasing: tokio::sync::Mutex::new(()),
            uploads: tokio::sync::Semaphore::new(config.max_uploads.max(1)),
            serving: config.serving,
        }))
    }

    fn now(&self) -> u64 {
        self.epoch.elapsed().as_millis() as u64
    }

    fn book(&self) -> std::sync::MutexGuard<'_, Book> {
        self.book.lock().unwrap_or_else(|p| p.into_inner())
    }

    fn up(&self, method: reqwest::Method, path: &str) -> reqwest::RequestBuilder {
        self.upstream.request(method, path)
    }

    fn new_key(&self) -> String {
        use std::hash::{BuildHasher, Hasher};
        let s = std::collections::hash_map::RandomState::new();
        let mut a = s.build_hasher();
        a.write_u128(self.epoch.elapsed().as_nanos());
        let mut b = s.build_hasher();
        b.write_u64(a.finish());
        format!("{:016x}{:016x}", a.finish(), b.finish())
    }
}

/// The relay's routes: the workers' part of the coordinator's API (docs/api.md).
/// Behind the coordinator's limits ([`crate::serving`]): JSON bodies are small, a result is
/// bounded by its lease in the handler.
pub fn router(relay: Arc<Relay>) -> Router {
    let routes = Router::new()
        .route(routes::HEALTH, get(|| async { Json(json!({ "status": "ok" })) }))
        .route(routes::LEASE, post(lease))
        .route(routes::HEARTBEAT, post(heartbeat))
        .route(
            routes::RESULT,
            put(result).layer(axum::extract::DefaultBodyLimit::disable()),
        )
        .route(routes::RELEASE, post(release))
        .route(routes::BUNDLE, get(bundle));
    crate::serving::guarded(routes, &relay.serving)
        .layer(axum::middleware::from_fn_with_state(relay.clone(), auth))
        .with_state(relay)
}

async fn auth(State(relay): State<Arc<Relay>>, req: Request, next: axum::middleware::Next) -> Response {
    if let Some(want) = &relay.local_token {
        let given = req
            .headers()
            .get(header::AUTHORIZATION)
            .and_then(|v| v.to_str().ok())
            .and_then(|v| v.split_once(' '))
            .filter(|(scheme, _)| scheme.eq_ignore_ascii_case("bearer"))
            .map_or("", |(_, t)| t.trim());
        if Sha256::digest(given.as_bytes()) != Sha256::digest(want.as_bytes()) {
            return RelayError(StatusCode::UNAUTHORIZED, "missing or wrong bearer token".into())
                .into_response();
        }
    }
    next.run(req).await
}

/// A JSON body, or the body limit's (or the body timeout's) error.
async fn json_bytes(req: Request) -> RelayResult<Bytes> {
    use axum::extract::FromRequest;
    Bytes::from_request(req, &())
        .await
        .map_err(|e| RelayError(e.status(), e.body_text()))
}

fn parse_id(s: &str) -> RelayResult<u64> {
    s.parse()
        .map_err(|_| RelayError(StatusCode::NOT_FOUND, format!("\"{s}\" is not an id")))
}

/// `POST /api/lease`: a part of a batch held, or of a new batch leased upstream.
async fn lease(State(relay): State<Arc<Relay>>, req: Request) -> RelayResult<Response> {
    let body = json_bytes(req).await?;
    let req: LeaseRequest = serde_json::from_slice(&body)
        .map_err(|e| RelayError(StatusCode::BAD_REQUEST, format!("malformed JSON: {e}")))?;
    let now = relay.now();
    let renderers = relay.book().asked(&req.worker, now);
    if let Some(l) = relay.book().take(relay.new_key(), now) {
        return Ok(Json(l).into_response());
    }
    let _turn = relay.leasing.lock().await;
    // Another request may have leased a batch while this one waited.
    if let Some(l) = relay.book().take(relay.new_key(), relay.now()) {
        return Ok(Json(l).into_response());
    }
    let request = LeaseRequest {
        worker: relay.name.clone(),
        threads: req.threads,
        renderers: Some(renderers),
    };
    let resp = relay
        .up(reqwest::Method::POST, routes::LEASE)
        .json(&request)
        .send()
        .await
        .map_err(bad_gateway)?;
    match resp.status() {
        StatusCode::NO_CONTENT => Ok(StatusCode::NO_CONTENT.into_response()),
        s if s.is_success() => {
            let up: Lease = resp.json().await.map_err(bad_gateway)?;
            tracing::info!(
                lease = up.lease_id,
                job = up.job_id,
                start = up.start,
                end = up.end,
                "leased upstream"
            );
            let now = relay.now();
            let mut book = relay.book();
            book.add_batch(up, now);
            match book.take(relay.new_key(), now) {
                Some(l) => Ok(Json(l).into_response()),
                None => Ok(StatusCode::NO_CONTENT.into_response()),
            }
        }
        s => Err(bad_gateway(format!(
            "{s} {}",
            resp.text().await.unwrap_or_default()
        ))),
    }
}

async fn heartbeat(
    State(relay): State<Arc<Relay>>,
    Path(id): Path<String>,
    headers: HeaderMap,
) -> RelayResult<Response> {
    let id = parse_id(&id)?;
    let deadline_ms = relay.book().heartbeat(id, &lease_key(&headers), relay.now())?;
    Ok(Json(HeartbeatReply { deadline_ms }).into_response())
}

async fn release(
    State(relay): State<Arc<Relay>>,
    Path(id): Path<String>,
    headers: HeaderMap,
    req: Request,
) -> RelayResult<Response> {
    let id = parse_id(&id)?;
    let body = json_bytes(req).await?;
    let r: Release = serde_json::from_slice(&body)
        .map_err(|e| RelayError(StatusCode::BAD_REQUEST, format!("malformed JSON: {e}")))?;
    let given_up = relay
        .book()
        .release(id, &lease_key(&headers), r.error.is_some())?;
    if let Some(up) = given_up {
        tracing::warn!(
            lease = up.lease_id,
            "a batch failed on local workers; giving it up upstream"
        );
        let _ = relay
            .up(reqwest::Method::POST, &routes::release(up.lease_id))
            .header(LEASE_KEY_HEADER, &up.key)
            .json(&r)
            .send()
            .await;
    }
    Ok(Json(json!({ "released": true })).into_response())
}

/// `PUT /api/leases/{id}/result`: bounded, decoded and checked like the coordinator does,
/// then added to its batch's sum; the part that completes a batch forwards it.
async fn result(
    State(relay): State<Arc<Relay>>,
    Path(id): Path<String>,
    headers: HeaderMap,
    req: Request,
) -> RelayResult<Response> {
    let id = parse_id(&id)?;
    let key = lease_key(&headers);
    let encoding = result_encoding(&headers)
        .map_err(|e| RelayError(StatusCode::UNSUPPORTED_MEDIA_TYPE, e.to_string()))?;
    let info = relay.book().expected(id, &key)?;
    if info.width == 0 {
        // Without the size no result can be bounded by its image (an older coordinator).
        return Err(RelayError(
            StatusCode::BAD_GATEWAY,
            format!(
                "the upstream coordinator did not say lease {id}'s image size, which a relay \
                 needs to bound its results: upgrade the coordinator"
            ),
        ));
    }
    let (width, height) = (info.width, info.height);
    let max = max_encoded_batch(width, height, info.features);
    let (body, _slot) = read_result_body(&headers, req, encoding, max, &relay.uploads)
        .await
        .map_err(|e| match e {
            BodyError::TooLarge(_) => RelayError(
                StatusCode::PAYLOAD_TOO_LARGE,
                format!("a result for lease {id} is at most {max} bytes"),
            ),
            BodyError::Stalled => RelayError(
                StatusCode::REQUEST_TIMEOUT,
                format!("the result for lease {id} stalled for longer than --body-timeout"),
            ),
            BodyError::Broken(m) => RelayError(StatusCode::BAD_REQUEST, format!("reading the result: {m}")),
            BodyError::Io(e) => bad_gateway(e),
            BodyError::Closed(e) => bad_gateway(e),
        })?;
    let decoded = tokio::task::spawn_blocking(move || {
        let plain = compression::decompress_bounded(encoding, &body, max)?;
        decode_result(&plain, width, height).map_err(|e| CompressionError::Malformed(e.to_string()))
    })
    .await
    .map_err(bad_gateway)?;
    let r = match decoded {
        Ok(r) => r,
        Err(e @ CompressionError::TooLarge(_)) => {
            return Err(RelayError(StatusCode::PAYLOAD_TOO_LARGE, e.to_string()));
        }
        Err(e) => return Err(RelayError(StatusCode::BAD_REQUEST, e.to_string())),
    };
    let passes = info.end - info.start;
    let odd_passes = info.end / 2 - info.start / 2;
    let fits = r.sum.passes == passes
        && r.odd.as_ref().is_none_or(|o| o.passes == odd_passes)
        && r.features.is_some() == info.features;
    if !fits {
        let msg = format!(
            "result does not match the lease: expected {passes} passes ({odd_passes} odd), got {}x{} with {}",
            r.sum.width, r.sum.height, r.sum.passes
        );
        let _ = relay.book().release(id, &key, true);
        return Err(RelayError(StatusCode::BAD_REQUEST, msg));
    }
    let sum = relay.book().deliver(id, &key)?;
    let start = info.start;
    let complete = tokio::task::spawn_blocking(move || {
        let mut s = sum.lock().unwrap_or_else(|p| p.into_inner());
        s.add(start, r.sum, r.odd, r.features).map_err(|e| e.to_string())
    })
    .await
    .map_err(bad_gateway)?
    .map_err(|e| RelayError(StatusCode::BAD_REQUEST, e))?;
    if complete {
        let lease = relay.book().forwarding(info.batch);
        if let Some(lease) = lease {
            tokio::spawn(forward(relay.clone(), lease));
        }
    }
    Ok(Json(json!({ "accepted": true })).into_response())
}

/// Sends a complete batch upstream, retrying while the upstream is away (the batch is
/// heartbeated meanwhile); forgets it once the upstream answers.
async fn forward(relay: Arc<Relay>, lease: Lease) {
    let Some(sum) = relay.book().sum_of(lease.lease_id) else {
        return;
    };
    let compress = lease.accept_encoding.iter().any(|e| e == compression::ZSTD);
    let body = tokio::task::spawn_blocking(move || {
        let s = sum.lock().unwrap_or_else(|p| p.into_inner());
        let film = s.sum.as_ref()?;
        // Features travel with the odd sample (PFBATCH4): see BatchSum::add.
        let plain = match &s.odd {
            Some(odd) => encode_result(film, odd, s.features.as_ref()),
            None => encode_batch(film),
        };
        Some(Bytes::from(if compress {
            compression::compress(&plain)
        } else {
            plain
        }))
    })
    .await
    .ok()
    .flatten();
    let Some(body) = body else {
        relay.book().finish(lease.lease_id);
        return;
    };
    let mut backoff = Duration::from_millis(200);
    loop {
        let mut put = relay
            .up(reqwest::Method::PUT, &routes::result(lease.lease_id))
            .header(header::CONTENT_TYPE, "application/octet-stream")
            .header(LEASE_KEY_HEADER, &lease.key);
        if compress {
            put = put.header(header::CONTENT_ENCODING, compression::ZSTD);
        }
        match put.body(body.clone()).send().await {
            Ok(r) if r.status().is_success() => {
                tracing::info!(
                    lease = lease.lease_id,
                    start = lease.start,
                    end = lease.end,
                    "batch forwarded"
                );
                break;
            }
            Ok(r) if !r.status().is_server_error() => {
                let s = r.status();
                tracing::warn!(
                    lease = lease.lease_id,
                    "upstream refused the batch: {s} {}",
                    r.text().await.unwrap_or_default()
                );
                break;
            }
            Ok(r) => tracing::warn!(
                lease = lease.lease_id,
                "upstream failed: {}; retrying",
                r.status()
            ),
            Err(e) => tracing::warn!(lease = lease.lease_id, "upstream unreachable: {e}; retrying"),
        }
        tokio::time::sleep(backoff).await;
        backoff = (backoff * 2).min(Duration::from_secs(5));
    }
    relay.book().finish(lease.lease_id);
}

/// `GET /api/bundles/{hash}`: streamed from upstream.
async fn bundle(State(relay): State<Arc<Relay>>, Path(hash): Path<String>) -> RelayResult<Response> {
    if hash.len() != 64 || !hash.chars().all(|c| c.is_ascii_hexdigit()) {
        return Err(RelayError(StatusCode::NOT_FOUND, "no such bundle".into()));
    }
    let resp = relay
        .up(reqwest::Method::GET, &routes::bundle(&hash))
        .send()
        .await
        .map_err(bad_gateway)?;
    let status = resp.status();
    if !status.is_success() {
        return Err(RelayError(status, resp.text().await.unwrap_or_default()));
    }
    let stream = futures_util::stream::unfold(resp, |mut r| async move {
        match r.chunk().await {
            Ok(Some(c)) => Some((Ok::<_, reqwest::Error>(c), r)),
            Ok(None) => None,
            Err(e) => Some((Err(e), r)),
        }
    });
    Ok((
        [(header::CONTENT_TYPE, "application/x-tar")],
        Body::from_stream(stream),
    )
        .into_response())
}

/// Heartbeats every upstream batch held as often as its lease asks (its `heartbeat_ms`, so a
/// coordinator with a short lease timeout is heartbeated in time); a batch the upstream no
/// longer holds is forgotten (its local workers learn it at their next heartbeat). Also
/// expires silent local parts.
async fn upkeep(relay: Arc<Relay>) {
    let mut tick = tokio::time::interval(UPKEEP_TICK);
    loop {
        tick.tick().await;
        let now = relay.now();
        relay.book().expire(now);
        let due = relay.book().due(now);
        for (id, key) in due {
            let r = relay
                .up(reqwest::Method::POST, &routes::heartbeat(id))
                .header(LEASE_KEY_HEADER, &key)
                .timeout(Duration::from_secs(10))
                .send()
                .await;
            if let Ok(r) = r
                && matches!(
                    r.status(),
                    StatusCode::CONFLICT | StatusCode::GONE | StatusCode::FORBIDDEN
                )
            {
                tracing::warn!(lease = id, "the upstream no longer holds this batch; dropping it");
                relay.book().finish(id);
            }
        }
    }
}

/// How often the relay looks for heartbeats due and local parts expired.
const UPKEEP_TICK: Duration = Duration::from_millis(100);

/// Serves local workers on `listener` until `shutdown`.
pub async fn serve(
    listener: tokio::net::TcpListener,
    relay: Arc<Relay>,
    shutdown: impl std::future::Future<Output = ()> + Send + 'static,
) -> anyhow::Result<()> {
    let keep = tokio::spawn(upkeep(relay.clone()));
    println!("listening on http://{}", listener.local_addr()?);
    let serving = relay.serving;
    crate::serving::serve(listener, router(relay), serving, shutdown).await?;
    keep.abort();
    Ok(())
}

/// `coordinator relay`.
pub fn run(args: &RelayArgs) -> anyhow::Result<()> {
    if !(args.lease_timeout > 0.0 && args.lease_timeout.is_finite()) {
        bail!("--lease-timeout must be a positive number of seconds");
    }
    photonfarm::process::init_logging();
    let token = args.token.clone().filter(|t| !t.is_empty());
    let name = args.name.clone().unwrap_or_else(|| {
        let host = std::env::var("HOSTNAME").unwrap_or_else(|_| "host".into());
        format!("relay-{host}-{}", std::process::id())
    });
    let relay = Relay::new(RelayConfig {
        upstream: args.upstream.clone(),
        local_token: args
            .local_token
            .clone()
            .filter(|t| !t.is_empty())
            .or_else(|| token.clone()),
        token,
        name,
        lease_timeout_ms: (args.lease_timeout * 1000.0) as u64,
        max_uploads: args.max_uploads,
        serving: args.connections.checked().map_err(anyhow::Error::msg)?,
    })?;
    let rt = tokio::runtime::Runtime::new().context("cannot start the async runtime")?;
    rt.block_on(async {
        let listener = tokio::net::TcpListener::bind(&args.bind)
            .await
            .with_context(|| format!("cannot listen on {}", args.bind))?;
        serve(listener, relay, photonfarm::process::shutdown_signal()).await
    })
}
