//! The photon pass: photons leave the lights in proportion to their power, fly through media
//! and bounce off surfaces with Russian roulette, and are stored where a surface has a diffuse
//! part and where they collide in a medium.

use rayon::prelude::*;

use super::photon::Photon;
use crate::bsdf::TransportMode;
use crate::geometry::{Frame, Ray, offset_ray_origin};
use crate::medium::Flight;
use crate::sampling::{Sampler, Stream};
use crate::scene::Scene;

/// Photons traced per parallel task: large enough to amortise scheduling, small enough to
/// balance two to dozens of threads.
const CHUNK: u64 = 4096;

/// The photons of one iteration.
#[derive(Debug, Default)]
pub struct PhotonBuffers {
    /// Photons on surfaces.
    pub surface: Vec<Photon>,
    /// Photons at collisions in media.
    pub volume: Vec<Photon>,
}

/// Traces photons 0..count of `iteration` into `out` (cleared first). Power is in units of
/// [`power_unit`]. The result is in photon-index order whatever the thread count.
pub fn trace_photons(
    scene: &Scene,
    seed: u64,
    iteration: u64,
    count: u64,
    max_depth: u32,
    out: &mut PhotonBuffers,
) {
    out.surface.clear();
    out.volume.clear();
    if scene.light_selection.is_empty() {
        return;
    }
    let chunks: Vec<PhotonBuffers> = (0..count.div_ceil(CHUNK))
        .into_par_iter()
        .map(|c| {
            let mut v = PhotonBuffers::default();
            for j in c * CHUNK..((c + 1) * CHUNK).min(count) {
                trace_one(scene, seed, iteration, j, max_depth, &mut v);
            }
            v
        })
        .collect();
    for c in chunks {
        out.surface.extend_from_slice(&c.surface);
        out.volume.extend_from_slice(&c.volume);
    }
}

/// The power that a stored photon's unit power stands for: the lights' total power, so stored
/// values are of order one (as half floats need), divided among the photons of an iteration.
pub fn power_unit(scene: &Scene, count: u64) -> f32 {
    scene.light_selection.total() / count as f32
}

fn trace_one(scene: &Scene, seed: u64, iteration: u64, index: u64, max_depth: u32, out: &mut PhotonBuffers) {
    let mut s = Sampler::new(seed, Stream::Photon, iteration, index);
    let (light, pmf, _) = scene.light_selection.sample(s.next_1d());
    let u_pos = s.next_2d();
    let u_dir = s.next_2d();
    let Some(e) = scene.lights[light].sample_emission(scene.bvh.primitives(), u_pos, u_dir) else {
        return;
    };
    // In units of the total power: beta = power / (pmf · total).
    let mut beta = e.power / (pmf * scene.light_selection.total());
    let origin = if e.n == glam::Vec3A::ZERO {
        e.origin
    } else {
        offset_ray_origin(e.origin, e.origin_err, e.n, e.dir)
    };
    let mut ray = Ray::new(origin, e.dir);
    let mut medium = scene.light_media[light];
    let mut depth = 0u32;
    let mut crossings = 0u32;
    while depth < max_depth {
        let hit = scene.intersect(&ray);
        let t_surface = hit.as_ref().map_or(f32::INFINITY, |(h, _)| h.t);
        if let Some(m) = medium {
            let med = &scene.media[m as usize];
            match med.sample_flight(t_surface, s.next_1d(), s.next_1d()) {
                Flight::Collision { t, weight } => {
                    beta *= weight;
                    let p = ray.at(t);
                    // As on surfaces, the first collision is direct light, sampled by the camera.
                    if depth > 0 {
                        out.volume.push(Photon::new(p, -ray.d, beta));
                    }
                    // Scatter with probability of the albedo; survivors keep their power.
                    let q = med.albedo.max_element().min(1.0);
                    if s.next_1d() >= q {
                        return;
                    }
                    beta *= med.albedo / q;
                    let (d, _) = med.phase.sample(ray.d, s.next_2d());
                    ray = Ray::new(p, d);
                    depth += 1;
                    continue;
                }
                Flight::Passed { weight } => beta *= weight,
            }
        }
        let Some((_, sp)) = hit else {
            return;
        };
        let shape = &scene.shapes[sp.shape as usize];
        let bsdf = &scene.bsdfs[shape.bsdf as usize];
        if bsdf.is_null() {
            let Some((next, entered)) = scene.cross_boundary(&sp, ray.d, medium, &mut crossings) else {
                return;
            };
            (ray, medium) = (next, entered);
            continue;
        }
        let wi = -ray.d;
        // The first hit is direct light, which the camera pass samples explicitly; photons are
        // kept only where the camera pass gathers them.
        if depth > 0 && bsdf.gathers_photons() {
            out.surface.push(Photon::new(sp.p, wi, beta));
        }
        let frame = Frame::from_normal(sp.ns);
        let u1 = s.next_1d();
        let u2 = s.next_2d();
        let Some(bs) = bsdf.sample(frame.to_local(wi), u1, u2, TransportMode::Importance) else {
            return;
        };
        // Russian roulette by the bounce's albedo: surviving photons keep their power.
        let q = bs.weight.max_element().min(1.0);
        if s.next_1d() >= q {
            return;
        }
        beta *= bs.weight / q;
        let d = frame.to_world(bs.wo);
        medium = shape.medium_after(d, sp.ng, medium);
        ray = Scene::spawn_ray(&sp, d);
        depth += 1;
    }
}
