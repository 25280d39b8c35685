//! The command line, documented flag by flag (`coordinator help SUBCOMMAND` prints this).

use std::path::PathBuf;

use clap::{Parser, Subcommand};
use photonfarm::integrator::sppm::VolumeEstimate;
use photonfarm::job::{Integrator as JobIntegrator, JobSettings};

/// Photonfarm: a physically based renderer for Mitsuba 3 XML scenes (path tracing and
/// progressive photon mapping), and the coordinator of its render farm.
#[derive(Debug, Parser)]
#[command(version, about)]
pub struct Cli {
    /// What to do.
    #[command(subcommand)]
    pub command: Command,
}

/// The subcommands.
#[derive(Debug, Subcommand)]
pub enum Command {
    /// Render a scene on this machine and write the image.
    Render(RenderArgs),
    /// Run the farm's coordinator service.
    Serve(ServeArgs),
    /// Submit a scene to a coordinator; optionally wait and download the image.
    Submit(SubmitArgs),
    /// Chart error against render time for several methods or settings.
    Converge(ConvergeArgs),
    /// A farm's jobs, one line each.
    Jobs(JobsArgs),
    /// One job's state, progress, rate, time left and workers.
    Status(JobIdArgs),
    /// Follow a job with a progress bar until it ends (and download its image with --out).
    Wait(WaitArgs),
    /// Download a job's latest image.
    Fetch(FetchArgs),
    /// Cancel a job.
    Cancel(JobIdArgs),
    /// Relay for many local workers: lease from an upstream coordinator on their behalf, merge
    /// their exact sums and forward one result per upstream batch.
    Relay(RelayArgs),
    /// Simulated workers against a real coordinator: measures the results and bytes per second
    /// it takes in and how long workers wait (docs/scaling.md).
    Loadgen(LoadgenArgs),
    /// The service's scene checker (run by `serve` in a child process).
    #[command(hide = true)]
    CheckScene(CheckSceneArgs),
}

/// Where the coordinator is, for the job commands.
#[derive(Debug, Clone, clap::Args)]
pub struct ConnectionArgs {
    /// The coordinator's address, with http:// or https://, e.g. http://render-host:8080.
    #[arg(long, value_name = "URL")]
    pub to: String,
    /// Bearer token, if the coordinator requires one.
    #[arg(long, env = "PHOTONFARM_TOKEN", hide_env_values = true)]
    pub token: Option<String>,
}

/// `coordinator jobs`.
#[derive(Debug, clap::Args)]
pub struct JobsArgs {
    /// The coordinator.
    #[command(flatten)]
    pub conn: ConnectionArgs,
}

/// `coordinator status ID` and `cancel ID`.
#[derive(Debug, clap::Args)]
pub struct JobIdArgs {
    /// The job's id (printed by `submit`, listed by `jobs`).
    pub id: u64,
    /// The coordinator.
    #[command(flatten)]
    pub conn: ConnectionArgs,
}

/// `coordinator wait ID`.
#[derive(Debug, clap::Args)]
pub struct WaitArgs {
    /// The job's id.
    pub id: u64,
    /// Download the final image here (.exr or .png).
    #[arg(long)]
    pub out: Option<PathBuf>,
    /// With --out, also download the denoised preview of a job submitted with --denoise, as
    /// OUT with `.denoised` before its extension (as `render --denoise` names it).
    #[arg(long, requires = "out")]
    pub denoised: bool,
    /// Give up after this many seconds with the job unfinished (status 1, saying how far it
    /// got); the job goes on. Without it, waits for as long as the job takes.
    #[arg(long, value_name = "SECONDS", value_parser = parse_timeout)]
    pub timeout: Option<std::time::Duration>,
    /// The coordinator.
    #[command(flatten)]
    pub conn: ConnectionArgs,
}

/// `coordinator fetch ID --out FILE`.
#[derive(Debug, clap::Args)]
pub struct FetchArgs {
    /// The job's id.
    pub id: u64,
    /// Where to write the latest image (.exr or .png).
    #[arg(long)]
    pub out: PathBuf,
    /// Also download the denoised preview of a job submitted with --denoise, as OUT with
    /// `.denoised` before its extension (as `render --denoise` names it).
    #[arg(long)]
    pub denoised: bool,
    /// The coordinator.
    #[command(flatten)]
    pub conn: ConnectionArgs,
}

