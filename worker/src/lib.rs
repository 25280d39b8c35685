//! The worker's pull loop: lease a batch, make sure its scene is loaded (bundles are fetched
//! once and cached, loaded scenes kept across batches), render it on a dedicated rayon pool
//! while heartbeating, upload the sum, repeat.
//!
//! On shutdown (SIGTERM, ctrl-c) the batch under way is finished and uploaded, then the worker
//! exits. A lost lease (expired, job cancelled) stops the batch at the next pass. A finished
//! batch is kept on disk until the coordinator has it (see [`outbox`]).
#![forbid(unsafe_code)]
#![warn(missing_docs)]

pub mod outbox;

use std::collections::HashMap;
use std::path::PathBuf;
use std::sync::Arc;
use std::sync::atomic::{AtomicBool, Ordering};
use std::time::Duration;

use anyhow::{Context, bail};
use photonfarm::bundle::UnpackLimits;
use photonfarm::compression::{self, Encoding};
use photonfarm::limits::Limits;
use photonfarm::protocol::{Endpoint, LEASE_KEY_HEADER, Lease, LeaseRequest, Release, encode_result, routes};
use photonfarm::render::Renderer;
use photonfarm::scene::Scene;
use tokio::sync::watch;

use crate::outbox::{Outbox, Parcel};

/// Worker settings.
#[derive(Clone, Debug)]
pub struct WorkerConfig {
    /// Coordinator URL.
    pub coordinator: String,
    /// Render threads.
    pub threads: usize,
    /// Bearer token.
    pub token: Option<String>,
    /// Name shown in job status.
    pub name: String,
    /// Bundle cache folder.
    pub cache: PathBuf,
    /// The largest batch this worker agrees to render (a batch beyond them is released as a
    /// failure, so a job too large for every worker fails instead of crashing them).
    pub limits: Limits,
}

/// Scenes loaded from bundles, by (bundle, scene path, defines).
type SceneCache = HashMap<(String, String, Vec<(String, String)>), Arc<Scene>>;

/// The coordinator (or relay) the worker serves.
type Client = Endpoint;

/// Runs until `shutdown` completes (then finishes the batch under way) or a fatal error.
pub async fn run(
    config: WorkerConfig,
    shutdown: impl std::future::Future<Output = ()> + Send + 'static,
) -> anyhow::Result<()> {
    let (stop_tx, mut stop_rx) = watch::channel(false);
    tokio::spawn(async move {
        shutdown.await;
        tracing::info!("shutting down after the batch under way");
        let _ = stop_tx.send(true);
    });
    std::fs::create_dir_all(&config.cache)
        .with_context(|| format!("cannot create {}", config.cache.display()))?;
    let pool = Arc::new(
        rayon::ThreadPoolBuilder::new()
            .num_threads(config.threads)
            .build()
            .context("cannot start the render threads")?,
    );
    let base = coordinator_url(&config.coordinator)?;
    let client = Arc::new(Endpoint::new(
        &base,
        config.token.clone(),
        reqwest::Client::builder()
            .timeout(Duration::from_secs(300))
            .build()?,
    ));
    let mut scenes = SceneCache::new();
    let mut backoff = Duration::from_millis(200);
    tracing::info!(name = %config.name, threads = config.threads, coordinator = %client.base(), "worker started");
    let mut trouble = Trouble::default();
    let outbox = Outbox::open(&config.cache)?;
    // Results an earlier run finished but could not deliver.
    for parcel in outbox.waiting() {
        tracing::info!(
            lease = parcel.lease_id,
            "delivering a batch kept from an earlier run"
        );
        let bytes = outbox.bytes(&parcel)?;
        deliver(&client, &outbox, &parcel, bytes, &mut trouble, &mut stop_rx).await?;
    }
    while !*stop_rx.borrow() {
        let asked = std::time::Instant::now();
        let answer = tokio::select! {
            answer = request_lease(&client, &config) => answer,
            // Stop at once, not at the end of a request waiting for work.
            _ = stop_rx.changed() => continue,
        };
        let lease = match answer {
            Ok(Some(lease)) => {
                trouble.cleared(client.base());
                backoff = Duration::from_millis(200);
                lease
            }
            Ok(None) if asked.elapsed() >= LEASE_WAIT / 2 => {
                // The coordinator waited for work and none came: ask again at once.
                trouble.cleared(client.base());
                backoff = Duration::from_millis(200);
                continue;
            }
            Ok(None) => {
                // An answer at once: a coordinator that does not wait for work. Poll.
                trouble.cleared(client.base());
                tokio::select! {
                    _ = tokio::time::sleep(backoff) => {}
                    _ = stop_rx.changed() => {}
                }
                backoff = (backoff * 2).min(Duration::from_secs(2));
                continue;
            }
            Err(e) => {
                // The coordinator is away (restarting, or a wrong address) or refuses us: say so
                // at once, then now and then; give up only on a token refused again and again.
                trouble.failed(client.base(), &e)?;
                tokio::select! {
                    _ = tokio::time::sleep(backoff) => {}
                    _ = stop_rx.changed() => {}
                }
                backoff = (backoff * 2).min(Duration::from_secs(2));
                continue;
            }
        };
        match work_on(&client, &config, &pool, &mut scenes, &outbox, lease.clone()).await {
            Ok(Some((parcel, bytes))) => {
                deliver(&client, &outbox, &parcel, bytes, &mut trouble, &mut stop_rx).await?;
            }
            Ok(None) => {}
            Err(e) => {
                tracing::error!(lease = lease.lease_id, "batch failed: {e:#}");
                let release = Release {
                    error: Some(format!("{e:#}")),
                };
                let _ = client
                    .request(reqwest::Method::POST, &routes::release(lease.lease_id))
                    .header(LEASE_KEY_HEADER, &lease.key)
                    .json(&release)
                    .send()
                    .await;
            }
        }
    }
    Ok(())
}

