//! The HTTP API (documented in docs/api.md): routes, authentication, limits and errors.
//!
//! Every failure is a JSON `{"error": "..."}` with a 4xx or 5xx status, never a panic;
//! internal details of 5xx errors are logged, not sent. Handlers lock the farm only for
//! bookkeeping: uploads are read, decoded and written to disk, scenes loaded, sums added and
//! images encoded outside that lock, on blocking threads.

use std::path::{Path as FsPath, PathBuf};
use std::sync::atomic::{AtomicU64, Ordering};
use std::sync::{Arc, Mutex};

use axum::body::{Body, Bytes};
use axum::extract::{DefaultBodyLimit, FromRequest, Multipart, Path, Request, State};
use axum::http::{HeaderMap, StatusCode, header};
use axum::middleware::{self, Next};
use axum::response::{IntoResponse, Response};
use axum::routing::{get, post, put};
use axum::{Json, Router};
use photonfarm::bundle::BundleError;
use photonfarm::compression::{self, CompressionError, Encoding};
use photonfarm::frames::parse_frames;
use photonfarm::job::JobSettings;
use photonfarm::protocol::{
    JobList, LeaseRequest, Release, Submitted, decode_result, max_encoded_batch, routes,
};
use photonfarm::render::Method;
use serde_json::json;
use sha2::{Digest, Sha256};
use tokio::io::AsyncWriteExt;
use tokio::sync::Semaphore;

use crate::service::accumulator::Accumulator;
use crate::service::admission::Admission;
use crate::service::farm::{Committed, Farm, FarmError, FrameJob, SharedFarm};
use crate::service::scene_check::{CheckError, check_in_child};
use crate::service::store::{Layout, StoredBatch};
use crate::serving::JSON_LIMIT;
use crate::serving::result_body::{BodyError, lease_key, receive_result_to, result_encoding};

/// Who may call what: users submit and read jobs, workers lease and render. Separate tokens
/// keep a worker's credentials (often spread over many machines) from cancelling or reading
/// users' jobs, and a user's from completing leases.
#[derive(Clone, Debug, Default)]
pub struct Tokens {
    /// Required of `/api/jobs*` requests, if set.
    pub client: Option<String>,
    /// Required of `/api/lease`, `/api/leases/*` and `/api/bundles/*` requests, if set.
    pub worker: Option<String>,
}

/// Shared by every handler.
pub struct AppState {
    /// The farm and its store, each behind a std mutex: critical sections are short and never
    /// await.
    pub farm: SharedFarm,
    /// The data folder's paths, for file work outside the farm's lock.
    pub layout: Layout,
    /// Bearer tokens.
    pub tokens: Tokens,
    /// The limits every request is held to.
    pub admission: Admission,
    /// Checks submitted scenes in a child process, if set (see [`crate::service::scene_check`]).
    pub checker: Option<PathBuf>,
    /// Names scratch folders for incoming bundles.
    pub uploads: AtomicU64,
    /// Bundles read at once (each is streamed to disk: bounds the space they take together).
    pub bundle_slots: Semaphore,
    /// Results decoded at once, once received (bounds the memory they take together).
    pub result_slots: Semaphore,
    /// Leases whose result is being received.
    pub receiving: Mutex<std::collections::HashSet<u64>>,
    /// Scene checks at once (loading a scene can take many times its files' size).
    pub scene_checks: Semaphore,
    /// What `/metrics` reports beyond the farm's state.
    pub metrics: crate::service::metrics::Metrics,
    /// Set when the service starts to stop.
    pub stopping: tokio::sync::watch::Sender<bool>,
}

/// The longest a lease request waits for work (`POST /api/lease?wait_ms=N`): well under the
/// idle and lease timeouts, and short enough that a worker notices a lost coordinator soon.
pub const MAX_LEASE_WAIT_MS: u64 = 5_000;

/// `POST /api/lease`'s query.
#[derive(serde::Deserialize)]
struct LeaseQuery {
    /// Wait up to this long for work instead of answering 204 at once (capped at
    /// [`MAX_LEASE_WAIT_MS`]).
    wait_ms: Option<u64>,
}

/// An error response.
#[derive(Debug)]
pub struct ApiError(StatusCode, String);

impl ApiError {
    fn new(status: StatusCode, msg: impl Into<String>) -> ApiError {
        ApiError(status, msg.into())
    }

    /// A failure of the coordinator: logged in full, reported without details.
    fn internal(what: impl std::fmt::Display) -> ApiError {
        tracing::error!("internal error: {what}");
        ApiError::new(
            StatusCode::INTERNAL_SERVER_ERROR,
            "internal error (see the coordinator's log)",
        )
    }
}

impl IntoResponse for ApiError {
    fn into_response(self) -> Response {
        (self.0, Json(json!({ "error": self.1 }))).into_response()
    }
}

