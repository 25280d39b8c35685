//! The unit of work: render passes [a, b) of an image and return their exact sum.
//!
//! A pass is one sample per pixel. Its random numbers come from (seed, pass, pixel) alone, so
//! the sum of a pass range is the same whichever thread, machine or batch renders it.

use std::ops::Range;

use rayon::prelude::*;

use crate::color::Rgb;
use crate::film::{FilmSum, to_fixed};
use crate::integrator::path::{self, PathSettings};
use crate::integrator::sppm::{self, GatherContext, PhotonBuffers, PhotonMap, SppmSettings};
use crate::sampling::{Sampler, Stream};
use crate::scene::Scene;

/// The rendering method and its parameters.
#[derive(Clone, Copy, Debug, serde::Serialize, serde::Deserialize, PartialEq)]
pub enum Method {
    /// Path tracing: a pass is one path per pixel.
    Path(PathSettings),
    /// Progressive photon mapping: a pass is one iteration (a photon pass and one camera path
    /// per pixel).
    Sppm(SppmSettings),
}

/// How to render.
#[derive(Clone, Copy, Debug, serde::Serialize, serde::Deserialize, PartialEq)]
pub struct RenderSettings {
    /// Seed of every random stream.
    pub seed: u64,
    /// The method.
    pub method: Method,
}

/// Renders passes `passes` in the current rayon pool. For SPPM the radii come from the
/// settings' schedule; [`render_sppm_iterations`] takes them from the caller instead.
pub fn render_passes(scene: &Scene, settings: &RenderSettings, passes: Range<u64>) -> FilmSum {
    match &settings.method {
        Method::Path(p) => {
            let mut film = FilmSum::new(scene.width(), scene.height());
            for pass in passes {
                add_pixel_samples(scene, &mut film, |x, y, pixel| {
                    let mut sampler = Sampler::new(settings.seed, Stream::Camera, pass, pixel);
                    let ray = scene
                        .camera
                        .generate_ray(x, y, sampler.next_2d(), sampler.next_2d());
                    path::radiance(scene, p, ray, &mut sampler)
                });
            }
            film
        }
        Method::Sppm(s) => {
            let radii = s.radii(passes.clone());
            render_sppm_iterations(scene, settings.seed, s, passes, &radii)
        }
    }
}

/// Renders passes `passes` of a batch: the farm's unit of work. For SPPM, `radii` holds the
/// (surface, volume) radii of each pass (from the coordinator); for path tracing it is ignored.
pub fn render_batch(
    scene: &Scene,
    settings: &RenderSettings,
    passes: Range<u64>,
    radii: &[[f32; 2]],
) -> FilmSum {
    match &settings.method {
        Method::Path(_) => render_passes(scene, settings, passes),
        Method::Sppm(s) => render_sppm_iterations(scene, settings.seed, s, passes, radii),
    }
}

/// Renders SPPM iterations `iterations` with the given (surface, volume) radii, one pair per
/// iteration.
pub fn render_sppm_iterations(
    scene: &Scene,
    seed: u64,
    settings: &SppmSettings,
    iterations: Range<u64>,
    radii: &[[f32; 2]],
) -> FilmSum {
    assert_eq!(
        radii.len() as u64,
        iterations.end - iterations.start,
        "one radius per iteration"
    );
    let mut film = FilmSum::new(scene.width(), scene.height());
    let max_depth = settings.max_depth.unwrap_or(u32::MAX);
    // Reused across iterations: memory depends on the photon count, not on the iterations.
    let mut photons = PhotonBuffers::default();
    let mut map = PhotonMap::new();
    let mut volume_map = PhotonMap::new();
    for (iteration, &[radius, volume_radius]) in iterations.zip(radii) {
        sppm::trace_photons(scene, seed, iteration, settings.photons, max_depth, &mut photons);
        map.build(&photons.surface, radius);
        volume_map.build(&photons.volume, volume_radius);
        let ctx = GatherContext {
            scene,
            map: &map,
            radius,
            volume_map: &volume_map,
            volume_radius,
            power_unit: sppm::power_unit(scene, settings.photons),
            k: settings.k,
            max_depth,
            rr_depth: settings.rr_depth,
        };
        add_pixel_samples(scene, &mut film, |x, y, pixel| {
            let mut sampler = Sampler::new(seed, Stream::Camera, iteration, pixel);
            let ray = scene
                .camera
                .generate_ray(x, y, sampler.next_2d(), sampler.next_2d());
            sppm::camera_path(&ctx, ray, &mut sampler)
        });
    }
    film
}

/// Adds one sample per pixel, computed in parallel by rows, to the film; counts one pass.
fn add_pixel_samples(scene: &Scene, film: &mut FilmSum, sample: impl Fn(u32, u32, u64) -> Rgb + Sync) {
    let w = scene.width();
    let rows: Vec<(Vec<[i64; 3]>, u64)> = (0..scene.height())
        .into_par_iter()
        .map(|y| {
            let mut nonfinite = 0;
            let row = (0..w)
                .map(|x| {
                    let pixel = y as u64 * w as u64 + x as u64;
                    to_fixed(sample(x, y, pixel)).unwrap_or_else(|| {
                        nonfinite += 1;
                        [0; 3]
                    })
                })
                .collect();
            (row, nonfinite)
        })
        .collect();
    for (y, (row, nonfinite)) in rows.into_iter().enumerate() {
        for (acc, v) in film.sums[y * w as usize..].iter_mut().zip(row) {
            for c in 0..3 {
                acc[c] += v[c];
            }
        }
        film.nonfinite += nonfinite;
    }
    film.passes += 1;
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
        let whole = render_passes(&scene, &settings, 0..6);
        let mut parts = render_passes(&scene, &settings, 4..6);
        parts.add(&render_passes(&scene, &settings, 0..1)).unwrap();
        parts.add(&render_passes(&scene, &settings, 1..4)).unwrap();
        assert_eq!(whole, parts);
        assert!(whole.sums.iter().any(|s| s[2] > 0));
    }
}
