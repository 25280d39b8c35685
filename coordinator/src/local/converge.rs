//! `coordinator converge`: error against time, per method, as a CSV and a log-log chart.
//!
//! Each line (a method, or one value of a swept SPPM setting) renders for the same time
//! budget; at geometrically spaced moments (every √2 of render time, from 0.25 s) the image so
//! far is compared with the reference. Comparison time is not counted as render time.
//!
//! With `--denoise`, every line also sums the denoiser's features, and each measurement is
//! taken twice: of the image, and of its denoised preview (a line `NAME+denoised`), whose time
//! includes the denoising. Both count the features' cost, so the two curves of a method differ
//! only by the denoiser.

use std::path::Path;
use std::sync::atomic::AtomicBool;
use std::time::{Duration, Instant};

use anyhow::{Context, bail};
use clap::ValueEnum;
use photonfarm::color::Rgb;
use photonfarm::features::Features;
use photonfarm::film::{FilmSum, read_image};
use photonfarm::integrator::sppm::VolumeEstimate;
use photonfarm::job::{Integrator as JobIntegrator, JobSettings};
use photonfarm::render::{RenderSettings, Renderer};
use photonfarm::scene::Scene;
use plotters::prelude::*;

use crate::cli::ConvergeArgs;

/// One measurement.
#[derive(Clone, Debug)]
pub struct Row {
    /// The line: method and swept setting.
    pub line: String,
    /// Render time so far.
    pub seconds: f64,
    /// Passes (spp or iterations) so far.
    pub passes: u64,
    /// Root mean squared error against the reference.
    pub rmse: f64,
    /// The largest relative error of a channel mean.
    pub worst_mean_error: f64,
}

/// RMSE and worst relative channel-mean error of `img` against `reference`.
pub fn errors(img: &[Rgb], reference: &[Rgb]) -> (f64, f64) {
    let (mut se, mut m, mut r) = (0.0f64, [0.0f64; 3], [0.0f64; 3]);
    for (a, b) in img.iter().zip(reference) {
        for c in 0..3 {
            let d = (a[c] - b[c]) as f64;
            se += d * d;
            m[c] += a[c] as f64;
            r[c] += b[c] as f64;
        }
    }
    let worst = (0..3)
        .filter(|&c| r[c] > 0.0)
        .map(|c| (m[c] - r[c]).abs() / r[c])
        .fold(0.0, f64::max);
    ((se / (3 * img.len()) as f64).sqrt(), worst)
}

/// Runs the command.
pub fn run(args: &ConvergeArgs) -> anyhow::Result<()> {
    if !(args.time_limit > 0.0 && args.time_limit.is_finite()) {
        bail!("--time-limit must be a positive number of seconds");
    }
    if args.denoise && !crate::denoise::AVAILABLE {
        bail!("--denoise: {}", crate::denoise::UNAVAILABLE);
    }
    let lines = plan_lines(args)?;
    let (rw, rh, reference) =
        read_image(&args.reference).with_context(|| format!("cannot read {}", args.reference.display()))?;
    std::fs::create_dir_all(&args.out_dir)
        .with_context(|| format!("cannot create {}", args.out_dir.display()))?;
    let threads = args
        .threads
        .unwrap_or_else(|| std::thread::available_parallelism().map_or(1, |n| n.get()));
    let pool = rayon::ThreadPoolBuilder::new().num_threads(threads).build()?;
    let mut rows = Vec::new();
    for (name, settings) in &lines {
        let scene = Scene::load(&args.scene, &settings.defines)?;
        if (scene.width(), scene.height()) != (rw, rh) {
            bail!(
                "the reference is {rw}x{rh} but the scene renders {}x{}: set the resolution with -D",
                scene.width(),
                scene.height()
            );
        }
        let resolved = settings.resolve(&scene, true)?;
        eprintln!("{name}: rendering for {:.0} s", args.time_limit);
        // With --denoise the raw line is rendered apart, without the features, so that it runs
        // at the speed of a render that does not ask for them: the twin pays for what it uses.
        let budget = Duration::from_secs_f64(args.time_limit);
        let mut line_rows = measure(&scene, &resolved.render, &reference, name, budget, false, &pool)?;
        if args.denoise {
            eprintln!("{name}+denoised: rendering for {:.0} s", args.time_limit);
            line_rows.extend(measure(
                &scene,
                &resolved.render,
                &reference,
                name,
                budget,
                true,
                &pool,
            )?);
        }
        if let Some(last) = line_rows.iter().rev().find(|r| r.line == *name) {
            eprintln!(
                "{name}: {} passes in {:.1} s, RMSE {:.4}, worst channel mean error {:.2}%",
                last.passes,
                last.seconds,
                last.rmse,
                100.0 * last.worst_mean_error
            );
        }
        rows.extend(line_rows);
    }
    let csv = args.out_dir.join("convergence.csv");
    write_csv(&csv, &rows)?;
    let title = format!(
        "{} — RMSE against render time ({threads} threads)",
        args.scene
            .file_name()
            .map(|n| n.to_string_lossy())
            .unwrap_or_default()
    );
    chart(
        &args.out_dir.join("convergence.png"),
        &args.out_dir.join("convergence.svg"),
        &title,
        &rows,
    )?;
    eprintln!("wrote {}, convergence.png and convergence.svg", csv.display());
    Ok(())
}

