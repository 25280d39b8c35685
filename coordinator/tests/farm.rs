//! The farm as users run it: a real `coordinator serve` process, real `worker` processes on
//! 127.0.0.1, real HTTP, a real SQLite database and files. Each test checks the farm's image
//! bytes against `coordinator render` with the same settings.

mod support;

use std::path::Path;
use std::process::Command;
use std::time::{Duration, Instant};

use serde_json::Value;
use support::{cbox_spheres as scene, coordinator_bin, worker};

fn serve(data: &Path, bind: &str, extra: &[&str]) -> (support::Proc, String) {
    support::serve(data, bind, extra, &[])
}

/// The job of these tests: SPPM on cbox-spheres, small enough for CI.
const JOB: &[&str] = &[
    "--integrator",
    "sppm",
    "--iterations",
    "40",
    "--photons",
    "120000",
    "--seed",
    "3",
    "--checkpoint-every",
    "16",
    "-D",
    "res=48",
    // Mitsuba's default filter: every sample splats into its neighbours and every pixel keeps
    // its weight, which the farm must merge as exactly as the sums.
    "-D",
    "filter=gaussian",
];

fn local_render(dir: &Path, job: &[&str]) -> Vec<u8> {
    local_render_of(dir, &scene(), job, &[])
}

/// `coordinator render` of `scene` with `job`'s flags and extra environment.
fn local_render_of(dir: &Path, scene: &Path, job: &[&str], env: &[(&str, &str)]) -> Vec<u8> {
    let out = dir.join("local.exr");
    let o = Command::new(coordinator_bin())
        .args(["render", scene.to_str().unwrap(), "--out", out.to_str().unwrap()])
        .args(job)
        .envs(env.iter().copied())
        .output()
        .unwrap();
    assert!(o.status.success(), "{}", String::from_utf8_lossy(&o.stderr));
    std::fs::read(out).unwrap()
}

fn submit(url: &str, job: &[&str]) -> u64 {
    submit_of(url, &scene(), job)
}

fn submit_of(url: &str, scene: &Path, job: &[&str]) -> u64 {
    let o = Command::new(coordinator_bin())
        .args(["submit", "--to", url, scene.to_str().unwrap()])
        .args(job)
        .output()
        .unwrap();
    assert!(o.status.success(), "{}", String::from_utf8_lossy(&o.stderr));
    String::from_utf8_lossy(&o.stdout).trim().parse().unwrap()
}

fn status(url: &str, id: u64) -> Option<Value> {
    let v = get(url, &format!("/api/jobs/{id}"));
    (!v.is_null()).then_some(v)
}

/// `GET url + path` as JSON (null if it fails).
fn get(url: &str, path: &str) -> Value {
    let rt = tokio::runtime::Builder::new_current_thread()
        .enable_all()
        .build()
        .unwrap();
    rt.block_on(async {
        let Ok(r) = reqwest::get(format!("{url}{path}")).await else {
            return Value::Null;
        };
        r.json().await.unwrap_or(Value::Null)
    })
}

fn wait_until(what: &str, timeout: Duration, mut f: impl FnMut() -> bool) {
    let start = Instant::now();
    while !f() {
        assert!(start.elapsed() < timeout, "timed out waiting for {what}");
        std::thread::sleep(Duration::from_millis(50));
    }
}

fn wait_done(url: &str, id: u64) -> Value {
    let mut last = Value::Null;
    wait_until("the job to finish", Duration::from_secs(240), || {
        last = status(url, id).unwrap_or(Value::Null);
        matches!(last["state"].as_str(), Some("done" | "failed" | "cancelled"))
    });
    assert_eq!(last["state"], "done", "{last}");
    last
}

fn image(url: &str, id: u64) -> Vec<u8> {
    let rt = tokio::runtime::Builder::new_current_thread()
        .enable_all()
        .build()
        .unwrap();
    rt.block_on(async {
        let r = reqwest::get(format!("{url}/api/jobs/{id}/image.exr"))
            .await
            .unwrap();
        assert!(r.status().is_success());
        r.bytes().await.unwrap().to_vec()
    })
}

