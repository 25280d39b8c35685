//! A particle tracer, Mitsuba's `ptracer`: paths leave the lights as photons do and, at every
//! vertex the camera could see through a non-delta BSDF or a medium, connect to the camera and
//! add what they carry to the pixel they land on. Where everything the camera sees is diffuse
//! this is the estimator of choice for caustics of point and spot lights (each light path lights
//! a pixel at every diffuse bounce, where SPPM blurs them by its radius); like Mitsuba's, it
//! renders nothing seen through glass or in a mirror, which a delta BSDF cannot connect to.
//!
//! Light path `index` of the `count` of pass `pass` draws its numbers from (seed, pass, count,
//! index) alone ([`Sampler::across_passes`]), so any machine renders any pass and the farm's
//! merge stays exact. Its settings are the path tracer's ([`PathSettings`]): `max_depth` counts
//! from the camera as Mitsuba's does, and light paths end by the photons' roulette (survival by
//! the bounce's albedo), so `rr_depth` is read and not used.

use glam::{Vec2, Vec3A};

use super::Share;
use super::path::PathSettings;
use super::walk::{Event, Walk};
use crate::bsdf::TransportMode;
use crate::color::Rgb;
use crate::geometry::SurfacePoint;
use crate::light::LightSample;
use crate::sampling::{Sampler, Stream};
use crate::scene::Scene;

/// Traces light path `index` of the `count` of pass `pass` and calls `splat(film position,
/// value)` for every connection to the camera. A pass of one light path per pixel, with the
/// values added into the pixels they land on, gives per pixel its mean times the pass count (see
/// [`crate::camera::Camera::connect`]); emitters seen directly are not included (the camera
/// finds those). Only the paths of `share` count: [`Share::All`], or the hybrid's caustics
/// ([`Share::LightSide`]).
pub fn trace_light_path(
    scene: &Scene,
    settings: &PathSettings,
    share: Share,
    seed: u64,
    pass: u64,
    (count, index): (u64, u64),
    splat: &mut impl FnMut(Vec2, Rgb),
) {
    let max_depth = settings.max_depth.unwrap_or(u32::MAX);
    if scene.light_selection.is_empty() || max_depth < 2 {
        return;
    }
    let mut s = Sampler::across_passes(seed, Stream::Photon, pass, count, index);
    let Some(mut walk) = Walk::from_light(scene, &mut s, 1.0) else {
        return;
    };
    // In the hybrid's light-side share, a light path counts only from a specular first bounce
    // on: the path tracer's light sampling finds the rest.
    let caustics_only = share == Share::LightSide;
    // Each vertex connects with a path one bounce longer than the light path so far.
    while walk.depth + 1 < max_depth {
        match walk.next_event(scene, &mut s) {
            Event::Gone => return,
            Event::Medium { .. } if caustics_only && walk.depth == 0 => return,
            Event::Surface(hit) if caustics_only && walk.depth == 0 => {
                if !walk.bounce_light(&hit, &mut s) || !walk.after_specular() {
                    return;
                }
            }
            Event::Medium { p, medium, weight } => {
                walk.beta *= weight;
                let med = &scene.media[medium as usize];
                let u = s.next_2d();
                if let Some((at, to_camera, value)) =
                    to_camera(scene, &SurfacePoint::in_medium(p), u, |_| Some(medium), &mut s)
                {
                    // The phase function for light travelling along the ray and leaving
                    // towards the camera, written as the camera path's (reversed) directions.
                    let phase = med.phase.eval(-to_camera, -walk.ray.d);
                    splat(at, walk.beta * med.albedo_at(p) * value * phase);
                }
                if !walk.scatter_light(scene, p, medium, &mut s) {
                    return;
                }
            }
            Event::Surface(hit) => {
                let u = s.next_2d();
                if hit.bsdf.has_smooth() {
                    let sp = &hit.sp;
                    let medium_toward = |d| hit.shape.medium_after(d, sp.ng, walk.medium);
                    if let Some((at, to_camera, value)) = to_camera(scene, sp, u, medium_toward, &mut s) {
                        // f · |cos θ| on the camera's side, in importance transport: the light
                        // arrived along `hit.wo`.
                        let wc = hit.frame.to_local(to_camera);
                        let f = hit
                            .bsdf
                            .eval_mode(&hit.at(), hit.wo_local, wc, TransportMode::Importance);
                        splat(at, walk.beta * f * value);
                    }
                }
                if !walk.bounce_light(&hit, &mut s) {
                    return;
                }
            }
        }
    }
}

/// Connects `sp` to the camera: the film position, the unit direction towards the lens, and the
/// camera's weight times the transmittance between them, through the medium `medium_toward`
/// gives for that direction.
fn to_camera(
    scene: &Scene,
    sp: &SurfacePoint,
    u_lens: Vec2,
    medium_toward: impl Fn(Vec3A) -> Option<u32>,
    sampler: &mut Sampler,
) -> Option<(Vec2, Vec3A, Rgb)> {
    let c = scene.camera.connect(sp.p, u_lens)?;
    let wi = (c.lens - sp.p).normalize();
    let lens = LightSample {
        p: c.lens,
        p_err: Vec3A::ZERO,
        n: Vec3A::ZERO,
        wi,
        radiance: Rgb::ZERO,
        pdf: 1.0,
        delta: true,
    };
    let tr = scene.transmittance(sp, &lens, medium_toward(wi), sampler);
    (tr != Rgb::ZERO).then(|| (c.film, wi, tr * c.weight))
}
