//! Issue 11: nothing slow under the farm's lock. The API must answer within 50 ms while a huge
//! job is submitted and large results are written. In its own test binary, so that no other
//! test of the same binary competes for the CPU while it measures.

mod support;

use std::path::Path;
use std::time::{Duration, Instant};

use reqwest::StatusCode;
use reqwest::multipart::{Form, Part};
use serde_json::Value;

const TOKEN: &str = "client-token";
const WORKER_TOKEN: &str = "worker-token";

fn tar_of(files: &[(&str, &[u8])]) -> Vec<u8> {
    let mut b = tar::Builder::new(Vec::new());
    for (name, data) in files {
        let mut h = tar::Header::new_gnu();
        h.set_size(data.len() as u64);
        h.set_mode(0o644);
        h.set_cksum();
        b.append_data(&mut h, name, *data).unwrap();
    }
    b.into_inner().unwrap()
}

/// A small scene with `integrator` and `film` inserted.
fn scene(integrator: &str, width: u64, height: u64) -> Vec<u8> {
    format!(
        r#"<scene version="3.0.0">
        {integrator}
        <sensor type="perspective"><float name="fov" value="60"/>
            <transform name="to_world"><lookat origin="0,0,3" target="0,0,0" up="0,1,0"/></transform>
            <film type="hdrfilm"><integer name="width" value="{width}"/><integer name="height" value="{height}"/>
                <rfilter type="box"/></film></sensor>
        <shape type="sphere"><float name="radius" value="0.8"/><bsdf type="diffuse"/></shape>
        <emitter type="point"><point name="position" x="0" y="2" z="2"/><rgb name="intensity" value="5"/></emitter>
        </scene>"#
    )
    .into_bytes()
}

fn serve(data: &Path, bind: &str, extra: &[&str]) -> (support::Proc, String) {
    support::serve(
        data,
        bind,
        extra,
        &[
            ("PHOTONFARM_TOKEN", TOKEN),
            ("PHOTONFARM_WORKER_TOKEN", WORKER_TOKEN),
        ],
    )
}

struct Api {
    url: String,
    http: reqwest::Client,
}

impl Api {
    fn new(url: &str) -> Api {
        Api {
            url: url.to_string(),
            http: reqwest::Client::new(),
        }
    }

    async fn submit_form(&self, form: Form) -> (StatusCode, Value) {
        let resp = self
            .http
            .post(format!("{}/api/jobs", self.url))
            .bearer_auth(TOKEN)
            .multipart(form)
            .send()
            .await
            .unwrap();
        let status = resp.status();
        (status, resp.json().await.unwrap_or(Value::Null))
    }

    async fn submit(&self, bundle: Vec<u8>, settings: &str) -> (StatusCode, Value) {
        let form = Form::new()
            .part("bundle", Part::bytes(bundle).file_name("b.tar"))
            .text("settings", settings.to_string());
        self.submit_form(form).await
    }

    async fn call(
        &self,
        method: reqwest::Method,
        path: &str,
        token: &str,
        key: &str,
        body: Vec<u8>,
    ) -> (StatusCode, Value) {
        let resp = self
            .http
            .request(method, format!("{}{path}", self.url))
            .header("Authorization", format!("Bearer {token}"))
            .header("x-photonfarm-lease-key", key)
            .body(body)
            .send()
            .await
            .unwrap();
        let status = resp.status();
        (status, resp.json().await.unwrap_or(Value::Null))
    }

    async fn get(&self, path: &str) -> (StatusCode, Value) {
        self.call(reqwest::Method::GET, path, TOKEN, "", vec![]).await
    }

    async fn lease(&self, worker: &str) -> Option<Value> {
        let body = format!(r#"{{"worker": "{worker}", "threads": 1}}"#).into_bytes();
        let (s, v) = self
            .call(reqwest::Method::POST, "/api/lease", WORKER_TOKEN, "", body)
            .await;
        match s {
            StatusCode::OK => Some(v),
            StatusCode::NO_CONTENT => None,
            s => panic!("lease: {s} {v}"),
        }
    }
}

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
    while results < 3 {
        let lease = api.lease("w").await.unwrap();
        let key = lease["key"].as_str().unwrap();
        let path = format!("/api/leases/{}/", lease["lease_id"]);
        assert_eq!(lease["job_id"].as_u64(), Some(big_id), "the oldest job first");
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
