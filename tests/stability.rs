//! Where methods fail or struggle (docs/stability.md reports each case with these figures).

use photonfarm::integrator::path::PathSettings;
use photonfarm::render::Method;
use photonfarm::scene::Scene;
use photonfarm_tests::{
    channel_means, compare, load, reference, refs_dir, render_path, render_sppm, render_with, scenes_dir,
    sppm_settings,
};

fn stability(name: &str) -> std::path::PathBuf {
    scenes_dir().join("stability").join(name)
}

/// A spot light's caustic, seen directly and in a mirror: the path tracer's error stays at the
/// level of the missing caustic, the hybrid's at the level of the mirrored one, while SPPM's
/// falls. Reference: SPPM, 4096 iterations of 50,000 photons, another seed (no independent
/// renderer here renders these paths: Mitsuba 3's path tracers miss them like ours, and it has
/// no photon mapper).
#[test]
fn mirrored_caustic_converges_with_sppm_only() {
    let scene = load(&stability("mirrored-caustic.xml"), &[]);
    let reference = reference("mirrored-caustic.exr");
    let settings = sppm_settings(&scene, 20_000);
    let sppm_few = compare(&render_sppm(&scene, settings, 16, 1).image().unwrap(), &reference);
    let sppm_many = compare(
        &render_sppm(&scene, settings, 256, 1).image().unwrap(),
        &reference,
    );
    let path_few = compare(&render_path(&scene, 64, 1).image().unwrap(), &reference);
    let path_many = compare(&render_path(&scene, 1024, 1).image().unwrap(), &reference);
    eprintln!(
        "mirrored caustic RMSE: SPPM {:.4} (16 it.) -> {:.4} (256 it.); path {:.4} (64 spp) -> {:.4} (1024 spp)",
        sppm_few.mse.sqrt(),
        sppm_many.mse.sqrt(),
        path_few.mse.sqrt(),
        path_many.mse.sqrt()
    );
    eprintln!(
        "mirrored caustic worst channel mean error: SPPM {:.2}%, path {:.2}%",
        100.0 * sppm_many.worst_mean_error(),
        100.0 * path_many.worst_mean_error()
    );
    assert!(sppm_many.mse < 0.35 * sppm_few.mse, "SPPM must converge");
    // 16 times the samples would cut a converging estimator's RMSE by 4; the path tracer's
    // barely moves, because what it misses is bias, not noise.
    assert!(
        path_many.mse > 0.5 * path_few.mse,
        "the path tracer should not converge here"
    );
    assert!(path_many.mse > 5.0 * sppm_many.mse);
    assert!(path_many.worst_mean_error() > 0.05 && sppm_many.worst_mean_error() < 0.02);
    // The hybrid's light paths render the caustic seen directly, and neither side the one in
    // the mirror (light → glass → floor → mirror → camera).
    let hybrid = |passes| {
        let method = Method::Hybrid(PathSettings::from_scene(&scene));
        compare(
            &render_with(&scene, method, passes, 1).image().unwrap(),
            &reference,
        )
    };
    let (hybrid_few, hybrid_many) = (hybrid(64), hybrid(1024));
    eprintln!(
        "mirrored caustic, hybrid: RMSE {:.4} (64 passes) -> {:.4} (1024), worst channel mean error {:.2}%",
        hybrid_few.mse.sqrt(),
        hybrid_many.mse.sqrt(),
        100.0 * hybrid_many.worst_mean_error()
    );
    assert!(
        hybrid_many.mse > 0.5 * hybrid_few.mse,
        "the hybrid should not converge here"
    );
    assert!(hybrid_many.mse < 0.5 * path_many.mse && hybrid_many.mse > 2.0 * sppm_many.mse);
}

