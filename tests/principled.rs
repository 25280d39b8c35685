//! Mitsuba's `principled` BSDF (the Blender exporter's default material) against Mitsuba 3.9.1:
//! `refs/principled.xml`, a 4 × 3 grid of spheres with its lobes alone and together (defaults,
//! dielectric and metallic at two roughnesses, anisotropic, sheen, clearcoat, flatness,
//! spec_trans 0.8 with eta 1.5, textured base_color, metallic and roughness), rendered by the
//! path tracer (criteria: channel means within 1%, MSE at 256 spp no worse than 1.25 times
//! Mitsuba's median) and converged by SPPM (means within 2%, MSE at 64 iterations under half
//! that at 8). The BSDF's own statistical tests and its albedo against Mitsuba's are in
//! `common/src/bsdf/tests.rs`.

use std::path::Path;

use photonfarm::bsdf::Bsdf;
use photonfarm::scene::Scene;
use photonfarm_tests::{check_declared_against_mitsuba, check_sppm_convergence};

#[test]
fn principled_matches_mitsuba() {
    check_declared_against_mitsuba("principled");
}

/// SPPM gathers photons on the opaque principled spheres with a diffuse base; on the metallic
/// and the transmissive ones (whose transmitted light a photon estimate on the outside would
/// miss) the camera path follows the BSDF, as it does through rough metals.
#[test]
fn principled_sppm_converges_to_mitsuba() {
    check_sppm_convergence("principled");
}

/// A scene with one principled material made of `params`.
fn with_principled(params: &str) -> Result<Scene, String> {
    let text = format!(
        r#"<scene version="3.0.0">
    <sensor type="perspective"><float name="fov" value="45"/>
        <film type="hdrfilm"><integer name="width" value="4"/><integer name="height" value="4"/></film>
    </sensor>
    <bsdf type="principled" id="p">
{params}
    </bsdf>
    <shape type="sphere"><ref id="p"/></shape>
</scene>"#
    );
    Scene::from_str(&text, Path::new("principled-test.xml"), &[]).map_err(|e| e.to_string())
}

fn principled_of(scene: &Scene) -> &photonfarm::bsdf::Principled {
    scene
        .bsdfs
        .iter()
        .find_map(|b| match b {
            Bsdf::Principled(p) => Some(&**p),
            _ => None,
        })
        .expect("a principled material")
}

