use std::f32::consts::FRAC_1_PI;

use glam::{Vec2, Vec3A};

use super::BsdfSample;
use crate::color::Rgb;
use crate::sampling::{square_to_cosine_hemisphere, square_to_cosine_hemisphere_pdf};
use crate::texture::{Param, TexAt};

/// Lambertian reflection, one-sided as in Mitsuba (the back is black; use `twosided`).
#[derive(Clone, Debug)]
pub struct Diffuse {
    /// Albedo.
    pub reflectance: Param<Rgb>,
}

impl Diffuse {
    pub(super) fn sample(&self, uv: &TexAt, wi: Vec3A, u: Vec2) -> Option<BsdfSample> {
        if wi.z <= 0.0 {
            return None;
        }
        let wo = square_to_cosine_hemisphere(u);
        let pdf = square_to_cosine_hemisphere_pdf(wo);
        (pdf > 0.0).then_some(BsdfSample {
            wo,
            weight: self.reflectance.at(uv),
            pdf,
            delta: false,
            eta: 1.0,
        })
    }

    pub(super) fn eval(&self, uv: &TexAt, wi: Vec3A, wo: Vec3A) -> Rgb {
        if wi.z <= 0.0 || wo.z <= 0.0 {
            return Rgb::ZERO;
        }
        self.reflectance.at(uv) * (FRAC_1_PI * wo.z)
    }

    pub(super) fn pdf(&self, wi: Vec3A, wo: Vec3A) -> f32 {
        if wi.z <= 0.0 || wo.z <= 0.0 {
            return 0.0;
        }
        square_to_cosine_hemisphere_pdf(wo)
    }
}
