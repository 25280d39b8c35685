//! `coordinator render --denoise` and `--aovs` as a user runs them, against Mitsuba's reference:
//! a real process, real files, the real Open Image Denoise. Only in builds with the `denoise`
//! feature (the README's test command enables it).
#![cfg(feature = "denoise")]

mod support;

use std::path::{Path, PathBuf};
use std::process::Command;
use std::time::{Duration, Instant};

use photonfarm::color::Rgb;
use photonfarm::film::read_image;

fn refs() -> PathBuf {
    Path::new(env!("CARGO_MANIFEST_DIR")).join("../tests/refs")
}

fn render(args: &[&str]) -> std::process::Output {
    let out = Command::new(env!("CARGO_BIN_EXE_coordinator"))
        .arg("render")
        .args(args)
        .output()
        .expect("the binary runs");
    eprintln!("{}", String::from_utf8_lossy(&out.stderr));
    out
}

fn render_owned(args: &[String]) -> std::process::Output {
    render(&args.iter().map(String::as_str).collect::<Vec<_>>())
}

fn rmse(a: &[Rgb], b: &[Rgb]) -> f64 {
    let sum: f64 = a
        .iter()
        .zip(b)
        .map(|(p, q)| (*p - *q).length_squared() as f64)
        .sum();
    (sum / (3 * a.len()) as f64).sqrt()
}

/// A channel group (`albedo`, `normal`) of an EXR, as RGB pixels row by row.
fn layer(path: &Path, prefix: &str) -> Vec<Rgb> {
    use exr::prelude::*;
    let image = read_all_flat_layers_from_file(path).unwrap();
    let channels = &image.layer_data[0].channel_data.list;
    let channel = |c: &str| {
        let name = format!("{prefix}.{c}");
        let found = channels.iter().find(|ch| ch.name.to_string() == name);
        found
            .unwrap_or_else(|| panic!("no channel {name}"))
            .sample_data
            .values_as_f32()
            .collect::<Vec<f32>>()
    };
    let (r, g, b) = (channel("R"), channel("G"), channel("B"));
    (0..r.len()).map(|i| Rgb::new(r[i], g[i], b[i])).collect()
}

/// The done-when's measure: cbox at 64 passes, denoised, against Mitsuba's 16384-spp
/// reference. The raw image keeps its bytes' pixels, and the EXR carries albedo and normal.
#[test]
fn denoising_cbox_at_64_passes_more_than_halves_the_error() {
    let dir = tempfile::tempdir().unwrap();
    let scene = refs().join("cbox.xml");
    let (plain, with) = (dir.path().join("plain.exr"), dir.path().join("cbox.exr"));
    for (out, extra) in [(&plain, None), (&with, Some("--denoise"))] {
        let mut args = vec![
            scene.to_str().unwrap(),
            "--spp",
            "64",
            "--out",
            out.to_str().unwrap(),
        ];
        args.extend(extra);
        assert!(render(&args).status.success());
    }
    let (_, _, reference) = read_image(&refs().join("cbox.exr")).unwrap();
    let (_, _, raw) = read_image(&plain).unwrap();
    // The raw image is the same with features summed beside it.
    assert_eq!(read_image(&with).unwrap().2, raw);
    let denoised_path = dir.path().join("cbox.denoised.exr");
    let (w, h, denoised) = read_image(&denoised_path).unwrap();
    assert_eq!((w, h), (256, 256));

    let (e_raw, e_denoised) = (rmse(&raw, &reference), rmse(&denoised, &reference));
    // Away from the light (two pixels around it), where the denoiser does its work.
    let light: Vec<bool> = reference.iter().map(|p| p.max_element() > 2.0).collect();
    let near_light = |i: usize| {
        let (x, y) = ((i % 256) as i64, (i / 256) as i64);
        (-2..=2).any(|dy| {
            (-2..=2).any(|dx| {
                let (u, v) = (x + dx, y + dy);
                (0..256).contains(&u) && (0..256).contains(&v) && light[(v * 256 + u) as usize]
            })
        })
    };
    let far: Vec<usize> = (0..raw.len()).filter(|&i| !near_light(i)).collect();
    let pick = |img: &[Rgb]| far.iter().map(|&i| img[i]).collect::<Vec<_>>();
    let (f_raw, f_denoised) = (
        rmse(&pick(&raw), &pick(&reference)),
        rmse(&pick(&denoised), &pick(&reference)),
    );
    eprintln!(
        "RMSE raw {e_raw:.5}, denoised {e_denoised:.5} ({:.2}x); away from the light raw \
         {f_raw:.5}, denoised {f_denoised:.5} ({:.2}x)",
        e_denoised / e_raw,
        f_denoised / f_raw
    );
    // Measured 0.21x away from the light and 0.24x in all (0.57x before the light's outline
    // was added back from the dense emission rays: docs/denoising.md). The figure is
    // half.
    assert!(f_denoised < 0.35 * f_raw);
    assert!(e_denoised < 0.5 * e_raw);

    // The features: the red wall's reflectance exactly, its normal facing +x; the light's
    // albedo is its radiance clamped (one).
    let (albedo, normal) = (layer(&with, "albedo"), layer(&with, "normal"));
    let red_wall = 128 * 256 + 12;
    // (to the film's fixed point, 2^-24)
    let red = Rgb::new(0.570068, 0.0430135, 0.0443706);
    assert!(
        (albedo[red_wall] - red).abs().max_element() < 1e-7,
        "{}",
        albedo[red_wall]
    );
    assert!(
        (normal[red_wall] - Rgb::X).length() < 1e-5,
        "{}",
        normal[red_wall]
    );
    let light_centre = (0..raw.len())
        .find(|&i| light[i] && light[i + 2] && light[i + 512])
        .unwrap()
        + 257;
    assert_eq!(albedo[light_centre], Rgb::ONE);
    assert!(
        albedo
            .iter()
            .all(|a| a.min_element() >= 0.0 && a.max_element() <= 1.0)
    );
    assert!(normal.iter().all(|n| n.length() <= 1.0 + 1e-5));
}

