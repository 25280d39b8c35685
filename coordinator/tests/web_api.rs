//! The endpoints behind the web page, on a real coordinator with real workers: the page's
//! files need no token and hold no data, `/api/workers` and `/api/jobs/{id}/noise` need the
//! users' token, the noise estimate falls as passes arrive and matches the real error against a
//! reference, and the image's bytes stay those of `coordinator render`.

mod support;

use std::path::Path;
use std::process::Command;
use std::time::{Duration, Instant};

use serde_json::Value;
use support::{cbox_spheres, coordinator_bin, worker_with_env};

const TOKEN: &str = "web-api-test-token";

/// GET `path`: status, content type and body.
fn get(url: &str, path: &str, token: Option<&str>) -> (u16, String, Vec<u8>) {
    let rt = tokio::runtime::Builder::new_current_thread()
        .enable_all()
        .build()
        .unwrap();
    rt.block_on(async {
        let mut req = reqwest::Client::new().get(format!("{url}{path}"));
        if let Some(t) = token {
            req = req.bearer_auth(t);
        }
        let r = req.send().await.unwrap();
        let mime = r
            .headers()
            .get("content-type")
            .map(|v| v.to_str().unwrap().to_string())
            .unwrap_or_default();
        (r.status().as_u16(), mime, r.bytes().await.unwrap().to_vec())
    })
}

fn json(url: &str, path: &str) -> Value {
    let (status, _, body) = get(url, path, Some(TOKEN));
    assert_eq!(status, 200, "{path}: {}", String::from_utf8_lossy(&body));
    serde_json::from_slice(&body).unwrap()
}

fn submit(url: &str, job: &[&str]) -> u64 {
    let o = Command::new(coordinator_bin())
        .args(["submit", "--to", url, "--token", TOKEN])
        .arg(cbox_spheres())
        .args(job)
        .output()
        .unwrap();
    assert!(o.status.success(), "{}", String::from_utf8_lossy(&o.stderr));
    String::from_utf8_lossy(&o.stdout).trim().parse().unwrap()
}

fn render(dir: &Path, job: &[&str]) -> Vec<u8> {
    let out = dir.join("local.exr");
    let o = Command::new(coordinator_bin())
        .arg("render")
        .arg(cbox_spheres())
        .arg("--out")
        .arg(&out)
        .args(job)
        .output()
        .unwrap();
    assert!(o.status.success(), "{}", String::from_utf8_lossy(&o.stderr));
    std::fs::read(out).unwrap()
}

fn wait_done(url: &str, id: u64, timeout: Duration) -> Value {
    let start = Instant::now();
    loop {
        let s = json(url, &format!("/api/jobs/{id}"));
        if s["state"] == "done" {
            return s;
        }
        assert!(start.elapsed() < timeout, "job {id} did not finish: {s}");
        std::thread::sleep(Duration::from_millis(100));
    }
}

/// (passes, variance) of a job's noise report.
fn points(report: &Value) -> Vec<(u64, f64)> {
    report["points"]
        .as_array()
        .unwrap()
        .iter()
        .map(|p| (p["passes"].as_u64().unwrap(), p["variance"].as_f64().unwrap()))
        .collect()
}