/// Why asking for work failed.
#[derive(Debug, thiserror::Error)]
enum RequestError {
    /// No answer: the coordinator is down, restarting or not at that address.
    #[error("cannot reach the coordinator: {0}")]
    Unreachable(String),
    /// The token was refused (401 or 403).
    #[error("the coordinator refused this worker's token ({0}): check --token / PHOTONFARM_TOKEN")]
    Refused(reqwest::StatusCode),
    /// Any other refusal.
    #[error("lease request refused: {0} {1}")]
    Other(reqwest::StatusCode, String),
}

/// The worker stopped because the coordinator refused its token: `worker` exits with
/// [`TokenRefused::EXIT_CODE`], so that a supervisor can tell it from a crash.
#[derive(Debug, thiserror::Error)]
#[error("{0}")]
pub struct TokenRefused(String);

impl TokenRefused {
    /// The process exit code for a refused token.
    pub const EXIT_CODE: u8 = 3;
}

/// A token refused this many times in a row ends the worker: it will not start working by
/// itself, and a worker that retries forever hides the mistake.
const MAX_REFUSALS: u32 = 5;
/// How often a failure that goes on is logged again.
const REPEAT_LOG: Duration = Duration::from_secs(30);

/// What the worker has told the operator about failing lease requests.
#[derive(Default)]
struct Trouble {
    refusals: u32,
    last_logged: Option<std::time::Instant>,
    failing_since: Option<std::time::Instant>,
}

impl Trouble {
    /// A failed request: logged at once, then every [`REPEAT_LOG`]; an error ends the worker.
    fn failed(&mut self, url: &str, e: &RequestError) -> anyhow::Result<()> {
        let now = std::time::Instant::now();
        self.failing_since.get_or_insert(now);
        self.refusals = if matches!(e, RequestError::Refused(_)) {
            self.refusals + 1
        } else {
            0
        };
        if self.refusals >= MAX_REFUSALS {
            return Err(TokenRefused(format!(
                "{e} ({MAX_REFUSALS} times in a row from {url}); stopping"
            ))
            .into());
        }
        if self.last_logged.is_none_or(|t| now - t >= REPEAT_LOG) {
            let since = now - *self.failing_since.get_or_insert(now);
            tracing::error!(coordinator = url, failing_for_s = since.as_secs(), "{e}");
            self.last_logged = Some(now);
        }
        Ok(())
    }

    /// A request that worked: says so if it had been failing.
    fn cleared(&mut self, url: &str) {
        if let Some(since) = self.failing_since.take() {
            tracing::info!(
                coordinator = url,
                "the coordinator answers again after {:.0} s",
                since.elapsed().as_secs_f64()
            );
        }
        *self = Trouble::default();
    }
}

