use std::f32::consts::PI;

use glam::{Vec2, Vec3A};

use super::{EmittedPhoton, LightSample};
use crate::color::Rgb;
use crate::geometry::Frame;
use crate::geometry::{Primitive, Sphere};
use crate::sampling::{Distribution1D, square_to_cosine_hemisphere};
use crate::texture::Param;

/// A shape that emits from its front side (Mitsuba's `area` emitter), a fixed radiance or one
/// read from a texture at the surface's (u, v).
#[derive(Clone, Debug)]
pub struct AreaLight {
    /// Emitted radiance.
    pub radiance: Param<Rgb>,
    /// Indices of the shape's primitives in the BVH.
    pub prims: Vec<u32>,
    /// Chooses a primitive in proportion to its area, so points are uniform over the shape.
    pub area_distribution: Distribution1D,
    /// Total area.
    pub area: f32,
    /// The sphere, when the light is one whole outward-facing sphere: seen from outside it is
    /// sampled within the cone it subtends, as Mitsuba does, rather than by area (which wastes
    /// the half of the samples that land on its far side and is far noisier for small spheres).
    pub sphere: Option<Sphere>,
}

impl AreaLight {
    /// A light over the given primitives.
    pub fn new(radiance: Param<Rgb>, prims: Vec<u32>, all: &[Primitive]) -> AreaLight {
        let areas: Vec<f32> = prims.iter().map(|&i| all[i as usize].area()).collect();
        let area_distribution = Distribution1D::new(&areas);
        let sphere = match prims.as_slice() {
            [one] => match &all[*one as usize] {
                Primitive::Sphere(s) if !s.flip => Some(s.clone()),
                _ => None,
            },
            _ => None,
        };
        AreaLight {
            radiance,
            area: area_distribution.total(),
            prims,
            area_distribution,
            sphere,
        }
    }

    /// For a sphere light seen from `p` outside it: the cone's axis, the distance to the
    /// centre and 1 - cos of the cone's half-angle (computed from sin² to keep its precision
    /// for small, distant spheres).
    fn cone(&self, p: Vec3A) -> Option<(&Sphere, Vec3A, f32, f32)> {
        let s = self.sphere.as_ref()?;
        let to_c = s.center - p;
        let dc = to_c.length();
        if dc <= s.radius * 1.0001 {
            return None;
        }
        let sin2 = (s.radius / dc).powi(2);
        let one_minus_cos = sin2 / (1.0 + (1.0 - sin2).max(0.0).sqrt());
        Some((s, to_c / dc, dc, one_minus_cos))
    }

    /// Radiance leaving the surface at `uv` with normal `n` in direction `w`: only the front
    /// emits.
    pub fn emitted(&self, uv: Vec2, n: Vec3A, w: Vec3A) -> Rgb {
        if n.dot(w) > 0.0 {
            self.radiance.at(uv)
        } else {
            Rgb::ZERO
        }
    }

    /// Density per unit solid angle of sampling `p_light` (normal `n`) from `p`.
    pub fn pdf_li(&self, p: Vec3A, p_light: Vec3A, n: Vec3A) -> f32 {
        if let Some((_, _, _, one_minus_cos)) = self.cone(p) {
            return 1.0 / (2.0 * PI * one_minus_cos);
        }
        let d = p_light - p;
        let dist2 = d.length_squared();
        let cos = n.dot(-d).abs() / dist2.sqrt();
        if cos <= 0.0 || self.area <= 0.0 {
            return 0.0;
        }
        dist2 / (cos * self.area)
    }

    pub(super) fn sample_li(&self, p: Vec3A, prims: &[Primitive], u: Vec2) -> Option<LightSample> {
        if self.area_distribution.is_empty() {
            return None;
        }
        let sp = match self.cone(p) {
            Some((sphere, axis, dc, one_minus_cos)) => {
                // A direction uniform in the cone, and where it first meets the sphere.
                let cos = 1.0 - u.x * one_minus_cos;
                let sin = (1.0 - cos * cos).max(0.0).sqrt();
                let phi = 2.0 * PI * u.y;
                let (sin_phi, cos_phi) = libm::sincosf(phi);
                let dir = Frame::from_normal(axis).to_world(Vec3A::new(sin * cos_phi, sin * sin_phi, cos));
                let r2 = sphere.radius * sphere.radius;
                let t = dc * cos - (r2 - dc * dc * sin * sin).max(0.0).sqrt();
                sphere.surface(p + dir * t)
            }
            None => {
                let (i, _, ux) = self.area_distribution.sample(u.x);
                prims[self.prims[i] as usize].sample_point(Vec2::new(ux, u.y))
            }
        };
        let d = sp.p - p;
        let dist2 = d.length_squared();
        if dist2 == 0.0 {
            return None;
        }
        let wi = d / dist2.sqrt();
        let radiance = self.emitted(sp.uv, sp.ns, -wi);
        if radiance == Rgb::ZERO {
            return None;
        }
        let pdf = self.pdf_li(p, sp.p, sp.ng);
        (pdf > 0.0 && pdf.is_finite()).then_some(LightSample {
            p: sp.p,
            p_err: sp.p_err,
            n: sp.ng,
            wi,
            radiance,
            pdf,
            delta: false,
        })
    }

    /// A uniform point on the surface and a cosine-distributed direction on its front side:
    /// the power is then the point's radiance · π · area.
    pub(super) fn sample_emission(
        &self,
        prims: &[Primitive],
        u_pos: Vec2,
        u_dir: Vec2,
    ) -> Option<EmittedPhoton> {
        if self.area_distribution.is_empty() {
            return None;
        }
        let (i, _, ux) = self.area_distribution.sample(u_pos.x);
        let sp = prims[self.prims[i] as usize].sample_point(Vec2::new(ux, u_pos.y));
        let dir = Frame::from_normal(sp.ns).to_world(square_to_cosine_hemisphere(u_dir));
        Some(EmittedPhoton {
            origin: sp.p,
            origin_err: sp.p_err,
            n: sp.ng,
            dir,
            power: self.radiance.at(sp.uv) * (PI * self.area),
        })
    }

    /// For a texture, its mean over (u, v) stands for the mean over the area: the choice of
    /// lights only needs a weight that its densities agree with.
    pub(super) fn power(&self) -> f32 {
        PI * self.area * self.radiance.light_weight()
    }
}
