//! Statistical tests that every material's sampling, evaluation and density agree.

use std::f32::consts::PI;

use glam::{Vec2, Vec3A};

use super::*;
use crate::sampling::{Sampler, Stream};

fn conductor(alpha: Option<f32>) -> Bsdf {
    conductor_with(Distribution::Ggx, alpha)
}

fn conductor_with(distribution: Distribution, alpha: Option<f32>) -> Bsdf {
    Bsdf::Conductor(Conductor {
        // Gold, from Mitsuba's table.
        eta: Rgb::new(0.143036, 0.375307, 1.442045),
        k: Rgb::new(3.982997, 2.385556, 1.603359),
        specular: Rgb::ONE.into(),
        roughness: alpha.map(|alpha| Roughness {
            distribution,
            alpha: alpha.into(),
        }),
    })
}

fn plastic(alpha: Option<f32>, diffuse: f32) -> Bsdf {
    plastic_with(Distribution::Ggx, alpha, diffuse)
}

fn plastic_with(distribution: Distribution, alpha: Option<f32>, diffuse: f32) -> Bsdf {
    Bsdf::Plastic(Box::new(Plastic::new(
        Rgb::splat(diffuse).into(),
        Rgb::ONE.into(),
        1.49,
        false,
        alpha.map(|alpha| Microfacet { distribution, alpha }),
    )))
}

/// Where the tests evaluate textured parameters.
const UV: Vec2 = Vec2::new(0.3, 0.7);

/// A rough conductor whose roughness comes from a 2 × 2 bitmap.
fn textured_conductor() -> Bsdf {
    use crate::texture::{Bitmap, Filter, Texture, Wrap};
    let texels = [0.05, 0.2, 0.4, 0.7].map(Rgb::splat).to_vec();
    let bitmap = Bitmap::from_texels(
        2,
        2,
        texels,
        Filter::Bilinear,
        Wrap::Repeat,
        glam::Affine2::IDENTITY,
    );
    let Bsdf::Conductor(mut c) = conductor(Some(0.1)) else {
        unreachable!()
    };
    c.roughness = Some(Roughness {
        distribution: Distribution::Ggx,
        alpha: Param::Textured(std::sync::Arc::new(Texture::Bitmap(bitmap))),
    });
    Bsdf::Conductor(c)
}

fn diffuse(r: f32) -> Bsdf {
    Bsdf::Diffuse(Diffuse {
        reflectance: Rgb::splat(r).into(),
    })
}

fn rough_glass(distribution: Distribution, alpha: f32) -> Bsdf {
    Bsdf::RoughDielectric(Box::new(RoughDielectric {
        eta: 1.5,
        roughness: Roughness {
            distribution,
            alpha: alpha.into(),
        },
        specular_reflectance: Rgb::ONE.into(),
        specular_transmittance: Rgb::ONE.into(),
    }))
}

fn glass() -> Bsdf {
    Bsdf::Dielectric(Dielectric {
        eta: 1.5,
        specular_reflectance: Rgb::ONE.into(),
        specular_transmittance: Rgb::ONE.into(),
    })
}

/// The materials under test, each with a name for the failure message.
fn cases() -> Vec<(&'static str, Bsdf)> {
    vec![
        ("diffuse", diffuse(0.7)),
        ("rough conductor 0.1", conductor(Some(0.1))),
        ("rough conductor 0.5", conductor(Some(0.5))),
        (
            "beckmann conductor 0.1",
            conductor_with(Distribution::Beckmann, Some(0.1)),
        ),
        (
            "beckmann conductor 0.6",
            conductor_with(Distribution::Beckmann, Some(0.6)),
        ),
        (
            "beckmann plastic 0.3",
            plastic_with(Distribution::Beckmann, Some(0.3), 0.5),
        ),
        ("plastic", plastic(None, 0.5)),
        ("rough plastic 0.2", plastic(Some(0.2), 0.5)),
        ("rough plastic 0.6", plastic(Some(0.6), 0.8)),
        (
            "blend diffuse/rough conductor",
            Bsdf::Blend(Box::new((diffuse(0.8), conductor(Some(0.3)))), 0.4.into()),
        ),
        (
            // Textures at the test's (u, v): a checkerboard weight, a bitmap roughness.
            "textured blend of diffuse and rough conductor",
            Bsdf::Blend(
                Box::new((diffuse(0.8), textured_conductor())),
                Param::Textured(std::sync::Arc::new(crate::texture::Texture::Checkerboard {
                    color0: Rgb::splat(0.3),
                    color1: Rgb::splat(0.9),
                    to_uv: glam::Affine2::IDENTITY,
                })),
            ),
        ),
        ("rough glass ggx 0.2", rough_glass(Distribution::Ggx, 0.2)),
        (
            "rough glass beckmann 0.5",
            rough_glass(Distribution::Beckmann, 0.5),
        ),
        (
            "mask over rough plastic",
            Bsdf::Mask(Box::new((plastic(Some(0.3), 0.6), 0.7.into()))),
        ),
        (
            "twosided diffuse/plastic",
            Bsdf::TwoSided(Box::new((diffuse(0.5), plastic(Some(0.3), 0.5)))),
        ),
    ]
}

