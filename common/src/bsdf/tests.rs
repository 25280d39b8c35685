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
        roughness: alpha.map(|alpha| Roughness::isotropic(distribution, alpha.into())),
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
        alpha.map(|alpha| Microfacet::isotropic(distribution, alpha)),
    )))
}

/// Where the tests evaluate textured parameters.
const UV: SurfaceAt = SurfaceAt::flat(Vec2::new(0.3, 0.7));

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
    c.roughness = Some(Roughness::isotropic(
        Distribution::Ggx,
        Param::Textured(std::sync::Arc::new(Texture::Bitmap(bitmap))),
    ));
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
        roughness: Roughness::isotropic(distribution, alpha.into()),
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

/// A principled BSDF with Mitsuba's defaults, to be adjusted.
fn principled_default() -> Principled {
    Principled {
        base_color: Rgb::splat(0.5).into(),
        roughness: 0.5.into(),
        anisotropic: 0.0.into(),
        metallic: 0.0.into(),
        spec_trans: 0.0.into(),
        spec_tint: 0.0.into(),
        sheen: 0.0.into(),
        sheen_tint: 0.0.into(),
        flatness: 0.0.into(),
        clearcoat: 0.0.into(),
        clearcoat_gloss: 0.0.into(),
        eta: eta_from_specular(0.5),
        diffuse_sampling_rate: 1.0,
        specular_sampling_rate: 1.0,
        clearcoat_sampling_rate: 1.0,
    }
}

fn principled(f: impl FnOnce(&mut Principled)) -> Bsdf {
    let mut p = principled_default();
    f(&mut p);
    Bsdf::Principled(Box::new(p))
}