/// The coordinator's base URL, checked before anything is sent: an address without `http://`
/// or `https://` would otherwise fail every request with an obscure message.
fn coordinator_url(given: &str) -> anyhow::Result<String> {
    let url = reqwest::Url::parse(given).with_context(|| {
        format!("--coordinator {given}: not a URL (expected e.g. http://render-host:8080)")
    })?;
    if !matches!(url.scheme(), "http" | "https") || url.host().is_none() {
        bail!(
            "--coordinator {given}: expected an http:// or https:// address with a host, e.g. http://render-host:8080"
        );
    }
    Ok(given.trim_end_matches('/').to_string())
}

/// How long a lease request asks the coordinator to wait for work before answering that there
/// is none: a new job starts on every idle worker at once, not at their next polls.
const LEASE_WAIT: Duration = Duration::from_secs(5);

async fn request_lease(client: &Client, config: &WorkerConfig) -> Result<Option<Lease>, RequestError> {
    let req = LeaseRequest {
        worker: config.name.clone(),
        threads: config.threads as u32,
        renderers: None,
    };
    let resp = client
        .request(
            reqwest::Method::POST,
            &routes::lease(LEASE_WAIT.as_millis() as u64),
        )
        .json(&req)
        .send()
        .await
        .map_err(|e| RequestError::Unreachable(error_chain(&e)))?;
    match resp.status() {
        reqwest::StatusCode::NO_CONTENT => Ok(None),
        s if s.is_success() => {
            Ok(Some(resp.json().await.map_err(|e| {
                RequestError::Other(s, format!("unreadable lease: {e}"))
            })?))
        }
        s @ (reqwest::StatusCode::UNAUTHORIZED | reqwest::StatusCode::FORBIDDEN) => {
            Err(RequestError::Refused(s))
        }
        s => Err(RequestError::Other(s, resp.text().await.unwrap_or_default())),
    }
}

/// An error and its causes on one line ("error sending request: connection refused").
fn error_chain(e: &dyn std::error::Error) -> String {
    let mut out = e.to_string();
    let mut cause = e.source();
    while let Some(c) = cause {
        out.push_str(": ");
        out.push_str(&c.to_string());
        cause = c.source();
    }
    out
}

/// Loads (or reuses) the lease's scene, renders the batch with heartbeats and keeps the result
/// in the outbox; returns it and its bytes (None if the lease was lost on the way).
async fn work_on(
    client: &Arc<Client>,
    config: &WorkerConfig,
    pool: &Arc<rayon::ThreadPool>,
    scenes: &mut SceneCache,
    outbox: &Outbox,
    lease: Lease,
) -> anyhow::Result<Option<(Parcel, Vec<u8>)>> {
    let scene = load_scene(client, config, scenes, &lease).await?;
    // Before any allocation for the batch: the film and the photon buffers.
    config
        .limits
        .check_job(scene.width(), scene.height(), None, &lease.settings)
        .context("this worker refuses the batch")?;
    if !lease.radii.is_empty() && lease.radii.len() as u64 != lease.end - lease.start {
        bail!(
            "the lease carries {} radii for {} passes",
            lease.radii.len(),
            lease.end - lease.start
        );
    }
    let lost = Arc::new(AtomicBool::new(false));
    let heartbeat = tokio::spawn(heartbeat_loop(
        client.clone(),
        lease.lease_id,
        lease.key.clone(),
        lease.heartbeat_ms,
        lost.clone(),
    ));
    let (pool, lost_r, lease_r) = (pool.clone(), lost.clone(), lease.clone());
    let sum = tokio::task::spawn_blocking(move || {
        pool.install(|| {
            // A lost lease stops the work before its next pass. The odd passes are also summed
            // on the sampled pixels, for the coordinator's noise estimate (photonfarm::parity).
            let radii = (!lease_r.radii.is_empty()).then_some(&lease_r.radii[..]);
            // The denoiser's features too, if the job asks for them (photonfarm::features).
            let mut renderer = Renderer::new(&scene, &lease_r.settings);
            if lease_r.features {
                renderer = renderer.with_features();
            }
            let batch = renderer.render(lease_r.start..lease_r.end, radii, &lost_r);
            (batch.sum.passes == lease_r.end - lease_r.start).then_some((
                batch.sum,
                batch.odd,
                batch.features,
            ))
        })
    })
    .await
    .context("the render thread failed")?;
    heartbeat.abort();
    let Some((sum, odd, features)) = sum else {
        tracing::warn!(
            lease = lease.lease_id,
            "lease lost (expired or job cancelled); batch dropped"
        );
        return Ok(None);
    };
    let parcel = Parcel {
        lease_id: lease.lease_id,
        key: lease.key.clone(),
        job_id: lease.job_id,
        start: lease.start,
        end: lease.end,
    };
    // Compressed when the coordinator says it takes zstd (older ones get the plain encoding);
    // the outbox keeps the bytes as they will be sent.
    let encoded = encode_result(&sum, &odd, features.as_ref());
    let bytes = if lease.accept_encoding.iter().any(|e| e == compression::ZSTD) {
        tokio::task::spawn_blocking(move || compression::compress(&encoded))
            .await
            .context("the compression thread failed")?
    } else {
        encoded
    };
    // A disk that cannot keep it (full, say) must not cost a finished batch, nor fail its job:
    // it is sent from memory, and only a stop before delivery loses it.
    if let Err(e) = outbox.put(&parcel, &bytes) {
        tracing::warn!(
            lease = lease.lease_id,
            "cannot keep the result on disk ({e:#}); sending it from memory"
        );
    }
    Ok(Some((parcel, bytes)))
}