/// Renders `job` on a coordinator with two workers, batches of `batch_seconds`: the job's final
/// status, and whether its image has the bytes of `coordinator render` with the same settings.
fn two_workers_render(job: &[&str], batch_seconds: &str) -> (Value, bool) {
    let dir = tempfile::tempdir().unwrap();
    let (_coordinator, url) = serve(
        &dir.path().join("data"),
        "127.0.0.1:0",
        &["--batch-seconds", batch_seconds],
    );
    let _w1 = worker(&url, "w1", dir.path());
    let _w2 = worker(&url, "w2", dir.path());
    let id = submit(&url, job);
    let s = wait_done(&url, id);
    let same = image(&url, id) == local_render(dir.path(), job);
    (s, same)
}

#[test]
fn two_workers_give_the_bytes_of_a_local_render() {
    let (s, same) = two_workers_render(JOB, "0.2");
    assert_eq!(s["iterations_done"], 40);
    assert_eq!(s["checkpoint_iterations"], 40);
    assert!(same, "farm and local bytes differ");
}

/// A path-tracing job on the Cornell box, which runs on the lane engine, rendered by two
/// workers pinned to different instruction sets (`PHOTONFARM_SIMD`), gives the bytes of a
/// local render on a third (or the first, on a machine with two).
#[test]
fn workers_on_different_simd_backends_give_the_local_bytes() {
    let available = photonfarm::engine::Backend::available();
    let pick = |i: usize| available[i.min(available.len() - 1)].name();
    let dir = tempfile::tempdir().unwrap();
    let cbox = Path::new(env!("CARGO_MANIFEST_DIR")).join("../tests/refs/cbox.xml");
    let job = ["--spp", "128", "--seed", "9", "-D", "res=64"];
    let (_coordinator, url) = serve(
        &dir.path().join("data"),
        "127.0.0.1:0",
        &["--batch-seconds", "0.05"],
    );
    let _w1 = support::worker_with_env(&url, "w1", dir.path(), &[("PHOTONFARM_SIMD", pick(0))]);
    let _w2 = support::worker_with_env(&url, "w2", dir.path(), &[("PHOTONFARM_SIMD", pick(1))]);
    let batches = |name: &str| {
        let w = get(&url, "/api/workers");
        w["workers"]
            .as_array()
            .and_then(|ws| ws.iter().find(|x| x["name"] == name))
            .map(|x| x["batches"].clone())
    };
    wait_until("both workers to ask for work", Duration::from_secs(30), || {
        batches("w1").is_some() && batches("w2").is_some()
    });
    let id = submit_of(&url, &cbox, &job);
    let s = wait_done(&url, id);
    assert_eq!(s["iterations_done"], 128, "{s}");
    for name in ["w1", "w2"] {
        let n = batches(name).and_then(|b| b.as_u64()).unwrap_or(0);
        assert!(
            n >= 1,
            "{name} rendered no batch: the test would compare one backend only"
        );
    }
    let local = local_render_of(dir.path(), &cbox, &job, &[("PHOTONFARM_SIMD", pick(2))]);
    assert!(image(&url, id) == local, "farm and local bytes differ");
}

/// Jobs of the particle tracer and of the hybrid method (cbox-spheres' glass gives it caustic
/// light paths): their light paths land anywhere on the film, and the farm's sums must still
/// merge to the local bytes.
#[test]
fn light_path_jobs_give_the_bytes_of_a_local_render() {
    for method in ["ptracer", "hybrid"] {
        let job = [
            "--integrator",
            method,
            "--spp",
            "24",
            "--seed",
            "5",
            "-D",
            "res=48",
            "-D",
            "filter=gaussian",
        ];
        let (s, same) = two_workers_render(&job, "0.05");
        assert_eq!(s["integrator"], method);
        assert_eq!(s["iterations_done"], 24);
        assert!(same, "{method}: farm and local bytes differ");
    }
}

