//! The HTTP API (documented in docs/api.md): routes, authentication, limits and errors.
//!
//! Every failure is a JSON `{"error": "..."}` with a 4xx or 5xx status, never a panic;
//! internal details of 5xx errors are logged, not sent. Handlers lock the farm only for
//! bookkeeping; scene loading and decoding happen outside the lock, on blocking threads.

use std::path::PathBuf;
use std::sync::atomic::{AtomicU64, Ordering};
use std::sync::{Arc, Mutex};

use axum::body::Bytes;
use axum::extract::{DefaultBodyLimit, FromRequest, Multipart, Path, Request, State};
use axum::http::{HeaderMap, StatusCode, header};
use axum::middleware::{self, Next};
use axum::response::{IntoResponse, Response};
use axum::routing::{get, post, put};
use axum::{Json, Router};
use photonfarm::job::JobSettings;
use photonfarm::protocol::{LeaseRequest, Release, decode_batch};
use photonfarm::scene::Scene;
use serde_json::json;
use sha2::{Digest, Sha256};

use crate::farm::{Farm, FarmError};

/// Shared by every handler.
pub struct AppState {
    /// The farm. A std mutex: critical sections are short and never await.
    pub farm: Mutex<Farm>,
    /// Bearer token every request must carry, if set.
    pub token: Option<String>,
    /// Largest accepted upload (bundles and batch results), bytes.
    pub max_upload: usize,
    /// Names scratch folders for incoming bundles.
    pub uploads: AtomicU64,
}

/// An error response.
#[derive(Debug)]
pub struct ApiError(StatusCode, String);

impl ApiError {
    fn new(status: StatusCode, msg: impl Into<String>) -> ApiError {
        ApiError(status, msg.into())
    }
}

impl IntoResponse for ApiError {
    fn into_response(self) -> Response {
        (self.0, Json(json!({ "error": self.1 }))).into_response()
    }
}

impl From<FarmError> for ApiError {
    fn from(e: FarmError) -> ApiError {
        use crate::scheduler::LeaseError;
        let status = match &e {
            FarmError::NoJob(_) | FarmError::NoImage(_) => StatusCode::NOT_FOUND,
            FarmError::Lease(LeaseError::NotActive(_)) => StatusCode::CONFLICT,
            FarmError::Lease(LeaseError::JobOver(_)) => StatusCode::GONE,
            FarmError::BadResult(_) => StatusCode::BAD_REQUEST,
            FarmError::Store(_) => {
                tracing::error!("storage error: {e}");
                return ApiError::new(
                    StatusCode::INTERNAL_SERVER_ERROR,
                    "internal storage error (see the coordinator's log)",
                );
            }
        };
        ApiError::new(status, e.to_string())
    }
}

type ApiResult<T> = Result<T, ApiError>;

/// Bodies of JSON endpoints are small; 64 KiB is plenty.
const JSON_LIMIT: usize = 64 * 1024;

/// The router.
pub fn router(state: Arc<AppState>) -> Router {
    let upload = DefaultBodyLimit::max(state.max_upload);
    Router::new()
        .route("/healthz", get(|| async { Json(json!({ "status": "ok" })) }))
        .route("/api/jobs", post(submit).layer(upload).get(list))
        .route("/api/jobs/{id}", get(status).delete(cancel))
        .route("/api/jobs/{id}/{file}", get(image))
        .route("/api/bundles/{hash}", get(bundle))
        .route("/api/lease", post(lease).layer(DefaultBodyLimit::max(JSON_LIMIT)))
        .route("/api/leases/{id}/heartbeat", post(heartbeat))
        .route("/api/leases/{id}/result", put(result).layer(upload))
        .route(
            "/api/leases/{id}/release",
            post(release).layer(DefaultBodyLimit::max(JSON_LIMIT)),
        )
        .fallback(|| async { ApiError::new(StatusCode::NOT_FOUND, "no such endpoint (see docs/api.md)") })
        .layer(DefaultBodyLimit::max(JSON_LIMIT))
        .layer(middleware::from_fn_with_state(state.clone(), auth))
        .with_state(state)
}

/// With a token configured, every request must carry `Authorization: Bearer TOKEN`.
async fn auth(State(state): State<Arc<AppState>>, headers: HeaderMap, req: Request, next: Next) -> Response {
    if let Some(token) = &state.token {
        let given = headers
            .get(header::AUTHORIZATION)
            .and_then(|v| v.to_str().ok())
            .and_then(|v| v.strip_prefix("Bearer "))
            .unwrap_or("");
        // Compare digests, so the time taken says nothing about how much of the token matched.
        if Sha256::digest(given.as_bytes()) != Sha256::digest(token.as_bytes()) {
            return ApiError::new(StatusCode::UNAUTHORIZED, "missing or wrong bearer token").into_response();
        }
    }
    next.run(req).await
}

fn parse_id(s: &str) -> ApiResult<u64> {
    s.parse()
        .map_err(|_| ApiError::new(StatusCode::NOT_FOUND, format!("\"{s}\" is not an id")))
}

