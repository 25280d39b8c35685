//! `coordinator loadgen`: simulated workers against a real coordinator, over real HTTP, to
//! measure how many workers one coordinator feeds (docs/scaling.md).
//!
//! Each simulated worker runs the real worker's protocol: it leases a batch, waits the batch's
//! simulated render time (heartbeating as a worker does), and uploads a valid result of the
//! lease's size and pass count (realistic content from [`crate::client::synthetic`], compressed as
//! the real worker does when the coordinator accepts it). It renders nothing, so one core
//! simulates thousands of workers. A simulated client may also stand for a relay of `fanout`
//! workers (`--fanout`): it asks for one pass per worker at first and renders `fanout` times
//! faster, which is what the coordinator sees of a relay.
//!
//! It measures, over a window after a warm-up: results and bytes per second taken in, the
//! workers' time spent waiting (lease requests and uploads) against their time rendering, and
//! the coordinator's CPU time per result when its process id is given.

use std::collections::HashMap;
use std::sync::atomic::{AtomicBool, Ordering};
use std::sync::{Arc, Mutex};
use std::time::{Duration, Instant};

use anyhow::{Context, bail};
use axum::body::Bytes;
use photonfarm::compression::{self, Encoding};
use photonfarm::protocol::{Endpoint, LEASE_KEY_HEADER, Lease, LeaseRequest, routes};
use tokio::sync::OnceCell;

use crate::cli::LoadgenArgs;
use crate::client::ApiClient;
use crate::client::synthetic::Synthetic;

/// The scene of the simulated job: the Cornell box with spheres, at the asked size.
const SCENE: &str = include_str!("../../../scenes/cbox-spheres.xml");

/// What the simulated workers measured in the window.
#[derive(Default, Debug)]
struct Tally {
    results: u64,
    passes: u64,
    bytes: u64,
    /// Seconds spent rendering (simulated), asking for leases and uploading.
    render_s: f64,
    lease_s: f64,
    upload_s: f64,
    /// Each lease request's and each upload's latency, seconds.
    lease_lat: Vec<f64>,
    upload_lat: Vec<f64>,
    /// Lease requests answered "no work" (204), and failed requests.
    no_work: u64,
    errors: u64,
}

/// Encoded results by (passes, odd passes): made once each, shared by every simulated worker.
type Bodies = Mutex<HashMap<(u64, u64), Arc<OnceCell<Bytes>>>>;

struct Shared {
    http: reqwest::Client,
    synthetic: Synthetic,
    bodies: Bodies,
    encoding: Encoding,
    pass_s: f64,
    fanout: u32,
    measuring: AtomicBool,
    stop: AtomicBool,
    tally: Mutex<Tally>,
}

impl Shared {
    /// The body of a result of `passes` passes with `odd` odd ones (made on first use, on a
    /// blocking thread, and kept).
    async fn body(self: &Arc<Self>, passes: u64, odd: u64, compress: bool) -> anyhow::Result<Bytes> {
        let cell = {
            let mut map = self.bodies.lock().unwrap_or_else(|p| p.into_inner());
            map.entry((passes, odd)).or_default().clone()
        };
        let me = self.clone();
        let bytes = cell
            .get_or_try_init(|| async move {
                tokio::task::spawn_blocking(move || {
                    let plain = me.synthetic.encoded(passes, odd, passes * 7919 + odd);
                    Bytes::from(if compress {
                        compression::compress(&plain)
                    } else {
                        plain
                    })
                })
                .await
            })
            .await?;
        Ok(bytes.clone())
    }
}

/// Runs the load generator and prints its figures.
pub fn run(args: &LoadgenArgs) -> anyhow::Result<()> {
    crate::client::check_address(&args.coordinator)?;
    for v in &args.via {
        crate::client::check_address(v)?;
    }
    if args.workers == 0 || args.fanout == 0 {
        bail!("--workers and --fanout must be at least 1");
    }
    if !(args.pass_seconds >= 0.0 && args.pass_seconds.is_finite()) {
        bail!("--pass-seconds must be 0 or more");
    }
    let rt = tokio::runtime::Runtime::new().context("cannot start the async runtime")?;
    rt.block_on(drive(args))
}

