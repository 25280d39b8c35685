//! The lane engine's prototype against the scalar path tracer:
//! `cargo bench -p photonfarm-common --bench engine`.
//!
//! The Cornell box and a bumpy sphere of 131,072 triangles in it (vertex normals), at 256², one thread ("per
//! core"): path samples per second of the scalar path tracer and of the prototype on each
//! backend this machine has, medians of 7 runs of 4 passes
//! taken in turn in one process (so that load from other processes falls on all alike), with
//! ratios to the scalar tracer. Then the traversal alone, on rays recorded as the path tracer
//! makes them (camera, diffuse bounce, shadow): one ray at a time against eight-ray packets,
//! M rays/s, medians of 7. docs/engine.md keeps the tables.

use std::path::Path;
use std::time::Instant;

use photonfarm::engine::Backend;
use photonfarm::engine::lanes::{F8, LANES, M8, V8};
use photonfarm::engine::path::{LaneScene, render_pass};
use photonfarm::film::FilmSum;
use photonfarm::geometry::{Ray, Rays8};
use photonfarm::integrator::path::PathSettings;
use photonfarm::render::{Method, RenderSettings, Renderer};
use photonfarm::scene::Scene;

mod shared;

const RUNS: usize = 7;
const PASSES: u64 = 4;

fn median(mut v: Vec<f64>) -> f64 {
    v.sort_by(f64::total_cmp);
    v[v.len() / 2]
}

/// Traces `rays` in packets of eight (the last one part full): how many hit.
struct Packets<'a> {
    scene: &'a Scene,
    rays: &'a [Ray],
    t_max: f32,
    shadow: bool,
}

impl pulp::WithSimd for Packets<'_> {
    type Output = usize;

    #[inline(always)]
    fn with_simd<S: pulp::Simd>(self, _: S) -> usize {
        let mut n = 0;
        for chunk in self.rays.chunks(LANES) {
            let lane = |i: usize, f: fn(&Ray) -> f32| chunk.get(i).map_or(0.0, f);
            let rays = Rays8 {
                o: V8 {
                    x: F8::from_fn(|i| lane(i, |r| r.o.x)),
                    y: F8::from_fn(|i| lane(i, |r| r.o.y)),
                    z: F8::from_fn(|i| lane(i, |r| r.o.z)),
                },
                d: V8 {
                    x: F8::from_fn(|i| lane(i, |r| r.d.x)),
                    y: F8::from_fn(|i| lane(i, |r| r.d.y)),
                    z: F8::from_fn(|i| lane(i, |r| r.d.z)),
                },
                t_max: F8::splat(self.t_max),
                active: M8::from_fn(|i| i < chunk.len()),
            };
            let hit = if self.shadow {
                self.scene.bvh.occluded8(&rays)
            } else {
                self.scene.bvh.intersect8(&rays).found
            };
            n += hit.to_bools().iter().filter(|&&b| b).count();
        }
        n
    }
}

/// Closest-hit and occlusion rates, one ray at a time and in packets on each backend.
fn traversal(scene: &Scene, backends: &[Backend]) {
    let rec = shared::record(scene);
    let octant =
        |r: &Ray| usize::from(r.d.x < 0.0) | usize::from(r.d.y < 0.0) << 1 | usize::from(r.d.z < 0.0) << 2;
    let mut by_octant = rec.bounce.clone();
    by_octant.sort_by_key(octant);
    let sets = [
        ("camera", &rec.camera, f32::INFINITY, false),
        ("bounce", &rec.bounce, f32::INFINITY, false),
        ("bounce/octant", &by_octant, f32::INFINITY, false),
        ("shadow", &rec.shadow, shared::SHADOW_T_MAX, true),
    ];
    println!("traversal, M rays/s, 1 thread");
    print!("{:<24}", "");
    for b in backends {
        print!(" {:>14}", format!("packets, {b}"));
    }
    println!();
    for (name, rays, t_max, shadow) in sets {
        let mut single = Vec::new();
        let mut packets = vec![Vec::new(); backends.len()];
        let mut counts = Vec::new();
        for _ in 0..RUNS {
            let t = Instant::now();
            let n = rays
                .iter()
                .filter(|r| {
                    if shadow {
                        scene.bvh.occluded(r, t_max)
                    } else {
                        scene.bvh.intersect(r, t_max).is_some()
                    }
                })
                .count();
            single.push(rays.len() as f64 / t.elapsed().as_secs_f64() / 1e6);
            counts.push(n);
            for (k, &b) in backends.iter().enumerate() {
                let t = Instant::now();
                let m = b.run(Packets {
                    scene,
                    rays,
                    t_max,
                    shadow,
                });
                packets[k].push(rays.len() as f64 / t.elapsed().as_secs_f64() / 1e6);
                assert_eq!(m, n, "{name} rays: packets on {b} found other hits");
            }
        }
        let one = median(single);
        print!(
            "{:<24}",
            format!("{name} ({}k), one ray {one:.1}", rays.len() / 1000)
        );
        for p in packets {
            let m = median(p);
            print!(" {:>8.1} {:>4.2}×", m, m / one);
        }
        println!();
    }
}