fn json_body<T: serde::de::DeserializeOwned>(bytes: &[u8]) -> ApiResult<T> {
    serde_json::from_slice(bytes)
        .map_err(|e| ApiError::new(StatusCode::BAD_REQUEST, format!("malformed JSON: {e}")))
}

/// The body, or the limit's or the connection's error as a JSON error.
async fn body_bytes(req: Request, state: &Arc<AppState>) -> ApiResult<Bytes> {
    Bytes::from_request(req, state)
        .await
        .map_err(|e| ApiError::new(e.status(), e.body_text()))
}

fn with_farm<T>(state: &AppState, f: impl FnOnce(&mut Farm) -> Result<T, FarmError>) -> ApiResult<T> {
    let mut farm = state.farm.lock().unwrap_or_else(|p| p.into_inner());
    f(&mut farm).map_err(ApiError::from)
}

async fn blocking<T: Send + 'static>(f: impl FnOnce() -> ApiResult<T> + Send + 'static) -> ApiResult<T> {
    tokio::task::spawn_blocking(f)
        .await
        .map_err(|e| ApiError::new(StatusCode::INTERNAL_SERVER_ERROR, format!("task failed: {e}")))?
}

/// `POST /api/jobs`: multipart with `bundle` (tar), optional `scene` (its path in the bundle)
/// and optional `settings` (JSON).
async fn submit(State(state): State<Arc<AppState>>, req: Request) -> ApiResult<Response> {
    let mut multipart = Multipart::from_request(req, &state)
        .await
        .map_err(|e| ApiError::new(e.status(), e.body_text()))?;
    let (mut bundle, mut scene, mut settings) = (None, None, JobSettings::default());
    while let Some(field) = multipart
        .next_field()
        .await
        .map_err(|e| ApiError::new(e.status(), e.body_text()))?
    {
        let name = field.name().unwrap_or_default().to_string();
        let data = field
            .bytes()
            .await
            .map_err(|e| ApiError::new(e.status(), e.body_text()))?;
        match name.as_str() {
            "bundle" => bundle = Some(data),
            "scene" => scene = Some(String::from_utf8_lossy(&data).into_owned()),
            "settings" => settings = json_body(&data)?,
            other => {
                return Err(ApiError::new(
                    StatusCode::BAD_REQUEST,
                    format!("unknown form field \"{other}\""),
                ));
            }
        }
    }
    let bundle =
        bundle.ok_or_else(|| ApiError::new(StatusCode::BAD_REQUEST, "the form has no \"bundle\" field"))?;
    let n = state.uploads.fetch_add(1, Ordering::Relaxed);
    let scratch = state
        .farm
        .lock()
        .unwrap_or_else(|p| p.into_inner())
        .store()
        .scratch_dir(&format!("{}-{n}", std::process::id()));
    let st = state.clone();
    blocking(move || {
        let out = accept_bundle(&st, &bundle, scene, settings, &scratch);
        let _ = std::fs::remove_dir_all(&scratch);
        out
    })
    .await
}

/// Unpacks, loads and checks a submitted bundle, then creates the job.
fn accept_bundle(
    state: &AppState,
    bundle: &[u8],
    scene: Option<String>,
    settings: JobSettings,
    scratch: &std::path::Path,
) -> ApiResult<Response> {
    let bad = |m: String| ApiError::new(StatusCode::UNPROCESSABLE_ENTITY, m);
    let files = photonfarm::bundle::unpack(bundle, scratch)
        .map_err(|e| ApiError::new(StatusCode::BAD_REQUEST, e.to_string()))?;
    let scene_rel =
        match scene {
            Some(s) => PathBuf::from(s),
            None => {
                let top: Vec<&PathBuf> = files
                    .iter()
                    .filter(|f| f.components().count() == 1 && f.extension().is_some_and(|e| e == "xml"))
                    .collect();
                match top.as_slice() {
                    [one] => (*one).clone(),
                    _ => return Err(bad(
                        "the bundle must hold one top-level .xml scene, or name it in the \"scene\" field"
                            .into(),
                    )),
                }
            }
        };
    if !files.contains(&scene_rel) {
        return Err(bad(format!("the bundle has no file \"{}\"", scene_rel.display())));
    }
    let loaded =
        Scene::load_inside(&scratch.join(&scene_rel), &settings.defines, scratch).map_err(|mut e| {
            // Name files as the user knows them: relative to the bundle.
            e.file = e.file.strip_prefix(scratch).map(PathBuf::from).unwrap_or(e.file);
            bad(e.to_string())
        })?;
    let resolved = settings.resolve(&loaded, false).map_err(|e| bad(e.to_string()))?;
    let total = resolved.passes.expect("closed-ended resolution has a count");
    let hash = photonfarm::bundle::content_hash(bundle);
    let mut farm = state.farm.lock().unwrap_or_else(|p| p.into_inner());
    let (dir, archive) = (farm.store().bundle_dir(&hash), farm.store().bundle_archive(&hash));
    if !archive.exists() {
        crate::store::write_durably(&archive, bundle).map_err(FarmError::from)?;
    }
    if !dir.exists() {
        let _ = std::fs::rename(scratch, &dir);
    }
    let id = farm.create_job(
        &settings,
        resolved.render,
        total,
        &scene_rel.to_string_lossy(),
        &hash,
        loaded.width(),
        loaded.height(),
    )?;
    let status = farm.status(id).ok_or(FarmError::NoJob(id))?;
    tracing::info!(job = id, total, "job accepted");
    let mut body = serde_json::to_value(status).expect("status serialises");
    body["warnings"] = json!(
        loaded
            .warnings
            .iter()
            .chain(&resolved.warnings)
            .collect::<Vec<_>>()
    );
    Ok((StatusCode::CREATED, Json(body)).into_response())
}

