use std::f32::consts::PI;

use glam::{Mat3A, Vec2, Vec3A};

use super::{EmittedPhoton, LightSample};
use crate::color::Rgb;
use crate::texture::Param;

/// Mitsuba's `projector`: a pinhole that throws an image into the scene, the reciprocal of
/// its perspective camera. The image is irradiance on a virtual plane at z = 1 in the light's
/// frame (the intensity along direction d is π · scale · E(u, v) / cos³θ), so that a constant
/// image lights a plane facing it evenly.
#[derive(Clone, Debug)]
pub struct ProjectorLight {
    /// The pinhole.
    pub position: Vec3A,
    /// World to local rotation; the projector shines along local +z.
    pub to_local: Mat3A,
    /// tan(fov_x / 2), Mitsuba's horizontal field of view.
    pub tan_half_x: f32,
    /// The image's width over its height.
    pub aspect: f32,
    /// The irradiance image (Mitsuba's `irradiance`).
    pub irradiance: Param<Rgb>,
    /// Mitsuba's `scale`.
    pub scale: f32,
}

impl ProjectorLight {
    /// Where local direction `d` meets the image, as Mitsuba's perspective projection maps it
    /// (u grows to the frame's -x, v to its -y), if it does.
    fn uv(&self, d: Vec3A) -> Option<Vec2> {
        if d.z <= 0.0 {
            return None;
        }
        let (x, y) = (d.x / (d.z * self.tan_half_x), d.y / (d.z * self.tan_half_x));
        let uv = Vec2::new(0.5 - 0.5 * x, 0.5 - 0.5 * self.aspect * y);
        (uv.cmpge(Vec2::ZERO).all() && uv.cmple(Vec2::ONE).all()).then_some(uv)
    }

    /// The image's area on the plane at z = 1.
    fn image_area(&self) -> f32 {
        4.0 * self.tan_half_x * self.tan_half_x / self.aspect
    }

    pub(super) fn sample_li(&self, p: Vec3A) -> Option<LightSample> {
        let local = self.to_local * (p - self.position);
        let uv = self.uv(local)?;
        let d = self.position - p;
        let dist = d.length();
        let cos = local.z / dist;
        let radiance = self.irradiance.at(uv) * (PI * self.scale / (local.z * local.z * cos));
        (radiance != Rgb::ZERO && radiance.is_finite()).then(|| LightSample {
            p: self.position,
            p_err: Vec3A::ZERO,
            n: Vec3A::ZERO,
            wi: d / dist,
            radiance,
            pdf: 1.0,
            delta: true,
        })
    }

    /// A point of the image, uniform in (u, v), and the direction through it: the power is
    /// then π · scale · E(u, v) · the image's area.
    pub(super) fn sample_emission(&self, u: Vec2) -> Option<EmittedPhoton> {
        let x = (0.5 - u.x) * 2.0 * self.tan_half_x;
        let y = (0.5 - u.y) * 2.0 * self.tan_half_x / self.aspect;
        let local = Vec3A::new(x, y, 1.0).normalize();
        let power = self.irradiance.at(u) * (PI * self.scale * self.image_area());
        (power != Rgb::ZERO).then(|| EmittedPhoton {
            origin: self.position,
            origin_err: Vec3A::ZERO,
            n: Vec3A::ZERO,
            dir: (self.to_local.transpose() * local).normalize(),
            power,
        })
    }

    /// A texture's mean over (u, v) gives the emitted power exactly: the photons sample the
    /// image uniformly.
    pub(super) fn power(&self) -> f32 {
        PI * self.scale * self.image_area() * self.irradiance.light_weight()
    }
}
