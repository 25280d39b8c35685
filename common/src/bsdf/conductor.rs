use glam::{Vec2, Vec3A};

use super::BsdfSample;
use super::fresnel::{fresnel_conductor, reflect, reflect_about};
use super::microfacet::Roughness;
use crate::color::Rgb;
use crate::texture::{Param, TexAt};

/// A metal: smooth (a perfect mirror with conductor Fresnel) or rough (GGX).
#[derive(Clone, Debug)]
pub struct Conductor {
    /// Real part of the complex index of refraction.
    pub eta: Rgb,
    /// Imaginary part (absorption).
    pub k: Rgb,
    /// Extra tint, Mitsuba's `specular_reflectance`.
    pub specular: Param<Rgb>,
    /// None for the smooth mirror.
    pub roughness: Option<Roughness>,
}

impl Conductor {
    fn fresnel(&self, uv: &TexAt, cos: f32) -> Rgb {
        self.specular.at(uv) * fresnel_conductor(cos, self.eta, self.k)
    }

    pub(super) fn sample(&self, uv: &TexAt, wi: Vec3A, u: Vec2) -> Option<BsdfSample> {
        if wi.z <= 0.0 {
            return None;
        }
        let Some(ggx) = self.roughness.as_ref().map(|r| r.at(uv)) else {
            return Some(BsdfSample {
                wo: reflect(wi),
                weight: self.fresnel(uv, wi.z),
                pdf: 1.0,
                delta: true,
                eta: 1.0,
            });
        };
        let m = ggx.sample_visible(wi, u);
        let wo = reflect_about(wi, m);
        let wo_m = wo.dot(m);
        if wo.z <= 0.0 || wo_m <= 0.0 {
            return None;
        }
        let pdf = ggx.pdf_visible(wi, m) / (4.0 * wo_m);
        (pdf > 0.0).then(|| BsdfSample {
            wo,
            weight: self.fresnel(uv, wi.dot(m)) * ggx.g1(wo, m),
            pdf,
            delta: false,
            eta: 1.0,
        })
    }

    pub(super) fn eval(&self, uv: &TexAt, wi: Vec3A, wo: Vec3A) -> Rgb {
        let Some(ggx) = self.roughness.as_ref().map(|r| r.at(uv)) else {
            return Rgb::ZERO;
        };
        if wi.z <= 0.0 || wo.z <= 0.0 {
            return Rgb::ZERO;
        }
        let m = (wi + wo).normalize();
        let d = ggx.d(m);
        if d == 0.0 {
            return Rgb::ZERO;
        }
        self.fresnel(uv, wi.dot(m)) * (d * ggx.g(wi, wo, m) / (4.0 * wi.z))
    }

    pub(super) fn pdf(&self, uv: &TexAt, wi: Vec3A, wo: Vec3A) -> f32 {
        let Some(ggx) = self.roughness.as_ref().map(|r| r.at(uv)) else {
            return 0.0;
        };
        if wi.z <= 0.0 || wo.z <= 0.0 {
            return 0.0;
        }
        let m = (wi + wo).normalize();
        let wo_m = wo.dot(m);
        if wo_m <= 0.0 {
            return 0.0;
        }
        ggx.pdf_visible(wi, m) / (4.0 * wo_m)
    }
}