/// The lines to render: one per method, or one per value of a swept SPPM setting.
fn plan_lines(args: &ConvergeArgs) -> anyhow::Result<Vec<(String, JobSettings)>> {
    let sweeps = [("alpha", args.alpha.len()), ("radius", args.radius.len())];
    if sweeps.iter().filter(|(_, n)| *n > 1).count() > 1 {
        bail!("sweep one setting at a time (--alpha or --radius with several values)");
    }
    let base = JobSettings {
        photons: args.photons,
        k: args.k,
        volume_radius_ratio: args.volume_radius_ratio,
        defines: args.define.clone(),
        seed: args.seed,
        ..JobSettings::default()
    };
    let mut lines = Vec::new();
    for m in args.methods.split(',').map(str::trim) {
        // A method by its name, or SPPM with a volume estimate: `sppm-` and the estimate's name.
        let parsed = match m.strip_prefix("sppm-") {
            Some(estimate) => VolumeEstimate::from_str(estimate, false)
                .ok()
                .map(|e| (JobIntegrator::Sppm, Some(e))),
            None => JobIntegrator::from_name(m).map(|i| (i, None)),
        };
        let Some((integrator, volume_estimate)) = parsed.filter(|(i, _)| converges(*i)) else {
            bail!(
                "unknown method \"{m}\" in --methods ({})",
                converge_methods().join(", ")
            );
        };
        if integrator != JobIntegrator::Sppm {
            // SPPM's settings do not apply to the path tracer's, particle tracer's or hybrid's line.
            lines.push((
                m.to_string(),
                JobSettings {
                    integrator: Some(integrator),
                    photons: None,
                    k: None,
                    volume_radius_ratio: None,
                    ..base.clone()
                },
            ));
            continue;
        }
        let alphas: Vec<Option<f64>> = if args.alpha.is_empty() {
            vec![None]
        } else {
            args.alpha.iter().map(|a| Some(*a)).collect()
        };
        let radii: Vec<Option<f32>> = if args.radius.is_empty() {
            vec![None]
        } else {
            args.radius.iter().map(|r| Some(*r)).collect()
        };
        for alpha in &alphas {
            for radius in &radii {
                let mut name = m.to_string();
                if alphas.len() > 1 {
                    name.push_str(&format!(" alpha={}", alpha.unwrap_or_default()));
                }
                if radii.len() > 1 {
                    name.push_str(&format!(" radius={}", radius.unwrap_or_default()));
                }
                lines.push((
                    name,
                    JobSettings {
                        integrator: Some(JobIntegrator::Sppm),
                        alpha: *alpha,
                        radius: *radius,
                        volume_estimate,
                        ..base.clone()
                    },
                ));
            }
        }
    }
    Ok(lines)
}

/// Whether `--methods` takes a method: all but `direct`, which leaves out most light and so
/// converges to another image.
fn converges(i: JobIntegrator) -> bool {
    i != JobIntegrator::Direct
}

/// The names `--methods` takes: the methods that converge, and SPPM with each volume estimate.
fn converge_methods() -> Vec<String> {
    let methods = JobIntegrator::ALL.into_iter().filter(|i| converges(*i));
    let estimates = VolumeEstimate::value_variants()
        .iter()
        .filter_map(|e| e.to_possible_value());
    methods
        .map(|i| i.name().to_string())
        .chain(estimates.map(|e| format!("sppm-{}", e.get_name())))
        .collect()
}

