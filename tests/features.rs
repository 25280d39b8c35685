//! Every part of the scene subset against Mitsuba 3, in three small scenes of our own whose
//! references we rendered with Mitsuba 3.9.1 (`refs/*.json` records how, the reference's noise
//! floor, and Mitsuba's own MSE at 256 spp over five seeds):
//!
//! - `materials.xml`: rough conductor (named and eta/k), plastic, rough plastic (nonlinear),
//!   blendbsdf, twosided with distinct sides;
//! - `lights.xml`: spot, point and disk area lights, a thin-lens camera, a named glass IOR;
//! - `meshes.xml`: PLY with vertex normals (and with `face_normals`), OBJ quads, `matrix`;
//! - `mirrored.xml`: rectangles, a disk and a cube under mirroring transforms;
//! - `bumpy.xml`: normal and bump maps on rectangles and spheres, one inside `twosided`;
//! - `instances.xml`: a shape group of three shapes, placed five times (one mirrored);
//! - `polarizer.xml`: Mitsuba's `polarizer`, as its RGB variants render it;
//! - `direct-projective.xml`: Mitsuba's `direct_projective` integrator, its primal image;
//! - `orthographic.xml`: `meshes.xml` through Mitsuba's orthographic sensor, on a 3:2 film;
//! - `mesh-attributes.xml`: `mesh_attribute` textures from PLY vertex and face properties;
//! - `nested-id.xml`: a material named inside another one.
//!
//! Criteria, as for the shared references: channel means within 1%, and at 256 spp an MSE no
//! worse than 1.25 times Mitsuba's median.

use photonfarm::integrator::sppm::VolumeEstimate;
use photonfarm_tests::{check_path_against_mitsuba, mitsuba_mse};

