//! The unit of work: render passes [a, b) of an image and return their exact sum.
//!
//! A pass is one sample per pixel. Its random numbers come from (seed, pass, pixel) alone, so
//! the sum of a pass range is the same whichever thread, machine or batch renders it.

use std::ops::Range;
use std::sync::atomic::{AtomicBool, Ordering};

use rayon::prelude::*;

use glam::{Vec2, Vec3A};

use crate::color::Rgb;
use crate::engine::Backend;
use crate::engine::lanes::LANES;
use crate::engine::path::LaneScene;
use crate::features::{self, Features};
use crate::film::{FilmSum, add_fixed, to_fixed};
use crate::geometry::Ray;
use crate::integrator::direct_illumination::{self, DirectSettings};
use crate::integrator::path::{self, PathSettings};
use crate::integrator::sppm::{
    self, BeamMap, GatherContext, PhotonBeamMap, PhotonBuffers, PhotonMap, SppmSettings, VolumeEstimate,
    VolumeMap,
};
use crate::integrator::{Share, ptracer};
use crate::job::Integrator;
use crate::parity::OddSums;
use crate::sampling::{Sampler, Stream};
use crate::scene::Scene;

mod splat;

/// The rendering method and its parameters.
#[derive(Clone, Copy, Debug, serde::Serialize, serde::Deserialize, PartialEq)]
pub enum Method {
    /// Path tracing: a pass is one path per pixel.
    Path(PathSettings),
    /// Mitsuba's `direct` integrator: a pass is one camera ray per pixel, shaded at its first
    /// surface only.
    Direct(DirectSettings),
    /// Progressive photon mapping: a pass is one iteration (a photon pass and one camera path
    /// per pixel).
    Sppm(SppmSettings),
    /// Mitsuba's particle tracer: a pass is one light path per pixel, connected to the camera
    /// at every bounce, and one camera ray per pixel for emitters seen directly.
    Ptracer(PathSettings),
    /// Hybrid path and particle tracing ([`crate::integrator::Share`]): a pass is one camera
    /// path per pixel for all light but caustics, and one light path per pixel for caustics.
    Hybrid(PathSettings),
}

impl Method {
    /// Which method this is.
    pub fn integrator(&self) -> Integrator {
        match self {
            Method::Path(_) => Integrator::Path,
            Method::Direct(_) => Integrator::Direct,
            Method::Sppm(_) => Integrator::Sppm,
            Method::Ptracer(_) => Integrator::Ptracer,
            Method::Hybrid(_) => Integrator::Hybrid,
        }
    }

    /// The method's name, as `--integrator` and the job API spell it.
    pub fn name(&self) -> &'static str {
        self.integrator().name()
    }
}

/// How to render.
#[derive(Clone, Copy, Debug, serde::Serialize, serde::Deserialize, PartialEq)]
pub struct RenderSettings {
    /// Seed of every random stream.
    pub seed: u64,
    /// The method.
    pub method: Method,
}

/// Renders a scene's passes with one method: the one entry point of `coordinator render`, the
/// worker, `converge`, the benches and the tests.
///
/// It owns what passes reuse, made once per render or per worker batch rather than per pass:
/// the lane engine's scene (a table of every triangle) and SPPM's photon buffers and maps.
/// Passes run in the current rayon pool.
pub struct Renderer<'s> {
    scene: &'s Scene,
    settings: RenderSettings,
    /// The lane engine's backend and scene, where the engine models the scene for the method
    /// (so far the path tracer on Lambertian triangles lit by area lights:
    /// `engine::path`).
    lanes: Option<(Backend, LaneScene)>,
    sppm: SppmBuffers,
    /// An odd pass's own sum, for [`Batch::odd`].
    part: FilmSum,
    /// Whether passes also sum the denoiser's features ([`Renderer::with_features`]).
    features: bool,
}

/// Passes rendered by [`Renderer::render`].
#[derive(Debug)]
pub struct Batch {
    /// Their sum; `sum.passes` says how many were rendered before a stop.
    pub sum: FilmSum,
    /// Their odd passes' sums on the sampled pixels, for the farm's noise estimate
    /// ([`crate::parity`]).
    pub odd: OddSums,
    /// Their features, if the renderer sums them ([`Renderer::with_features`]).
    pub features: Option<Features>,
}

