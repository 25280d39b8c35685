//! Transmittance from a camera ray's origin to every distance along it, for the beam
//! estimates, which weigh each photon met along the ray by it: in closed form in a medium of
//! constant density, by one ratio-tracking pass in one whose density varies.
//!
//! Why one pass serves the whole ray: ratio tracking's running product of (1 − σt/μ) over the
//! tentative collisions before t is an unbiased estimate of Tr(t) for every t at once, so the
//! piecewise-constant function it leaves can be read at a photon's distance, or integrated
//! over its chord exactly. Estimating each photon's transmittance anew would cost a tracking
//! pass per photon, and correlating them costs no bias (each photon's term stays unbiased).
//!
//! Both forms play Russian roulette past a transmittance of [`ROULETTE_BELOW`] (in the clearest
//! channel): in a dense medium, photons far along the ray contribute almost nothing and would
//! cost as much as the near ones. The closed form draws one random number for the whole
//! stretch, survival S(t) = Tr_min(t) / 0.1; ratio tracking plays it at each tentative collision
//! past the threshold. Either way the estimate is zero past [`RayTransmittance::t_stop`], where
//! the photon march ends.

use crate::color::Rgb;
use crate::geometry::Ray;
use crate::medium::{Density, Medium};
use crate::sampling::Sampler;

/// Below this transmittance (from the ray's origin, in its clearest channel) the estimate
/// plays Russian roulette with the rest of the ray.
pub const ROULETTE_BELOW: f32 = 0.1;

/// Tr(t) along one camera ray, divided by the roulette's survival.
pub enum RayTransmittance<'a> {
    /// A medium of constant density: Tr = e^(−σt t), with the roulette's survival S(t) and
    /// the distance `t_cut` where it fails.
    Closed {
        /// The medium.
        medium: &'a Medium,
        /// The clearest channel's σt, which the survival follows.
        sigma_min: f32,
        /// Where the roulette ends the stretch (infinity: never).
        t_cut: f32,
    },
    /// A medium whose density varies: the ratio-tracking estimate, 1 before the first step
    /// and each step's value from its distance on.
    Tracked(Vec<(f32, Rgb)>),
}

impl<'a> RayTransmittance<'a> {
    /// The estimate along `ray.at(0..t_max)` in `medium`: one random number in closed form,
    /// a ratio-tracking pass otherwise.
    pub fn new(medium: &'a Medium, ray: &Ray, t_max: f32, sampler: &mut Sampler) -> RayTransmittance<'a> {
        match medium.density() {
            None => RayTransmittance::closed(medium, sampler.next_1d()),
            Some(density) => RayTransmittance::tracked(density, ray, t_max, sampler),
        }
    }

    fn closed(medium: &'a Medium, u_cut: f32) -> RayTransmittance<'a> {
        let sigma_min = medium.sigma_t.min_element();
        let t_cut = if sigma_min > 0.0 {
            -libm::logf(u_cut * ROULETTE_BELOW) / sigma_min
        } else {
            f32::INFINITY
        };
        RayTransmittance::Closed {
            medium,
            sigma_min,
            t_cut,
        }
    }

    fn tracked(density: &Density, ray: &Ray, t_max: f32, sampler: &mut Sampler) -> RayTransmittance<'a> {
        let mut steps = Vec::new();
        density.ratio_steps(ray, t_max, ROULETTE_BELOW, sampler, |t, tr| steps.push((t, tr)));
        RayTransmittance::Tracked(steps)
    }

    /// The distance past which the estimate is zero (infinity: nowhere).
    pub fn t_stop(&self) -> f32 {
        match self {
            RayTransmittance::Closed { t_cut, .. } => *t_cut,
            RayTransmittance::Tracked(steps) => match steps.last() {
                Some(&(t, tr)) if tr == Rgb::ZERO => t,
                _ => f32::INFINITY,
            },
        }
    }

    /// The closed form's survival to distance t.
    fn survival(sigma_min: f32, t: f32) -> f32 {
        if sigma_min > 0.0 {
            (libm::expf(-sigma_min * t) / ROULETTE_BELOW).min(1.0)
        } else {
            1.0
        }
    }

    /// Tr(t) / S(t), for a photon met at distance t.
    pub fn at(&self, t: f32) -> Rgb {
        match self {
            RayTransmittance::Closed {
                medium, sigma_min, ..
            } => medium.transmittance(t) / Self::survival(*sigma_min, t),
            RayTransmittance::Tracked(steps) => match steps.partition_point(|s| s.0 <= t) {
                0 => Rgb::ONE,
                i => steps[i - 1].1,
            },
        }
    }

    /// ∫ Tr dt over [a, b] for a photon's chord: in closed form weighted by 1/S(a) (the chord
    /// counts if the stretch survives to its start), exactly over the steps otherwise.
    pub fn over(&self, a: f32, b: f32) -> Rgb {
        match self {
            RayTransmittance::Closed {
                medium, sigma_min, ..
            } => medium.integrated_transmittance(a, b) / Self::survival(*sigma_min, a),
            RayTransmittance::Tracked(steps) => {
                let first = steps.partition_point(|s| s.0 <= a);
                let mut value = if first == 0 { Rgb::ONE } else { steps[first - 1].1 };
                let (mut from, mut sum) = (a, Rgb::ZERO);
                for &(t, tr) in steps[first..].iter().take_while(|s| s.0 < b) {
                    sum += value * (t - from);
                    (from, value) = (t, tr);
                }
                sum + value * (b - from)
            }
        }
    }

    /// The estimate at the stretch's end `t_max`: what the surface behind it is weighted by.
    pub fn at_end(&self, t_max: f32) -> Rgb {
        match self {
            RayTransmittance::Closed {
                medium,
                sigma_min,
                t_cut,
            } => {
                let s_end = Self::survival(*sigma_min, t_max);
                if (t_max < *t_cut || *t_cut == f32::INFINITY) && s_end > 0.0 {
                    medium.transmittance(t_max) / s_end
                } else {
                    Rgb::ZERO
                }
            }
            RayTransmittance::Tracked(_) => self.at(t_max),
        }
    }
}

#[cfg(test)]
mod tests {
    use glam::Vec3A;

