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
use crate::sampling::Sampler;
use crate::scene::Scene;

/// What the camera pass needs of the iteration.
pub struct GatherContext<'a> {
    /// The scene.
    pub scene: &'a Scene,
    /// This iteration's photons.
    pub map: &'a PhotonMap,
    /// This iteration's radius.
    pub radius: f32,
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
    for depth in 0..ctx.max_depth {
        let Some((_, sp)) = scene.intersect(&ray) else {
            break;
        };
        let wo = -ray.d;
        let shape = &scene.shapes[sp.shape as usize];
        // Emitters seen directly, through specular bounces (full weight: light sampling cannot
        // find these paths) or through glossy ones (weighted against light sampling).
        if let Some(li) = shape.light {
            l += beta * direct::emitted(scene, li, &sp, wo, prev.as_ref());
        }
        if depth + 1 >= ctx.max_depth {
            break;
        }
        let bsdf = &scene.bsdfs[shape.bsdf as usize];
        let frame = Frame::from_normal(sp.ns);
        let wi_local = frame.to_local(wo);
        let u_light = sampler.next_1d();
        let u_light2 = sampler.next_2d();
        let gather = bsdf.gathers_photons();
        if gather {
            l += beta * direct::light_sample(scene, bsdf, &sp, &frame, wi_local, u_light, u_light2, false);
            l += beta * photon_estimate(ctx, bsdf, &sp, &frame, wo, wi_local);
        } else if bsdf.has_smooth() {
            l += beta * direct::light_sample(scene, bsdf, &sp, &frame, wi_local, u_light, u_light2, true);
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
        ray = Scene::spawn_ray(&sp, frame.to_world(bs.wo));
        if depth + 1 > ctx.rr_depth {
            let q = (beta.max_element() * eta * eta).min(0.95);
            if sampler.next_1d() >= q {
                break;
            }
            beta /= q;
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
