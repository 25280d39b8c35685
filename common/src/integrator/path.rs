//! A unidirectional volumetric path tracer with next-event estimation and multiple importance
//! sampling, following Mitsuba 3's `path` and `volpath` integrators so that both converge to the
//! same image with similar noise: same depth meaning, same Russian roulette, free flights in
//! homogeneous media, medium boundaries crossed without a bounce. One departure: in media,
//! point and spot lights are sampled equiangularly along the ray rather than at the sampled
//! collision (Mitsuba's volpath), which bounds the noise of a light inside fog.

use super::Share;
use super::direct;
use super::walk::{Event, Walk};
use crate::bsdf::TransportMode;
use crate::color::Rgb;
use crate::geometry::Ray;
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

/// Radiance arriving along `ray` (unit direction), which starts in the camera's medium, by the
/// paths of `share` ([`Share::All`] or [`Share::CameraSide`]).
pub fn radiance(
    scene: &Scene,
    settings: &PathSettings,
    share: Share,
    ray: Ray,
    sampler: &mut Sampler,
) -> Rgb {
    let max_depth = settings.max_depth.unwrap_or(u32::MAX);
    let mut l = Rgb::ZERO;
    let mut walk = Walk::new(ray, Rgb::ONE, scene.camera_medium);
    // Whether emission found after a specular bounce is the particle tracer's: in its share,
    // once the first bounce (at x1) was not specular.
    let mut leave_caustics = false;
    loop {
        // Point-like lights are sampled along each stretch of medium (from one collision drawn
        // equiangularly about the light), not at the flight's collision, whose distance does not
        // follow their 1/d²: for a light inside fog that had infinite variance.
        let event = walk.next_event_tracing(scene, sampler, |w, stretch, sampler| {
            if w.depth + 1 < max_depth {
                l += w.beta
                    * direct::point_lights_along(scene, &w.ray, stretch.medium, stretch.surface, sampler);
            }
        });
        let finds_light = !(leave_caustics && walk.after_specular());
        if finds_light {
            l += walk.take_crossed();
        }
        match event {
            // A path that leaves the scene finds the environment, if there is one, and ends.
            Event::Gone => {
                if finds_light {
                    l += walk.escaped(scene);
                }
                break;
            }
            // Scattering in a medium: light sampling, then the phase function.
            Event::Medium { p, medium, weight } => {
                walk.beta *= weight * scene.media[medium as usize].albedo_at(p);
                leave_caustics |= walk.depth == 0 && share == Share::CameraSide;
                if walk.depth + 1 >= max_depth {
                    break;
                }
                let (u_sel, u_light) = (sampler.next_1d(), sampler.next_2d());
                if let Some((li, pmf)) = scene.pick_light(u_sel)
                    && scene.lights[li as usize].point_position().is_none()
                {
                    let ls = scene.sample_picked_light(li, pmf, p, u_light);
                    l += walk.beta * direct::light_in_medium(scene, p, walk.ray.d, medium, ls, 1.0, sampler);
                }
                walk.scatter_in_medium(scene, p, medium, sampler);
            }
            Event::Surface(hit) => {
                // Emission found by the camera ray or by BSDF sampling.
                if finds_light {
                    l += walk.emission(scene, &hit);
                }
                if walk.depth + 1 >= max_depth {
                    break;
                }
                // Next-event estimation: a light sample, weighted against BSDF sampling.
                let (u_sel, u_light) = (sampler.next_1d(), sampler.next_2d());
                if hit.bsdf.has_smooth() {
                    l += walk.beta
                        * direct::light_sample(scene, &hit, walk.medium, (u_sel, u_light), 1.0, sampler);
                }
                let Some(bs) = Walk::sample_bsdf(&hit, sampler, TransportMode::Radiance) else {
                    break;
                };
                leave_caustics |= walk.depth == 0 && share == Share::CameraSide && !bs.delta;
                walk.follow(&hit, &bs);
            }
        }
        if !walk.survives_roulette(settings.rr_depth, sampler) {
            break;
        }
    }
    l
}