/// The scene file of the simulated job at `width` × `height`.
pub fn scene_xml(width: u32, height: u32) -> String {
    SCENE
        .replace(
            "<integer name=\"width\" value=\"$res\"/>",
            &format!("<integer name=\"width\" value=\"{width}\"/>"),
        )
        .replace(
            "<integer name=\"height\" value=\"$res\"/>",
            &format!("<integer name=\"height\" value=\"{height}\"/>"),
        )
}

/// Submits the simulated job; returns its id.
async fn submit(args: &LoadgenArgs, xml: &str) -> anyhow::Result<u64> {
    let mut tar = tar::Builder::new(Vec::new());
    let mut header = tar::Header::new_gnu();
    header.set_size(xml.len() as u64);
    header.set_mode(0o644);
    header.set_cksum();
    tar.append_data(&mut header, "scene.xml", xml.as_bytes())?;
    let bundle = tar.into_inner()?;
    let settings = photonfarm::job::JobSettings {
        integrator: Some(photonfarm::job::Integrator::Path),
        passes: Some(args.passes),
        checkpoint_every: Some(args.checkpoint_every),
        ..Default::default()
    };
    let client = ApiClient::new(&args.coordinator, args.token.clone());
    Ok(client.submit(bundle, "scene.xml", &settings).await?.status.id)
}

async fn drive(args: &LoadgenArgs) -> anyhow::Result<()> {
    let xml = scene_xml(args.width, args.height);
    let dir = tempfile_dir()?;
    let path = dir.join("scene.xml");
    std::fs::write(&path, &xml)?;
    eprintln!(
        "rendering two real passes at {}x{} for the results' content...",
        args.width, args.height
    );
    let synthetic = tokio::task::spawn_blocking(move || -> anyhow::Result<Synthetic> {
        let scene = photonfarm::scene::Scene::load(&path, &[])?;
        Ok(Synthetic::render(&scene))
    })
    .await??;
    let _ = std::fs::remove_dir_all(&dir);
    let job = submit(args, &xml).await?;
    let clients = args.workers.div_ceil(args.fanout);
    eprintln!(
        "job {job}: {} simulated workers as {clients} clients of {} each, {} s per pass",
        args.workers, args.fanout, args.pass_seconds
    );
    let token = args.worker_token.clone().or_else(|| args.token.clone());
    let shared = Arc::new(Shared {
        http: reqwest::Client::builder()
            .timeout(Duration::from_secs(600))
            .pool_idle_timeout(Duration::from_secs(20))
            .build()?,
        synthetic,
        bodies: Mutex::default(),
        encoding: if args.identity {
            Encoding::Identity
        } else {
            Encoding::Zstd
        },
        pass_s: args.pass_seconds,
        fanout: args.fanout,
        measuring: AtomicBool::new(false),
        stop: AtomicBool::new(false),
        tally: Mutex::default(),
    });
    let targets: Vec<String> = if args.via.is_empty() {
        vec![args.coordinator.clone()]
    } else {
        args.via.clone()
    };
    let mut tasks = Vec::new();
    for i in 0..clients {
        let target = Endpoint::new(
            &targets[i as usize % targets.len()],
            token.clone(),
            shared.http.clone(),
        );
        let shared = shared.clone();
        // Spread the starts over a second, as workers starting at once would not be.
        let delay = Duration::from_millis((i as u64 * 1000) / clients as u64);
        tasks.push(tokio::spawn(async move {
            tokio::time::sleep(delay).await;
            simulate(shared, target, format!("sim-{i}")).await
        }));
    }
    tokio::time::sleep(Duration::from_secs_f64(args.warmup)).await;
    let cpu0 = args.coordinator_pid.and_then(cpu_seconds);
    let t0 = Instant::now();
    shared.measuring.store(true, Ordering::Relaxed);
    tokio::time::sleep(Duration::from_secs_f64(args.duration)).await;
    shared.measuring.store(false, Ordering::Relaxed);
    let window = t0.elapsed().as_secs_f64();
    let cpu1 = args.coordinator_pid.and_then(cpu_seconds);
    shared.stop.store(true, Ordering::Relaxed);
    for t in tasks {
        t.abort();
    }
    let status = ApiClient::new(&args.coordinator, args.token.clone())
        .cancel(job)
        .await
        .ok();
    let tally = std::mem::take(&mut *shared.tally.lock().unwrap_or_else(|p| p.into_inner()));
    let cpu = cpu0.zip(cpu1).map(|(a, b)| b - a);
    report(args, clients, window, &tally, cpu, status.as_ref());
    Ok(())
}