async fn list(State(state): State<Arc<AppState>>) -> ApiResult<Response> {
    let jobs = with_farm(&state, |f| Ok(f.list()))?;
    Ok(Json(json!({ "jobs": jobs })).into_response())
}

async fn status(State(state): State<Arc<AppState>>, Path(id): Path<String>) -> ApiResult<Response> {
    let id = parse_id(&id)?;
    let s = with_farm(&state, |f| f.status(id).ok_or(FarmError::NoJob(id)))?;
    Ok(Json(s).into_response())
}

async fn cancel(State(state): State<Arc<AppState>>, Path(id): Path<String>) -> ApiResult<Response> {
    let id = parse_id(&id)?;
    let s = with_farm(&state, |f| f.cancel(id))?;
    Ok(Json(s).into_response())
}

async fn image(
    State(state): State<Arc<AppState>>,
    Path((id, file)): Path<(String, String)>,
) -> ApiResult<Response> {
    let id = parse_id(&id)?;
    let (ext, mime) = match file.as_str() {
        "image.exr" => ("exr", "image/x-exr"),
        "image.png" => ("png", "image/png"),
        _ => {
            return Err(ApiError::new(
                StatusCode::NOT_FOUND,
                "images are image.exr and image.png",
            ));
        }
    };
    let path = with_farm(&state, |f| f.image(id, ext))?;
    let bytes = tokio::fs::read(&path).await.map_err(|e| {
        ApiError::new(
            StatusCode::INTERNAL_SERVER_ERROR,
            format!("cannot read the image: {e}"),
        )
    })?;
    Ok(([(header::CONTENT_TYPE, mime)], bytes).into_response())
}

async fn bundle(State(state): State<Arc<AppState>>, Path(hash): Path<String>) -> ApiResult<Response> {
    let path = with_farm(&state, |f| {
        if f.knows_bundle(&hash) {
            Ok(Some(f.store().bundle_archive(&hash)))
        } else {
            Ok(None)
        }
    })?
    .ok_or_else(|| ApiError::new(StatusCode::NOT_FOUND, "no such bundle"))?;
    let bytes = tokio::fs::read(&path).await.map_err(|e| {
        ApiError::new(
            StatusCode::INTERNAL_SERVER_ERROR,
            format!("cannot read the bundle: {e}"),
        )
    })?;
    Ok(([(header::CONTENT_TYPE, "application/x-tar")], bytes).into_response())
}

async fn lease(State(state): State<Arc<AppState>>, req: Request) -> ApiResult<Response> {
    let body = body_bytes(req, &state).await?;
    let req: LeaseRequest = json_body(&body)?;
    if req.worker.is_empty() || req.worker.len() > 200 {
        return Err(ApiError::new(
            StatusCode::BAD_REQUEST,
            "worker names are 1 to 200 bytes",
        ));
    }
    match with_farm(&state, |f| f.lease(&req))? {
        Some(l) => Ok(Json(l).into_response()),
        None => Ok(StatusCode::NO_CONTENT.into_response()),
    }
}

async fn heartbeat(State(state): State<Arc<AppState>>, Path(id): Path<String>) -> ApiResult<Response> {
    let id = parse_id(&id)?;
    Ok(Json(with_farm(&state, |f| f.heartbeat(id))?).into_response())
}

async fn result(
    State(state): State<Arc<AppState>>,
    Path(id): Path<String>,
    req: Request,
) -> ApiResult<Response> {
    let id = parse_id(&id)?;
    // Refuse a dead lease before reading a large body.
    with_farm(&state, |f| f.expected_result(id))?;
    let body = body_bytes(req, &state).await?;
    let len = body.len() as u64;
    let sum = blocking(move || {
        decode_batch(&body).map_err(|e| ApiError::new(StatusCode::BAD_REQUEST, e.to_string()))
    })
    .await?;
    let st = state.clone();
    blocking(move || with_farm(&st, |f| f.complete(id, sum, len))).await?;
    Ok(Json(json!({ "accepted": true })).into_response())
}

async fn release(
    State(state): State<Arc<AppState>>,
    Path(id): Path<String>,
    req: Request,
) -> ApiResult<Response> {
    let id = parse_id(&id)?;
    let body = body_bytes(req, &state).await?;
    let r: Release = json_body(&body)?;
    with_farm(&state, |f| f.release(id, r.error.as_deref()))?;
    Ok(Json(json!({ "released": true })).into_response())
}
