//! `coordinator serve`: flags to configuration, logging, the runtime, signals.

use anyhow::{Context, bail};

use crate::cli::ServeArgs;
use crate::farm::FarmConfig;
use crate::scheduler::SchedulerConfig;
use crate::service::{ServeConfig, run as serve};

/// Runs the service until ctrl-c or SIGTERM.
pub fn run(args: ServeArgs) -> anyhow::Result<()> {
    if !(args.lease_timeout > 0.0 && args.lease_timeout.is_finite()) {
        bail!("--lease-timeout must be a positive number of seconds");
    }
    if !(args.batch_seconds > 0.0 && args.batch_seconds.is_finite()) {
        bail!("--batch-seconds must be a positive number of seconds");
    }
    if args.max_upload_mb == 0 || args.checkpoint_every == 0 {
        bail!("--max-upload-mb and --checkpoint-every must be at least 1");
    }
    photonfarm::process::init_logging();
    // An empty PHOTONFARM_TOKEN (as docker compose passes an unset variable) means no token.
    let token = args.token.clone().filter(|t| !t.is_empty());
    if token.is_none() {
        tracing::warn!("no token configured: anyone who can reach this address can use the service");
    }
    let config = ServeConfig {
        data: args.data.clone(),
        token,
        max_upload: args.max_upload_mb << 20,
        farm: FarmConfig {
            scheduler: SchedulerConfig {
                lease_timeout_ms: (args.lease_timeout * 1000.0) as u64,
                target_batch_ms: (args.batch_seconds * 1000.0) as u64,
                ..SchedulerConfig::default()
            },
            default_checkpoint: args.checkpoint_every,
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
