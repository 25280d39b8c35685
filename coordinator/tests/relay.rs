//! The relay as users run it: a real coordinator, a real `coordinator relay` in front of two
//! real workers, real HTTP. The farm's image through the relay must be the bytes of
//! `coordinator render` with the same job and seed, and the noise estimate must follow (the
//! relay sums its workers' odd passes, and their features, too).

mod support;

use std::path::Path;
use std::process::Command;

use serde_json::Value;
use support::{Proc, announced, cbox_spheres as scene, coordinator_bin, worker};

/// SPPM (so the relay must hand each worker its passes' radii) with a Gaussian filter (so
/// pixel weights are merged too) and the denoiser's features (so the relay sums its workers'
/// features, and the EXR compared carries them as channels); small enough for CI.
const JOB: &[&str] = &[
    "--aovs",
    "--integrator",
    "sppm",
    "--iterations",
    "24",
    "--photons",
    "60000",
    "--seed",
    "5",
    "--checkpoint-every",
    "24",
    "-D",
    "res=40",
    "-D",
    "filter=gaussian",
];

fn relay(upstream: &str) -> (Proc, String) {
    let mut command = Command::new(coordinator_bin());
    command.args([
        "relay",
        "--upstream",
        upstream,
        "--bind",
        "127.0.0.1:0",
        "--name",
        "relay-a",
    ]);
    announced(command)
}

fn get(url: &str) -> Value {
    let rt = tokio::runtime::Builder::new_current_thread()
        .enable_all()
        .build()
        .unwrap();
    rt.block_on(async { reqwest::get(url).await.unwrap().json().await.unwrap() })
}

fn run(args: &[&str], dir: &Path) -> std::process::Output {
    let o = Command::new(coordinator_bin())
        .args(args)
        .current_dir(dir)
        .output()
        .unwrap();
    assert!(o.status.success(), "{}", String::from_utf8_lossy(&o.stderr));
    o
}

#[test]
fn two_workers_behind_a_relay_give_the_bytes_of_a_local_render() {
    let dir = tempfile::tempdir().unwrap();
    let scene = scene();
    let scene = scene.to_str().unwrap();
    let local = dir.path().join("local.exr");
    run(
        &[&["render", scene, "--out", local.to_str().unwrap()], JOB].concat(),
        dir.path(),
    );

    let (_serve, url) = support::serve(
        &dir.path().join("data"),
        "127.0.0.1:0",
        &["--batch-seconds", "0.5"],
        &[],
    );
    let (_relay, relay_url) = relay(&url);
    let _workers: Vec<Proc> = (0..2)
        .map(|i| worker(&relay_url, &format!("w{i}"), dir.path()))
        .collect();
    let farm = dir.path().join("farm.exr");
    let o = run(
        &[
            &["submit", "--to", &url, scene],
            JOB,
            &["--wait", "--out", farm.to_str().unwrap()],
        ]
        .concat(),
        dir.path(),
    );
    let id: u64 = String::from_utf8_lossy(&o.stdout).trim().parse().unwrap();
    assert!(
        std::fs::read(&farm).unwrap() == std::fs::read(&local).unwrap(),
        "the image through the relay differs from the local render's"
    );
    // Only the relay leased from the coordinator, and it sent whole batches of several passes.
    let status = get(&format!("{url}/api/jobs/{id}"));
    let workers = get(&format!("{url}/api/workers"));
    let names: Vec<&str> = workers["workers"]
        .as_array()
        .unwrap()
        .iter()
        .map(|w| w["name"].as_str().unwrap())
        .collect();
    assert_eq!(names, ["relay-a"], "{workers}");
    assert!(status["batches_received"].as_u64().unwrap() < 24, "{status}");
    // The odd passes came through: the noise estimate kept tracking.
    let noise = get(&format!("{url}/api/jobs/{id}/noise"));
    assert_eq!(noise["tracking"], true, "{noise}");
    assert!(!noise["points"].as_array().unwrap().is_empty(), "{noise}");
}