/// A worker whose disk cannot keep its finished batches (full, say) sends them from memory:
/// it used to give each batch up as failed, and so fail the job. Here every name the outbox
/// writes through (`CACHE/results/LEASE.partial`) is taken by a folder.
#[test]
fn a_worker_whose_disk_cannot_keep_results_still_delivers_them() {
    let dir = tempfile::tempdir().unwrap();
    let (_coordinator, url) = serve(
        &dir.path().join("data"),
        "127.0.0.1:0",
        &["--batch-seconds", "0.2"],
    );
    for lease in 1..=400 {
        std::fs::create_dir_all(dir.path().join(format!("w/results/{lease}.partial"))).unwrap();
    }
    let _w = worker(&url, "w", dir.path());
    let id = submit(&url, JOB);
    let s = wait_done(&url, id);
    assert_eq!(s["iterations_done"], 40, "{s}");
    assert!(image(&url, id) == local_render(dir.path(), JOB), "bytes differ");
}

#[test]
fn a_worker_killed_mid_batch_loses_nothing() {
    let dir = tempfile::tempdir().unwrap();
    let (_coordinator, url) = serve(
        &dir.path().join("data"),
        "127.0.0.1:0",
        &["--batch-seconds", "2", "--lease-timeout", "1"],
    );
    let mut victim = worker(&url, "victim", dir.path());
    let id = submit(&url, JOB);
    // Its first batch is one pass (to measure it); kill it inside a later, larger one.
    wait_until(
        "the victim to hold a second batch",
        Duration::from_secs(60),
        || {
            status(&url, id).is_some_and(|s| {
                s["iterations_done"].as_u64().unwrap_or(0) >= 1
                    && s["workers"] == serde_json::json!(["victim"])
            })
        },
    );
    victim.sigkill();
    let done_at_kill = status(&url, id).unwrap()["iterations_done"].as_u64().unwrap();
    assert!(done_at_kill < 40, "the victim finished before it could be killed");
    let _rescuer = worker(&url, "rescuer", dir.path());
    let s = wait_done(&url, id);
    assert_eq!(s["iterations_done"], 40, "exactly the requested iterations: {s}");
    assert!(
        image(&url, id) == local_render(dir.path(), JOB),
        "bytes differ after a worker was killed"
    );
}

#[test]
fn a_restarted_coordinator_resumes_the_job() {
    let dir = tempfile::tempdir().unwrap();
    let data = dir.path().join("data");
    // A fixed port, so the worker finds the coordinator again after the restart.
    let bind = support::fixed_loopback_address();
    let flags = ["--batch-seconds", "0.3", "--lease-timeout", "2"];
    let (mut coordinator, url) = serve(&data, &bind, &flags);
    let _w = worker(&url, "w", dir.path());
    let id = submit(&url, JOB);
    wait_until("some passes to arrive", Duration::from_secs(60), || {
        status(&url, id).is_some_and(|s| s["iterations_done"].as_u64().unwrap_or(0) >= 17)
    });
    let seen = status(&url, id).unwrap();
    let before = seen["iterations_done"].as_u64().unwrap();
    coordinator.sigkill();
    assert!(
        before < 40,
        "the job finished before the coordinator could be killed"
    );
    let (_coordinator, url2) = serve(&data, &bind, &flags);
    assert_eq!(url, url2);
    let after = status(&url, id).unwrap();
    assert!(
        after["iterations_done"].as_u64().unwrap() >= before,
        "reported passes were lost: {after}"
    );
    // The job's counters go on from where they were, not from zero.
    assert!(
        after["batches_received"].as_u64() >= seen["batches_received"].as_u64()
            && seen["batches_received"].as_u64() > Some(0),
        "batch count reset: {seen} then {after}"
    );
    assert!(
        after["elapsed_seconds"].as_f64().unwrap() + 1.0 >= seen["elapsed_seconds"].as_f64().unwrap(),
        "elapsed time reset: {seen} then {after}"
    );
    let s = wait_done(&url, id);
    assert_eq!(s["iterations_done"], 40, "{s}");
    assert!(
        image(&url, id) == local_render(dir.path(), JOB),
        "bytes differ after a restart"
    );
}

