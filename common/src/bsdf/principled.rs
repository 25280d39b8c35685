//! Mitsuba 3's `principled` BSDF (Burley's Disney BSDF, as Mitsuba 3.9.1 implements it in
//! `src/bsdfs/principled.cpp` and `principledhelpers.h`), in RGB: a diffuse base with
//! Burley's retro-reflection and optional fake subsurface (`flatness`), sheen, an anisotropic GGX
//! specular lobe whose Fresnel term blends a dielectric, a tinted Schlick term and a metallic
//! Schlick term, a rough dielectric transmission lobe (`spec_trans`), and a GTR1 clearcoat.
//!
//! The formulas, the lobe selection probabilities and the sampling follow Mitsuba's code line by
//! line; the comments note where a line looks surprising but is Mitsuba's (the clearcoat has no
//! 1/(4 cos θi cos θo), the sheen has no 1/π).

use std::f32::consts::{FRAC_1_PI, PI};

use glam::{Vec2, Vec3A};

use super::fresnel::{fresnel_dielectric, reflect_about};
use super::microfacet::{Distribution, Microfacet};
use super::{BsdfSample, TransportMode};
use crate::color::{Rgb, luminance};
use crate::sampling::{square_to_cosine_hemisphere, square_to_cosine_hemisphere_pdf};
use crate::texture::{Param, TexAt};

/// The principled BSDF's parameters, each a number or a texture where Mitsuba accepts one.
#[derive(Clone, Debug)]
pub struct Principled {
    /// Colour of the diffuse base, of the metal, of the transmission (its square root) and of
    /// the tints.
    pub base_color: Param<Rgb>,
    /// Roughness of the main specular lobes (GGX alpha = roughness²).
    pub roughness: Param<f32>,
    /// Anisotropy of the main specular lobes (0: isotropic).
    pub anisotropic: Param<f32>,
    /// Weight of the metallic response.
    pub metallic: Param<f32>,
    /// Weight of the transmission lobe against the diffuse base.
    pub spec_trans: Param<f32>,
    /// Fraction of the dielectric reflection tinted towards the base colour.
    pub spec_tint: Param<f32>,
    /// Weight of the sheen lobe.
    pub sheen: Param<f32>,
    /// Fraction of the sheen tinted towards the base colour.
    pub sheen_tint: Param<f32>,
    /// Blend of the diffuse base towards Hanrahan–Krueger's fake subsurface.
    pub flatness: Param<f32>,
    /// Weight of the clearcoat lobe.
    pub clearcoat: Param<f32>,
    /// Glossiness of the clearcoat (GTR1 alpha from 0.1 at 0 to 0.001 at 1).
    pub clearcoat_gloss: Param<f32>,
    /// Interior over exterior index of refraction.
    pub eta: f32,
    /// Relative rate of sampling the diffuse lobe.
    pub diffuse_sampling_rate: f32,
    /// Relative rate of sampling the main specular lobes.
    pub specular_sampling_rate: f32,
    /// Relative rate of sampling the clearcoat.
    pub clearcoat_sampling_rate: f32,
}

/// The parameters at one point.
struct At {
    base: Rgb,
    roughness: f32,
    metallic: f32,
    spec_trans: f32,
    clearcoat: f32,
    dist: Microfacet,
}

impl At {
    /// Weight of the diffuse base (Mitsuba's `brdf`).
    fn brdf(&self) -> f32 {
        (1.0 - self.metallic) * (1.0 - self.spec_trans)
    }

    /// Weight of the transmission lobe (Mitsuba's `bsdf`).
    fn bsdf(&self) -> f32 {
        (1.0 - self.metallic) * self.spec_trans
    }
}

/// The lobes [`Principled::sample`] chooses between, with their probabilities.
struct LobeProbabilities {
    diffuse: f32,
    clearcoat: f32,
    transmission: f32,
    reflection: f32,
}

/// Mitsuba's `specular` parameter as a relative index of refraction: the eta whose normal
/// Fresnel reflectance is 0.08 · specular.
pub fn eta_from_specular(specular: f32) -> f32 {
    2.0 / (1.0 - (0.08 * specular).sqrt()) - 1.0
}

