//! Microfacet distributions, Beckmann (Mitsuba's default) and GGX, with visible-normal sampling
//! and Mitsuba 3's exact formulas: its Beckmann masking term is the rational approximation of
//! Smith's (within 0.35%), so we use the same, and rough materials render as in Mitsuba.

use std::f32::consts::PI;

use glam::{Vec2, Vec3A};

/// The shape of the distribution of microfacet normals.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash)]
pub enum Distribution {
    /// Gaussian slopes: Mitsuba's default.
    Beckmann,
    /// Trowbridge–Reitz: longer tails.
    Ggx,
}

/// A microfacet distribution with roughness `alpha_u` along the shading frame's first tangent
/// and `alpha_v` along the second (equal for an isotropic one), with Mitsuba 3's formulas
/// (its `MicrofacetDistribution` is anisotropic for every material).
#[derive(Clone, Copy, Debug)]
pub struct Microfacet {
    /// Which distribution.
    pub distribution: Distribution,
    /// Roughness along x (Mitsuba's `alpha_u`, or `alpha`).
    pub alpha_u: f32,
    /// Roughness along y (Mitsuba's `alpha_v`, or `alpha`).
    pub alpha_v: f32,
}

/// A distribution whose roughness may vary over the surface (textures on `alpha`, or on
/// `alpha_u` and `alpha_v`).
#[derive(Clone, Debug)]
pub struct Roughness {
    /// Which distribution.
    pub distribution: Distribution,
    /// Mitsuba's `alpha_u` (or `alpha`).
    pub alpha_u: crate::texture::Param<f32>,
    /// Mitsuba's `alpha_v` (or `alpha`).
    pub alpha_v: crate::texture::Param<f32>,
    /// Whether `alpha_u` and `alpha_v` were given apart.
    pub anisotropic: bool,
}

impl Roughness {
    /// One roughness in both directions.
    pub fn isotropic(distribution: Distribution, alpha: crate::texture::Param<f32>) -> Roughness {
        Roughness {
            distribution,
            alpha_u: alpha.clone(),
            alpha_v: alpha,
            anisotropic: false,
        }
    }

    /// The distribution at `uv`; roughness below 1e-4 is raised to it, as Mitsuba does.
    #[inline]
    pub fn at(&self, uv: &crate::texture::TexAt) -> Microfacet {
        let alpha_u = self.alpha_u.at(uv).max(1e-4);
        Microfacet {
            distribution: self.distribution,
            alpha_u,
            alpha_v: if self.anisotropic {
                self.alpha_v.at(uv).max(1e-4)
            } else {
                alpha_u
            },
        }
    }
}

impl Microfacet {
    /// One roughness in both directions.
    pub fn isotropic(distribution: Distribution, alpha: f32) -> Microfacet {
        Microfacet {
            distribution,
            alpha_u: alpha,
            alpha_v: alpha,
        }
    }

    /// Normal distribution D(m).
    pub fn d(&self, m: Vec3A) -> f32 {
        let (au, av) = (self.alpha_u, self.alpha_v);
        let (x, y) = (m.x / au, m.y / av);
        let c2 = m.z * m.z;
        let d = match self.distribution {
            Distribution::Beckmann => libm::expf(-(x * x + y * y) / c2) / (PI * au * av * c2 * c2),
            Distribution::Ggx => {
                let s = x * x + y * y + c2;
                1.0 / (PI * au * av * s * s)
            }
        };
        if d * m.z > 1e-20 { d } else { 0.0 }
    }

    /// Smith's masking term for one direction against microfacet `m`.
    pub fn g1(&self, v: Vec3A, m: Vec3A) -> f32 {
        if v.dot(m) * v.z <= 0.0 {
            return 0.0;
        }
        let (x, y) = (self.alpha_u * v.x, self.alpha_v * v.y);
        let xy = x * x + y * y;
        if xy == 0.0 {
            return 1.0;
        }
        let tan2 = xy / (v.z * v.z);
        match self.distribution {
            Distribution::Beckmann => {
                let a = 1.0 / tan2.sqrt();
                if a >= 1.6 {
                    1.0
                } else {
                    (3.535 * a + 2.181 * a * a) / (1.0 + 2.276 * a + 2.577 * a * a)
                }
            }
            Distribution::Ggx => 2.0 / (1.0 + (1.0 + tan2).sqrt()),
        }
    }

