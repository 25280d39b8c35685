//! The GGX (Trowbridge–Reitz) microfacet distribution with Heitz's visible-normal sampling.

use std::f32::consts::PI;

use glam::{Vec2, Vec3A};

/// Isotropic GGX with roughness `alpha`.
#[derive(Clone, Copy, Debug)]
pub struct Ggx {
    /// Roughness (Mitsuba's `alpha`).
    pub alpha: f32,
}

impl Ggx {
    /// Normal distribution D(m).
    pub fn d(&self, m: Vec3A) -> f32 {
        if m.z <= 0.0 {
            return 0.0;
        }
        let a2 = self.alpha * self.alpha;
        let c2 = m.z * m.z;
        let denom = c2 * (a2 - 1.0) + 1.0;
        a2 / (PI * denom * denom)
    }

    /// Smith's masking term for one direction against microfacet `m`.
    pub fn g1(&self, v: Vec3A, m: Vec3A) -> f32 {
        if v.dot(m) * v.z <= 0.0 {
            return 0.0;
        }
        let xy = self.alpha * self.alpha * (v.x * v.x + v.y * v.y);
        let tan2 = xy / (v.z * v.z);
        2.0 / (1.0 + (1.0 + tan2).sqrt())
    }

    /// Separable masking-shadowing, as Mitsuba uses.
    pub fn g(&self, wi: Vec3A, wo: Vec3A, m: Vec3A) -> f32 {
        self.g1(wi, m) * self.g1(wo, m)
    }

    /// A microfacet normal drawn from the distribution of normals visible from `wi` (wi.z > 0).
    pub fn sample_visible(&self, wi: Vec3A, u: Vec2) -> Vec3A {
        let a = self.alpha;
        let vh = Vec3A::new(a * wi.x, a * wi.y, wi.z).normalize();
        let len2 = vh.x * vh.x + vh.y * vh.y;
        let t1 = if len2 > 0.0 {
            Vec3A::new(-vh.y, vh.x, 0.0) / len2.sqrt()
        } else {
            Vec3A::X
        };
        let t2 = vh.cross(t1);
        let r = u.x.sqrt();
        let phi = 2.0 * PI * u.y;
        let p1 = r * phi.cos();
        let s = 0.5 * (1.0 + vh.z);
        let p2 = (1.0 - s) * (1.0 - p1 * p1).max(0.0).sqrt() + s * r * phi.sin();
        let nh = p1 * t1 + p2 * t2 + (1.0 - p1 * p1 - p2 * p2).max(0.0).sqrt() * vh;
        Vec3A::new(a * nh.x, a * nh.y, nh.z.max(1e-7)).normalize()
    }

    /// Density of [`Ggx::sample_visible`] per unit solid angle of `m`.
    pub fn pdf_visible(&self, wi: Vec3A, m: Vec3A) -> f32 {
        if wi.z <= 0.0 {
            return 0.0;
        }
        self.g1(wi, m) * wi.dot(m).max(0.0) * self.d(m) / wi.z
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::sampling::{Sampler, Stream, square_to_uniform_sphere};

    #[test]
    fn projected_area_is_one() {
        // ∫ D(m) cos θm dωm = 1 for a valid distribution.
        for alpha in [0.05f32, 0.3, 0.8] {
            let g = Ggx { alpha };
            let mut s = Sampler::new(1, Stream::Camera, 0, 0);
            let n = 400_000;
            let mut sum = 0.0f64;
            for _ in 0..n {
                let m = square_to_uniform_sphere(s.next_2d());
                sum += (g.d(m) * m.z.max(0.0)) as f64 * 4.0 * PI as f64;
            }
            let est = sum / n as f64;
            assert!((est - 1.0).abs() < 0.05, "alpha {alpha}: {est}");
        }
    }
}
