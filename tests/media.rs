//! Participating media: both integrators against Mitsuba 3's `volpath`, exact attenuation
//! through an absorbing slab, the volumetric caustic that only SPPM renders, and the iteration
//! contract with volume photons.

use std::path::Path;
use std::sync::atomic::AtomicBool;

use photonfarm::integrator::sppm::{SppmSettings, VolumeEstimate};
use photonfarm::render::{Method, RenderSettings, Renderer};
use photonfarm_tests::{
    Comparison, channel_means, compare, load, noise_floor, reference, refs_dir, render_path, render_sppm,
    scenes_dir, sppm_settings,
};

fn report(what: &str, c: &Comparison) {
    eprintln!(
        "{what}: rmse {:.4}, mae {:.4}, means {:?} vs {:?}, worst mean error {:.2}%",
        c.mse.sqrt(),
        c.mae,
        c.mean,
        c.reference_mean,
        100.0 * c.worst_mean_error()
    );
}

/// `refs/fog.xml`: the camera in fog, a spot light, a sphere's volumetric shadow. Reference:
/// Mitsuba 3.9.1 volpath, 32768 spp at 64×64 (its halves' channel means agree to 0.7%).
#[test]
fn fog_path_tracer_matches_mitsuba_volpath() {
    let scene = load(&refs_dir().join("fog.xml"), &[("res", "64")]);
    let reference = reference("fog.exr");
    let few = compare(&render_path(&scene, 32, 1).image().unwrap(), &reference);
    let many = compare(&render_path(&scene, 512, 1).image().unwrap(), &reference);
    report("fog, path 32 spp", &few);
    report("fog, path 512 spp", &many);
    assert!(many.worst_mean_error() < 0.03, "{many:?}");
    // Light sampling a point-like light from inside the fog has infinite variance (∫ 1/d² dd
    // diverges at the light), so rare fireflies make the MSE erratic; the mean absolute error
    // still falls. docs/stability.md has the figures.
    assert!(
        many.mae < 0.5 * few.mae,
        "error must fall: {:.3e} then {:.3e}",
        few.mae,
        many.mae
    );
}

/// The volume estimates of SPPM against Mitsuba: the beam radiance estimate (the default), the
/// point estimate and photon beams. At equal iterations (the same photons) the beam's error
/// above the reference's own noise is lower than the point's; equal-time figures are in
/// docs/volumes.md.
#[test]
fn fog_sppm_matches_mitsuba_volpath() {
    let scene = load(&refs_dir().join("fog.xml"), &[("res", "64")]);
    let reference = reference("fog.exr");
    let floor = noise_floor("fog");
    let mut excess = Vec::new();
    for estimate in [
        VolumeEstimate::Beam,
        VolumeEstimate::Point,
        VolumeEstimate::PhotonBeams,
    ] {
        let settings = sppm_settings(&scene, 20_000).with_volume_estimate(estimate);
        // Photon beams keep 1 photon in 256 (79 beams an iteration here) and an iteration costs
        // a quarter of the beam estimate's: they get 4× the iterations.
        let (few_n, many_n) = match estimate {
            VolumeEstimate::PhotonBeams => (16, 192),
            _ => (4, 48),
        };
        let few = compare(
            &render_sppm(&scene, settings, few_n, 1).image().unwrap(),
            &reference,
        );
        let many = compare(
            &render_sppm(&scene, settings, many_n, 1).image().unwrap(),
            &reference,
        );
        report(&format!("fog, SPPM {estimate:?}, {few_n} iterations"), &few);
        report(&format!("fog, SPPM {estimate:?}, {many_n} iterations"), &many);
        assert!(many.worst_mean_error() < 0.03, "{estimate:?}: {many:?}");
        assert!(
            many.mse - floor < 0.5 * (few.mse - floor),
            "{estimate:?}: error must fall: {:.3e} then {:.3e}",
            few.mse,
            many.mse
        );
        excess.push(many.mse - floor);
    }
    eprintln!(
        "fog, MSE above the reference's floor: beam {:.3e}, point {:.3e} (48 iterations), photon beams {:.3e} (192)",
        excess[0], excess[1], excess[2]
    );
    assert!(
        excess[0] < 0.5 * excess[1],
        "beam {:.3e}, point {:.3e}",
        excess[0],
        excess[1]
    );
}

