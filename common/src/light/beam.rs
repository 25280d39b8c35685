use std::f32::consts::PI;

use glam::{Vec2, Vec3A};

use super::{EmittedPhoton, LightSample};
use crate::color::{Rgb, luminance};
use crate::geometry::{Frame, Ray};
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

    /// The part of `ray.at(0..t_max)` inside the beam's cylinder, past its disc.
    pub(super) fn lit_span(&self, ray: &Ray, t_max: f32) -> Option<(f32, f32)> {
        let n = self.frame.n;
        let v = ray.o - self.origin;
        let (v_along, d_along) = (v.dot(n), ray.d.dot(n));
        let (v_perp, d_perp) = (v - v_along * n, ray.d - d_along * n);
        // |v⊥ + t d⊥|² ≤ r²: a t² + 2 b t + c ≤ 0.
        let (a, b, c) = (
            d_perp.length_squared(),
            v_perp.dot(d_perp),
            v_perp.length_squared() - self.radius * self.radius,
        );
        let (mut lo, mut hi) = if a <= 1e-12 {
            if c > 0.0 {
                return None;
            }
            (0.0, t_max)
        } else {
            let disc = b * b - a * c;
            if disc < 0.0 {
                return None;
            }
            let root = disc.sqrt();
            ((-b - root) / a, (-b + root) / a)
        };
        // Past the disc: v_along + t d_along > 0.
        if d_along > 0.0 {
            lo = lo.max(-v_along / d_along);
        } else if d_along < 0.0 {
            hi = hi.min(-v_along / d_along);
        } else if v_along <= 0.0 {
            return None;
        }
        let (lo, hi) = (lo.max(0.0), hi.min(t_max));
        (lo < hi).then_some((lo, hi))
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

#[cfg(test)]
mod tests {
    use super::*;

    /// The span holds exactly the points of the segment that the beam lights.
    #[test]
    fn lit_span_is_where_the_beam_reaches() {
        let beam = BeamLight {
            origin: Vec3A::new(0.0, 5.0, 0.0),
            frame: Frame::from_normal(Vec3A::new(0.1, -1.0, 0.05).normalize()),
            radius: 0.3,
            irradiance: Rgb::ONE,
        };
        let mut s = crate::sampling::Sampler::new(7, crate::sampling::Stream::Camera, 0, 0);
        let (mut spans, mut misses) = (0, 0);
        for _ in 0..2000 {
            let o = Vec3A::new(0.0, 2.5, 0.0) + (Vec3A::from(s.next_2d().extend(s.next_1d())) - 0.5) * 8.0;
            let target =
                Vec3A::new(0.0, 2.5, 0.0) + (Vec3A::from(s.next_2d().extend(s.next_1d())) - 0.5) * 2.0;
            let ray = Ray::new(o, (target - o).normalize());
            let t_max = 10.0 * s.next_1d();
            let span = beam.lit_span(&ray, t_max);
            if span.is_some() {
                spans += 1;
            } else {
                misses += 1;
            }
            for i in 0..400 {
                let t = t_max * (i as f32 + 0.5) / 400.0;
                let lit = beam.sample_li(ray.at(t)).is_some();
                let inside = span.is_some_and(|(a, b)| t >= a && t <= b);
                // Points within float error of the span's ends may go either way.
                let near_end = span.is_some_and(|(a, b)| (t - a).abs() < 1e-3 || (t - b).abs() < 1e-3);
                assert!(lit == inside || near_end, "t {t} lit {lit} span {span:?}");
            }
        }
        assert!(spans > 200 && misses > 200, "{spans} {misses}");
    }
}
