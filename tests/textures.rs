//! Textures against Mitsuba 3 (`refs/textures.xml`, reference rendered with Mitsuba 3.9.1 at
//! 8192 spp): bitmaps from PNG (8-bit sRGB, bilinear, repeated), JPEG (on a rotated sphere) and
//! EXR (a rough metal's roughness), nearest filtering with mirror wrapping, and a checkerboard
//! as a plastic's diffuse colour and as a blend weight (read as a number, where Mitsuba swaps
//! its colours); texture coordinates from a rectangle, a sphere, an OBJ (v flipped on load) and
//! a PLY file.
//!
//! Criteria: channel means within 1%, and an MSE no worse than 1.25 times Mitsuba's median at
//! the same spp.

use photonfarm_tests::check_declared_against_mitsuba;

#[test]
fn textures_match_mitsuba() {
    check_declared_against_mitsuba("textures");
}

/// Image files are scene files: a job's bundle carries them like meshes.
#[test]
fn image_files_go_into_the_bundle() {
    let scene = photonfarm_tests::load(&photonfarm_tests::refs_dir().join("textures.xml"), &[]);
    for name in [
        "colors.png",
        "checker.jpg",
        "roughness.exr",
        "strip.obj",
        "strip.ply",
    ] {
        assert!(
            scene.files.iter().any(|f| f.ends_with(name)),
            "{name} missing from {:?}",
            scene.files
        );
    }
    let (bytes, _) =
        photonfarm::bundle::pack(&photonfarm_tests::refs_dir().join("textures.xml"), &scene.files).unwrap();
    let dir = tempfile::tempdir().unwrap();
    let unpacked = photonfarm::bundle::unpack(&bytes, dir.path(), &Default::default()).unwrap();
    assert!(
        unpacked.iter().any(|f| f.ends_with("textures/colors.png")),
        "{unpacked:?}"
    );
}