/// What SPPM's iterations reuse: memory depends on the photon count, not on the iterations.
#[derive(Default)]
struct SppmBuffers {
    photons: PhotonBuffers,
    map: PhotonMap,
    point_map: PhotonMap,
    beam_map: BeamMap,
    flights: PhotonBeamMap,
}

impl<'s> Renderer<'s> {
    /// A renderer on the process's backend ([`Backend::current`], `PHOTONFARM_SIMD`).
    pub fn new(scene: &'s Scene, settings: &RenderSettings) -> Renderer<'s> {
        Renderer::on(scene, settings, Some(Backend::current()))
    }

    /// A renderer whose path tracer runs in the lane engine on `lanes` where the engine models
    /// the scene, with the same bytes on every backend; everything else runs on the scalar
    /// integrators, and so does everything with `None` (the benches' and tests' reference).
    pub fn on(scene: &'s Scene, settings: &RenderSettings, lanes: Option<Backend>) -> Renderer<'s> {
        let lanes = match (&settings.method, lanes) {
            // The lane engine's scene is made only when the lanes are asked for.
            (Method::Path(p), Some(b)) => LaneScene::new(scene, p).ok().map(|ds| (b, ds)),
            _ => None,
        };
        Renderer {
            scene,
            settings: *settings,
            lanes,
            sppm: SppmBuffers::default(),
            part: FilmSum::new(scene.width(), scene.height()),
            features: false,
        }
    }

    /// The same renderer, whose batches also sum the denoiser's features, pass by pass
    /// ([`crate::features`]): a render pays for them only when it asks.
    pub fn with_features(mut self) -> Renderer<'s> {
        self.features = true;
        self
    }

    /// Whether its path tracer runs on the lane engine (the engine models the scene).
    pub fn on_lanes(&self) -> bool {
        self.lanes.is_some()
    }

    /// The sum of passes `passes`.
    pub fn passes(&mut self, passes: Range<u64>) -> FilmSum {
        self.run(passes, None, &AtomicBool::new(false), None, None)
    }

    /// Renders passes `passes`, in order, until `stop` is set (checked before each pass). For
    /// SPPM, `radii` holds the (surface, volume) radii of each pass (the coordinator's
    /// schedule), or `None` to take them from the settings; the other methods ignore it.
    ///
    /// Panics if `radii` does not hold one pair per pass: callers check what they were sent.
    pub fn render(&mut self, passes: Range<u64>, radii: Option<&[[f32; 2]]>, stop: &AtomicBool) -> Batch {
        let (w, h) = (self.scene.width(), self.scene.height());
        let mut odd = OddSums::empty(w, h);
        let mut features = self.features.then(|| Features::new(w, h));
        let sum = self.run(passes, radii, stop, Some(&mut odd), features.as_mut());
        Batch { sum, odd, features }
    }

    fn run(
        &mut self,
        passes: Range<u64>,
        radii: Option<&[[f32; 2]]>,
        stop: &AtomicBool,
        mut odd: Option<&mut OddSums>,
        mut features: Option<&mut Features>,
    ) -> FilmSum {
        let schedule;
        let radii = match (&self.settings.method, radii) {
            (_, Some(r)) => {
                assert_eq!(
                    r.len() as u64,
                    passes.end - passes.start,
                    "one radius pair per pass"
                );
                r
            }
            (Method::Sppm(s), None) => {
                schedule = s.radii(passes.clone());
                &schedule[..]
            }
            _ => &[][..],
        };
        let mut film = FilmSum::new(self.scene.width(), self.scene.height());
        for (k, pass) in passes.enumerate() {
            if stop.load(Ordering::Relaxed) {
                break;
            }
            let radii = radii.get(k).copied().unwrap_or([0.0; 2]);
            if let Some(f) = features.as_deref_mut() {
                add_feature_pass(self.scene, self.settings.seed, pass, f);
            }
            match odd.as_deref_mut() {
                Some(odd) if pass % 2 == 1 => {
                    let mut part = std::mem::replace(&mut self.part, FilmSum::new(0, 0));
                    part.clear();
                    self.add_pass(pass, radii, &mut part);
                    odd.add(&OddSums::of(&part));
                    film.add(&part).expect("one scene, one size");
                    self.part = part;
                }
                _ => self.add_pass(pass, radii, &mut film),
            }
        }
        film
    }

    /// Adds pass `pass` to `film`; `radii` are SPPM's (surface, volume) radii.
    fn add_pass(&mut self, pass: u64, radii: [f32; 2], film: &mut FilmSum) {
        let (scene, seed) = (self.scene, self.settings.seed);
        match &self.settings.method {
            Method::Path(p) => match &self.lanes {
                None => add_pixel_samples(scene, film, seed, pass, |ray, sampler| {
                    path::radiance(scene, p, Share::All, ray, sampler)
                }),
                Some((backend, ds)) => {
                    crate::engine::path::render_pass(scene, ds, seed, pass, *backend, film)
                }
            },
            Method::Direct(d) => add_pixel_samples(scene, film, seed, pass, |ray, sampler| {
                direct_illumination::radiance(scene, d, ray, sampler)
            }),
            Method::Sppm(s) => sppm_iteration(scene, seed, s, pass, radii, &mut self.sppm, film),
            Method::Ptracer(p) => light_path_pass(scene, p, Share::All, seed, pass, film),
            Method::Hybrid(p) => light_path_pass(scene, p, Share::LightSide, seed, pass, film),
        }
    }
}

/// Adds SPPM iteration `iteration` with (surface, volume) radii `radii` to `film`.
fn sppm_iteration(
    scene: &Scene,
    seed: u64,
    settings: &SppmSettings,
    iteration: u64,
    [radius, volume_radius]: [f32; 2],
    buffers: &mut SppmBuffers,
    film: &mut FilmSum,
) {
    let max_depth = settings.max_depth.unwrap_or(u32::MAX);
    let b = buffers;
    sppm::trace_photons(
        scene,
        seed,
        iteration,
        settings.photons,
        max_depth,
        settings.volume_record(),
        &mut b.photons,
    );
    b.map.build(&b.photons.surface, radius);
    let volume_map = match settings.volume_estimate {
        VolumeEstimate::Beam => {
            b.beam_map.build(&b.photons.volume, volume_radius);
            VolumeMap::Beam(&b.beam_map)
        }
        VolumeEstimate::Point => {
            b.point_map.build(&b.photons.volume, volume_radius);
            VolumeMap::Point(&b.point_map)
        }
        VolumeEstimate::PhotonBeams => {
            let beam_bounds = scene
                .bounds()
                .grow(scene.camera.to_world.transform_point3a(Vec3A::ZERO));
            b.flights.build(&b.photons.beams, volume_radius, &beam_bounds);
            VolumeMap::PhotonBeams(&b.flights)
        }
    };
    let ctx = GatherContext {
        scene,
        map: &b.map,
        radius,
        volume_map,
        volume_radius,
        power_unit: sppm::power_unit(scene, settings.photons),
        k: settings.k,
        max_depth,
        rr_depth: settings.rr_depth,
    };
    add_pixel_samples(scene, film, seed, iteration, |ray, sampler| {
        sppm::camera_path(&ctx, ray, sampler)
    });
}

/// Adds one camera sample per pixel of pass `pass` to the film, in parallel; counts one pass.
/// `radiance` follows the camera ray with the pixel's sampler, which has drawn the film and lens
/// positions; with a box filter the sample counts for its pixel alone, otherwise it is splatted.
fn add_pixel_samples(
    scene: &Scene,
    film: &mut FilmSum,
    seed: u64,
    pass: u64,
    radiance: impl Fn(Ray, &mut Sampler) -> Rgb + Sync,
) {
    add_samples(scene, film, |x, y| {
        let (ray, u_pixel, mut sampler) = camera_sample(scene, seed, pass, x, y);
        (radiance(ray, &mut sampler), u_pixel)
    });
}

/// Adds one sample per pixel, `sample(x, y)` giving its value and its offset within the pixel,
/// through the scene's filter; counts one pass.
fn add_samples(scene: &Scene, film: &mut FilmSum, sample: impl Fn(u32, u32) -> (Rgb, Vec2) + Sync) {
    add_sample_sets(scene, film, 1, |_| &sample);
}

/// Adds `count` samples per pixel as one pass, `set(j)` giving the j-th sample of every pixel:
/// each through the filter at its own film position, so the pass's mean is theirs.
fn add_sample_sets<S: Fn(u32, u32) -> (Rgb, Vec2) + Sync>(
    scene: &Scene,
    film: &mut FilmSum,
    count: u32,
    set: impl Fn(u32) -> S,
) {
    // A box film divides by passes: each of the pass's samples weighs 1/count (exact for a
    // power of two). A filtered film divides by the filter weights it sums.
    let weight = if scene.filter.is_box() {
        1.0 / count as f32
    } else {
        1.0
    };
    for j in 0..count {
        let sample = set(j);
        add_rows(scene, film, |y| {
            (0..scene.width())
                .map(|x| {
                    let (v, u) = sample(x, y);
                    (v * weight, u)
                })
                .collect()
        });
    }
    film.passes += 1;
}

/// Adds one sample per pixel through the scene's filter, computed in parallel by rows: `row(y)`
/// gives row y's values, each with its offset within its pixel (the lane engine traces a row's
/// paths together). The caller counts the pass.
pub(crate) fn add_rows(scene: &Scene, film: &mut FilmSum, row: impl Fn(u32) -> Vec<(Rgb, Vec2)> + Sync) {
    if scene.filter.is_box() {
        add_box_rows(scene, film, row);
    } else {
        splat::add_filtered_rows(scene, film, row);
    }
}

/// Adds pass `pass`'s features: one walk per pixel from the pass's camera sample, then the
/// albedo and the normal through the filter at the sample's film position, as the image's;
/// then the dense emission's own rays.
fn add_feature_pass(scene: &Scene, seed: u64, pass: u64, out: &mut Features) {
    let w = scene.width();
    let pixels = w as usize * scene.height() as usize;
    let samples: Vec<(features::Sample, Vec2)> = (0..pixels)
        .into_par_iter()
        .map(|i| {
            let (x, y) = ((i % w as usize) as u32, (i / w as usize) as u32);
            let (ray, u_pixel, mut sampler) = camera_sample(scene, seed, pass, x, y);
            (features::sample(scene, ray, &mut sampler), u_pixel)
        })
        .collect();
    let at = |x: u32, y: u32| &samples[y as usize * w as usize + x as usize];
    add_samples(scene, &mut out.albedo, |x, y| (at(x, y).0.albedo, at(x, y).1));
    add_samples(scene, &mut out.normal, |x, y| (at(x, y).0.normal, at(x, y).1));
    add_samples(scene, &mut out.emitted, |x, y| (at(x, y).0.emitted, at(x, y).1));
    if !scene.has_visible_lights() {
        // Nothing to find: exact zeros, without the rays.
        add_samples(scene, &mut out.emitted_dense, |x, y| (Rgb::ZERO, at(x, y).1));
        return;
    }
    let k = features::DENSE_SAMPLES;
    add_sample_sets(scene, &mut out.emitted_dense, k, |j| {
        let index = |pixel: u64| (pixel, pass * k as u64 + j as u64);
        let rows: Vec<Vec<(Rgb, Vec2)>> = (0..scene.height())
            .into_par_iter()
            .map(|y| {
                Backend::current().run(DenseRow {
                    scene,
                    seed,
                    y,
                    index,
                })
            })
            .collect();
        move |x: u32, y: u32| rows[y as usize][x as usize]
    });
}

/// One film row of dense emission rays, eight pixels to a packet, compiled for the process's
/// backend (the packet traversal's lanes are its instruction set's; the bytes are the same on
/// every one). `index(pixel)` is the pixel's sequence and the sample's index in it.
struct DenseRow<'a, I> {
    scene: &'a Scene,
    seed: u64,
    y: u32,
    index: I,
}

