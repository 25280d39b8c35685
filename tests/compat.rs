//! Mitsuba 3's own scenes, as published in mitsuba-data (copied with their layout into
//! `refs/mitsuba-data/`, see its README), against Mitsuba 3's renders of the same files.
//!
//! - `scenes/cbox/cbox-rgb.xml`: `<include>`d fragments that declare the defaults the main file
//!   uses, a top-level area emitter that a shape refers to by id (declared after the include
//!   that refers to it), OBJ meshes resolved against the main scene's folder, `near_clip`,
//!   `far_clip` and `focus_distance` on a pinhole;
//! - `scenes/cbox/cbox.xml`: reflectances and radiance as wavelength:value spectra, a Gaussian
//!   filter;
//! - `docs/scenes/integrator_depth_3.xml`: `<path value="../../common">`, `max_depth` 3, a
//!   top-level spectral area emitter;
//! - `docs/scenes/integrator_direct_both.xml`, `_lum.xml`, `_bsdf.xml`: Veach's MIS scene, an
//!   included scene file, Beckmann rough plastic by default, sphere lights, the `direct`
//!   integrator with one sample of each kind, light samples only, BSDF samples only;
//! - `docs/scenes/integrator_depth_inf.xml`, `variants_cbox_rgb.xml`: the Cornell box with
//!   unlimited depth (also with SPPM), and with spectral reflectances.
//!
//! Criteria: channel means within 1% and an MSE at most 1.25 times Mitsuba's at equal spp.

use photonfarm_tests::{
    check_scene_against_mitsuba, compare, load, reference, refs_dir, render_sppm, sppm_settings,
};

fn cbox_rgb() -> std::path::PathBuf {
    refs_dir().join("mitsuba-data/scenes/cbox/cbox-rgb.xml")
}

#[test]
fn mitsuba_cbox_rgb_path_matches_mitsuba() {
    check_scene_against_mitsuba(&cbox_rgb(), &[("res", "64")], "mitsuba-cbox-rgb");
}

#[test]
fn mitsuba_cbox_rgb_sppm_matches_mitsuba() {
    let scene = load(&cbox_rgb(), &[("res", "64")]);
    let film = render_sppm(&scene, sppm_settings(&scene, 100_000), 32, 1);
    let cmp = compare(&film.image().unwrap(), &reference("mitsuba-cbox-rgb.exr"));
    eprintln!("cbox-rgb SPPM: means {:?} vs {:?}", cmp.mean, cmp.reference_mean);
    assert!(cmp.worst_mean_error() < 0.02, "{cmp:?}");
}

#[test]
fn mitsuba_cbox_with_spectra_and_gaussian_filter_matches_mitsuba() {
    let scene = refs_dir().join("mitsuba-data/scenes/cbox/cbox.xml");
    check_scene_against_mitsuba(&scene, &[("res", "64")], "mitsuba-cbox");
}

#[test]
fn mitsuba_docs_depth_3_matches_mitsuba() {
    let scene = refs_dir().join("mitsuba-data/docs/scenes/integrator_depth_3.xml");
    check_scene_against_mitsuba(&scene, &[("width", "64"), ("height", "64")], "mitsuba-depth-3");
}

#[test]
fn mitsuba_docs_veach_direct_matches_mitsuba() {
    let scene = refs_dir().join("mitsuba-data/docs/scenes/integrator_direct_both.xml");
    check_scene_against_mitsuba(
        &scene,
        &[("width", "96"), ("height", "64")],
        "mitsuba-veach-direct",
    );
}

#[test]
fn mitsuba_docs_veach_light_samples_only_matches_mitsuba() {
    let scene = refs_dir().join("mitsuba-data/docs/scenes/integrator_direct_lum.xml");
    check_scene_against_mitsuba(&scene, &[("width", "96"), ("height", "64")], "mitsuba-veach-lum");
}

#[test]
fn mitsuba_docs_veach_bsdf_samples_only_matches_mitsuba() {
    let scene = refs_dir().join("mitsuba-data/docs/scenes/integrator_direct_bsdf.xml");
    check_scene_against_mitsuba(&scene, &[("width", "96"), ("height", "64")], "mitsuba-veach-bsdf");
}

#[test]
fn mitsuba_docs_variants_cbox_rgb_matches_mitsuba() {
    let scene = refs_dir().join("mitsuba-data/docs/scenes/variants_cbox_rgb.xml");
    check_scene_against_mitsuba(
        &scene,
        &[("width", "64"), ("height", "64")],
        "mitsuba-variants-cbox-rgb",
    );
}

#[test]
fn mitsuba_docs_depth_inf_path_and_sppm_match_mitsuba() {
    let path = refs_dir().join("mitsuba-data/docs/scenes/integrator_depth_inf.xml");
    let defines = [("width", "64"), ("height", "64")];
    check_scene_against_mitsuba(&path, &defines, "mitsuba-depth-inf");
    let scene = load(&path, &defines);
    let film = render_sppm(&scene, sppm_settings(&scene, 100_000), 32, 1);
    let cmp = compare(&film.image().unwrap(), &reference("mitsuba-depth-inf.exr"));
    eprintln!("depth-inf SPPM: means {:?} vs {:?}", cmp.mean, cmp.reference_mean);
    assert!(cmp.worst_mean_error() < 0.02, "{cmp:?}");
}

/// `tests/scenes/texture_interp/test_texture_interp_direct.xml`, one of Mitsuba's own texture
/// tests: one PNG on rectangles with repeat, mirror and clamp wrapping, bilinear and nearest
/// filtering and `to_uv` transforms, under a point light with the `direct` integrator (inside
/// `moment`, whose extra channels we do not write).
#[test]
fn mitsuba_tests_texture_interp_matches_mitsuba() {
    let scene = refs_dir().join("mitsuba-data/tests/scenes/texture_interp/test_texture_interp_direct.xml");
    check_scene_against_mitsuba(&scene, &[], "mitsuba-texture-interp");
}