/// Principled materials: every lobe, alone and together. The transmissive ones are seen from
/// both sides (their `wi` below the surface is inside the material); the opaque ones sample
/// nothing from below, and the chi-square test skips that side.
fn principled_cases() -> Vec<(&'static str, Bsdf)> {
    vec![
        ("principled default", principled(|_| {})),
        (
            "principled dielectric-like",
            principled(|p| {
                p.base_color = Rgb::new(0.8, 0.3, 0.2).into();
                p.roughness = 0.3.into();
                p.eta = 1.5;
                p.spec_tint = 0.4.into();
            }),
        ),
        (
            "principled metal",
            principled(|p| {
                p.base_color = Rgb::new(0.9, 0.6, 0.3).into();
                p.metallic = 1.0.into();
                p.roughness = 0.4.into();
            }),
        ),
        (
            "principled rough anisotropic half metal",
            principled(|p| {
                p.base_color = Rgb::new(0.3, 0.5, 0.8).into();
                p.metallic = 0.5.into();
                p.roughness = 0.6.into();
                p.anisotropic = 0.8.into();
            }),
        ),
        (
            "principled sheen and clearcoat",
            principled(|p| {
                p.base_color = Rgb::new(0.2, 0.6, 0.3).into();
                p.roughness = 0.7.into();
                p.sheen = 1.0.into();
                p.sheen_tint = 0.5.into();
                p.clearcoat = 1.0.into();
                p.clearcoat_gloss = 0.3.into();
                p.flatness = 0.5.into();
            }),
        ),
        (
            "principled spec_trans",
            principled(|p| {
                p.base_color = Rgb::new(0.9, 0.9, 0.7).into();
                p.roughness = 0.4.into();
                p.spec_trans = 0.8.into();
                p.eta = 1.5;
            }),
        ),
        (
            "principled anisotropic glass with everything",
            principled(|p| {
                p.base_color = Rgb::new(0.7, 0.8, 0.9).into();
                p.roughness = 0.5.into();
                p.anisotropic = 0.6.into();
                p.spec_trans = 1.0.into();
                p.metallic = 0.2.into();
                p.spec_tint = 0.3.into();
                p.sheen = 0.5.into();
                p.clearcoat = 0.5.into();
                p.clearcoat_gloss = 0.8.into();
                p.eta = 1.33;
                p.specular_sampling_rate = 2.0;
                p.clearcoat_sampling_rate = 0.5;
                p.diffuse_sampling_rate = 0.5;
            }),
        ),
        (
            // Textures at the test's (u, v): the base colour and metallic from a checkerboard.
            "textured principled",
            principled(|p| {
                let checker = |a: f32, b: f32| {
                    std::sync::Arc::new(crate::texture::Texture::Checkerboard {
                        color0: Rgb::splat(a),
                        color1: Rgb::splat(b),
                        to_uv: glam::Affine2::IDENTITY,
                    })
                };
                p.base_color = Param::Textured(checker(0.2, 0.7));
                p.metallic = Param::Textured(checker(0.3, 0.6));
                p.spec_trans = Param::Textured(checker(0.5, 0.0));
                p.roughness = 0.45.into();
            }),
        ),
    ]
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
        (
            // Through a blend, importance transport must reach the principled's transmission.
            "blend diffuse/transmissive principled",
            Bsdf::Blend(
                Box::new((
                    diffuse(0.6),
                    principled(|p| {
                        p.spec_trans = 0.9.into();
                        p.roughness = 0.5.into();
                        p.eta = 1.5;
                    }),
                )),
                0.5.into(),
            ),
        ),
    ]
    .into_iter()
    .chain(principled_cases())
    .collect()
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
    let phi = libm::atan2f(w.y, w.x) + PI;
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
                    let wo = Vec3A::new(s * libm::cosf(phi), s * libm::sinf(phi), z);
                    sum += b.pdf(&UV, wi, wo) as f64;
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
    for (name, b) in cases().into_iter().chain(perturbed_cases()) {
        for (k, wi) in incoming().into_iter().enumerate() {
            let mut s = Sampler::new(11, Stream::Camera, k as u64, 0);
            let mut counts = vec![0f64; THETA_BINS * PHI_BINS];
            for _ in 0..n {
                let u1 = s.next_1d();
                if let Some(bs) = b.sample(&UV, wi, u1, s.next_2d(), TransportMode::Radiance)
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
    for (name, b) in cases().into_iter().chain(perturbed_cases()) {
        for mode in [TransportMode::Radiance, TransportMode::Importance] {
            for (k, wi) in incoming().into_iter().enumerate() {
                let mut s = Sampler::new(12, Stream::Camera, k as u64, 0);
                for _ in 0..2000 {
                    let u1 = s.next_1d();
                    let Some(bs) = b.sample(&UV, wi, u1, s.next_2d(), mode) else {
                        continue;
                    };
                    if bs.delta {
                        continue;
                    }
                    let expect = b.eval_mode(&UV, wi, bs.wo, mode) / b.pdf(&UV, wi, bs.wo);
                    let err = (bs.weight - expect).abs().max_element() / expect.max_element().max(1e-3);
                    assert!(
                        err < 1e-3,
                        "{name}, {mode:?}: weight {} but eval/pdf {}",
                        bs.weight,
                        expect
                    );
                }
            }
        }
    }
}

/// Materials under normal and bump maps, whose tilted frames vary over the test's (u, v). They
/// are not reciprocal (Mitsuba flips a normal by `wi`'s side and dims by `wo` alone), so the
/// reciprocity test leaves them out.
fn perturbed_cases() -> Vec<(&'static str, Bsdf)> {
    use crate::texture::{Bitmap, Filter, Texture, Wrap};
    let bitmap = |w, h, texels: Vec<Rgb>| {
        Bitmap::from_texels(
            w,
            h,
            texels,
            Filter::Bilinear,
            Wrap::Repeat,
            glam::Affine2::IDENTITY,
        )
    };
    let normals = bitmap(
        2,
        2,
        vec![
            Rgb::new(0.8, 0.5, 0.9),
            Rgb::new(0.3, 0.6, 0.9),
            Rgb::new(0.5, 0.2, 0.8),
            Rgb::new(0.6, 0.7, 0.95),
        ],
    );
    let normal_map = |nested: Bsdf| {
        Bsdf::Perturbed(Box::new(Perturbed {
            nested,
            by: Perturbation::Normal(std::sync::Arc::new(Texture::Bitmap(normals.clone()))),
            flip_invalid_normals: true,
            shadowing: true,
        }))
    };
    let heights = bitmap(
        3,
        3,
        [0.1, 0.7, 0.3, 0.9, 0.2, 0.5, 0.4, 0.8, 0.0]
            .map(Rgb::splat)
            .to_vec(),
    );
    vec![
        (
            "normal map over rough plastic",
            normal_map(plastic(Some(0.3), 0.5)),
        ),
        (
            "twosided normal map over rough conductor",
            Bsdf::TwoSided(Box::new((
                normal_map(conductor(Some(0.3))),
                normal_map(conductor(Some(0.3))),
            ))),
        ),
        (
            "bump map over diffuse",
            Bsdf::Perturbed(Box::new(Perturbed {
                nested: diffuse(0.7),
                by: Perturbation::Bump {
                    height: Box::new(heights),
                    scale: 0.05,
                },
                flip_invalid_normals: true,
                shadowing: true,
            })),
        ),
    ]
}

/// Reflection only (both directions above the surface): the principled's lobes all are; its
/// transmission is checked by `principled_transmission_obeys_generalised_reciprocity`.
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
            let f_ac = b.eval(&UV, a, c) / c.z;
            let f_ca = b.eval(&UV, c, a) / a.z;
            let scale = f_ac.max_element().max(f_ca.max_element()).max(1e-4);
            assert!(
                (f_ac - f_ca).abs().max_element() / scale < 1e-3,
                "{name}: f({a}, {c}) = {f_ac} but f({c}, {a}) = {f_ca}"
            );
        }
    }
}