fn tempfile_dir() -> anyhow::Result<std::path::PathBuf> {
    let dir = std::env::temp_dir().join(format!("photonfarm-loadgen-{}", std::process::id()));
    std::fs::create_dir_all(&dir)?;
    Ok(dir)
}

/// A process's CPU time so far (user and system), from /proc; None where there is none.
fn cpu_seconds(pid: u32) -> Option<f64> {
    let stat = std::fs::read_to_string(format!("/proc/{pid}/stat")).ok()?;
    // Fields after the command name (which may hold spaces) start after its ')'.
    let rest = stat.rsplit_once(')')?.1;
    let fields: Vec<&str> = rest.split_whitespace().collect();
    let ticks: f64 = fields.get(11)?.parse::<f64>().ok()? + fields.get(12)?.parse::<f64>().ok()?;
    Some(ticks / 100.0)
}

fn percentile(v: &mut [f64], p: f64) -> f64 {
    if v.is_empty() {
        return 0.0;
    }
    v.sort_by(f64::total_cmp);
    v[((v.len() - 1) as f64 * p).round() as usize]
}

fn report(
    args: &LoadgenArgs,
    clients: u32,
    window: f64,
    t: &Tally,
    cpu: Option<f64>,
    status: Option<&photonfarm::protocol::JobStatus>,
) {
    let mut lease = t.lease_lat.clone();
    let mut upload = t.upload_lat.clone();
    let busy = t.render_s + t.lease_s + t.upload_s;
    let waiting = if busy > 0.0 {
        (t.lease_s + t.upload_s) / busy
    } else {
        0.0
    };
    println!(
        "{}x{} workers={} clients={} fanout={} pass_s={} encoding={}",
        args.width,
        args.height,
        args.workers,
        clients,
        args.fanout,
        args.pass_seconds,
        if args.identity { "identity" } else { "zstd" }
    );
    println!(
        "  window {window:.1} s: {} results ({:.2}/s), {:.1} MB/s on the wire, {:.1} passes/s, {:.2} passes per result",
        t.results,
        t.results as f64 / window,
        t.bytes as f64 / window / 1e6,
        t.passes as f64 / window,
        t.passes as f64 / t.results.max(1) as f64
    );
    println!(
        "  waiting: {:.2}% of the workers' time; lease p50 {:.1} ms p99 {:.1} ms; upload p50 {:.1} ms p99 {:.1} ms; {} 'no work' answers, {} errors",
        waiting * 100.0,
        percentile(&mut lease, 0.5) * 1e3,
        percentile(&mut lease, 0.99) * 1e3,
        percentile(&mut upload, 0.5) * 1e3,
        percentile(&mut upload, 0.99) * 1e3,
        t.no_work,
        t.errors
    );
    if let Some(cpu) = cpu {
        println!(
            "  coordinator CPU: {:.1}% of one core, {:.1} ms per result",
            cpu / window * 100.0,
            cpu * 1e3 / t.results.max(1) as f64
        );
    }
    if let Some(s) = status {
        println!(
            "  job: {} passes received in {} batches",
            s.iterations_done, s.batches_received
        );
    }
}

