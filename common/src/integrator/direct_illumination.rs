//! Mitsuba's `direct` integrator: light that reaches the camera after at most one bounce,
//! estimated at the first surface by `emitter_samples` light samples and `bsdf_samples` BSDF
//! samples, combined by the power heuristic on the sample-count-weighted densities.
//!
//! Why a method of its own: scenes that ask for `direct` (Mitsuba's documentation uses it to
//! show MIS) must not be rendered with full global illumination.

use super::direct::{self as light, PreviousBounce};
use super::walk::{Hit, Walk};
use crate::bsdf::TransportMode;
use crate::color::Rgb;
use crate::geometry::Ray;
use crate::sampling::Sampler;
use crate::scene::Scene;

/// Samples per camera hit.
#[derive(Clone, Copy, Debug, serde::Serialize, serde::Deserialize, PartialEq)]
pub struct DirectSettings {
    /// Light samples per hit (Mitsuba's `emitter_samples`).
    pub emitter_samples: u32,
    /// BSDF samples per hit (Mitsuba's `bsdf_samples`).
    pub bsdf_samples: u32,
}

impl DirectSettings {
    /// The scene's `<integrator type="direct">` settings (Mitsuba's defaults otherwise: one of
    /// each).
    pub fn from_scene(scene: &Scene) -> DirectSettings {
        match scene.integrator.params {
            crate::scene::MethodParams::Direct {
                emitter_samples,
                bsdf_samples,
            } => DirectSettings {
                emitter_samples,
                bsdf_samples,
            },
            _ => DirectSettings {
                emitter_samples: 1,
                bsdf_samples: 1,
            },
        }
    }
}

/// Radiance arriving along the camera ray `ray`: emission seen directly, plus light reflected
/// once at the first surface. Media are not modelled, as in Mitsuba's `direct`.
pub fn radiance(scene: &Scene, settings: &DirectSettings, ray: Ray, sampler: &mut Sampler) -> Rgb {
    let Some((_, sp)) = scene.intersect(&ray) else {
        return scene.environment_at(ray.d).map_or(Rgb::ZERO, |(le, _)| le);
    };
    let hit = Hit::new(scene, sp, -ray.d);
    let mut l = Rgb::ZERO;
    if let Some(li) = hit.shape.light {
        l += light::emitted(scene, li, &hit.sp, hit.wo, None);
    }
    let (ne, nb) = (settings.emitter_samples, settings.bsdf_samples);

    // Each light sample is weighted against the BSDF samples, nb / ne times as many.
    if ne > 0 && hit.bsdf.has_smooth() {
        let share = nb as f32 / ne as f32;
        for _ in 0..ne {
            let (u_select, u) = (sampler.next_1d(), sampler.next_2d());
            l += light::light_sample(scene, &hit, None, (u_select, u), share, sampler) / ne as f32;
        }
    }
    for _ in 0..nb {
        let Some(bs) = Walk::sample_bsdf(&hit, sampler, TransportMode::Radiance) else {
            continue;
        };
        let wi = hit.frame.to_world(bs.wo);
        // The previous bounce's density, scaled so that the power heuristic compares it with
        // the light samples' in proportion to the sample counts.
        let prev = PreviousBounce {
            p: hit.sp.p,
            pdf: if ne > 0 {
                bs.pdf * nb as f32 / ne as f32
            } else {
                f32::INFINITY
            },
            delta: bs.delta || ne == 0 || !hit.bsdf.has_smooth(),
        };
        let emitted = match scene.intersect(&Scene::spawn_ray(&hit.sp, wi)) {
            Some((_, found)) => match scene.shapes[found.shape as usize].light {
                Some(li) => light::emitted(scene, li, &found, -wi, Some(&prev)),
                None => continue,
            },
            None => {
                let mut walk = Walk::new(Scene::spawn_ray(&hit.sp, wi), Rgb::ONE, None);
                walk.prev = Some(prev);
                walk.escaped(scene)
            }
        };
        l += bs.weight * emitted / nb as f32;
    }
    l
}