/// Refraction is not reciprocal in the simple sense: for radiance, the transmission lobe obeys
/// f(a, c) / η(a)² = f(c, a) / η(c)², η being the index on each direction's side. This checks
/// the lobe's Jacobian and its radiance scaling together.
#[test]
fn principled_transmission_obeys_generalised_reciprocity() {
    let mut s = Sampler::new(15, Stream::Camera, 0, 0);
    for (name, b) in principled_cases() {
        let Bsdf::Principled(p) = &b else { unreachable!() };
        let mut checked = 0;
        for _ in 0..2000 {
            let a = crate::sampling::square_to_cosine_hemisphere(s.next_2d());
            let c = -crate::sampling::square_to_cosine_hemisphere(s.next_2d());
            if a.z < 1e-3 || c.z > -1e-3 {
                continue;
            }
            let f_ac = b.eval(&UV, a, c) / c.z.abs();
            let f_ca = b.eval(&UV, c, a) / a.z;
            let (lhs, rhs) = (f_ac, f_ca / (p.eta * p.eta));
            let scale = lhs.max_element().max(rhs.max_element());
            if scale > 0.0 {
                checked += 1;
            }
            assert!(
                // Loose: the half vector's denominator η·(wo·h) + wi·h cancels in f32.
                (lhs - rhs).abs().max_element() <= 1e-2 * scale.max(1e-4),
                "{name}: f({a}, {c}) = {f_ac} but f({c}, {a}) / eta^2 = {rhs}"
            );
        }
        let transmits = !matches!(p.spec_trans, Param::Fixed(t) if t == 0.0);
        assert_eq!(checked > 0, transmits, "{name}: {checked} transmitting pairs");
    }
}

/// The principled's albedo (importance transport, the mean sample weight) from each of the
/// tests' incoming directions, against Mitsuba 3.9.1's own `principled` (llvm_ad_rgb, 10⁶
/// samples per direction, the same parameters; rows in the order of `incoming()`): this checks every lobe's value, the lobe
/// selection and the sampling at once, including the anisotropic lobe's orientation.
#[test]
fn principled_albedo_matches_mitsuba() {
    #[rustfmt::skip]
    let mitsuba: [(&str, [[f32; 3]; 6]); 7] = [
        (
            "principled default",
            [
                [0.5404, 0.5404, 0.5404],
                [0.0000, 0.0000, 0.0000],
                [0.5578, 0.5578, 0.5578],
                [0.0000, 0.0000, 0.0000],
                [0.6419, 0.6419, 0.6419],
                [0.0000, 0.0000, 0.0000],
            ],
        ),
        (
            "principled dielectric-like",
            [
                [0.8511, 0.3342, 0.2308],
                [0.0000, 0.0000, 0.0000],
                [0.8684, 0.3529, 0.2499],
                [0.0000, 0.0000, 0.0000],
                [1.0123, 0.5285, 0.4317],
                [0.0000, 0.0000, 0.0000],
            ],
        ),
        (
            "principled metal",
            [
                [0.8693, 0.5795, 0.2898],
                [0.0000, 0.0000, 0.0000],
                [0.8474, 0.5691, 0.2909],
                [0.0000, 0.0000, 0.0000],
                [0.7910, 0.5770, 0.3629],
                [0.0000, 0.0000, 0.0000],
            ],
        ),
        (
            "principled rough anisotropic half metal",
            [
                [0.2702, 0.4407, 0.6965],
                [0.0000, 0.0000, 0.0000],
                [0.2782, 0.4506, 0.7092],
                [0.0000, 0.0000, 0.0000],
                [0.3121, 0.4952, 0.7699],
                [0.0000, 0.0000, 0.0000],
            ],
        ),
        (
            "principled sheen and clearcoat",
            [
                [0.2344, 0.5943, 0.3244],
                [0.0000, 0.0000, 0.0000],
                [0.2617, 0.6699, 0.3638],
                [0.0000, 0.0000, 0.0000],
                [0.3606, 0.8726, 0.4886],
                [0.0000, 0.0000, 0.0000],
            ],
        ),
        (
            "principled spec_trans",
            [
                [0.9456, 0.9456, 0.8199],
                [0.7381, 0.7381, 0.6570],
                [0.9438, 0.9438, 0.8209],
                [0.7344, 0.7344, 0.7257],
                [0.9256, 0.9256, 0.8191],
                [0.6684, 0.6684, 0.6667],
            ],
        ),
        (
            "principled anisotropic glass with everything",
            [
                [0.8019, 0.8649, 0.9252],
                [0.6204, 0.6616, 0.7004],
                [0.7706, 0.8305, 0.8878],
                [0.6139, 0.6292, 0.6436],
                [0.7202, 0.7723, 0.8222],
                [0.6009, 0.6029, 0.6048],
            ],
        ),
    ];
    let n = 200_000;
    let cases = principled_cases();
    for (name, expected) in mitsuba {
        let b = &cases.iter().find(|(c, _)| *c == name).expect("a test case").1;
        for (k, (wi, want)) in incoming().into_iter().zip(expected).enumerate() {
            let mut s = Sampler::new(16, Stream::Camera, k as u64, 0);
            let mut sum = Rgb::ZERO;
            for _ in 0..n {
                let u1 = s.next_1d();
                if let Some(bs) = b.sample(&UV, wi, u1, s.next_2d(), TransportMode::Importance) {
                    sum += bs.weight;
                }
            }
            let albedo = sum / n as f32;
            let want = Rgb::from(want);
            assert!(
                (albedo - want).abs().max_element() < 0.006,
                "{name}, wi {wi}: albedo {albedo}, Mitsuba's {want}"
            );
        }
    }
}

