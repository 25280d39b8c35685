//! The web page in a real headless Chromium, driven over WebDriver (chromedriver, started here
//! on a free port) against a real coordinator and real workers: without the token the page
//! shows nothing; with it, the running job is listed, its page shows its image and the image
//! changes as checkpoints arrive, the noise chart has points, the workers are listed, cancel
//! cancels, and a bundle submitted from the page becomes a job.
//!
//! Needs Debian's `chromium` and `chromium-driver` (`.ci/run` installs them): without
//! chromedriver the test fails and says so, it never passes silently. Screenshots go to
//! `CARGO_TARGET_TMPDIR`, and into `docs/` with `PHOTONFARM_UPDATE_SCREENSHOTS=1`.

mod support;

use std::net::TcpListener;
use std::path::{Path, PathBuf};
use std::process::{Command, Stdio};
use std::time::{Duration, Instant};

use fantoccini::{Client, ClientBuilder, Locator};
use serde_json::{Value, json};
use support::{Proc, cbox_spheres, coordinator_bin, worker_with_env};

const TOKEN: &str = "browser-test-token";

fn free_port() -> u16 {
    TcpListener::bind("127.0.0.1:0")
        .unwrap()
        .local_addr()
        .unwrap()
        .port()
}

/// chromedriver on a free port, or a failure that says how to install it.
fn chromedriver() -> (Proc, String) {
    let program = std::env::var("CHROMEDRIVER").unwrap_or_else(|_| "chromedriver".into());
    let port = free_port();
    let child = Command::new(&program)
        .arg(format!("--port={port}"))
        .stdout(Stdio::null())
        .stderr(Stdio::null())
        .spawn()
        .unwrap_or_else(|e| {
            panic!(
                "cannot start {program} ({e}): the browser test needs Chromium's WebDriver; \
                 install it with `apt-get install -y chromium chromium-driver` (as .ci/run does)"
            )
        });
    (Proc(child), format!("http://127.0.0.1:{port}"))
}

/// A Chromium session with a fresh profile in `profile`.
async fn browser(webdriver: &str, profile: &Path) -> Client {
    let mut args = vec![
        "--headless",
        "--no-sandbox",
        "--disable-gpu",
        "--disable-quic",
        "--no-first-run",
        "--disable-background-networking",
        "--disable-component-update",
        "--disable-sync",
        "--disable-dev-shm-usage",
        "--window-size=1280,960",
        "--hide-scrollbars",
    ]
    .into_iter()
    .map(String::from)
    .collect::<Vec<_>>();
    args.push(format!("--user-data-dir={}", profile.display()));
    let mut options = json!({ "args": args });
    if Path::new("/usr/bin/chromium").exists() {
        options["binary"] = json!("/usr/bin/chromium");
    }
    let caps = json!({ "browserName": "chrome", "goog:chromeOptions": options });
    let connector = hyper_util::client::legacy::connect::HttpConnector::new();
    let start = Instant::now();
    loop {
        // chromedriver takes a moment to listen.
        match ClientBuilder::new(connector.clone())
            .capabilities(caps.as_object().unwrap().clone())
            .connect(webdriver)
            .await
        {
            Ok(c) => return c,
            Err(e) if start.elapsed() < Duration::from_secs(30) => {
                let _ = e;
                tokio::time::sleep(Duration::from_millis(200)).await;
            }
            Err(e) => panic!("cannot open a Chromium session through chromedriver: {e}"),
        }
    }
}

