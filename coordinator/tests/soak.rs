//! A bounded soak over loopback: slow connections, good and bad submissions, bad results and a
//! real worker at once, for a few seconds, with the coordinator's address space capped by the
//! operating system. The coordinator must keep answering, keep its descriptors and memory
//! bounded, lose nothing across a SIGKILL in the middle, finish every good job with the bytes of
//! `coordinator render`, and restart cleanly.

mod support;

use support::api::tar_of;

use std::io::{Read, Write};
use std::net::TcpStream;
use std::time::{Duration, Instant};

use reqwest::StatusCode;
use reqwest::multipart::{Form, Part};
use serde_json::Value;

const TOKEN: &str = "soak-token";

/// The coordinator's address-space cap (virtual memory: thread stacks and allocator arenas
/// count, so it is well above the resident peak asserted below).
const ADDRESS_SPACE_MB: u64 = 2048;

fn scene(width: u32) -> Vec<u8> {
    format!(
        r#"<scene version="3.0.0">
        <sensor type="perspective"><transform name="to_world"><lookat origin="0,0,3" target="0,0,0" up="0,1,0"/></transform>
            <film type="hdrfilm"><integer name="width" value="{width}"/><integer name="height" value="{width}"/>
                <rfilter type="box"/></film></sensor>
        <shape type="sphere"><float name="radius" value="0.8"/><bsdf type="diffuse"/></shape>
        <emitter type="point"><point name="position" x="0" y="2" z="2"/><rgb name="intensity" value="5"/></emitter>
        </scene>"#
    )
    .into_bytes()
}

/// Open descriptors and peak resident memory (KiB) of a process.
fn usage(pid: u32) -> (usize, u64) {
    let fds = std::fs::read_dir(format!("/proc/{pid}/fd")).unwrap().count();
    let status = std::fs::read_to_string(format!("/proc/{pid}/status")).unwrap();
    let hwm = status
        .lines()
        .find_map(|l| l.strip_prefix("VmHWM:"))
        .and_then(|v| v.trim().trim_end_matches("kB").trim().parse().ok())
        .unwrap();
    (fds, hwm)
}

async fn submit(http: &reqwest::Client, url: &str, bundle: Vec<u8>, settings: &str) -> (StatusCode, Value) {
    let form = Form::new()
        .part("bundle", Part::bytes(bundle).file_name("b.tar"))
        .text("settings", settings.to_string());
    let r = http
        .post(format!("{url}/api/jobs"))
        .bearer_auth(TOKEN)
        .multipart(form)
        .send()
        .await
        .unwrap();
    let s = r.status();
    (s, r.json().await.unwrap_or(Value::Null))
}

