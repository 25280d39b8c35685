//! A unidirectional path tracer with next-event estimation and multiple importance sampling,
//! following Mitsuba 3's `path` integrator so that both converge to the same image with
//! similar noise: same depth meaning, same Russian roulette.

use super::direct::{self, PreviousBounce};
use crate::bsdf::TransportMode;
use crate::color::Rgb;
use crate::geometry::{Frame, Ray};
use crate::sampling::Sampler;
use crate::scene::Scene;

/// Path tracer settings.
#[derive(Clone, Copy, Debug, serde::Serialize, serde::Deserialize, PartialEq)]
pub struct PathSettings {
    /// Longest path in Mitsuba's meaning: 1 renders emitters seen directly, 2 adds direct
    /// light, and so on; `None` is unlimited (Russian roulette ends paths).
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

/// Radiance arriving along `ray`.
pub fn radiance(scene: &Scene, settings: &PathSettings, mut ray: Ray, sampler: &mut Sampler) -> Rgb {
    let max_depth = settings.max_depth.unwrap_or(u32::MAX);
    let mut l = Rgb::ZERO;
    let mut beta = Rgb::ONE;
    let mut eta = 1.0f32;
    let mut prev: Option<PreviousBounce> = None;
    let mut depth = 0u32;
    // A ray that leaves the scene ends the path: there are no environment lights in our subset.
    while let Some((_, sp)) = scene.intersect(&ray) {
        let wo = -ray.d;
        let shape = &scene.shapes[sp.shape as usize];

        // Emission found by the camera ray or by BSDF sampling.
        if let Some(li) = shape.light {
            l += beta * direct::emitted(scene, li, &sp, wo, prev.as_ref());
        }
        if depth + 1 >= max_depth {
            break;
        }

        let bsdf = &scene.bsdfs[shape.bsdf as usize];
        let frame = Frame::from_normal(sp.ns);
        let wi_local = frame.to_local(wo);

        // Next-event estimation: a light sample, weighted against BSDF sampling.
        let u_light = sampler.next_1d();
        let u_light2 = sampler.next_2d();
        if bsdf.has_smooth() {
            l += beta * direct::light_sample(scene, bsdf, &sp, &frame, wi_local, u_light, u_light2, true);
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
        ray = Scene::spawn_ray(&sp, wi);
        depth += 1;

        // Russian roulette, as Mitsuba: survival by throughput, corrected for refraction.
        if depth > settings.rr_depth {
            let q = (beta.max_element() * eta * eta).min(0.95);
            if sampler.next_1d() >= q {
                break;
            }
            beta /= q;
        }
        if beta == Rgb::ZERO {
            break;
        }
    }
    l
}
