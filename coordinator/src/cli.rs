//! The command line, documented flag by flag (`coordinator help render` prints this).

use std::path::PathBuf;

use clap::{Parser, Subcommand, ValueEnum};

/// Photonfarm: a physically based renderer (path tracing, and progressive photon mapping to come)
/// for Mitsuba 3 XML scenes.
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
}

/// The rendering method.
#[derive(Clone, Copy, Debug, PartialEq, Eq, ValueEnum)]
pub enum Integrator {
    /// Unidirectional path tracing with next-event estimation and MIS.
    Path,
    /// Stochastic progressive photon mapping (Knaus and Zwicker): caustics and light seen
    /// through glass or in mirrors.
    Sppm,
}

/// `coordinator render`.
#[derive(Debug, clap::Args)]
pub struct RenderArgs {
    /// The Mitsuba 3 XML scene file.
    pub scene: PathBuf,
    /// Output image: .exr (linear 32-bit float) or .png (sRGB, 8-bit).
    #[arg(long, short)]
    pub out: PathBuf,
    /// Rendering method.
    #[arg(long, value_enum, default_value = "path")]
    pub integrator: Integrator,
    /// Path tracing: samples per pixel (passes). Default: the scene's sampler sample_count, or
    /// no limit when --time-limit is given.
    #[arg(long)]
    pub spp: Option<u64>,
    /// SPPM: iterations (each a photon pass and one sample per pixel). Default: the scene's
    /// sampler sample_count, or no limit when --time-limit is given.
    #[arg(long)]
    pub iterations: Option<u64>,
    /// SPPM: photons emitted per iteration [default: the scene's photon_count, else 200000].
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
    /// Write the image so far every N passes or iterations, next to --out with the count in
    /// the name (out-000256.exr).
    #[arg(long, value_name = "N")]
    pub checkpoint_every: Option<u64>,
    /// Stop after this many seconds, at the end of the pass under way.
    #[arg(long, value_name = "SECONDS", allow_negative_numbers = true)]
    pub time_limit: Option<f64>,
    /// Seed of every random number: the same seed gives the same image bytes.
    #[arg(long, default_value_t = 0)]
    pub seed: u64,
    /// Worker threads (default: one per core). Does not change the image.
    #[arg(long)]
    pub threads: Option<usize>,
    /// Override a scene parameter declared with <default name=... value=...>; repeatable.
    #[arg(short = 'D', value_name = "NAME=VALUE", value_parser = parse_define)]
    pub define: Vec<(String, String)>,
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
        Command::Render(args) => crate::render_command::run(&args),
    }
}