/// One simulated worker (or relay): lease, wait, upload, until stopped.
async fn simulate(shared: Arc<Shared>, target: Endpoint, name: String) {
    let mut backoff = Duration::from_millis(200);
    while !shared.stop.load(Ordering::Relaxed) {
        let asked = Instant::now();
        let request = LeaseRequest {
            worker: name.clone(),
            threads: 1,
            renderers: (shared.fanout > 1).then_some(shared.fanout),
        };
        let sent = target
            .request(reqwest::Method::POST, routes::LEASE)
            .json(&request)
            .send()
            .await;
        let lease: Lease = match sent {
            Ok(r) if r.status() == reqwest::StatusCode::NO_CONTENT => {
                shared.count(|t| t.no_work += 1);
                tokio::time::sleep(backoff).await;
                backoff = (backoff * 2).min(Duration::from_secs(2));
                continue;
            }
            Ok(r) if r.status().is_success() => match r.json().await {
                Ok(l) => l,
                Err(_) => {
                    shared.count(|t| t.errors += 1);
                    continue;
                }
            },
            _ => {
                shared.count(|t| t.errors += 1);
                tokio::time::sleep(backoff).await;
                continue;
            }
        };
        backoff = Duration::from_millis(200);
        let lease_s = asked.elapsed().as_secs_f64();
        let passes = lease.end - lease.start;
        let odd = lease.end / 2 - lease.start / 2;
        let render = Duration::from_secs_f64(passes as f64 * shared.pass_s / shared.fanout as f64);
        let compress =
            shared.encoding == Encoding::Zstd && lease.accept_encoding.iter().any(|e| e == compression::ZSTD);
        // The body is made while "rendering" (and only once per pass count).
        let (body, ()) = tokio::join!(
            shared.body(passes, odd, compress),
            wait_rendering(&target, &lease, render)
        );
        let Ok(body) = body else {
            shared.count(|t| t.errors += 1);
            continue;
        };
        let upload = upload(
            shared.clone(),
            target.clone(),
            lease,
            body,
            compress,
            lease_s,
            render,
        );
        if shared.fanout > 1 {
            // A relay forwards a finished batch in the background while its workers render
            // the next one (see crate::relay): the simulated relay leases again at once.
            tokio::spawn(upload);
        } else {
            upload.await;
        }
    }
}

/// Uploads a result and tallies the cycle.
async fn upload(
    shared: Arc<Shared>,
    target: Endpoint,
    lease: Lease,
    body: Bytes,
    compress: bool,
    lease_s: f64,
    render: Duration,
) {
    let passes = lease.end - lease.start;
    let started = Instant::now();
    let mut put = target
        .request(reqwest::Method::PUT, &routes::result(lease.lease_id))
        .header(reqwest::header::CONTENT_TYPE, "application/octet-stream")
        .header(LEASE_KEY_HEADER, &lease.key);
    if compress {
        put = put.header(reqwest::header::CONTENT_ENCODING, compression::ZSTD);
    }
    let len = body.len() as u64;
    let ok = matches!(put.body(body).send().await, Ok(r) if r.status().is_success());
    // A relay's workers do not wait for its upload: only a worker's own upload is waiting.
    let upload_s = if shared.fanout > 1 {
        0.0
    } else {
        started.elapsed().as_secs_f64()
    };
    shared.count(|t| {
        if ok {
            t.results += 1;
            t.passes += passes;
            t.bytes += len;
        } else {
            t.errors += 1;
        }
        t.render_s += render.as_secs_f64();
        t.lease_s += lease_s;
        t.upload_s += upload_s;
        t.lease_lat.push(lease_s);
        t.upload_lat.push(started.elapsed().as_secs_f64());
    });
}

impl Shared {
    /// Adds to the tally, inside the measuring window only.
    fn count(&self, f: impl FnOnce(&mut Tally)) {
        if self.measuring.load(Ordering::Relaxed) {
            f(&mut self.tally.lock().unwrap_or_else(|p| p.into_inner()));
        }
    }
}

/// Sleeps for the simulated render time, heartbeating the lease as a worker does.
async fn wait_rendering(target: &Endpoint, lease: &Lease, render: Duration) {
    let until = Instant::now() + render;
    let every = Duration::from_millis(lease.heartbeat_ms.max(10));
    loop {
        let left = until.saturating_duration_since(Instant::now());
        if left.is_zero() {
            return;
        }
        tokio::time::sleep(left.min(every)).await;
        if Instant::now() < until {
            let _ = target
                .request(reqwest::Method::POST, &routes::heartbeat(lease.lease_id))
                .header(LEASE_KEY_HEADER, &lease.key)
                .send()
                .await;
        }
    }
}