/// A worker that finishes its batch while the coordinator is down (killed, back 10 s later)
/// keeps the result on disk, sends it again until the restarted coordinator answers, and the
/// coordinator, which kept the lease, accepts it: nothing is rendered twice and the bytes are
/// those of a local render.
#[test]
fn a_batch_finished_while_the_coordinator_is_down_is_delivered_after_its_restart() {
    let dir = tempfile::tempdir().unwrap();
    let data = dir.path().join("data");
    let bind = support::fixed_loopback_address();
    // The lease outlives the outage however long the batch takes: the kept batch must be
    // accepted, not handed to another worker.
    let flags = ["--batch-seconds", "3", "--lease-timeout", "120"];
    let (mut coordinator, url) = serve(&data, &bind, &flags);
    let log = dir.path().join("worker.log");
    let _w = support::Proc(
        Command::new(support::worker_bin())
            .args(["--coordinator", &url, "--threads", "1", "--name", "w", "--cache"])
            .arg(dir.path().join("cache"))
            .env("RUST_LOG", "info")
            .stdout(std::process::Stdio::null())
            .stderr(std::fs::File::create(&log).unwrap())
            .spawn()
            .unwrap(),
    );
    let id = submit(&url, JOB);
    // Its first batch is one pass (to measure it); the second takes about 3 s.
    wait_until(
        "the worker to hold its second batch",
        Duration::from_secs(60),
        || {
            status(&url, id).is_some_and(|s| {
                s["iterations_done"].as_u64().unwrap_or(0) >= 1 && s["workers"] == serde_json::json!(["w"])
            })
        },
    );
    coordinator.sigkill();
    let down = Instant::now();
    let results = dir.path().join("cache/results");
    let kept = || {
        std::fs::read_dir(&results)
            .map(|d| {
                d.flatten()
                    .any(|e| e.path().extension().is_some_and(|x| x == "batch"))
            })
            .unwrap_or(false)
    };
    // About 3 s alone; the file's other tests render beside it on the same two cores, and their
    // load can stretch it several times over (9 s was once too short in CI).
    wait_until(
        "the batch to finish while the coordinator is down",
        Duration::from_secs(60),
        kept,
    );
    std::thread::sleep(Duration::from_secs(10).saturating_sub(down.elapsed()));
    let (_coordinator, _) = serve(&data, &bind, &flags);
    wait_until("the kept batch to be delivered", Duration::from_secs(15), || {
        !kept()
    });
    let s = wait_done(&url, id);
    assert_eq!(s["iterations_done"], 40, "{s}");
    let log = std::fs::read_to_string(&log).unwrap();
    assert!(log.contains("cannot reach the coordinator"), "{log}");
    assert!(log.contains("answers again"), "{log}");
    assert!(
        !log.contains("result refused"),
        "the kept batch was refused: {log}"
    );
    assert!(
        image(&url, id) == local_render(dir.path(), JOB),
        "bytes differ after a batch was delivered across a restart"
    );
}

/// SIGTERM: the worker finishes the batch under way, delivers it, and exits cleanly.
#[test]
fn a_worker_stopped_with_sigterm_delivers_its_batch_and_exits() {
    let dir = tempfile::tempdir().unwrap();
    let (_coordinator, url) = serve(&dir.path().join("data"), "127.0.0.1:0", &["--batch-seconds", "1"]);
    let mut w = worker(&url, "polite", dir.path());
    let id = submit(&url, JOB);
    wait_until("the worker to hold a batch", Duration::from_secs(60), || {
        status(&url, id).is_some_and(|s| {
            s["iterations_done"].as_u64().unwrap_or(0) >= 1 && s["workers"] == serde_json::json!(["polite"])
        })
    });
    let before = status(&url, id).unwrap()["iterations_done"].as_u64().unwrap();
    let pid = w.0.id().to_string();
    assert!(
        Command::new("kill")
            .args(["-TERM", &pid])
            .status()
            .unwrap()
            .success()
    );
    let start = Instant::now();
    let exit = loop {
        if let Some(e) = w.0.try_wait().unwrap() {
            break e;
        }
        assert!(
            start.elapsed() < Duration::from_secs(60),
            "the worker did not exit after SIGTERM"
        );
        std::thread::sleep(Duration::from_millis(20));
    };
    assert!(exit.success(), "SIGTERM is a clean exit: {exit:?}");
    let after = status(&url, id).unwrap();
    assert!(
        after["iterations_done"].as_u64().unwrap() > before,
        "the batch under way was delivered: {before} then {after}"
    );
    assert_eq!(after["workers"], serde_json::json!([]), "no lease left behind");
}

