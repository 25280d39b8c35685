//! Issue 11: the farm never goes down. Each defect of the issue, reproduced against a real
//! `coordinator serve` over loopback: it now gets a 4xx naming the limit, the coordinator
//! keeps serving, and it restarts cleanly.

mod support;

use std::path::Path;
use std::time::{Duration, Instant};

use reqwest::StatusCode;
use reqwest::multipart::{Form, Part};
use serde_json::Value;

use support::api::*;

fn error_of(v: &Value) -> &str {
    v["error"]
        .as_str()
        .unwrap_or_else(|| panic!("not a JSON error: {v}"))
}

/// A scene that takes about `seconds` to load: rough plastics, each tabulating its coating's
/// albedo when loaded, as many as this machine needs (measured here, so the test holds
/// whatever the cost of one).
fn slow_scene(seconds: f64) -> Vec<u8> {
    let with = |n: usize| -> String {
        let bsdfs: String = (0..n)
            .map(|i| {
                format!(
                    r#"<bsdf type="roughplastic" id="p{i}"><string name="distribution" value="ggx"/><float name="alpha" value="0.{}"/></bsdf>"#,
                    100 + i % 800
                )
            })
            .collect();
        String::from_utf8(scene("", 8, 8))
            .unwrap()
            .replacen("<sensor", &format!("{bsdfs}<sensor"), 1)
    };
    let time = |n: usize| {
        let text = with(n);
        let start = Instant::now();
        photonfarm::scene::Scene::from_str(&text, Path::new("probe.xml"), &[]).unwrap();
        start.elapsed().as_secs_f64()
    };
    // The difference of two loads leaves out what every scene costs.
    let each = (time(40) - time(10)) / 30.0;
    let n = ((seconds / each.max(1e-6)) as usize).clamp(40, 100_000);
    with(n).into_bytes()
}

/// Asserts a refusal with `status` whose message contains `needle`.
fn refused(got: (StatusCode, Value), status: StatusCode, needle: &str) {
    assert_eq!(got.0, status, "{}", got.1);
    assert!(error_of(&got.1).contains(needle), "{}", got.1);
}

