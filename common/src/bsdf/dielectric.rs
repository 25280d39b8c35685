use glam::Vec3A;

use super::fresnel::{fresnel_dielectric, reflect, refract};
use super::{BsdfSample, TransportMode};
use crate::color::Rgb;
use crate::texture::{Param, TexAt};

/// A smooth glass interface: Fresnel-weighted choice between mirror reflection and refraction,
/// with total internal reflection. Both sides are glass.
#[derive(Clone, Debug)]
pub struct Dielectric {
    /// Interior over exterior index of refraction.
    pub eta: f32,
    /// Tint of the reflected light.
    pub specular_reflectance: Param<Rgb>,
    /// Tint of the transmitted light.
    pub specular_transmittance: Param<Rgb>,
}

impl Dielectric {
    pub(super) fn sample(&self, uv: &TexAt, wi: Vec3A, u: f32, mode: TransportMode) -> Option<BsdfSample> {
        let (r, cos_t, eta_it, eta_ti) = fresnel_dielectric(wi.z, self.eta);
        if u < r {
            Some(BsdfSample {
                wo: reflect(wi),
                weight: self.specular_reflectance.at(uv),
                pdf: r,
                delta: true,
                eta: 1.0,
            })
        } else {
            // Radiance is compressed into a smaller solid angle when it enters a denser medium;
            // importance (photons) is not.
            let scale = match mode {
                TransportMode::Radiance => eta_ti * eta_ti,
                TransportMode::Importance => 1.0,
            };
            Some(BsdfSample {
                wo: refract(wi, cos_t, eta_ti),
                weight: self.specular_transmittance.at(uv) * scale,
                pdf: 1.0 - r,
                delta: true,
                eta: eta_it,
            })
        }
    }
}
