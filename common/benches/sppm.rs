//! SPPM costs: `cargo bench -p photonfarm-common --bench sppm`.
//!
//! On cbox-spheres at 256×256 with 200,000 photons per iteration, medians of 5 runs in one
//! process: photons traced per second on one core, photon map build time, gather time per
//! pixel (the whole camera pass on one core, over the pixel count), and the whole iteration on
//! all cores. Also the same photons and queries through kiddo's kd-tree, the well-kept crate
//! the issue names, to justify the hashed grid.

use std::path::Path;
use std::time::Instant;

use glam::Vec2;
use kiddo::{ImmutableKdTree, SquaredEuclidean};
use photonfarm::integrator::sppm::{self, GatherContext, PhotonMap, SppmSettings, VolumeMap};
use photonfarm::render::{Method, RenderSettings, Renderer};
use photonfarm::sampling::{Sampler, Stream};
use photonfarm::scene::Scene;

const RUNS: usize = 5;
const PHOTONS: u64 = 200_000;

fn median(mut v: Vec<f64>) -> f64 {
    v.sort_by(f64::total_cmp);
    v[v.len() / 2]
}

fn main() {
    let path = Path::new(env!("CARGO_MANIFEST_DIR")).join("../tests/refs/cbox-spheres.xml");
    let scene = Scene::load(&path, &[("res".into(), "256".into())]).unwrap();
    let mut settings = SppmSettings::from_scene(&scene);
    settings.photons = PHOTONS;
    let radius = settings.initial_radius;
    let one = rayon::ThreadPoolBuilder::new().num_threads(1).build().unwrap();
    let pixels = (scene.width() * scene.height()) as f64;

    let mut buffers = sppm::PhotonBuffers::default();
    let mut trace = Vec::new();
    for run in 0..RUNS as u64 {
        let t = Instant::now();
        one.install(|| {
            sppm::trace_photons(
                &scene,
                0,
                run,
                PHOTONS,
                u32::MAX,
                sppm::VolumeRecord::Points,
                &mut buffers,
            )
        });
        trace.push(PHOTONS as f64 / t.elapsed().as_secs_f64());
    }
    println!(
        "photon pass: {:.2} M photons/s/core ({} emitted, {} stored, {} bytes each)",
        median(trace) / 1e6,
        PHOTONS,
        buffers.surface.len(),
        std::mem::size_of::<sppm::Photon>()
    );

    let photons = buffers.surface;
    let mut map = PhotonMap::new();
    let volume_map = sppm::BeamMap::new();
    let (mut grid_build, mut kd_build) = (Vec::new(), Vec::new());
    let points: Vec<[f32; 3]> = photons.iter().map(|p| p.p).collect();
    let mut tree = None;
    for _ in 0..RUNS {
        let t = Instant::now();
        map.build(&photons, radius);
        grid_build.push(t.elapsed().as_secs_f64());
        let t = Instant::now();
        tree = Some(ImmutableKdTree::<f32, 3>::new_from_slice(&points).unwrap());
        kd_build.push(t.elapsed().as_secs_f64());
    }
    let tree = tree.unwrap();
    println!(
        "photon map build ({} photons): hashed grid {:.2} ms, kiddo kd-tree {:.2} ms",
        photons.len(),
        median(grid_build) * 1e3,
        median(kd_build) * 1e3
    );

    // Query points: where camera rays first meet a diffuse surface.
    let mut queries = Vec::new();
    for y in 0..scene.height() {
        for x in 0..scene.width() {
            let ray = scene.camera.generate_ray(x, y, Vec2::splat(0.5), Vec2::ZERO);
            if let Some((_, sp)) = scene.intersect(&ray) {
                queries.push(sp.p);
            }
        }
    }
    let (mut grid_q, mut kd_q) = (Vec::new(), Vec::new());
    let (mut grid_found, mut kd_found) = (0usize, 0usize);
    let r2 = radius * radius;
    for _ in 0..RUNS {
        let t = Instant::now();
        grid_found = 0;
        for q in &queries {
            map.for_each_near(*q, |_, _| grid_found += 1);
        }
        grid_q.push(t.elapsed().as_secs_f64() / queries.len() as f64);
        let t = Instant::now();
        kd_found = 0;
        for q in &queries {
            kd_found += tree
                .query(&[q.x, q.y, q.z])
                .within::<SquaredEuclidean<f32>>(r2)
                .unsorted()
                .execute()
                .len();
        }
        kd_q.push(t.elapsed().as_secs_f64() / queries.len() as f64);
    }
    println!(
        "radius query (r = {radius:.4}, {:.1} photons found on average): hashed grid {:.0} ns, kiddo {:.0} ns \
         (found {grid_found} vs {kd_found})",
        grid_found as f64 / queries.len() as f64,
        median(grid_q) * 1e9,
        median(kd_q) * 1e9
    );

    let mut gather = Vec::new();
    for run in 0..RUNS as u64 {
        let ctx = GatherContext {
            scene: &scene,
            map: &map,
            radius,
            volume_map: VolumeMap::Beam(&volume_map),
            volume_radius: radius,
            power_unit: sppm::power_unit(&scene, PHOTONS),
            k: settings.k,
            max_depth: u32::MAX,
            rr_depth: settings.rr_depth,
        };
        let t = Instant::now();
        let mut sum = 0.0f32;
        for y in 0..scene.height() {
            for x in 0..scene.width() {
                let mut s = Sampler::new(0, Stream::Camera, run, (y * scene.width() + x) as u64);
                let ray = scene.camera.generate_ray(x, y, s.next_2d(), s.next_2d());
                sum += sppm::camera_path(&ctx, ray, &mut s).x;
            }
        }
        std::hint::black_box(sum);
        gather.push(t.elapsed().as_secs_f64() / pixels);
    }
    println!(
        "camera pass: {:.2} µs per pixel per core (path to the gather point, direct light, photon estimate)",
        median(gather) * 1e6
    );

    let render = RenderSettings {
        seed: 0,
        method: Method::Sppm(settings),
    };
    let mut whole = Vec::new();
    for run in 0..RUNS as u64 {
        let t = Instant::now();
        Renderer::new(&scene, &render).passes(run..run + 1);
        whole.push(t.elapsed().as_secs_f64());
    }
    println!(
        "whole iteration on {} threads: {:.1} ms",
        rayon::current_num_threads(),
        median(whole) * 1e3
    );

    // The cost of a medium: the fog test scene as it is, and with its fog removed (the sensor's
    // and the light's references to it deleted), same photons, same resolution.
    let fog_path = Path::new(env!("CARGO_MANIFEST_DIR")).join("../tests/refs/fog.xml");
    let fog_text = std::fs::read_to_string(&fog_path).unwrap();
    let clear_text = fog_text.replace("<ref id=\"fog\"/>", "");
    let res = [("res".to_string(), "128".to_string())];
    for (name, text) in [("with fog", &fog_text), ("without fog", &clear_text)] {
        let scene = Scene::from_str(text, &fog_path, &res).unwrap();
        let mut s = SppmSettings::from_scene(&scene);
        s.photons = PHOTONS;
        let render = RenderSettings {
            seed: 0,
            method: Method::Sppm(s),
        };
        let mut times = Vec::new();
        for run in 0..RUNS as u64 {
            let t = Instant::now();
            Renderer::new(&scene, &render).passes(run..run + 1);
            times.push(t.elapsed().as_secs_f64());
        }
        let mut buffers = sppm::PhotonBuffers::default();
        sppm::trace_photons(
            &scene,
            0,
            0,
            PHOTONS,
            u32::MAX,
            sppm::VolumeRecord::Points,
            &mut buffers,
        );
        println!(
            "fog scene {name}, 128x128, 200000 photons: {:.1} ms per iteration ({} surface and {} volume photons stored)",
            median(times) * 1e3,
            buffers.surface.len(),
            buffers.volume.len()
        );
    }
}
