use std::f32::consts::FRAC_1_PI;
use std::sync::Arc;

use glam::{Vec2, Vec3A};
use rayon::prelude::*;

use super::BsdfSample;
use super::fresnel::{diffuse_fresnel_reflectance, fresnel_dielectric, reflect, reflect_about};
use super::microfacet::Microfacet;
use crate::color::Rgb;
use crate::sampling::{square_to_cosine_hemisphere, square_to_cosine_hemisphere_pdf};
use crate::texture::{Param, TexAt};

/// Diffuse base under a dielectric coating (Mitsuba's `plastic` and `roughplastic`).
///
/// Light either reflects off the coating (Fresnel-weighted, smooth or GGX) or enters it,
/// scatters diffusely with internal reflections at the coating, and leaves again.
#[derive(Clone, Debug)]
pub struct Plastic {
    /// Albedo of the base.
    pub diffuse: Param<Rgb>,
    /// Tint of the coating's reflection.
    pub specular: Param<Rgb>,
    /// Coating over exterior index of refraction.
    pub eta: f32,
    /// Mitsuba's `nonlinear`: account for the darkening of the base's colour by internal
    /// reflections.
    pub nonlinear: bool,
    /// None for the smooth coating.
    pub roughness: Option<Microfacet>,
    /// Probability weight of sampling the coating, from the mean reflectances (as Mitsuba).
    specular_weight: f32,
    coating: Coating,
}

/// What the coating passes and reflects back inside, which depends on its roughness and index
/// alone: scenes give many materials one coating (the staircase six of two), and integrating
/// a rough one took some 10% of its load, so the scene builder computes each once.
#[derive(Clone, Debug)]
pub struct Coating {
    /// The coating's roughness, none where smooth.
    roughness: Option<Microfacet>,
    /// Its relative index of refraction.
    eta: f32,
    /// Fraction of the diffuse light that the coating reflects back inside.
    internal_reflectance: f32,
    /// Rough coating only: transmittance into the coating against cos θ, 0..=1 in equal steps.
    transmittance_table: Arc<[f32]>,
}

impl Coating {
    /// The coating of index `eta`, smooth or of the given roughness; a rough one's
    /// transmittance is integrated numerically here.
    pub fn new(roughness: Option<Microfacet>, eta: f32) -> Coating {
        match roughness {
            None => Coating {
                roughness,
                eta,
                internal_reflectance: diffuse_fresnel_reflectance(1.0 / eta),
                transmittance_table: Arc::new([]),
            },
            Some(mf) => {
                // Mitsuba's tables: cos θ at 64 equal steps from 0 to 1 (0 nudged to 1e-6).
                let mus: Vec<f32> = (0..TABLE_SIZE)
                    .map(|i| (i as f32 / (TABLE_SIZE - 1) as f32).max(1e-6))
                    .collect();
                // Each entry on its own thread (a million microfacet normals a coating, the
                // scene's load waits for them); the sum below adds them in order, as before.
                let table: Vec<f32> = mus
                    .par_iter()
                    .map(|&mu| rough_transmittance(mf, eta, mu))
                    .collect();
                // Internal: light leaving the base meets the coating from inside (eta inverted),
                // averaged over the cosine-weighted hemisphere.
                let internal: Vec<f32> = mus
                    .par_iter()
                    .map(|&mu| rough_reflectance(mf, 1.0 / eta, mu) * mu)
                    .collect();
                let sum: f32 = internal.iter().sum();
                Coating {
                    roughness,
                    eta,
                    internal_reflectance: 2.0 * sum / TABLE_SIZE as f32,
                    transmittance_table: table.into(),
                }
            }
        }
    }
}

const TABLE_SIZE: usize = 64;

impl Plastic {
    /// A plastic with its own coating (see [`Coating`] for sharing one).
    pub fn new(
        diffuse: Param<Rgb>,
        specular: Param<Rgb>,
        eta: f32,
        nonlinear: bool,
        roughness: Option<Microfacet>,
    ) -> Self {
        Self::with_coating(diffuse, specular, nonlinear, Coating::new(roughness, eta))
    }

