//! Ray throughput: `cargo bench -p photonfarm-common --bench rays`.
//!
//! Prints, per scene, single-thread figures (so "per core"): closest-hit camera rays per second,
//! a path-tracing mix of rays (camera, diffuse bounce, shadow) per second, and path-traced
//! samples per second; medians of 5 runs taken in one process. Scenes: the Cornell box, a
//! generated bumpy sphere of 131,072 triangles loaded from a binary PLY file, and any given as
//! `-- --scene PATH[,NAME=VALUE...]` (repeatable; the values are the scene's defaults).
//!
//! With `--features obvhs` it also records one set of camera, bounce and shadow rays per scene
//! and traces exactly those with our BVH, obvhs's CWBVH and obvhs's BVH2 (BVH only, no surface
//! evaluation): rays per second per type (medians of 5), build times and hit mismatches against
//! ours.

use std::path::Path;
use std::time::Instant;

use glam::Vec2;
use photonfarm::geometry::Frame;
use photonfarm::integrator::path::PathSettings;
use photonfarm::render::{Method, RenderSettings, Renderer};
use photonfarm::sampling::{Sampler, Stream, square_to_cosine_hemisphere};
use photonfarm::scene::Scene;
#[cfg(feature = "obvhs")]
use shared::{SHADOW_T_MAX, record};

mod shared;

const RUNS: usize = 5;

fn median(mut v: Vec<f64>) -> f64 {
    v.sort_by(f64::total_cmp);
    v[v.len() / 2]
}

/// Camera rays, then for each hit one cosine-distributed bounce and one shadow ray to a light.
fn ray_mix(scene: &Scene, pass: u64) -> (u64, u64) {
    let (mut primary, mut total) = (0u64, 0u64);
    for y in 0..scene.height() {
        for x in 0..scene.width() {
            let mut s = Sampler::new(1, Stream::Camera, pass, (y * scene.width() + x) as u64);
            let ray = scene.camera.generate_ray(x, y, s.next_2d(), Vec2::ZERO);
            primary += 1;
            total += 1;
            let Some((_, sp)) = scene.intersect(&ray) else {
                continue;
            };
            let frame = Frame::from_normal(sp.ns);
            let w = frame.to_world(square_to_cosine_hemisphere(s.next_2d()));
            let _ = scene.intersect(&Scene::spawn_ray(&sp, w));
            total += 1;
            if let Some((_, ls)) = scene.sample_light(sp.p, s.next_1d(), s.next_2d()) {
                let _ = scene.transmittance(&sp, &ls, None, &mut s);
                total += 1;
            }
        }
    }
    (primary, total)
}

fn primary_rays(scene: &Scene, pass: u64) -> u64 {
    let mut n = 0;
    for y in 0..scene.height() {
        for x in 0..scene.width() {
            let mut s = Sampler::new(1, Stream::Camera, pass, (y * scene.width() + x) as u64);
            let ray = scene.camera.generate_ray(x, y, s.next_2d(), Vec2::ZERO);
            std::hint::black_box(scene.intersect(&ray));
            n += 1;
        }
    }
    n
}

fn bench(name: &str, scene: &Scene) {
    let mut primary = Vec::new();
    let mut mix = Vec::new();
    let mut paths = Vec::new();
    let settings = RenderSettings {
        seed: 0,
        method: Method::Path(PathSettings::from_scene(scene)),
    };
    let pool = rayon::ThreadPoolBuilder::new().num_threads(1).build().unwrap();
    for run in 0..RUNS as u64 {
        let t = Instant::now();
        let n = primary_rays(scene, run);
        primary.push(n as f64 / t.elapsed().as_secs_f64());
        let t = Instant::now();
        let (_, n) = ray_mix(scene, run);
        mix.push(n as f64 / t.elapsed().as_secs_f64());
        let t = Instant::now();
        pool.install(|| Renderer::on(scene, &settings, None).passes(run..run + 1));
        paths.push((scene.width() * scene.height()) as f64 / t.elapsed().as_secs_f64());
    }
    println!(
        "{name:<28} camera rays {:>6.2} M/s/core | ray mix {:>6.2} M/s/core | path samples {:>6.3} M/s/core",
        median(primary) / 1e6,
        median(mix) / 1e6,
        median(paths) / 1e6
    );
}