/// The job commands, for the one function that runs them.
pub enum JobCommand<'a> {
    /// `jobs`.
    Jobs(&'a JobsArgs),
    /// `status`.
    Status(&'a JobIdArgs),
    /// `wait`.
    Wait(&'a WaitArgs),
    /// `fetch`.
    Fetch(&'a FetchArgs),
    /// `cancel`.
    Cancel(&'a JobIdArgs),
}

impl JobCommand<'_> {
    /// The coordinator the command talks to.
    pub fn connection(&self) -> &ConnectionArgs {
        match self {
            JobCommand::Jobs(a) => &a.conn,
            JobCommand::Status(a) | JobCommand::Cancel(a) => &a.conn,
            JobCommand::Wait(a) => &a.conn,
            JobCommand::Fetch(a) => &a.conn,
        }
    }
}

/// `coordinator check-scene` (internal).
#[derive(Debug, clap::Args)]
pub struct CheckSceneArgs {
    /// The scene file.
    pub scene: PathBuf,
    /// The folder every file the scene reads must lie in (the job's bundle).
    #[arg(long)]
    pub root: PathBuf,
    /// The job's settings, as JSON.
    #[arg(long)]
    pub settings: String,
    /// Where to write the report.
    #[arg(long)]
    pub out: PathBuf,
}

/// `coordinator converge`.
#[derive(Debug, clap::Args)]
pub struct ConvergeArgs {
    /// The Mitsuba 3 XML scene file.
    pub scene: PathBuf,
    /// Reference image (EXR) of the same resolution.
    #[arg(long)]
    pub reference: PathBuf,
    /// Methods to compare, comma-separated: path, ptracer, hybrid, sppm (its default volume
    /// estimate), sppm-beam, sppm-point, sppm-photon-beams (SPPM with that volume estimate).
    #[arg(long, default_value = "path,sppm")]
    pub methods: String,
    /// Render time per line, seconds.
    #[arg(long, default_value_t = 30.0, allow_negative_numbers = true)]
    pub time_limit: f64,
    /// Where to write convergence.csv, convergence.png and convergence.svg.
    #[arg(long, default_value = "convergence")]
    pub out_dir: PathBuf,
    /// SPPM alpha; several comma-separated values sweep it (one line each).
    #[arg(long, value_delimiter = ',', allow_negative_numbers = true)]
    pub alpha: Vec<f64>,
    /// SPPM initial radius; several comma-separated values sweep it (one line each).
    #[arg(long, value_delimiter = ',', allow_negative_numbers = true)]
    pub radius: Vec<f32>,
    /// SPPM photons per iteration.
    #[arg(long)]
    pub photons: Option<u64>,
    /// SPPM cone filter k.
    #[arg(long)]
    pub k: Option<f32>,
    /// SPPM initial volume radius over the surface one.
    #[arg(long)]
    pub volume_radius_ratio: Option<f32>,
    /// Seed of every random number.
    #[arg(long, default_value_t = 0)]
    pub seed: u64,
    /// Render threads (default: one per core).
    #[arg(long)]
    pub threads: Option<usize>,
    /// Also measure each line's denoised preview (a line NAME+denoised; Open Image Denoise,
    /// as `render --denoise`), in a render of its own with the features, so the raw line keeps
    /// the speed of a render without them. Doubles the run's time.
    #[arg(long)]
    pub denoise: bool,
    /// Override a scene parameter; repeatable.
    #[arg(short = 'D', value_name = "NAME=VALUE", value_parser = parse_define)]
    pub define: Vec<(String, String)>,
}

/// What to render: shared by `render` and `submit`.
#[derive(Debug, clap::Args)]
pub struct JobArgs {
    /// The Mitsuba 3 XML scene file.
    pub scene: PathBuf,
    /// More scene files: the files are then a sequence, one frame each, numbered from 1 in
    /// the order given (`render`: `--out` names them with `#`; `submit`: one bundle for all).
    #[arg(value_name = "MORE_SCENES")]
    pub more_scenes: Vec<PathBuf>,
    /// Rendering method [default: the scene's <integrator>: path and volpath render with
    /// path, direct with direct, sppm with sppm, ptracer with ptracer; path if it has none].
    #[arg(long, value_enum)]
    pub integrator: Option<JobIntegrator>,
    /// Path tracing, direct, ptracer and hybrid: samples (light paths for ptracer) per pixel
    /// (passes). Default: the scene's sampler sample_count (`render`: no limit when
    /// --time-limit is given).
    #[arg(long)]
    pub spp: Option<u64>,
    /// SPPM: iterations (each a photon pass and one sample per pixel). Default: the scene's
    /// sampler sample_count (`render`: no limit when --time-limit is given).
    #[arg(long)]
    pub iterations: Option<u64>,
    /// SPPM: photons emitted per iteration [default: the scene's photon_count, else a quarter
    /// of the pixels, at least 16384].
    #[arg(long)]
    pub photons: Option<u64>,
    /// SPPM: initial gather radius in scene units [default: the scene's initial_radius, else
    /// three pixel footprints at the median distance the camera sees].
    #[arg(long, allow_negative_numbers = true)]
    pub radius: Option<f32>,
    /// SPPM: Knaus and Zwicker's alpha in (0, 1), the fraction of photons kept per iteration
    /// [default: the scene's alpha, else 2/3].
    #[arg(long, allow_negative_numbers = true)]
    pub alpha: Option<f64>,
    /// SPPM: the cone filter's k >= 1 (weights fall linearly to 1 - 1/k at the radius)
    /// [default: 1.1].
    #[arg(long, allow_negative_numbers = true)]
    pub k: Option<f32>,
    /// SPPM: initial volume radius over the initial surface radius [default: the scene's
    /// volume_radius_ratio, else 0.5 with --volume-estimate beam and 2 with point and
    /// photon-beams].
    #[arg(long, allow_negative_numbers = true)]
    pub volume_radius_ratio: Option<f32>,
    /// SPPM: how light scattered in media is estimated from the volume photons: `beam` along
    /// the whole camera ray (Jarosz et al.'s beam radiance estimate), `point` at one sampled
    /// collision, or `photon-beams` from photon flights passing the camera ray [default: beam].
    /// See docs/volumes.md.
    #[arg(long, value_enum)]
    pub volume_estimate: Option<VolumeEstimate>,
    /// Seed of every random number: the same seed gives the same image bytes.
    #[arg(long, default_value_t = 0)]
    pub seed: u64,
    /// Write the image so far every N passes or iterations (`render`: next to --out as
    /// out-000256.exr; `submit`: the job's latest image) [submit default: 64].
    #[arg(long, value_name = "N")]
    pub checkpoint_every: Option<u64>,
    /// Override a scene parameter declared with <default name=... value=...>; repeatable.
    #[arg(short = 'D', value_name = "NAME=VALUE", value_parser = parse_define)]
    pub define: Vec<(String, String)>,
    /// Render a sequence: the frames in Flamenco's syntax (`1-240`, `1-100x2,150`). Each frame
    /// sets the scene parameter `frame` (`$frame`; a scene need not use it) and has its own
    /// seed, derived from --seed and the frame; each `-D name=A:B` runs linearly from A at the
    /// first frame to B at the last (`render`: --time-limit applies to each frame, and --resume
    /// goes on from the first unfinished frame; `submit`: one job of many frames).
    #[arg(long, value_name = "LIST")]
    pub frames: Option<String>,
    /// Also make a denoised preview, made by Open Image Denoise from the image, its albedo and
    /// its normal: `render` writes OUT with `.denoised` before its extension (`x.exr` →
    /// `x.denoised.exr`), the farm beside each checkpoint (`fetch --denoised`). The image
    /// itself is unchanged. Needs a build with OIDN (README).
    #[arg(long)]
    pub denoise: bool,
    /// Also sum the denoiser's features, the albedo and normal of the first surface seen past
    /// mirrors and glass, and write them into the EXR as channels `albedo.R` … `normal.B`. Costs
    /// about one ray per pixel and pass; the EXR only (a PNG has no channels for them).
    #[arg(long)]
    pub aovs: bool,
}

impl JobArgs {
    /// The settings these flags ask for.
    pub fn settings(&self) -> anyhow::Result<JobSettings> {
        let integrator = self.integrator;
        let passes = match (integrator, self.spp, self.iterations) {
            (_, Some(_), Some(_)) => {
                anyhow::bail!("give --spp (path, direct, ptracer, hybrid) or --iterations (sppm), not both")
            }
            (Some(i), _, Some(_)) if i != JobIntegrator::Sppm => {
                anyhow::bail!("--iterations applies to --integrator sppm; use --spp")
            }
            (Some(JobIntegrator::Sppm), Some(_), _) => {
                anyhow::bail!("SPPM counts iterations: use --iterations, not --spp")
            }
            // Without --integrator the scene decides the method; either flag counts passes.
            (_, spp, it) => spp.or(it),
        };
        if integrator.is_some_and(|i| i != JobIntegrator::Sppm) {
            for (flag, given) in [
                ("--photons", self.photons.is_some()),
                ("--radius", self.radius.is_some()),
                ("--alpha", self.alpha.is_some()),
                ("--k", self.k.is_some()),
                ("--volume-radius-ratio", self.volume_radius_ratio.is_some()),
                ("--volume-estimate", self.volume_estimate.is_some()),
            ] {
                if given {
                    anyhow::bail!("{flag} applies to --integrator sppm");
                }
            }
        }
        let frames = match (&self.frames, self.more_scenes.len()) {
            (Some(_), n) if n > 0 => {
                anyhow::bail!(
                    "several scene files are a sequence of their own: give --frames or several files, not both"
                )
            }
            (_, 0) => self.frames.clone(),
            (_, n) => Some(format!("1-{}", n + 1)),
        };
        Ok(JobSettings {
            integrator,
            passes,
            photons: self.photons,
            radius: self.radius,
            alpha: self.alpha,
            k: self.k,
            volume_radius_ratio: self.volume_radius_ratio,
            volume_estimate: self.volume_estimate,
            defines: self.define.clone(),
            seed: self.seed,
            checkpoint_every: self.checkpoint_every,
            frames,
            scenes: Vec::new(),
            aovs: self.aovs,
            denoise: self.denoise,
        })
    }
}

/// `coordinator render`.
#[derive(Debug, clap::Args)]
pub struct RenderArgs {
    /// What to render.
    #[command(flatten)]
    pub job: JobArgs,
    /// Output image: .exr (linear 32-bit float) or .png (sRGB, 8-bit). With --frames, each run
    /// of `#` in the file name is the frame number padded with zeros (`shots/cbox-####.exr`);
    /// a name without `#` gets the number, four digits, before its extension (as Blender does).
    #[arg(long, short)]
    pub out: PathBuf,
    /// Stop after this many seconds, at the end of the batch under way.
    #[arg(long, value_name = "SECONDS", allow_negative_numbers = true)]
    pub time_limit: Option<f64>,
    /// Worker threads (default: one per core). Does not change the image.
    #[arg(long)]
    pub threads: Option<usize>,
    /// Continue an interrupted render from the sums saved beside OUT (`OUT.resume`); the result
    /// is the bytes of an uninterrupted render. The scene and every setting that changes the
    /// pixels must be the same; the pass count may be larger.
    #[arg(long)]
    pub resume: bool,
    /// How often the exact sums are saved to `OUT.resume` while rendering [default: 30].
    #[arg(long, value_name = "SECONDS", allow_negative_numbers = true)]
    pub save_every: Option<f64>,
    /// Size limits (as for `coordinator serve`).
    #[command(flatten)]
    pub limits: LimitArgs,
}

/// The job size limits, for `render` (the service has its own, with more).
#[derive(Debug, clap::Args)]
pub struct LimitArgs {
    /// Largest film, in pixels (width × height) [default: memory / 512 B].
    #[arg(long)]
    pub max_pixels: Option<u64>,
    /// Most passes [default: 10000000].
    #[arg(long)]
    pub max_passes: Option<u64>,
    /// Most SPPM photons per iteration [default: memory / 256 B].
    #[arg(long)]
    pub max_photons: Option<u64>,
}

impl LimitArgs {
    /// This machine's limits, overridden by the flags.
    pub fn limits(&self) -> photonfarm::limits::Limits {
        let mut l = photonfarm::limits::Limits::for_this_machine();
        l.max_pixels = self.max_pixels.unwrap_or(l.max_pixels);
        l.max_passes = self.max_passes.unwrap_or(l.max_passes);
        l.max_photons = self.max_photons.unwrap_or(l.max_photons);
        l
    }
}

/// `coordinator serve`.
#[derive(Debug, clap::Args)]
pub struct ServeArgs {
    /// Address to listen on.
    #[arg(long, default_value = "127.0.0.1:8080")]
    pub bind: String,
    /// Data folder: the SQLite database, job bundles, partial sums and images.
    #[arg(long)]
    pub data: PathBuf,
    /// Require `Authorization: Bearer TOKEN` of users (`/api/jobs*`), and of workers too
    /// unless --worker-token is given.
    #[arg(long, env = "PHOTONFARM_TOKEN", hide_env_values = true)]
    pub token: Option<String>,
    /// Require `Authorization: Bearer TOKEN` of workers (`/api/lease`, `/api/leases/*`,
    /// `/api/bundles/*`); the users' token is then refused there.
    #[arg(long, env = "PHOTONFARM_WORKER_TOKEN", hide_env_values = true)]
    pub worker_token: Option<String>,
    /// Largest upload (a job bundle; a batch result is also held to its lease's size), in MiB.
    #[arg(long, default_value_t = 512)]
    pub max_upload_mb: u64,
    /// Largest film of a job, in pixels (width × height) [default: memory / 512 B].
    #[arg(long)]
    pub max_pixels: Option<u64>,
    /// Most passes (samples per pixel or SPPM iterations) of a job [default: 10000000].
    #[arg(long)]
    pub max_passes: Option<u64>,
    /// Most SPPM photons per iteration [default: memory / 256 B].
    #[arg(long)]
    pub max_photons: Option<u64>,
    /// Most bytes of a bundle's files (the scene and its meshes), in MiB
    /// [default: memory / 128].
    #[arg(long)]
    pub max_geometry_mb: Option<u64>,
    /// Most files in a bundle.
    #[arg(long, default_value_t = 10_000)]
    pub max_bundle_files: usize,
    /// Most bytes a bundle may unpack to, in MiB [default: memory / 16].
    #[arg(long)]
    pub max_bundle_mb: Option<u64>,
    /// Uploads (bundles and results) read at the same time.
    #[arg(long, default_value_t = 4)]
    pub max_uploads: usize,
    /// Connections and their timeouts.
    #[command(flatten)]
    pub connections: crate::serving::ConnectionArgs,
    /// Submitted scenes checked at the same time (each loads in a child process, taking up to
    /// about 30 times its files' size, bounded by --max-geometry-mb).
    #[arg(long, default_value_t = 2)]
    pub max_scene_checks: usize,
    /// Seconds a submitted scene may take to load (in a child process, killed beyond).
    #[arg(long, default_value_t = 120)]
    pub scene_check_timeout: u64,
    /// Seconds without a heartbeat after which a batch goes to another worker.
    #[arg(long, default_value_t = 30.0)]
    pub lease_timeout: f64,
    /// Batches aim at this many seconds on the worker that renders them.
    #[arg(long, default_value_t = 5.0)]
    pub batch_seconds: f64,
    /// Checkpoint interval (passes) of jobs that do not set one.
    #[arg(long, default_value_t = 64)]
    pub checkpoint_every: u64,
    /// Megapixels of results per second this coordinator absorbs: batches lengthen beyond
    /// --batch-seconds so that all workers' results together stay within it (workers × image
    /// pixels / this). 0 turns the rule off. See docs/scaling.md.
    #[arg(long, default_value_t = crate::service::scheduler::DEFAULT_ABSORB_PIXELS_PER_S / 1e6)]
    pub absorb_mpx_per_second: f64,
}

/// `coordinator relay`.
#[derive(Debug, clap::Args)]
pub struct RelayArgs {
    /// The coordinator (or relay) to lease from, e.g. http://render-host:8080.
    #[arg(long, value_name = "URL")]
    pub upstream: String,
    /// Address the local workers connect to.
    #[arg(long, default_value = "127.0.0.1:8090")]
    pub bind: String,
    /// The upstream's workers' token.
    #[arg(long, env = "PHOTONFARM_TOKEN", hide_env_values = true)]
    pub token: Option<String>,
    /// The token the local workers must present [default: --token].
    #[arg(long, env = "PHOTONFARM_LOCAL_TOKEN", hide_env_values = true)]
    pub local_token: Option<String>,
    /// This relay's name upstream [default: relay-HOST-PID].
    #[arg(long)]
    pub name: Option<String>,
    /// Seconds without a heartbeat after which a local worker's part goes to another one.
    #[arg(long, default_value_t = 30.0)]
    pub lease_timeout: f64,
    /// Local workers' results read at the same time (each may be a whole image's sums).
    #[arg(long, default_value_t = 4)]
    pub max_uploads: usize,
    /// Connections and their timeouts, as for `coordinator serve`.
    #[command(flatten)]
    pub connections: crate::serving::ConnectionArgs,
}

/// `coordinator loadgen`.
#[derive(Debug, clap::Args)]
pub struct LoadgenArgs {
    /// The coordinator to submit the simulated job to (and to lease from, without --via).
    #[arg(long, value_name = "URL")]
    pub coordinator: String,
    /// Relays to lease from instead, comma-separated: the clients are spread over them.
    #[arg(long, value_name = "URL", value_delimiter = ',')]
    pub via: Vec<String>,
    /// The users' token (to submit and cancel the job).
    #[arg(long, env = "PHOTONFARM_TOKEN", hide_env_values = true)]
    pub token: Option<String>,
    /// The workers' token [default: --token].
    #[arg(long, env = "PHOTONFARM_WORKER_TOKEN", hide_env_values = true)]
    pub worker_token: Option<String>,
    /// Simulated workers.
    #[arg(long, default_value_t = 100)]
    pub workers: u32,
    /// Workers per simulated client: each client stands for a relay of this many workers
    /// (one pass per worker at first, this many times faster).
    #[arg(long, default_value_t = 1)]
    pub fanout: u32,
    /// Image width.
    #[arg(long, default_value_t = 1920)]
    pub width: u32,
    /// Image height.
    #[arg(long, default_value_t = 1080)]
    pub height: u32,
    /// Simulated render time of one pass on one worker, seconds.
    #[arg(long, default_value_t = 5.0)]
    pub pass_seconds: f64,
    /// Seconds before measuring (batch sizes settle).
    #[arg(long, default_value_t = 30.0)]
    pub warmup: f64,
    /// Seconds measured.
    #[arg(long, default_value_t = 60.0)]
    pub duration: f64,
    /// Send results uncompressed, as workers before compression did.
    #[arg(long)]
    pub identity: bool,
    /// Passes of the simulated job.
    #[arg(long, default_value_t = 10_000_000)]
    pub passes: u64,
    /// Checkpoint interval of the simulated job, passes.
    #[arg(long, default_value_t = 1024)]
    pub checkpoint_every: u64,
    /// The coordinator's process id, to report its CPU time per result (same machine).
    #[arg(long)]
    pub coordinator_pid: Option<u32>,
}

/// `coordinator submit`.
#[derive(Debug, clap::Args)]
pub struct SubmitArgs {
    /// The coordinator.
    #[command(flatten)]
    pub conn: ConnectionArgs,
    /// What to render.
    #[command(flatten)]
    pub job: JobArgs,
    /// Wait for the job to finish, showing progress.
    #[arg(long)]
    pub wait: bool,
    /// With --wait: give up waiting after this many seconds (as `wait --timeout`).
    #[arg(long, value_name = "SECONDS", requires = "wait", value_parser = parse_timeout)]
    pub timeout: Option<std::time::Duration>,
    /// With --wait: where to write the final image (.exr or .png).
    #[arg(long, short, requires = "wait")]
    pub out: Option<PathBuf>,
}

fn parse_define(s: &str) -> Result<(String, String), String> {
    match s.split_once('=') {
        Some((k, v)) if !k.is_empty() => Ok((k.to_string(), v.to_string())),
        _ => Err(format!("expected NAME=VALUE, got \"{s}\"")),
    }
}

/// Runs a parsed command line.
pub fn run(cli: Cli) -> anyhow::Result<()> {
    match cli.command {
        Command::Render(args) => crate::local::render::run(&args),
        Command::Serve(args) => crate::service::serve_command::run(args),
        Command::Submit(args) => crate::client::run_submit(&args),
        Command::Converge(args) => crate::local::converge::run(&args),
        Command::Jobs(c) => crate::client::run_job_command(&JobCommand::Jobs(&c)),
        Command::Status(a) => crate::client::run_job_command(&JobCommand::Status(&a)),
        Command::Wait(a) => crate::client::run_job_command(&JobCommand::Wait(&a)),
        Command::Fetch(a) => crate::client::run_job_command(&JobCommand::Fetch(&a)),
        Command::Cancel(a) => crate::client::run_job_command(&JobCommand::Cancel(&a)),
        Command::Relay(args) => crate::relay::run(&args),
        Command::Loadgen(args) => crate::client::loadgen::run(&args),
        Command::CheckScene(args) => {
            crate::service::scene_check::run_child(&args.scene, &args.root, &args.settings, &args.out)
        }
    }
}

/// A positive, finite number of seconds.
fn parse_timeout(s: &str) -> Result<std::time::Duration, String> {
    match s.parse::<f64>() {
        Ok(v) if v > 0.0 && v.is_finite() => {
            std::time::Duration::try_from_secs_f64(v).map_err(|e| e.to_string())
        }
        _ => Err(format!("expected a positive number of seconds, got {s:?}")),
    }
}