/// A Mitsuba documentation scene that reads its meshes through `<path value="../../common"/>`:
/// `submit` packs it with every file it reads under their common folder, the coordinator and the
/// worker load it confined to that bundle, and the farm gives the bytes of a local render.
#[test]
fn a_scene_reading_outside_its_folder_submits_and_gives_the_local_bytes() {
    let dir = tempfile::tempdir().unwrap();
    let (_coordinator, url) = serve(
        &dir.path().join("data"),
        "127.0.0.1:0",
        &["--batch-seconds", "0.2"],
    );
    let _w = worker(&url, "w1", dir.path());
    let scene = Path::new(env!("CARGO_MANIFEST_DIR"))
        .join("../tests/refs/mitsuba-data/docs/scenes/integrator_depth_3.xml");
    let job = ["--spp", "6", "--seed", "5", "-D", "width=24", "-D", "height=16"];
    let out = dir.path().join("depth.exr");
    let o = Command::new(coordinator_bin())
        .args(["render", scene.to_str().unwrap(), "--out", out.to_str().unwrap()])
        .args(job)
        .output()
        .unwrap();
    assert!(o.status.success(), "{}", String::from_utf8_lossy(&o.stderr));
    let o = Command::new(coordinator_bin())
        .args(["submit", "--to", &url, scene.to_str().unwrap()])
        .args(job)
        .output()
        .unwrap();
    assert!(o.status.success(), "{}", String::from_utf8_lossy(&o.stderr));
    let id: u64 = String::from_utf8_lossy(&o.stdout).trim().parse().unwrap();
    wait_done(&url, id);
    assert!(
        image(&url, id) == std::fs::read(out).unwrap(),
        "farm and local bytes differ"
    );
}

