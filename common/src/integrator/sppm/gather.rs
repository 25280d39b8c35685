//! The camera pass: one jittered path per pixel through specular and glossy bounces to the first
//! surface with a diffuse part, where direct light is sampled and the photons within the
//! iteration's radius estimate the rest.
//!
//! Specular bounces are followed as photons are. Glossy-only surfaces (rough metals) are
//! followed by BSDF sampling, with light sampling and multiple importance sampling as in the
//! path tracer, because a density estimate through a sharp lobe is speckled.

use std::f32::consts::PI;

use glam::Vec3A;

use super::photon_map::PhotonMap;
use crate::bsdf::{Bsdf, TransportMode};
use crate::color::Rgb;
use crate::geometry::{Frame, Ray, SurfacePoint};
use crate::integrator::direct::{self, PreviousBounce};
use crate::integrator::russian_roulette;
use crate::medium::Flight;
use crate::sampling::Sampler;
use crate::scene::Scene;

/// What the camera pass needs of the iteration.
pub struct GatherContext<'a> {
    /// The scene.
    pub scene: &'a Scene,
    /// This iteration's surface photons.
    pub map: &'a PhotonMap,
    /// This iteration's surface radius.
    pub radius: f32,
    /// This iteration's volume photons.
    pub volume_map: &'a PhotonMap,
    /// This iteration's volume radius.
    pub volume_radius: f32,
    /// Power of a stored photon's unit power.
    pub power_unit: f32,
    /// The cone filter's k (≥ 1): weights fall from 1 at the centre to 1 − 1/k at the radius.
    pub k: f32,
    /// Longest camera path.
    pub max_depth: u32,
    /// Depth from which Russian roulette applies.
    pub rr_depth: u32,
}

/// Radiance along the camera ray of one pixel sample.
pub fn camera_path(ctx: &GatherContext, mut ray: Ray, sampler: &mut Sampler) -> Rgb {
    let scene = ctx.scene;
    let mut l = Rgb::ZERO;
    let mut beta = Rgb::ONE;
    let mut eta = 1.0f32;
    let mut prev: Option<PreviousBounce> = None;
    let mut medium = scene.camera_medium;
    let mut depth = 0;
    let mut crossings = 0;
    while depth < ctx.max_depth {
        let hit = scene.intersect(&ray);
        let t_surface = hit.as_ref().map_or(f32::INFINITY, |(h, _)| h.t);
        // In a medium, the first collision is a gather point: direct light plus volume photons.
        if let Some(m) = medium {
            let med = &scene.media[m as usize];
            match med.sample_flight(t_surface, sampler.next_1d(), sampler.next_1d()) {
                Flight::Collision { t, weight } => {
                    beta *= weight * med.albedo;
                    let p = ray.at(t);
                    let (u_sel, u_light) = (sampler.next_1d(), sampler.next_2d());
                    l += beta * direct::light_sample_in_medium(scene, p, ray.d, m, u_sel, u_light, false);
                    l += beta * volume_estimate(ctx, p, ray.d, m);
                    break;
                }
                Flight::Passed { weight } => beta *= weight,
            }
        }
        let Some((_, sp)) = hit else {
            break;
        };
        let wo = -ray.d;
        let shape = &scene.shapes[sp.shape as usize];
        let bsdf = &scene.bsdfs[shape.bsdf as usize];
        if bsdf.is_null() {
            let Some((next, entered)) = scene.cross_boundary(&sp, ray.d, medium, &mut crossings) else {
                break;
            };
            (ray, medium) = (next, entered);
            continue;
        }
        // Emitters seen directly, through specular bounces (full weight: light sampling cannot
        // find these paths) or through glossy ones (weighted against light sampling).
        if let Some(li) = shape.light {
            l += beta * direct::emitted(scene, li, &sp, wo, prev.as_ref());
        }
        if depth + 1 >= ctx.max_depth {
            break;
        }
        let frame = Frame::from_normal(sp.ns);
        let wi_local = frame.to_local(wo);
        let u_light = sampler.next_1d();
        let u_light2 = sampler.next_2d();
        let gather = bsdf.gathers_photons();
        if gather {
            l += beta
                * direct::light_sample(
                    scene, bsdf, &sp, &frame, wi_local, medium, u_light, u_light2, false,
                );
            l += beta * photon_estimate(ctx, bsdf, &sp, &frame, wo, wi_local);
        } else if bsdf.has_smooth() {
            l += beta
                * direct::light_sample(
                    scene, bsdf, &sp, &frame, wi_local, medium, u_light, u_light2, true,
                );
        }
        // Continue through specular lobes, and through glossy ones where nothing was gathered.
        let u1 = sampler.next_1d();
        let u2 = sampler.next_2d();
        let Some(bs) = bsdf.sample(wi_local, u1, u2, TransportMode::Radiance) else {
            break;
        };
        if gather && !bs.delta {
            break;
        }
        beta *= bs.weight;
        eta *= bs.eta;
        prev = Some(PreviousBounce {
            p: sp.p,
            pdf: bs.pdf,
            delta: bs.delta,
        });
        let d = frame.to_world(bs.wo);
        medium = shape.medium_after(d, sp.ng, medium);
        ray = Scene::spawn_ray(&sp, d);
        depth += 1;
        if !russian_roulette(&mut beta, eta, depth, ctx.rr_depth, sampler) {
            break;
        }
    }
    l
}

/// The density estimate: Σ f · Φ · w / (normalisation · π r²), with the cone filter w.
fn photon_estimate(
    ctx: &GatherContext,
    bsdf: &Bsdf,
    sp: &SurfacePoint,
    frame: &Frame,
    wo: Vec3A,
    wi_local: Vec3A,
) -> Rgb {
    let inv_kr = 1.0 / (ctx.k * ctx.radius);
    let side = wo.dot(sp.ng);
    let mut sum = Rgb::ZERO;
    ctx.map.for_each_near(sp.p, |ph, d2| {
        let dir = ph.direction();
        // A photon that arrived on the other side of the surface (through a thin wall) is not
        // light this side receives.
        if dir.dot(sp.ng) * side <= 0.0 {
            return;
        }
        let local = frame.to_local(dir);
        if local.z.abs() < 1e-6 {
            return;
        }
        // eval includes |cos| of the photon's direction; the photon's power already does.
        let f = bsdf.eval(wi_local, local) / local.z.abs();
        sum += f * ph.power() * (1.0 - d2.sqrt() * inv_kr);
    });
    let norm = 1.0 - 2.0 / (3.0 * ctx.k);
    sum * (ctx.power_unit / (norm * PI * ctx.radius * ctx.radius))
}

/// In-scattered radiance at `p` in medium `m`, for a path that travelled along `d`, from the
/// volume photons within the volume radius: Σ phase · Φ / (σt · (4/3)π r³). Photons are stored
/// at collisions, whose density is σt times the fluence, hence the division by σt.
fn volume_estimate(ctx: &GatherContext, p: Vec3A, d: Vec3A, m: u32) -> Rgb {
    let med = &ctx.scene.media[m as usize];
    let mut sum = Rgb::ZERO;
    ctx.volume_map.for_each_near(p, |ph, _| {
        sum += ph.power() * med.phase.eval(d, ph.direction());
    });
    if sum == Rgb::ZERO {
        return sum;
    }
    let r = ctx.volume_radius;
    let volume = 4.0 / 3.0 * PI * r * r * r;
    let inv_sigma = Rgb::select(med.sigma_t.cmpgt(Rgb::ZERO), Rgb::ONE / med.sigma_t, Rgb::ZERO);
    sum * inv_sigma * (ctx.power_unit / volume)
}
