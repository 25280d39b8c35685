//! Homogeneous participating media and their phase functions.
//!
//! Free-flight distances are sampled from the channel-averaged density
//! p(t) = mean_c σt_c exp(−σt_c t), as Mitsuba's RGB volumetric path tracer does, so that a
//! chromatic medium stays unbiased in every channel: the caller multiplies its throughput by the
//! returned per-channel weight.

use std::f32::consts::PI;

use glam::{Vec2, Vec3A};

use crate::color::Rgb;
use crate::geometry::Frame;

/// A phase function.
#[derive(Clone, Copy, Debug, PartialEq)]
pub enum Phase {
    /// Uniform over the sphere.
    Isotropic,
    /// Henyey–Greenstein with mean cosine g in (−1, 1).
    HenyeyGreenstein(f32),
}

impl Phase {
    /// Density of scattering from direction of travel `d_in` into `d_out` (both unit, both
    /// pointing along the light's travel), per steradian. Symmetric, so it is also the pdf of
    /// [`Phase::sample`].
    pub fn eval(&self, d_in: Vec3A, d_out: Vec3A) -> f32 {
        match *self {
            Phase::Isotropic => 1.0 / (4.0 * PI),
            Phase::HenyeyGreenstein(g) => {
                let cos = d_in.dot(d_out);
                let denom = 1.0 + g * g - 2.0 * g * cos;
                (1.0 - g * g) / (4.0 * PI * denom * denom.max(1e-12).sqrt())
            }
        }
    }

    /// Samples an outgoing direction of travel given the incoming one; returns it and its pdf.
    pub fn sample(&self, d_in: Vec3A, u: Vec2) -> (Vec3A, f32) {
        let cos = match *self {
            Phase::Isotropic => 1.0 - 2.0 * u.x,
            Phase::HenyeyGreenstein(g) if g.abs() < 1e-3 => 1.0 - 2.0 * u.x,
            Phase::HenyeyGreenstein(g) => {
                let s = (1.0 - g * g) / (1.0 - g + 2.0 * g * u.x);
                ((1.0 + g * g - s * s) / (2.0 * g)).clamp(-1.0, 1.0)
            }
        };
        let sin = (1.0 - cos * cos).max(0.0).sqrt();
        let phi = 2.0 * PI * u.y;
        let d = Frame::from_normal(d_in).to_world(Vec3A::new(sin * phi.cos(), sin * phi.sin(), cos));
        (d, self.eval(d_in, d))
    }
}

/// A homogeneous medium.
#[derive(Clone, Debug, PartialEq)]
pub struct Medium {
    /// Extinction coefficient per unit length (after Mitsuba's `scale`).
    pub sigma_t: Rgb,
    /// Single-scattering albedo σs / σt.
    pub albedo: Rgb,
    /// The phase function.
    pub phase: Phase,
}

/// Where a free flight ended.
#[derive(Clone, Copy, Debug)]
pub enum Flight {
    /// A collision inside the medium at distance `t`; multiply the throughput by `weight`
    /// (transmittance times σt over the sampling density; the albedo is not included).
    Collision {
        /// Distance.
        t: f32,
        /// Per-channel weight.
        weight: Rgb,
    },
    /// No collision before `t_max`; multiply the throughput by `weight` (transmittance over
    /// the probability of getting that far).
    Passed {
        /// Per-channel weight.
        weight: Rgb,
    },
}

impl Medium {
    /// Transmittance over a distance.
    pub fn transmittance(&self, dist: f32) -> Rgb {
        if !dist.is_finite() {
            return Rgb::select(self.sigma_t.cmpgt(Rgb::ZERO), Rgb::ZERO, Rgb::ONE);
        }
        (-self.sigma_t * dist).exp()
    }

    /// Samples a free flight along a unit-speed ray with a surface (or nothing) at `t_max`.
    /// `u_channel` picks the channel whose coefficient drives the sampling, `u` the distance.
    pub fn sample_flight(&self, t_max: f32, u_channel: f32, u: f32) -> Flight {
        let c = ((u_channel * 3.0) as usize).min(2);
        let s = self.sigma_t[c];
        let t = if s > 0.0 {
            -(1.0 - u).ln() / s
        } else {
            f32::INFINITY
        };
        if t < t_max {
            let tr = self.transmittance(t);
            let pdf = (self.sigma_t * tr).dot(Rgb::splat(1.0 / 3.0));
            Flight::Collision {
                t,
                weight: if pdf > 0.0 {
                    self.sigma_t * tr / pdf
                } else {
                    Rgb::ZERO
                },
            }
        } else {
            let tr = self.transmittance(t_max);
            let p = tr.dot(Rgb::splat(1.0 / 3.0));
            Flight::Passed {
                weight: if p > 0.0 { tr / p } else { Rgb::ZERO },
            }
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::sampling::{Sampler, Stream, square_to_uniform_sphere};

    #[test]
    fn phase_functions_are_normalised_and_sampled_by_their_pdf() {
        for phase in [
            Phase::Isotropic,
            Phase::HenyeyGreenstein(0.6),
            Phase::HenyeyGreenstein(-0.3),
        ] {
            let d_in = Vec3A::new(0.3, -0.4, 0.866).normalize();
            let mut s = Sampler::new(1, Stream::Photon, 0, 0);
            let n = 200_000;
            let (mut integral, mut mean_cos) = (0.0f64, 0.0f64);
            for _ in 0..n {
                integral += (phase.eval(d_in, square_to_uniform_sphere(s.next_2d())) * 4.0 * PI) as f64;
                let (d, pdf) = phase.sample(d_in, s.next_2d());
                assert!((pdf - phase.eval(d_in, d)).abs() <= 1e-4 * pdf.max(1.0));
                mean_cos += d.dot(d_in) as f64;
            }
            assert!(
                (integral / n as f64 - 1.0).abs() < 0.02,
                "{phase:?}: {}",
                integral / n as f64
            );
            let g = match phase {
                Phase::Isotropic => 0.0,
                Phase::HenyeyGreenstein(g) => g as f64,
            };
            assert!(
                (mean_cos / n as f64 - g).abs() < 0.01,
                "{phase:?}: mean cosine {}",
                mean_cos / n as f64
            );
        }
    }

    #[test]
    fn free_flights_are_unbiased_per_channel() {
        // E[weight · 1(collision before t)] must equal 1 − exp(−σ t) in every channel.
        let m = Medium {
            sigma_t: Rgb::new(0.5, 1.0, 3.0),
            albedo: Rgb::ONE,
            phase: Phase::Isotropic,
        };
        let mut s = Sampler::new(2, Stream::Photon, 0, 0);
        let n = 400_000;
        let (mut collide, mut pass) = (Rgb::ZERO, Rgb::ZERO);
        for _ in 0..n {
            match m.sample_flight(0.7, s.next_1d(), s.next_1d()) {
                // E[weight] over collisions = ∫ σt·Tr = 1 − Tr(t_max), per channel.
                Flight::Collision { weight, .. } => collide += weight,
                Flight::Passed { weight } => pass += weight,
            }
        }
        let expect_pass = m.transmittance(0.7);
        assert!(
            ((pass / n as f32) - expect_pass).abs().max_element() < 0.01,
            "{} vs {expect_pass}",
            pass / n as f32
        );
        let expect_collide = Rgb::ONE - expect_pass;
        assert!(
            ((collide / n as f32) - expect_collide).abs().max_element() < 0.01,
            "{} vs {expect_collide}",
            collide / n as f32
        );
    }
}
