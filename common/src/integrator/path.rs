//! A unidirectional volumetric path tracer with next-event estimation and multiple importance
//! sampling, following Mitsuba 3's `path` and `volpath` integrators so that both converge to the
//! same image with similar noise: same depth meaning, same Russian roulette, free flights in
//! homogeneous media, medium boundaries crossed without a bounce.

use super::direct::{self, PreviousBounce};
use super::russian_roulette;
use crate::bsdf::TransportMode;
use crate::color::Rgb;
use crate::geometry::{Frame, Ray};
use crate::medium::Flight;
use crate::sampling::Sampler;
use crate::scene::Scene;

/// Path tracer settings.
#[derive(Clone, Copy, Debug, serde::Serialize, serde::Deserialize, PartialEq)]
pub struct PathSettings {
    /// Longest path in Mitsuba's meaning: 1 renders emitters seen directly, 2 adds direct
    /// light, and so on; `None` is unlimited (Russian roulette ends paths). Scattering in a
    /// medium counts as a bounce.
    pub max_depth: Option<u32>,
    /// Path depth from which Russian roulette applies.
    pub rr_depth: u32,
}

impl PathSettings {
    /// The scene's `<integrator>` settings.
    pub fn from_scene(scene: &Scene) -> PathSettings {
        PathSettings {
            max_depth: u32::try_from(scene.integrator.max_depth).ok(),
            rr_depth: scene.integrator.rr_depth,
        }
    }
}

/// Radiance arriving along `ray` (unit direction), which starts in the camera's medium.
pub fn radiance(scene: &Scene, settings: &PathSettings, mut ray: Ray, sampler: &mut Sampler) -> Rgb {
    let max_depth = settings.max_depth.unwrap_or(u32::MAX);
    let mut l = Rgb::ZERO;
    let mut beta = Rgb::ONE;
    let mut eta = 1.0f32;
    let mut prev: Option<PreviousBounce> = None;
    let mut depth = 0u32;
    let mut medium = scene.camera_medium;
    // Medium boundaries do not count as bounces; this bounds a path through many of them.
    let mut crossings = 0u32;
    loop {
        let hit = scene.intersect(&ray);
        let t_surface = hit.as_ref().map_or(f32::INFINITY, |(h, _)| h.t);

        // A free flight through the medium: scatter in it, or reach the surface.
        if let Some(m) = medium {
            let med = &scene.media[m as usize];
            match med.sample_flight(t_surface, sampler.next_1d(), sampler.next_1d()) {
                Flight::Collision { t, weight } => {
                    beta *= weight * med.albedo;
                    if depth + 1 >= max_depth {
                        break;
                    }
                    let p = ray.at(t);
                    let (u_sel, u_light) = (sampler.next_1d(), sampler.next_2d());
                    l += beta * direct::light_sample_in_medium(scene, p, ray.d, m, u_sel, u_light, true);
                    let (d, pdf) = med.phase.sample(ray.d, sampler.next_2d());
                    prev = Some(PreviousBounce { p, pdf, delta: false });
                    ray = Ray::new(p, d);
                    depth += 1;
                    if !russian_roulette(&mut beta, eta, depth, settings.rr_depth, sampler) {
                        break;
                    }
                    continue;
                }
                Flight::Passed { weight } => beta *= weight,
            }
        }

        // A ray that leaves the scene ends the path: there are no environment lights.
        let Some((_, sp)) = hit else {
            break;
        };
        let shape = &scene.shapes[sp.shape as usize];
        let bsdf = &scene.bsdfs[shape.bsdf as usize];
        if bsdf.is_null() {
            let Some((next, entered)) = scene.cross_boundary(&sp, ray.d, medium, &mut crossings) else {
                break;
            };
            (ray, medium) = (next, entered);
            continue;
        }
        let wo = -ray.d;

        // Emission found by the camera ray or by BSDF sampling.
        if let Some(li) = shape.light {
            l += beta * direct::emitted(scene, li, &sp, wo, prev.as_ref());
        }
        if depth + 1 >= max_depth {
            break;
        }
        let frame = Frame::from_normal(sp.ns);
        let wi_local = frame.to_local(wo);

        // Next-event estimation: a light sample, weighted against BSDF sampling.
        let u_light = sampler.next_1d();
        let u_light2 = sampler.next_2d();
        if bsdf.has_smooth() {
            l += beta
                * direct::light_sample(
                    scene, bsdf, &sp, &frame, wi_local, medium, u_light, u_light2, true,
                );
        }

        // BSDF sampling for the next bounce.
        let u1 = sampler.next_1d();
        let u2 = sampler.next_2d();
        let Some(bs) = bsdf.sample(wi_local, u1, u2, TransportMode::Radiance) else {
            break;
        };
        let wi = frame.to_world(bs.wo);
        beta *= bs.weight;
        eta *= bs.eta;
        prev = Some(PreviousBounce {
            p: sp.p,
            pdf: bs.pdf,
            delta: bs.delta,
        });
        medium = shape.medium_after(wi, sp.ng, medium);
        ray = Scene::spawn_ray(&sp, wi);
        depth += 1;
        if !russian_roulette(&mut beta, eta, depth, settings.rr_depth, sampler) {
            break;
        }
    }
    l
}
