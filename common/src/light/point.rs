use std::f32::consts::PI;

use glam::Vec3A;

use super::{EmittedPhoton, LightSample};
use crate::color::{Rgb, luminance};

/// An isotropic point light (Mitsuba's `point`).
#[derive(Clone, Debug)]
pub struct PointLight {
    /// Position.
    pub position: Vec3A,
    /// Radiant intensity, W/sr.
    pub intensity: Rgb,
}

impl PointLight {
    pub(super) fn sample_li(&self, p: Vec3A) -> Option<LightSample> {
        let d = self.position - p;
        let dist2 = d.length_squared();
        if dist2 == 0.0 {
            return None;
        }
        Some(LightSample {
            p: self.position,
            p_err: Vec3A::ZERO,
            n: Vec3A::ZERO,
            wi: d / dist2.sqrt(),
            radiance: self.intensity / dist2,
            pdf: 1.0,
            delta: true,
        })
    }

    pub(super) fn sample_emission(&self, u: glam::Vec2) -> Option<EmittedPhoton> {
        Some(EmittedPhoton {
            origin: self.position,
            origin_err: Vec3A::ZERO,
            n: Vec3A::ZERO,
            dir: crate::sampling::square_to_uniform_sphere(u),
            power: self.intensity * (4.0 * PI),
        })
    }

    pub(super) fn power(&self) -> f32 {
        4.0 * PI * luminance(self.intensity)
    }
}