/// Schlick's weight (1 − cos)⁵, with 1 − cos clamped to [0, 1].
fn schlick_weight(cos: f32) -> f32 {
    let m = (1.0 - cos).clamp(0.0, 1.0);
    let m2 = m * m;
    m2 * m2 * m
}

/// Mitsuba's `calc_schlick`: Schlick's approximation with normal reflectance `r0`, using the
/// transmitted angle when light arrives from the denser side.
fn schlick(r0: Rgb, cos_i: f32, eta: f32) -> Rgb {
    let outside = cos_i >= 0.0;
    let (eta_it, eta_ti) = if outside {
        (eta, 1.0 / eta)
    } else {
        (1.0 / eta, eta)
    };
    let w = if eta_it > 1.0 {
        schlick_weight(cos_i.abs())
    } else {
        let cos_t_sqr = 1.0 - (1.0 - cos_i * cos_i) * (eta_ti * eta_ti);
        schlick_weight(cos_t_sqr.max(0.0).sqrt())
    };
    // dr::lerp(w, 1, r0) = w (1 − r0) + r0.
    Rgb::splat(w) * (Rgb::ONE - r0) + r0
}

/// Normal reflectance of a dielectric with relative index `eta`.
fn schlick_r0(eta: f32) -> f32 {
    let r = (eta - 1.0) / (eta + 1.0);
    r * r
}

/// `base / luminance(base)`, or white for a black base.
fn tint(base: Rgb, lum: f32) -> Rgb {
    if lum > 0.0 { base / lum } else { Rgb::ONE }
}

/// Burley's GTR1 distribution of the clearcoat (isotropic, sampled by normals, not visible
/// normals, as in Mitsuba).
struct Gtr1 {
    alpha: f32,
}

impl Gtr1 {
    fn d(&self, m: Vec3A) -> f32 {
        let a2 = self.alpha * self.alpha;
        let c2 = m.z * m.z;
        let d = (a2 - 1.0) / (PI * libm::logf(a2) * (1.0 + (a2 - 1.0) * c2));
        if d * m.z > 1e-20 { d } else { 0.0 }
    }

    fn pdf(&self, m: Vec3A) -> f32 {
        if m.z < 0.0 { 0.0 } else { m.z * self.d(m) }
    }

    fn sample(&self, u: Vec2) -> Vec3A {
        let phi = 2.0 * PI * u.x;
        let a2 = self.alpha * self.alpha;
        let cos2 = (1.0 - libm::powf(a2, 1.0 - u.y)) / (1.0 - a2);
        let sin = (1.0 - cos2).max(0.0).sqrt();
        let cos = cos2.max(0.0).sqrt();
        let (sin_phi, cos_phi) = libm::sincosf(phi);
        Vec3A::new(cos_phi * sin, sin_phi * sin, cos)
    }
}

/// Mitsuba's `smith_ggx1`: the clearcoat's GGX masking with a fixed alpha.
fn smith_ggx1(v: Vec3A, m: Vec3A, alpha: f32) -> f32 {
    if v.dot(m) * v.z <= 0.0 {
        return 0.0;
    }
    if v.z == 1.0 {
        return 1.0;
    }
    let c2 = v.z * v.z;
    let tan2 = (1.0 - c2) / c2;
    2.0 / (1.0 + (1.0 + alpha * alpha * tan2).sqrt())
}

/// Mitsuba's `mac_mic_compatibility`: `wi` (and for reflection `wo`, for refraction `−wo`) on
/// the side of the microfacet `m` that faces the side `wi` arrives from.
fn compatible(m: Vec3A, wi: Vec3A, wo: Vec3A, cos_i: f32, reflection: bool) -> bool {
    let m = if cos_i < 0.0 { -m } else { m };
    wi.dot(m) > 0.0
        && if reflection {
            wo.dot(m) > 0.0
        } else {
            wo.dot(m) < 0.0
        }
}

