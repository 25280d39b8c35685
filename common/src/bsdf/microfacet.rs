//! Microfacet distributions, Beckmann (Mitsuba's default) and GGX, with visible-normal sampling
//! and Mitsuba 3's exact formulas: its Beckmann masking term is the rational approximation of
//! Smith's (within 0.35%), so we use the same, and rough materials render as in Mitsuba.

use std::f32::consts::PI;

use glam::{Vec2, Vec3A};

/// The shape of the distribution of microfacet normals.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Distribution {
    /// Gaussian slopes: Mitsuba's default.
    Beckmann,
    /// Trowbridge–Reitz: longer tails.
    Ggx,
}

/// An isotropic microfacet distribution with roughness `alpha`.
#[derive(Clone, Copy, Debug)]
pub struct Microfacet {
    /// Which distribution.
    pub distribution: Distribution,
    /// Roughness (Mitsuba's `alpha`).
    pub alpha: f32,
}

/// A distribution whose roughness may vary over the surface (a texture on `alpha`).
#[derive(Clone, Debug)]
pub struct Roughness {
    /// Which distribution.
    pub distribution: Distribution,
    /// Mitsuba's `alpha`.
    pub alpha: crate::texture::Param<f32>,
}

impl Roughness {
    /// The distribution at `uv`; roughness below 1e-4 is raised to it, as Mitsuba does.
    #[inline]
    pub fn at(&self, uv: glam::Vec2) -> Microfacet {
        Microfacet {
            distribution: self.distribution,
            alpha: self.alpha.at(uv).max(1e-4),
        }
    }
}

impl Microfacet {
    /// Normal distribution D(m).
    pub fn d(&self, m: Vec3A) -> f32 {
        if m.z <= 0.0 {
            return 0.0;
        }
        let a2 = self.alpha * self.alpha;
        let c2 = m.z * m.z;
        let d = match self.distribution {
            Distribution::Beckmann => libm::expf(-(m.x * m.x + m.y * m.y) / (a2 * c2)) / (PI * a2 * c2 * c2),
            Distribution::Ggx => {
                let denom = c2 * (a2 - 1.0) + 1.0;
                a2 / (PI * denom * denom)
            }
        };
        if d * m.z > 1e-20 { d } else { 0.0 }
    }

    /// Smith's masking term for one direction against microfacet `m`.
    pub fn g1(&self, v: Vec3A, m: Vec3A) -> f32 {
        if v.dot(m) * v.z <= 0.0 {
            return 0.0;
        }
        let xy = self.alpha * self.alpha * (v.x * v.x + v.y * v.y);
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

    /// Heitz's exact sampling of GGX's visible normals (the anisotropic code with equal
    /// roughnesses: the same arithmetic).
    fn sample_visible_ggx(&self, wi: Vec3A, u: Vec2) -> Vec3A {
        AnisotropicGgx {
            alpha_u: self.alpha,
            alpha_v: self.alpha,
        }
        .sample_visible(wi, u)
    }

    /// Beckmann's visible normals: stretch the view to unit roughness, draw slopes with Jakob's
    /// inversion of the visible-slope distribution (three Newton steps), rotate and unstretch,
    /// as Mitsuba does. In f64: the inversion works near erf's flat ends.
    fn sample_visible_beckmann(&self, wi: Vec3A, u: Vec2) -> Vec3A {
        use libm::erf;
        use statrs::function::erf::erf_inv;
        let a = self.alpha as f64;
        let (wx, wy, wz) = (a * wi.x as f64, a * wi.y as f64, wi.z as f64);
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
        Vec3A::new((-rx * a) as f32, (-ry * a) as f32, 1.0).normalize()
    }

    /// Density of [`Microfacet::sample_visible`] per unit solid angle of `m`.
    pub fn pdf_visible(&self, wi: Vec3A, m: Vec3A) -> f32 {
        if wi.z <= 0.0 {
            return 0.0;
        }
        self.g1(wi, m) * wi.dot(m).max(0.0) * self.d(m) / wi.z
    }
}

/// An anisotropic GGX distribution (roughness `alpha_u` along the shading frame's first tangent,
/// `alpha_v` along the second), with Mitsuba 3's formulas: the principled BSDF's main lobes.
/// [`Microfacet`] stays the isotropic model of the other materials.
#[derive(Clone, Copy, Debug)]
pub struct AnisotropicGgx {
    /// Roughness along x.
    pub alpha_u: f32,
    /// Roughness along y.
    pub alpha_v: f32,
}

impl AnisotropicGgx {
    /// Normal distribution D(m).
    pub fn d(&self, m: Vec3A) -> f32 {
        let (x, y) = (m.x / self.alpha_u, m.y / self.alpha_v);
        let s = x * x + y * y + m.z * m.z;
        let d = 1.0 / (PI * self.alpha_u * self.alpha_v * s * s);
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
        2.0 / (1.0 + (1.0 + tan2).sqrt())
    }

    /// Separable masking-shadowing, as Mitsuba uses.
    pub fn g(&self, wi: Vec3A, wo: Vec3A, m: Vec3A) -> f32 {
        self.g1(wi, m) * self.g1(wo, m)
    }

    /// A microfacet normal drawn from the normals visible from `wi` (wi.z > 0): Heitz's exact
    /// method, with the view stretched by (alpha_u, alpha_v) and the normal unstretched.
    pub fn sample_visible(&self, wi: Vec3A, u: Vec2) -> Vec3A {
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

    /// Density of [`AnisotropicGgx::sample_visible`] per unit solid angle of `m`.
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
                let g = Microfacet { distribution, alpha };
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

    #[test]
    fn anisotropic_ggx_is_normalised_and_matches_the_isotropic_one() {
        let mut s = Sampler::new(3, Stream::Camera, 0, 0);
        for (au, av) in [(0.05f32, 0.2f32), (0.3, 0.1), (0.6, 0.6)] {
            let g = AnisotropicGgx {
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
            assert!((area - 1.0).abs() < 0.05, "({au}, {av}): projected area {area}");
            assert!(
                (visible - 1.0).abs() < 0.05,
                "({au}, {av}): visible normals {visible}"
            );
        }
        // Equal roughnesses: the isotropic GGX, to rounding.
        let iso = Microfacet {
            distribution: Distribution::Ggx,
            alpha: 0.3,
        };
        let aniso = AnisotropicGgx {
            alpha_u: 0.3,
            alpha_v: 0.3,
        };
        for _ in 0..1000 {
            let wi = crate::sampling::square_to_cosine_hemisphere(s.next_2d());
            let u = s.next_2d();
            let (a, b) = (iso.sample_visible(wi, u), aniso.sample_visible(wi, u));
            assert!((a - b).length() < 1e-5, "{a} vs {b}");
            let rel = |x: f32, y: f32| (x - y).abs() <= 1e-4 * x.abs().max(y.abs()).max(1e-6);
            assert!(rel(iso.d(a), aniso.d(a)), "{} vs {}", iso.d(a), aniso.d(a));
            assert!(rel(iso.g1(wi, a), aniso.g1(wi, a)));
            assert!(rel(iso.pdf_visible(wi, a), aniso.pdf_visible(wi, a)));
        }
    }

    /// At normal incidence the visible normals are distributed as D(m) cos θm, whose Beckmann
    /// slopes have variance α²/2 per axis: E[tan² θm] = α². (Other angles: the BSDF tests'
    /// chi-square test of sampling against the density.)
    #[test]
    fn beckmann_visible_slopes_have_the_right_spread() {
        for alpha in [0.1f32, 0.4] {
            let g = Microfacet {
                distribution: Distribution::Beckmann,
                alpha,
            };
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