    /// A plastic whose coating is already computed: its roughness and index are the coating's.
    pub fn with_coating(
        diffuse: Param<Rgb>,
        specular: Param<Rgb>,
        nonlinear: bool,
        coating: Coating,
    ) -> Self {
        // From the textures' means, as Mitsuba does: the sampling weights do not vary.
        let (d, s) = (diffuse.mean(), specular.mean());
        let specular_weight = if d + s > 0.0 { s / (d + s) } else { 0.5 };
        Plastic {
            diffuse,
            specular,
            eta: coating.eta,
            nonlinear,
            roughness: coating.roughness,
            specular_weight,
            coating,
        }
    }

    /// Fraction of light arriving at cos θ that passes the coating.
    fn transmittance(&self, cos: f32) -> f32 {
        if self.roughness.is_none() {
            return 1.0 - fresnel_dielectric(cos, self.eta).0;
        }
        let x = cos.clamp(0.0, 1.0) * (TABLE_SIZE - 1) as f32;
        let i = (x as usize).min(TABLE_SIZE - 2);
        let f = x - i as f32;
        let table = &self.coating.transmittance_table;
        table[i] * (1.0 - f) + table[i + 1] * f
    }

    /// What the lane engine's plastic needs besides the public fields: the probability weight
    /// of the coating, the coating's internal reflectance and its transmittance table.
    pub(crate) fn coating_parts(&self) -> (f32, f32, &Arc<[f32]>) {
        (
            self.specular_weight,
            self.coating.internal_reflectance,
            &self.coating.transmittance_table,
        )
    }

    /// Whether two plastics use one computed coating (the scene builder shares them).
    #[cfg(test)]
    pub(crate) fn shares_coating(&self, other: &Plastic) -> bool {
        Arc::ptr_eq(
            &self.coating.transmittance_table,
            &other.coating.transmittance_table,
        )
    }

    fn diffuse_eval(&self, uv: &TexAt, wi: Vec3A, wo: Vec3A) -> Rgb {
        let diffuse = self.diffuse.at(uv);
        let base = if self.nonlinear {
            diffuse / (Rgb::ONE - diffuse * self.coating.internal_reflectance)
        } else {
            diffuse / (1.0 - self.coating.internal_reflectance)
        };
        let inv_eta2 = 1.0 / (self.eta * self.eta);
        base * (self.transmittance(wi.z) * self.transmittance(wo.z) * FRAC_1_PI * inv_eta2 * wo.z)
    }

    fn lobe_probabilities(&self, wi: Vec3A) -> (f32, f32) {
        let t = self.transmittance(wi.z);
        let ps = (1.0 - t) * self.specular_weight;
        let pd = t * (1.0 - self.specular_weight);
        if ps + pd <= 0.0 {
            return (0.0, 1.0);
        }
        (ps / (ps + pd), pd / (ps + pd))
    }

    pub(super) fn sample(&self, uv: &TexAt, wi: Vec3A, u1: f32, u2: Vec2) -> Option<BsdfSample> {
        if wi.z <= 0.0 {
            return None;
        }
        let (ps, pd) = self.lobe_probabilities(wi);
        match self.roughness {
            None if u1 < ps => {
                let f = fresnel_dielectric(wi.z, self.eta).0;
                Some(BsdfSample {
                    wo: reflect(wi),
                    weight: self.specular.at(uv) * (f / ps),
                    pdf: ps,
                    delta: true,
                    eta: 1.0,
                })
            }
            None => {
                let wo = square_to_cosine_hemisphere(u2);
                let pdf = pd * square_to_cosine_hemisphere_pdf(wo);
                (pdf > 0.0).then(|| BsdfSample {
                    wo,
                    weight: self.diffuse_eval(uv, wi, wo) / pdf,
                    pdf,
                    delta: false,
                    eta: 1.0,
                })
            }
            Some(ggx) => {
                let wo = if u1 < ps {
                    reflect_about(wi, ggx.sample_visible(wi, u2))
                } else {
                    square_to_cosine_hemisphere(u2)
                };
                if wo.z <= 0.0 {
                    return None;
                }
                let pdf = self.pdf(wi, wo);
                (pdf > 0.0).then(|| BsdfSample {
                    wo,
                    weight: self.eval(uv, wi, wo) / pdf,
                    pdf,
                    delta: false,
                    eta: 1.0,
                })
            }
        }
    }

