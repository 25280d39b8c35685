//! Participating media and their phase functions.
//!
//! Free-flight distances in a homogeneous medium are sampled from the channel-averaged density
//! p(t) = mean_c σt_c exp(−σt_c t), as Mitsuba's RGB volumetric path tracer does, so that a
//! chromatic medium stays unbiased in every channel: the caller multiplies its throughput by the
//! returned per-channel weight.
//!
//! A heterogeneous medium (σt from a grid) is sampled by delta tracking against a majorant and
//! its transmittance estimated by ratio tracking, both unbiased; only such a medium draws the
//! random numbers they need, so scenes without one render the same bytes as before.

use std::f32::consts::PI;

use glam::{Vec2, Vec3A};

use crate::color::Rgb;
use crate::geometry::{Frame, Ray};
use crate::sampling::Sampler;
use crate::volume::GridVolume;

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
        let (sin_phi, cos_phi) = libm::sincosf(phi);
        let d = Frame::from_normal(d_in).to_world(Vec3A::new(sin * cos_phi, sin * sin_phi, cos));
        (d, self.eval(d_in, d))
    }
}

/// A medium.
#[derive(Clone, Debug, PartialEq)]
pub struct Medium {
    /// Extinction coefficient per unit length (after Mitsuba's `scale`). In a heterogeneous
    /// medium, the majorant in every channel: read σt through [`Medium::sigma_t_at`].
    pub sigma_t: Rgb,
    /// Single-scattering albedo σs / σt, where no grid gives it: read it through
    /// [`Medium::albedo_at`].
    pub albedo: Rgb,
    /// The phase function.
    pub phase: Phase,
    /// What varies in space; None for the common homogeneous medium of constant albedo.
    pub grids: Option<Box<Grids>>,
}

/// The parts of a medium given by grids.
#[derive(Clone, Debug, PartialEq)]
pub struct Grids {
    /// Mitsuba's `heterogeneous`: σt from a grid.
    pub density: Option<Density>,
    /// The albedo from a grid (in a homogeneous or a heterogeneous medium).
    pub albedo: Option<GridVolume>,
}

/// σt = scale · grid inside the grid's box, zero outside it (Mitsuba samples collisions only
/// within the box).
#[derive(Clone, Debug, PartialEq)]
pub struct Density {
    /// The grid.
    pub grid: GridVolume,
    /// Mitsuba's `scale`.
    pub scale: f32,
    /// A bound on σt in every channel (scale times the grid's maximum, or Mitsuba's
    /// `max_value`): the rate of tentative collisions in delta and ratio tracking.
    pub majorant: f32,
}

