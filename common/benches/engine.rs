//! The lane engine's prototype against the scalar path tracer:
//! `cargo bench -p photonfarm-common --bench engine`.
//!
//! Cornell box at 256², one thread ("per core"): path samples per second of the scalar path
//! tracer and of the prototype on each backend this machine has, medians of 7 runs of 4 passes
//! taken in turn in one process (so that load from other processes falls on all alike), with
//! ratios to the scalar tracer. docs/engine.md keeps the table.

use std::path::Path;
use std::time::Instant;

use photonfarm::engine::Backend;
use photonfarm::engine::diffuse_path::{DiffuseScene, render_pass};
use photonfarm::film::FilmSum;
use photonfarm::integrator::path::PathSettings;
use photonfarm::render::{Method, RenderSettings, render_passes};
use photonfarm::scene::Scene;

const RUNS: usize = 7;
const PASSES: u64 = 4;

fn median(mut v: Vec<f64>) -> f64 {
    v.sort_by(f64::total_cmp);
    v[v.len() / 2]
}

fn main() {
    let refs = Path::new(env!("CARGO_MANIFEST_DIR")).join("../tests/refs");
    let res = [("res".to_string(), "256".to_string())];
    let scene = Scene::load(&refs.join("cbox.xml"), &res).unwrap();
    let ds = DiffuseScene::new(&scene).unwrap();
    let settings = RenderSettings {
        seed: 0,
        method: Method::Path(PathSettings::from_scene(&scene)),
    };
    let samples = (scene.width() * scene.height()) as f64 * PASSES as f64;
    let backends = Backend::available();
    let pool = rayon::ThreadPoolBuilder::new().num_threads(1).build().unwrap();
    // [0] scalar, [1..] backends: M samples/s of each run.
    let mut rates = vec![Vec::new(); 1 + backends.len()];
    pool.install(|| {
        for run in 0..RUNS as u64 {
            let passes = run * PASSES..(run + 1) * PASSES;
            let t = Instant::now();
            std::hint::black_box(render_passes(&scene, &settings, passes.clone()));
            rates[0].push(samples / t.elapsed().as_secs_f64() / 1e6);
            for (k, &b) in backends.iter().enumerate() {
                let mut film = FilmSum::new(scene.width(), scene.height());
                let t = Instant::now();
                for pass in passes.clone() {
                    render_pass(&scene, &ds, 0, pass, b, &mut film);
                }
                std::hint::black_box(&film);
                rates[k + 1].push(samples / t.elapsed().as_secs_f64() / 1e6);
            }
        }
    });
    let scalar = median(rates[0].clone());
    println!("cbox 256², 1 thread, medians of {RUNS} runs of {PASSES} passes");
    println!("{:<24} {:>8.3} M samples/s", "scalar path tracer", scalar);
    for (k, b) in backends.iter().enumerate() {
        let m = median(rates[k + 1].clone());
        println!(
            "{:<24} {:>8.3} M samples/s  {:>5.2}× scalar",
            format!("lanes, {b}"),
            m,
            m / scalar
        );
    }
}
