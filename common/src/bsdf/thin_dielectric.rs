//! Mitsuba's `thindielectric`: a thin pane of glass, whose two interfaces reflect and transmit
//! with the sum of all internal bounces; transmitted light goes straight on.

use glam::Vec3A;

use super::BsdfSample;
use super::fresnel::{fresnel_dielectric, reflect};
use crate::color::Rgb;
use crate::texture::{Param, TexAt};

/// A thin dielectric sheet.
#[derive(Clone, Debug)]
pub struct ThinDielectric {
    /// Interior over exterior index of refraction.
    pub eta: f32,
    /// Tint of the reflected light.
    pub specular_reflectance: Param<Rgb>,
    /// Tint of the transmitted light.
    pub specular_transmittance: Param<Rgb>,
}

impl ThinDielectric {
    /// Reflectance of the sheet, internal reflections included.
    fn reflectance(&self, cos_i: f32) -> f32 {
        let r = fresnel_dielectric(cos_i.abs(), self.eta).0;
        if r < 1.0 {
            let t = 1.0 - r;
            r + t * t * r / (1.0 - r * r)
        } else {
            r
        }
    }

    pub(super) fn sample(&self, uv: &TexAt, wi: Vec3A, u: f32) -> Option<BsdfSample> {
        let r = self.reflectance(wi.z);
        Some(if u <= r {
            BsdfSample {
                wo: reflect(wi),
                weight: self.specular_reflectance.at(uv),
                pdf: r,
                delta: true,
                eta: 1.0,
            }
        } else {
            BsdfSample {
                wo: -wi,
                weight: self.specular_transmittance.at(uv),
                pdf: 1.0 - r,
                delta: true,
                eta: 1.0,
            }
        })
    }
}