/// Features are saved with the sums: an interrupted `--aovs` render resumed gives the bytes
/// (image and channels) of an uninterrupted one. `--aovs` refuses a PNG, which has no channels
/// for them.
#[test]
fn an_interrupted_render_with_features_resumes_to_the_same_bytes() {
    let dir = tempfile::tempdir().unwrap();
    let scene = refs().join("cbox.xml");
    let (whole, parts) = (dir.path().join("whole.exr"), dir.path().join("parts.exr"));
    let args = |out: &Path| -> Vec<String> {
        [
            scene.to_str().unwrap(),
            "--spp",
            "256",
            "-D",
            "res=96",
            "--aovs",
            "--out",
            out.to_str().unwrap(),
        ]
        .map(String::from)
        .to_vec()
    };
    assert!(render_owned(&args(&whole)).status.success());
    let mut first = args(&parts);
    first.extend(["--time-limit".into(), "0.3".into()]);
    assert!(render_owned(&first).status.success());
    let sums = dir.path().join("parts.exr.resume");
    assert!(sums.exists(), "the first run was to stop early");
    assert!(dir.path().join("parts.exr.resume.albedo").exists());
    let mut resumed = args(&parts);
    resumed.push("--resume".into());
    assert!(render_owned(&resumed).status.success());
    assert_eq!(std::fs::read(&whole).unwrap(), std::fs::read(&parts).unwrap());
    assert!(!sums.exists() && !dir.path().join("parts.exr.resume.normal").exists());

    let png = dir.path().join("x.png");
    let o = render(&[
        scene.to_str().unwrap(),
        "--spp",
        "1",
        "--aovs",
        "--out",
        png.to_str().unwrap(),
    ]);
    assert!(!o.status.success());
    assert!(String::from_utf8_lossy(&o.stderr).contains("only EXR files hold the albedo and normal"));
}

/// `converge --denoise` gives each method a denoised twin, rendered apart with the features (so
/// the raw line keeps the speed of a render without them), whose time includes the features and
/// the denoising, against Mitsuba's reference.
#[test]
fn converge_draws_a_denoised_twin_of_each_line() {
    let dir = tempfile::tempdir().unwrap();
    let scene = refs().join("cbox.xml");
    let out = dir.path().join("conv");
    let o = Command::new(env!("CARGO_BIN_EXE_coordinator"))
        .args(["converge", scene.to_str().unwrap(), "--reference"])
        .arg(refs().join("cbox.exr"))
        .args(["--methods", "path", "--time-limit", "2", "--denoise", "--out-dir"])
        .arg(&out)
        .output()
        .unwrap();
    assert!(o.status.success(), "{}", String::from_utf8_lossy(&o.stderr));
    let csv = std::fs::read_to_string(out.join("convergence.csv")).unwrap();
    let rows: Vec<Vec<&str>> = csv.lines().skip(1).map(|l| l.split(',').collect()).collect();
    let line = |name: &str| rows.iter().filter(|r| r[0] == name).cloned().collect::<Vec<_>>();
    let (raw, denoised) = (line("path"), line("path+denoised"));
    assert!(raw.len() >= 3 && denoised.len() >= 3, "{csv}");
    let seconds = |l: &[Vec<&str>]| l.iter().map(|r| r[1].parse::<f64>().unwrap()).collect::<Vec<_>>();
    for l in [&raw, &denoised] {
        assert!(seconds(l).windows(2).all(|w| w[0] < w[1]), "{csv}");
        assert!(
            *seconds(l).last().unwrap() >= 2.0,
            "both run to the budget: {csv}"
        );
    }
    let last_rmse = |l: &[Vec<&str>]| l.last().unwrap()[3].parse::<f64>().unwrap();
    assert!(last_rmse(&denoised) < 0.8 * last_rmse(&raw), "{csv}");
    let svg = std::fs::read_to_string(out.join("convergence.svg")).unwrap();
    assert!(svg.contains("path+denoised"));
}

