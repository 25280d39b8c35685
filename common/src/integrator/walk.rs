//! One bounce of a light path, written once for the transport loops: the path tracer, SPPM's
//! camera pass and photon pass, and the particle tracer (whose light paths start and bounce as
//! photons do).
//!
//! A [`Walk`] is a path between bounces. [`Walk::next_event`] finds where it interacts next (a
//! collision in a medium, a surface that scatters, or nothing), crossing medium boundaries on the
//! way; [`Walk::sample_bsdf`], [`Walk::follow`] and [`Walk::scatter_in_medium`] move it on. What
//! differs between the loops stays in them, where it reads as the algorithm: which transport
//! mode the BSDF is sampled in, what a collision's weight includes, where light is sampled or
//! photons are gathered or stored, and which Russian roulette decides survival.

use glam::Vec3A;

use super::direct::PreviousBounce;
use crate::bsdf::{Bsdf, BsdfSample, SurfaceAt, TransportMode};
use crate::color::Rgb;
use crate::geometry::{Frame, Ray, SurfacePoint, offset_ray_origin};
use crate::medium::Flight;
use crate::sampling::Sampler;
use crate::scene::{Scene, ShapeInfo};

/// A path between bounces.
pub struct Walk {
    /// The ray to follow next.
    pub ray: Ray,
    /// Throughput (camera paths) or power (photons).
    pub beta: Rgb,
    /// Product of the relative indices of refraction crossed (Mitsuba's roulette uses it).
    pub eta: f32,
    /// The medium the ray travels in.
    pub medium: Option<u32>,
    /// Bounces so far (surface and medium scattering; boundary crossings do not count).
    pub depth: u32,
    /// The last bounce, for weighting emission found by it against light sampling.
    pub prev: Option<PreviousBounce>,
    /// Medium boundaries crossed (bounded by [`Scene::cross_boundary`]).
    crossings: u32,
    /// Light emitted by null surfaces crossed since it was last taken ([`Walk::take_crossed`]),
    /// times the throughput there, weighted as [`Walk::emission`] weights it. Mitsuba counts an
    /// emitter's light wherever a ray meets it, also where its material lets the ray through.
    crossed: Rgb,
}

/// Where a walk interacts next.
pub enum Event<'s> {
    /// It collided in medium `medium` at `p`. `weight` is the free flight's (transmittance over
    /// its density); the caller applies it, with the medium's albedo where it models
    /// scattering as a weight.
    Medium {
        /// Where.
        p: Vec3A,
        /// Which medium.
        medium: u32,
        /// The free flight's weight, not yet in `beta`.
        weight: Rgb,
    },
    /// It reached a surface that scatters.
    Surface(Hit<'s>),
    /// It left the scene, or crossed too many boundaries.
    Gone,
}

/// A surface a walk reached, with what every loop needs of it.
pub struct Hit<'s> {
    /// The point.
    pub sp: SurfacePoint,
    /// Its shape.
    pub shape: &'s ShapeInfo,
    /// Its material.
    pub bsdf: &'s Bsdf,
    /// The shading frame.
    pub frame: Frame,
    /// The direction back along the arriving ray (world).
    pub wo: Vec3A,
    /// The same, in the shading frame.
    pub wo_local: Vec3A,
}

