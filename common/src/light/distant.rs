//! What the lights at infinity share (Mitsuba's `constant`, `envmap` and `directional`): a
//! light sample is a point far beyond the scene, and photons leave a disk as wide as the scene's
//! bounding sphere, facing their direction of flight, so that every photon that can reach the
//! scene starts outside it.

use std::f32::consts::PI;

use glam::{Vec2, Vec3A};

use super::{EmittedPhoton, LightSample};
use crate::color::Rgb;
use crate::geometry::Frame;

/// The scene's bounding sphere, as Mitsuba computes it: around the shapes' bounding box, with
/// a relative margin of 1500 · 2⁻²⁴.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct SceneSphere {
    /// Centre.
    pub center: Vec3A,
    /// Radius.
    pub radius: f32,
}

impl Default for SceneSphere {
    fn default() -> Self {
        SceneSphere {
            center: Vec3A::ZERO,
            radius: RAY_EPSILON,
        }
    }
}

const RAY_EPSILON: f32 = 1500.0 / 16_777_216.0;

impl SceneSphere {
    /// Around the box [min, max].
    pub fn around(min: Vec3A, max: Vec3A) -> SceneSphere {
        if !(min.is_finite() && max.is_finite()) || min.cmpgt(max).any() {
            return SceneSphere::default();
        }
        let center = 0.5 * (min + max);
        let radius = ((max - center).length() * (1.0 + RAY_EPSILON)).max(RAY_EPSILON);
        SceneSphere { center, radius }
    }

    /// A light sample arriving at `p` from direction `wi` (towards the light): its point lies
    /// outside the sphere, twice as far as the sphere's far side, so shadow rays cross the
    /// whole scene.
    pub fn sample_towards(&self, p: Vec3A, wi: Vec3A, radiance: Rgb, pdf: f32, delta: bool) -> LightSample {
        let dist = 2.0 * self.radius.max((p - self.center).length());
        LightSample {
            p: p + wi * dist,
            p_err: Vec3A::ZERO,
            n: Vec3A::ZERO,
            wi,
            radiance,
            pdf,
            delta,
        }
    }

    /// A photon flying along `dir` from a uniform point on the disk of the sphere's radius that
    /// faces `dir` behind the sphere; `radiance_over_pdf` is the radiance arriving from `-dir`
    /// over the density of choosing `dir` (irradiance for a directional light).
    pub fn photon(&self, dir: Vec3A, u_pos: Vec2, radiance_over_pdf: Rgb) -> EmittedPhoton {
        let o = crate::sampling::square_to_uniform_disk_concentric(u_pos);
        let frame = Frame::from_normal(dir);
        let origin = self.center + (frame.to_world(Vec3A::new(o.x, o.y, 0.0)) - dir) * self.radius;
        EmittedPhoton {
            origin,
            origin_err: Vec3A::ZERO,
            n: Vec3A::ZERO,
            dir,
            power: radiance_over_pdf * (PI * self.radius * self.radius),
        }
    }

    /// The disk's area, which the lights' powers scale with.
    pub fn disk_area(&self) -> f32 {
        PI * self.radius * self.radius
    }
}

/// Mitsuba's `constant`: the same radiance from every direction.
#[derive(Clone, Debug)]
pub struct ConstantLight {
    /// Radiance.
    pub radiance: Rgb,
    /// Set once the scene is built.
    pub sphere: SceneSphere,
}

impl ConstantLight {
    pub(super) fn sample_li(&self, p: Vec3A, u: Vec2) -> Option<LightSample> {
        let wi = crate::sampling::square_to_uniform_sphere(u);
        Some(
            self.sphere
                .sample_towards(p, wi, self.radiance, 1.0 / (4.0 * PI), false),
        )
    }

    pub(super) fn sample_emission(&self, u_pos: Vec2, u_dir: Vec2) -> Option<EmittedPhoton> {
        let dir = crate::sampling::square_to_uniform_sphere(u_dir);
        Some(self.sphere.photon(dir, u_pos, self.radiance * (4.0 * PI)))
    }

    pub(super) fn power(&self) -> f32 {
        crate::color::luminance(self.radiance) * 4.0 * PI * self.sphere.disk_area()
    }
}

/// Mitsuba's `directional`: parallel light of a given irradiance, such as the sun. A delta
/// light: only light sampling and photons find it.
#[derive(Clone, Debug)]
pub struct DirectionalLight {
    /// Direction of travel (unit).
    pub direction: Vec3A,
    /// Irradiance on a surface facing the light.
    pub irradiance: Rgb,
    /// Set once the scene is built.
    pub sphere: SceneSphere,
}

impl DirectionalLight {
    pub(super) fn sample_li(&self, p: Vec3A) -> Option<LightSample> {
        Some(
            self.sphere
                .sample_towards(p, -self.direction, self.irradiance, 1.0, true),
        )
    }

    pub(super) fn sample_emission(&self, u_pos: Vec2) -> Option<EmittedPhoton> {
        Some(self.sphere.photon(self.direction, u_pos, self.irradiance))
    }

    pub(super) fn power(&self) -> f32 {
        crate::color::luminance(self.irradiance) * self.sphere.disk_area()
    }
}