#[tokio::test(flavor = "multi_thread")]
async fn every_size_is_admitted_or_refused_with_a_4xx_and_the_coordinator_survives_restarts() {
    let dir = tempfile::tempdir().unwrap();
    let data = dir.path().join("data");
    let flags = [
        "--max-geometry-mb",
        "1",
        "--max-bundle-files",
        "20",
        "--max-upload-mb",
        "8",
    ];
    let (mut coordinator, url) = serve(&data, "127.0.0.1:0", &flags);
    let api = Api::new(&url);
    let unprocessable = StatusCode::UNPROCESSABLE_ENTITY;

    // Critical: a 65536×65536 film (an allowed size for the parser) used to abort the
    // coordinator allocating 103 GB; the job was stored first, so every restart aborted too.
    let big = tar_of(&[("s.xml", &scene("", 65536, 65536))]);
    refused(api.submit(big, "{}").await, unprocessable, "--max-pixels");
    // SPPM passes 1e12 (the radius schedule was 8 B per pass) and photons 1e12.
    let small = tar_of(&[("s.xml", &scene("", 8, 8))]);
    refused(
        api.submit(
            small.clone(),
            r#"{"integrator": "sppm", "passes": 1000000000000}"#,
        )
        .await,
        unprocessable,
        "--max-passes",
    );
    refused(
        api.submit(
            small.clone(),
            r#"{"integrator": "sppm", "photons": 1000000000000}"#,
        )
        .await,
        unprocessable,
        "--max-photons",
    );
    // A scene-declared iteration count of 1e9, 0 and -5.
    for (value, needle) in [
        ("1000000000", "--max-passes"),
        ("0", "positive integer"),
        ("-5", "positive integer"),
    ] {
        let integrator =
            format!(r#"<integrator type="sppm"><integer name="iterations" value="{value}"/></integrator>"#);
        let b = tar_of(&[("s.xml", &scene(&integrator, 8, 8))]);
        refused(
            api.submit(b, r#"{"integrator": "sppm"}"#).await,
            unprocessable,
            needle,
        );
    }
    // XML nested 5000 deep (35 KB) overflowed the stack.
    let deep = format!(
        "<scene version=\"3.0.0\">{}{}</scene>",
        "<shape>".repeat(5000),
        "</shape>".repeat(5000)
    );
    refused(
        api.submit(tar_of(&[("s.xml", deep.as_bytes())]), "{}").await,
        unprocessable,
        "nest deeper",
    );
    // A <default> expansion bomb: a 1 KB scene asking for gigabytes, even unused.
    let mut bomb = String::from(r#"<scene version="3.0.0"><default name="d0" value="xxxxxxxxxxxxxxxx"/>"#);
    for i in 1..40 {
        bomb.push_str(&format!(
            r#"<default name="d{i}" value="$d{}$d{}"/>"#,
            i - 1,
            i - 1
        ));
    }
    bomb.push_str("</scene>");
    refused(
        api.submit(tar_of(&[("s.xml", bomb.as_bytes())]), "{}").await,
        unprocessable,
        "more than",
    );
    // Geometry beyond --max-geometry-mb, refused before the mesh is loaded.
    let obj = "v 0 0 0\nv 1 0 0\nv 0 1 0\nf 1 2 3\n".repeat(60_000);
    let with_mesh = String::from_utf8(scene("", 8, 8)).unwrap().replace(
        "</scene>",
        r#"<shape type="obj"><string name="filename" value="m.obj"/></shape></scene>"#,
    );
    refused(
        api.submit(
            tar_of(&[("s.xml", with_mesh.as_bytes()), ("m.obj", obj.as_bytes())]),
            "{}",
        )
        .await,
        StatusCode::PAYLOAD_TOO_LARGE,
        "--max-geometry-mb",
    );
    // Bundles with too many files.
    let names: Vec<String> = (0..30).map(|i| format!("f{i}.txt")).collect();
    let mut files: Vec<(&str, &[u8])> = names.iter().map(|n| (n.as_str(), &b"x"[..])).collect();
    let s8 = scene("", 8, 8);
    files.push(("s.xml", &s8));
    refused(
        api.submit(tar_of(&files), "{}").await,
        StatusCode::PAYLOAD_TOO_LARGE,
        "files",
    );
    // The settings field escaped the 64 KiB JSON limit; defines are bounded too.
    let huge_settings = format!(r#"{{"defines": [["a", "{}"]]}}"#, "x".repeat(100_000));
    refused(
        api.submit(small.clone(), &huge_settings).await,
        StatusCode::PAYLOAD_TOO_LARGE,
        "settings",
    );
    let many: Vec<String> = (0..300).map(|i| format!(r#"["d{i}", "1"]"#)).collect();
    refused(
        api.submit(small.clone(), &format!(r#"{{"defines": [{}]}}"#, many.join(",")))
            .await,
        unprocessable,
        "defines",
    );

    // A good job; its lease's result is held to the lease's size before it is read (a 429 MB
    // body for a 16×16 job used to be decoded, and kill the coordinator).
    let (s, job) = api.submit(small.clone(), r#"{"passes": 3}"#).await;
    assert_eq!(s, StatusCode::CREATED, "{job}");
    let lease = api.lease("w").await.unwrap();
    let (id, key) = (
        lease["lease_id"].as_u64().unwrap(),
        lease["key"].as_str().unwrap(),
    );
    let result = format!("/api/leases/{id}/result");
    refused(
        api.call(
            reqwest::Method::PUT,
            &result,
            WORKER_TOKEN,
            key,
            // Small enough to be sent whole before the early answer (the limit of an 8×8
            // image's result, its odd-pass sample included, is 5,201 B).
            vec![0; 8 << 10],
        )
        .await,
        StatusCode::PAYLOAD_TOO_LARGE,
        "at most",
    );
    // Workers are not users: the client token cannot lease, the worker token cannot cancel,
    // and a lease can only be used with its secret.
    refused(
        api.call(
            reqwest::Method::POST,
            &format!("/api/leases/{id}/heartbeat"),
            TOKEN,
            key,
            vec![],
        )
        .await,
        StatusCode::UNAUTHORIZED,
        "token",
    );
    let job_path = format!("/api/jobs/{}", job["id"]);
    refused(
        api.call(reqwest::Method::DELETE, &job_path, WORKER_TOKEN, "", vec![])
            .await,
        StatusCode::UNAUTHORIZED,
        "token",
    );
    for path in ["heartbeat", "release"] {
        refused(
            api.call(
                reqwest::Method::POST,
                &format!("/api/leases/{id}/{path}"),
                WORKER_TOKEN,
                "guessed",
                br#"{"error": "made up"}"#.to_vec(),
            )
            .await,
            StatusCode::FORBIDDEN,
            "another worker",
        );
    }
    let (s, v) = api
        .call(
            reqwest::Method::POST,
            &format!("/api/leases/{id}/heartbeat"),
            WORKER_TOKEN,
            key,
            vec![],
        )
        .await;
    assert_eq!(s, StatusCode::OK, "{v}");
    // "bearer" in lower case is the same scheme.
    let r = api
        .http
        .get(format!("{url}/api/jobs"))
        .header("Authorization", format!("bearer {TOKEN}"))
        .send()
        .await
        .unwrap();
    assert_eq!(r.status(), StatusCode::OK);

    // Still serving, and it restarts cleanly (nothing refused was stored).
    let (s, v) = api.get("/api/jobs").await;
    assert_eq!(s, StatusCode::OK);
    assert_eq!(v["jobs"].as_array().unwrap().len(), 1, "{v}");
    coordinator.sigkill();
    let (_coordinator, url) = serve(&data, "127.0.0.1:0", &flags);
    let (s, v) = Api::new(&url).get("/api/jobs").await;
    assert_eq!(s, StatusCode::OK);
    assert_eq!(v["jobs"].as_array().unwrap().len(), 1, "{v}");
    assert_ne!(v["jobs"][0]["state"], "failed", "{v}");
}

/// Job rows and files as an older version, a crash or a disk fault may leave them.
#[tokio::test(flavor = "multi_thread")]
async fn a_job_that_cannot_be_resumed_fails_alone_and_the_coordinator_starts() {
    let dir = tempfile::tempdir().unwrap();
    let data = dir.path().join("data");
    let (mut coordinator, url) = serve(&data, "127.0.0.1:0", &[]);
    let api = Api::new(&url);
    let small = tar_of(&[("s.xml", &scene("", 8, 8))]);
    let mut ids = Vec::new();
    for _ in 0..4 {
        let (s, v) = api.submit(small.clone(), r#"{"passes": 4}"#).await;
        assert_eq!(s, StatusCode::CREATED, "{v}");
        ids.push(v["id"].as_u64().unwrap());
    }
    coordinator.sigkill();
    // Job 1: a damaged prefix. Job 2: a 65536×65536 film and job 3: zero passes, as older
    // versions stored them. Job 4: a damaged batch file, which is dropped and re-rendered.
    std::fs::create_dir_all(data.join(format!("jobs/{}", ids[0]))).unwrap();
    std::fs::write(data.join(format!("jobs/{}/prefix.bin", ids[0])), b"garbage").unwrap();
    std::fs::create_dir_all(data.join(format!("jobs/{}", ids[3]))).unwrap();
    std::fs::write(data.join(format!("jobs/{}/batch-0-2.bin", ids[3])), b"garbage").unwrap();
    {
        let db = rusqlite::Connection::open(data.join("photonfarm.sqlite")).unwrap();
        db.execute(
            "UPDATE jobs SET width = 65536, height = 65536 WHERE id = ?1",
            [ids[1] as i64],
        )
        .unwrap();
        db.execute("UPDATE jobs SET total = 0 WHERE id = ?1", [ids[2] as i64])
            .unwrap();
        db.execute(
            "INSERT INTO batches (job, start, end) VALUES (?1, 0, 2)",
            [ids[3] as i64],
        )
        .unwrap();
        db.execute(
            "UPDATE jobs SET next_start = 2, state = 'running' WHERE id = ?1",
            [ids[3] as i64],
        )
        .unwrap();
    }
    // And a submission a crash interrupted left its scratch folder.
    let scratch = data.join("bundles/incoming-1-0");
    std::fs::create_dir_all(&scratch).unwrap();
    std::fs::write(scratch.join("bundle.tar"), b"partial").unwrap();
    let (_coordinator, url) = serve(&data, "127.0.0.1:0", &[]);
    assert!(!scratch.exists(), "scratch folders are cleared at start");
    let api = Api::new(&url);
    for (id, needle) in [
        (ids[0], "damaged"),
        (ids[1], "--max-pixels"),
        (ids[2], "no passes"),
    ] {
        let (s, v) = api.get(&format!("/api/jobs/{id}")).await;
        assert_eq!(s, StatusCode::OK);
        assert_eq!(v["state"], "failed", "{v}");
        assert!(v["message"].as_str().unwrap().contains(needle), "{v}");
    }
    let (_, v) = api.get(&format!("/api/jobs/{}", ids[3])).await;
    assert_eq!(v["state"], "running", "{v}");
    assert_eq!(v["iterations_done"], 0, "the damaged batch is not counted: {v}");
    // Its passes are handed out again, from the start.
    let lease = api.lease("w").await.unwrap();
    assert_eq!(
        (lease["job_id"].as_u64(), lease["start"].as_u64()),
        (Some(ids[3]), Some(0))
    );
}

/// A lost database used to restart ids at 1, and a new job was reported done with the
/// previous job 1's image.
#[tokio::test(flavor = "multi_thread")]
async fn a_lost_database_never_reuses_ids_or_files() {
    let dir = tempfile::tempdir().unwrap();
    let data = dir.path().join("data");
    let (mut coordinator, url) = serve(&data, "127.0.0.1:0", &[]);
    let api = Api::new(&url);
    let small = tar_of(&[("s.xml", &scene("", 8, 8))]);
    let (_, v) = api.submit(small.clone(), r#"{"passes": 1}"#).await;
    let first = v["id"].as_u64().unwrap();
    // Render it by hand: one pass, one result.
    let lease = api.lease("w").await.unwrap();
    let mut sum = photonfarm::film::FilmSum::new(8, 8);
    sum.passes = 1;
    sum.sums[0] = [1 << 24, 0, 0];
    let (s, v) = api
        .call(
            reqwest::Method::PUT,
            &format!("/api/leases/{}/result", lease["lease_id"]),
            WORKER_TOKEN,
            lease["key"].as_str().unwrap(),
            photonfarm::protocol::encode_batch(&sum),
        )
        .await;
    assert_eq!(s, StatusCode::OK, "{v}");
    let (_, v) = api.get(&format!("/api/jobs/{first}")).await;
    assert_eq!(v["state"], "done", "{v}");
    coordinator.sigkill();
    for f in [
        "photonfarm.sqlite",
        "photonfarm.sqlite-wal",
        "photonfarm.sqlite-shm",
    ] {
        let _ = std::fs::remove_file(data.join(f));
    }
    let (_coordinator, url) = serve(&data, "127.0.0.1:0", &[]);
    let api = Api::new(&url);
    let (s, v) = api.submit(small, r#"{"passes": 1}"#).await;
    assert_eq!(s, StatusCode::CREATED, "{v}");
    let second = v["id"].as_u64().unwrap();
    assert!(second > first, "id {second} reused");
    assert_eq!(v["state"], "queued");
    let (s, _) = api.get(&format!("/api/jobs/{second}/image.exr")).await;
    assert_eq!(s, StatusCode::NOT_FOUND, "a new job has no image");
}

/// `checkpoint_iterations` used to count passes merged but not yet in an image.
#[tokio::test(flavor = "multi_thread")]
async fn checkpoint_iterations_counts_only_passes_in_a_written_image() {
    let dir = tempfile::tempdir().unwrap();
    let (_coordinator, url) = serve(&dir.path().join("data"), "127.0.0.1:0", &[]);
    let api = Api::new(&url);
    let small = tar_of(&[("s.xml", &scene("", 8, 8))]);
    let (_, v) = api.submit(small, r#"{"passes": 4, "checkpoint_every": 2}"#).await;
    let job = v["id"].as_u64().unwrap();
    let mut sum = photonfarm::film::FilmSum::new(8, 8);
    sum.passes = 1;
    let lease = api.lease("w").await.unwrap();
    assert_eq!(
        (lease["start"].as_u64(), lease["end"].as_u64()),
        (Some(0), Some(1))
    );
    let (s, v) = api
        .call(
            reqwest::Method::PUT,
            &format!("/api/leases/{}/result", lease["lease_id"]),
            WORKER_TOKEN,
            lease["key"].as_str().unwrap(),
            photonfarm::protocol::encode_batch(&sum),
        )
        .await;
    assert_eq!(s, StatusCode::OK, "{v}");
    let (_, v) = api.get(&format!("/api/jobs/{job}")).await;
    assert_eq!(v["iterations_done"], 1, "{v}");
    assert_eq!(v["checkpoint_iterations"], 0, "no image has pass 0 alone: {v}");
    let (s, _) = api.get(&format!("/api/jobs/{job}/image.exr")).await;
    assert_eq!(s, StatusCode::NOT_FOUND);
}

/// A batch too large for every worker used to crash each worker that took it, and the job
/// stayed "running" forever. Here the worker refuses it (its own --max-photons) and the job
/// fails with a message saying why.
#[test]
fn a_job_no_worker_can_take_fails_with_a_message() {
    let dir = tempfile::tempdir().unwrap();
    let (_coordinator, url) = support::serve(
        &dir.path().join("data"),
        "127.0.0.1:0",
        &["--max-photons", "1000000000000"],
        &[],
    );
    let rt = tokio::runtime::Runtime::new().unwrap();
    let small = tar_of(&[("s.xml", &scene("", 8, 8))]);
    let form = Form::new()
        .part("bundle", Part::bytes(small).file_name("b.tar"))
        .text(
            "settings",
            r#"{"integrator": "sppm", "passes": 2, "photons": 2000000}"#,
        );
    let job: Value = rt.block_on(async {
        reqwest::Client::new()
            .post(format!("{url}/api/jobs"))
            .multipart(form)
            .send()
            .await
            .unwrap()
            .json()
            .await
            .unwrap()
    });
    let id = job["id"].as_u64().expect("accepted");
    let _w = support::Proc(
        std::process::Command::new(support::worker_bin())
            .args([
                "--coordinator",
                &url,
                "--threads",
                "1",
                "--name",
                "small",
                "--max-photons",
                "1000",
                "--cache",
            ])
            .arg(dir.path().join("cache"))
            .stdout(std::process::Stdio::null())
            .stderr(std::process::Stdio::null())
            .spawn()
            .unwrap(),
    );
    let start = Instant::now();
    let v = loop {
        let v: Value = rt.block_on(async {
            reqwest::get(format!("{url}/api/jobs/{id}"))
                .await
                .unwrap()
                .json()
                .await
                .unwrap()
        });
        if v["state"] != "queued" && v["state"] != "running" {
            break v;
        }
        assert!(start.elapsed() < Duration::from_secs(60), "still {v}");
        std::thread::sleep(Duration::from_millis(100));
    };
    assert_eq!(v["state"], "failed", "{v}");
    let msg = v["message"].as_str().unwrap();
    assert!(
        msg.contains("every available worker (small)") && msg.contains("--max-photons"),
        "{msg}"
    );
}

/// The idle timeout closes silent connections, but not one whose request is being handled:
/// a scene check longer than the timeout still gets its answer.
#[tokio::test(flavor = "multi_thread")]
async fn a_long_scene_check_outlives_the_idle_timeout() {
    let dir = tempfile::tempdir().unwrap();
    let (_coordinator, url) = serve(&dir.path().join("data"), "127.0.0.1:0", &["--idle-timeout", "1"]);
    let api = Api::new(&url);
    let text = slow_scene(3.0);
    let start = Instant::now();
    let (s, v) = api.submit(tar_of(&[("s.xml", &text)]), "{}").await;
    let took = start.elapsed();
    eprintln!("the scene check took {took:?}");
    assert_eq!(s, StatusCode::CREATED, "{v}");
    assert!(
        took > Duration::from_millis(1200),
        "not longer than the timeout: {took:?}"
    );
}

/// A request head trickling in a byte at a time is never idle, but it is slow: it is cut off
/// at --header-timeout, while a keep-alive client that pauses between requests is not.
#[tokio::test(flavor = "multi_thread")]
async fn a_trickling_request_head_is_cut_off() {
    use std::io::{Read, Write};
    let dir = tempfile::tempdir().unwrap();
    let (_coordinator, url) = serve(
        &dir.path().join("data"),
        "127.0.0.1:0",
        &["--header-timeout", "1"],
    );
    let addr = url.strip_prefix("http://").unwrap().to_string();
    let cut_after = tokio::task::spawn_blocking(move || {
        let mut s = std::net::TcpStream::connect(&addr).unwrap();
        s.set_read_timeout(Some(Duration::from_millis(1))).unwrap();
        s.write_all(b"GET /api/jobs HTTP/1.1\r\nX-Slow: ").unwrap();
        let start = Instant::now();
        let mut buf = [0u8; 64];
        while start.elapsed() < Duration::from_secs(10) {
            if s.write_all(b"a").is_err() {
                return start.elapsed();
            }
            match s.read(&mut buf) {
                Ok(0) => return start.elapsed(),
                Err(e) if e.kind() != std::io::ErrorKind::WouldBlock => return start.elapsed(),
                _ => {}
            }
            std::thread::sleep(Duration::from_millis(100));
        }
        start.elapsed()
    })
    .await
    .unwrap();
    assert!(
        cut_after < Duration::from_secs(3),
        "still open after {cut_after:?}"
    );
    // A client pausing between requests on one connection is served throughout.
    let api = Api::new(&url);
    for _ in 0..2 {
        assert_eq!(api.get("/api/jobs").await.0, StatusCode::OK);
        tokio::time::sleep(Duration::from_millis(1500)).await;
    }
}

/// Scene checks run side by side (--max-scene-checks, 2 by default): a small job submitted
/// while a slow scene (about 4 s to load) is checked is created at once. One at a time, it used
/// to wait for the slow one (49.6 s in the probe).
#[tokio::test(flavor = "multi_thread")]
async fn a_slow_scene_check_does_not_hold_up_other_submissions() {
    let dir = tempfile::tempdir().unwrap();
    let (_coordinator, url) = serve(&dir.path().join("data"), "127.0.0.1:0", &[]);
    let slow = {
        let api = Api::new(&url);
        let text = slow_scene(4.0);
        tokio::spawn(async move {
            let (s, v) = api.submit(tar_of(&[("s.xml", &text)]), "{}").await;
            assert_eq!(s, StatusCode::CREATED, "{v}");
            Instant::now()
        })
    };
    tokio::time::sleep(Duration::from_millis(500)).await;
    let api = Api::new(&url);
    let start = Instant::now();
    let (s, v) = api.submit(tar_of(&[("s.xml", &scene("", 8, 8))]), "{}").await;
    let small_done = Instant::now();
    assert_eq!(s, StatusCode::CREATED, "{v}");
    let slow_done = slow.await.unwrap();
    eprintln!(
        "the small job took {:?}; the slow one ended {:?} after it",
        small_done - start,
        slow_done.saturating_duration_since(small_done)
    );
    assert!(small_done < slow_done, "the small job waited for the slow check");
}

/// Loading a scene runs in a child process with a time limit: a scene that takes too long to
/// load (about 3 s of rough plastics for a 1 s limit) is refused, and the coordinator
/// goes on serving.
#[tokio::test(flavor = "multi_thread")]
async fn a_scene_that_loads_too_long_is_refused() {
    let dir = tempfile::tempdir().unwrap();
    let (_coordinator, url) = serve(
        &dir.path().join("data"),
        "127.0.0.1:0",
        &["--scene-check-timeout", "1"],
    );
    let api = Api::new(&url);
    let text = slow_scene(3.0);
    let start = Instant::now();
    refused(
        api.submit(tar_of(&[("s.xml", &text)]), "{}").await,
        StatusCode::UNPROCESSABLE_ENTITY,
        "--scene-check-timeout",
    );
    assert!(start.elapsed() < Duration::from_secs(3), "{:?}", start.elapsed());
    let (s, v) = api.submit(tar_of(&[("s.xml", &scene("", 8, 8))]), "{}").await;
    assert_eq!(s, StatusCode::CREATED, "{v}");
}

/// A full data disk is the operator's to fix and the client's to retry: a 507 that says so (it
/// was a 500, or a 422 when the unpacked bundle came out truncated). The disk is played by
/// /dev/full (every write fails with ENOSPC), linked where the first submission's archive goes.
#[cfg(target_os = "linux")]
#[tokio::test(flavor = "multi_thread")]
async fn a_full_data_disk_is_a_507_and_the_next_submission_goes_through() {
    let dir = tempfile::tempdir().unwrap();
    let data = dir.path().join("data");
    let (coordinator, url) = serve(&data, "127.0.0.1:0", &[]);
    let scratch = data.join(format!("bundles/incoming-{}-0", coordinator.0.id()));
    std::fs::create_dir_all(&scratch).unwrap();
    std::os::unix::fs::symlink("/dev/full", scratch.join("bundle.tar")).unwrap();
    let api = Api::new(&url);
    let (s, v) = api.submit(tar_of(&[("s.xml", &scene("", 8, 8))]), "{}").await;
    assert_eq!(s, StatusCode::INSUFFICIENT_STORAGE, "{v}");
    assert!(error_of(&v).contains("disk is full"), "{v}");
    let (s, v) = api.submit(tar_of(&[("s.xml", &scene("", 8, 8))]), "{}").await;
    assert_eq!(s, StatusCode::CREATED, "{v}");
}

/// A storage failure is the coordinator's fault: a 500 without details (it used to be a 400,
/// with the server's paths in the message), and the service goes on.
#[tokio::test(flavor = "multi_thread")]
async fn a_storage_failure_is_a_500_without_details() {
    let dir = tempfile::tempdir().unwrap();
    let data = dir.path().join("data");
    let (_coordinator, url) = serve(&data, "127.0.0.1:0", &[]);
    let api = Api::new(&url);
    // The bundles folder becomes a file: nothing can be stored under it.
    std::fs::remove_dir_all(data.join("bundles")).unwrap();
    std::fs::write(data.join("bundles"), b"not a folder").unwrap();
    let (s, v) = api.submit(tar_of(&[("s.xml", &scene("", 8, 8))]), "{}").await;
    assert_eq!(s, StatusCode::INTERNAL_SERVER_ERROR, "{v}");
    let msg = error_of(&v);
    assert!(
        !msg.contains(data.to_str().unwrap()) && !msg.contains("bundles"),
        "{msg}"
    );
    assert_eq!(api.get("/api/jobs").await.0, StatusCode::OK);
}

/// `POST /api/lease?wait_ms=N`: with no work, 204 after the wait; a request waiting when a job
/// is submitted gets the job's first batch then, not after its wait; and a waiting request is
/// answered at once when the coordinator stops (SIGTERM), so waits never hold up a shutdown.
#[tokio::test]
async fn a_waiting_lease_request_gets_the_job_submitted_meanwhile() {
    let dir = tempfile::tempdir().unwrap();
    let (mut serve, url) = serve(dir.path(), "127.0.0.1:0", &[]);
    let ask = |wait_ms: u64| {
        let api = Api::new(&url);
        async move {
            let started = Instant::now();
            let body = br#"{"worker": "w", "threads": 1}"#.to_vec();
            let path = format!("/api/lease?wait_ms={wait_ms}");
            let (s, v) = api
                .call(reqwest::Method::POST, &path, WORKER_TOKEN, "", body)
                .await;
            (s, v, started.elapsed())
        }
    };
    let (s, _, took) = ask(300).await;
    assert_eq!(s, StatusCode::NO_CONTENT);
    assert!(took >= Duration::from_millis(300), "answered after {took:?}");

    let waiting = tokio::spawn(ask(5_000));
    tokio::time::sleep(Duration::from_millis(300)).await;
    let api = Api::new(&url);
    let bundle = tar_of(&[("s.xml", &scene("", 8, 8))]);
    let (s, v) = api.submit(bundle, r#"{"passes": 2}"#).await;
    assert_eq!(s, StatusCode::CREATED, "{v}");
    let (s, lease, took) = waiting.await.unwrap();
    assert_eq!(s, StatusCode::OK, "{lease}");
    assert_eq!(lease["job_id"], v["id"]);
    // Woken by the submission: not at the end of its 5 s wait.
    assert!(took < Duration::from_millis(4_000), "answered after {took:?}");

    // The job's other pass goes to a second worker (first batches are one pass); a third
    // request then waits...
    let body = br#"{"worker": "v", "threads": 1}"#.to_vec();
    let (s, _) = api
        .call(reqwest::Method::POST, "/api/lease", WORKER_TOKEN, "", body)
        .await;
    assert_eq!(s, StatusCode::OK);
    let waiting = tokio::spawn(ask(5_000));
    tokio::time::sleep(Duration::from_millis(300)).await;
    // ...and is answered when the coordinator is told to stop.
    let pid = serve.0.id().to_string();
    assert!(
        std::process::Command::new("kill")
            .args(["-TERM", &pid])
            .status()
            .unwrap()
            .success()
    );
    let (s, _, took) = waiting.await.unwrap();
    assert_eq!(s, StatusCode::NO_CONTENT);
    assert!(took < Duration::from_millis(4_000), "answered after {took:?}");
    let exit = serve.0.wait().unwrap();
    assert!(exit.success(), "{exit:?}");
}