/// Glossy surfaces lit by a caustic (from an area light, which the path tracer can find): both
/// methods agree on the energy and stay finite; the figures show SPPM's blur against path
/// tracing's noise.
#[test]
fn glossy_surfaces_lit_by_a_caustic() {
    let scene = load(&stability("glossy-caustic.xml"), &[]);
    let sppm = render_sppm(&scene, sppm_settings(&scene, 40_000), 128, 1);
    let path = render_path(&scene, 512, 1);
    assert_eq!(sppm.nonfinite + path.nonfinite, 0);
    let (a, b) = (sppm.image().unwrap(), path.image().unwrap());
    let (ma, mb) = (channel_means(&a), channel_means(&b));
    let c = compare(&a, &b);
    eprintln!(
        "glossy caustic: SPPM means {ma:?}, path means {mb:?}, RMSE between them {:.4}",
        c.mse.sqrt()
    );
    for ch in 0..3 {
        assert!(
            (ma[ch] / mb[ch] - 1.0).abs() < 0.05,
            "energy differs: {ma:?} vs {mb:?}"
        );
    }
}

/// Photons on a thin two-sided wall must not leak to its other side, however large the radius.
#[test]
fn thin_wall_does_not_leak_photons() {
    for radius in ["0.001", "0.5"] {
        let scene = load(&stability("thin-wall.xml"), &[("radius", radius)]);
        let img = render_sppm(&scene, sppm_settings(&scene, 20_000), 8, 1)
            .image()
            .unwrap();
        let worst = img.iter().map(|p| p.max_element()).fold(0.0f32, f32::max);
        eprintln!("thin wall, radius {radius}: brightest pixel below the wall {worst}");
        assert_eq!(worst, 0.0, "light leaked through the wall at radius {radius}");
    }
}

/// Initial radius far too small (few photons found: noise) or far too large (blur: bias), and
/// alpha near 0 and near 1: every setting stays finite and keeps its energy; the errors say
/// what each costs.
#[test]
fn extreme_radius_and_alpha() {
    let scene = load(&refs_dir().join("cbox.xml"), &[("res", "64")]);
    let reference: Vec<_> = downsample(&reference("cbox.exr"), 256, 4);
    let base = sppm_settings(&scene, 20_000);
    let run = |f: &dyn Fn(&mut photonfarm::integrator::sppm::SppmSettings), n: u64| {
        let mut s = base;
        f(&mut s);
        let film = render_sppm(&scene, s, n, 1);
        assert_eq!(film.nonfinite, 0);
        compare(&film.image().unwrap(), &reference)
    };
    let default = run(&|_| {}, 32);
    let tiny = run(&|s| s.initial_radius *= 0.02, 32);
    let huge = run(&|s| s.initial_radius *= 30.0, 32);
    let report = |name: &str, c: &photonfarm_tests::Comparison| {
        eprintln!(
            "cbox 64x64, 32 iterations, {name}: RMSE {:.4}, worst mean error {:.2}%",
            c.mse.sqrt(),
            100.0 * c.worst_mean_error()
        );
    };
    report("default radius", &default);
    report("radius x0.02", &tiny);
    report("radius x30", &huge);
    assert!(tiny.mse > 2.0 * default.mse, "a tiny radius should be noisy");
    // A huge radius blurs: light leaks from bright walls into dark corners and across the
    // image's edges, which shows in the channel means rather than in early noise.
    assert!(
        huge.worst_mean_error() > 2.0 * default.worst_mean_error(),
        "a huge radius should be biased"
    );
    assert!(
        huge.worst_mean_error() < 0.1,
        "blur moves energy around but keeps most of it"
    );
    for alpha in [0.02, 0.98] {
        let few = run(&|s| s.alpha = alpha, 8);
        let many = run(&|s| s.alpha = alpha, 64);
        report(&format!("alpha {alpha}, 8 it."), &few);
        report(&format!("alpha {alpha}, 64 it."), &many);
        assert!(many.mse < few.mse, "alpha {alpha} must still converge");
    }
}

fn downsample(img: &[photonfarm::color::Rgb], w: usize, f: usize) -> Vec<photonfarm::color::Rgb> {
    let (ow, oh) = (w / f, img.len() / w / f);
    let mut out = vec![photonfarm::color::Rgb::ZERO; ow * oh];
    for y in 0..oh {
        for x in 0..ow {
            let mut s = photonfarm::color::Rgb::ZERO;
            for dy in 0..f {
                for dx in 0..f {
                    s += img[(y * f + dy) * w + x * f + dx];
                }
            }
            out[y * ow + x] = s / (f * f) as f32;
        }
    }
    out
}

