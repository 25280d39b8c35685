use std::f32::consts::PI;

use glam::{Vec2, Vec3A};

use super::{EmittedPhoton, LightSample};
use crate::color::{Rgb, luminance};
use crate::geometry::Frame;
use crate::geometry::Primitive;
use crate::sampling::{Distribution1D, square_to_cosine_hemisphere};

/// A shape that emits constant radiance from its front side (Mitsuba's `area` emitter).
#[derive(Clone, Debug)]
pub struct AreaLight {
    /// Emitted radiance.
    pub radiance: Rgb,
    /// Indices of the shape's primitives in the BVH.
    pub prims: Vec<u32>,
    /// Chooses a primitive in proportion to its area, so points are uniform over the shape.
    pub area_distribution: Distribution1D,
    /// Total area.
    pub area: f32,
}

impl AreaLight {
    /// A light over the given primitives.
    pub fn new(radiance: Rgb, prims: Vec<u32>, all: &[Primitive]) -> AreaLight {
        let areas: Vec<f32> = prims.iter().map(|&i| all[i as usize].area()).collect();
        let area_distribution = Distribution1D::new(&areas);
        AreaLight {
            radiance,
            area: area_distribution.total(),
            prims,
            area_distribution,
        }
    }

    /// Radiance leaving the surface with normal `n` in direction `w`: only the front emits.
    pub fn emitted(&self, n: Vec3A, w: Vec3A) -> Rgb {
        if n.dot(w) > 0.0 { self.radiance } else { Rgb::ZERO }
    }

    /// Density per unit solid angle of sampling `p_light` (normal `n`) from `p`.
    pub fn pdf_li(&self, p: Vec3A, p_light: Vec3A, n: Vec3A) -> f32 {
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
        let (i, _, ux) = self.area_distribution.sample(u.x);
        let sp = prims[self.prims[i] as usize].sample_point(Vec2::new(ux, u.y));
        let d = sp.p - p;
        let dist2 = d.length_squared();
        if dist2 == 0.0 {
            return None;
        }
        let wi = d / dist2.sqrt();
        let radiance = self.emitted(sp.ns, -wi);
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
    /// the power is then radiance · π · area.
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
            power: self.radiance * (PI * self.area),
        })
    }

    pub(super) fn power(&self) -> f32 {
        PI * self.area * luminance(self.radiance)
    }
}