/// Every parameter Mitsuba 3.9.1's principled reads is accepted, as a number or a texture where
/// Mitsuba takes a texture.
#[test]
fn every_mitsuba_parameter_is_accepted() {
    let scene = with_principled(
        r#"
        <rgb name="base_color" value="0.8, 0.5, 0.2"/>
        <float name="roughness" value="0.3"/>
        <float name="anisotropic" value="0.4"/>
        <float name="metallic" value="0.2"/>
        <float name="spec_trans" value="0.3"/>
        <float name="specular" value="0.6"/>
        <float name="spec_tint" value="0.1"/>
        <float name="sheen" value="0.5"/>
        <float name="sheen_tint" value="0.5"/>
        <float name="flatness" value="0.2"/>
        <float name="clearcoat" value="0.7"/>
        <float name="clearcoat_gloss" value="0.9"/>
        <float name="diffuse_reflectance_sampling_rate" value="0.5"/>
        <float name="main_specular_sampling_rate" value="2"/>
        <float name="clearcoat_sampling_rate" value="0.25"/>"#,
    )
    .unwrap();
    let p = principled_of(&scene);
    // specular ↦ eta as Mitsuba maps it: 2 / (1 − √(0.08 · specular)) − 1.
    assert!((p.eta - (2.0 / (1.0 - (0.08f32 * 0.6).sqrt()) - 1.0)).abs() < 1e-6);
    assert_eq!(p.clearcoat_sampling_rate, 0.25);
    assert!(Bsdf::Principled(Box::new(p.clone())).needs_tangent_frame());

    let textured = with_principled(
        r#"
        <texture type="checkerboard" name="base_color"/>
        <texture type="checkerboard" name="roughness"/>
        <texture type="checkerboard" name="anisotropic"/>
        <texture type="checkerboard" name="metallic"/>
        <texture type="checkerboard" name="spec_trans"/>
        <texture type="checkerboard" name="spec_tint"/>
        <texture type="checkerboard" name="sheen"/>
        <texture type="checkerboard" name="sheen_tint"/>
        <texture type="checkerboard" name="flatness"/>
        <texture type="checkerboard" name="clearcoat"/>
        <texture type="checkerboard" name="clearcoat_gloss"/>
        <float name="eta" value="1.33"/>"#,
    )
    .unwrap();
    let p = principled_of(&textured);
    assert_eq!(p.eta, 1.33);
    // A textured spec_trans may transmit: no photon gathering there.
    assert!(!Bsdf::Principled(Box::new(p.clone())).gathers_photons());

    // The defaults: specular 0.5 is eta 1.5; every sampling rate 1 (the code's default for
    // clearcoat_sampling_rate, whatever Mitsuba's documentation says).
    let defaults = with_principled("").unwrap();
    let p = principled_of(&defaults);
    assert!((p.eta - 1.5).abs() < 1e-6, "{}", p.eta);
    assert_eq!(
        (
            p.diffuse_sampling_rate,
            p.specular_sampling_rate,
            p.clearcoat_sampling_rate
        ),
        (1.0, 1.0, 1.0)
    );
    assert!(Bsdf::Principled(Box::new(p.clone())).gathers_photons());
    assert!(!Bsdf::Principled(Box::new(p.clone())).needs_tangent_frame());

    // Index-matched transmission is nudged as Mitsuba nudges it.
    let matched =
        with_principled(r#"<float name="spec_trans" value="1"/><float name="eta" value="1"/>"#).unwrap();
    assert_eq!(principled_of(&matched).eta, 1.001);
}

#[test]
fn bad_principled_parameters_are_clear_errors() {
    for (params, needle) in [
        (
            r#"<float name="eta" value="1.5"/><float name="specular" value="0.5"/>"#,
            "either eta or specular",
        ),
        (r#"<float name="roughness" value="1.5"/>"#, "must lie in [0, 1]"),
        (r#"<float name="metallic" value="-0.1"/>"#, "must lie in [0, 1]"),
        (r#"<float name="eta" value="0"/>"#, "eta must be positive"),
        (r#"<float name="specular" value="20"/>"#, "specular must lie in"),
        (
            r#"<float name="clearcoat_sampling_rate" value="-1"/>"#,
            "cannot be negative",
        ),
        (
            r#"<texture type="checkerboard" name="eta"/>"#,
            "not supported inside",
        ),
        (
            r#"<float name="subsurface" value="0.5"/>"#,
            "unknown parameter 'subsurface'",
        ),
    ] {
        let err = with_principled(params).expect_err(params);
        assert!(err.contains(needle), "{params}: expected \"{needle}\" in: {err}");
        assert!(!err.contains('\n'), "one line: {err}");
    }
}

/// Mitsuba reads principled's weights as textures, and an `<rgb>` there is its `srgb` texture,
/// whose `eval_1` is the mean of the three channels (src/spectra/srgb.cpp): one held-out
/// Blender export gives `spec_tint` so. Out of [0, 1] it is refused, as Mitsuba refuses it.
#[test]
fn an_rgb_weight_is_the_mean_of_its_channels() {
    let scene =
        with_principled(r#"<rgb name="spec_tint" value="0.2, 0.4, 0.9"/><rgb name="sheen" value="0.5"/>"#)
            .unwrap();
    let p = principled_of(&scene);
    let fixed = |v: &photonfarm::texture::Param<f32>| match v {
        photonfarm::texture::Param::Fixed(x) => *x,
        photonfarm::texture::Param::Textured(_) => panic!("a number was expected"),
    };
    assert_eq!(fixed(&p.spec_tint), (0.2f32 + 0.4 + 0.9) / 3.0);
    assert_eq!(fixed(&p.sheen), 0.5);
    let e = with_principled(r#"<rgb name="spec_tint" value="0.2, 1.4, 0.9"/>"#).unwrap_err();
    assert!(e.contains("'spec_tint' must lie in [0, 1]"), "{e}");
}
