//! `GET /metrics` scraped from a real coordinator while a real worker renders a job: the text
//! parses as Prometheus' format (read by the independent `prometheus-parse` crate), needs the
//! users' token, and its figures follow the job from queued to done.

mod support;

use std::process::Command;
use std::time::{Duration, Instant};

use support::{cbox_spheres, coordinator_bin, worker_with_env};

const TOKEN: &str = "metrics-test-token";

fn scrape(url: &str, token: Option<&str>) -> (u16, String) {
    let rt = tokio::runtime::Builder::new_current_thread()
        .enable_all()
        .build()
        .unwrap();
    rt.block_on(async {
        let mut req = reqwest::Client::new().get(format!("{url}/metrics"));
        if let Some(t) = token {
            req = req.bearer_auth(t);
        }
        let r = req.send().await.unwrap();
        (r.status().as_u16(), r.text().await.unwrap())
    })
}

fn parse(text: &str) -> prometheus_parse::Scrape {
    prometheus_parse::Scrape::parse(text.lines().map(|l| Ok(l.to_string())))
        .unwrap_or_else(|e| panic!("{e}: {text}"))
}

/// The value of `metric` with the given labels.
fn value(s: &prometheus_parse::Scrape, metric: &str, labels: &[(&str, &str)]) -> Option<f64> {
    s.samples
        .iter()
        .find(|x| x.metric == metric && labels.iter().all(|(k, v)| x.labels.get(k) == Some(*v)))
        .map(|x| match &x.value {
            prometheus_parse::Value::Gauge(v)
            | prometheus_parse::Value::Counter(v)
            | prometheus_parse::Value::Untyped(v) => *v,
            prometheus_parse::Value::Histogram(_) | prometheus_parse::Value::Summary(_) => f64::NAN,
        })
}

#[test]
fn metrics_parse_and_follow_a_job() {
    let dir = tempfile::tempdir().unwrap();
    let (_coordinator, url) = support::serve(
        &dir.path().join("data"),
        "127.0.0.1:0",
        &["--batch-seconds", "0.3"],
        &[("PHOTONFARM_TOKEN", TOKEN)],
    );
    assert_eq!(scrape(&url, None).0, 401, "the users' token is required");
    let (status, text) = scrape(&url, Some(TOKEN));
    assert_eq!(status, 200);
    let empty = parse(&text);
    assert_eq!(value(&empty, "photonfarm_pending_passes", &[]), Some(0.0));
    assert_eq!(value(&empty, "photonfarm_workers", &[]), Some(0.0));

    // A job with no worker yet: its passes are the queue depth an autoscaler sees.
    let o = Command::new(coordinator_bin())
        .args([
            "submit",
            "--to",
            &url,
            "--token",
            TOKEN,
            cbox_spheres().to_str().unwrap(),
        ])
        .args([
            "--integrator",
            "sppm",
            "--iterations",
            "24",
            "--photons",
            "20000",
            "-D",
            "res=32",
        ])
        .args(["--checkpoint-every", "8"])
        .output()
        .unwrap();
    assert!(o.status.success(), "{}", String::from_utf8_lossy(&o.stderr));
    let id = String::from_utf8_lossy(&o.stdout).trim().to_string();
    let queued = parse(&scrape(&url, Some(TOKEN)).1);
    assert_eq!(value(&queued, "photonfarm_pending_passes", &[]), Some(24.0));
    assert_eq!(
        value(&queued, "photonfarm_jobs", &[("state", "queued")]),
        Some(1.0)
    );
    assert_eq!(
        value(&queued, "photonfarm_job_passes", &[("job", &id)]),
        Some(24.0)
    );

    let _worker = worker_with_env(&url, "w", dir.path(), &[("PHOTONFARM_TOKEN", TOKEN)]);
    let start = Instant::now();
    let done = loop {
        let s = parse(&scrape(&url, Some(TOKEN)).1);
        if value(&s, "photonfarm_jobs", &[("state", "done")]) == Some(1.0) {
            break s;
        }
        assert!(
            start.elapsed() < Duration::from_secs(120),
            "the job did not finish"
        );
        std::thread::sleep(Duration::from_millis(100));
    };
    assert_eq!(value(&done, "photonfarm_pending_passes", &[]), Some(0.0));
    assert_eq!(value(&done, "photonfarm_workers", &[]), Some(1.0));
    assert_eq!(
        value(&done, "photonfarm_job_passes", &[("job", &id)]),
        None,
        "only open jobs are listed"
    );
    // Checkpoints at 8, 16 and 24 passes were written and timed.
    let count = value(&done, "photonfarm_checkpoint_seconds_count", &[]);
    let histogram = done
        .samples
        .iter()
        .find(|x| x.metric == "photonfarm_checkpoint_seconds")
        .map(|x| &x.value);
    let observed = match histogram {
        Some(prometheus_parse::Value::Histogram(buckets)) => buckets.last().map(|b| b.count),
        _ => count,
    };
    assert_eq!(observed, Some(3.0), "{histogram:?}");
}
