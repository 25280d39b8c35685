//! Every reference scene gives the same bytes on every SIMD backend this machine has, on one
//! thread and on two (issue 27): the farm's promise of the same image whatever the workers.
//! Scenes the lane engine models (25 of the 36 today: mostly Lambertian or GGX-plastic
//! triangles, under any lights, without media or null surfaces) run on it; the rest run on
//! the scalar integrators whatever the backend, and join the comparison as the engine grows.

use photonfarm::engine::Backend;
use photonfarm::job::JobSettings;
use photonfarm::render::Renderer;
use photonfarm_tests::{load, refs_dir};

#[test]
fn every_reference_scene_gives_the_same_bytes_on_every_backend() {
    let mut scenes: Vec<_> = std::fs::read_dir(refs_dir())
        .unwrap()
        .map(|e| e.unwrap().path())
        .filter(|p| p.extension().is_some_and(|e| e == "xml"))
        .collect();
    scenes.sort();
    assert!(scenes.len() >= 30, "{} scenes", scenes.len());
    let backends = Backend::available();
    let pools: Vec<_> = [1, 2]
        .map(|n| rayon::ThreadPoolBuilder::new().num_threads(n).build().unwrap())
        .into();
    let mut on_lanes = 0;
    for path in &scenes {
        let text = std::fs::read_to_string(path).unwrap();
        // Small films, where the scene's size is a parameter (`$res`, or `$width` and `$height`).
        let defines: &[(&str, &str)] = if text.contains("$res") {
            &[("res", "12")]
        } else if text.contains("$width") {
            &[("width", "12"), ("height", "12")]
        } else {
            &[]
        };
        let scene = load(path, defines);
        let settings = JobSettings {
            passes: Some(2),
            seed: 3,
            ..JobSettings::default()
        }
        .resolve(&scene, false)
        .unwrap_or_else(|e| panic!("{}: {e}", path.display()));
        let render = |b: Backend| Renderer::on(&scene, &settings.render, Some(b));
        let mut renderer = render(backends[0]);
        on_lanes += usize::from(renderer.on_lanes());
        let first = pools[0].install(|| renderer.passes(0..2));
        for (pool, threads) in pools.iter().zip([1, 2]) {
            for &b in &backends {
                let film = pool.install(|| render(b).passes(0..2));
                assert!(
                    film == first,
                    "{}: {b} on {threads} threads differs from {} on 1",
                    path.display(),
                    backends[0]
                );
            }
        }
    }
    eprintln!(
        "{} scenes, {on_lanes} on the lane engine, backends {backends:?}",
        scenes.len()
    );
    // The comparison covers the lane engine, not only the scalar code.
    assert!(on_lanes >= 25, "{on_lanes} scenes ran on the lane engine");
}
