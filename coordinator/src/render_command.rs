//! `coordinator render`: load, render on this machine, write.

use std::time::Duration;

use anyhow::{Context, bail};
use photonfarm::integrator::path::PathSettings;
use photonfarm::render::{Budget, RenderSettings, render_progressive};
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
    if args.spp == Some(0) {
        bail!("--spp must be at least 1");
    }
    if args.threads == Some(0) {
        bail!("--threads must be at least 1");
    }
    let scene = Scene::load(&args.scene, &args.define)?;
    for w in &scene.warnings {
        eprintln!("warning: {w}");
    }
    let budget = Budget {
        passes: match (args.spp, args.time_limit) {
            (Some(n), _) => Some(n),
            (None, Some(_)) => None,
            (None, None) => Some(scene.spp as u64),
        },
        time_limit: args.time_limit.map(Duration::from_secs_f64),
    };
    let settings = match args.integrator {
        Integrator::Path => RenderSettings {
            seed: args.seed,
            path: PathSettings::from_scene(&scene),
        },
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
    let mut reporter = Reporter::new(budget.passes, "passes");
    let film = pool.install(|| {
        render_progressive(&scene, &settings, budget, |p, _| {
            reporter.update(p.done, p.total, p.elapsed)
        })
    });
    reporter.finish();
    if film.nonfinite > 0 {
        eprintln!(
            "warning: {} samples were NaN or infinite and were left out of the image",
            film.nonfinite
        );
    }
    film.write(&args.out)?;
    eprintln!("wrote {} ({} passes)", args.out.display(), film.passes);
    Ok(())
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
