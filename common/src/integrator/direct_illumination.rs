//! Mitsuba's `direct` integrator: light that reaches the camera after at most one bounce,
//! estimated at the first surface by `emitter_samples` light samples and `bsdf_samples` BSDF
//! samples, combined by the power heuristic on the sample-count-weighted densities.
//!
//! Why a method of its own: scenes that ask for `direct` (Mitsuba's documentation uses it to
//! show MIS) must not be rendered with full global illumination.

use super::direct::{self as light, PreviousBounce};
use crate::bsdf::TransportMode;
use crate::color::Rgb;
use crate::geometry::{Frame, Ray};
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
        let get = |name: &str| {
            scene
                .integrator
                .params
                .iter()
                .find(|(n, _)| n == name)
                .map_or(1, |(_, v)| *v as u32)
        };
        DirectSettings {
            emitter_samples: get("emitter_samples"),
            bsdf_samples: get("bsdf_samples"),
        }
    }
}

/// Radiance arriving along the camera ray `ray`: emission seen directly, plus light reflected
/// once at the first surface. Media are not modelled, as in Mitsuba's `direct`.
pub fn radiance(scene: &Scene, settings: &DirectSettings, ray: Ray, sampler: &mut Sampler) -> Rgb {
    let Some((_, sp)) = scene.intersect(&ray) else {
        return Rgb::ZERO;
    };
    let shape = &scene.shapes[sp.shape as usize];
    let bsdf = &scene.bsdfs[shape.bsdf as usize];
    let wo = -ray.d;
    let mut l = Rgb::ZERO;
    if let Some(li) = shape.light {
        l += light::emitted(scene, li, &sp, wo, None);
    }
    let (ne, nb) = (settings.emitter_samples, settings.bsdf_samples);
    let frame = Frame::from_normal(sp.ns);
    let wi_local = frame.to_local(wo);

    // Each light sample is weighted against the BSDF samples, nb / ne times as many.
    if ne > 0 && bsdf.has_smooth() {
        let share = nb as f32 / ne as f32;
        for _ in 0..ne {
            let (u_select, u) = (sampler.next_1d(), sampler.next_2d());
            l += light::light_sample_shared(scene, bsdf, &sp, &frame, wi_local, None, u_select, u, share)
                / ne as f32;
        }
    }
    for _ in 0..nb {
        let (u1, u2) = (sampler.next_1d(), sampler.next_2d());
        let Some(bs) = bsdf.sample(wi_local, u1, u2, TransportMode::Radiance) else {
            continue;
        };
        let wi = frame.to_world(bs.wo);
        let Some((_, hit)) = scene.intersect(&Scene::spawn_ray(&sp, wi)) else {
            continue;
        };
        let Some(li) = scene.shapes[hit.shape as usize].light else {
            continue;
        };
        // The previous bounce's density, scaled so that the power heuristic compares it with
        // the light samples' in proportion to the sample counts.
        let prev = PreviousBounce {
            p: sp.p,
            pdf: if ne > 0 {
                bs.pdf * nb as f32 / ne as f32
            } else {
                f32::INFINITY
            },
            delta: bs.delta || ne == 0 || !bsdf.has_smooth(),
        };
        l += bs.weight * light::emitted(scene, li, &hit, -wi, Some(&prev)) / nb as f32;
    }
    l
}