/// Renders until the budget is spent, measuring at √2-spaced moments of render time; with
/// `denoise`, with the features, measuring the denoised preview alone (line `NAME+denoised`),
/// its time including the features and the denoising.
fn measure(
    scene: &Scene,
    settings: &RenderSettings,
    reference: &[Rgb],
    name: &str,
    budget: Duration,
    denoise: bool,
    pool: &rayon::ThreadPool,
) -> anyhow::Result<Vec<Row>> {
    let mut film = FilmSum::new(scene.width(), scene.height());
    let mut features = denoise.then(|| Features::new(scene.width(), scene.height()));
    let mut render_time = Duration::ZERO;
    let mut next = Duration::from_millis(250).min(budget);
    let mut chunk = 1u64;
    let mut rows = Vec::new();
    let mut renderer = Renderer::new(scene, settings);
    if denoise {
        renderer = renderer.with_features();
    }
    let never = AtomicBool::new(false);
    loop {
        let start = Instant::now();
        let batch = pool.install(|| renderer.render(film.passes..film.passes + chunk, None, &never));
        render_time += start.elapsed();
        film.add(&batch.sum).expect("same scene, same size");
        if let (Some(all), Some(these)) = (features.as_mut(), &batch.features) {
            all.add(these).expect("same scene, same size");
        }
        if render_time >= next || render_time >= budget {
            let image = film.image().expect("passes were rendered");
            if let Some(f) = &features {
                let start = Instant::now();
                let denoised = crate::denoise::denoise(&image, f)?;
                let (rmse, worst) = errors(&denoised, reference);
                rows.push(Row {
                    line: format!("{name}+denoised"),
                    seconds: (render_time + start.elapsed()).as_secs_f64(),
                    passes: film.passes,
                    rmse,
                    worst_mean_error: worst,
                });
            } else {
                let (rmse, worst) = errors(&image, reference);
                rows.push(Row {
                    line: name.to_string(),
                    seconds: render_time.as_secs_f64(),
                    passes: film.passes,
                    rmse,
                    worst_mean_error: worst,
                });
            }
            while next <= render_time {
                next = next.mul_f64(std::f64::consts::SQRT_2);
            }
            next = next.min(budget);
        }
        if render_time >= budget {
            return Ok(rows);
        }
        // Aim the next chunk at the next measurement.
        let per_pass = render_time.as_secs_f64() / film.passes as f64;
        chunk =
            (((next - render_time.min(next)).as_secs_f64() / per_pass.max(1e-9)) as u64).clamp(1, 1 << 16);
    }
}

fn write_csv(path: &Path, rows: &[Row]) -> anyhow::Result<()> {
    let mut out = String::from("method,seconds,passes,rmse,worst_channel_mean_error\n");
    for r in rows {
        out.push_str(&format!(
            "{},{:.4},{},{:.6e},{:.6e}\n",
            r.line, r.seconds, r.passes, r.rmse, r.worst_mean_error
        ));
    }
    std::fs::write(path, out).with_context(|| format!("cannot write {}", path.display()))
}

const FONT: &[u8] = include_bytes!("../../assets/DejaVuSans.ttf");

/// A font that ships with the program: the chart looks the same on every machine.
fn register_font() {
    static REGISTERED: std::sync::Once = std::sync::Once::new();
    REGISTERED.call_once(|| {
        let _ = plotters::style::register_font("sans-serif", FontStyle::Normal, FONT);
    });
}

fn chart(png: &Path, svg: &Path, title: &str, rows: &[Row]) -> anyhow::Result<()> {
    register_font();
    {
        let root = BitMapBackend::new(png, (1000, 680)).into_drawing_area();
        draw(&root, title, rows)?;
        root.present().map_err(|e| anyhow::anyhow!("{e}"))?;
    }
    let root = SVGBackend::new(svg, (1000, 680)).into_drawing_area();
    draw(&root, title, rows)?;
    root.present().map_err(|e| anyhow::anyhow!("{e}"))?;
    Ok(())
}

