use std::f32::consts::PI;

use std::sync::Arc;

use glam::{Mat3A, Vec2, Vec3A};

use super::{EmittedPhoton, LightSample};
use crate::color::{Rgb, luminance};
use crate::sampling::{square_to_uniform_cone, square_to_uniform_cone_pdf};
use crate::texture::Texture;

/// A point light restricted to a cone (Mitsuba's `spot`): full intensity within `beam_width`,
/// falling linearly in angle to zero at `cutoff_angle`, and scaled by a texture projected over
/// the cone, if it has one.
#[derive(Clone, Debug)]
pub struct SpotLight {
    /// Position.
    pub position: Vec3A,
    /// World to local rotation; the spot shines along local +z.
    pub to_local: Mat3A,
    /// Intensity at the centre of the beam, W/sr.
    pub intensity: Rgb,
    /// Cutoff angle, radians.
    pub cutoff: f32,
    /// Beam width, radians.
    pub beam_width: f32,
    /// Mitsuba's `texture`: (u, v) spans the square the cutoff cone's base fits in.
    pub texture: Option<Arc<Texture>>,
}

impl SpotLight {
    /// Fraction of the central intensity emitted along local direction `d`.
    pub fn falloff(&self, d: Vec3A) -> f32 {
        let cos = d.normalize_or_zero().z;
        if cos <= libm::cosf(self.cutoff) {
            0.0
        } else if cos >= libm::cosf(self.beam_width) {
            1.0
        } else {
            ((self.cutoff - libm::acosf(cos.clamp(-1.0, 1.0))) / (self.cutoff - self.beam_width))
                .clamp(0.0, 1.0)
        }
    }

    /// The texture's colour along local direction `d`, at Mitsuba's (u, v):
    /// ½ + ½ · (x, y) / (z · tan cutoff).
    fn projected(&self, d: Vec3A) -> Rgb {
        let Some(t) = &self.texture else {
            return Rgb::ONE;
        };
        let d = d.normalize_or_zero();
        let scale = 0.5 / (d.z * libm::tanf(self.cutoff));
        t.eval(Vec2::new(0.5 + d.x * scale, 0.5 + d.y * scale).into())
    }

    pub(super) fn sample_li(&self, p: Vec3A) -> Option<LightSample> {
        let d = self.position - p;
        let dist2 = d.length_squared();
        if dist2 == 0.0 {
            return None;
        }
        let wi = d / dist2.sqrt();
        let local = self.to_local * -wi;
        let falloff = self.falloff(local);
        (falloff > 0.0).then(|| LightSample {
            p: self.position,
            p_err: Vec3A::ZERO,
            n: Vec3A::ZERO,
            wi,
            radiance: self.intensity * self.projected(local) * (falloff / dist2),
            pdf: 1.0,
            delta: true,
        })
    }

    /// A direction uniform in the cutoff cone, weighted by the falloff.
    pub(super) fn sample_emission(&self, u: glam::Vec2) -> Option<EmittedPhoton> {
        let cos_cutoff = libm::cosf(self.cutoff);
        let local = square_to_uniform_cone(u, cos_cutoff);
        let falloff = self.falloff(local);
        (falloff > 0.0).then(|| EmittedPhoton {
            origin: self.position,
            origin_err: Vec3A::ZERO,
            n: Vec3A::ZERO,
            dir: (self.to_local.transpose() * local).normalize(),
            power: self.intensity
                * self.projected(local)
                * (falloff / square_to_uniform_cone_pdf(cos_cutoff)),
        })
    }

    /// With a texture, its mean stands for its mean over the cone: the choice of lights only
    /// needs a weight that its densities agree with.
    pub(super) fn power(&self) -> f32 {
        // 2π ∫ falloff(θ) sin θ dθ over the cone, by the midpoint rule.
        let n = 256;
        let mut sum = 0.0;
        for i in 0..n {
            let theta = (i as f32 + 0.5) / n as f32 * self.cutoff;
            let (sin_theta, cos_theta) = libm::sincosf(theta);
            let d = Vec3A::new(sin_theta, 0.0, cos_theta);
            sum += self.falloff(d) * sin_theta * self.cutoff / n as f32;
        }
        let texture = self.texture.as_ref().map_or(1.0, |t| t.mean());
        2.0 * PI * sum * luminance(self.intensity) * texture
    }
}
