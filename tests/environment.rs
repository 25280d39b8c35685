//! Lights at infinity against Mitsuba 3 (references rendered with Mitsuba 3.9.1 at 8192 spp):
//!
//! - `environment.xml`: an EXR environment map, rotated and scaled, with a small bright sun,
//!   lighting a floor, a rough metal sphere, a plastic cube and a glass sphere;
//! - `constant.xml`: Mitsuba's `constant` on the same objects;
//! - `sun.xml`: a `directional` sun with a dim constant sky.
//!
//! Path tracer: channel means within 1%, MSE within 1.25 times Mitsuba's at the same spp.
//! SPPM: means within 2% and error falling with iterations; in `environment.xml` the glass
//! sphere's caustic on the floor is lit by the map alone, so photons from the map must carry it.

use photonfarm_tests::{check_declared_against_mitsuba, check_sppm_convergence};

#[test]
fn environment_map_matches_mitsuba() {
    check_declared_against_mitsuba("environment");
}

#[test]
fn constant_environment_matches_mitsuba() {
    check_declared_against_mitsuba("constant");
}

#[test]
fn directional_sun_matches_mitsuba() {
    check_declared_against_mitsuba("sun");
}

/// Photons leave the environment map from a disk as wide as the scene, in proportion to the
/// map's luminance: the caustic under the glass sphere comes from them.
#[test]
fn environment_map_caustic_with_sppm_matches_mitsuba() {
    check_sppm_convergence("environment");
}

#[test]
fn constant_environment_with_sppm_matches_mitsuba() {
    check_sppm_convergence("constant");
}

#[test]
fn directional_sun_with_sppm_matches_mitsuba() {
    check_sppm_convergence("sun");
}