/// Tentative collisions one flight or one transmittance estimate may take: a majorant times
/// length of a million. Beyond it the light is taken as absorbed, which nothing but a medium of
/// absurd density reaches, and which ends the walk instead of hanging it.
const MAX_TENTATIVE: u32 = 1 << 20;

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
    /// A homogeneous medium of constant albedo.
    pub fn homogeneous(sigma_t: Rgb, albedo: Rgb, phase: Phase) -> Medium {
        Medium {
            sigma_t,
            albedo,
            phase,
            grids: None,
        }
    }

    /// The density grid, for a heterogeneous medium.
    pub fn density(&self) -> Option<&Density> {
        self.grids.as_ref()?.density.as_ref()
    }

    /// Whether σt and the albedo are the same everywhere, so that an estimate along a ray can
    /// take them out of its sums.
    pub fn is_uniform(&self) -> bool {
        self.grids.is_none()
    }

    /// Single-scattering albedo at `p`.
    pub fn albedo_at(&self, p: Vec3A) -> Rgb {
        match self.grids.as_ref().and_then(|g| g.albedo.as_ref()) {
            Some(grid) => grid.eval(p),
            None => self.albedo,
        }
    }

    /// Extinction at `p`.
    pub fn sigma_t_at(&self, p: Vec3A) -> Rgb {
        match self.density() {
            None => self.sigma_t,
            Some(d) => d.sigma_t_at(p),
        }
    }

    /// Samples a free flight along `ray` (unit direction) with a surface (or nothing) at
    /// `t_max`: closed-form in a homogeneous medium (two random numbers), by delta tracking in a
    /// heterogeneous one.
    pub fn sample_flight_along(&self, ray: &Ray, t_max: f32, sampler: &mut Sampler) -> Flight {
        match self.density() {
            None => self.sample_flight(t_max, sampler.next_1d(), sampler.next_1d()),
            Some(d) => d.delta_tracking(ray, t_max, sampler),
        }
    }

    /// Transmittance along `ray.at(0..t_max)` (unit direction): exact in a homogeneous medium
    /// (no random numbers), an unbiased ratio-tracking estimate in a heterogeneous one.
    pub fn transmittance_along(&self, ray: &Ray, t_max: f32, sampler: &mut Sampler) -> Rgb {
        match self.density() {
            None => self.transmittance(t_max),
            Some(d) => d.ratio_tracking(ray, t_max, sampler),
        }
    }

    /// σt · Tr at `ray.at(t)` from the ray's origin (unit direction): what a collision drawn
    /// by some other density than the flight's (equiangularly about a light) is weighted by.
    pub fn collision_weight(&self, ray: &Ray, t: f32, sampler: &mut Sampler) -> Rgb {
        match self.density() {
            None => self.sigma_t * self.transmittance(t),
            Some(d) => d.sigma_t_at(ray.at(t)) * d.ratio_tracking(ray, t, sampler),
        }
    }

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
            -libm::logf(1.0 - u) / s
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

    /// Probability that [`Medium::sample_flight`] flies past distance `t` (its channel is picked
    /// uniformly among the three): what turns a photon beam ended at its sampled collision into
    /// an unbiased estimate of the transmitted power, Φ·Tr(t)/P(flight > t) along it.
    pub fn flight_survival(&self, t: f32) -> f32 {
        self.transmittance(t).dot(Rgb::splat(1.0 / 3.0))
    }

    /// ∫ Tr(t) dt over [a, b], per channel: what a stretch of the ray contributes to an
    /// estimate that is constant along it (the beam radiance estimate's photon chords).
    pub fn integrated_transmittance(&self, a: f32, b: f32) -> Rgb {
        let len = b - a;
        let one = |s: f32| {
            let x = s * len;
            if x < 0.1 {
                // (1 − e^−x)/x by its series, to 4e-5 relative: one exp less, and no division
                // by s = 0.
                libm::expf(-s * a) * len * (1.0 - x * (0.5 - x * (1.0 / 6.0)))
            } else {
                libm::expf(-s * a) * -libm::expm1f(-s * len) / s
            }
        };
        Rgb::new(one(self.sigma_t.x), one(self.sigma_t.y), one(self.sigma_t.z))
    }

    /// Samples a collision that always happens before `t_max` (which may be infinite), from
    /// the exponential of a channel with σt > 0 truncated to [0, t_max), the channel picked
    /// uniformly by `u_channel`. Returns the distance and the weight Tr·σt / pdf, with the pdf
    /// the mixture over those channels, so that E[weight · g(t)] = ∫₀^t_max Tr σt g dt in every
    /// channel (channels with σt = 0 scatter nothing). None if no channel attenuates.
    pub fn sample_collision_within(&self, t_max: f32, u_channel: f32, u: f32) -> Option<(f32, Rgb)> {
        let sigma = [self.sigma_t.x, self.sigma_t.y, self.sigma_t.z];
        let n = sigma.iter().filter(|s| **s > 0.0).count();
        if n == 0 || t_max <= 0.0 {
            return None;
        }
        // Probability of colliding before t_max in each channel, without cancellation.
        let reach = sigma.map(|s| if s > 0.0 { -libm::expm1f(-s * t_max) } else { 0.0 });
        let pick = ((u_channel * n as f32) as usize).min(n - 1);
        let c = (0..3).filter(|&c| sigma[c] > 0.0).nth(pick)?;
        let t = (-libm::log1pf(-u * reach[c]) / sigma[c]).min(t_max.next_down());
        let tr = self.transmittance(t);
        let pdf: f32 = (0..3)
            .filter(|&c| sigma[c] > 0.0)
            .map(|c| sigma[c] * tr[c] / reach[c])
            .sum::<f32>()
            / n as f32;
        (pdf > 0.0 && t.is_finite()).then(|| (t, self.sigma_t * tr / pdf))
    }
}

impl Density {
    /// σt at `p`.
    pub fn sigma_t_at(&self, p: Vec3A) -> Rgb {
        let b = self.grid.bbox();
        if p.cmplt(b.min).any() || p.cmpgt(b.max).any() {
            return Rgb::ZERO;
        }
        self.grid.eval(p) * self.scale
    }