    pub(super) fn eval(&self, uv: &TexAt, wi: Vec3A, wo: Vec3A) -> Rgb {
        if wi.z <= 0.0 || wo.z <= 0.0 {
            return Rgb::ZERO;
        }
        let mut value = self.diffuse_eval(uv, wi, wo);
        if let Some(ggx) = self.roughness {
            let m = (wi + wo).normalize();
            let f = fresnel_dielectric(wi.dot(m), self.eta).0;
            value += self.specular.at(uv) * (f * ggx.d(m) * ggx.g(wi, wo, m) / (4.0 * wi.z));
        }
        value
    }

    pub(super) fn pdf(&self, wi: Vec3A, wo: Vec3A) -> f32 {
        if wi.z <= 0.0 || wo.z <= 0.0 {
            return 0.0;
        }
        let (ps, pd) = self.lobe_probabilities(wi);
        let mut pdf = pd * square_to_cosine_hemisphere_pdf(wo);
        if let Some(ggx) = self.roughness {
            let m = (wi + wo).normalize();
            let wo_m = wo.dot(m);
            if wo_m > 0.0 {
                pdf += ps * ggx.pdf_visible(wi, m) / (4.0 * wo_m);
            }
        }
        pdf
    }
}

/// Quadrature points per axis over the visible-normal sample square: Mitsuba's counts (a
/// coating seen from outside varies slowly; from inside, total internal reflection makes the
/// integrand steep).
fn quadrature_points(eta: f32) -> usize {
    if eta > 1.0 { 32 } else { 128 }
}

/// The mean over visible microfacet normals (sampled from a grid on the unit square, so that
/// any roughness, however small, is integrated accurately) of `f(m)`.
fn visible_normal_mean(mf: Microfacet, mu: f32, eta: f32, f: impl Fn(Vec3A, Vec3A) -> f32) -> f32 {
    let wi = Vec3A::new((1.0 - mu * mu).max(0.0).sqrt(), 0.0, mu);
    let n = quadrature_points(eta);
    let mut sum = 0.0f64;
    for i in 0..n {
        for j in 0..n {
            let u = Vec2::new((i as f32 + 0.5) / n as f32, (j as f32 + 0.5) / n as f32);
            sum += f(wi, mf.sample_visible(wi, u)) as f64;
        }
    }
    (sum / (n * n) as f64) as f32
}

/// Fraction of light arriving at cos θ = `mu` that a rough dielectric interface (relative index
/// `eta`) transmits, counting the refracted light's masking: Mitsuba's `eval_transmittance`.
fn rough_transmittance(mf: Microfacet, eta: f32, mu: f32) -> f32 {
    visible_normal_mean(mf, mu, eta, |wi, m| {
        let cos_im = wi.dot(m);
        let (f, cos_t, _, eta_ti) = fresnel_dielectric(cos_im, eta);
        let wt = m * (cos_im * eta_ti + cos_t) - wi * eta_ti;
        (1.0 - f) * mf.g1(wt, m)
    })
}

/// Fraction of light arriving at cos θ = `mu` that a rough dielectric interface reflects,
/// counting the reflected light's masking: Mitsuba's `eval_reflectance`.
fn rough_reflectance(mf: Microfacet, eta: f32, mu: f32) -> f32 {
    visible_normal_mean(mf, mu, eta, |wi, m| {
        let f = fresnel_dielectric(wi.dot(m), eta).0;
        f * mf.g1(reflect_about(wi, m), m)
    })
}