    use super::*;
    use crate::medium::two_voxels;
    use crate::sampling::Stream;

    /// Through two grey voxels of σt 2 and 6 (a ray from x = −1 meets them at t = 1 and 2),
    /// the tracked estimate's mean matches the exact transmittance at several
    /// distances and its integral matches ∫ Tr over chords, with the roulette (which starts
    /// near t = 2.1) playing for the far ones.
    #[test]
    fn tracked_estimates_are_unbiased_at_every_distance_and_over_chords() {
        let medium = two_voxels(Rgb::ONE, Rgb::splat(3.0), 2.0);
        let ray = Ray::new(Vec3A::new(-1.0, 0.5, 0.5), Vec3A::X);
        let optical = |t: f64| 2.0 * (t - 1.0).clamp(0.0, 1.0) + 6.0 * (t - 2.0).clamp(0.0, 1.0);
        let exact_at = |t: f32| libm::exp(-optical(t as f64));
        let exact_over = |a: f32, b: f32| {
            let n = 4000;
            let h = (b - a) as f64 / n as f64;
            (0..n)
                .map(|i| libm::exp(-optical(a as f64 + h * (i as f64 + 0.5))) * h)
                .sum::<f64>()
        };
        let n = 100_000;
        let probes = [0.5f32, 1.5, 2.2, 2.4];
        let chords = [(0.5f32, 1.5f32), (1.8, 2.3), (2.2, 2.9), (0.0, 10.0)];
        let (mut at, mut over) = ([0.0f64; 4], [0.0f64; 4]);
        for i in 0..n {
            let mut s = Sampler::new(3, Stream::Camera, i, 0);
            let tr = RayTransmittance::new(&medium, &ray, 10.0, &mut s);
            for (k, &t) in probes.iter().enumerate() {
                at[k] += tr.at(t).x as f64 / n as f64;
            }
            for (k, &(a, b)) in chords.iter().enumerate() {
                over[k] += tr.over(a, b).x as f64 / n as f64;
            }
            assert_eq!(tr.at_end(10.0), tr.at(10.0));
        }
        for (k, &t) in probes.iter().enumerate() {
            let want = exact_at(t);
            assert!(
                (at[k] - want).abs() < 0.03 * want,
                "Tr({t}) = {:.5}, exact {want:.5}",
                at[k]
            );
        }
        for (k, &(a, b)) in chords.iter().enumerate() {
            let want = exact_over(a, b);
            assert!(
                (over[k] - want).abs() < 0.03 * want,
                "∫Tr over {a}..{b} = {:.5}, exact {want:.5}",
                over[k]
            );
        }
    }
}