fn incoming() -> Vec<Vec3A> {
    [0.95f32, 0.6, 0.2]
        .iter()
        .flat_map(|&c| {
            let s = (1.0 - c * c).sqrt();
            [Vec3A::new(s, 0.0, c), Vec3A::new(-s * 0.6, -s * 0.8, -c)]
        })
        .collect()
}

const THETA_BINS: usize = 10;
const PHI_BINS: usize = 20;

fn bin_of(w: Vec3A) -> usize {
    let t = (((w.z.clamp(-1.0, 1.0) + 1.0) * 0.5 * THETA_BINS as f32) as usize).min(THETA_BINS - 1);
    let phi = w.y.atan2(w.x) + PI;
    let p = ((phi / (2.0 * PI) * PHI_BINS as f32) as usize).min(PHI_BINS - 1);
    t * PHI_BINS + p
}

/// Expected probability of each (cos θ, φ) bin: the pdf integrated by a fine midpoint rule.
fn expected_probabilities(b: &Bsdf, wi: Vec3A) -> Vec<f64> {
    let sub = 32;
    let mut out = vec![0.0f64; THETA_BINS * PHI_BINS];
    let (dz, dphi) = (2.0 / THETA_BINS as f32, 2.0 * PI / PHI_BINS as f32);
    for t in 0..THETA_BINS {
        for p in 0..PHI_BINS {
            let mut sum = 0.0f64;
            for i in 0..sub {
                for j in 0..sub {
                    let z = -1.0 + (t as f32 + (i as f32 + 0.5) / sub as f32) * dz;
                    let phi = (p as f32 + (j as f32 + 0.5) / sub as f32) * dphi - PI;
                    let s = (1.0 - z * z).max(0.0).sqrt();
                    let wo = Vec3A::new(s * phi.cos(), s * phi.sin(), z);
                    sum += b.pdf(UV, wi, wo) as f64;
                }
            }
            out[t * PHI_BINS + p] = sum / (sub * sub) as f64 * (dz * dphi) as f64;
        }
    }
    out
}

#[test]
fn sampled_directions_follow_the_pdf() {
    let n = 200_000usize;
    for (name, b) in cases() {
        for (k, wi) in incoming().into_iter().enumerate() {
            let mut s = Sampler::new(11, Stream::Camera, k as u64, 0);
            let mut counts = vec![0f64; THETA_BINS * PHI_BINS];
            for _ in 0..n {
                let u1 = s.next_1d();
                if let Some(bs) = b.sample(UV, wi, u1, s.next_2d(), TransportMode::Radiance)
                    && !bs.delta
                {
                    counts[bin_of(bs.wo)] += 1.0;
                }
            }
            let expected: Vec<f64> = expected_probabilities(&b, wi)
                .iter()
                .map(|p| p * n as f64)
                .collect();
            // Pool bins with few expected samples, as the chi-square test requires.
            let (mut chi2, mut dof, mut pool_o, mut pool_e) = (0.0f64, 0usize, 0.0f64, 0.0f64);
            for (o, e) in counts.iter().zip(&expected) {
                if *e < 5.0 {
                    pool_o += o;
                    pool_e += e;
                } else {
                    chi2 += (o - e).powi(2) / e;
                    dof += 1;
                }
            }
            if pool_e >= 5.0 {
                chi2 += (pool_o - pool_e).powi(2) / pool_e;
                dof += 1;
            } else {
                assert!(
                    pool_o < 20.0,
                    "{name}, wi {wi}: {pool_o} samples where the pdf expects {pool_e}"
                );
            }
            if dof == 0 {
                continue; // Nothing smooth to test from this side (a one-sided material from below).
            }
            // Far in the tail: p < 1e-6 by the Wilson–Hilferty approximation.
            let dof_f = (dof - 1).max(1) as f64;
            let limit = dof_f * (1.0 - 2.0 / (9.0 * dof_f) + 4.75 * (2.0 / (9.0 * dof_f)).sqrt()).powi(3);
            assert!(
                chi2 < limit,
                "{name}, wi {wi}: chi2 {chi2:.1} over {dof} bins (limit {limit:.1})"
            );
        }
    }
}

