//! Mitsuba 3's own scenes, as published in mitsuba-data (copied with their layout into
//! `refs/mitsuba-data/`, see its README), against Mitsuba 3's renders of the same files.
//!
//! `scenes/cbox/cbox-rgb.xml` exercises the file structure: `<include>`d fragments that declare
//! the defaults the main file uses, a top-level area emitter that a shape refers to by id
//! (declared after the include that refers to it), OBJ meshes resolved against the main scene's
//! folder, `near_clip`, `far_clip` and `focus_distance` on a pinhole.

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
