//! Helpers shared by the accuracy tests: rendering a scene file and comparing images the way
//! `shared/scenes-ref/README.md` prescribes (MSE over pixels and channels, and channel means).

use std::path::{Path, PathBuf};

use photonfarm::color::Rgb;
use photonfarm::film::{FilmSum, read_image};
use photonfarm::integrator::path::PathSettings;
use photonfarm::integrator::sppm::{SppmSettings, VolumeEstimate};
use photonfarm::job::JobSettings;
use photonfarm::render::{Method, RenderSettings, Renderer};
use photonfarm::scene::Scene;

/// The folder of checked-in references and test scenes.
pub fn refs_dir() -> PathBuf {
    Path::new(env!("CARGO_MANIFEST_DIR")).join("refs")
}

/// The folder of small test scenes.
pub fn scenes_dir() -> PathBuf {
    Path::new(env!("CARGO_MANIFEST_DIR")).join("scenes")
}

/// Errors of an image against a reference.
#[derive(Clone, Copy, Debug)]
pub struct Comparison {
    /// Mean squared error over all pixels and the three channels.
    pub mse: f64,
    /// Mean absolute error: unlike the MSE it converges for estimators whose variance is
    /// infinite (light sampling of a point light from inside a medium).
    pub mae: f64,
    /// Channel means of the image.
    pub mean: [f64; 3],
    /// Channel means of the reference.
    pub reference_mean: [f64; 3],
}

impl Comparison {
    /// The largest relative difference of a channel mean.
    pub fn worst_mean_error(&self) -> f64 {
        (0..3)
            .map(|c| (self.mean[c] - self.reference_mean[c]).abs() / self.reference_mean[c])
            .fold(0.0, f64::max)
    }
}

/// Channel means.
pub fn channel_means(img: &[Rgb]) -> [f64; 3] {
    let mut m = [0.0f64; 3];
    for p in img {
        for (c, mc) in m.iter_mut().enumerate() {
            *mc += p[c] as f64;
        }
    }
    m.map(|v| v / img.len() as f64)
}

/// Compares two images of the same size.
pub fn compare(img: &[Rgb], reference: &[Rgb]) -> Comparison {
    assert_eq!(img.len(), reference.len(), "images differ in size");
    let (mut se, mut ae) = (0.0f64, 0.0f64);
    for (a, b) in img.iter().zip(reference) {
        let d = *a - *b;
        se += (d.x as f64).powi(2) + (d.y as f64).powi(2) + (d.z as f64).powi(2);
        ae += d.x.abs() as f64 + d.y.abs() as f64 + d.z.abs() as f64;
    }
    Comparison {
        mse: se / (3 * img.len()) as f64,
        mae: ae / (3 * img.len()) as f64,
        mean: channel_means(img),
        reference_mean: channel_means(reference),
    }
}

/// Loads a scene, failing the test with the loader's message.
pub fn load(path: &Path, defines: &[(&str, &str)]) -> Scene {
    let defines: Vec<(String, String)> = defines
        .iter()
        .map(|(k, v)| (k.to_string(), v.to_string()))
        .collect();
    Scene::load(path, &defines).unwrap_or_else(|e| panic!("{e}"))
}

/// Renders passes [0, passes) with `method`.
pub fn render_with(scene: &Scene, method: Method, passes: u64, seed: u64) -> FilmSum {
    Renderer::new(scene, &RenderSettings { seed, method }).passes(0..passes)
}

/// Renders passes [0, spp) with the path tracer.
pub fn render_path(scene: &Scene, spp: u64, seed: u64) -> FilmSum {
    render_with(scene, Method::Path(PathSettings::from_scene(scene)), spp, seed)
}

/// SPPM settings from the scene, with the given photon count.
pub fn sppm_settings(scene: &Scene, photons: u64) -> SppmSettings {
    let mut s = SppmSettings::from_scene(scene);
    s.photons = photons;
    s
}

/// Renders SPPM iterations [0, n).
pub fn render_sppm(scene: &Scene, settings: SppmSettings, n: u64, seed: u64) -> FilmSum {
    render_with(scene, Method::Sppm(settings), n, seed)
}