fn draw<DB: DrawingBackend>(
    root: &DrawingArea<DB, plotters::coord::Shift>,
    title: &str,
    rows: &[Row],
) -> anyhow::Result<()>
where
    DB::ErrorType: 'static,
{
    let err = |e: DrawingAreaErrorKind<DB::ErrorType>| anyhow::anyhow!("cannot draw the chart: {e:?}");
    root.fill(&WHITE).map_err(err)?;
    let (mut x0, mut x1, mut y0, mut y1) = (f64::MAX, f64::MIN, f64::MAX, f64::MIN);
    for r in rows.iter().filter(|r| r.rmse > 0.0) {
        x0 = x0.min(r.seconds);
        x1 = x1.max(r.seconds);
        y0 = y0.min(r.rmse);
        y1 = y1.max(r.rmse);
    }
    if x0 > x1 {
        (x0, x1, y0, y1) = (0.1, 1.0, 0.01, 0.1);
    }
    let (x0, x1, y0, y1) = (x0 * 0.8, x1 * 1.25, y0 * 0.8, y1 * 1.25);
    // Our own ticks: plotters' log-scale ticks repeat each decade's end (two "0.1" labels).
    let (x_labels, x_grid) = log_ticks(x0, x1);
    let (y_labels, y_grid) = log_ticks(y0, y1);
    let mut chart = ChartBuilder::on(root)
        .caption(title, ("sans-serif", 24))
        .margin(20)
        .x_label_area_size(50)
        .y_label_area_size(80)
        .build_cartesian_2d(
            (x0..x1)
                .log_scale()
                .with_key_points(x_labels)
                .with_light_points(x_grid),
            (y0..y1)
                .log_scale()
                .with_key_points(y_labels)
                .with_light_points(y_grid),
        )
        .map_err(err)?;
    chart
        .configure_mesh()
        .x_desc("render time (s)")
        .y_desc("RMSE against the reference")
        .x_label_formatter(&|v| tick_label(*v))
        .y_label_formatter(&|v| tick_label(*v))
        .label_style(("sans-serif", 16))
        .axis_desc_style(("sans-serif", 18))
        .draw()
        .map_err(err)?;
    // Each line once, in order of first appearance (a denoised twin's rows interleave with
    // its line's).
    let mut names: Vec<&str> = Vec::new();
    for r in rows {
        if !names.contains(&r.line.as_str()) {
            names.push(&r.line);
        }
    }
    for (i, name) in names.iter().enumerate() {
        let color = Palette99::pick(i).to_rgba();
        let pts: Vec<(f64, f64)> = rows
            .iter()
            .filter(|r| r.line == *name && r.rmse > 0.0)
            .map(|r| (r.seconds, r.rmse))
            .collect();
        chart
            .draw_series(LineSeries::new(pts.clone(), color.stroke_width(3)))
            .map_err(err)?
            .label(*name)
            .legend(move |(x, y)| PathElement::new(vec![(x, y), (x + 24, y)], color.stroke_width(3)));
        chart
            .draw_series(pts.into_iter().map(|p| Circle::new(p, 4, color.filled())))
            .map_err(err)?;
    }
    chart
        .configure_series_labels()
        .label_font(("sans-serif", 18))
        .background_style(WHITE.mix(0.85))
        .border_style(BLACK)
        .draw()
        .map_err(err)?;
    Ok(())
}

/// Ticks of a log axis over [lo, hi]: the labelled ones (each decade's 1, 2, ..., 9 over up to
/// 1.5 decades, its 1, 2 and 5 over up to 4, its 1 beyond; halves as well below 2 labels) and
/// the grid lines (every 1, 2, ..., 9). Every value is the double nearest its decimal, m × 10^e,
/// so that no two ticks coincide or print alike.
pub fn log_ticks(lo: f64, hi: f64) -> (Vec<f64>, Vec<f64>) {
    if !(lo > 0.0 && hi > lo && hi.is_finite()) {
        return (Vec::new(), Vec::new());
    }
    let ticks = |mantissas: &[f64]| -> Vec<f64> {
        let mut out = Vec::new();
        for e in lo.log10().floor() as i32 - 1..=hi.log10().ceil() as i32 {
            for m in mantissas {
                let v: f64 = format!("{m}e{e}").parse().expect("a decimal number");
                if (lo..=hi).contains(&v) {
                    out.push(v);
                }
            }
        }
        out
    };
    let decades = (hi / lo).log10();
    let all: Vec<f64> = (1..=9).map(f64::from).collect();
    let labelled = if decades <= 1.5 {
        ticks(&all)
    } else if decades <= 4.0 {
        ticks(&[1.0, 2.0, 5.0])
    } else {
        ticks(&[1.0])
    };
    if labelled.len() >= 2 {
        return (labelled, ticks(&all));
    }
    let halves: Vec<f64> = (2..=19).map(|h| f64::from(h) / 2.0).collect();
    (ticks(&halves), ticks(&halves))
}

/// A tick's label: the shortest decimal that reads back as the tick (`0.1`, `2`, `10`).
pub fn tick_label(v: f64) -> String {
    format!("{v}")
}

#[cfg(test)]
mod tests {
    use super::*;
    use clap::Parser;

    /// `coordinator converge s.xml --reference r.exr --methods METHODS`'s lines.
    fn plan(methods: &str) -> anyhow::Result<Vec<(String, JobSettings)>> {
        let argv = [
            "coordinator",
            "converge",
            "s.xml",
            "--reference",
            "r.exr",
            "--methods",
            methods,
        ];
        let crate::cli::Command::Converge(args) = crate::cli::Cli::try_parse_from(argv)?.command else {
            panic!("not converge")
        };
        plan_lines(&args)
    }