    /// Delta tracking against the majorant μ, over the part of the ray inside the grid's box.
    /// At each tentative collision the event is real with probability mean(σt)/μ and null
    /// otherwise, and the throughput takes the ratio of each channel's probability to that:
    /// σt/mean(σt) for a real one, (μ − σt)/(μ − mean(σt)) for a null one. Unbiased in every
    /// channel of a chromatic medium without picking a channel (a grey medium's weights are 1).
    fn delta_tracking(&self, ray: &Ray, t_max: f32, sampler: &mut Sampler) -> Flight {
        let mu = self.majorant;
        let Some((mut t, end)) = self.grid.bbox().clip(ray, t_max).filter(|_| mu > 0.0) else {
            return Flight::Passed { weight: Rgb::ONE };
        };
        let mut weight = Rgb::ONE;
        for _ in 0..MAX_TENTATIVE {
            t -= libm::log1pf(-sampler.next_1d()) / mu;
            if t >= end {
                return Flight::Passed { weight };
            }
            let s = self.sigma_t_at(ray.at(t));
            let mean = (s.x + s.y + s.z) * (1.0 / 3.0);
            if sampler.next_1d() * mu < mean {
                return Flight::Collision {
                    t,
                    weight: weight * s / mean,
                };
            }
            if mean > 0.0 {
                weight *= (Rgb::splat(mu) - s) / (mu - mean);
            }
        }
        Flight::Passed { weight: Rgb::ZERO }
    }

    /// Ratio tracking: the product of (1 − σt/μ) over the tentative collisions, an unbiased
    /// estimate of the transmittance in every channel.
    fn ratio_tracking(&self, ray: &Ray, t_max: f32, sampler: &mut Sampler) -> Rgb {
        self.ratio_steps(ray, t_max, 0.0, sampler, |_, _| {})
    }

    /// Ratio tracking that reports every tentative collision: `step(t, tr)` with the estimate
    /// from the ray's origin to just past t, so that the running product is an unbiased
    /// estimate at every distance at once (what an estimate integrated along the ray needs).
    /// Below `roulette` in its largest channel the estimate survives each further collision
    /// with probability max(tr)/`roulette`, divided by it; 0 plays no roulette (and draws no
    /// extra random numbers). Returns the estimate at `t_max`; a zero step is the last.
    pub fn ratio_steps(
        &self,
        ray: &Ray,
        t_max: f32,
        roulette: f32,
        sampler: &mut Sampler,
        mut step: impl FnMut(f32, Rgb),
    ) -> Rgb {
        let mu = self.majorant;
        let Some((mut t, end)) = self.grid.bbox().clip(ray, t_max).filter(|_| mu > 0.0) else {
            return Rgb::ONE;
        };
        let mut tr = Rgb::ONE;
        for _ in 0..MAX_TENTATIVE {
            t -= libm::log1pf(-sampler.next_1d()) / mu;
            if t >= end {
                return tr;
            }
            tr *= (Rgb::ONE - self.sigma_t_at(ray.at(t)) / mu).max(Rgb::ZERO);
            let largest = tr.max_element();
            if largest < roulette {
                let q = largest / roulette;
                tr = if sampler.next_1d() < q { tr / q } else { Rgb::ZERO };
            }
            step(t, tr);
            if tr == Rgb::ZERO {
                return tr;
            }
        }
        step(t, Rgb::ZERO);
        Rgb::ZERO
    }
}