/// Runs `script` (a function body) until it returns something truthy; returns that.
async fn wait_js(c: &Client, what: &str, timeout: Duration, script: &str) -> Value {
    let start = Instant::now();
    loop {
        let v = c.execute(script, vec![]).await.unwrap();
        let truthy = match &v {
            Value::Null | Value::Bool(false) => false,
            Value::Number(n) => n.as_f64() != Some(0.0),
            Value::String(s) => !s.is_empty(),
            _ => true,
        };
        if truthy {
            return v;
        }
        if start.elapsed() > timeout {
            let body = c.execute("return document.body.innerText", vec![]).await.unwrap();
            panic!(
                "timed out waiting for {what}; the page says:\n{}",
                body.as_str().unwrap_or("")
            );
        }
        tokio::time::sleep(Duration::from_millis(150)).await;
    }
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

async fn api(url: &str, path: &str) -> Value {
    support::get_json(url, path, TOKEN).await
}

/// Clicks the element with id `id`.
async fn click(c: &Client, id: &str) {
    c.find(Locator::Id(id)).await.unwrap().click().await.unwrap();
}

/// Types `text` into the element with id `id`.
async fn type_into(c: &Client, id: &str, text: &str) {
    c.find(Locator::Id(id))
        .await
        .unwrap()
        .send_keys(text)
        .await
        .unwrap();
}

async fn screenshot(c: &Client, name: &str) {
    let png = c.screenshot().await.unwrap();
    let out = PathBuf::from(env!("CARGO_TARGET_TMPDIR")).join(name);
    std::fs::write(&out, &png).unwrap();
    if std::env::var_os("PHOTONFARM_UPDATE_SCREENSHOTS").is_some() {
        let docs = Path::new(env!("CARGO_MANIFEST_DIR")).join("../docs").join(name);
        std::fs::write(docs, &png).unwrap();
    }
    eprintln!("screenshot: {}", out.display());
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn web_page_in_headless_chromium() {
    let (_driver, webdriver) = chromedriver();
    let dir = tempfile::tempdir().unwrap();
    let env = [("PHOTONFARM_TOKEN", TOKEN)];
    let (_coordinator, url) = support::serve(
        &dir.path().join("data"),
        "127.0.0.1:0",
        &["--batch-seconds", "0.4"],
        &env,
    );
    // A small job that finishes, then a long one that runs while the page is watched.
    let done = submit(&url, &["--integrator", "path", "--spp", "16", "-D", "res=64"]);
    let running = submit(
        &url,
        &[
            "--integrator",
            "sppm",
            "--iterations",
            "20000",
            "--photons",
            "20000",
            "--checkpoint-every",
            "6",
            "-D",
            "res=128",
        ],
    );
    // A sequence of three frames: its page shows them as a strip of thumbnails.
    let sequence = submit(
        &url,
        &[
            "--frames",
            "1-3",
            "--integrator",
            "path",
            "--spp",
            "8",
            "-D",
            "res=32",
        ],
    );
    // A job with a denoised preview: its page offers raw and denoised (builds with OIDN).
    #[cfg(feature = "denoise")]
    let denoised = submit(
        &url,
        &["--integrator", "path", "--spp", "16", "-D", "res=64", "--denoise"],
    );
    let _w1 = worker_with_env(&url, "render-a", dir.path(), &env);
    let _w2 = worker_with_env(&url, "render-b", dir.path(), &env);

    let profile = tempfile::tempdir().unwrap();
    let c = browser(&webdriver, profile.path()).await;

    // Without the token: the login form, and no data anywhere on the page.
    c.goto(&format!("{url}/")).await.unwrap();
    wait_js(
        &c,
        "the login form",
        Duration::from_secs(10),
        "return !document.getElementById('login').hidden",
    )
    .await;
    let empty = c
        .execute(
            "return document.getElementById('view').childElementCount + ':' + document.body.innerText",
            vec![],
        )
        .await
        .unwrap();
    let empty = empty.as_str().unwrap();
    assert!(empty.starts_with("0:") && !empty.contains("Job "), "{empty}");
    type_into(&c, "token", "not-the-token").await;
    click(&c, "login-button").await;
    wait_js(
        &c,
        "the refusal",
        Duration::from_secs(10),
        "return document.getElementById('login-error').innerText.includes('refused')",
    )
    .await;
    let view = c
        .execute("return document.getElementById('view').innerText", vec![])
        .await
        .unwrap();
    assert_eq!(view, json!(""), "a refused token shows no data");

    // Log in: both jobs are listed, the long one running on the workers.
    type_into(&c, "token", TOKEN).await;
    click(&c, "login-button").await;
    wait_js(
        &c,
        "the job list with a running job and a done one",
        Duration::from_secs(60),
        &format!(
            "const r = document.querySelector('tr[data-job=\"{running}\"] .state');
         const d = document.querySelector('tr[data-job=\"{done}\"] .state');
         const w = document.querySelector('tr[data-job=\"{running}\"]');
         return r && d && r.dataset.state === 'running' && d.dataset.state === 'done'
             && w.innerText.includes('render-') && w.innerText.includes('/s')"
        ),
    )
    .await;
    screenshot(&c, "web-jobs.png").await;

    // The job's page: its image appears, then changes with a later checkpoint; the chart has
    // points.
    c.find(Locator::Css(&format!("tr[data-job=\"{running}\"] a")))
        .await
        .unwrap()
        .click()
        .await
        .unwrap();
    let first = wait_js(&c, "the checkpoint image", Duration::from_secs(60),
        "const i = document.getElementById('job-image');
         return i && i.complete && i.naturalWidth === 128 && i.src.startsWith('blob:') ? i.src + ' ' + i.dataset.passes : null").await;
    let later = wait_js(
        &c,
        "a newer checkpoint image",
        Duration::from_secs(60),
        &format!(
            "const i = document.getElementById('job-image');
         const now = i.src + ' ' + i.dataset.passes;
         return i.complete && i.naturalWidth === 128 && now !== {first} ? now : null"
        ),
    )
    .await;
    eprintln!("image went from {first} to {later}");
    wait_js(
        &c,
        "a chart with 10 points",
        Duration::from_secs(90),
        "return document.querySelectorAll('#noise-chart circle.point').length >= 10",
    )
    .await;
    // Let a few more checkpoints in, for a chart worth a screenshot.
    tokio::time::sleep(Duration::from_secs(4)).await;
    screenshot(&c, "web-job.png").await;

    // No URL the page asked for, nor its own, carries the token.
    let urls = c
        .execute(
            "return [location.href].concat(performance.getEntries().map(e => e.name)).join('\\n')",
            vec![],
        )
        .await
        .unwrap();
    assert!(!urls.as_str().unwrap().contains(TOKEN), "{urls}");

    // The workers.
    click(&c, "nav-workers").await;
    wait_js(
        &c,
        "both workers, one with a lease",
        Duration::from_secs(30),
        "const t = document.getElementById('workers');
         return t && t.tBodies[0].rows.length === 2 && t.innerText.includes('render-a')
             && /job \\d+ passes \\d+–\\d+/.test(t.innerText)",
    )
    .await;
    screenshot(&c, "web-workers.png").await;

    // The sequence's page: three frames, each done with its thumbnail, each linking to its job.
    c.goto(&format!("{url}/#/jobs/{sequence}")).await.unwrap();
    let strip = wait_js(&c, "the frame strip", Duration::from_secs(60),
        "const f = [...document.querySelectorAll('#frames .frame')];
         return f.length === 3 && f.every(a => a.dataset.state === 'done')
             && f.every(a => { const i = a.querySelector('img'); return i.complete && i.naturalWidth === 32; })
             ? f.map(a => a.dataset.frame + ':' + a.getAttribute('href')).join(' ') : null").await;
    let frames = api(&url, &format!("/api/jobs/{sequence}")).await["frames"].clone();
    let expected: Vec<String> = frames
        .as_array()
        .unwrap()
        .iter()
        .map(|f| format!("{}:#/jobs/{}", f["frame"], f["job"]))
        .collect();
    assert_eq!(strip, json!(expected.join(" ")));
    screenshot(&c, "web-frames.png").await;

    // The denoised job's page: raw first, then the denoised preview at the toggle's word.
    #[cfg(feature = "denoise")]
    {
        c.goto(&format!("{url}/#/jobs/{denoised}")).await.unwrap();
        let raw = "const i = document.getElementById('job-image');
             return !document.getElementById('view-toggle').hidden && i && i.complete
                 && i.naturalWidth === 64 && i.dataset.view";
        assert_eq!(
            wait_js(&c, "the raw image", Duration::from_secs(60), raw).await,
            json!("image")
        );
        c.execute(
            "document.querySelector('#view-toggle input[value=\"image.denoised\"]').click()",
            vec![],
        )
        .await
        .unwrap();
        let shown = wait_js(
            &c,
            "the denoised preview",
            Duration::from_secs(30),
            "const i = document.getElementById('job-image');
             return i && i.complete && i.naturalWidth === 64 && i.dataset.view === 'image.denoised'
                 && i.dataset.view",
        )
        .await;
        assert_eq!(shown, json!("image.denoised"));
        screenshot(&c, "web-denoised.png").await;
    }

    // Cancel from the job's page, which offers no denoised view (not asked for).
    c.goto(&format!("{url}/#/jobs/{running}")).await.unwrap();
    wait_js(
        &c,
        "the job page without a view toggle",
        Duration::from_secs(20),
        "const t = document.getElementById('view-toggle'); return t && t.hidden",
    )
    .await;
    c.wait()
        .for_element(Locator::Id("cancel"))
        .await
        .unwrap()
        .click()
        .await
        .unwrap();
    wait_js(
        &c,
        "the cancelled state",
        Duration::from_secs(20),
        "const s = document.querySelector('#job-title .state');
         return s && s.dataset.state === 'cancelled'",
    )
    .await;
    assert_eq!(
        api(&url, &format!("/api/jobs/{running}")).await["state"],
        "cancelled"
    );

    // Submit a bundle from the page.
    let bundle = dir.path().join("bundle.tar");
    let scene = support::api::scene(r#"<integrator type="path"/>"#, 32, 24);
    std::fs::write(&bundle, support::api::tar_of(&[("scene.xml", &scene)])).unwrap();
    click(&c, "nav-submit").await;
    let file = c.wait().for_element(Locator::Id("bundle")).await.unwrap();
    file.send_keys(bundle.to_str().unwrap()).await.unwrap();
    type_into(&c, "passes", "8").await;
    click(&c, "submit-button").await;
    let hash = wait_js(&c, "the new job's page", Duration::from_secs(30),
        &format!("return location.hash !== '#/submit' && location.hash.startsWith('#/jobs/') && location.hash !== '#/jobs/{running}' ? location.hash : null")).await;
    let new_id: u64 = hash
        .as_str()
        .unwrap()
        .trim_start_matches("#/jobs/")
        .parse()
        .unwrap();
    let job = api(&url, &format!("/api/jobs/{new_id}")).await;
    assert_eq!(
        (job["iterations_total"].as_u64(), job["width"].as_u64()),
        (Some(8), Some(32)),
        "{job}"
    );

    // Logging out leaves nothing on the page.
    click(&c, "logout").await;
    wait_js(&c, "the login form again", Duration::from_secs(10),
        "return !document.getElementById('login').hidden && document.getElementById('view').childElementCount === 0
             && sessionStorage.length === 0").await;
    c.close().await.unwrap();
}