impl Principled {
    fn at(&self, uv: &TexAt) -> At {
        let roughness = self.roughness.at(uv);
        let anisotropic = self.anisotropic.at(uv).min(1.0);
        // Mitsuba's calc_dist_params.
        let r2 = roughness * roughness;
        let aspect = (1.0 - 0.9 * anisotropic).sqrt();
        let dist = Microfacet {
            distribution: Distribution::Ggx,
            alpha_u: (r2 / aspect).max(0.001),
            alpha_v: (r2 * aspect).max(0.001),
        };
        At {
            base: self.base_color.at(uv),
            roughness,
            metallic: self.metallic.at(uv),
            spec_trans: self.spec_trans.at(uv),
            clearcoat: self.clearcoat.at(uv),
            dist,
        }
    }

    fn clearcoat_distribution(&self, uv: &TexAt) -> Gtr1 {
        let gloss = self.clearcoat_gloss.at(uv);
        // dr::lerp(0.1, 0.001, gloss).
        Gtr1 {
            alpha: 0.1 * (1.0 - gloss) + 0.001 * gloss,
        }
    }

    /// Whether the roughness differs along the two tangents anywhere: only then does the
    /// orientation of the shading frame about the normal matter.
    pub fn is_anisotropic(&self) -> bool {
        !matches!(self.anisotropic, Param::Fixed(a) if a == 0.0)
    }

    /// Whether the diffuse base is present somewhere and nothing is transmitted anywhere: where
    /// SPPM's camera pass may stop and estimate the photons. Transmitted light arrives from
    /// the surface's other side, where a photon estimate does not look.
    pub fn gathers_photons(&self) -> bool {
        let no_transmission = matches!(self.spec_trans, Param::Fixed(t) if t <= 0.0);
        let not_all_metal = !matches!(self.metallic, Param::Fixed(m) if m >= 1.0);
        no_transmission && not_all_metal
    }

    /// The lobe probabilities for `wi` seen against a microfacet with dielectric Fresnel
    /// reflectance `f` (Mitsuba's, normalised; from inside only the two specular lobes).
    fn probabilities(&self, p: &At, front: bool, f: f32) -> Option<LobeProbabilities> {
        let bsdf = p.bsdf();
        let (reflection, transmission, clearcoat, diffuse) = if front {
            (
                self.specular_sampling_rate * (1.0 - bsdf * (1.0 - f)),
                if bsdf > 0.0 {
                    self.specular_sampling_rate * bsdf * (1.0 - f)
                } else {
                    0.0
                },
                if p.clearcoat > 0.0 {
                    0.25 * p.clearcoat * self.clearcoat_sampling_rate
                } else {
                    0.0
                },
                p.brdf() * self.diffuse_sampling_rate,
            )
        } else {
            (f, 1.0 - f, 0.0, 0.0)
        };
        let total = reflection + transmission + clearcoat + diffuse;
        if total.is_nan() || total <= 0.0 {
            return None;
        }
        let inv = 1.0 / total;
        Some(LobeProbabilities {
            diffuse: diffuse * inv,
            clearcoat: clearcoat * inv,
            transmission: transmission * inv,
            reflection: reflection * inv,
        })
    }

    /// The half vector of `wi` and `wo` (oriented to +z) and whether they are on the same side:
    /// None for grazing or degenerate configurations.
    fn half_vector(&self, wi: Vec3A, wo: Vec3A) -> Option<(Vec3A, bool)> {
        super::fresnel::half_vector(wi, wo, self.eta).map(|(m, reflect, _)| (m, reflect))
    }

