//! Mitsuba 3's defaults, each against a Mitsuba reference of a scene that relies on it
//! (`refs/*.json` records how each was rendered, its noise floor and Mitsuba's own MSE at the
//! spp rendered here). Criteria as for every reference: channel means within 1%, MSE at most
//! 1.25 times Mitsuba's.

use photonfarm_tests::{check_declared_against_mitsuba, load, refs_dir};

/// No fov: Mitsuba's 50 mm focal length, measured along the 35 mm film's diagonal, on a 4:3
/// image; no `<rfilter>`: Mitsuba's Gaussian.
#[test]
fn default_focal_length_and_gaussian_filter_match_mitsuba() {
    let scene = load(&refs_dir().join("focal-length.xml"), &[]);
    // 2 atan(tan(46.793 deg / 2) * a / sqrt(1 + a^2)) for a = 4/3.
    let fov_x = 2.0 * scene.camera.tan_half_x.atan().to_degrees();
    assert!((fov_x - 38.1848).abs() < 1e-3, "x field of view {fov_x}");
    check_declared_against_mitsuba("focal-length");
}

/// `<integrator type="direct">` with two emitter samples and one BSDF sample.
#[test]
fn direct_integrator_matches_mitsuba() {
    check_declared_against_mitsuba("direct");
}

/// An emitting shape with no BSDF absorbs light (Mitsuba gives it a black one); tent filter.
#[test]
fn emitter_without_bsdf_is_black_and_tent_filter_matches_mitsuba() {
    check_declared_against_mitsuba("emitter-no-bsdf");
}

/// Rough materials without a `distribution`: Mitsuba's Beckmann, with its rational masking
/// term and visible-normal sampling (rough conductors, `alpha_u` = `alpha_v`, rough plastic).
#[test]
fn beckmann_is_the_default_distribution_and_matches_mitsuba() {
    check_declared_against_mitsuba("beckmann");
}

/// Mitsuba's `serialized` meshes (with and without normals, `shape_index`), and smooth normals
/// computed for a mesh file that has none, as Mitsuba does.
#[test]
fn serialized_meshes_and_computed_normals_match_mitsuba() {
    check_declared_against_mitsuba("serialized");
}