/// Two voxels along x over [0, 2] × [0, 1]², σt `first` on the first and `second` on the
/// second, times `scale`, looked up nearest; the majorant is the largest σt.
#[cfg(test)]
pub(crate) fn two_voxels(first: Rgb, second: Rgb, scale: f32) -> Medium {
    use crate::texture::Wrap;
    use crate::volume::{GridVolume, VolumeData, VolumeFilter};
    let mut bytes = b"VOL\x03".to_vec();
    for i in [1i32, 2, 1, 1, 3] {
        bytes.extend(i.to_le_bytes());
    }
    let values = [first.to_array(), second.to_array()].concat();
    for f in [[0.0f32, 0.0, 0.0, 1.0, 1.0, 1.0].as_slice(), &values].concat() {
        bytes.extend(f.to_le_bytes());
    }
    let data = VolumeData::parse(&bytes).unwrap();
    let to_world = glam::Affine3A::from_scale(glam::Vec3::new(2.0, 1.0, 1.0));
    let grid = GridVolume::new(data, to_world, false, VolumeFilter::Nearest, Wrap::Clamp);
    Medium {
        grids: Some(Box::new(Grids {
            density: Some(Density {
                grid,
                scale,
                majorant: first.max(second).max_element() * scale,
            }),
            albedo: None,
        })),
        ..Medium::homogeneous(
            Rgb::splat(first.max(second).max_element() * scale),
            Rgb::ONE,
            Phase::Isotropic,
        )
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
    fn collisions_within_a_segment_are_unbiased_per_channel() {
        // E[weight · g(t)] = ∫₀^T Tr σt g dt, with g(t) = t, on a finite and an infinite
        // segment; and the transmittance integral against the closed form.
        let m = Medium::homogeneous(Rgb::new(0.0, 1.0, 3.0), Rgb::ONE, Phase::Isotropic);
        let mut s = Sampler::new(3, Stream::Photon, 0, 0);
        let n = 400_000;
        for t_max in [0.7f32, f32::INFINITY] {
            let mut sum = Rgb::ZERO;
            for _ in 0..n {
                let (t, w) = m
                    .sample_collision_within(t_max, s.next_1d(), s.next_1d())
                    .unwrap();
                assert!(t < t_max);
                sum += w * t;
            }
            // ∫₀^T σ t e^{−σt} dt = (1 − e^{−σT}(1 + σT)) / σ.
            let expect = |sg: f32| {
                if sg == 0.0 {
                    0.0
                } else {
                    (1.0 - libm::expf(-sg * t_max) * (1.0 + sg * t_max.min(1e30))) / sg
                }
            };
            let expect = Rgb::new(expect(0.0), expect(1.0), expect(3.0));
            let got = sum / n as f32;
            assert!(
                (got - expect).abs().max_element() < 0.01,
                "{got} vs {expect} (T = {t_max})"
            );
        }
        let got = m.integrated_transmittance(0.2, 0.9);
        let expect = |sg: f32| {
            if sg == 0.0 {
                0.7
            } else {
                (libm::expf(-sg * 0.2f32) - libm::expf(-sg * 0.9f32)) / sg
            }
        };
        assert!(
            (got - Rgb::new(expect(0.0), expect(1.0), expect(3.0)))
                .abs()
                .max_element()
                < 1e-5
        );
        assert!(m.sample_collision_within(1.0, 0.5, 0.5).is_some());
        let clear = Medium {
            sigma_t: Rgb::ZERO,
            ..m.clone()
        };
        assert!(clear.sample_collision_within(1.0, 0.5, 0.5).is_none());
    }

    #[test]
    fn free_flights_are_unbiased_per_channel() {
        // E[weight · 1(collision before t)] must equal 1 − exp(−σ t) in every channel.
        let m = Medium::homogeneous(Rgb::new(0.5, 1.0, 3.0), Rgb::ONE, Phase::Isotropic);
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

    #[test]
    fn delta_and_ratio_tracking_are_unbiased_per_channel() {
        use crate::geometry::Ray;
        // A ray along x from x = −1 to x = 1.5 crosses 1 of the first voxel and 0.5 of the
        // second: τ = 0.5 · (1 + 1.5, 2 + 0.25, 0).
        let m = two_voxels(Rgb::new(1.0, 2.0, 0.0), Rgb::new(3.0, 0.5, 0.0), 0.5);
        let ray = Ray::new(Vec3A::new(-1.0, 0.5, 0.5), Vec3A::X);
        let expect = (-Rgb::new(1.25, 1.125, 0.0)).exp();
        let mut s = Sampler::new(4, Stream::Photon, 0, 0);
        let n = 200_000;
        let (mut ratio, mut pass, mut collide) = (Rgb::ZERO, Rgb::ZERO, Rgb::ZERO);
        for _ in 0..n {
            ratio += m.transmittance_along(&ray, 2.5, &mut s);
            match m.sample_flight_along(&ray, 2.5, &mut s) {
                Flight::Collision { t, weight } => {
                    assert!(t > 1.0 && t < 2.5, "a collision outside the grid, at {t}");
                    collide += weight;
                }
                Flight::Passed { weight } => pass += weight,
            }
        }
        let n = n as f32;
        for (what, got, want) in [
            ("ratio tracking", ratio / n, expect),
            ("delta tracking's passes", pass / n, expect),
            ("delta tracking's collisions", collide / n, Rgb::ONE - expect),
        ] {
            assert!((got - want).abs().max_element() < 0.01, "{what}: {got} vs {want}");
        }
    }
}