    pub(super) fn sample(
        &self,
        uv: &TexAt,
        wi: Vec3A,
        u1: f32,
        u2: Vec2,
        mode: TransportMode,
    ) -> Option<BsdfSample> {
        let cos_i = wi.z;
        if cos_i == 0.0 {
            return None;
        }
        let p = self.at(uv);
        let front = cos_i > 0.0;
        // Opaque from below unless something is transmitted.
        if !front && p.bsdf() <= 0.0 {
            return None;
        }
        let wi_up = if front { wi } else { -wi };
        let m = p.dist.sample_visible(wi_up, u2);
        let (f, cos_t, eta_it, eta_ti) = fresnel_dielectric(wi.dot(m), self.eta);
        let probs = self.probabilities(&p, front, f)?;
        let (wo, eta) = if u1 < probs.diffuse {
            let wo = square_to_cosine_hemisphere(u2);
            if cos_i * wo.z <= 0.0 {
                return None;
            }
            (wo, 1.0)
        } else if u1 < probs.diffuse + probs.clearcoat {
            let m = self.clearcoat_distribution(uv).sample(u2);
            let wo = reflect_about(wi, m);
            if !(compatible(m, wi, wo, cos_i, true) && cos_i * wo.z > 0.0) {
                return None;
            }
            (wo, 1.0)
        } else if u1 < probs.diffuse + probs.clearcoat + probs.transmission {
            let wo = m * (wi.dot(m) * eta_ti + cos_t) - wi * eta_ti;
            if !(compatible(m, wi, wo, cos_i, false) && cos_i * wo.z < 0.0) {
                return None;
            }
            (wo, eta_it)
        } else {
            let wo = reflect_about(wi, m);
            if !(compatible(m, wi, wo, cos_i, true) && cos_i * wo.z > 0.0) {
                return None;
            }
            (wo, 1.0)
        };
        let pdf = self.pdf(uv, wi, wo);
        if pdf.is_nan() || pdf <= 0.0 {
            return None;
        }
        let weight = self.eval(uv, wi, wo, mode) / pdf;
        weight.is_finite().then_some(BsdfSample {
            wo,
            weight,
            pdf,
            delta: false,
            eta,
        })
    }

    /// f · |cos θo|; refraction scales radiance, not importance, by 1/η².
    pub(super) fn eval(&self, uv: &TexAt, wi: Vec3A, wo: Vec3A, mode: TransportMode) -> Rgb {
        let (cos_i, cos_o) = (wi.z, wo.z);
        if cos_i == 0.0 {
            return Rgb::ZERO;
        }
        let Some((wh, reflect)) = self.half_vector(wi, wo) else {
            return Rgb::ZERO;
        };
        let p = self.at(uv);
        let (brdf, bsdf) = (p.brdf(), p.bsdf());
        let front = cos_i > 0.0;
        let eta_path = if front { self.eta } else { 1.0 / self.eta };
        let wi_h = wi.dot(wh);
        let wo_h = wo.dot(wh);
        let f_dielectric = fresnel_dielectric(wi_h, self.eta).0;
        let d = p.dist.d(wh);
        let g = p.dist.g(wi, wo, wh);
        let mut value = Rgb::ZERO;

        if reflect && compatible(wh, wi, wo, cos_i, true) && f_dielectric > 0.0 {
            // Mitsuba's principled_fresnel.
            let spec_tint = self.spec_tint.at(uv);
            let f = if front {
                let lum = luminance(p.base);
                let eta_it = if wi_h >= 0.0 { self.eta } else { 1.0 / self.eta };
                let metal = p.metallic * schlick(p.base, wi_h, self.eta);
                let tinted = (1.0 - p.metallic)
                    * spec_tint
                    * schlick(tint(p.base, lum) * schlick_r0(eta_it), wi_h, self.eta);
                Rgb::splat((1.0 - p.metallic) * (1.0 - spec_tint) * f_dielectric) + metal + tinted
            } else {
                Rgb::splat(bsdf * f_dielectric)
            };
            value += f * (d * g / (4.0 * cos_i.abs()));
        }

        if !reflect && bsdf > 0.0 && compatible(wh, wi, wo, cos_i, false) && f_dielectric < 1.0 {
            // Radiance is compressed into a smaller solid angle when it enters a denser medium;
            // importance is not.
            let scale = match mode {
                TransportMode::Radiance => 1.0 / (eta_path * eta_path),
                TransportMode::Importance => 1.0,
            };
            let denom = wi_h + eta_path * wo_h;
            let t = (scale * (1.0 - f_dielectric) * d * g * eta_path * eta_path * wi_h * wo_h
                / (cos_i * denom * denom))
                .abs();
            value += p.base.max(Rgb::ZERO).powf(0.5) * (bsdf * t);
        }

        if reflect && front && p.clearcoat > 0.0 && compatible(wh, wi, wo, cos_i, true) {
            let fcc = schlick(Rgb::splat(0.04), wi_h, self.eta).x;
            let dcc = self.clearcoat_distribution(uv).d(wh);
            let gcc = smith_ggx1(wi, wh, 0.25) * smith_ggx1(wo, wh, 0.25);
            // As in Mitsuba: no 1 / (4 cos θi cos θo).
            value += Rgb::splat(p.clearcoat * 0.25 * fcc * dcc * gcc * cos_o.abs());
        }

        if reflect && front {
            let (ao, ai) = (cos_o.abs(), cos_i.abs());
            let fo = schlick_weight(ao);
            let fi = schlick_weight(ai);
            let cos_d = wh.dot(wo);
            if brdf > 0.0 {
                let f_diff = (1.0 - 0.5 * fi) * (1.0 - 0.5 * fo);
                let rr = 2.0 * p.roughness * cos_d * cos_d;
                let f_retro = rr * (fo + fi + fo * fi * (rr - 1.0));
                let flatness = self.flatness.at(uv);
                let shape = if flatness != 0.0 {
                    let fss90 = rr / 2.0;
                    let fss = ((1.0 - fo) + fss90 * fo) * ((1.0 - fi) + fss90 * fi);
                    let f_ss = 1.25 * (fss * (1.0 / (ao + ai) - 0.5) + 0.5);
                    (f_diff + f_retro) * (1.0 - flatness) + f_ss * flatness
                } else {
                    f_diff + f_retro
                };
                value += p.base * (brdf * ao * FRAC_1_PI * shape);
            }
            // The sheen does not require the diffuse base: in Mitsuba's vectorised variants
            // (llvm_ad_rgb, the references' variant), the sheen's block runs whatever the
            // diffuse mask, so a fully transmissive principled still has its sheen.
            let sheen = self.sheen.at(uv);
            if sheen > 0.0 && 1.0 - p.metallic > 0.0 {
                let fd = schlick_weight(cos_d.abs());
                let sheen_tint = self.sheen_tint.at(uv);
                let c = if sheen_tint != 0.0 {
                    let c_tint = tint(p.base, luminance(p.base));
                    Rgb::splat(1.0 - sheen_tint) + c_tint * sheen_tint
                } else {
                    Rgb::ONE
                };
                // As in Mitsuba: no 1/π.
                value += c * (sheen * (1.0 - p.metallic) * fd * ao);
            }
        }
        value
    }