impl From<FarmError> for ApiError {
    fn from(e: FarmError) -> ApiError {
        use crate::service::scheduler::LeaseError;
        let status = match &e {
            FarmError::NoJob(_) | FarmError::NoImage(_) => StatusCode::NOT_FOUND,
            FarmError::Lease(LeaseError::NotActive(_)) => StatusCode::CONFLICT,
            FarmError::Lease(LeaseError::JobOver(_)) => StatusCode::GONE,
            FarmError::NotYours(_) => StatusCode::FORBIDDEN,
            FarmError::BadResult(_) => StatusCode::BAD_REQUEST,
            FarmError::Store(_) => return ApiError::internal(format!("storage: {e}")),
        };
        ApiError::new(status, e.to_string())
    }
}

type ApiResult<T> = Result<T, ApiError>;

/// The router.
pub fn router(state: Arc<AppState>) -> Router {
    let upload = DefaultBodyLimit::max(state.admission.max_upload as usize);
    let routes = Router::new()
        .route(routes::HEALTH, get(|| async { Json(json!({ "status": "ok" })) }))
        .route(routes::METRICS, get(metrics))
        .route(routes::JOBS, post(submit).layer(upload).get(list))
        .route(routes::JOB, get(status).delete(cancel))
        .route(routes::JOB_NOISE, get(noise))
        .route(routes::JOB_FILE, get(image))
        .route(routes::WORKERS, get(workers))
        .merge(crate::service::web::routes())
        .route(routes::BUNDLE, get(bundle))
        .route(
            routes::LEASE,
            post(lease).layer(DefaultBodyLimit::max(JSON_LIMIT)),
        )
        .route(routes::HEARTBEAT, post(heartbeat))
        // The lease's expected size is the real limit of a result (checked in the handler).
        .route(routes::RESULT, put(result).layer(DefaultBodyLimit::disable()))
        .route(
            routes::RELEASE,
            post(release).layer(DefaultBodyLimit::max(JSON_LIMIT)),
        )
        .fallback(|| async { ApiError::new(StatusCode::NOT_FOUND, "no such endpoint (see docs/api.md)") });
    crate::serving::guarded(routes, &state.admission.serving)
        .layer(middleware::from_fn_with_state(state.clone(), auth))
        .with_state(state)
}