/// Issue 28: a 6-frame sequence (ramped `-D`, the scene's camera and a sphere moving) on two
/// workers, its coordinator SIGKILLed once some frames are done and restarted: every frame
/// fetched has the bytes of the same frame of `coordinator render --frames`, and frames
/// finish in order.
#[test]
fn a_sequence_survives_a_sigkill_and_gives_the_frames_of_render_frames() {
    let dir = tempfile::tempdir().unwrap();
    let data = dir.path().join("data");
    let bind = support::fixed_loopback_address();
    let flags = ["--batch-seconds", "0.3", "--lease-timeout", "2"];
    let (mut coordinator, url) = serve(&data, &bind, &flags);
    let _w: Vec<_> = (0..2)
        .map(|i| worker(&url, &format!("w{i}"), &dir.path().join(format!("c{i}"))))
        .collect();
    let scene = Path::new(env!("CARGO_MANIFEST_DIR")).join("../scenes/turntable.xml");
    let job: &[&str] = &[
        "--frames",
        "1-6",
        "-D",
        "angle=-20:20",
        "-D",
        "roll=-0.5:0.4",
        "-D",
        "res=32",
        "--spp",
        "300",
        "--seed",
        "2",
        "--checkpoint-every",
        "100",
    ];
    let id = submit_of(&url, &scene, job);
    let frames_done = |s: &Value| -> Vec<u64> {
        s["frames"]
            .as_array()
            .unwrap()
            .iter()
            .filter(|f| f["state"] == "done")
            .map(|f| f["frame"].as_u64().unwrap())
            .collect()
    };
    wait_until("two frames to finish", Duration::from_secs(120), || {
        status(&url, id).is_some_and(|s| frames_done(&s).len() >= 2)
    });
    let seen = status(&url, id).unwrap();
    coordinator.sigkill();
    let done = frames_done(&seen);
    assert!(
        done.len() < 6,
        "the sequence finished before the coordinator could be killed"
    );
    // In order: the first frames are the ones done.
    assert_eq!(done, (1..=done.len() as u64).collect::<Vec<_>>(), "{seen}");
    let (_coordinator, again) = serve(&data, &bind, &flags);
    assert_eq!(url, again);
    let s = wait_done(&url, id);
    assert_eq!(s["frames"].as_array().unwrap().len(), 6, "{s}");
    assert_eq!(s["iterations_done"], 1800, "{s}");
    let metrics = tokio::runtime::Builder::new_current_thread()
        .enable_all()
        .build()
        .unwrap()
        .block_on(async {
            reqwest::get(format!("{url}/metrics"))
                .await
                .unwrap()
                .text()
                .await
                .unwrap()
        });
    assert!(
        metrics.contains("photonfarm_frames{state=\"done\"} 6"),
        "{metrics}"
    );
    assert!(metrics.contains("photonfarm_jobs{state=\"done\"} 1"), "{metrics}");
    let out = dir.path().join("farm-#.exr");
    let o = Command::new(coordinator_bin())
        .args([
            "fetch",
            "--to",
            &url,
            &id.to_string(),
            "--out",
            out.to_str().unwrap(),
        ])
        .output()
        .unwrap();
    assert!(o.status.success(), "{}", String::from_utf8_lossy(&o.stderr));
    let local = dir.path().join("local-#.exr");
    let o = Command::new(coordinator_bin())
        .args([
            "render",
            scene.to_str().unwrap(),
            "--out",
            local.to_str().unwrap(),
        ])
        .args(job)
        .output()
        .unwrap();
    assert!(o.status.success(), "{}", String::from_utf8_lossy(&o.stderr));
    for f in 1..=6 {
        let farm = std::fs::read(dir.path().join(format!("farm-{f}.exr"))).unwrap();
        let here = std::fs::read(dir.path().join(format!("local-{f}.exr"))).unwrap();
        assert!(farm == here, "frame {f} differs from coordinator render --frames");
    }

    // Several scene files submitted together: a sequence of one frame each, in one bundle.
    let text = std::fs::read_to_string(&scene).unwrap();
    let files: Vec<String> = [0.3, 0.0, -0.3]
        .iter()
        .enumerate()
        .map(|(i, x)| {
            let path = dir.path().join(format!("shot{i}.xml"));
            let moved = text.replace(
                r#"name="roll" value="0.42""#,
                &format!(r#"name="roll" value="{x}""#),
            );
            assert!(moved != text, "the scene no longer declares roll=0.42");
            std::fs::write(&path, moved).unwrap();
            path.to_string_lossy().into_owned()
        })
        .collect();
    let flags = ["-D", "res=24", "--spp", "16", "--seed", "5"];
    let render = |command: &[&str], out: &str| {
        let out = dir.path().join(out);
        let o = Command::new(coordinator_bin())
            .args(command)
            .args(&files)
            .args(flags)
            .args(["--out", out.to_str().unwrap()])
            .output()
            .unwrap();
        assert!(o.status.success(), "{}", String::from_utf8_lossy(&o.stderr));
    };
    render(&["submit", "--to", &url, "--wait"], "files-farm-#.exr");
    render(&["render"], "files-local-#.exr");
    let read = |name: String| std::fs::read(dir.path().join(name)).unwrap();
    for f in 1..=3 {
        let farm = read(format!("files-farm-{f}.exr"));
        assert!(
            farm == read(format!("files-local-{f}.exr")),
            "file frame {f} differs"
        );
        if f > 1 {
            assert!(
                farm != read(format!("files-farm-{}.exr", f - 1)),
                "frames {f} and {} are one",
                f - 1
            );
        }
    }
}