/// SPPM with Mitsuba's Gaussian filter (weights per pixel), batches of several passes from two
/// workers: odd-pass samples are merged out of order, and the image is still the local one.
#[test]
fn web_endpoints_need_the_token_and_noise_falls_as_passes_arrive() {
    let dir = tempfile::tempdir().unwrap();
    let env = [("PHOTONFARM_TOKEN", TOKEN)];
    let (_coordinator, url) = support::serve(
        &dir.path().join("data"),
        "127.0.0.1:0",
        &["--batch-seconds", "0.3"],
        &env,
    );
    // The page's files: no token, no data.
    for (path, mime) in [
        ("/", "text/html"),
        ("/app.js", "text/javascript"),
        ("/style.css", "text/css"),
    ] {
        let (status, got, body) = get(&url, path, None);
        assert_eq!(status, 200, "{path}");
        assert!(got.starts_with(mime), "{path}: {got}");
        assert!(body.len() < 40_000, "{path} is {} bytes", body.len());
    }
    for path in ["/api/workers", "/api/jobs/1/noise", "/api/jobs"] {
        assert_eq!(get(&url, path, None).0, 401, "{path} needs the token");
        assert_eq!(get(&url, path, Some("wrong")).0, 401, "{path}");
    }
    assert_eq!(json(&url, "/api/workers")["workers"], serde_json::json!([]));

    let job = [
        "--integrator",
        "sppm",
        "--iterations",
        "48",
        "--photons",
        "40000",
        "--seed",
        "5",
        "--checkpoint-every",
        "16",
        "-D",
        "res=48",
        "-D",
        "filter=gaussian",
    ];
    let id = submit(&url, &job);
    let before = json(&url, &format!("/api/jobs/{id}/noise"));
    assert_eq!(before["tracking"], true);
    assert_eq!(points(&before), vec![]);
    assert_eq!(get(&url, "/api/jobs/999/noise", Some(TOKEN)).0, 404);

    let _w1 = worker_with_env(&url, "web-a", dir.path(), &env);
    let _w2 = worker_with_env(&url, "web-b", dir.path(), &env);
    let status = wait_done(&url, id, Duration::from_secs(180));
    let batches = status["batches_received"].as_u64().unwrap();
    assert!(batches < 48, "batches of several passes: {batches} batches");

    let report = json(&url, &format!("/api/jobs/{id}/noise"));
    assert_eq!(report["tracking"], true, "{report}");
    let pts = points(&report);
    eprintln!("noise estimates (passes, variance): {pts:?}");
    assert!(pts.windows(2).all(|w| w[0].0 < w[1].0), "{pts:?}");
    for checkpoint in [16, 32, 48] {
        assert!(pts.iter().any(|p| p.0 == checkpoint), "{checkpoint}: {pts:?}");
    }
    let (first, last) = (pts[0], pts[pts.len() - 1]);
    assert!(
        last.1 < first.1 * 0.5 && last.1 > 0.0,
        "the estimate falls as passes arrive: {pts:?}"
    );

    let workers = json(&url, "/api/workers");
    let list = workers["workers"].as_array().unwrap();
    let names: Vec<&str> = list.iter().map(|w| w["name"].as_str().unwrap()).collect();
    assert_eq!(names, ["web-a", "web-b"], "{workers}");
    for w in list {
        assert_eq!(w["threads"], 1, "{w}");
        assert!(w["rate"].as_f64().unwrap() > 0.0, "{w}");
        assert!(w["last_seen_seconds"].as_f64().unwrap() < 10.0, "{w}");
        assert!(w["leases"].is_array(), "{w}");
    }
    let passes: u64 = list.iter().map(|w| w["passes"].as_u64().unwrap()).sum();
    assert_eq!(passes, 48);

    // Odd passes ride beside the sums: the image is still byte for byte the local render's.
    let (status, _, farm) = get(&url, &format!("/api/jobs/{id}/image.exr"), Some(TOKEN));
    assert_eq!(status, 200);
    assert!(farm == render(dir.path(), &job), "farm and local images differ");
}

/// The estimate against the truth: a path-traced job (unbiased, so its error is its variance)
/// against Mitsuba 3's 16,384-spp reference of the same scene.
#[test]
fn noise_estimate_matches_the_error_against_a_reference() {
    let dir = tempfile::tempdir().unwrap();
    let env = [("PHOTONFARM_TOKEN", TOKEN)];
    let (_coordinator, url) = support::serve(&dir.path().join("data"), "127.0.0.1:0", &[], &env);
    let spp = 32;
    let job = [
        "--integrator",
        "path",
        "--spp",
        "32",
        "--seed",
        "1",
        "--checkpoint-every",
        "8",
    ];
    let id = submit(&url, &job);
    let _worker = worker_with_env(&url, "ref", dir.path(), &env);
    wait_done(&url, id, Duration::from_secs(300));
    let pts = points(&json(&url, &format!("/api/jobs/{id}/noise")));
    let estimate = pts.iter().find(|p| p.0 == spp).expect("an estimate at the end").1;

    let (_, _, exr) = get(&url, &format!("/api/jobs/{id}/image.exr"), Some(TOKEN));
    let ours = dir.path().join("ours.exr");
    std::fs::write(&ours, exr).unwrap();
    let reference = Path::new(env!("CARGO_MANIFEST_DIR")).join("../tests/refs/cbox-spheres.exr");
    let (w, h, a) = photonfarm::film::read_image(&ours).unwrap();
    let (rw, rh, b) = photonfarm::film::read_image(&reference).unwrap();
    assert_eq!((w, h), (rw, rh));
    let se: f64 = a
        .iter()
        .zip(&b)
        .map(|(p, q)| {
            let d = *p - *q;
            (d.x as f64).powi(2) + (d.y as f64).powi(2) + (d.z as f64).powi(2)
        })
        .sum();
    let mse = se / (3 * a.len()) as f64;
    eprintln!(
        "cbox-spheres, path, {spp} spp, 256x256: noise estimate {estimate:.4e}, MSE against the reference {mse:.4e}, ratio {:.3}; all estimates {pts:?}",
        estimate / mse
    );
    assert!(
        (0.8..1.25).contains(&(estimate / mse)),
        "estimate {estimate:.4e} against MSE {mse:.4e}"
    );
}