/// The token a request's path needs: workers' routes need the worker token, the rest the
/// client token; `/healthz` takes either; the web page's files need none (they hold no data:
/// the page asks the API for everything, with the token its user types in).
async fn auth(State(state): State<Arc<AppState>>, headers: HeaderMap, req: Request, next: Next) -> Response {
    let path = req.uri().path();
    if crate::service::web::is_asset(path) {
        return next.run(req).await;
    }
    let wanted: Vec<&String> = if path == routes::HEALTH {
        [&state.tokens.client, &state.tokens.worker]
            .into_iter()
            .flatten()
            .collect()
    } else if routes::is_workers(path) {
        state.tokens.worker.iter().collect()
    } else {
        state.tokens.client.iter().collect()
    };
    if !wanted.is_empty() {
        let given = headers
            .get(header::AUTHORIZATION)
            .and_then(|v| v.to_str().ok())
            .and_then(|v| v.split_once(' '))
            // The scheme is case-insensitive (RFC 9110).
            .filter(|(scheme, _)| scheme.eq_ignore_ascii_case("bearer"))
            .map_or("", |(_, t)| t.trim());
        // Compare digests, so the time taken says nothing about how much of a token matched.
        let given = Sha256::digest(given.as_bytes());
        if !wanted.iter().any(|t| Sha256::digest(t.as_bytes()) == given) {
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

/// Applies one farm event and commits its writes (see [`SharedFarm::run`]).
fn with_farm<T>(state: &AppState, f: impl FnOnce(&mut Farm) -> Result<T, FarmError>) -> ApiResult<T> {
    state.farm.run(f).map_err(ApiError::from)
}

async fn blocking<T: Send + 'static>(f: impl FnOnce() -> ApiResult<T> + Send + 'static) -> ApiResult<T> {
    tokio::task::spawn_blocking(f)
        .await
        .map_err(|e| ApiError::internal(format!("task failed: {e}")))?
}

fn too_large(msg: String) -> ApiError {
    ApiError::new(StatusCode::PAYLOAD_TOO_LARGE, msg)
}

/// Reads one multipart field, at most `limit` bytes.
async fn small_field(
    field: &mut axum::extract::multipart::Field<'_>,
    limit: usize,
    name: &str,
) -> ApiResult<Vec<u8>> {
    let mut out = Vec::new();
    while let Some(chunk) = field
        .chunk()
        .await
        .map_err(|e| ApiError::new(e.status(), e.body_text()))?
    {
        if out.len() + chunk.len() > limit {
            return Err(too_large(format!(
                "the \"{name}\" field is larger than {limit} bytes"
            )));
        }
        out.extend_from_slice(&chunk);
    }
    Ok(out)
}

/// Streams the bundle field to `path`; returns its SHA-256.
async fn bundle_to_disk(field: &mut axum::extract::multipart::Field<'_>, path: &FsPath) -> ApiResult<String> {
    if let Some(dir) = path.parent() {
        tokio::fs::create_dir_all(dir).await.map_err(storage_error)?;
    }
    let mut file = tokio::fs::File::create(path).await.map_err(storage_error)?;
    let mut hash = Sha256::new();
    while let Some(chunk) = field
        .chunk()
        .await
        .map_err(|e| ApiError::new(e.status(), e.body_text()))?
    {
        hash.update(&chunk);
        file.write_all(&chunk).await.map_err(storage_error)?;
    }
    // Flushed first: tokio's File reports a failed background write (ENOSPC on a full disk)
    // only to the next write or flush, and sync_all alone drops it, which stored a truncated
    // archive (then refused as a bad bundle).
    file.flush().await.map_err(storage_error)?;
    file.sync_all().await.map_err(storage_error)?;
    Ok(hex::encode(hash.finalize()))
}

/// `POST /api/jobs`: multipart with `bundle` (tar), optional `scene` (its path in the bundle)
/// and optional `settings` (JSON).
async fn submit(State(state): State<Arc<AppState>>, req: Request) -> ApiResult<Response> {
    let n = state.uploads.fetch_add(1, Ordering::Relaxed);
    let scratch = state.layout.scratch_dir(&format!("{}-{n}", std::process::id()));
    let out = receive_and_accept(&state, req, &scratch).await;
    let _ = tokio::fs::remove_dir_all(&scratch).await;
    out
}

async fn receive_and_accept(state: &Arc<AppState>, req: Request, scratch: &FsPath) -> ApiResult<Response> {
    // An upload slot while the body is read; the scene check that follows waits for its own
    // turn without holding one, so slow checks never hold up workers' results.
    let slot = state.bundle_slots.acquire().await.map_err(ApiError::internal)?;
    let mut multipart = Multipart::from_request(req, state)
        .await
        .map_err(|e| ApiError::new(e.status(), e.body_text()))?;
    let (mut hash, mut scene, mut settings) = (None, None, JobSettings::default());
    let archive = scratch.join("bundle.tar");
    while let Some(mut field) = multipart
        .next_field()
        .await
        .map_err(|e| ApiError::new(e.status(), e.body_text()))?
    {
        let name = field.name().unwrap_or_default().to_string();
        match name.as_str() {
            "bundle" => hash = Some(bundle_to_disk(&mut field, &archive).await?),
            "scene" => {
                let data = small_field(&mut field, 4096, "scene").await?;
                scene = Some(String::from_utf8_lossy(&data).into_owned());
            }
            "settings" => settings = json_body(&small_field(&mut field, JSON_LIMIT, "settings").await?)?,
            other => {
                return Err(ApiError::new(
                    StatusCode::BAD_REQUEST,
                    format!("unknown form field \"{other}\""),
                ));
            }
        }
    }
    let hash =
        hash.ok_or_else(|| ApiError::new(StatusCode::BAD_REQUEST, "the form has no \"bundle\" field"))?;
    drop(slot);
    let _check = state.scene_checks.acquire().await.map_err(ApiError::internal)?;
    let st = state.clone();
    let scratch = scratch.to_path_buf();
    blocking(move || accept_bundle(&st, &archive, &hash, scene, settings, &scratch)).await
}

/// Unpacks, loads and checks a submitted bundle against the limits, then creates the job.
fn accept_bundle(
    state: &AppState,
    archive: &FsPath,
    hash: &str,
    scene: Option<String>,
    settings: JobSettings,
    scratch: &FsPath,
) -> ApiResult<Response> {
    let bad = |m: String| ApiError::new(StatusCode::UNPROCESSABLE_ENTITY, m);
    let limits = &state.admission;
    let files_dir = scratch.join("files");
    let reader = std::fs::File::open(archive).map_err(ApiError::internal)?;
    let files = photonfarm::bundle::unpack_from(std::io::BufReader::new(reader), &files_dir, &limits.bundle)
        .map_err(|e| match e {
            BundleError::Io(what, io) => {
                storage_error(StorageFailure(Some(io.kind()), format!("{what}: {io}")))
            }
            BundleError::TooLarge(_) => too_large(e.to_string()),
            _ => ApiError::new(StatusCode::BAD_REQUEST, e.to_string()),
        })?;
    settings.check_defines().map_err(|e| bad(e.to_string()))?;
    if settings.denoise && !crate::denoise::AVAILABLE {
        return Err(bad(format!("denoise: {}", crate::denoise::UNAVAILABLE)));
    }
    // A job with features holds five sums of its film (the image and four features).
    let sums_per_pixel: u64 = if settings.features() {
        1 + photonfarm::features::Features::NAMES.len() as u64
    } else {
        1
    };
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
    // What loading reads is bounded before the scene is loaded: parsing the XML or a mesh
    // takes many times the file's size.
    let geometry: u64 = files
        .iter()
        .filter_map(|f| std::fs::metadata(files_dir.join(f)).ok())
        .map(|m| m.len())
        .sum();
    if geometry > limits.max_geometry {
        return Err(too_large(format!(
            "the bundle's files (the scene and its meshes) take {geometry} bytes, above the limit of {} (--max-geometry-mb)",
            limits.max_geometry
        )));
    }
    let check = |scene_rel: &FsPath, settings: &JobSettings| {
        let scene_path = files_dir.join(scene_rel);
        match &state.checker {
            Some(program) => check_in_child(
                program,
                &scene_path,
                &files_dir,
                settings,
                scratch,
                std::time::Duration::from_secs(limits.scene_check_timeout_s),
            ),
            None => crate::service::scene_check::check(&scene_path, &files_dir, settings)
                .map_err(CheckError::Refused),
        }
        .map_err(|e| match e {
            CheckError::Internal(m) => ApiError::internal(m),
            // Name files as the user knows them: relative to the bundle, never by the
            // coordinator's own paths.
            other => {
                let ours = files_dir.display().to_string();
                let real = files_dir
                    .canonicalize()
                    .map_or_else(|_| ours.clone(), |p| p.display().to_string());
                bad(other
                    .to_string()
                    .replace(&format!("{real}/"), "")
                    .replace(&format!("{ours}/"), ""))
            }
        })
        .and_then(|checked| {
            limits
                .job
                .check_job(
                    checked.width,
                    checked.height,
                    Some(checked.total),
                    &checked.render,
                )
                .map_err(|e| bad(e.to_string()))?;
            let px = checked.width as u64 * checked.height as u64;
            if px * sums_per_pixel > limits.job.max_pixels {
                return Err(too_large(format!(
                    "with the denoiser's features a job holds {sums_per_pixel} sums of its {px}-pixel film, above the \
                     limit of {} pixels (--max-pixels)",
                    limits.job.max_pixels
                )));
            }
            Ok(checked)
        })
    };
    // A sequence: each frame checked with its own settings (its parameters may change the
    // film or the SPPM radius), before anything is allocated; their sums together are held
    // to one job's film limit, as they are all allocated now.
    let frames = match &settings.frames {
        None => None,
        Some(spec) => {
            let frames = parse_frames(spec).map_err(|e| bad(e.to_string()))?;
            // A sequence given as files: frame i is the i-th, each in the bundle.
            if !settings.scenes.is_empty() && settings.scenes.len() != frames.len() {
                return Err(bad(format!(
                    "{} scene files for {} frames: a sequence of files has one frame per file",
                    settings.scenes.len(),
                    frames.len()
                )));
            }
            let mut checked = Vec::with_capacity(frames.len());
            let mut pixels = 0u64;
            for (i, &frame) in frames.iter().enumerate() {
                let scene = match settings.scenes.get(i) {
                    Some(s) => PathBuf::from(s),
                    None => scene_rel.clone(),
                };
                if !files.contains(&scene) {
                    return Err(bad(format!("the bundle has no file \"{}\"", scene.display())));
                }
                let frame_settings = settings
                    .for_frame(&frames, frame)
                    .map_err(|e| bad(e.to_string()))?;
                let c = check(&scene, &frame_settings)?;
                let px = c.width as u64 * c.height as u64 * sums_per_pixel;
                pixels += px;
                // Judged from the first frame before checking the others: each check loads
                // the scene.
                if pixels > limits.job.max_pixels
                    || px.saturating_mul(frames.len() as u64) > limits.job.max_pixels
                {
                    return Err(too_large(format!(
                        "the sequence's frames take more than {} pixels together, the limit of one job's \
                         film (--max-pixels): submit fewer frames at a time",
                        limits.job.max_pixels
                    )));
                }
                checked.push((frame, scene, frame_settings, c));
            }
            Some(checked)
        }
    };
    let checked = match &frames {
        Some(f) => f[0].3.clone(),
        None => check(&scene_rel, &settings)?,
    };
    let total = checked.total;
    // Everything that takes time or memory, before the lock: the empty sums, the archive and
    // its unpacked files in their content-addressed places.
    let window = settings.checkpoint_every.unwrap_or(0);
    let empty = |w, h| {
        let sum = Accumulator::empty(w, h, window);
        if settings.features() {
            sum.with_features()
        } else {
            sum
        }
    };
    let single = frames.is_none().then(|| empty(checked.width, checked.height));
    let frames: Option<Vec<FrameJob>> = frames.map(|f| {
        f.into_iter()
            .map(|(frame, scene, settings, c)| FrameJob {
                frame,
                scene: scene.to_string_lossy().into_owned(),
                settings,
                render: c.render,
                total: c.total,
                sum: empty(c.width, c.height),
            })
            .collect()
    });
    let (dir, stored) = (state.layout.bundle_dir(hash), state.layout.bundle_archive(hash));
    if !stored.exists() {
        crate::service::store::rename_durably(archive, &stored).map_err(storage_error)?;
    }
    if !dir.exists() {
        let _ = std::fs::rename(&files_dir, &dir);
    }
    let (id, status) = with_farm(state, |farm| {
        let windowed = |sum: Accumulator, settings: &JobSettings| {
            if window == 0 {
                sum.with_window(farm.window_of(settings))
            } else {
                sum
            }
        };
        let scene = scene_rel.to_string_lossy();
        let id = match frames {
            Some(frames) => {
                let frames = frames
                    .into_iter()
                    .map(|f| FrameJob {
                        sum: windowed(f.sum, &f.settings),
                        ..f
                    })
                    .collect();
                farm.create_sequence(&settings, frames, &scene, hash)?
            }
            None => {
                let sum = windowed(single.expect("made for a single image"), &settings);
                farm.create_job(&settings, checked.render, total, &scene, hash, sum)?
            }
        };
        Ok((id, farm.status(id).ok_or(FarmError::NoJob(id))?))
    })?;
    tracing::info!(job = id, total, "job accepted");
    let body = Submitted {
        status,
        warnings: checked.warnings,
    };
    Ok((StatusCode::CREATED, Json(body)).into_response())
}

/// The farm in Prometheus' text format (see [`crate::service::metrics`]); the users' token, as for jobs.
async fn metrics(State(state): State<Arc<AppState>>) -> ApiResult<Response> {
    let snapshot = with_farm(&state, |f| {
        Ok(crate::service::metrics::Snapshot {
            jobs: f.list(),
            workers: f.workers_present(),
            leases: f.live_leases(),
        })
    })?;
    let text = state.metrics.encode(&snapshot);
    Ok((
        [(
            header::CONTENT_TYPE,
            "application/openmetrics-text; version=1.0.0; charset=utf-8",
        )],
        text,
    )
        .into_response())
}

/// `GET /api/jobs/{id}/noise`: the job's noise estimates as its passes arrived.
async fn noise(State(state): State<Arc<AppState>>, Path(id): Path<String>) -> ApiResult<Response> {
    let id = parse_id(&id)?;
    let (points, sum) = with_farm(&state, |f| f.noise(id))?;
    // Read from the job's sum, under its own lock, never while holding the farm's.
    let tracking = sum.is_none_or(|s| s.lock().unwrap_or_else(|p| p.into_inner()).odd().is_some());
    Ok(Json(crate::service::farm::NoiseReport { id, tracking, points }).into_response())
}

/// `GET /api/workers`: the workers seen lately, for users (the users' token).
async fn workers(State(state): State<Arc<AppState>>) -> ApiResult<Response> {
    let workers = with_farm(&state, |f| Ok(f.workers()))?;
    Ok(Json(json!({ "workers": workers })).into_response())
}

async fn list(State(state): State<Arc<AppState>>) -> ApiResult<Response> {
    let jobs = with_farm(&state, |f| Ok(f.list()))?;
    Ok(Json(JobList { jobs }).into_response())
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

/// A file as a streamed response: never read whole into memory.
async fn stream_file(path: &FsPath, mime: &'static str) -> ApiResult<Response> {
    let file = tokio::fs::File::open(path).await.map_err(ApiError::internal)?;
    let len = file.metadata().await.map_err(ApiError::internal)?.len();
    let stream = futures_util::stream::unfold(file, |mut file| async move {
        use tokio::io::AsyncReadExt;
        let mut buf = vec![0u8; 64 * 1024];
        match file.read(&mut buf).await {
            Ok(0) => None,
            Ok(n) => {
                buf.truncate(n);
                Some((Ok::<_, std::io::Error>(Bytes::from(buf)), file))
            }
            Err(e) => Some((Err(e), file)),
        }
    });
    Ok((
        [
            (header::CONTENT_TYPE, mime.to_string()),
            (header::CONTENT_LENGTH, len.to_string()),
        ],
        Body::from_stream(stream),
    )
        .into_response())
}

async fn image(
    State(state): State<Arc<AppState>>,
    Path((id, file)): Path<(String, String)>,
) -> ApiResult<Response> {
    let id = parse_id(&id)?;
    let (name, ext) = match file.as_str() {
        "image.exr" => ("image", "exr"),
        "image.png" => ("image", "png"),
        "image.denoised.exr" => ("image.denoised", "exr"),
        "image.denoised.png" => ("image.denoised", "png"),
        _ => {
            return Err(ApiError::new(
                StatusCode::NOT_FOUND,
                "images are image.exr and image.png, and for a job with --denoise \
                 image.denoised.exr and image.denoised.png",
            ));
        }
    };
    let mime = if ext == "exr" { "image/x-exr" } else { "image/png" };
    let path = with_farm(&state, |f| f.image(id, name, ext))?;
    stream_file(&path, mime).await
}

async fn bundle(State(state): State<Arc<AppState>>, Path(hash): Path<String>) -> ApiResult<Response> {
    let known = with_farm(&state, |f| Ok(f.knows_bundle(&hash)))?;
    if !known {
        return Err(ApiError::new(StatusCode::NOT_FOUND, "no such bundle"));
    }
    stream_file(&state.layout.bundle_archive(&hash), "application/x-tar").await
}

/// Grants a batch, or 204 if there is none. With `wait_ms`, waits for work to appear (a
/// submission, a released or expired batch) before answering 204: idle workers start on a new
/// job at once instead of at their next poll, up to seconds apart, which cost short jobs a
/// quarter of their speed on two workers (docs/scaling.md).
async fn lease(
    State(state): State<Arc<AppState>>,
    axum::extract::Query(query): axum::extract::Query<LeaseQuery>,
    req: Request,
) -> ApiResult<Response> {
    let body = body_bytes(req, &state).await?;
    let req: LeaseRequest = json_body(&body)?;
    if req.worker.is_empty() || req.worker.len() > 200 {
        return Err(ApiError::new(
            StatusCode::BAD_REQUEST,
            "worker names are 1 to 200 bytes",
        ));
    }
    let wait = std::time::Duration::from_millis(query.wait_ms.unwrap_or(0).min(MAX_LEASE_WAIT_MS));
    let deadline = tokio::time::Instant::now() + wait;
    let mut stopping = state.stopping.subscribe();
    let mut lease = loop {
        // Armed before asking, so that work arriving in between wakes it.
        let new_work = state.farm.new_work();
        tokio::pin!(new_work);
        new_work.as_mut().enable();
        if let Some(lease) = with_farm(&state, |f| f.lease(&req))? {
            break lease;
        }
        if *stopping.borrow() || tokio::time::Instant::now() >= deadline {
            return Ok(StatusCode::NO_CONTENT.into_response());
        }
        tokio::select! {
            _ = new_work => {}
            _ = tokio::time::sleep_until(deadline) => {}
            _ = stopping.wait_for(|s| *s) => {}
        }
    };
    // The radii cost time in proportion to the pass index: computed outside the lock.
    if let Method::Sppm(s) = lease.settings.method {
        let range = lease.start..lease.end;
        lease.radii = blocking(move || Ok(s.radii(range))).await?;
    }
    Ok(Json(lease).into_response())
}

async fn heartbeat(
    State(state): State<Arc<AppState>>,
    Path(id): Path<String>,
    headers: HeaderMap,
) -> ApiResult<Response> {
    let id = parse_id(&id)?;
    let key = lease_key(&headers);
    Ok(Json(with_farm(&state, |f| f.heartbeat(id, &key))?).into_response())
}

/// `PUT /api/leases/{id}/result`: checked against the lease's expected size before it is
/// read, streamed to a file of the lease's own, decoded under a decoding slot outside the
/// lock, then counted, then merged into the job's sum under the job's own lock.
async fn result(
    State(state): State<Arc<AppState>>,
    Path(id): Path<String>,
    headers: HeaderMap,
    req: Request,
) -> ApiResult<Response> {
    let id = parse_id(&id)?;
    let key = lease_key(&headers);
    let encoding = result_encoding(&headers)
        .map_err(|e| ApiError::new(StatusCode::UNSUPPORTED_MEDIA_TYPE, e.to_string()))?;
    // Refuse a dead lease, or one of another worker, before reading a large body.
    let expected = with_farm(&state, |f| f.expected_result(id, &key))?;
    let _receiving = Receiving::claim(&state, id)?;
    let max = max_encoded_batch(expected.width, expected.height, expected.features);
    let batch = StoredBatch {
        start: expected.start,
        end: expected.end,
        lease: id,
    };
    let part = state.layout.received_path(expected.job, batch);
    tokio::fs::create_dir_all(state.layout.job_dir(expected.job))
        .await
        .map_err(storage_error)?;
    let outcome = match receive_result_to(&headers, req, encoding, max, &part).await {
        Ok(len) => {
            // A slot only now that the body is here: a stalled body never holds one.
            let slot = state.result_slots.acquire().await.map_err(ApiError::internal)?;
            let st = state.clone();
            let out = blocking(move || store_result(&st, id, &key, expected, batch, encoding, len)).await;
            drop(slot);
            out
        }
        Err(e) => Err(match e {
            BodyError::TooLarge(declared) => too_large(format!(
                "a result for lease {id} ({}x{}) is at most {max} bytes; this one is {}",
                expected.width,
                expected.height,
                declared.map_or("larger".to_string(), |n| n.to_string())
            )),
            BodyError::Stalled => ApiError::new(
                StatusCode::REQUEST_TIMEOUT,
                format!("the result for lease {id} stalled for longer than --body-timeout"),
            ),
            BodyError::Broken(m) => {
                ApiError::new(StatusCode::BAD_REQUEST, format!("reading the result: {m}"))
            }
            BodyError::Io(e) => storage_error(e),
            BodyError::Closed(e) => ApiError::internal(e),
        }),
    };
    // Kept under the batch's name if it counted; otherwise never anywhere.
    let _ = tokio::fs::remove_file(&part).await;
    outcome?;
    Ok(Json(json!({ "accepted": true })).into_response())
}

/// A lease's result being received: one at a time per lease, so that two uploads of one lease
/// never write one file.
struct Receiving<'a> {
    state: &'a AppState,
    lease: u64,
}

impl<'a> Receiving<'a> {
    fn claim(state: &'a AppState, lease: u64) -> ApiResult<Receiving<'a>> {
        let mut under_way = state.receiving.lock().unwrap_or_else(|p| p.into_inner());
        if !under_way.insert(lease) {
            return Err(ApiError::new(
                StatusCode::CONFLICT,
                format!("a result for lease {lease} is being received on another request"),
            ));
        }
        Ok(Receiving { state, lease })
    }
}

impl Drop for Receiving<'_> {
    fn drop(&mut self) {
        let mut under_way = self.state.receiving.lock().unwrap_or_else(|p| p.into_inner());
        under_way.remove(&self.lease);
    }
}

/// A storage failure: out of space is the operator's to fix and the client's to retry later
/// (507), anything else the coordinator's (500, details logged).
fn storage_error(e: impl Into<StorageFailure>) -> ApiError {
    let StorageFailure(kind, what) = e.into();
    if kind == Some(std::io::ErrorKind::StorageFull) || kind == Some(std::io::ErrorKind::QuotaExceeded) {
        tracing::error!("storage full: {what}");
        ApiError::new(
            StatusCode::INSUFFICIENT_STORAGE,
            "the coordinator's data disk is full; try again later",
        )
    } else {
        ApiError::internal(format!("storage: {what}"))
    }
}

/// What [`storage_error`] needs of an error: its I/O kind, if any, and its text.
struct StorageFailure(Option<std::io::ErrorKind>, String);

impl From<std::io::Error> for StorageFailure {
    fn from(e: std::io::Error) -> StorageFailure {
        StorageFailure(Some(e.kind()), e.to_string())
    }
}

impl From<crate::service::store::StoreError> for StorageFailure {
    fn from(e: crate::service::store::StoreError) -> StorageFailure {
        let kind = match &e {
            crate::service::store::StoreError::Io(_, io) => Some(io.kind()),
            _ => None,
        };
        StorageFailure(kind, e.to_string())
    }
}

/// Decodes, checks and keeps a received result (`batch`, of lease `id`), counts it, and merges
/// it (writing any checkpoint).
fn store_result(
    state: &AppState,
    id: u64,
    key: &str,
    expected: crate::service::farm::Expected,
    batch: StoredBatch,
    encoding: Encoding,
    len: u64,
) -> ApiResult<()> {
    let body = std::fs::read(state.layout.received_path(expected.job, batch)).map_err(storage_error)?;
    // Odd passes in [start, end): those the odd-pass sample, if sent, must hold.
    let odd_passes = expected.end / 2 - expected.start / 2;
    let max = max_encoded_batch(expected.width, expected.height, expected.features);
    let plain = match compression::decompress_bounded(encoding, &body, max) {
        Ok(p) => p,
        Err(e @ CompressionError::TooLarge(_)) => {
            return Err(too_large(format!("a result for lease {id}: {e}")));
        }
        Err(e) => {
            let msg = e.to_string();
            with_farm(state, |f| f.reject(id, &msg))?;
            return Err(ApiError::from(FarmError::BadResult(msg)));
        }
    };
    let decoded = decode_result(&plain, expected.width, expected.height);
    drop(plain);
    drop(body);
    let (sum, odd, features) = match decoded {
        Ok(r)
            if (r.sum.width, r.sum.height) == (expected.width, expected.height)
                && r.sum.passes == expected.end - expected.start
                && r.odd.as_ref().is_none_or(|o| o.passes == odd_passes)
                && r.features.is_some() == expected.features =>
        {
            (r.sum, r.odd, r.features)
        }
        other => {
            let msg = match other {
                Ok(r) if r.features.is_some() != expected.features => {
                    if expected.features {
                        "the job asks for the denoiser's features (--aovs, --denoise) and the result has none: \
                         is the worker older than the coordinator?"
                            .to_string()
                    } else {
                        "the result carries features its job did not ask for".to_string()
                    }
                }
                Ok(r)
                    if r.sum.passes == expected.end - expected.start
                        && (r.sum.width, r.sum.height) == (expected.width, expected.height) =>
                {
                    format!(
                        "expected {odd_passes} odd passes in the odd-pass sample, got {}",
                        r.odd.map_or(0, |o| o.passes)
                    )
                }
                Ok(photonfarm::protocol::BatchResult { sum, .. }) => format!(
                    "expected {}x{} and {} passes, got {}x{} and {}",
                    expected.width,
                    expected.height,
                    expected.end - expected.start,
                    sum.width,
                    sum.height,
                    sum.passes
                ),
                Err(e) => e.to_string(),
            };
            with_farm(state, |f| f.reject(id, &msg))?;
            return Err(ApiError::from(FarmError::BadResult(msg)));
        }
    };
    // The body is the batch's encoding: kept as received (compressed or not), under a name of
    // this lease's own; only the commit's row makes it count.
    state
        .layout
        .keep_received(expected.job, batch)
        .map_err(storage_error)?;
    // The committed lease's job is the expected one's (`expected.job`).
    let Committed {
        job: _,
        sum: job_sum,
        total,
    } = match with_farm(state, |f| f.commit(id, key, len)) {
        Ok(committed) => committed,
        Err(e) => {
            // Refused (the lease moved on while the body was read): unless a row names the
            // file (a retried upload of a result already counted), it never counted, and it
            // goes. No row can appear for it meanwhile: only this lease's commit writes one.
            if !state.farm.store().has_batch(expected.job, batch).unwrap_or(true) {
                let _ = std::fs::remove_file(state.layout.batch_path(expected.job, batch));
            }
            return Err(e);
        }
    };
    merge(state, &expected, &job_sum, total, sum, odd, features)
}

/// Adds a counted result to its job's sum under the job's lock; writes the prefix and the
/// images at a checkpoint or at the end; then tells the farm the noise estimates and the
/// checkpoint (the farm's lock is never taken under the job's).
fn merge(
    state: &AppState,
    expected: &crate::service::farm::Expected,
    job_sum: &crate::service::farm::JobSum,
    total: u64,
    sum: photonfarm::film::FilmSum,
    odd: Option<photonfarm::parity::OddSums>,
    features: Option<photonfarm::features::Features>,
) -> ApiResult<()> {
    let job = expected.job;
    let mut acc = job_sum.lock().unwrap_or_else(|p| p.into_inner());
    let merged = acc
        .add(expected.start, sum, odd, features)
        .map_err(|e| ApiError::internal(format!("job {job}: {e}")))?;
    let finished = acc.prefix_passes() >= total;
    let image = if finished {
        Some((acc.prefix(), acc.features()))
    } else {
        merged.checkpoints.last().map(|c| (&c.sum, c.features.as_ref()))
    };
    let mut preview = None;
    let written = match image {
        None => None,
        Some((image, features)) => {
            // The prefix file first: the checkpoint images must never be ahead of it.
            let storage = |e| ApiError::internal(format!("storage: {e}"));
            let started = std::time::Instant::now();
            state
                .layout
                .write_prefix(job, acc.prefix(), acc.odd(), acc.features())
                .map_err(storage)?;
            state.layout.write_images(job, image, features).map_err(storage)?;
            state.metrics.observe_checkpoint(started.elapsed());
            if expected.denoise {
                preview = features.map(|f| (image.clone(), f.clone()));
            }
            Some((acc.prefix_passes(), image.passes))
        }
    };
    drop(acc);
    // The denoised preview outside the job's lock (OIDN takes seconds on a large film); a
    // failure costs the preview, never the checkpoint.
    if let Some((image, features)) = preview
        && let Err(e) = state.layout.write_denoised(job, &image, &features)
    {
        tracing::warn!(job, "no denoised preview: {e}");
    }
    with_farm(state, |f| {
        f.record_noise(job, &merged.noise);
        match written {
            Some((prefix, image_passes)) => f.checkpointed(job, prefix, Some(image_passes)),
            None => Ok(()),
        }
    })
}

async fn release(
    State(state): State<Arc<AppState>>,
    Path(id): Path<String>,
    headers: HeaderMap,
    req: Request,
) -> ApiResult<Response> {
    let id = parse_id(&id)?;
    let key = lease_key(&headers);
    let body = body_bytes(req, &state).await?;
    let r: Release = json_body(&body)?;
    let error = r.error.map(|e| e.chars().take(2000).collect::<String>());
    with_farm(&state, |f| f.release(id, &key, error.as_deref()))?;
    Ok(Json(json!({ "released": true })).into_response())
}