impl<'s> Hit<'s> {
    /// The surface at `sp`, seen from direction `wo`.
    #[inline]
    pub fn new(scene: &'s Scene, sp: SurfacePoint, wo: Vec3A) -> Hit<'s> {
        let shape = &scene.shapes[sp.shape as usize];
        let bsdf = &scene.bsdfs[shape.bsdf as usize];
        // Isotropic materials do not depend on the tangents' orientation: the cheaper basis.
        let frame = if bsdf.needs_tangent_frame() {
            Frame::from_normal_and_tangent(sp.ns, sp.dpdu)
        } else {
            Frame::from_normal(sp.ns)
        };
        let wo_local = frame.to_local(wo);
        Hit {
            sp,
            shape,
            bsdf,
            frame,
            wo,
            wo_local,
        }
    }

    /// Where its material is evaluated (made on demand: kept in the hit, it would double the
    /// size of every [`Event`]).
    #[inline]
    pub fn at(&self) -> SurfaceAt {
        SurfaceAt {
            uv: self.sp.uv,
            attr: self.sp.attr,
            frame: self.frame,
            dpdu: self.sp.dpdu,
            dpdv: self.sp.dpdv,
            ng: self.sp.ng,
        }
    }
}

/// A stretch of medium along the walk's ray, from the ray's origin: where the free flight ended
/// (a collision, or the surface) and where the surface is (infinite if there is none).
#[derive(Clone, Copy, Debug)]
pub struct Stretch {
    /// Which medium.
    pub medium: u32,
    /// Distance to the flight's end.
    pub flight: f32,
    /// Distance to the surface.
    pub surface: f32,
}

impl Walk {
    /// A walk starting along `ray` in `medium`, carrying `beta`.
    pub fn new(ray: Ray, beta: Rgb, medium: Option<u32>) -> Walk {
        Walk {
            ray,
            beta,
            eta: 1.0,
            medium,
            depth: 0,
            prev: None,
            crossings: 0,
            crossed: Rgb::ZERO,
        }
    }