fn check(name: &str) {
    let (spp, mitsuba) = mitsuba_mse(name);
    check_path_against_mitsuba(
        &format!("{name}.xml"),
        &format!("{name}.exr"),
        "128",
        spp,
        mitsuba,
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

/// `mirrored.xml`: a rectangle light, a disk light, a one-sided wall and a cube placed by
/// mirroring `to_world` matrices. Mitsuba orients its rectangle and disk by the inverse
/// transpose of to_world, and its cube by vertex normals transformed the same way; by the
/// transformed edges' cross product, both lights faced away from the room (every channel
/// mean 99.99% low), the wall from the camera and the cube inwards (2.3% low alone).
#[test]
fn mirrored_rectangles_disks_and_cubes_face_as_in_mitsuba() {
    check("mirrored");
}

/// `bumpy.xml`: normal maps (a floor inside `twosided`, a sphere whose tangent frame follows its
/// ∂p/∂u) and bump maps (a wall, and a sphere whose slopes scale by its ∂p/∂u and ∂p/∂v), lit
/// at grazing angles where Mitsuba's normal flip and shadow terminator term show.
#[test]
fn bump_and_normal_maps_match_mitsuba() {
    check("bumpy");
}

/// `instances.xml`: one group (an OBJ torus, a PLY sphere, a one-sided rectangle) placed by
/// five instances: turned, unevenly scaled, mirrored, through a matrix, and one declared before
/// its group.
#[test]
fn instanced_shape_groups_match_mitsuba() {
    check("instances");
}

/// `polarizer.xml`: a coloured polarizer sheet between a light and a wall passes half its
/// transmittance, to shadow rays and paths alike (Mitsuba's RGB variants carry no polarization).
#[test]
fn a_polarizer_passes_half_its_transmittance_as_in_mitsuba() {
    photonfarm_tests::check_declared_against_mitsuba("polarizer");
}

/// `direct-projective.xml`: Mitsuba's differentiable direct illumination, rendered as its primal
/// image (the path tracer at max_depth 2), with a warning that says so.
#[test]
fn direct_projective_renders_its_primal_image_as_in_mitsuba() {
    let scene = photonfarm_tests::load(&photonfarm_tests::refs_dir().join("direct-projective.xml"), &[]);
    assert!(
        scene
            .warnings
            .iter()
            .any(|w| w.contains("direct_projective") && w.contains("primal")),
        "{:?}",
        scene.warnings
    );
    photonfarm_tests::check_declared_against_mitsuba("direct-projective");
}

/// `orthographic.xml`: parallel rays from the near plane, the extent set by to_world's scale, on
/// a film of aspect 3:2, looking into the box at an angle.
#[test]
fn orthographic_sensor_matches_mitsuba() {
    photonfarm_tests::check_declared_against_mitsuba("orthographic");
}

#[test]
fn meshes_and_transforms_match_mitsuba() {
    check("meshes");
}

/// `rough-glass.xml`: rough dielectric spheres (GGX and Beckmann) and a cube with a
/// checkerboard roughness, a thin glass pane, and a mask whose opacity is a checkerboard.
#[test]
fn rough_glass_thin_glass_and_mask_match_mitsuba() {
    photonfarm_tests::check_declared_against_mitsuba("rough-glass");
}

/// `anisotropic.xml`: `alpha_u` and `alpha_v` apart on a GGX rough conductor, a Beckmann rough
/// dielectric and a Beckmann rough conductor, so the highlights stretch along the spheres'
/// ∂p/∂u as in Mitsuba.
#[test]
fn anisotropic_roughness_matches_mitsuba() {
    photonfarm_tests::check_declared_against_mitsuba("anisotropic");
}

/// `textured-light.xml`: area lights whose radiance is a checkerboard (a rectangle) and an
/// sRGB bitmap (a sphere), seen directly and lighting the scene, as in Mitsuba: by the path
/// tracer, and by SPPM, whose photons leave with the radiance where they start.
#[test]
fn textured_area_lights_match_mitsuba() {
    photonfarm_tests::check_declared_against_mitsuba("textured-light");
    photonfarm_tests::check_sppm_convergence("textured-light");
}

/// `textured-spot.xml`: a spot light projecting a bitmap over its cone, as Mitsuba's `spot`
/// with a `texture`: by the path tracer, and by SPPM, whose photons carry the texture's colour.
#[test]
fn textured_spot_light_matches_mitsuba() {
    photonfarm_tests::check_declared_against_mitsuba("textured-spot");
    photonfarm_tests::check_sppm_convergence("textured-spot");
}

/// `projector.xml`: Mitsuba's projector throwing a 3:2 bitmap with a vertical field of view and
/// a scale: by the path tracer, and by SPPM, whose photons leave through the image.
#[test]
fn projector_matches_mitsuba() {
    photonfarm_tests::check_declared_against_mitsuba("projector");
    photonfarm_tests::check_sppm_convergence("projector");
}

/// `cylinder.xml`: Mitsuba's analytic cylinder, its (u, v) under a checkerboard, its ∂p/∂u under
/// an anisotropic conductor, as an area light, and seen from inside through its open end.
#[test]
fn cylinders_match_mitsuba() {
    photonfarm_tests::check_declared_against_mitsuba("cylinder");
}

/// `mesh-attributes.xml`: PLY vertex colours as a diffuse reflectance, a one-channel face weight
/// blending two materials, scaled three-channel face colours tinting a rough conductor, and
/// `red green blue` vertex colours on a floor.
#[test]
fn mesh_attributes_match_mitsuba() {
    photonfarm_tests::check_declared_against_mitsuba("mesh-attributes");
    photonfarm_tests::check_sppm_convergence("mesh-attributes");
}

/// Delta tracking and ratio tracking through a chromatic density grid with an albedo grid, under
/// an area light and a point light (sampled equiangularly, weighted by ratio tracking), beside
/// homogeneous fog with a repeated albedo grid; SPPM with the beam estimate (transmittance by
/// ratio tracking along the camera ray) and with the point estimate.
#[test]
fn heterogeneous_media_match_mitsuba() {
    photonfarm_tests::check_declared_against_mitsuba("heterogeneous");
    for estimate in [VolumeEstimate::Beam, VolumeEstimate::Point] {
        photonfarm_tests::check_sppm_estimate_convergence("heterogeneous", Some(estimate));
    }
}

/// `rawconstant.xml`: Mitsuba's `rawconstant` as a constant normal map that tilts every shading
/// normal (taken as a plain normal map, 4.7% off), as the identity normal map, and as a
/// roughness.
#[test]
fn raw_constants_match_mitsuba() {
    photonfarm_tests::check_declared_against_mitsuba("rawconstant");
}

/// `curves.xml`: Mitsuba's `linearcurve`, tapering and constant, under a checkerboard (u about
/// the axis, v along all of a shape's segments) and, placed by a rotation and a non-uniform
/// scale, in an anisotropic conductor oriented by its ∂p/∂u.
#[test]
fn linear_curves_match_mitsuba() {
    photonfarm_tests::check_declared_against_mitsuba("curves");
}

/// `bspline.xml`: Mitsuba's `bsplinecurve`, intersected as linear pieces and put back on the
/// cubic sweep, under a checkerboard and in an anisotropic conductor.
#[test]
fn bspline_curves_match_mitsuba() {
    photonfarm_tests::check_declared_against_mitsuba("bspline");
}

/// `null-emitter.xml`: area lights with a null material (Blender's exporter writes them so),
/// whose light counts wherever a ray meets them and which rays cross: one lighting a floor,
/// one facing the camera before a wall that shows through it, one facing away. Before their
/// light counted where a ray crossed them, the path tracer lost 39% of this image (7% of
/// sapo17/BachelorThesis's simple-monkey).
#[test]
fn emitters_with_null_materials_match_mitsuba() {
    photonfarm_tests::check_declared_against_mitsuba("null-emitter");
    photonfarm_tests::check_sppm_convergence("null-emitter");
}

/// `nested-id.xml`: a material with an id declared inside another material (Bitterli's
/// staircase, converted for Mitsuba 3, keeps its brushed metal so), which a shape refers to.
/// Before, the loader refused the scene: only top-level materials had names.
#[test]
fn materials_named_inside_others_match_mitsuba() {
    photonfarm_tests::check_declared_against_mitsuba("nested-id");
}