/// A camera looking at an emitter of radiance 1 through a non-scattering slab sees exp(−σt d).
#[test]
fn slab_attenuates_the_view_by_exp_minus_sigma_d() {
    let expect = (-1.0f64).exp();
    let scene = load(&scenes_dir().join("slab.xml"), &[]);
    let path = channel_means(&render_path(&scene, 1024, 1).image().unwrap())[0];
    let sppm = channel_means(
        &render_sppm(&scene, sppm_settings(&scene, 1000), 1024, 1)
            .image()
            .unwrap(),
    )[0];
    eprintln!("slab, emitter seen through it: path {path:.5}, SPPM {sppm:.5}, exp(-1) = {expect:.5}");
    // Each sample passes or not (Bernoulli): 262,144 samples give a standard error of 0.1%.
    assert!((path / expect - 1.0).abs() < 0.005, "{path}");
    assert!((sppm / expect - 1.0).abs() < 0.005, "{sppm}");
}

/// A vertical beam crossing the slab lights a floor: exactly exp(−σt d) of the light arrives
/// (light sampling through the medium and its boundaries), for both integrators.
#[test]
fn slab_attenuates_a_beam_by_exp_minus_sigma_d() {
    let floor = |sigma: &str, sppm: bool| {
        let scene = load(
            &scenes_dir().join("slab.xml"),
            &[("sigma", sigma), ("target", "0,-5,0"), ("emitter_radiance", "0")],
        );
        let img = if sppm {
            render_sppm(&scene, sppm_settings(&scene, 20_000), 2, 1)
        } else {
            render_path(&scene, 2, 1)
        };
        channel_means(&img.image().unwrap())[0]
    };
    for sppm in [false, true] {
        let (clear, one, two) = (floor("0", sppm), floor("1", sppm), floor("2", sppm));
        eprintln!("slab, beam on floor (sppm {sppm}): {clear:.6} {one:.6} {two:.6}");
        assert!(
            (clear / (1.5 / std::f64::consts::PI) - 1.0).abs() < 1e-4,
            "unattenuated: {clear}"
        );
        assert!(
            (one / clear / (-1.0f64).exp() - 1.0).abs() < 1e-4,
            "{}",
            one / clear
        );
        assert!(
            (two / clear / (-2.0f64).exp() - 1.0).abs() < 1e-4,
            "{}",
            two / clear
        );
    }
}

/// Behind the glass sphere the beam is focused into a volumetric caustic: SPPM renders it, the
/// path tracer cannot (its beam light is blocked by the glass, and BSDF sampling never finds a
/// collimated beam). Before the sphere both see the same beam.
#[test]
fn beam_through_glass_in_fog_makes_a_volumetric_caustic_with_sppm_only() {
    let path = Path::new(env!("CARGO_MANIFEST_DIR")).join("../scenes/beam-caustic.xml");
    let scene = load(&path, &[("width", "96"), ("height", "54")]);
    let sppm = render_sppm(&scene, sppm_settings(&scene, 100_000), 24, 1)
        .image()
        .unwrap();
    let pt = render_path(&scene, 96, 1).image().unwrap();
    // Mean red radiance over a block of columns in the beam's rows (the beam runs at
    // mid-height from the left; the sphere spans the middle columns).
    let block = |img: &[photonfarm::color::Rgb], x0: usize, x1: usize| {
        let (w, mut sum, mut n) = (96usize, 0.0f64, 0usize);
        for y in 14..26 {
            for x in x0..x1 {
                sum += img[y * w + x].x as f64;
                n += 1;
            }
        }
        sum / n as f64
    };
    let (before_sppm, before_path) = (block(&sppm, 2, 30), block(&pt, 2, 30));
    let (after_sppm, after_path) = (block(&sppm, 52, 75), block(&pt, 52, 75));
    eprintln!("beam before the sphere: SPPM {before_sppm:.4}, path {before_path:.4}");
    eprintln!("beam after the sphere (caustic): SPPM {after_sppm:.4}, path {after_path:.4}");
    assert!(
        (before_sppm / before_path - 1.0).abs() < 0.15,
        "the incoming beam should agree"
    );
    assert!(after_sppm > 3.0 * after_path, "SPPM should show the focused beam");
}