impl<I: Fn(u64) -> (u64, u64)> pulp::WithSimd for DenseRow<'_, I> {
    type Output = Vec<(Rgb, Vec2)>;

    #[inline(always)]
    fn with_simd<S: pulp::Simd>(self, _: S) -> Vec<(Rgb, Vec2)> {
        let (scene, y) = (self.scene, self.y);
        let w = scene.width();
        let mut row = Vec::with_capacity(w as usize);
        let (mut rays, mut samplers, mut at) = (
            Vec::with_capacity(LANES),
            Vec::with_capacity(LANES),
            Vec::with_capacity(LANES),
        );
        for x0 in (0..w).step_by(LANES) {
            rays.clear();
            samplers.clear();
            at.clear();
            for x in x0..(x0 + LANES as u32).min(w) {
                // One sequence per pixel across all passes (not split by parity: no noise
                // estimate reads it), so an outline's coverage converges as a net of k points a
                // pass would.
                let (key, index) = (self.index)(y as u64 * w as u64 + x as u64);
                let mut sampler = Sampler::sobol(self.seed, Stream::Emission, key, index);
                let u_pixel = sampler.next_2d();
                rays.push(scene.camera.generate_ray(x, y, u_pixel, sampler.next_2d()));
                samplers.push(sampler);
                at.push(u_pixel);
            }
            let le = features::direct_emission8(scene, &rays, &mut samplers);
            row.extend(le.into_iter().zip(at.iter().copied()));
        }
        row
    }
}

