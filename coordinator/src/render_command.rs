//! `coordinator render`: load, render on this machine, write.

use std::time::Duration;

use anyhow::{Context, bail};
use std::path::{Path, PathBuf};

use photonfarm::integrator::path::PathSettings;
use photonfarm::integrator::sppm::SppmSettings;
use photonfarm::render::{Budget, Method, RenderSettings, render_progressive};
use photonfarm::scene::Scene;

use crate::cli::{Integrator, RenderArgs};
use crate::progress::Reporter;

/// Renders `args.scene` to `args.out`.
pub fn run(args: &RenderArgs) -> anyhow::Result<()> {
    // Check the output first: a typo must not cost a long render.
    check_output(&args.out)?;
    if let Some(t) = args.time_limit
        && !(t > 0.0 && t.is_finite())
    {
        bail!("--time-limit must be a positive number of seconds, not {t}");
    }
    if args.spp == Some(0) || args.iterations == Some(0) {
        bail!("--spp and --iterations must be at least 1");
    }
    if args.threads == Some(0) {
        bail!("--threads must be at least 1");
    }
    if args.checkpoint_every == Some(0) {
        bail!("--checkpoint-every must be at least 1");
    }
    let sppm_flags = [
        ("--iterations", args.iterations.is_some()),
        ("--photons", args.photons.is_some()),
        ("--radius", args.radius.is_some()),
        ("--alpha", args.alpha.is_some()),
        ("--k", args.k.is_some()),
    ];
    match args.integrator {
        Integrator::Path => {
            if let Some((flag, _)) = sppm_flags.iter().find(|(_, given)| *given) {
                bail!("{flag} applies to --integrator sppm");
            }
        }
        Integrator::Sppm if args.spp.is_some() => {
            bail!("SPPM counts iterations: use --iterations, not --spp")
        }
        Integrator::Sppm => {}
    }
    let scene = Scene::load(&args.scene, &args.define)?;
    for w in &scene.warnings {
        eprintln!("warning: {w}");
    }
    let (method, count, unit) = match args.integrator {
        Integrator::Path => (Method::Path(PathSettings::from_scene(&scene)), args.spp, "passes"),
        Integrator::Sppm => {
            let (mut s, warnings) = SppmSettings::from_scene(&scene);
            for w in warnings {
                eprintln!("warning: {w}");
            }
            s.photons = args.photons.unwrap_or(s.photons);
            s.initial_radius = args.radius.unwrap_or(s.initial_radius);
            s.alpha = args.alpha.unwrap_or(s.alpha);
            s.k = args.k.unwrap_or(s.k);
            s.validate()?;
            eprintln!(
                "SPPM: {} photons per iteration, initial radius {:.4e}, alpha {:.3}, k {}",
                s.photons, s.initial_radius, s.alpha, s.k
            );
            let declared = scene
                .integrator
                .params
                .iter()
                .find(|(n, _)| n == "iterations")
                .map(|(_, v)| *v as u64);
            (Method::Sppm(s), args.iterations.or(declared), "iterations")
        }
    };
    let budget = Budget {
        passes: match (count, args.time_limit) {
            (Some(n), _) => Some(n),
            (None, Some(_)) => None,
            (None, None) => Some(scene.spp as u64),
        },
        time_limit: args.time_limit.map(Duration::from_secs_f64),
        checkpoint_every: args.checkpoint_every,
    };
    let settings = RenderSettings {
        seed: args.seed,
        method,
    };
    let threads = args
        .threads
        .unwrap_or_else(|| std::thread::available_parallelism().map_or(1, |n| n.get()));
    let pool = rayon::ThreadPoolBuilder::new()
        .num_threads(threads)
        .build()
        .context("cannot start the render threads")?;
    eprintln!(
        "rendering {} ({}x{}, {} shapes, {} lights) with {threads} thread(s)",
        args.scene.display(),
        scene.width(),
        scene.height(),
        scene.shapes.len(),
        scene.lights.len()
    );
    let mut reporter = Reporter::new(budget.passes, unit);
    let mut checkpoint_error = None;
    let film = pool.install(|| {
        render_progressive(&scene, &settings, budget, |p, film| {
            reporter.update(p.done, p.total, p.elapsed);
            let due = args.checkpoint_every.is_some_and(|n| p.done % n == 0);
            if due && checkpoint_error.is_none() {
                let path = checkpoint_path(&args.out, p.done);
                if let Err(e) = film.write(&path) {
                    // Keep rendering: the final image may still be written elsewhere.
                    checkpoint_error = Some(e.to_string());
                }
            }
        })
    });
    reporter.finish();
    if film.nonfinite > 0 {
        eprintln!(
            "warning: {} samples were NaN or infinite and were left out of the image",
            film.nonfinite
        );
    }
    if let Some(e) = checkpoint_error {
        eprintln!("warning: checkpoints stopped: {e}");
    }
    film.write(&args.out)?;
    eprintln!("wrote {} ({} {unit})", args.out.display(), film.passes);
    Ok(())
}

/// `out.exr` → `out-000256.exr`, beside it.
pub fn checkpoint_path(out: &Path, count: u64) -> PathBuf {
    let stem = out.file_stem().map(|s| s.to_string_lossy()).unwrap_or_default();
    let ext = out.extension().map(|s| s.to_string_lossy()).unwrap_or_default();
    out.with_file_name(format!("{stem}-{count:06}.{ext}"))
}

fn check_output(out: &std::path::Path) -> anyhow::Result<()> {
    let ext = out
        .extension()
        .and_then(|e| e.to_str())
        .map(str::to_ascii_lowercase);
    if !matches!(ext.as_deref(), Some("exr" | "png")) {
        bail!("--out {}: the file name must end in .exr or .png", out.display());
    }
    let dir = out.parent().filter(|d| !d.as_os_str().is_empty());
    if let Some(dir) = dir
        && !dir.is_dir()
    {
        bail!("--out {}: folder {} does not exist", out.display(), dir.display());
    }
    Ok(())
}