/// The farm's done-when: a `--denoise` job on two workers, with the coordinator SIGKILLed
/// mid-job and restarted, gives the EXR of `coordinator render` byte for byte: the raw image and
/// its albedo and normal channels. Its denoised preview is served and fetched beside it.
#[test]
fn a_farm_job_with_features_survives_a_restart_and_gives_the_local_bytes() {
    use support::{coordinator_bin, worker};
    let dir = tempfile::tempdir().unwrap();
    // SPPM on cbox-spheres with Mitsuba's default (Gaussian) filter: the features are splatted
    // and weighted like the image, and merged as exactly.
    let job = [
        "--integrator",
        "sppm",
        "--iterations",
        "40",
        "--photons",
        "60000",
        "--seed",
        "3",
        "--checkpoint-every",
        "16",
        "-D",
        "res=48",
        "-D",
        "filter=gaussian",
        "--denoise",
    ];
    let scene = support::cbox_spheres();
    let local = dir.path().join("local.exr");
    let mut args = vec![scene.to_str().unwrap(), "--out", local.to_str().unwrap()];
    args.extend(job);
    assert!(render(&args).status.success());

    let data = dir.path().join("data");
    let bind = support::fixed_loopback_address();
    let flags = ["--batch-seconds", "0.3", "--lease-timeout", "2"];
    let (mut coordinator, url) = support::serve(&data, &bind, &flags, &[]);
    let _w1 = worker(&url, "w1", dir.path());
    let _w2 = worker(&url, "w2", dir.path());
    let cli = |args: &[&str]| {
        let o = Command::new(coordinator_bin()).args(args).output().unwrap();
        assert!(
            o.status.success(),
            "{}\n{}",
            String::from_utf8_lossy(&o.stderr),
            support::logs(dir.path())
        );
        String::from_utf8_lossy(&o.stdout).trim().to_string()
    };
    let mut submit = vec!["submit", "--to", &url, scene.to_str().unwrap()];
    submit.extend(job);
    let id = cli(&submit);
    let done = |url: &str| -> u64 {
        let o = Command::new(coordinator_bin())
            .args(["status", &id, "--to", url])
            .output()
            .unwrap();
        let line = String::from_utf8_lossy(&o.stdout).to_string();
        line.split_whitespace()
            .find_map(|w| w.split_once('/').and_then(|(d, _)| d.parse().ok()))
            .unwrap_or(0)
    };
    let start = Instant::now();
    while done(&url) < 17 {
        assert!(
            start.elapsed() < Duration::from_secs(120),
            "no passes arrived\n{}",
            support::logs(dir.path())
        );
        std::thread::sleep(Duration::from_millis(50));
    }
    coordinator.sigkill();
    let (_coordinator, url2) = support::serve(&data, &bind, &flags, &[]);
    assert_eq!(url, url2);
    let farm = dir.path().join("farm.exr");
    cli(&[
        "wait",
        &id,
        "--to",
        &url,
        "--out",
        farm.to_str().unwrap(),
        "--denoised",
        "--timeout",
        "300",
    ]);
    assert!(
        std::fs::read(&farm).unwrap() == std::fs::read(&local).unwrap(),
        "the farm's EXR (image, albedo, normal) differs from the local render's"
    );
    let (w, h, denoised) = read_image(&dir.path().join("farm.denoised.exr")).unwrap();
    assert_eq!((w, h), (48, 48));
    assert_ne!(denoised, read_image(&farm).unwrap().2);
    // A job without --denoise has no preview to serve.
    let plain = cli(&[
        "submit",
        "--to",
        &url,
        scene.to_str().unwrap(),
        "--spp",
        "2",
        "-D",
        "res=8",
    ]);
    cli(&["wait", &plain, "--to", &url, "--timeout", "300"]);
    let o = Command::new(coordinator_bin())
        .args(["fetch", &plain, "--to", &url, "--out"])
        .arg(dir.path().join("p.exr"))
        .arg("--denoised")
        .output()
        .unwrap();
    assert!(!o.status.success());
}
