//! The hybrid method (path tracing for all light but caustics, particle tracing for caustics)
//! against Mitsuba 3 references of scenes whose caustics each side alone renders badly or not
//! at all: the two shares must add up to the whole image, nothing missed, nothing twice.

use photonfarm::integrator::path::PathSettings;
use photonfarm::render::Method;
use photonfarm_tests::{check_convergence, load, refs_dir, render_with};

/// The hybrid on `refs/NAME.xml` against `refs/NAME.exr`: channel means within 1% at `passes`,
/// the MSE under half that at a sixteenth of them.
fn check(name: &str, passes: u64, seed: u64) {
    let scene = load(&refs_dir().join(format!("{name}.xml")), &[]);
    let method = Method::Hybrid(PathSettings::from_scene(&scene));
    check_convergence(
        &format!("{name}, hybrid"),
        name,
        (passes / 16, passes),
        0.01,
        |n| render_with(&scene, method, n, seed),
    );
}

/// A spot light's caustic through a glass ball: all of it is the particle tracer's share (the
/// path tracer cannot find it), and the direct and indirect light around it the path tracer's.
/// Against Mitsuba's `ptracer` at 262,144 spp.
#[test]
fn spot_caustic_matches_mitsuba_ptracer() {
    check("caustic", 256, 1);
}

/// The Cornell box with a glass and a mirror sphere under an area light: its caustics are
/// found by both sides of the split (BSDF samples that hit the light after glass, light paths
/// that pass the glass first), so counting them twice or not at all would show in the means.
/// Against Mitsuba's path tracer at 16,384 spp.
#[test]
fn area_light_caustics_match_mitsuba_path() {
    check("cbox-spheres", 128, 2);
}