/// Reads a reference EXR.
pub fn reference(name: &str) -> Vec<Rgb> {
    let (_, _, px) = read_image(&refs_dir().join(name)).unwrap_or_else(|e| panic!("{name}: {e}"));
    px
}

/// Renders passes [0, spp) with the method the scene's `<integrator>` asks for.
pub fn render_as_declared(scene: &Scene, spp: u64, seed: u64) -> FilmSum {
    let settings = JobSettings {
        passes: Some(spp),
        seed,
        ..JobSettings::default()
    };
    let resolved = settings.resolve(scene, false).unwrap_or_else(|e| panic!("{e}"));
    Renderer::new(scene, &resolved.render).passes(0..spp)
}

/// The spp at which a reference's channel means are compared, if not the test's.
fn means_spp(name: &str) -> Option<u64> {
    reference_meta(name)["means_spp"].as_u64()
}

/// A reference's JSON: how it was rendered, its noise floor, Mitsuba's own MSE.
fn reference_meta(name: &str) -> serde_json::Value {
    let path = refs_dir().join(format!("{name}.json"));
    let text = std::fs::read_to_string(&path).unwrap_or_else(|e| panic!("{}: {e}", path.display()));
    serde_json::from_str(&text).unwrap_or_else(|e| panic!("{}: {e}", path.display()))
}

/// The reference's own remaining noise (`noise_floor_mse` in `refs/NAME.json`, NAME without
/// extension): an MSE against it is the render's MSE against the truth plus this.
pub fn noise_floor(name: &str) -> f64 {
    reference_meta(name)["noise_floor_mse"].as_f64().unwrap()
}

/// The reference's recorded Mitsuba MSE at the test's spp: (spp, median MSE over seeds).
pub fn mitsuba_mse(name: &str) -> (u64, f64) {
    let meta = reference_meta(name);
    let m = &meta["mitsuba_mse_at_test_spp"];
    (m["spp"].as_u64().unwrap(), m["median"].as_f64().unwrap())
}

/// Renders `refs/NAME.xml` as its `<integrator>` declares, at the spp its reference JSON
/// records Mitsuba's own MSE for, and checks it against `refs/NAME.exr`: every channel mean
/// within 1%, and an MSE no worse than 1.25 times Mitsuba's.
pub fn check_declared_against_mitsuba(name: &str) -> Comparison {
    check_scene_against_mitsuba(&refs_dir().join(format!("{name}.xml")), &[], name)
}

/// [`check_declared_against_mitsuba`] for any scene file and parameters, against the reference
/// `refs/REFERENCE.exr` and `.json`.
pub fn check_scene_against_mitsuba(scene: &Path, defines: &[(&str, &str)], name: &str) -> Comparison {
    let (spp, mitsuba) = mitsuba_mse(name);
    let scene = load(scene, defines);
    let reference = reference(&format!("{name}.exr"));
    // Like Mitsuba's figure (15 seeds), the median over seeds: one seed's MSE varies by ±30%
    // on scenes with glints or small bright lights, and five seeds' median by ±15%.
    let mut runs: Vec<Comparison> = (1..=9)
        .map(|seed| {
            let film = render_as_declared(&scene, spp, seed);
            assert_eq!(film.nonfinite, 0);
            compare(&film.image().unwrap(), &reference)
        })
        .collect();
    runs.sort_by(|a, b| a.mse.total_cmp(&b.mse));
    let mut cmp = runs[4];
    // A scene whose image mean is itself noisy at the test's spp (sub-pixel lights hundreds of
    // times brighter than the rest) names in its JSON the spp at which its means are compared.
    if let Some(spp) = means_spp(name) {
        let film = render_as_declared(&scene, spp, 100);
        let long = compare(&film.image().unwrap(), &reference);
        (cmp.mean, cmp.reference_mean) = (long.mean, long.reference_mean);
    }
    eprintln!(
        "{name}: median mse {:.3e} over 9 seeds (Mitsuba {mitsuba:.3e}, ratio {:.3}), means {:?} vs {:?}, worst mean error {:.3}%",
        cmp.mse,
        cmp.mse / mitsuba,
        cmp.mean,
        cmp.reference_mean,
        100.0 * cmp.worst_mean_error()
    );
    assert_matches_mitsuba(name, &cmp, mitsuba);
    cmp
}

