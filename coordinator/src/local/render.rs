//! `coordinator render`: the farm's flow with an in-process worker.
//!
//! The same [`Scheduler`] hands out batches and the same [`Accumulator`] merges them as in the
//! farm, so a local render and a farm render of the same settings give the same bytes, and
//! checkpoints fall on the same pass counts.

use std::path::{Path, PathBuf};
use std::sync::Arc;
use std::sync::atomic::{AtomicBool, Ordering};
use std::time::{Duration, Instant};

use anyhow::{Context, bail};
use photonfarm::features::{Features, write_image_with_features};
use photonfarm::film::{FilmSum, is_exr, write_image};
use photonfarm::frames::{frame_path, parse_frames};
use photonfarm::job::JobSettings;
use photonfarm::render::{Method, Renderer};
use photonfarm::scene::Scene;

use crate::cli::RenderArgs;
use crate::local::resume;
use crate::progress::Reporter;
use crate::service::accumulator::Accumulator;
use crate::service::scheduler::{JobState, Scheduler, SchedulerConfig};

/// Renders `args.job.scene` to `args.out`, or each frame of `--frames` to its name.
pub fn run(args: &RenderArgs) -> anyhow::Result<()> {
    // Check everything cheap first: a typo must not cost a long render.
    check_output(&args.out)?;
    if args.job.denoise && !crate::denoise::AVAILABLE {
        bail!("--denoise: {}", crate::denoise::UNAVAILABLE);
    }
    if args.job.aovs && !is_exr(&args.out) {
        bail!(
            "--aovs: {} is not an EXR, and only EXR files hold the albedo and normal channels \
             (--denoise alone works with PNG)",
            args.out.display()
        );
    }
    if let Some(t) = args.time_limit
        && !(t > 0.0 && t.is_finite())
    {
        bail!("--time-limit must be a positive number of seconds, not {t}");
    }
    if args.threads == Some(0) {
        bail!("--threads must be at least 1");
    }
    let save_every = args.save_every.unwrap_or(30.0);
    if !(save_every > 0.0 && save_every.is_finite()) {
        bail!("--save-every must be a positive number of seconds, not {save_every}");
    }
    let settings = args.job.settings()?;
    let interrupted = interruption_flag();
    let Some(spec) = &settings.frames else {
        return render_image(
            args,
            &args.job.scene,
            &settings,
            &args.out,
            args.resume,
            &interrupted,
        );
    };
    let files: Vec<&Path> = std::iter::once(&args.job.scene)
        .chain(&args.job.more_scenes)
        .map(PathBuf::as_path)
        .collect();
    let frames = parse_frames(spec)?;
    // Every frame's parameters first: a bad ramp fails before the first frame renders.
    let plans = frames
        .iter()
        .map(|&frame| {
            Ok((
                frame,
                frame_path(&args.out, frame),
                settings.for_frame(&frames, frame)?,
            ))
        })
        .collect::<Result<Vec<_>, photonfarm::frames::FrameError>>()?;
    for (i, (frame, out, frame_settings)) in plans.iter().enumerate() {
        // Several files: frame i is the i-th file; else every frame is the scene.
        let scene = if files.len() > 1 { files[i] } else { files[0] };
        // --resume goes on from the first frame not finished: a finished frame has its image
        // and no sums beside it.
        let sums = resume::path_for(out);
        let done = args.resume && out.exists() && !sums.exists();
        let of = frames.len();
        eprintln!(
            "frame {frame} ({} of {of}): {}{}",
            i + 1,
            out.display(),
            if done { " is done" } else { "" }
        );
        if !done {
            render_image(
                args,
                scene,
                frame_settings,
                out,
                args.resume && sums.exists(),
                &interrupted,
            )?;
        }
    }
    Ok(())
}