/// Volume photons keep the iteration contract with either estimate: split renders add up to the
/// same bytes.
#[test]
fn split_and_merge_is_bit_exact_in_fog() {
    let scene = load(&refs_dir().join("fog.xml"), &[("res", "24")]);
    for estimate in [
        VolumeEstimate::Beam,
        VolumeEstimate::Point,
        VolumeEstimate::PhotonBeams,
    ] {
        let settings = sppm_settings(&scene, 3_000).with_volume_estimate(estimate);
        let radii = settings.radii(0..6);
        let method = RenderSettings {
            seed: 5,
            method: Method::Sppm(settings),
        };
        let render = |threads: usize, a: u64, b: u64| {
            let pool = rayon::ThreadPoolBuilder::new()
                .num_threads(threads)
                .build()
                .unwrap();
            let (r, never) = (&radii[a as usize..b as usize], AtomicBool::new(false));
            pool.install(|| Renderer::new(&scene, &method).render(a..b, Some(r), &never).sum)
        };
        let whole = render(2, 0, 6);
        let mut merged = render(1, 4, 6);
        merged.add(&render(2, 0, 4)).unwrap();
        assert_eq!(whole, merged, "{estimate:?}");
        assert!(whole.sums.iter().any(|s| s[0] > 0));
    }
}

/// Where a case of [`volume_estimates_in_thin_dense_and_glass_seen_media`] takes its unbiased
/// channel means from.
#[derive(Clone, Copy)]
enum Unbiased {
    /// Mitsuba's volpath reference, `refs/fog.exr`: a point-like light inside the fog gives a
    /// path tracer rare fireflies, which move the means of 8192 spp at 32×32 by up to 2%.
    MitsubaFog,
    /// Our path tracer at 8192 spp.
    PathTracer,
    /// The point estimate with the same radius, over four seeds: one point render is noisy
    /// enough (variance 2.6e-3 a pixel through glass) to move its own means by a few percent.
    PointEstimate,
}

/// The mean of channel means.
fn mean_of(means: &[[f64; 3]]) -> [f64; 3] {
    [0, 1, 2].map(|c| means.iter().map(|m| m[c]).sum::<f64>() / means.len() as f64)
}