/// Longest wait between two attempts to deliver a result.
const MAX_DELIVERY_BACKOFF: Duration = Duration::from_secs(5);
/// After a shutdown signal, how long a worker keeps trying to deliver before it leaves the
/// result on disk for its next start.
const DELIVERY_AFTER_STOP: Duration = Duration::from_secs(30);

/// Sends a kept result until the coordinator answers: accepted or refused for good, it leaves
/// the outbox; unreachable (restarting, network down) or failing (5xx), it is sent again with
/// backoff. Returns whether it was accepted.
async fn deliver(
    client: &Client,
    outbox: &Outbox,
    parcel: &Parcel,
    bytes: Vec<u8>,
    trouble: &mut Trouble,
    stop: &mut watch::Receiver<bool>,
) -> anyhow::Result<bool> {
    let encoding = Encoding::sniff(&bytes);
    let mut backoff = Duration::from_millis(200);
    let mut stopped_at: Option<std::time::Instant> = None;
    loop {
        let mut request = client
            .request(reqwest::Method::PUT, &routes::result(parcel.lease_id))
            .header(reqwest::header::CONTENT_TYPE, "application/octet-stream")
            .header(LEASE_KEY_HEADER, &parcel.key);
        if let Some(e) = encoding.header() {
            request = request.header(reqwest::header::CONTENT_ENCODING, e);
        }
        let sent = request.body(bytes.clone()).send().await;
        let failure = match sent {
            Ok(resp) if resp.status().is_success() => {
                trouble.cleared(client.base());
                outbox.remove(parcel);
                tracing::info!(
                    job = parcel.job_id,
                    start = parcel.start,
                    end = parcel.end,
                    "batch delivered"
                );
                return Ok(true);
            }
            Ok(resp) if resp.status().is_server_error() => {
                let s = resp.status();
                RequestError::Other(s, resp.text().await.unwrap_or_default())
            }
            Ok(resp) => {
                // Refused for good: the lease expired and went to another worker, the job
                // ended, or the result does not fit. Sending it again cannot help.
                trouble.cleared(client.base());
                outbox.remove(parcel);
                let s = resp.status();
                let text = resp.text().await.unwrap_or_default();
                tracing::warn!(lease = parcel.lease_id, "result refused: {s} {}", text.trim());
                return Ok(false);
            }
            Err(e) if e.is_builder() => {
                // The request cannot be made (a kept lease key that is not a header value):
                // no attempt can ever send it.
                outbox.remove(parcel);
                tracing::warn!(lease = parcel.lease_id, "result dropped: {}", error_chain(&e));
                return Ok(false);
            }
            Err(e) => RequestError::Unreachable(error_chain(&e)),
        };
        trouble.failed(client.base(), &failure)?;
        if *stop.borrow() {
            let since = *stopped_at.get_or_insert_with(std::time::Instant::now);
            if since.elapsed() >= DELIVERY_AFTER_STOP {
                tracing::warn!(
                    lease = parcel.lease_id,
                    "stopping with the result undelivered: it stays in {} and a worker started \
                     with the same --cache sends it",
                    outbox.path_of(parcel).display()
                );
                return Ok(false);
            }
        }
        tokio::select! {
            _ = tokio::time::sleep(backoff) => {}
            _ = stop.changed(), if !*stop.borrow() => {}
        }
        backoff = (backoff * 2).min(MAX_DELIVERY_BACKOFF);
    }
}

