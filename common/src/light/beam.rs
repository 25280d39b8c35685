use std::f32::consts::PI;

use glam::{Vec2, Vec3A};

use super::{EmittedPhoton, LightSample};
use crate::color::{Rgb, luminance};
use crate::geometry::Frame;
use crate::sampling::square_to_uniform_disk_concentric;

/// A collimated beam leaving a disc (our extension, `<emitter type="beam">`): every point of
/// the disc emits along the disc's normal only. The original renderer's light-shaft source.
///
/// Light sampling finds it like a directional light restricted to the beam's cylinder; a path
/// tracer cannot see it through glass (a delta direction), which SPPM's photons can.
#[derive(Clone, Debug)]
pub struct BeamLight {
    /// Centre of the disc.
    pub origin: Vec3A,
    /// The disc's frame; the beam travels along `frame.n`.
    pub frame: Frame,
    /// Radius of the disc.
    pub radius: f32,
    /// Irradiance across the beam (power per unit area perpendicular to it).
    pub irradiance: Rgb,
}

impl BeamLight {
    pub(super) fn sample_li(&self, p: Vec3A) -> Option<LightSample> {
        let v = p - self.origin;
        let along = v.dot(self.frame.n);
        let radial = v - along * self.frame.n;
        if along <= 0.0 || radial.length_squared() > self.radius * self.radius {
            return None;
        }
        Some(LightSample {
            p: self.origin + radial,
            p_err: Vec3A::ZERO,
            n: self.frame.n,
            wi: -self.frame.n,
            radiance: self.irradiance,
            pdf: 1.0,
            delta: true,
        })
    }

    pub(super) fn sample_emission(&self, u: Vec2) -> Option<EmittedPhoton> {
        let d = square_to_uniform_disk_concentric(u) * self.radius;
        Some(EmittedPhoton {
            origin: self.origin + self.frame.s * d.x + self.frame.t * d.y,
            origin_err: Vec3A::ZERO,
            n: Vec3A::ZERO,
            dir: self.frame.n,
            power: self.irradiance * (PI * self.radius * self.radius),
        })
    }

    pub(super) fn power(&self) -> f32 {
        luminance(self.irradiance) * PI * self.radius * self.radius
    }
}