#[tokio::test(flavor = "multi_thread")]
async fn a_bounded_soak_keeps_the_farm_up() {
    let dir = tempfile::tempdir().unwrap();
    let data = dir.path().join("data");
    let flags = [
        "--max-connections",
        "32",
        "--idle-timeout",
        "2",
        "--max-upload-mb",
        "4",
        "--batch-seconds",
        "0.2",
    ];
    // A fixed port, so that the worker finds the coordinator again after the SIGKILL.
    let bind = support::fixed_loopback_address();
    let serve = || {
        support::serve_limited(
            &data,
            &bind,
            &flags,
            &[("PHOTONFARM_TOKEN", TOKEN)],
            Some(ADDRESS_SPACE_MB),
        )
    };
    let (mut coordinator, url) = serve();
    let pid = coordinator.0.id();
    let addr = url.strip_prefix("http://").unwrap().to_string();
    let (fds_at_start, _) = usage(pid);
    // No pooled connections: the coordinator answers a refused upload before reading its body
    // and then closes the connection, and a request sent on that pooled connection in the
    // meantime would fail for the client's reuse, not for anything the coordinator did.
    let http = reqwest::Client::builder()
        .pool_max_idle_per_host(0)
        .build()
        .unwrap();

    // 300 slow, unauthenticated connections: half a request head each, then silence. They
    // used to take 300 descriptors; now at most 32 are accepted, and silent ones are closed.
    let mut slow: Vec<TcpStream> = (0..300)
        .map(|_| {
            let mut s = TcpStream::connect(&addr).unwrap();
            let _ = s.write_all(b"GET /api/jobs HTTP/1.1\r\nHost: x\r\n");
            s
        })
        .collect();
    std::thread::sleep(Duration::from_millis(500));
    let (fds, _) = usage(pid);
    assert!(
        fds <= fds_at_start + 40,
        "{fds} descriptors open (at start {fds_at_start})"
    );
    // A real client still gets through, once the silent ones time out.
    let start = Instant::now();
    let r = http
        .get(format!("{url}/api/jobs"))
        .bearer_auth(TOKEN)
        .timeout(Duration::from_secs(30))
        .send()
        .await
        .unwrap();
    assert_eq!(r.status(), StatusCode::OK);
    let waited = start.elapsed();
    eprintln!("served after {waited:?} behind 300 slow connections, {fds} descriptors");
    // The accepted ones were closed after 2 s of silence (the rest wait in the backlog).
    let mut closed = 0;
    for s in &mut slow {
        s.set_read_timeout(Some(Duration::from_millis(5))).unwrap();
        let mut buf = [0u8; 256];
        match s.read(&mut buf) {
            Ok(0) => closed += 1,
            Err(e) if e.kind() == std::io::ErrorKind::ConnectionReset => closed += 1,
            _ => {}
        }
    }
    assert!(closed >= 32, "silent connections are closed: {closed}");
    drop(slow);

    // The soak: a worker renders while clients submit good and bad jobs and post garbage.
    let _worker = support::worker_with_env(&url, "soaker", dir.path(), &[("PHOTONFARM_TOKEN", TOKEN)]);
    let good = tar_of(&[("s.xml", &scene(16))]);
    let bad: Vec<(Vec<u8>, &str)> = vec![
        (tar_of(&[("s.xml", &scene(65536))]), "{}"),
        (tar_of(&[("s.xml", b"<scene version=\"3.0.0\"><shape>")]), "{}"),
        (b"not a tar archive".to_vec(), "{}"),
        (
            good.clone(),
            r#"{"integrator": "sppm", "photons": 1000000000000}"#,
        ),
        (good.clone(), r#"{"passes": 0}"#),
        (vec![0u8; 5 << 20], "{}"),
    ];
    let deadline = Instant::now() + Duration::from_secs(12);
    let mut accepted = Vec::new();
    let mut refused = 0;
    let mut round = 0;
    let mut killed = false;
    let mut pid = pid;
    while Instant::now() < deadline {
        // A SIGKILL in the middle of it all: the coordinator restarts on the same data and
        // port, loses no job, and the worker and the clients go on with it.
        if !killed && deadline - Instant::now() < Duration::from_secs(6) {
            coordinator.sigkill();
            let (restarted, again) = serve();
            assert_eq!(again, url);
            coordinator = restarted;
            pid = coordinator.0.id();
            killed = true;
            eprintln!(
                "killed and restarted the coordinator after {} accepted jobs",
                accepted.len()
            );
        }
        let (s, v) = submit(
            &http,
            &url,
            good.clone(),
            r#"{"passes": 4, "checkpoint_every": 2}"#,
        )
        .await;
        assert_eq!(s, StatusCode::CREATED, "{v}");
        accepted.push(v["id"].as_u64().unwrap());
        let (bundle, settings) = &bad[round % bad.len()];
        let r = http
            .post(format!("{url}/api/jobs"))
            .bearer_auth(TOKEN)
            .multipart(
                Form::new()
                    .part("bundle", Part::bytes(bundle.clone()).file_name("b.tar"))
                    .text("settings", settings.to_string()),
            )
            .send()
            .await;
        if let Ok(r) = r {
            assert!(r.status().is_client_error(), "round {round}: {}", r.status());
            refused += 1;
        }
        let (s, _) = {
            let r = http
                .put(format!("{url}/api/leases/{}/result", round + 1))
                .bearer_auth(TOKEN)
                .body(vec![7u8; 1000])
                .send()
                .await
                .unwrap();
            (r.status(), ())
        };
        assert!(s.is_client_error(), "{s}");
        round += 1;
        tokio::time::sleep(Duration::from_millis(100)).await;
    }
    // Every good job finishes.
    let wait = Instant::now();
    for id in &accepted {
        loop {
            let v: Value = http
                .get(format!("{url}/api/jobs/{id}"))
                .bearer_auth(TOKEN)
                .send()
                .await
                .unwrap()
                .json()
                .await
                .unwrap();
            if v["state"] == "done" {
                break;
            }
            assert!(v["state"] == "queued" || v["state"] == "running", "{v}");
            assert!(
                wait.elapsed() < Duration::from_secs(120),
                "job {id} did not finish: {v}"
            );
            tokio::time::sleep(Duration::from_millis(100)).await;
        }
    }
    let (fds, hwm_kib) = usage(pid);
    eprintln!(
        "{} jobs done, {refused} bad submissions refused, {round} bad results refused; {fds} descriptors, peak RSS {} MiB",
        accepted.len(),
        hwm_kib / 1024
    );
    assert!(fds <= fds_at_start + 40, "{fds} descriptors");
    assert!(hwm_kib < 512 * 1024, "peak RSS {} MiB", hwm_kib / 1024);

    // A good job's image has the bytes of a local render of the same scene and settings.
    let local = dir.path().join("local.exr");
    let scene_file = dir.path().join("s.xml");
    std::fs::write(&scene_file, scene(16)).unwrap();
    let o = std::process::Command::new(support::coordinator_bin())
        .args([
            "render",
            scene_file.to_str().unwrap(),
            "--spp",
            "4",
            "--out",
            local.to_str().unwrap(),
        ])
        .output()
        .unwrap();
    assert!(o.status.success(), "{}", String::from_utf8_lossy(&o.stderr));
    let last = *accepted.last().unwrap();
    let farm = http
        .get(format!("{url}/api/jobs/{last}/image.exr"))
        .bearer_auth(TOKEN)
        .send()
        .await
        .unwrap()
        .bytes()
        .await
        .unwrap();
    assert!(
        farm.as_ref() == std::fs::read(&local).unwrap().as_slice(),
        "farm and local bytes differ"
    );

    // And it restarts cleanly, with every job.
    coordinator.sigkill();
    let (_coordinator, url) = serve();
    let v: Value = http
        .get(format!("{url}/api/jobs"))
        .bearer_auth(TOKEN)
        .send()
        .await
        .unwrap()
        .json()
        .await
        .unwrap();
    let jobs = v["jobs"].as_array().unwrap();
    assert_eq!(jobs.len(), accepted.len(), "only the good jobs were stored");
    assert!(jobs.iter().all(|j| j["state"] == "done"), "{v}");
}