/// Scenes with no light, or with every light enclosed: a clear message, not a silent black image.
#[test]
fn no_light_and_enclosed_lights_are_reported() {
    let none = Scene::load(&stability("no-light.xml"), &[]).unwrap();
    assert!(
        none.warnings.iter().any(|w| w.contains("no light source")),
        "{:?}",
        none.warnings
    );
    let coordinator = std::path::Path::new(env!("CARGO_MANIFEST_DIR")).join("../target/release/coordinator");
    if coordinator.exists() {
        let dir = tempfile::tempdir().unwrap();
        for scene in ["no-light.xml", "enclosed-light.xml"] {
            let o = std::process::Command::new(&coordinator)
                .arg("render")
                .arg(stability(scene))
                .args(["--spp", "2", "--out"])
                .arg(dir.path().join("x.exr"))
                .output()
                .unwrap();
            let err = String::from_utf8_lossy(&o.stderr);
            eprintln!("{scene}: {err}");
            assert!(o.status.success());
            assert!(
                err.contains("no light source") || err.contains("the image is black"),
                "{err}"
            );
        }
    }
    let enclosed = load(&stability("enclosed-light.xml"), &[]);
    let img = render_path(&enclosed, 4, 1).image().unwrap();
    assert!(img.iter().all(|p| *p == photonfarm::color::Rgb::ZERO));
}

/// The same Cornell box at 1e-3 and 1e4 times its size renders the same image with both
/// methods: ray offsets and the default SPPM radius follow the scale.
#[test]
fn very_small_and_very_large_scenes() {
    let text = std::fs::read_to_string(refs_dir().join("cbox.xml")).unwrap();
    let at_scale = |s: f64| {
        // Scale the whole scene: every to_world transform ends with a uniform scale.
        let scaled = text.replace("</transform>", &format!("<scale value=\"{s}\"/></transform>"));
        Scene::from_str(
            &scaled,
            &refs_dir().join("cbox.xml"),
            &[("res".into(), "48".into())],
        )
        .unwrap()
    };
    let unit = at_scale(1.0);
    let unit_path = channel_means(&render_path(&unit, 64, 1).image().unwrap());
    let unit_sppm = channel_means(
        &render_sppm(&unit, sppm_settings(&unit, 20_000), 32, 1)
            .image()
            .unwrap(),
    );
    let r1 = sppm_settings(&unit, 1).initial_radius;
    for s in [1e-3, 1e4] {
        let scene = at_scale(s);
        let r = sppm_settings(&scene, 1).initial_radius;
        let path = channel_means(&render_path(&scene, 64, 1).image().unwrap());
        let sppm = channel_means(
            &render_sppm(&scene, sppm_settings(&scene, 20_000), 32, 1)
                .image()
                .unwrap(),
        );
        eprintln!(
            "cbox at scale {s}: default radius {r:.4e} (unit: {r1:.4e}); path means {path:?}, SPPM means {sppm:?}"
        );
        // The median of 256 hit distances can step to a neighbouring sample at another scale.
        assert!(
            ((r / r1) as f64 / s - 1.0).abs() < 0.1,
            "the default radius follows the scale"
        );
        for c in 0..3 {
            assert!(
                (path[c] / unit_path[c] - 1.0).abs() < 0.02,
                "path at scale {s}: {path:?} vs {unit_path:?}"
            );
            assert!(
                (sppm[c] / unit_sppm[c] - 1.0).abs() < 0.02,
                "SPPM at scale {s}: {sppm:?} vs {unit_sppm:?}"
            );
        }
    }
}

/// Degenerate geometry never puts NaN or infinity in the image.
#[test]
fn degenerate_geometry_stays_finite() {
    let scene = load(&stability("degenerate.xml"), &[]);
    let path = render_path(&scene, 64, 1);
    let sppm = render_sppm(&scene, sppm_settings(&scene, 5_000), 16, 1);
    eprintln!(
        "degenerate geometry: {} and {} non-finite samples (path, SPPM), all left out and counted",
        path.nonfinite, sppm.nonfinite
    );
    for film in [&path, &sppm] {
        assert!(film.image().unwrap().iter().all(|p| p.is_finite()));
    }
    assert!(channel_means(&path.image().unwrap())[0] > 0.0);
}
