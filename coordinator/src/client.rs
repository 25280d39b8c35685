//! `coordinator submit`: the API's client.

use std::time::{Duration, Instant};

use anyhow::{Context, bail};
use photonfarm::scene::Scene;
use reqwest::multipart::{Form, Part};
use serde_json::Value;

use crate::cli::SubmitArgs;
use crate::progress::Reporter;
use crate::render_command::check_output;

/// An authenticated client of one coordinator.
pub struct ApiClient {
    base: String,
    token: Option<String>,
    http: reqwest::Client,
}

impl ApiClient {
    /// A client of the coordinator at `base` (e.g. `http://127.0.0.1:8080`).
    pub fn new(base: &str, token: Option<String>) -> ApiClient {
        ApiClient {
            base: base.trim_end_matches('/').to_string(),
            token,
            http: reqwest::Client::new(),
        }
    }

    fn req(&self, method: reqwest::Method, path: &str) -> reqwest::RequestBuilder {
        let r = self.http.request(method, format!("{}{path}", self.base));
        match &self.token {
            Some(t) => r.bearer_auth(t),
            None => r,
        }
    }

    /// Sends a request; a non-success status becomes an error with the API's message.
    async fn send(&self, r: reqwest::RequestBuilder) -> anyhow::Result<reqwest::Response> {
        let resp = r
            .send()
            .await
            .with_context(|| format!("cannot reach the coordinator at {}", self.base))?;
        if resp.status().is_success() {
            return Ok(resp);
        }
        let status = resp.status();
        let text = resp.text().await.unwrap_or_default();
        let msg = serde_json::from_str::<Value>(&text)
            .ok()
            .and_then(|v| v["error"].as_str().map(str::to_string))
            .unwrap_or(text);
        bail!("{status}: {msg}")
    }

    /// Submits a bundle; returns the job's status JSON.
    pub async fn submit(
        &self,
        bundle: Vec<u8>,
        scene: &str,
        settings: &photonfarm::job::JobSettings,
    ) -> anyhow::Result<Value> {
        let form = Form::new()
            .part("bundle", Part::bytes(bundle).file_name("bundle.tar"))
            .text("scene", scene.to_string())
            .text("settings", serde_json::to_string(settings)?);
        Ok(self
            .send(self.req(reqwest::Method::POST, "/api/jobs").multipart(form))
            .await?
            .json()
            .await?)
    }

    /// A job's status JSON.
    pub async fn status(&self, id: u64) -> anyhow::Result<Value> {
        Ok(self
            .send(self.req(reqwest::Method::GET, &format!("/api/jobs/{id}")))
            .await?
            .json()
            .await?)
    }

    /// A job's latest image, `image.exr` or `image.png`.
    pub async fn image(&self, id: u64, file: &str) -> anyhow::Result<Vec<u8>> {
        Ok(self
            .send(self.req(reqwest::Method::GET, &format!("/api/jobs/{id}/{file}")))
            .await?
            .bytes()
            .await?
            .to_vec())
    }
}

/// Packs the scene, submits it, and with `--wait` follows the job and downloads the image.
pub fn run_submit(args: &SubmitArgs) -> anyhow::Result<()> {
    if let Some(out) = &args.out {
        check_output(out)?;
    }
    let settings = args.job.settings()?;
    // Load locally first: a broken scene fails here, with its file and line, before uploading.
    let scene = Scene::load(&args.job.scene, &settings.defines)?;
    let (bundle, scene_in_bundle) = photonfarm::bundle::pack(&args.job.scene, &scene.files)?;
    let scene_name = scene_in_bundle.to_string_lossy().into_owned();
    let client = ApiClient::new(&args.to, args.token.clone().filter(|t| !t.is_empty()));
    let rt = tokio::runtime::Runtime::new()?;
    rt.block_on(async {
        let job = client.submit(bundle, &scene_name, &settings).await?;
        let id = job["id"]
            .as_u64()
            .context("the coordinator's answer has no job id")?;
        for w in job["warnings"].as_array().into_iter().flatten() {
            eprintln!("warning: {}", w.as_str().unwrap_or_default());
        }
        println!("{id}");
        eprintln!("submitted job {id} ({} passes)", job["iterations_total"]);
        if !args.wait {
            return Ok(());
        }
        let total = job["iterations_total"].as_u64();
        let mut reporter = Reporter::new(total, "passes");
        let start = Instant::now();
        let status = loop {
            let s = client.status(id).await?;
            reporter.update(s["iterations_done"].as_u64().unwrap_or(0), total, start.elapsed());
            match s["state"].as_str() {
                Some("done" | "failed" | "cancelled") => break s,
                _ => tokio::time::sleep(Duration::from_millis(500)).await,
            }
        };
        reporter.finish();
        match status["state"].as_str() {
            Some("done") => {}
            Some(state) => bail!(
                "job {id} {state}: {}",
                status["message"].as_str().unwrap_or("no message")
            ),
            None => bail!("job {id}: the coordinator's answer has no state"),
        }
        if let Some(out) = &args.out {
            let ext = out
                .extension()
                .and_then(|e| e.to_str())
                .unwrap_or("exr")
                .to_ascii_lowercase();
            let bytes = client.image(id, &format!("image.{ext}")).await?;
            std::fs::write(out, bytes).with_context(|| format!("cannot write {}", out.display()))?;
            eprintln!("wrote {}", out.display());
        }
        Ok(())
    })
}
