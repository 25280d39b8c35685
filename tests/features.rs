//! Every part of the scene subset against Mitsuba 3, in three small scenes of our own whose
//! references we rendered with Mitsuba 3.9.1 (`refs/*.json` records how, the reference's noise
//! floor, and Mitsuba's own MSE at 256 spp over five seeds):
//!
//! - `materials.xml`: rough conductor (named and eta/k), plastic, rough plastic (nonlinear),
//!   blendbsdf, twosided with distinct sides;
//! - `lights.xml`: spot, point and disk area lights, a thin-lens camera, a named glass IOR;
//! - `meshes.xml`: PLY with vertex normals (and with `face_normals`), OBJ quads, `matrix`.
//!
//! Criteria, as for the shared references: channel means within 1%, and at 256 spp an MSE no
//! worse than 1.25 times Mitsuba's median.

use photonfarm_tests::{compare, load, reference, refs_dir, render_path};

fn check(name: &str) {
    let meta: serde_json::Value =
        serde_json::from_str(&std::fs::read_to_string(refs_dir().join(format!("{name}.json"))).unwrap())
            .unwrap();
    let mitsuba = meta["mitsuba_mse_at_test_spp"]["median"].as_f64().unwrap();
    let spp = meta["mitsuba_mse_at_test_spp"]["spp"].as_u64().unwrap();
    let scene = load(&refs_dir().join(format!("{name}.xml")), &[("res", "128")]);
    let film = render_path(&scene, spp, 1);
    let cmp = compare(&film.image().unwrap(), &reference(&format!("{name}.exr")));
    eprintln!(
        "{name}: mse {:.3e} (Mitsuba {mitsuba:.3e}, ratio {:.3}), means {:?} vs {:?}, worst mean error {:.3}%",
        cmp.mse,
        cmp.mse / mitsuba,
        cmp.mean,
        cmp.reference_mean,
        100.0 * cmp.worst_mean_error()
    );
    assert_eq!(film.nonfinite, 0);
    assert!(
        cmp.worst_mean_error() < 0.01,
        "{name}: a channel mean is off by more than 1%: {cmp:?}"
    );
    assert!(
        cmp.mse <= 1.25 * mitsuba,
        "{name}: MSE {:.3e} exceeds 1.25 x Mitsuba's {mitsuba:.3e}",
        cmp.mse
    );
}

#[test]
fn materials_match_mitsuba() {
    check("materials");
}

#[test]
fn lights_and_thin_lens_match_mitsuba() {
    check("lights");
}

#[test]
fn meshes_and_transforms_match_mitsuba() {
    check("meshes");
}
