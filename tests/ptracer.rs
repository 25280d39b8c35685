//! The particle tracer against Mitsuba 3's `ptracer`, and the pass contract the farm is built on.

use photonfarm::integrator::path::PathSettings;
use photonfarm::render::{Method, RenderSettings, Renderer};
use photonfarm::scene::Scene;
use photonfarm_tests::{check_convergence, load, refs_dir, render_as_declared};

fn settings(scene: &Scene, seed: u64) -> RenderSettings {
    RenderSettings {
        seed,
        method: Method::Ptracer(PathSettings::from_scene(scene)),
    }
}

/// The particle tracer on `scene` against Mitsuba's `ptracer` reference `name`: channel means
/// within 1% at 256 passes, the MSE under half that at 16.
fn check_against_mitsuba(scene: &Scene, name: &str) {
    let s = settings(scene, 1);
    check_convergence(&format!("{name}, ptracer"), name, (16, 256), 0.01, |n| {
        Renderer::new(scene, &s).passes(0..n)
    });
}

/// The spot light's caustic through the glass ball (out of view), against the two 131,072-spp
/// Mitsuba `ptracer` renders of `refs/caustic.exr`. The scene declares `ptracer`, and renders
/// with ours as declared.
#[test]
fn spot_caustic_matches_mitsuba_ptracer() {
    let scene = load(&refs_dir().join("caustic.xml"), &[]);
    check_against_mitsuba(&scene, "caustic");
    let small = load(&refs_dir().join("caustic.xml"), &[("res", "32")]);
    assert_eq!(
        render_as_declared(&small, 2, 5),
        Renderer::new(&small, &settings(&small, 5)).passes(0..2)
    );
}

/// A thin lens, an area, a spot and a point light, and a glass sphere that the particle tracer
/// sees black (as Mitsuba's does: a delta BSDF cannot connect to the camera), against Mitsuba's
/// `ptracer` at 65,536 spp (`refs/lights-ptracer.exr`).
#[test]
fn thin_lens_and_three_lights_match_mitsuba_ptracer() {
    let scene = load(&refs_dir().join("lights.xml"), &[("res", "64")]);
    check_against_mitsuba(&scene, "lights-ptracer");
}

/// Connections to an orthographic camera (a delta direction: the camera's share is 1 / A, A the
/// film's area in world space, with no 1/r²), against the path-traced Mitsuba reference
/// `refs/orthographic.exr`: Mitsuba's own `ptracer` refuses an orthographic sensor
/// ("Endpoint::sample_direction(): not implemented!"), and the light is the same.
#[test]
fn orthographic_camera_connections_match_mitsuba_path() {
    let scene = load(&refs_dir().join("orthographic.xml"), &[]);
    check_against_mitsuba(&scene, "orthographic");
}

/// Passes [0, 3) and [3, 8) add up to exactly [0, 8), with one thread or two: every
/// contribution is rounded on its own, so where and in which order light paths land does not
/// matter.
#[test]
fn split_passes_and_threads_give_the_same_sums() {
    let scene = load(&refs_dir().join("lights.xml"), &[("res", "24")]);
    let s = settings(&scene, 9);
    let pool = |n| rayon::ThreadPoolBuilder::new().num_threads(n).build().unwrap();
    let whole = pool(2).install(|| Renderer::new(&scene, &s).passes(0..8));
    let mut parts = pool(1).install(|| Renderer::new(&scene, &s).passes(3..8));
    parts.add(&Renderer::new(&scene, &s).passes(0..3)).unwrap();
    assert_eq!(parts, whole);
    assert!(whole.sums.iter().any(|p| p.iter().any(|&c| c > 0)));
}