    /// Separable masking-shadowing, as Mitsuba uses.
    pub fn g(&self, wi: Vec3A, wo: Vec3A, m: Vec3A) -> f32 {
        self.g1(wi, m) * self.g1(wo, m)
    }

    /// A microfacet normal drawn from the distribution of normals visible from `wi` (wi.z > 0).
    pub fn sample_visible(&self, wi: Vec3A, u: Vec2) -> Vec3A {
        match self.distribution {
            Distribution::Ggx => self.sample_visible_ggx(wi, u),
            Distribution::Beckmann => self.sample_visible_beckmann(wi, u),
        }
    }

    /// Heitz's exact sampling of GGX's visible normals, with the view stretched by
    /// (alpha_u, alpha_v) and the normal unstretched.
    fn sample_visible_ggx(&self, wi: Vec3A, u: Vec2) -> Vec3A {
        let (au, av) = (self.alpha_u, self.alpha_v);
        let vh = Vec3A::new(au * wi.x, av * wi.y, wi.z).normalize();
        let len2 = vh.x * vh.x + vh.y * vh.y;
        let t1 = if len2 > 0.0 {
            Vec3A::new(-vh.y, vh.x, 0.0) / len2.sqrt()
        } else {
            Vec3A::X
        };
        let t2 = vh.cross(t1);
        let r = u.x.sqrt();
        let phi = 2.0 * PI * u.y;
        let (sin_phi, cos_phi) = libm::sincosf(phi);
        let p1 = r * cos_phi;
        let s = 0.5 * (1.0 + vh.z);
        let p2 = (1.0 - s) * (1.0 - p1 * p1).max(0.0).sqrt() + s * r * sin_phi;
        let nh = p1 * t1 + p2 * t2 + (1.0 - p1 * p1 - p2 * p2).max(0.0).sqrt() * vh;
        Vec3A::new(au * nh.x, av * nh.y, nh.z.max(1e-7)).normalize()
    }

    /// Beckmann's visible normals: stretch the view to unit roughness, draw slopes with Jakob's
    /// inversion of the visible-slope distribution (three Newton steps), rotate and unstretch,
    /// as Mitsuba does. In f64: the inversion works near erf's flat ends.
    fn sample_visible_beckmann(&self, wi: Vec3A, u: Vec2) -> Vec3A {
        use libm::erf;
        use statrs::function::erf::erf_inv;
        let (au, av) = (self.alpha_u as f64, self.alpha_v as f64);
        let (wx, wy, wz) = (au * wi.x as f64, av * wi.y as f64, wi.z as f64);
        let len = (wx * wx + wy * wy + wz * wz).sqrt();
        let (wx, wy, wz) = (wx / len, wy / len, wz / len);
        let sin_theta = (wx * wx + wy * wy).sqrt();
        let (cos_phi, sin_phi) = if sin_theta > 1e-12 {
            (wx / sin_theta, wy / sin_theta)
        } else {
            (1.0, 0.0)
        };
        // Slopes of the visible normals of a unit-roughness Beckmann surface seen at theta.
        let ux = (u.x as f64).clamp(1e-6, 1.0 - 1e-6);
        let uy = (u.y as f64).clamp(1e-6, 1.0 - 1e-6);
        let tan_theta = sin_theta / wz;
        let cot_theta = 1.0 / tan_theta;
        let inv_sqrt_pi = 1.0 / std::f64::consts::PI.sqrt();
        let max_val = erf(cot_theta);
        let tail = if tan_theta > 0.0 {
            inv_sqrt_pi * tan_theta * libm::exp(-cot_theta * cot_theta)
        } else {
            0.0
        };
        let mut x = max_val - (max_val + 1.0) * erf((-libm::log(ux)).sqrt());
        let target = ux * (1.0 + max_val + tail);
        for _ in 0..3 {
            let slope = erf_inv(x.clamp(-1.0 + 1e-12, 1.0 - 1e-12));
            let value = 1.0 + x + inv_sqrt_pi * tan_theta * libm::exp(-slope * slope) - target;
            let deriv = 1.0 - slope * tan_theta;
            x -= value / deriv;
        }
        let sx = erf_inv(x.clamp(-1.0 + 1e-12, 1.0 - 1e-12));
        let sy = erf_inv(2.0 * uy - 1.0);
        let (rx, ry) = (cos_phi * sx - sin_phi * sy, sin_phi * sx + cos_phi * sy);
        Vec3A::new((-rx * au) as f32, (-ry * av) as f32, 1.0).normalize()
    }

