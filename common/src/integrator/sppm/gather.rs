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
use crate::bsdf::TransportMode;
use crate::color::Rgb;
use crate::geometry::Ray;
use crate::integrator::direct;
use crate::integrator::walk::{Event, Hit, Walk};
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
pub fn camera_path(ctx: &GatherContext, ray: Ray, sampler: &mut Sampler) -> Rgb {
    let scene = ctx.scene;
    let mut l = Rgb::ZERO;
    let mut walk = Walk::new(ray, Rgb::ONE, scene.camera_medium);
    while walk.depth < ctx.max_depth {
        match walk.next_event(scene, sampler) {
            Event::Gone => {
                l += walk.escaped(scene);
                break;
            }
            // In a medium, the first collision is a gather point: direct light plus volume
            // photons.
            Event::Medium { p, medium, weight } => {
                walk.beta *= weight * scene.media[medium as usize].albedo;
                let (u_sel, u_light) = (sampler.next_1d(), sampler.next_2d());
                l += walk.beta
                    * direct::light_sample_in_medium(scene, p, walk.ray.d, medium, u_sel, u_light, 0.0);
                l += walk.beta * volume_estimate(ctx, p, walk.ray.d, medium);
                break;
            }
            Event::Surface(hit) => {
                // Emitters seen directly, through specular bounces (full weight: light sampling
                // cannot find these paths) or through glossy ones (weighted against light
                // sampling).
                l += walk.emission(scene, &hit);
                if walk.depth + 1 >= ctx.max_depth {
                    break;
                }
                let (u_sel, u_light) = (sampler.next_1d(), sampler.next_2d());
                let gather = hit.bsdf.gathers_photons();
                if gather {
                    l += walk.beta * direct::light_sample(scene, &hit, walk.medium, u_sel, u_light, 0.0);
                    l += walk.beta * photon_estimate(ctx, &hit);
                } else if hit.bsdf.has_smooth() {
                    l += walk.beta * direct::light_sample(scene, &hit, walk.medium, u_sel, u_light, 1.0);
                }
                // Continue through specular lobes, and through glossy ones where nothing was
                // gathered.
                let Some(bs) = Walk::sample_bsdf(&hit, sampler, TransportMode::Radiance) else {
                    break;
                };
                if gather && !bs.delta {
                    break;
                }
                walk.follow(&hit, &bs);
                if !walk.survives_roulette(ctx.rr_depth, sampler) {
                    break;
                }
            }
        }
    }
    l
}

/// The density estimate: Σ f · Φ · w / (normalisation · π r²), with the cone filter w.
fn photon_estimate(ctx: &GatherContext, hit: &Hit) -> Rgb {
    let (sp, wo) = (&hit.sp, hit.wo);
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
        let local = hit.frame.to_local(dir);
        if local.z.abs() < 1e-6 {
            return;
        }
        // eval includes |cos| of the photon's direction; the photon's power already does.
        let f = hit.bsdf.eval(sp.uv, hit.wo_local, local) / local.z.abs();
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
