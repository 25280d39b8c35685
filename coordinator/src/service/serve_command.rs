//! `coordinator serve`: flags to configuration, logging, the runtime, signals.

use anyhow::{Context, bail};

use crate::cli::ServeArgs;
use crate::service::admission::Admission;
use crate::service::api::Tokens;
use crate::service::farm::FarmConfig;
use crate::service::scheduler::SchedulerConfig;
use crate::service::{ServeConfig, run as serve};

/// The limits: this machine's defaults, overridden by the flags.
fn admission_of(args: &ServeArgs) -> anyhow::Result<Admission> {
    let mut a = Admission::for_this_machine();
    fn mib(v: u64) -> u64 {
        v.saturating_mul(1 << 20)
    }
    a.max_upload = mib(args.max_upload_mb);
    a.job.max_pixels = args.max_pixels.unwrap_or(a.job.max_pixels);
    a.job.max_passes = args.max_passes.unwrap_or(a.job.max_passes);
    a.job.max_photons = args.max_photons.unwrap_or(a.job.max_photons);
    a.max_geometry = args.max_geometry_mb.map_or(a.max_geometry, mib);
    a.bundle.max_files = args.max_bundle_files;
    a.bundle.max_bytes = args.max_bundle_mb.map_or(a.bundle.max_bytes, mib);
    a.max_uploads = args.max_uploads;
    a.max_scene_checks = args.max_scene_checks;
    a.serving = args.connections.checked().map_err(anyhow::Error::msg)?;
    a.scene_check_timeout_s = args.scene_check_timeout;
    let zero = [
        ("--max-pixels", a.job.max_pixels),
        ("--max-passes", a.job.max_passes),
        ("--max-photons", a.job.max_photons),
        ("--max-bundle-files", a.bundle.max_files as u64),
        ("--max-bundle-mb", a.bundle.max_bytes),
        ("--max-uploads", a.max_uploads as u64),
        ("--max-scene-checks", a.max_scene_checks as u64),
        ("--scene-check-timeout", a.scene_check_timeout_s),
    ];
    if let Some((flag, _)) = zero.iter().find(|(_, v)| *v == 0) {
        bail!("{flag} must be at least 1");
    }
    Ok(a)
}

/// Runs the service until ctrl-c or SIGTERM.
pub fn run(args: ServeArgs) -> anyhow::Result<()> {
    if !(args.lease_timeout > 0.0 && args.lease_timeout.is_finite()) {
        bail!("--lease-timeout must be a positive number of seconds");
    }
    if !(args.batch_seconds > 0.0 && args.batch_seconds.is_finite()) {
        bail!("--batch-seconds must be a positive number of seconds");
    }
    if !(args.absorb_mpx_per_second >= 0.0 && args.absorb_mpx_per_second.is_finite()) {
        bail!("--absorb-mpx-per-second must be 0 (off) or a positive number");
    }
    if args.max_upload_mb == 0 || args.checkpoint_every == 0 {
        bail!("--max-upload-mb and --checkpoint-every must be at least 1");
    }
    let admission = admission_of(&args)?;
    photonfarm::process::init_logging();
    // An empty PHOTONFARM_TOKEN (as docker compose passes an unset variable) means no token.
    let client = args.token.clone().filter(|t| !t.is_empty());
    let worker = args
        .worker_token
        .clone()
        .filter(|t| !t.is_empty())
        .or_else(|| client.clone());
    if client.is_none() || worker.is_none() {
        tracing::warn!("no token configured: anyone who can reach this address can use the service");
    }
    tracing::info!(?admission, "limits");
    let config = ServeConfig {
        data: args.data.clone(),
        tokens: Tokens { client, worker },
        // Scenes are checked by this program in a child process.
        checker: std::env::current_exe().ok(),
        admission,
        farm: FarmConfig {
            scheduler: SchedulerConfig {
                lease_timeout_ms: (args.lease_timeout * 1000.0) as u64,
                target_batch_ms: (args.batch_seconds * 1000.0) as u64,
                absorb_pixels_per_s: args.absorb_mpx_per_second * 1e6,
                ..SchedulerConfig::default()
            },
            default_checkpoint: args.checkpoint_every,
            limits: admission.job,
        },
    };
    let rt = tokio::runtime::Runtime::new().context("cannot start the async runtime")?;
    rt.block_on(async {
        let listener = tokio::net::TcpListener::bind(&args.bind)
            .await
            .with_context(|| format!("cannot listen on {}", args.bind))?;
        let shutdown = async {
            photonfarm::process::shutdown_signal().await;
            tracing::info!("shutting down");
        };
        serve(listener, config, shutdown).await
    })
}
