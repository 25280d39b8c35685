//! The photon pass: photons leave the lights in proportion to their power, fly through media
//! and bounce off surfaces with Russian roulette, and are stored where a surface has a diffuse
//! part and, in media, where they collide (photon points) or along their flights (photon
//! beams).

use rayon::prelude::*;

use super::photon::Photon;
use super::photon_beams::BeamSegment;
use crate::integrator::walk::{Event, Walk};
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
    /// Flights through media.
    pub beams: Vec<BeamSegment>,
}

/// What the photon pass keeps of photons in media.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum VolumeRecord {
    /// Their collisions (photon points), from every photon.
    Points,
    /// Their flights (photon beams), from the first `n` photons of the iteration only: a beam
    /// lights many more camera rays than a point, so far fewer are needed, and each costs every
    /// ray it passes. Their power is scaled by photons / n.
    Beams(u64),
}

/// Traces photons 0..count of `iteration` into `out` (cleared first). Power is in units of
/// [`power_unit`]. The result is in photon-index order whatever the thread count.
pub fn trace_photons(
    scene: &Scene,
    seed: u64,
    iteration: u64,
    count: u64,
    max_depth: u32,
    record: VolumeRecord,
    out: &mut PhotonBuffers,
) {
    out.surface.clear();
    out.volume.clear();
    out.beams.clear();
    if scene.light_selection.is_empty() {
        return;
    }
    let chunks: Vec<PhotonBuffers> = (0..count.div_ceil(CHUNK))
        .into_par_iter()
        .map(|c| {
            let mut v = PhotonBuffers::default();
            for j in c * CHUNK..((c + 1) * CHUNK).min(count) {
                trace_one(
                    scene,
                    seed,
                    iteration,
                    j,
                    max_depth,
                    record_of(record, count, j),
                    &mut v,
                );
            }
            v
        })
        .collect();
    for c in chunks {
        out.surface.extend_from_slice(&c.surface);
        out.volume.extend_from_slice(&c.volume);
        out.beams.extend_from_slice(&c.beams);
    }
}

/// What one photon keeps in media.
#[derive(Clone, Copy, PartialEq)]
enum Keep {
    Nothing,
    Points,
    /// Beams, with their power times this scale.
    Beams(f32),
}

/// What photon `j` of `count` keeps in media.
fn record_of(record: VolumeRecord, count: u64, j: u64) -> Keep {
    match record {
        VolumeRecord::Points => Keep::Points,
        VolumeRecord::Beams(n) if j < n => Keep::Beams(count as f32 / n.min(count) as f32),
        VolumeRecord::Beams(_) => Keep::Nothing,
    }
}

/// The power that a stored photon's unit power stands for: the lights' total power, so stored
/// values are of order one (as half floats need), divided among the photons of an iteration.
pub fn power_unit(scene: &Scene, count: u64) -> f32 {
    scene.light_selection.total() / count as f32
}

fn trace_one(
    scene: &Scene,
    seed: u64,
    iteration: u64,
    index: u64,
    max_depth: u32,
    keep: Keep,
    out: &mut PhotonBuffers,
) {
    let mut s = Sampler::sobol(seed, Stream::Photon, iteration, index);
    let Some(mut walk) = Walk::from_light(scene, &mut s, scene.light_selection.total()) else {
        return;
    };
    let beams = &mut out.beams;
    while walk.depth < max_depth {
        // As on surfaces, the first flight and collision are direct light, sampled by the
        // camera.
        let event = walk.next_event_tracing(scene, &mut s, |w, stretch, _| {
            if let Keep::Beams(scale) = keep
                && w.depth > 0
            {
                beams.push(BeamSegment {
                    origin: w.ray.o,
                    direction: w.ray.d,
                    length: stretch.flight,
                    power: w.beta * scale,
                    medium: stretch.medium,
                });
            }
        });
        match event {
            Event::Gone => return,
            Event::Medium { p, medium, weight } => {
                walk.beta *= weight;
                if walk.depth > 0 && keep == Keep::Points {
                    out.volume.push(Photon::new(p, -walk.ray.d, walk.beta));
                }
                if !walk.scatter_light(scene, p, medium, &mut s) {
                    return;
                }
            }
            Event::Surface(hit) => {
                // The first hit is direct light, which the camera pass samples explicitly;
                // photons are kept only where the camera pass gathers them.
                if walk.depth > 0 && hit.bsdf.gathers_photons() {
                    out.surface.push(Photon::new(hit.sp.p, hit.wo, walk.beta));
                }
                if !walk.bounce_light(&hit, &mut s) {
                    return;
                }
            }
        }
    }
}
