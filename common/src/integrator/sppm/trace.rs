//! The photon pass: photons leave the lights in proportion to their power, bounce through the
//! scene with Russian roulette, and are stored where a surface has a non-specular part.

use rayon::prelude::*;

use super::photon::Photon;
use crate::bsdf::TransportMode;
use crate::geometry::{Frame, Ray, offset_ray_origin};
use crate::sampling::{Sampler, Stream};
use crate::scene::Scene;

/// Photons traced per parallel task: large enough to amortise scheduling, small enough to
/// balance two to dozens of threads.
const CHUNK: u64 = 4096;

/// Traces photons 0..count of `iteration` into `out` (cleared first). Power is in units of
/// [`power_unit`]. The result is in photon-index order whatever the thread count.
pub fn trace_photons(
    scene: &Scene,
    seed: u64,
    iteration: u64,
    count: u64,
    max_depth: u32,
    out: &mut Vec<Photon>,
) {
    out.clear();
    if scene.light_selection.is_empty() {
        return;
    }
    let chunks: Vec<Vec<Photon>> = (0..count.div_ceil(CHUNK))
        .into_par_iter()
        .map(|c| {
            let mut v = Vec::new();
            for j in c * CHUNK..((c + 1) * CHUNK).min(count) {
                trace_one(scene, seed, iteration, j, max_depth, &mut v);
            }
            v
        })
        .collect();
    for c in chunks {
        out.extend_from_slice(&c);
    }
}

/// The power that a stored photon's unit power stands for: the lights' total power, so stored
/// values are of order one (as half floats need), divided among the photons of an iteration.
pub fn power_unit(scene: &Scene, count: u64) -> f32 {
    scene.light_selection.total() / count as f32
}

fn trace_one(scene: &Scene, seed: u64, iteration: u64, index: u64, max_depth: u32, out: &mut Vec<Photon>) {
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
    for depth in 0..max_depth {
        let Some((_, sp)) = scene.intersect(&ray) else {
            return;
        };
        let shape = &scene.shapes[sp.shape as usize];
        let bsdf = &scene.bsdfs[shape.bsdf as usize];
        let wi = -ray.d;
        // The first hit is direct light, which the camera pass samples explicitly; photons are
        // kept only where the camera pass gathers them.
        if depth > 0 && bsdf.gathers_photons() {
            out.push(Photon::new(sp.p, wi, beta));
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
        ray = Scene::spawn_ray(&sp, frame.to_world(bs.wo));
    }
}
