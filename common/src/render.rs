//! The unit of work: render passes [a, b) of an image and return their exact sum.
//!
//! A pass is one sample per pixel. Its random numbers come from (seed, pass, pixel) alone, so
//! the sum of a pass range is the same whichever thread, machine or batch renders it.

use std::ops::Range;
use std::time::{Duration, Instant};

use rayon::prelude::*;

use crate::film::{FilmSum, to_fixed};
use crate::integrator::path::{self, PathSettings};
use crate::sampling::{Sampler, Stream};
use crate::scene::Scene;

/// How to render.
#[derive(Clone, Copy, Debug)]
pub struct RenderSettings {
    /// Seed of every random stream.
    pub seed: u64,
    /// Path tracer settings.
    pub path: PathSettings,
}

/// Renders passes `passes` in the current rayon pool.
pub fn render_passes(scene: &Scene, settings: &RenderSettings, passes: Range<u64>) -> FilmSum {
    let (w, h) = (scene.width(), scene.height());
    let rows: Vec<(Vec<[i64; 3]>, u64)> = (0..h)
        .into_par_iter()
        .map(|y| render_row(scene, settings, y, passes.clone()))
        .collect();
    let mut film = FilmSum::new(w, h);
    film.passes = passes.end.saturating_sub(passes.start);
    for (y, (row, bad)) in rows.into_iter().enumerate() {
        film.sums[y * w as usize..(y + 1) * w as usize].copy_from_slice(&row);
        film.nonfinite += bad;
    }
    film
}

fn render_row(scene: &Scene, settings: &RenderSettings, y: u32, passes: Range<u64>) -> (Vec<[i64; 3]>, u64) {
    let w = scene.width();
    let mut row = vec![[0i64; 3]; w as usize];
    let mut nonfinite = 0;
    for (x, acc) in row.iter_mut().enumerate() {
        let pixel = y as u64 * w as u64 + x as u64;
        for pass in passes.clone() {
            let mut sampler = Sampler::new(settings.seed, Stream::Camera, pass, pixel);
            let u_pixel = sampler.next_2d();
            let u_lens = sampler.next_2d();
            let ray = scene.camera.generate_ray(x as u32, y, u_pixel, u_lens);
            let l = path::radiance(scene, &settings.path, ray, &mut sampler);
            match to_fixed(l) {
                Some(v) => {
                    for c in 0..3 {
                        acc[c] += v[c];
                    }
                }
                None => nonfinite += 1,
            }
        }
    }
    (row, nonfinite)
}

/// When to stop a progressive render.
#[derive(Clone, Copy, Debug, Default)]
pub struct Budget {
    /// Total passes; None for no limit (then a time limit is needed).
    pub passes: Option<u64>,
    /// Wall-clock limit: whole passes are rendered until it is reached.
    pub time_limit: Option<Duration>,
}

/// Where a progressive render stands.
#[derive(Clone, Copy, Debug)]
pub struct Progress {
    /// Passes finished.
    pub done: u64,
    /// Passes planned, if known.
    pub total: Option<u64>,
    /// Time since the start.
    pub elapsed: Duration,
}

/// Renders passes in chunks from 0 until the budget is spent, reporting after each chunk.
/// At least one pass is always rendered.
pub fn render_progressive(
    scene: &Scene,
    settings: &RenderSettings,
    budget: Budget,
    mut on_progress: impl FnMut(&Progress, &FilmSum),
) -> FilmSum {
    let start = Instant::now();
    let mut film = FilmSum::new(scene.width(), scene.height());
    let mut chunk = 1u64;
    loop {
        let remaining = budget.passes.map(|t| t - film.passes);
        let chunk_now = remaining.map_or(chunk, |r| chunk.min(r));
        let part = render_passes(scene, settings, film.passes..film.passes + chunk_now);
        film.add(&part).expect("same scene, same size");
        let elapsed = start.elapsed();
        on_progress(
            &Progress {
                done: film.passes,
                total: budget.passes,
                elapsed,
            },
            &film,
        );
        if budget.passes.is_some_and(|t| film.passes >= t) {
            break;
        }
        // Aim for about half a second per chunk, so progress and the time limit stay responsive.
        let per_pass = elapsed.as_secs_f64() / film.passes as f64;
        let mut next = (0.5 / per_pass.max(1e-9)) as u64;
        if let Some(limit) = budget.time_limit {
            if elapsed >= limit {
                break;
            }
            next = next.min(((limit - elapsed).as_secs_f64() / per_pass.max(1e-9)) as u64);
        }
        chunk = next.clamp(1, 1 << 20);
    }
    film
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
            path: PathSettings::from_scene(&scene),
        };
        let whole = render_passes(&scene, &settings, 0..6);
        let mut parts = render_passes(&scene, &settings, 4..6);
        parts.add(&render_passes(&scene, &settings, 0..1)).unwrap();
        parts.add(&render_passes(&scene, &settings, 1..4)).unwrap();
        assert_eq!(whole, parts);
        assert!(whole.sums.iter().any(|s| s[2] > 0));
    }
}