    /// Density of [`Microfacet::sample_visible`] per unit solid angle of `m`.
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
        for distribution in [Distribution::Ggx, Distribution::Beckmann] {
            for alpha in [0.05f32, 0.3, 0.8] {
                let g = Microfacet::isotropic(distribution, alpha);
                let mut s = Sampler::new(1, Stream::Camera, 0, 0);
                let n = 400_000;
                let mut sum = 0.0f64;
                for _ in 0..n {
                    let m = square_to_uniform_sphere(s.next_2d());
                    sum += (g.d(m) * m.z.max(0.0)) as f64 * 4.0 * PI as f64;
                }
                let est = sum / n as f64;
                assert!((est - 1.0).abs() < 0.05, "{distribution:?} alpha {alpha}: {est}");
            }
        }
    }

    /// Both distributions, anisotropic: D(m) cos θm integrates to one, and so does the density
    /// of the visible normals, from an oblique view.
    #[test]
    fn anisotropic_distributions_are_normalised() {
        let mut s = Sampler::new(3, Stream::Camera, 0, 0);
        for distribution in [Distribution::Ggx, Distribution::Beckmann] {
            for (au, av) in [(0.05f32, 0.2f32), (0.3, 0.1), (0.6, 0.6)] {
                let g = Microfacet {
                    distribution,
                    alpha_u: au,
                    alpha_v: av,
                };
                let wi = Vec3A::new(0.5, -0.3, 0.6).normalize();
                let n = 400_000;
                let (mut area, mut visible) = (0.0f64, 0.0f64);
                for _ in 0..n {
                    let m = square_to_uniform_sphere(s.next_2d());
                    area += (g.d(m) * m.z.max(0.0)) as f64 * 4.0 * PI as f64;
                    visible += g.pdf_visible(wi, m) as f64 * 4.0 * PI as f64;
                }
                let (area, visible) = (area / n as f64, visible / n as f64);
                let what = format!("{distribution:?} ({au}, {av})");
                assert!((area - 1.0).abs() < 0.05, "{what}: projected area {area}");
                assert!((visible - 1.0).abs() < 0.05, "{what}: visible normals {visible}");
            }
        }
    }

    /// Sampled visible normals follow the roughness of their own axis: along x at alpha_u, along
    /// y at alpha_v (E[tan² θ] per axis is alpha² / 2 for Beckmann at normal incidence).
    #[test]
    fn anisotropic_beckmann_slopes_follow_each_axis() {
        let g = Microfacet {
            distribution: Distribution::Beckmann,
            alpha_u: 0.1,
            alpha_v: 0.4,
        };
        let mut s = Sampler::new(5, Stream::Camera, 0, 0);
        let n = 200_000;
        let (mut sx, mut sy) = (0.0f64, 0.0f64);
        for _ in 0..n {
            let m = g.sample_visible(Vec3A::Z, s.next_2d());
            sx += ((m.x / m.z) * (m.x / m.z)) as f64;
            sy += ((m.y / m.z) * (m.y / m.z)) as f64;
        }
        let (ex, ey) = (sx / n as f64 / (0.5 * 0.01), sy / n as f64 / (0.5 * 0.16));
        assert!((ex - 1.0).abs() < 0.03 && (ey - 1.0).abs() < 0.03, "{ex}, {ey}");
    }

    /// At normal incidence the visible normals are distributed as D(m) cos θm, whose Beckmann
    /// slopes have variance α²/2 per axis: E[tan² θm] = α². (Other angles: the BSDF tests'
    /// chi-square test of sampling against the density.)
    #[test]
    fn beckmann_visible_slopes_have_the_right_spread() {
        for alpha in [0.1f32, 0.4] {
            let g = Microfacet::isotropic(Distribution::Beckmann, alpha);
            let mut s = Sampler::new(7, Stream::Camera, 0, 0);
            let n = 200_000;
            let mut t2 = 0.0f64;
            for _ in 0..n {
                let m = g.sample_visible(Vec3A::Z, s.next_2d());
                assert!(m.is_finite() && m.z > 0.0, "{m}");
                t2 += ((m.x * m.x + m.y * m.y) / (m.z * m.z)) as f64;
            }
            let est = t2 / n as f64 / (alpha * alpha) as f64;
            assert!(
                (est - 1.0).abs() < 0.02,
                "alpha {alpha}: E[tan^2]/alpha^2 = {est}"
            );
        }
    }
}