#[test]
fn sample_weights_equal_eval_over_pdf() {
    for (name, b) in cases() {
        for (k, wi) in incoming().into_iter().enumerate() {
            let mut s = Sampler::new(12, Stream::Camera, k as u64, 0);
            for _ in 0..2000 {
                let u1 = s.next_1d();
                let Some(bs) = b.sample(UV, wi, u1, s.next_2d(), TransportMode::Radiance) else {
                    continue;
                };
                if bs.delta {
                    continue;
                }
                let expect = b.eval(UV, wi, bs.wo) / b.pdf(UV, wi, bs.wo);
                let err = (bs.weight - expect).abs().max_element() / expect.max_element().max(1e-3);
                assert!(err < 1e-3, "{name}: weight {} but eval/pdf {}", bs.weight, expect);
            }
        }
    }
}

#[test]
fn reflection_is_reciprocal() {
    let mut s = Sampler::new(13, Stream::Camera, 0, 0);
    for (name, b) in cases() {
        for _ in 0..500 {
            let a = crate::sampling::square_to_cosine_hemisphere(s.next_2d());
            let c = crate::sampling::square_to_cosine_hemisphere(s.next_2d());
            if a.z < 1e-3 || c.z < 1e-3 {
                continue;
            }
            let f_ac = b.eval(UV, a, c) / c.z;
            let f_ca = b.eval(UV, c, a) / a.z;
            let scale = f_ac.max_element().max(f_ca.max_element()).max(1e-4);
            assert!(
                (f_ac - f_ca).abs().max_element() / scale < 1e-3,
                "{name}: f({a}, {c}) = {f_ac} but f({c}, {a}) = {f_ca}"
            );
        }
    }
}

#[test]
fn white_furnace_never_creates_energy() {
    let mut all = cases();
    all.push(("white diffuse", diffuse(1.0)));
    all.push(("white rough plastic", plastic(Some(0.3), 1.0)));
    all.push(("smooth gold", conductor(None)));
    all.push(("glass", glass()));
    all.push((
        "thin glass",
        Bsdf::ThinDielectric(ThinDielectric {
            eta: 1.5,
            specular_reflectance: Rgb::ONE.into(),
            specular_transmittance: Rgb::ONE.into(),
        }),
    ));
    all.push((
        "mask over mirror",
        Bsdf::Mask(Box::new((conductor(None), 0.4.into()))),
    ));
    all.push((
        "mirror",
        Bsdf::Conductor(Conductor {
            eta: Rgb::ZERO,
            k: Rgb::ONE,
            specular: Rgb::ONE.into(),
            roughness: None,
        }),
    ));
    let n = 100_000;
    for (name, b) in all {
        for (k, wi) in incoming().into_iter().enumerate() {
            let mut s = Sampler::new(14, Stream::Camera, k as u64, 0);
            let mut sum = Rgb::ZERO;
            for _ in 0..n {
                let u1 = s.next_1d();
                // Importance transport: no radiance compression, so albedo is energy.
                if let Some(bs) = b.sample(UV, wi, u1, s.next_2d(), TransportMode::Importance) {
                    sum += bs.weight;
                }
            }
            let albedo = sum / n as f32;
            assert!(albedo.max_element() <= 1.01, "{name}, wi {wi}: albedo {albedo}");
            let lossless = matches!(name, "white diffuse" | "mirror") && wi.z > 0.0
                || matches!(name, "glass" | "thin glass");
            if lossless {
                assert!(
                    (albedo - Rgb::ONE).abs().max_element() < 0.01,
                    "{name}, wi {wi}: albedo {albedo}"
                );
            }
        }
    }
}

#[test]
fn smooth_lobes_have_no_density() {
    let wi = Vec3A::new(0.0, 0.6, 0.8);
    assert_eq!(glass().pdf(UV, wi, Vec3A::Z), 0.0);
    assert_eq!(
        conductor(None).eval(UV, wi, Vec3A::new(0.0, -0.6, 0.8)),
        Rgb::ZERO
    );
    let s = glass()
        .sample(UV, wi, 0.99, Vec2::ZERO, TransportMode::Radiance)
        .unwrap();
    assert!(s.delta && s.wo.z < 0.0);
}