/// The reference criteria: every channel mean within 1% and an MSE at most 1.25 times
/// Mitsuba's own at the same spp.
fn assert_matches_mitsuba(name: &str, cmp: &Comparison, mitsuba_mse: f64) {
    assert!(
        cmp.worst_mean_error() < 0.01,
        "{name}: a channel mean is off by more than 1%: {cmp:?}"
    );
    assert!(
        cmp.mse <= 1.25 * mitsuba_mse,
        "{name}: MSE {:.3e} exceeds 1.25 x Mitsuba's {mitsuba_mse:.3e}",
        cmp.mse
    );
}

/// Renders `scene` (in `refs/`) with the path tracer at `spp` and checks it against the Mitsuba
/// reference `exr`: every channel mean within 1%, and an MSE no worse than 1.25 times
/// `mitsuba_mse` (Mitsuba's own MSE at the same spp).
pub fn check_path_against_mitsuba(scene: &str, exr: &str, res: &str, spp: u64, mitsuba_mse: f64) {
    let loaded = load(&refs_dir().join(scene), &[("res", res)]);
    let film = render_path(&loaded, spp, 1);
    let cmp = compare(&film.image().unwrap(), &reference(exr));
    eprintln!(
        "{exr}: mse {:.3e} (Mitsuba {mitsuba_mse:.3e}, ratio {:.3}), means {:?} vs {:?}, worst mean error {:.3}%",
        cmp.mse,
        cmp.mse / mitsuba_mse,
        cmp.mean,
        cmp.reference_mean,
        100.0 * cmp.worst_mean_error()
    );
    assert_eq!(film.nonfinite, 0);
    assert_matches_mitsuba(exr, &cmp, mitsuba_mse);
}

/// SPPM on `refs/NAME.xml` (100,000 photons per iteration) against `refs/NAME.exr`: at 64
/// iterations every channel mean within 2%, and the MSE under half that at 8 iterations
/// (variance and bias both fall; pure variance would give a factor 8).
pub fn check_sppm_convergence(name: &str) {
    check_sppm_estimate_convergence(name, None);
}

/// [`check_sppm_convergence`] with the volume estimate `estimate` (None: the scene's default).
pub fn check_sppm_estimate_convergence(name: &str, estimate: Option<VolumeEstimate>) {
    let scene = load(&refs_dir().join(format!("{name}.xml")), &[]);
    let mut settings = sppm_settings(&scene, 100_000);
    if let Some(estimate) = estimate {
        settings = settings.with_volume_estimate(estimate);
    }
    let label = format!("{name}, SPPM, {:?} estimate", settings.volume_estimate);
    check_convergence(&label, name, (8, 64), 0.02, |n| {
        render_sppm(&scene, settings, n, 1)
    });
}

/// `render(n)` renders n passes; against `refs/REFERENCE.exr`, at `many` passes every channel
/// mean must be within `max_mean_error` and the MSE under half that at `few`.
pub fn check_convergence(
    label: &str,
    reference_name: &str,
    (few, many): (u64, u64),
    max_mean_error: f64,
    render: impl Fn(u64) -> FilmSum,
) {
    let reference = reference(&format!("{reference_name}.exr"));
    let a = compare(&render(few).image().unwrap(), &reference);
    let many_film = render(many);
    assert_eq!(many_film.nonfinite, 0);
    let b = compare(&many_film.image().unwrap(), &reference);
    for (n, c) in [(few, &a), (many, &b)] {
        eprintln!(
            "{label} {n} passes: rmse {:.4}, means {:?} vs {:?}, worst mean error {:.3}%",
            c.mse.sqrt(),
            c.mean,
            c.reference_mean,
            100.0 * c.worst_mean_error()
        );
    }
    assert!(
        b.worst_mean_error() < max_mean_error,
        "{label}: a channel mean is off by more than {:.1}%: {b:?}",
        100.0 * max_mean_error
    );
    assert!(
        b.mse < 0.5 * a.mse,
        "{label}: MSE {:.3e} at {many} passes vs {:.3e} at {few}",
        b.mse,
        a.mse
    );
}