/// The prototype against the scalar path tracer on `scene`, then the traversal table.
fn race(name: &str, scene: &Scene, backends: &[Backend]) {
    let path = PathSettings::from_scene(scene);
    let ds = LaneScene::new(scene, &path).unwrap();
    // What a worker paid per pass before `Renderer` made the lane scene once per batch.
    let build = median(
        (0..RUNS)
            .map(|_| {
                let t = Instant::now();
                std::hint::black_box(LaneScene::new(scene, &path).unwrap());
                t.elapsed().as_secs_f64() * 1e3
            })
            .collect(),
    );
    let settings = RenderSettings {
        seed: 0,
        method: Method::Path(path),
    };
    let samples = (scene.width() * scene.height()) as f64 * PASSES as f64;
    // [0] scalar, [1..] backends: M samples/s of each run.
    let mut rates = vec![Vec::new(); 1 + backends.len()];
    for run in 0..RUNS as u64 {
        let passes = run * PASSES..(run + 1) * PASSES;
        let t = Instant::now();
        std::hint::black_box(Renderer::on(scene, &settings, None).passes(passes.clone()));
        rates[0].push(samples / t.elapsed().as_secs_f64() / 1e6);
        for (k, &b) in backends.iter().enumerate() {
            let mut film = FilmSum::new(scene.width(), scene.height());
            let t = Instant::now();
            for pass in passes.clone() {
                render_pass(scene, &ds, 0, pass, b, &mut film);
            }
            std::hint::black_box(&film);
            rates[k + 1].push(samples / t.elapsed().as_secs_f64() / 1e6);
        }
    }
    let scalar = median(rates[0].clone());
    println!("{name}, 256², 1 thread, medians of {RUNS} runs of {PASSES} passes");
    println!("{:<24} {:>8.3} M samples/s", "scalar path tracer", scalar);
    let pass_ms = (scene.width() * scene.height()) as f64 / median(rates[1].clone()) / 1e3;
    println!(
        "lane scene made in {build:.2} ms; a pass on {} takes {pass_ms:.1} ms",
        backends[0]
    );
    for (k, b) in backends.iter().enumerate() {
        let m = median(rates[k + 1].clone());
        println!(
            "{:<24} {:>8.3} M samples/s  {:>5.2}× scalar",
            format!("lanes, {b}"),
            m,
            m / scalar
        );
    }
    traversal(scene, backends);
}

fn main() {
    let refs = Path::new(env!("CARGO_MANIFEST_DIR")).join("../tests/refs");
    let res = [("res".to_string(), "256".to_string())];
    let backends = Backend::available();
    let pool = rayon::ThreadPoolBuilder::new().num_threads(1).build().unwrap();
    let cbox = Scene::load(&refs.join("cbox.xml"), &res).unwrap();
    pool.install(|| race("cbox (36 triangles)", &cbox, &backends));
    let dir = tempfile::tempdir().unwrap();
    let (bumpy, tris) = shared::bumpy_cbox(dir.path(), &res, false);
    let name = format!(
        "bumpy sphere in cbox ({}k triangles, vertex normals)",
        tris / 1000
    );
    pool.install(|| race(&name, &bumpy, &backends));
}
