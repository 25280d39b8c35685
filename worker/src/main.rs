//! `worker`: parses the command line and runs the pull loop until SIGTERM or ctrl-c.

use std::path::PathBuf;
use std::process::ExitCode;

use clap::Parser;

/// Photonfarm's render farm worker: asks a coordinator for batches of passes, renders them
/// with all its threads, and sends back the partial images. It needs only outbound connections.
#[derive(Debug, Parser)]
#[command(version, about)]
struct Args {
    /// The coordinator's URL, e.g. http://render-host:8080. An unreachable coordinator is
    /// logged at once and every 30 s while the worker keeps asking; a token refused 5 times in
    /// a row ends the worker with exit code 3.
    #[arg(long)]
    coordinator: String,
    /// Render threads (default: one per core).
    #[arg(long)]
    threads: Option<usize>,
    /// Bearer token, if the coordinator requires one.
    #[arg(long, env = "PHOTONFARM_TOKEN", hide_env_values = true)]
    token: Option<String>,
    /// This worker's name in the coordinator's job status (default: host name and process id).
    #[arg(long)]
    name: Option<String>,
    /// Folder for downloaded job bundles (default: a folder in the system's temporary folder).
    #[arg(long)]
    cache: Option<PathBuf>,
    /// Largest film this worker renders, in pixels [default: memory / 512 B]; a larger batch
    /// is released as a failure.
    #[arg(long)]
    max_pixels: Option<u64>,
    /// Most SPPM photons per iteration this worker renders [default: memory / 256 B].
    #[arg(long)]
    max_photons: Option<u64>,
}

fn main() -> ExitCode {
    let args = Args::parse();
    photonfarm::process::init_logging();
    let name = args
        .name
        .unwrap_or_else(|| default_name(&gethostname::gethostname().to_string_lossy(), std::process::id()));
    let config = worker::WorkerConfig {
        coordinator: args.coordinator,
        threads: args
            .threads
            .unwrap_or_else(|| std::thread::available_parallelism().map_or(1, |n| n.get())),
        token: args.token.filter(|t| !t.is_empty()),
        cache: args
            .cache
            .unwrap_or_else(|| std::env::temp_dir().join(format!("photonfarm-worker-{name}"))),
        name,
        limits: {
            let mut l = photonfarm::limits::Limits::for_this_machine();
            l.max_pixels = args.max_pixels.unwrap_or(l.max_pixels);
            l.max_photons = args.max_photons.unwrap_or(l.max_photons);
            l
        },
    };
    if config.threads == 0 {
        eprintln!("error: --threads must be at least 1");
        return ExitCode::FAILURE;
    }
    // Every backend gives the same bytes; PHOTONFARM_SIMD pins one (docs/engine.md).
    match photonfarm::engine::Backend::from_env() {
        Ok(b) => tracing::info!(simd = b.name(), "lane engine backend"),
        Err(e) => {
            eprintln!("error: {e}");
            return ExitCode::FAILURE;
        }
    }
    let rt = match tokio::runtime::Runtime::new() {
        Ok(rt) => rt,
        Err(e) => {
            eprintln!("error: cannot start the async runtime: {e}");
            return ExitCode::FAILURE;
        }
    };
    match rt.block_on(worker::run(config, photonfarm::process::shutdown_signal())) {
        Ok(()) => ExitCode::SUCCESS,
        Err(e) => {
            eprintln!("error: {e:#}");
            if e.downcast_ref::<worker::TokenRefused>().is_some() {
                ExitCode::from(worker::TokenRefused::EXIT_CODE)
            } else {
                ExitCode::FAILURE
            }
        }
    }
}

/// The default `--name`: the host name and the process id, e.g. `render-a-12345` (`worker-12345`
/// if the host has no name).
fn default_name(host: &str, pid: u32) -> String {
    let host = host.trim();
    let host = if host.is_empty() { "worker" } else { host };
    format!("{host}-{pid}")
}

#[cfg(test)]
mod tests {
    use super::default_name;

    #[test]
    fn the_default_name_is_the_host_name_and_the_process_id() {
        assert_eq!(default_name("render-a", 12345), "render-a-12345");
        assert_eq!(default_name("", 7), "worker-7");
        let host = gethostname::gethostname().to_string_lossy().into_owned();
        assert!(!host.trim().is_empty(), "this machine has no host name");
    }
}