    /// Every name the error message offers is taken, as the method it names.
    #[test]
    fn every_listed_method_is_taken() {
        for name in converge_methods() {
            let lines = plan(&name).unwrap();
            assert_eq!(lines.len(), 1, "{name}");
            let settings = &lines[0].1;
            let estimate = name
                .strip_prefix("sppm-")
                .map(|e| VolumeEstimate::from_str(e, false).unwrap());
            let method = if estimate.is_some() { "sppm" } else { name.as_str() };
            assert_eq!(
                settings.integrator.map(JobIntegrator::name),
                Some(method),
                "{name}"
            );
            assert_eq!(settings.volume_estimate, estimate, "{name}");
        }
        for bad in ["direct", "sppm-points", "bdpt"] {
            assert!(
                plan(bad).unwrap_err().to_string().contains("unknown method"),
                "{bad}"
            );
        }
    }

    #[test]
    fn log_ticks_are_distinct_and_label_distinctly() {
        for (lo, hi) in [
            (0.0073, 0.17),
            (0.2, 37.0),
            (0.01, 0.1),
            (1e-4, 10.0),
            (0.05, 0.09),
            (3.0, 3.5),
            (0.25 * 0.8, 30.0 * 1.25),
        ] {
            let (labelled, grid) = log_ticks(lo, hi);
            assert!(labelled.len() >= 2, "{lo}..{hi}: {labelled:?}");
            for ticks in [&labelled, &grid] {
                let labels: Vec<String> = ticks.iter().map(|&v| tick_label(v)).collect();
                let mut unique = labels.clone();
                unique.dedup();
                assert_eq!(unique, labels, "{lo}..{hi}");
                assert!(ticks.windows(2).all(|w| w[0] < w[1]), "{lo}..{hi}: {ticks:?}");
                assert!(
                    ticks.iter().all(|v| (lo..=hi).contains(v)),
                    "{lo}..{hi}: {ticks:?}"
                );
            }
        }
        let (labelled, _) = log_ticks(0.0073, 0.17);
        let labels: Vec<String> = labelled.iter().map(|&v| tick_label(v)).collect();
        assert_eq!(labels[..3], ["0.008", "0.009", "0.01"]);
        assert_eq!(labels.iter().filter(|l| *l == "0.1").count(), 1, "{labels:?}");
        assert_eq!(log_ticks(0.2, 37.0).0, [0.2, 0.5, 1.0, 2.0, 5.0, 10.0, 20.0]);
    }

    /// A chart like the README's convergence figure (RMSE from 0.009 to 0.12) labels every
    /// tick once: it used to print "0.1" twice, one over the other.
    #[test]
    fn the_chart_labels_each_tick_once() {
        register_font();
        let mut rows = Vec::new();
        for (line, scale) in [("path", 0.14), ("sppm", 0.11)] {
            let mut t = 0.25;
            while t < 30.0 {
                rows.push(Row {
                    line: line.into(),
                    seconds: t,
                    passes: 1,
                    rmse: scale * 0.42 / t.sqrt(),
                    worst_mean_error: 0.0,
                });
                // A denoised twin's rows interleave with its line's, as `--denoise` writes
                // them: each still has one legend entry (the check of repeated labels below).
                rows.push(Row {
                    line: format!("{line}+denoised"),
                    seconds: t * 1.05,
                    passes: 1,
                    rmse: scale * 0.2 / t.sqrt(),
                    worst_mean_error: 0.0,
                });
                t *= std::f64::consts::SQRT_2;
            }
        }
        let mut svg = String::new();
        {
            let root = SVGBackend::with_string(&mut svg, (1000, 680)).into_drawing_area();
            draw(&root, "test", &rows).unwrap();
            root.present().unwrap();
        }
        let texts: Vec<&str> = svg
            .split("<text")
            .skip(1)
            .map(|t| t[t.find('>').unwrap() + 1..t.find("</text>").unwrap()].trim())
            .collect();
        for label in ["0.1", "0.01", "1", "10", "path+denoised", "sppm"] {
            assert_eq!(
                texts.iter().filter(|t| **t == label).count(),
                1,
                "{label} in {texts:?}"
            );
        }
        let mut sorted = texts.clone();
        sorted.sort();
        sorted.dedup();
        assert_eq!(sorted.len(), texts.len(), "a label is repeated: {texts:?}");
    }
}