async fn heartbeat_loop(client: Arc<Client>, lease: u64, key: String, every_ms: u64, lost: Arc<AtomicBool>) {
    let mut tick = tokio::time::interval(Duration::from_millis(every_ms.max(10)));
    tick.tick().await;
    loop {
        tick.tick().await;
        match client
            .request(reqwest::Method::POST, &routes::heartbeat(lease))
            .header(LEASE_KEY_HEADER, &key)
            .send()
            .await
        {
            Ok(r)
                if r.status() == reqwest::StatusCode::CONFLICT
                    || r.status() == reqwest::StatusCode::GONE
                    || r.status() == reqwest::StatusCode::FORBIDDEN =>
            {
                lost.store(true, Ordering::Relaxed);
                return;
            }
            // A failed heartbeat is retried at the next tick; the lease only expires after
            // several are missed.
            _ => {}
        }
    }
}

/// Streams a bundle to `path` (never whole in memory); returns its SHA-256.
async fn download(client: &Client, bundle: &str, path: &std::path::Path) -> anyhow::Result<String> {
    use sha2::Digest;
    use tokio::io::AsyncWriteExt;
    let mut resp = client
        .request(reqwest::Method::GET, &routes::bundle(bundle))
        .send()
        .await?
        .error_for_status()?;
    let mut file = tokio::fs::File::create(path).await?;
    let mut hash = sha2::Sha256::new();
    while let Some(chunk) = resp.chunk().await? {
        hash.update(&chunk);
        file.write_all(&chunk).await?;
    }
    file.flush().await?;
    Ok(hex::encode(hash.finalize()))
}

async fn load_scene(
    client: &Client,
    config: &WorkerConfig,
    scenes: &mut SceneCache,
    lease: &Lease,
) -> anyhow::Result<Arc<Scene>> {
    let key = (lease.bundle.clone(), lease.scene.clone(), lease.defines.clone());
    if let Some(s) = scenes.get(&key) {
        return Ok(s.clone());
    }
    if lease.bundle.len() != 64 || !lease.bundle.chars().all(|c| c.is_ascii_hexdigit()) {
        bail!("malformed bundle id \"{}\"", lease.bundle);
    }
    let dir = config.cache.join(&lease.bundle);
    if !dir.exists() {
        let archive = config
            .cache
            .join(format!("{}.tar.partial-{}", lease.bundle, std::process::id()));
        let hash = download(client, &lease.bundle, &archive).await?;
        if hash != lease.bundle {
            let _ = std::fs::remove_file(&archive);
            bail!("bundle {} arrived damaged (hash mismatch)", lease.bundle);
        }
        let tmp = config
            .cache
            .join(format!("{}.partial-{}", lease.bundle, std::process::id()));
        let _ = std::fs::remove_dir_all(&tmp);
        let unpacked = std::fs::File::open(&archive)
            .map_err(anyhow::Error::from)
            .and_then(|f| {
                photonfarm::bundle::unpack_from(std::io::BufReader::new(f), &tmp, &UnpackLimits::default())
                    .map_err(anyhow::Error::from)
            });
        let _ = std::fs::remove_file(&archive);
        unpacked?;
        std::fs::rename(&tmp, &dir).or_else(|e| if dir.exists() { Ok(()) } else { Err(e) })?;
    }
    let path = dir.join(&lease.scene);
    let defines = lease.defines.clone();
    let dir = dir.clone();
    let scene = tokio::task::spawn_blocking(move || Scene::load_inside(&path, &defines, &dir)).await??;
    let scene = Arc::new(scene);
    scenes.insert(key, scene.clone());
    Ok(scene)
}