    pub(super) fn pdf(&self, uv: &TexAt, wi: Vec3A, wo: Vec3A) -> f32 {
        let cos_i = wi.z;
        if cos_i == 0.0 {
            return 0.0;
        }
        let p = self.at(uv);
        let front = cos_i > 0.0;
        // Mitsuba's pdf does not vanish from below on an opaque principled, but its sample
        // returns nothing there and its eval is zero: the density of what is sampled is 0.
        if !front && p.bsdf() <= 0.0 {
            return 0.0;
        }
        let Some((wh, reflect)) = self.half_vector(wi, wo) else {
            return 0.0;
        };
        let eta_path = if front { self.eta } else { 1.0 / self.eta };
        let f = fresnel_dielectric(wi.dot(wh), self.eta).0;
        let Some(probs) = self.probabilities(&p, front, f) else {
            return 0.0;
        };
        let wo_h = wo.dot(wh);
        let dwh_dwo = if reflect {
            (1.0 / (4.0 * wo_h)).abs()
        } else {
            let denom = wi.dot(wh) + eta_path * wo_h;
            (eta_path * eta_path * wo_h / (denom * denom)).abs()
        };
        let wi_up = if front { wi } else { -wi };
        let mut pdf = 0.0;
        if reflect {
            pdf += probs.diffuse * square_to_cosine_hemisphere_pdf(wo);
            if compatible(wh, wi, wo, cos_i, true) {
                pdf += probs.reflection * p.dist.pdf_visible(wi_up, wh) * dwh_dwo;
                if probs.clearcoat > 0.0 {
                    pdf += probs.clearcoat * self.clearcoat_distribution(uv).pdf(wh) * dwh_dwo;
                }
            }
        } else if probs.transmission > 0.0 && compatible(wh, wi, wo, cos_i, false) {
            pdf += probs.transmission * p.dist.pdf_visible(wi_up, wh) * dwh_dwo;
        }
        if pdf.is_finite() { pdf } else { 0.0 }
    }
}
