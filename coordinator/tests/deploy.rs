//! The batch-system files in deploy/: the Slurm array script is valid bash and really starts a
//! worker that reaches the coordinator (run here with the variables a Slurm task gets), and the
//! KEDA trigger's query and the worker Deployment's CPU limit are what the coordinator and the
//! worker understand.

mod support;

use std::path::{Path, PathBuf};
use std::process::Command;
use std::time::{Duration, Instant};

use serde_json::Value;

fn repo(path: &str) -> PathBuf {
    Path::new(env!("CARGO_MANIFEST_DIR")).join("..").join(path)
}

fn text(url: &str) -> String {
    let rt = tokio::runtime::Builder::new_current_thread()
        .enable_all()
        .build()
        .unwrap();
    rt.block_on(async { reqwest::get(url).await.unwrap().text().await.unwrap() })
}

#[test]
fn the_slurm_array_script_starts_a_worker_that_reaches_the_coordinator() {
    let script = repo("deploy/slurm-workers.sbatch");
    let syntax = Command::new("bash").arg("-n").arg(&script).output().unwrap();
    assert!(
        syntax.status.success(),
        "{}",
        String::from_utf8_lossy(&syntax.stderr)
    );
    let body = std::fs::read_to_string(&script).unwrap();
    assert!(body.contains("#SBATCH --array="), "no job array");

    let dir = tempfile::tempdir().unwrap();
    let (_serve, url) = support::serve(
        &dir.path().join("data"),
        "127.0.0.1:0",
        &[],
        &[("PHOTONFARM_TOKEN", "t0k")],
    );
    // As Slurm runs it: the task's variables, the token in the environment.
    let mut task = support::Proc(
        Command::new("bash")
            .arg(&script)
            .env("PHOTONFARM_COORDINATOR", &url)
            .env("PHOTONFARM_TOKEN", "t0k")
            .env("PHOTONFARM_WORKER", support::worker_bin())
            .env("SLURM_ARRAY_JOB_ID", "77")
            .env("SLURM_ARRAY_TASK_ID", "3")
            .env("SLURM_CPUS_PER_TASK", "1")
            .env("SLURM_TMPDIR", dir.path())
            .stdout(std::process::Stdio::null())
            .stderr(std::process::Stdio::null())
            .spawn()
            .unwrap(),
    );
    // The worker asks for work under the script's name: its command line parsed, and the
    // token from the environment was accepted.
    let start = Instant::now();
    let rt = tokio::runtime::Builder::new_current_thread()
        .enable_all()
        .build()
        .unwrap();
    let names = loop {
        let v: Value = rt.block_on(support::get_json(&url, "/api/workers", "t0k"));
        let names: Vec<String> = v["workers"]
            .as_array()
            .unwrap()
            .iter()
            .map(|w| w["name"].as_str().unwrap().to_string())
            .collect();
        if !names.is_empty() || start.elapsed() > Duration::from_secs(20) {
            break names;
        }
        std::thread::sleep(Duration::from_millis(100));
    };
    assert_eq!(names.len(), 1, "{names:?}");
    assert!(names[0].starts_with("slurm-77-3-"), "{names:?}");
    assert!(task.0.try_wait().unwrap().is_none(), "the worker exited");
    // Without the coordinator's address the script stops with a message, not a worker.
    let o = Command::new("bash")
        .arg(&script)
        .env_remove("PHOTONFARM_COORDINATOR")
        .env("PHOTONFARM_TOKEN", "x")
        .output()
        .unwrap();
    assert!(!o.status.success());
    assert!(String::from_utf8_lossy(&o.stderr).contains("PHOTONFARM_COORDINATOR"));
}

#[test]
fn keda_scales_on_a_metric_the_coordinator_exports_and_workers_have_cpu_limits() {
    let keda = std::fs::read_to_string(repo("deploy/keda.yaml")).unwrap();
    let query = keda
        .lines()
        .find_map(|l| l.trim().strip_prefix("query:"))
        .expect("a query in deploy/keda.yaml")
        .trim()
        .to_string();
    let dir = tempfile::tempdir().unwrap();
    let (_serve, url) = support::serve(&dir.path().join("data"), "127.0.0.1:0", &[], &[]);
    let metrics = text(&format!("{url}/metrics"));
    assert!(
        metrics.lines().any(|l| l.starts_with(&format!("{query} "))),
        "/metrics has no sample of {query}:\n{metrics}"
    );
    let manifest = std::fs::read_to_string(repo("deploy/photonfarm.yaml")).unwrap();
    let worker = &manifest[manifest
        .find("name: photonfarm-worker")
        .expect("the worker Deployment")..];
    assert!(
        worker.contains("limits: {cpu:"),
        "the worker Deployment has no CPU limit"
    );
    assert!(
        worker.contains("requests: {cpu:"),
        "the worker Deployment has no CPU request"
    );
}