/// Where each volume estimate struggles (docs/stability.md): a thin medium (the point estimate
/// rarely collides), a light inside the medium (fog.xml's spot light), a dense medium and a
/// medium seen through glass (the beam caustic). Each estimate renders with its defaults; its
/// noise is the mean squared difference of two renders with different seeds, over two (its
/// variance). The beam estimate must be the less noisy, and its channel means within 3% of an
/// unbiased one ([`Unbiased`]): Mitsuba's reference or the path tracer's in fog, and through
/// glass (which the path tracer cannot render) the point estimate's with the same radius, whose
/// expectation the beam's equals by construction. In the dense medium few photons reach what
/// the camera sees (the light is 10 mean free paths away), so every pixel shares the same few
/// photons and the means of both estimates move together by 20–30% from seed to seed: only the
/// noise is compared there.
#[test]
fn volume_estimates_in_thin_dense_and_glass_seen_media() {
    let fog = refs_dir().join("fog.xml");
    let caustic = Path::new(env!("CARGO_MANIFEST_DIR")).join("../scenes/beam-caustic.xml");
    // (name, scene, defines, iterations, whether the means are checked, against what)
    type Case<'a> = (&'a str, &'a Path, &'a [(&'a str, &'a str)], u64, bool, Unbiased);
    let cases: [Case; 4] = [
        (
            "thin fog (density 0.05)",
            &fog,
            &[("res", "32"), ("density", "0.05")],
            16,
            true,
            Unbiased::PathTracer,
        ),
        (
            "fog (light inside)",
            &fog,
            &[("res", "32")],
            16,
            true,
            Unbiased::MitsubaFog,
        ),
        (
            "dense fog (density 8)",
            &fog,
            &[("res", "32"), ("density", "8")],
            16,
            false,
            Unbiased::PathTracer,
        ),
        (
            "beam through glass",
            &caustic,
            &[("width", "48"), ("height", "27")],
            8,
            true,
            Unbiased::PointEstimate,
        ),
    ];
    for (name, path, defines, iterations, check_means, source) in cases {
        let scene = load(path, defines);
        let render = |settings, n, seed| render_sppm(&scene, settings, n, seed).image().unwrap();
        let mut noise = Vec::new();
        let mut means = Vec::new();
        for estimate in [
            VolumeEstimate::Beam,
            VolumeEstimate::Point,
            VolumeEstimate::PhotonBeams,
        ] {
            let settings = sppm_settings(&scene, 20_000).with_volume_estimate(estimate);
            // Photon beams keep 1 photon in 256, so an iteration costs them about a quarter of
            // the beam's: they get 4× the iterations. And four seeds: their means have a heavy
            // right tail (with the light inside the fog, most renders of 64 iterations fall 1–3%
            // below the reference's mean and a few far above), so two renders' means can miss
            // by more than 3% while the estimate converges (0.75% at 192 iterations).
            let (n, seeds) = match estimate {
                VolumeEstimate::PhotonBeams => (4 * iterations, 1..5),
                _ => (iterations, 1..3),
            };
            let images: Vec<_> = seeds.map(|seed| render(settings, n, seed)).collect();
            noise.push(compare(&images[0], &images[1]).mse / 2.0);
            let image_means: Vec<_> = images.iter().map(|i| channel_means(i)).collect();
            means.push(mean_of(&image_means));
        }
        let unbiased = match source {
            Unbiased::MitsubaFog => channel_means(&reference("fog.exr")),
            Unbiased::PathTracer => channel_means(&render_path(&scene, 8192, 3).image().unwrap()),
            Unbiased::PointEstimate => {
                // The beam's radius, not the point estimate's default.
                let point = SppmSettings {
                    volume_estimate: VolumeEstimate::Point,
                    ..sppm_settings(&scene, 20_000)
                };
                let m: Vec<[f64; 3]> = (3..7)
                    .map(|seed| channel_means(&render(point, iterations, seed)))
                    .collect();
                mean_of(&m)
            }
        };
        let error = |m: &[f64; 3]| {
            (0..3)
                .map(|c| (m[c] / unbiased[c] - 1.0).abs())
                .fold(0.0, f64::max)
        };
        eprintln!(
            "{name}: variance beam {:.3e}, point {:.3e} (ratio {:.1}), photon beams {:.3e}; worst channel mean error beam {:.2}%, point {:.2}%, photon beams {:.2}%",
            noise[0],
            noise[1],
            noise[1] / noise[0],
            noise[2],
            100.0 * error(&means[0]),
            100.0 * error(&means[1]),
            100.0 * error(&means[2]),
        );
        // Photon beams' variance, at other iterations, is not compared; their means are.
        for (estimate, m) in [("beam", &means[0]), ("photon beams", &means[2])] {
            assert!(
                !check_means || error(m) < 0.03,
                "{name}: {estimate} means {m:?} vs {unbiased:?}"
            );
        }
        assert!(
            noise[0] < noise[1],
            "{name}: beam {:.3e}, point {:.3e}",
            noise[0],
            noise[1]
        );
    }
}