#[test]
fn white_furnace_never_creates_energy() {
    let mut all = cases();
    all.extend(perturbed_cases());
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
                if let Some(bs) = b.sample(&UV, wi, u1, s.next_2d(), TransportMode::Importance) {
                    sum += bs.weight;
                }
            }
            let albedo = sum / n as f32;
            // Burley's model adds its diffuse base to the specular lobe without coupling their
            // energies: at grazing incidence a bright, tinted base reflects a little more than
            // arrives. Mitsuba's own principled does so (albedo 1.012 in red at cos θ = 0.2,
            // see `principled_albedo_matches_mitsuba`), so this one case gets a looser bound.
            let limit = if name == "principled dielectric-like" && wi.z.abs() < 0.3 {
                1.025
            } else {
                1.01
            };
            assert!(albedo.max_element() <= limit, "{name}, wi {wi}: albedo {albedo}");
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

/// `has_delta` says whether samples ever take a delta lobe: a wrong no would lose the hybrid's
/// caustics off that material, a wrong yes would waste its light paths.
#[test]
fn has_delta_says_whether_samples_take_a_delta_lobe() {
    let smooth = [
        ("glass", glass()),
        ("smooth conductor", conductor(None)),
        ("smooth plastic", plastic(None, 0.5)),
        (
            "mask over diffuse",
            Bsdf::Mask(Box::new((diffuse(0.5), 0.6.into()))),
        ),
        (
            "blend of diffuse and smooth conductor",
            Bsdf::Blend(Box::new((diffuse(0.5), conductor(None))), 0.5.into()),
        ),
    ];
    let mut s = Sampler::new(4, Stream::Camera, 0, 0);
    for (name, b) in cases().into_iter().chain(smooth) {
        let mut any_delta = false;
        for wi in incoming() {
            for mode in [TransportMode::Radiance, TransportMode::Importance] {
                for _ in 0..200 {
                    let (u1, u2) = (s.next_1d(), s.next_2d());
                    any_delta |= b.sample(&UV, wi, u1, u2, mode).is_some_and(|bs| bs.delta);
                }
            }
        }
        assert_eq!(any_delta, b.has_delta(), "{name}: has_delta is {}", b.has_delta());
    }
}

#[test]
fn smooth_lobes_have_no_density() {
    let wi = Vec3A::new(0.0, 0.6, 0.8);
    assert_eq!(glass().pdf(&UV, wi, Vec3A::Z), 0.0);
    assert_eq!(
        conductor(None).eval(&UV, wi, Vec3A::new(0.0, -0.6, 0.8)),
        Rgb::ZERO
    );
    let s = glass()
        .sample(&UV, wi, 0.99, Vec2::ZERO, TransportMode::Radiance)
        .unwrap();
    assert!(s.delta && s.wo.z < 0.0);
}