/// The camera ray of pixel (x, y) in pass `pass`, its offset within the pixel, and the sampler
/// that goes on along it.
pub(crate) fn camera_sample(scene: &Scene, seed: u64, pass: u64, x: u32, y: u32) -> (Ray, Vec2, Sampler) {
    let pixel = y as u64 * scene.width() as u64 + x as u64;
    // Even and odd passes are two independent sequences (of `pass / 2`), so the noise
    // estimate's halves stay independent (`parity.rs`).
    let mut sampler = Sampler::sobol(seed, Stream::Camera, 2 * pixel + pass % 2, pass / 2);
    let u_pixel = sampler.next_2d();
    let ray = scene.camera.generate_ray(x, y, u_pixel, sampler.next_2d());
    (ray, u_pixel, sampler)
}

/// Light paths (and camera paths) per parallel task of a particle tracer's or hybrid's pass.
const LIGHT_PATH_CHUNK: u64 = 1024;

/// Adds pass `pass` of the particle tracer or the hybrid method, the two whose light paths land
/// anywhere on the film: every contribution is splatted on its own ([`splat::Splats`]), so the
/// sums do not depend on the threads.
///
/// For the particle tracer, pixel i's camera ray finds emitters seen directly (the path tracer
/// stopped at depth 1) and light path i the rest. Scenes whose lights cannot be seen (points,
/// spots, beams, the sun) trace no camera rays: those would add exact zeros. For the hybrid
/// (light paths in [`Share::LightSide`]), pixel i's camera path is the path tracer's, in
/// [`Share::CameraSide`], and scenes without a specular surface trace no light paths.
fn light_path_pass(
    scene: &Scene,
    settings: &PathSettings,
    light_share: Share,
    seed: u64,
    pass: u64,
    film: &mut FilmSum,
) {
    let (camera, camera_share) = match light_share {
        Share::LightSide => (*settings, Share::CameraSide),
        _ => (
            PathSettings {
                max_depth: Some(1),
                rr_depth: settings.rr_depth,
            },
            Share::All,
        ),
    };
    let (w, pixels) = (scene.width() as u64, scene.width() as u64 * scene.height() as u64);
    let visible = light_share == Share::LightSide || scene.has_visible_lights();
    // The hybrid's light paths count only from a specular bounce: none without such a surface.
    let light_paths = light_share != Share::LightSide || scene.has_specular_surfaces();
    let chunks: Vec<splat::Splats> = (0..pixels.div_ceil(LIGHT_PATH_CHUNK))
        .into_par_iter()
        .map(|c| {
            let mut out = splat::Splats::new();
            for i in c * LIGHT_PATH_CHUNK..((c + 1) * LIGHT_PATH_CHUNK).min(pixels) {
                if visible {
                    let (x, y) = ((i % w) as u32, (i / w) as u32);
                    let (ray, u_pixel, mut sampler) = camera_sample(scene, seed, pass, x, y);
                    let at = Vec2::new(x as f32, y as f32) + u_pixel;
                    out.add(
                        scene,
                        at,
                        path::radiance(scene, &camera, camera_share, ray, &mut sampler),
                    );
                }
                if light_paths {
                    ptracer::trace_light_path(
                        scene,
                        settings,
                        light_share,
                        seed,
                        pass,
                        (pixels, i),
                        &mut |at, l| out.add(scene, at, l),
                    );
                }
            }
            out
        })
        .collect();
    for c in chunks {
        film.nonfinite += c.nonfinite;
        for (p, v) in &c.values {
            add_fixed(&mut film.sums[*p as usize], v);
        }
    }
    film.passes += 1;
}