/// Ours vs obvhs's CWBVH vs its BVH2 on the same recorded rays. The backends take turns within
/// each run, so that load from other processes falls on all of them alike.
#[cfg(feature = "obvhs")]
fn ab(name: &str, scene: &Scene) {
    use photonfarm::geometry::{Backend, Bvh};
    use std::hint::black_box;
    const AB_RUNS: usize = 15;
    let rays = record(scene);
    let prims: Vec<_> = scene.bvh.distinct().map(|(_, p)| p.clone()).collect();
    let backends = [Backend::Own, Backend::Cwbvh, Backend::Bvh2];
    let mut builds = vec![Vec::new(); backends.len()];
    let mut bvhs = Vec::new();
    for _ in 0..RUNS {
        bvhs.clear();
        for (i, &b) in backends.iter().enumerate() {
            let t = Instant::now();
            bvhs.push(Bvh::build_with(prims.clone(), b));
            builds[i].push(t.elapsed().as_secs_f64());
        }
    }
    let counts = [
        rays.camera.len(),
        rays.bounce.len(),
        rays.shadow.len(),
        rays.camera.len() + rays.bounce.len() + rays.shadow.len(),
    ];
    // [backend][ray type] -> M rays/s of each run.
    let mut rates = vec![[(); 4].map(|_| Vec::new()); backends.len()];
    for _ in 0..AB_RUNS {
        for (i, bvh) in bvhs.iter().enumerate() {
            let t0 = Instant::now();
            for r in &rays.camera {
                black_box(bvh.intersect(r, f32::INFINITY));
            }
            let t1 = Instant::now();
            for r in &rays.bounce {
                black_box(bvh.intersect(r, f32::INFINITY));
            }
            let t2 = Instant::now();
            for r in &rays.shadow {
                black_box(bvh.occluded(r, SHADOW_T_MAX));
            }
            let t3 = Instant::now();
            let secs = [t1 - t0, t2 - t1, t3 - t2, t3 - t0].map(|d| d.as_secs_f64());
            for k in 0..4 {
                rates[i][k].push(counts[k] as f64 / secs[k] / 1e6);
            }
        }
    }
    let closest = |bvh: &Bvh, rs: &[photonfarm::geometry::Ray]| -> Vec<Option<f32>> {
        rs.iter()
            .map(|r| bvh.intersect(r, f32::INFINITY).map(|h| h.t))
            .collect()
    };
    let results: Vec<_> = bvhs
        .iter()
        .map(|bvh| {
            let sha: Vec<bool> = rays
                .shadow
                .iter()
                .map(|r| bvh.occluded(r, SHADOW_T_MAX))
                .collect();
            (closest(bvh, &rays.camera), closest(bvh, &rays.bounce), sha)
        })
        .collect();
    let differs = |a: &Option<f32>, b: &Option<f32>| match (a, b) {
        (Some(a), Some(b)) => (a - b).abs() > 1e-4 * a.abs(),
        (None, None) => false,
        _ => true,
    };
    println!(
        "  A/B on {name}: {} camera, {} bounce, {} shadow rays; M rays/s/core, median (best) of {AB_RUNS}",
        counts[0], counts[1], counts[2]
    );
    println!(
        "  {:<7} {:>9} {:>15} {:>15} {:>15} {:>15} {:>11}",
        "backend", "build ms", "camera", "bounce", "shadow", "all", "mismatches"
    );
    let (rc, rb, rs) = &results[0];
    for (i, bvh) in bvhs.iter().enumerate() {
        let (c, b, s) = &results[i];
        let mismatches = if i == 0 {
            "(reference)".to_string()
        } else {
            let mc = rc.iter().zip(c).filter(|(x, y)| differs(x, y)).count();
            let mb = rb.iter().zip(b).filter(|(x, y)| differs(x, y)).count();
            let ms = rs.iter().zip(s).filter(|(x, y)| x != y).count();
            format!("{mc}/{mb}/{ms}")
        };
        let cell = |v: &Vec<f64>| {
            let best = v.iter().copied().fold(0.0, f64::max);
            format!("{:.2} ({:.2})", median(v.clone()), best)
        };
        println!(
            "  {:<7} {:>9.2} {:>15} {:>15} {:>15} {:>15} {mismatches:>11}{}",
            format!("{:?}", bvh.backend()).to_lowercase(),
            median(builds[i].clone()) * 1e3,
            cell(&rates[i][0]),
            cell(&rates[i][1]),
            cell(&rates[i][2]),
            cell(&rates[i][3]),
            if bvh.backend() != backends[i] {
                "  (fell back to ours)"
            } else {
                ""
            }
        );
    }
}

fn main() {
    let refs = Path::new(env!("CARGO_MANIFEST_DIR")).join("../tests/refs");
    let res = [("res".to_string(), "256".to_string())];
    let cbox = Scene::load(&refs.join("cbox.xml"), &res).unwrap();
    bench("cbox (36 triangles)", &cbox);
    #[cfg(feature = "obvhs")]
    ab("cbox", &cbox);

    let dir = tempfile::tempdir().unwrap();
    let t = Instant::now();
    let (mesh, tris) = shared::bumpy_cbox(dir.path(), &res, false);
    println!(
        "bumpy sphere: {tris} triangles, loaded and BVH built in {:.3} s",
        t.elapsed().as_secs_f64()
    );
    bench(&format!("bumpy sphere ({}k triangles)", tris / 1000), &mesh);
    #[cfg(feature = "obvhs")]
    ab("bumpy sphere", &mesh);

    // Scenes of one's own, for instance the interiors of the fair race (not checked in):
    // `--scene PATH[,NAME=VALUE...]`, repeatable.
    let args: Vec<String> = std::env::args().collect();
    for w in args.windows(2).filter(|w| w[0] == "--scene") {
        let mut parts = w[1].split(',');
        let path = parts.next().unwrap_or_default();
        let defines: Vec<(String, String)> = parts
            .filter_map(|kv| kv.split_once('='))
            .map(|(k, v)| (k.to_string(), v.to_string()))
            .collect();
        let t = Instant::now();
        let scene = match Scene::load(Path::new(path), &defines) {
            Ok(scene) => scene,
            Err(e) => {
                eprintln!("{path}: {e}");
                std::process::exit(1);
            }
        };
        let name = format!(
            "{path} ({} primitives, {} in leaves, loaded in {:.2} s)",
            scene.bvh.distinct_len(),
            scene.bvh.primitives().len(),
            t.elapsed().as_secs_f64()
        );
        bench(&name, &scene);
        #[cfg(feature = "obvhs")]
        ab(&name, &scene);
    }
}
