//! Farm scaling on loopback: `cargo build --release -p worker && cargo bench -p coordinator --bench farm`.
//!
//! Renders the same SPPM job (cbox-spheres, 256×256, 200,000 photons per iteration, 96 iterations
//! unless `FARM_BENCH_ITERATIONS` says otherwise) once with
//! one worker of one thread and once with two such workers, through a real coordinator process
//! and real worker processes, and prints iterations per second of each, their ratio, and the
//! bytes sent per iteration. Rates are taken from the job's own status (iterations over the time
//! from the first lease to the last result).

#[path = "../tests/support/mod.rs"]
mod support;

use std::path::Path;
use std::process::{Command, Stdio};

/// Iterations of the job: 96 by default (about 28 s on one thread of the 2-core CI machine);
/// `FARM_BENCH_ITERATIONS=27` makes the 8 s job whose last batch guided self-scheduling shares.
fn iterations() -> String {
    std::env::var("FARM_BENCH_ITERATIONS").unwrap_or_else(|_| "96".into())
}

fn run(workers: usize, dir: &Path) -> serde_json::Value {
    let coordinator = support::coordinator_bin();
    let data = dir.join(format!("data-{workers}"));
    let (_serve, url) = support::serve(&data, "127.0.0.1:0", &["--batch-seconds", "2"], &[]);
    let _workers: Vec<support::Proc> = (0..workers)
        .map(|i| support::worker(&url, &format!("w{i}"), &dir.join(format!("cache-{workers}"))))
        .collect();
    let scene = support::cbox_spheres();
    let out = Command::new(&coordinator)
        .args([
            "submit",
            "--to",
            &url,
            scene.to_str().unwrap(),
            "--integrator",
            "sppm",
        ])
        .args([
            "--iterations",
            &iterations(),
            "--photons",
            "200000",
            "--checkpoint-every",
            &iterations(),
            "--wait",
        ])
        .stderr(Stdio::null())
        .output()
        .unwrap();
    assert!(out.status.success());
    let id = String::from_utf8_lossy(&out.stdout).trim().to_string();
    let rt = tokio::runtime::Builder::new_current_thread()
        .enable_all()
        .build()
        .unwrap();
    rt.block_on(async {
        let s: serde_json::Value = reqwest::get(format!("{url}/api/jobs/{id}"))
            .await
            .unwrap()
            .json()
            .await
            .unwrap();
        s
    })
}

fn main() {
    let dir = tempfile::tempdir().unwrap();
    let one = run(1, dir.path());
    let two = run(2, dir.path());
    let rate = |s: &serde_json::Value| s["rate"].as_f64().unwrap();
    for (n, s) in [(1, &one), (2, &two)] {
        println!(
            "{n} worker(s) x 1 thread: {:.2} iterations/s ({} iterations in {:.1} s, {} batches, {:.0} bytes per iteration)",
            rate(s),
            s["iterations_done"],
            s["elapsed_seconds"].as_f64().unwrap(),
            s["batches_received"],
            s["bytes_received"].as_f64().unwrap() / s["iterations_done"].as_f64().unwrap()
        );
    }
    println!("scaling, 2 workers over 1: {:.2}x", rate(&two) / rate(&one));
}
