//! Issue 11: nothing slow under the farm's lock. The API must answer within 50 ms while a huge
//! job is submitted and large results are written. In its own test binary, so that no other
//! test of the same binary competes for the CPU while it measures.

mod support;

use std::time::{Duration, Instant};

use reqwest::StatusCode;

use support::api::*;

/// One HTTP GET over a raw socket; returns how long the answer took.
fn timed_get(addr: &str, path: &str) -> Duration {
    use std::io::{Read, Write};
    let start = Instant::now();
    let mut s = std::net::TcpStream::connect(addr).unwrap();
    write!(
        s,
        "GET {path} HTTP/1.1\r\nHost: {addr}\r\nAuthorization: Bearer {TOKEN}\r\nConnection: close\r\n\r\n"
    )
    .unwrap();
    let mut out = Vec::new();
    s.read_to_end(&mut out).unwrap();
    assert!(
        out.starts_with(b"HTTP/1.1 200"),
        "{}",
        String::from_utf8_lossy(&out)
    );
    start.elapsed()
}

#[tokio::test(flavor = "multi_thread")]
async fn the_api_answers_within_50_ms_while_a_huge_job_is_submitted_and_results_are_written() {
    let dir = tempfile::tempdir().unwrap();
    let (coordinator, url) = serve(&dir.path().join("data"), "127.0.0.1:0", &[]);
    let api = Api::new(&url);
    let addr = url.strip_prefix("http://").unwrap().to_string();
    let stop = std::sync::Arc::new(std::sync::atomic::AtomicBool::new(false));
    let (poll_stop, poll_addr) = (stop.clone(), addr.clone());
    let poller = std::thread::spawn(move || {
        let mut times = Vec::new();
        while !poll_stop.load(std::sync::atomic::Ordering::Relaxed) {
            times.push(timed_get(&poll_addr, "/api/jobs"));
            std::thread::sleep(Duration::from_millis(5));
        }
        times
    });
    // A 1024×1024 film checkpointed at every pass (the prefix fsynced and EXR and PNG
    // encoded, which used to happen under the lock), then the longest job allowed (its radius
    // schedule, 10 million entries, used to be computed under the lock).
    let big = tar_of(&[("s.xml", &scene("", 1024, 1024))]);
    let (s, v) = api.submit(big, r#"{"passes": 3, "checkpoint_every": 1}"#).await;
    assert_eq!(s, StatusCode::CREATED, "{v}");
    let big_id = v["id"].as_u64().unwrap();
    let sppm = tar_of(&[("s.xml", &scene("", 8, 8))]);
    let (s, v) = api
        .submit(
            sppm,
            r#"{"integrator": "sppm", "passes": 10000000, "photons": 100}"#,
        )
        .await;
    assert_eq!(s, StatusCode::CREATED, "{v}");
    let mut sum = photonfarm::film::FilmSum::new(1024, 1024);
    sum.passes = 1;
    for (i, s) in sum.sums.iter_mut().enumerate() {
        *s = [(i as i64 * 7919) % (1 << 26), (i as i64) << 10, 12345];
    }
    let encoded = photonfarm::protocol::encode_batch(&sum);
    let mut results = 0;
    let mut leases = 0;
    while results < 3 {
        let lease = api.lease("w").await.unwrap();
        leases += 1;
        assert!(leases <= 12, "the big job's leases do not come");
        let key = lease["key"].as_str().unwrap();
        let path = format!("/api/leases/{}/", lease["lease_id"]);
        if lease["job_id"].as_u64() != Some(big_id) {
            // Jobs take turns: the SPPM job's batch is handed back cleanly.
            let (s, v) = api
                .call(
                    reqwest::Method::POST,
                    &(path + "release"),
                    WORKER_TOKEN,
                    key,
                    br#"{"error": null}"#.to_vec(),
                )
                .await;
            assert_eq!(s, StatusCode::OK, "{v}");
            continue;
        }
        let (s, v) = api
            .call(
                reqwest::Method::PUT,
                &(path + "result"),
                WORKER_TOKEN,
                key,
                encoded.clone(),
            )
            .await;
        assert_eq!(s, StatusCode::OK, "{v}");
        results += 1;
    }
    let (_, v) = api.get(&format!("/api/jobs/{big_id}")).await;
    assert_eq!(v["state"], "done", "{v}");
    assert_eq!(v["checkpoint_iterations"], 3, "{v}");
    stop.store(true, std::sync::atomic::Ordering::Relaxed);
    let mut times = poller.join().unwrap();
    times.sort();
    let n = times.len();
    let (p95, worst) = (
        times[(n * 95 / 100).min(n.saturating_sub(1))],
        times[n.saturating_sub(1)],
    );
    let status = std::fs::read_to_string(format!("/proc/{}/status", coordinator.0.id())).unwrap();
    let peak = status.lines().find(|l| l.starts_with("VmHWM")).unwrap_or("");
    eprintln!(
        "{n} status requests, 95% within {p95:?}, the slowest in {worst:?}; {} B results; coordinator {peak}",
        encoded.len()
    );
    assert!(n >= 10, "too few samples: {n}");
    // The machine is shared (CI has two cores and other tests): one scheduling hiccup can
    // exceed 50 ms with no lock involved, so 95% of the requests must answer within 50 ms and
    // none may wait a second. Work under the lock stalled every request for seconds (7.4 s).
    assert!(p95 < Duration::from_millis(50), "95% of requests within {p95:?}");
    assert!(worst < Duration::from_secs(1), "the API stalled for {worst:?}");
}