/// Box filter: [`add_rows`]'s samples count for their pixels alone.
fn add_box_rows(scene: &Scene, film: &mut FilmSum, row: impl Fn(u32) -> Vec<(Rgb, Vec2)> + Sync) {
    let w = scene.width();
    let rows: Vec<(Vec<[i64; 3]>, u64)> = (0..scene.height())
        .into_par_iter()
        .map(|y| {
            let mut nonfinite = 0;
            let row = row(y)
                .into_iter()
                .map(|(v, _)| {
                    to_fixed(v).unwrap_or_else(|| {
                        nonfinite += 1;
                        [0; 3]
                    })
                })
                .collect();
            (row, nonfinite)
        })
        .collect();
    for (y, (row, nonfinite)) in rows.into_iter().enumerate() {
        for (acc, v) in film.sums[y * w as usize..].iter_mut().zip(&row) {
            add_fixed(acc, v);
        }
        film.nonfinite += nonfinite;
    }
    // Keeps a weighted sum weighted: each pixel received weight one.
    if !film.weights.is_empty() {
        let one = crate::film::FIXED_SCALE as i64;
        film.weights.iter_mut().for_each(|wt| *wt += one);
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use std::path::Path;

    const SCENE: &str = r#"<scene version="3.0.0">
        <sensor type="perspective"><float name="fov" value="60"/>
            <transform name="to_world"><lookat origin="0,0,3" target="0,0,0" up="0,1,0"/></transform>
            <film type="hdrfilm"><integer name="width" value="12"/><integer name="height" value="8"/>
                <rfilter type="box"/></film></sensor>
        <shape type="sphere"><float name="radius" value="0.8"/><bsdf type="diffuse"/></shape>
        <shape type="rectangle"><transform name="to_world"><translate z="-2"/><scale value="3"/></transform>
            <emitter type="area"><rgb name="radiance" value="1, 2, 3"/></emitter></shape>
        <emitter type="point"><point name="position" x="0" y="2" z="2"/><rgb name="intensity" value="5"/></emitter>
    </scene>"#;

    #[test]
    fn split_passes_sum_to_the_same_bytes() {
        let scene = Scene::from_str(SCENE, Path::new("inline.xml"), &[]).unwrap();
        let settings = RenderSettings {
            seed: 9,
            method: Method::Path(PathSettings::from_scene(&scene)),
        };
        let whole = Renderer::new(&scene, &settings).passes(0..6);
        let mut parts = Renderer::new(&scene, &settings).passes(4..6);
        parts.add(&Renderer::new(&scene, &settings).passes(0..1)).unwrap();
        parts.add(&Renderer::new(&scene, &settings).passes(1..4)).unwrap();
        assert_eq!(whole, parts);
        assert!(whole.sums.iter().any(|s| s[2] > 0));
    }

    /// A batch's odd sums are those of its odd passes rendered alone, as the worker sent them
    /// before the renderer made them; a set stop flag renders nothing; a renderer reused over
    /// ranges gives what fresh ones give.
    #[test]
    fn a_batch_carries_its_odd_passes_and_stops_on_the_flag() {
        let scene = Scene::from_str(SCENE, Path::new("inline.xml"), &[]).unwrap();
        let path = PathSettings::from_scene(&scene);
        for method in [Method::Path(path), Method::Ptracer(path)] {
            let settings = RenderSettings { seed: 4, method };
            let mut renderer = Renderer::new(&scene, &settings);
            let never = AtomicBool::new(false);
            let batch = renderer.render(2..7, None, &never);
            let mut odd = OddSums::empty(scene.width(), scene.height());
            for pass in [3, 5] {
                odd.add(&OddSums::of(
                    &Renderer::new(&scene, &settings).passes(pass..pass + 1),
                ));
            }
            assert_eq!(batch.odd, odd);
            assert_eq!(batch.odd.passes, 2);
            assert!(batch.odd.sums.iter().any(|s| *s != [0; 3]));
            assert_eq!(batch.sum, Renderer::new(&scene, &settings).passes(2..7));
            // Reused after a batch: the same bytes as a fresh renderer's.
            assert_eq!(
                renderer.passes(0..3),
                Renderer::new(&scene, &settings).passes(0..3)
            );
            let stopped = renderer.render(0..4, None, &AtomicBool::new(true));
            assert_eq!((stopped.sum.passes, stopped.odd.passes), (0, 0));
            assert!(stopped.sum.sums.iter().all(|s| *s == [0; 3]));
        }
    }

    /// Features are exact sums like the image: any split of the passes gives the same bytes,
    /// they change nothing in the image, and on a Lambertian surface seen head-on the albedo is
    /// its reflectance exactly and the normal faces the camera.
    #[test]
    fn features_sum_exactly_and_read_the_first_surface() {
        let scene = Scene::from_str(SCENE, Path::new("inline.xml"), &[]).unwrap();
        let path = PathSettings::from_scene(&scene);
        let never = AtomicBool::new(false);
        for method in [Method::Path(path), Method::Ptracer(path)] {
            let settings = RenderSettings { seed: 5, method };
            let whole = Renderer::new(&scene, &settings)
                .with_features()
                .render(0..6, None, &never);
            let mut parts = Renderer::new(&scene, &settings)
                .with_features()
                .render(2..6, None, &never);
            let first = Renderer::new(&scene, &settings)
                .with_features()
                .render(0..2, None, &never);
            parts
                .features
                .as_mut()
                .unwrap()
                .add(first.features.as_ref().unwrap())
                .unwrap();
            assert_eq!(whole.features, parts.features);
            assert_eq!(whole.sum, Renderer::new(&scene, &settings).passes(0..6));
            assert!(
                Renderer::new(&scene, &settings)
                    .render(0..1, None, &never)
                    .features
                    .is_none()
            );
            let f = whole.features.unwrap();
            let centre = 4 * 12 + 6;
            assert_eq!(f.albedo_image().unwrap()[centre], Rgb::splat(0.5));
            let n = f.normal_image().unwrap()[centre];
            // Pixel (6, 4) lies right of and below the centre: the sphere's normal there
            // leans right (+x) and down (-y), by about 8°.
            assert!(n.z > 0.97 && n.x > 0.1 && n.y < -0.08, "{n}");
            // A mean of unit normals over the pixel: a little shorter than one.
            assert!((0.98..=1.0).contains(&n.length()), "{n}");
            // The emitter behind the sphere is seen directly only past its outline (the
            // sphere covers columns 3 to 8): there the emission seen directly is the image,
            // and the path tracer's image holds it everywhere.
            let (emitted, image) = (f.emitted.image().unwrap(), whole.sum.image().unwrap());
            let beside = 4 * 12 + 9;
            assert!(emitted[beside].x > 0.5 && emitted[centre] == Rgb::ZERO);
            if let Method::Path(_) = method {
                assert_eq!(emitted[beside], image[beside]);
                assert!(emitted.iter().zip(&image).all(|(e, i)| e.cmple(*i + 1e-6).all()));
            }
            // The dense estimate of the same emission, from rays of its own: nothing where the
            // sphere covers the pixel, and the same light where the own rays see it, to the
            // noise of the outline.
            let dense = f.emitted_dense.image().unwrap();
            assert_eq!(f.emitted_dense.passes, 6);
            assert_eq!(dense[centre], Rgb::ZERO);
            let mean = |v: &[Rgb]| v.iter().map(|c| c.x as f64).sum::<f64>() / v.len() as f64;
            let (m_own, m_dense) = (mean(&emitted), mean(&dense));
            assert!((m_dense / m_own - 1.0).abs() < 0.05, "{m_dense} against {m_own}");
        }
    }

    /// Splatted samples (Gaussian, tent), a camera's and a particle tracer's, keep the farm's
    /// contract: any split of the passes, in any order, on any number of threads, sums to the
    /// same bytes.
    #[test]
    fn splatted_passes_sum_to_the_same_bytes_with_any_split_and_threads() {
        for filter in [
            "<rfilter type=\"gaussian\"/>",
            "<rfilter type=\"tent\"><float name=\"radius\" value=\"1.5\"/></rfilter>",
        ] {
            let text = SCENE.replace("<rfilter type=\"box\"/>", filter);
            let scene = Scene::from_str(&text, Path::new("inline.xml"), &[]).unwrap();
            assert!(!scene.filter.is_box());
            let path = PathSettings::from_scene(&scene);
            // The particle tracer's contributions land anywhere on the film.
            for method in [Method::Path(path), Method::Ptracer(path), Method::Hybrid(path)] {
                let settings = RenderSettings { seed: 3, method };
                let pool = |n| rayon::ThreadPoolBuilder::new().num_threads(n).build().unwrap();
                let whole = pool(1).install(|| Renderer::new(&scene, &settings).passes(0..5));
                let mut parts = pool(2).install(|| Renderer::new(&scene, &settings).passes(2..5));
                parts.add(&Renderer::new(&scene, &settings).passes(0..2)).unwrap();
                assert_eq!(whole, parts);
                if let Method::Path(_) = method {
                    // Every pixel received weight; a box-filtered sum added to it stays
                    // consistent.
                    assert_eq!(whole.weights.len(), 12 * 8);
                    assert!(whole.weights.iter().all(|&w| w > 0));
                } else {
                    // Each splat keeps its own total: the film divides by the pass count.
                    assert!(whole.weights.is_empty());
                }
                let img = whole.image().unwrap();
                assert!(img.iter().all(|p| p.is_finite()) && img.iter().any(|p| p.z > 0.0));
            }
        }
    }

    /// A particle tracer's contribution lands whole, whatever the filter and wherever it
    /// lands (the corner included, where most of a wide filter's pixels are off the image).
    #[test]
    fn splats_keep_each_contribution_whole() {
        for filter in [
            "<rfilter type=\"box\"/>",
            "<rfilter type=\"gaussian\"/>",
            "<rfilter type=\"tent\"><float name=\"radius\" value=\"1.5\"/></rfilter>",
        ] {
            let text = SCENE.replace("<rfilter type=\"box\"/>", filter);
            let scene = Scene::from_str(&text, Path::new("inline.xml"), &[]).unwrap();
            let l = Rgb::new(0.25, 1.0, 3.0);
            for at in [Vec2::new(0.1, 0.2), Vec2::new(6.5, 4.0), Vec2::new(11.9, 7.99)] {
                let mut splats = splat::Splats::new();
                splats.add(&scene, at, l);
                let mut total = [0i64; 3];
                for (p, v) in &splats.values {
                    assert!((*p as usize) < 12 * 8);
                    add_fixed(&mut total, v);
                }
                let whole = to_fixed(l).unwrap();
                for c in 0..3 {
                    assert!(
                        (total[c] - whole[c]).abs() <= splats.values.len() as i64,
                        "{filter} at {at}: {total:?} vs {whole:?}"
                    );
                }
            }
        }
    }
}
