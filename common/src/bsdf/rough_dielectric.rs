//! Mitsuba's `roughdielectric`: a rough glass interface (Walter et al.'s microfacet model with
//! visible-normal sampling), reflecting and refracting with Fresnel's weights.

use glam::{Vec2, Vec3A};

use super::fresnel::{fresnel_dielectric, half_vector, reflect_about};
use super::microfacet::Roughness;
use super::{BsdfSample, TransportMode};
use crate::color::Rgb;
use crate::texture::{Param, TexAt};

/// A rough dielectric interface. Both sides are glass.
#[derive(Clone, Debug)]
pub struct RoughDielectric {
    /// Interior over exterior index of refraction.
    pub eta: f32,
    /// The microfacets.
    pub roughness: Roughness,
    /// Tint of the reflected light.
    pub specular_reflectance: Param<Rgb>,
    /// Tint of the transmitted light.
    pub specular_transmittance: Param<Rgb>,
}

/// `v` turned into the upper hemisphere when `cos` is negative.
fn mulsign(v: Vec3A, cos: f32) -> Vec3A {
    if cos < 0.0 { -v } else { v }
}

impl RoughDielectric {
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
        let mf = self.roughness.at(uv);
        let wi_up = mulsign(wi, cos_i);
        let m = mf.sample_visible(wi_up, u2);
        let pdf_m = mf.pdf_visible(wi_up, m);
        if pdf_m <= 0.0 {
            return None;
        }
        let (f, cos_t, eta_it, eta_ti) = fresnel_dielectric(wi.dot(m), self.eta);
        let (wo, weight, pdf, eta) = if u1 <= f {
            let wo = reflect_about(wi, m);
            let dwh_dwo = 1.0 / (4.0 * wo.dot(m));
            (
                wo,
                self.specular_reflectance.at(uv),
                pdf_m * f * dwh_dwo.abs(),
                1.0,
            )
        } else {
            let wo = m * (wi.dot(m) * eta_ti + cos_t) - wi * eta_ti;
            // Radiance is compressed into a smaller solid angle entering a denser medium.
            let scale = match mode {
                TransportMode::Radiance => eta_ti * eta_ti,
                TransportMode::Importance => 1.0,
            };
            let denom = wi.dot(m) + eta_it * wo.dot(m);
            let dwh_dwo = eta_it * eta_it * wo.dot(m) / (denom * denom);
            (
                wo,
                self.specular_transmittance.at(uv) * scale,
                pdf_m * (1.0 - f) * dwh_dwo.abs(),
                eta_it,
            )
        };
        let weight = weight * mf.g1(wo, m);
        (pdf > 0.0 && pdf.is_finite() && weight != Rgb::ZERO).then_some(BsdfSample {
            wo,
            weight,
            pdf,
            delta: false,
            eta,
        })
    }

    /// f · |cos θo|; transmission is scaled for radiance as in [`RoughDielectric::sample`].
    pub(super) fn eval(&self, uv: &TexAt, wi: Vec3A, wo: Vec3A, mode: TransportMode) -> Rgb {
        let cos_i = wi.z;
        if cos_i == 0.0 {
            return Rgb::ZERO;
        }
        let Some((m, reflect, eta)) = half_vector(wi, wo, self.eta) else {
            return Rgb::ZERO;
        };
        let mf = self.roughness.at(uv);
        let d = mf.d(m);
        if d == 0.0 {
            return Rgb::ZERO;
        }
        let f = fresnel_dielectric(wi.dot(m), self.eta).0;
        let g = mf.g(wi, wo, m);
        if reflect {
            self.specular_reflectance.at(uv) * (f * d * g / (4.0 * cos_i.abs()))
        } else {
            let scale = match mode {
                TransportMode::Radiance => 1.0 / (eta * eta),
                TransportMode::Importance => 1.0,
            };
            let denom = wi.dot(m) + eta * wo.dot(m);
            let value =
                scale * (1.0 - f) * d * g * eta * eta * wi.dot(m) * wo.dot(m) / (cos_i * denom * denom);
            self.specular_transmittance.at(uv) * value.abs()
        }
    }

    pub(super) fn pdf(&self, uv: &TexAt, wi: Vec3A, wo: Vec3A) -> f32 {
        let cos_i = wi.z;
        if cos_i == 0.0 {
            return 0.0;
        }
        let Some((m, reflect, eta)) = half_vector(wi, wo, self.eta) else {
            return 0.0;
        };
        // Where the microsurface and the macrosurface disagree on the side, sampling never goes.
        if wi.dot(m) * cos_i <= 0.0 || wo.dot(m) * wo.z <= 0.0 {
            return 0.0;
        }
        let dwh_dwo = if reflect {
            1.0 / (4.0 * wo.dot(m))
        } else {
            let denom = wi.dot(m) + eta * wo.dot(m);
            eta * eta * wo.dot(m) / (denom * denom)
        };
        let mf = self.roughness.at(uv);
        let f = fresnel_dielectric(wi.dot(m), self.eta).0;
        let prob = mf.pdf_visible(mulsign(wi, cos_i), m) * if reflect { f } else { 1.0 - f };
        let pdf = prob * dwh_dwo.abs();
        if pdf.is_finite() { pdf } else { 0.0 }
    }
}
