//! `coordinator serve`: the farm as a network service.
//!
//! [`run`] takes a bound listener and a shutdown future, so tests start a real server on port 0
//! and stop it at will; `main` only parses flags and waits for ctrl-c or SIGTERM.

pub mod accumulator;
pub mod admission;
pub mod api;
pub mod farm;
pub mod metrics;
pub mod scene_check;
pub mod scheduler;
pub mod serve_command;
pub mod store;
pub mod web;
pub mod workers;

use std::path::PathBuf;
use std::sync::Arc;
use std::sync::atomic::AtomicU64;
use std::time::Duration;

use tokio::net::TcpListener;
use tokio::sync::Semaphore;

use crate::service::admission::Admission;
use crate::service::api::{AppState, Tokens, router};
use crate::service::farm::{FarmConfig, SharedFarm};
use crate::service::store::Store;

/// Service settings.
#[derive(Clone, Debug)]
pub struct ServeConfig {
    /// Data folder (SQLite database, bundles, images).
    pub data: PathBuf,
    /// Bearer tokens of users and workers.
    pub tokens: Tokens,
    /// Limits on every request (the job limits also go to the farm, for jobs it reloads).
    pub admission: Admission,
    /// The program that checks submitted scenes in a child process (`coordinator
    /// check-scene`); None checks them in this process.
    pub checker: Option<PathBuf>,
    /// Scheduling.
    pub farm: FarmConfig,
}

/// The service's state: the farm opened on its data folder (resuming its jobs), and the
/// request limits. [`run`] serves it; tests drive its router in process.
pub async fn open(config: &ServeConfig) -> anyhow::Result<Arc<AppState>> {
    let data = config.data.clone();
    let farm_config = config.farm;
    let farm = tokio::task::spawn_blocking(move || -> anyhow::Result<SharedFarm> {
        let store = Store::open(&data)?;
        Ok(SharedFarm::open(store, farm_config)?)
    })
    .await??;
    let admission = config.admission;
    Ok(Arc::new(AppState {
        layout: farm.read(|f| f.layout()),
        farm,
        tokens: config.tokens.clone(),
        admission,
        checker: config.checker.clone(),
        uploads: AtomicU64::new(0),
        bundle_slots: Semaphore::new(admission.max_uploads.max(1)),
        result_slots: Semaphore::new(admission.max_uploads.max(1)),
        receiving: Default::default(),
        scene_checks: Semaphore::new(admission.max_scene_checks.max(1)),
        metrics: Default::default(),
        stopping: tokio::sync::watch::Sender::new(false),
    }))
}

/// Serves until `shutdown` completes, then finishes the requests under way.
pub async fn run(
    listener: TcpListener,
    config: ServeConfig,
    shutdown: impl std::future::Future<Output = ()> + Send + 'static,
) -> anyhow::Result<()> {
    let state = open(&config).await?;
    let admission = config.admission;
    // Leases without heartbeats expire; check several times per timeout.
    let period = Duration::from_millis((config.farm.scheduler.lease_timeout_ms / 10).clamp(10, 1000));
    let expiry_state = state.clone();
    let expiry = tokio::spawn(async move {
        let mut tick = tokio::time::interval(period);
        loop {
            tick.tick().await;
            let st = expiry_state.clone();
            let _ = tokio::task::spawn_blocking(move || {
                if let Err(e) = st.farm.run(|f| f.expire()) {
                    tracing::error!("lease expiry: {e}");
                }
            })
            .await;
        }
    });
    let addr = listener.local_addr()?;
    tracing::info!(
        %addr,
        data = %config.data.display(),
        client_auth = config.tokens.client.is_some(),
        worker_auth = config.tokens.worker.is_some(),
        "serving"
    );
    // On standard output, for scripts (and tests) that bind port 0.
    println!("listening on http://{addr}");
    // Lease requests waiting for work answer at once when the service stops.
    let stopping = state.clone();
    let shutdown = async move {
        shutdown.await;
        stopping.stopping.send_replace(true);
    };
    crate::serving::serve(listener, router(state), admission.serving, shutdown).await?;
    expiry.abort();
    Ok(())
}