    /// Follows the ray to its next interaction: a free flight through the current medium (two
    /// random numbers), then the surface, crossing null surfaces (medium boundaries) without a
    /// bounce. A flight that passes through its medium has its weight applied here.
    pub fn next_event<'s>(&mut self, scene: &'s Scene, sampler: &mut Sampler) -> Event<'s> {
        self.next_event_tracing(scene, sampler, |_, _, _| {})
    }

    /// [`Walk::next_event`], calling `stretch(walk, stretch, sampler)` for every stretch of medium
    /// the flight covers, with the throughput at the stretch's start: the segments photon beams
    /// are made of (origin to the collision or the surface), and the segments along which the
    /// path tracer samples point lights (origin to the surface, wherever the flight ends).
    pub fn next_event_tracing<'s>(
        &mut self,
        scene: &'s Scene,
        sampler: &mut Sampler,
        mut stretch: impl FnMut(&Walk, Stretch, &mut Sampler),
    ) -> Event<'s> {
        self.advance(scene, |walk, m, t_surface| {
            let med = &scene.media[m as usize];
            let flight = med.sample_flight_along(&walk.ray, t_surface, sampler);
            let end = match flight {
                Flight::Collision { t, .. } => t,
                Flight::Passed { .. } => t_surface,
            };
            let s = Stretch {
                medium: m,
                flight: end,
                surface: t_surface,
            };
            stretch(walk, s, sampler);
            match flight {
                Flight::Collision { t, weight } => Some(Event::Medium {
                    p: walk.ray.at(t),
                    medium: m,
                    weight,
                }),
                Flight::Passed { weight } => {
                    walk.beta *= weight;
                    None
                }
            }
        })
    }

    /// Follows the ray to the next surface that scatters without sampling collisions in media:
    /// `segment(walk, medium, t)` is called for every stretch of medium the ray crosses, from
    /// the ray's origin to `t` (a surface, or infinity), and returns the throughput's factor
    /// over the stretch (its transmittance, or an unbiased estimate of it); zero ends the walk.
    /// For estimators that integrate along the ray (the beam radiance estimate) instead of at
    /// one sampled point; never returns [`Event::Medium`].
    pub fn next_surface<'s>(
        &mut self,
        scene: &'s Scene,
        mut segment: impl FnMut(&Walk, u32, f32) -> Rgb,
    ) -> Event<'s> {
        self.advance(scene, |walk, m, t_surface| {
            walk.beta *= segment(walk, m, t_surface);
            (walk.beta == Rgb::ZERO).then_some(Event::Gone)
        })
    }

    /// The walk to the next surface, crossing null surfaces; `in_medium(walk, medium, t)` decides
    /// what happens on each stretch of medium up to `t` (an event ends the walk there).
    fn advance<'s>(
        &mut self,
        scene: &'s Scene,
        mut in_medium: impl FnMut(&mut Walk, u32, f32) -> Option<Event<'s>>,
    ) -> Event<'s> {
        loop {
            let hit = scene.intersect(&self.ray);
            if let Some(m) = self.medium {
                let t_surface = hit.as_ref().map_or(f32::INFINITY, |(h, _)| h.t);
                if let Some(event) = in_medium(self, m, t_surface) {
                    return event;
                }
            }
            let Some((_, sp)) = hit else {
                return Event::Gone;
            };
            let shape = &scene.shapes[sp.shape as usize];
            let bsdf = &scene.bsdfs[shape.bsdf as usize];
            if bsdf.is_null() {
                if let Some(li) = shape.light {
                    self.crossed +=
                        self.beta * super::direct::emitted(scene, li, &sp, -self.ray.d, self.prev.as_ref());
                }
                self.beta *= bsdf.null_transmission(sp.tex());
                match scene.cross_boundary(&sp, self.ray.d, self.medium, &mut self.crossings) {
                    Some((next, entered)) => (self.ray, self.medium) = (next, entered),
                    None => return Event::Gone,
                }
                continue;
            }
            return Event::Surface(Hit::new(scene, sp, -self.ray.d));
        }
    }

    /// What `hit` emits back along the walk, times the throughput, weighted against the light
    /// sampling of the previous bounce (in full for camera rays and after specular bounces).
    pub fn emission(&self, scene: &Scene, hit: &Hit) -> Rgb {
        match hit.shape.light {
            Some(li) => self.beta * super::direct::emitted(scene, li, &hit.sp, hit.wo, self.prev.as_ref()),
            None => Rgb::ZERO,
        }
    }

    /// The light of emitting null surfaces the walk crossed on its way to its last event, as
    /// [`Walk::emission`] gives a surface's (light paths leave it).
    pub fn take_crossed(&mut self) -> Rgb {
        std::mem::take(&mut self.crossed)
    }

    /// Whether the last bounce sampled a delta lobe.
    pub fn after_specular(&self) -> bool {
        self.prev.as_ref().is_some_and(|p| p.delta)
    }

    /// What a walk that left the scene finds there (an environment light), times the
    /// throughput, weighted against light sampling as [`Walk::emission`] is.
    pub fn escaped(&self, scene: &Scene) -> Rgb {
        let Some((le, light_pdf)) = scene.environment_at(self.ray.d) else {
            return Rgb::ZERO;
        };
        let w = match &self.prev {
            Some(p) if !p.delta => super::mis_weight(p.pdf, light_pdf),
            _ => 1.0,
        };
        self.beta * le * w
    }

    /// Samples the BSDF at `hit` for the next direction (three random numbers).
    pub fn sample_bsdf(hit: &Hit, sampler: &mut Sampler, mode: TransportMode) -> Option<BsdfSample> {
        let u1 = sampler.next_1d();
        let u2 = sampler.next_2d();
        hit.bsdf.sample(&hit.at(), hit.wo_local, u1, u2, mode)
    }

    /// Bounces off `hit` along the sampled direction: the throughput takes the sample's
    /// weight, the path enters the medium on that side, and the bounce counts.
    pub fn follow(&mut self, hit: &Hit, bs: &BsdfSample) {
        let d = hit.frame.to_world(bs.wo);
        self.beta *= bs.weight;
        self.eta *= bs.eta;
        self.prev = Some(PreviousBounce {
            p: hit.sp.p,
            pdf: bs.pdf,
            delta: bs.delta,
        });
        self.medium = hit.shape.medium_after(d, hit.sp.ng, self.medium);
        self.ray = Scene::spawn_ray(&hit.sp, d);
        self.depth += 1;
    }

    /// Scatters at `p` in medium `m` by sampling its phase function (two random numbers); the
    /// phase function's weight is one.
    pub fn scatter_in_medium(&mut self, scene: &Scene, p: Vec3A, m: u32, sampler: &mut Sampler) {
        let (d, pdf) = scene.media[m as usize]
            .phase
            .sample(self.ray.d, sampler.next_2d());
        self.prev = Some(PreviousBounce { p, pdf, delta: false });
        self.ray = Ray::new(p, d);
        self.depth += 1;
    }

    /// Mitsuba's Russian roulette for camera paths: past `rr_depth` bounces a path survives
    /// with probability max(throughput) · η² (at most 0.95) and carries 1/q more. False when the
    /// path ends, or when nothing more could reach the camera along it.
    pub fn survives_roulette(&mut self, rr_depth: u32, sampler: &mut Sampler) -> bool {
        if self.depth > rr_depth {
            let q = (self.beta.max_element() * self.eta * self.eta).min(0.95);
            if sampler.next_1d() >= q {
                return false;
            }
            self.beta /= q;
        }
        self.beta != Rgb::ZERO
    }

    /// A light path leaving a light picked by power (five random numbers: the direction, the
    /// light, the position), carrying its power over the pick's probability, in units of
    /// `unit` (SPPM's total power, so stored photons are of order one; 1 for absolute power).
    pub fn from_light(scene: &Scene, sampler: &mut Sampler, unit: f32) -> Option<Walk> {
        // The direction first: a Sobol point's first two numbers are its best-stratified pair,
        // and the photons of one point or spot light differ in nothing else (docs/sampling.md).
        let u_dir = sampler.next_2d();
        let (light, pmf, _) = scene.light_selection.sample(sampler.next_1d());
        let u_pos = sampler.next_2d();
        let e = scene.lights[light].sample_emission(scene.bvh.primitives(), u_pos, u_dir)?;
        let origin = if e.n == Vec3A::ZERO {
            e.origin
        } else {
            offset_ray_origin(e.origin, e.origin_err, e.n, e.dir)
        };
        let beta = e.power / (pmf * unit);
        Some(Walk::new(Ray::new(origin, e.dir), beta, scene.light_media[light]))
    }

    /// Bounces a light path (a photon) off `hit`: a BSDF sample in importance transport, then
    /// the photons' roulette on its weight. False when the path ends.
    pub fn bounce_light(&mut self, hit: &Hit, sampler: &mut Sampler) -> bool {
        let Some(mut bs) = Walk::sample_bsdf(hit, sampler, TransportMode::Importance) else {
            return false;
        };
        let Some(weight) = photon_roulette(bs.weight, sampler) else {
            return false;
        };
        bs.weight = weight;
        self.follow(hit, &bs);
        true
    }

    /// Scatters a light path in medium `m` at `p`: the photons' roulette on the medium's
    /// albedo, then the phase function. False when the path ends.
    pub fn scatter_light(&mut self, scene: &Scene, p: Vec3A, m: u32, sampler: &mut Sampler) -> bool {
        let Some(weight) = photon_roulette(scene.media[m as usize].albedo_at(p), sampler) else {
            return false;
        };
        self.beta *= weight;
        self.scatter_in_medium(scene, p, m, sampler);
        true
    }
}

/// Photons' Russian roulette at a scattering event of weight `weight` (a BSDF sample's, or a
/// medium's albedo): survive with probability max(weight), so that surviving photons keep their
/// power; returns the weight to apply, or None when the photon ends.
pub fn photon_roulette(weight: Rgb, sampler: &mut Sampler) -> Option<Rgb> {
    let q = weight.max_element().min(1.0);
    (sampler.next_1d() < q).then(|| weight / q)
}