/// Renders one image (a still, or one frame of a sequence) to `out`.
fn render_image(
    args: &RenderArgs,
    scene_path: &Path,
    settings: &JobSettings,
    out: &Path,
    resume: bool,
    interrupted: &Arc<AtomicBool>,
) -> anyhow::Result<()> {
    let scene = Scene::load(scene_path, &settings.defines)?;
    for w in &scene.warnings {
        eprintln!("warning: {w}");
    }
    if settings.denoise && !scene.filter.is_box() {
        eprintln!(
            "warning: --denoise: the film's filter is not a box, so each sample is spread over \
             its neighbours, which Open Image Denoise cannot tell from detail: expect little \
             denoising (<rfilter type=\"box\"/> gives it independent pixels; docs/denoising.md)"
        );
    }
    let resolved = settings.resolve(&scene, args.time_limit.is_some())?;
    // Before anything the size of the film or the photon count is allocated.
    args.limits
        .limits()
        .check_job(scene.width(), scene.height(), resolved.passes, &resolved.render)?;
    let method = resolved.render.method.name();
    let source = if args.job.integrator.is_none() {
        " (the scene's <integrator>)"
    } else {
        ""
    };
    eprintln!("method: {method}{source}");
    let unit = match &resolved.render.method {
        Method::Path(_) | Method::Direct(_) | Method::Ptracer(_) | Method::Hybrid(_) => "passes",
        Method::Sppm(s) => {
            eprintln!(
                "SPPM: {} photons per iteration, initial radius {:.4e} (volume {:.4e}), alpha {:.3}, k {}",
                s.photons,
                s.initial_radius,
                s.initial_radius * s.volume_radius_ratio,
                s.alpha,
                s.k
            );
            "iterations"
        }
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
        scene_path.display(),
        scene.width(),
        scene.height(),
        scene.shapes.len(),
        scene.lights.len()
    );

    // The farm's scheduler with one in-process worker; short batches keep progress and the
    // time limit responsive.
    let mut scheduler = Scheduler::new(
        SchedulerConfig {
            lease_timeout_ms: u64::MAX / 4,
            target_batch_ms: 500,
            max_batch: 1 << 16,
            absorb_pixels_per_s: 0.0,
        },
        1,
    );
    let total = resolved.passes.unwrap_or(u64::MAX);
    let window = settings.checkpoint_every.unwrap_or(1 << 40);
    let fingerprint = resume::fingerprint(scene_path, &scene, &settings.defines, &resolved.render)?;
    let sums_path = resume::path_for(out);
    let prefix = if resume {
        let sum = resume::load(&sums_path, &fingerprint, scene.width(), scene.height())?;
        eprintln!(
            "resuming from {} ({} {unit} done)",
            sums_path.display(),
            sum.passes
        );
        sum
    } else {
        if sums_path.exists() {
            eprintln!(
                "warning: starting afresh; {} (an earlier render's sums) will be replaced \
                 (--resume continues it instead)",
                sums_path.display()
            );
        }
        FilmSum::new(scene.width(), scene.height())
    };
    let done = prefix.passes;
    // The denoiser's features, summed beside the image and saved beside its sums.
    let with_features = settings.features();
    let features = match (with_features, resume) {
        (false, _) => None,
        (true, false) => Some(Features::new(scene.width(), scene.height())),
        (true, true) => Some(resume::load_features(
            &sums_path,
            &fingerprint,
            scene.width(),
            scene.height(),
            done,
        )?),
    };
    let save_features = |f: &Features| resume::save_features(&sums_path, &fingerprint, f);
    if done > total {
        bail!(
            "--resume: {} already holds {done} {unit}, more than the {total} asked for (ask for at \
             least {done})",
            sums_path.display()
        );
    }
    scheduler.add_job(0, total, window, done, &[(0, done)], JobState::Queued);
    // A local render follows no noise estimate (no odd-pass sample).
    let mut acc = Accumulator::new(prefix, None, features, window);
    let save_every = Duration::from_secs_f64(args.save_every.unwrap_or(30.0));
    let mut saved = Instant::now();
    let mut save_error = None;
    let start = Instant::now();
    let limit = args.time_limit.map(Duration::from_secs_f64);
    let mut reporter = Reporter::new(resolved.passes, unit);
    let mut checkpoint_error = None;
    let now = || start.elapsed().as_millis() as u64;
    let mut renderer = Renderer::new(&scene, &resolved.render);
    if with_features {
        renderer = renderer.with_features();
    }
    loop {
        let stop = interrupted.load(Ordering::Relaxed);
        if stop || limit.is_some_and(|l| start.elapsed() >= l) {
            scheduler.close(0);
        }
        let Some(grant) = scheduler.lease("local", now()) else {
            break;
        };
        // SPPM's radii from the settings' schedule, as the coordinator sends them to workers.
        let batch = pool.install(|| renderer.render(grant.start..grant.end, None, interrupted));
        let sum = batch.sum;
        if sum.passes == 0 {
            // Interrupted before the batch's first pass; the loop closes the job.
            continue;
        }
        if sum.passes == grant.end - grant.start {
            scheduler.complete(grant.lease_id, now())?;
        }
        let checkpoints = acc.add(grant.start, sum, None, batch.features)?.checkpoints;
        if (saved.elapsed() >= save_every || !checkpoints.is_empty()) && save_error.is_none() {
            // Keep rendering if this fails: the image may still be written.
            let saved_all = resume::save(&sums_path, &fingerprint, acc.prefix())
                .and_then(|()| acc.features().map_or(Ok(()), save_features));
            if let Err(e) = saved_all {
                save_error = Some(format!("{e:#}"));
            }
            saved = Instant::now();
        }
        for cp in checkpoints {
            let write = |path: &Path| -> Result<(), photonfarm::film::FilmError> {
                let (w, h) = (cp.sum.width, cp.sum.height);
                write_image_with_features(&cp.sum.image()?, w, h, cp.features.as_ref(), path)
            };
            if cp.sum.passes < total
                && checkpoint_error.is_none()
                && let Err(e) = write(&checkpoint_path(out, cp.sum.passes))
            {
                // Keep rendering: the final image may still be written.
                checkpoint_error = Some(e.to_string());
            }
        }
        reporter.update(acc.prefix_passes(), resolved.passes, start.elapsed());
    }
    reporter.finish();
    let film = acc.prefix();
    if film.nonfinite > 0 {
        eprintln!(
            "warning: {} samples were NaN or infinite and were left out of the image",
            film.nonfinite
        );
    }
    if film.sums.iter().all(|s| *s == [0; 3]) && !scene.lights.is_empty() {
        eprintln!(
            "warning: the image is black: no light reaches the camera (are all lights enclosed, \
             facing away, or outside the view's reach?)"
        );
    }
    if let Some(e) = checkpoint_error {
        eprintln!("warning: checkpoints stopped: {e}");
    }
    if let Some(e) = save_error {
        eprintln!("warning: the sums for --resume were not saved: {e}");
    }
    let image = film.image()?;
    let features = acc.features();
    write_image_with_features(&image, film.width, film.height, features, out)?;
    // A render that reached its pass count needs no sums; one that stopped early keeps them for
    // --resume.
    let finished = film.passes >= total;
    if finished {
        let _ = std::fs::remove_file(&sums_path);
        resume::remove_features(&sums_path);
    } else {
        resume::save(&sums_path, &fingerprint, film)?;
        if let Some(f) = features {
            save_features(f)?;
        }
    }
    if settings
        .checkpoint_every
        .is_some_and(|n| film.passes.is_multiple_of(n))
    {
        // The last checkpoint is the final image.
        let _ = std::fs::copy(out, checkpoint_path(out, film.passes));
    }
    eprintln!(
        "wrote {} ({} {unit} in {:.1} s)",
        out.display(),
        film.passes,
        start.elapsed().as_secs_f64()
    );
    if settings.denoise
        && let Some(f) = features
    {
        // After the image and its sums are safe: a failing denoiser loses no work.
        let t = Instant::now();
        let denoised = crate::denoise::denoise(&image, f)
            .with_context(|| format!("{} was written, but denoising it failed", out.display()))?;
        let path = crate::denoise::denoised_path(out);
        write_image(&denoised, film.width, film.height, &path)?;
        eprintln!(
            "wrote {} (denoised in {:.2} s)",
            path.display(),
            t.elapsed().as_secs_f64()
        );
    }
    if interrupted.load(Ordering::Relaxed) {
        let of = resolved.passes.map(|n| format!(" of {n}")).unwrap_or_default();
        bail!(
            "interrupted: {} wholly holds the {} finished {unit}{of}; the same command with \
             --resume continues from them",
            out.display(),
            film.passes
        );
    }
    if !finished {
        eprintln!(
            "{} holds the exact sums: the same command with --resume (and a larger pass count \
             or time limit) continues the render",
            sums_path.display()
        );
    }
    Ok(())
}

/// Set on ctrl-c or SIGTERM: the render stops after the batch under way (at most about half a
/// second of work) and writes the image of every finished pass, so an interruption keeps the
/// work done.
fn interruption_flag() -> Arc<AtomicBool> {
    let flag = Arc::new(AtomicBool::new(false));
    let set = flag.clone();
    std::thread::spawn(move || {
        let Ok(rt) = tokio::runtime::Builder::new_current_thread().enable_all().build() else {
            return;
        };
        rt.block_on(photonfarm::process::shutdown_signal());
        eprintln!("\ninterrupted: finishing the pass under way, then writing the image");
        set.store(true, Ordering::Relaxed);
    });
    flag
}

/// `out.exr` → `out-000256.exr`, beside it.
pub fn checkpoint_path(out: &Path, count: u64) -> PathBuf {
    photonfarm::film::beside(out, &format!("-{count:06}"))
}

/// Fails early on an output the render could not write.
pub fn check_output(out: &Path) -> anyhow::Result<()> {
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
