//! The API's client: `coordinator submit`, and the job commands (`jobs`, `status`, `wait`,
//! `fetch`, `cancel`) that follow a job after it was submitted.

pub mod loadgen;
pub mod synthetic;

use std::time::{Duration, Instant};

use anyhow::{Context, bail};
use photonfarm::protocol::{Endpoint, JobList, JobState, JobStatus, Submitted, routes};
use photonfarm::scene::Scene;
use reqwest::multipart::{Form, Part};
use serde_json::Value;

use crate::cli::SubmitArgs;
use crate::local::render::check_output;
use crate::progress::Reporter;

/// An authenticated client of one coordinator.
pub struct ApiClient {
    endpoint: Endpoint,
}

impl ApiClient {
    /// A client of the coordinator at `base` (e.g. `http://127.0.0.1:8080`).
    pub fn new(base: &str, token: Option<String>) -> ApiClient {
        ApiClient {
            endpoint: Endpoint::new(base, token, reqwest::Client::new()),
        }
    }

    /// A client of the coordinator named on the command line (an empty token is none); an
    /// error if `--to` is not an http:// or https:// address.
    pub fn for_connection(conn: &crate::cli::ConnectionArgs) -> anyhow::Result<ApiClient> {
        check_address(&conn.to)?;
        Ok(ApiClient::new(&conn.to, conn.token.clone()))
    }

    /// Sends a request; a non-success status becomes an error with the API's message.
    async fn send(&self, r: reqwest::RequestBuilder) -> anyhow::Result<reqwest::Response> {
        let resp = r
            .send()
            .await
            .with_context(|| format!("cannot reach the coordinator at {}", self.endpoint.base()))?;
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

    /// Submits a bundle; returns the job's status and the scene's warnings.
    pub async fn submit(
        &self,
        bundle: Vec<u8>,
        scene: &str,
        settings: &photonfarm::job::JobSettings,
    ) -> anyhow::Result<Submitted> {
        let form = Form::new()
            .part("bundle", Part::bytes(bundle).file_name("bundle.tar"))
            .text("scene", scene.to_string())
            .text("settings", serde_json::to_string(settings)?);
        Ok(self
            .send(
                self.endpoint
                    .request(reqwest::Method::POST, routes::JOBS)
                    .multipart(form),
            )
            .await?
            .json()
            .await?)
    }

    /// A job's status.
    pub async fn status(&self, id: u64) -> anyhow::Result<JobStatus> {
        Ok(self
            .send(self.endpoint.request(reqwest::Method::GET, &routes::job(id)))
            .await?
            .json()
            .await?)
    }

    /// Every job's status, oldest first.
    pub async fn jobs(&self) -> anyhow::Result<Vec<JobStatus>> {
        let list: JobList = self
            .send(self.endpoint.request(reqwest::Method::GET, routes::JOBS))
            .await?
            .json()
            .await?;
        Ok(list.jobs)
    }

    /// Cancels a job; returns its status.
    pub async fn cancel(&self, id: u64) -> anyhow::Result<JobStatus> {
        Ok(self
            .send(self.endpoint.request(reqwest::Method::DELETE, &routes::job(id)))
            .await?
            .json()
            .await?)
    }

    /// A job's latest image, `image.exr` or `image.png`.
    pub async fn image(&self, id: u64, file: &str) -> anyhow::Result<Vec<u8>> {
        Ok(self
            .send(
                self.endpoint
                    .request(reqwest::Method::GET, &routes::job_file(id, file)),
            )
            .await?
            .bytes()
            .await?
            .to_vec())
    }
}

/// Checks `--to` before anything is sent: without `http://` a request fails with an obscure
/// "relative URL without a base" or "builder error".
pub fn check_address(given: &str) -> anyhow::Result<()> {
    let ok = reqwest::Url::parse(given)
        .is_ok_and(|url| matches!(url.scheme(), "http" | "https") && url.host().is_some());
    if !ok {
        let example = if given.contains("://") || given.is_empty() {
            "http://render-host:8080".to_string()
        } else {
            format!("http://{given}")
        };
        bail!("--to {given}: expected an http:// or https:// address, e.g. {example}");
    }
    Ok(())
}

/// Packs the scene, submits it, and with `--wait` follows the job and downloads the image.
pub fn run_submit(args: &SubmitArgs) -> anyhow::Result<()> {
    if let Some(out) = &args.out {
        check_output(out)?;
    }
    let client = ApiClient::for_connection(&args.conn)?;
    let mut settings = args.job.settings()?;
    // Load locally first: a broken scene fails here, with its file and line, before uploading
    // (each file of a sequence given as files, at its frame's settings; of a sequence of one
    // scene, its first frame: the coordinator checks every frame).
    let frames = match &settings.frames {
        Some(spec) => photonfarm::frames::parse_frames(spec)?,
        None => Vec::new(),
    };
    let paths: Vec<&std::path::Path> = std::iter::once(&args.job.scene)
        .chain(&args.job.more_scenes)
        .map(|p| p.as_path())
        .collect();
    let mut files = Vec::new();
    for (i, path) in paths.iter().enumerate() {
        let frame_settings = match frames.get(i) {
            Some(&f) => settings.for_frame(&frames, f)?,
            None => settings.clone(),
        };
        files.extend(Scene::load(path, &frame_settings.defines)?.files);
    }
    let (bundle, inside) = photonfarm::bundle::pack_scenes(&paths, &files)?;
    let names: Vec<String> = inside.iter().map(|p| p.to_string_lossy().into_owned()).collect();
    let scene_name = names[0].clone();
    if names.len() > 1 {
        settings.scenes = names;
    }
    let rt = tokio::runtime::Runtime::new()?;
    rt.block_on(async {
        let job = client.submit(bundle, &scene_name, &settings).await?;
        let id = job.status.id;
        for w in &job.warnings {
            eprintln!("warning: {w}");
        }
        println!("{id}");
        eprintln!("submitted job {id} ({} passes)", job.status.iterations_total);
        if !args.wait {
            return Ok(());
        }
        wait_for(&client, id, args.timeout).await?;
        if let Some(out) = &args.out {
            fetch(&client, id, out, settings.denoise).await?;
        }
        Ok(())
    })
}

/// Follows a job with a progress bar until it ends; an error unless it is done. While it is
/// queued and no worker has asked for work, says so instead of an endless estimate. Past
/// `timeout`, an error saying how far the job got (a script's or a test's bound on a stall).
pub async fn wait_for(client: &ApiClient, id: u64, timeout: Option<Duration>) -> anyhow::Result<()> {
    let start = Instant::now();
    let mut reporter: Option<Reporter> = None;
    let mut said_idle = false;
    let mut frames_said = std::collections::HashSet::new();
    let status = loop {
        let s = client.status(id).await?;
        // A sequence: each frame said once when it ends, with how far the whole is.
        for f in &s.frames {
            if f.state.is_final() && frames_said.insert(f.frame) {
                let ended = frames_said.len();
                let msg = format!(
                    "frame {} {} ({ended} of {} frames)",
                    f.frame,
                    f.state.as_str(),
                    s.frames.len()
                );
                match &reporter {
                    Some(r) => r.println(&msg),
                    None => eprintln!("{msg}"),
                }
            }
        }
        if s.state.is_final() {
            break s;
        }
        if s.state == JobState::Queued && s.workers_present == 0 {
            if !said_idle {
                eprintln!(
                    "job {id} is queued: no worker has asked for work (start one with `worker --coordinator URL`)"
                );
                said_idle = true;
            }
        } else {
            let total = Some(s.iterations_total);
            reporter
                .get_or_insert_with(|| Reporter::new(total, "passes"))
                .update(s.iterations_done, total, start.elapsed());
        }
        if let Some(limit) = timeout
            && start.elapsed() >= limit
        {
            if let Some(r) = reporter.as_mut() {
                r.finish();
            }
            bail!(
                "job {id} is still {} after {} s ({} of {} passes done; {} workers present): \
                 stopped waiting, the job goes on",
                s.state.as_str(),
                limit.as_secs_f64(),
                s.iterations_done,
                s.iterations_total,
                s.workers_present
            );
        }
        tokio::time::sleep(Duration::from_millis(500)).await;
    };
    if let Some(r) = reporter.as_mut() {
        r.finish();
    }
    match status.state {
        JobState::Done => Ok(()),
        state => bail!(
            "job {id} {}: {}",
            state.as_str(),
            status.message.as_deref().unwrap_or("no message")
        ),
    }
}

/// Downloads a job's latest image to `out` (EXR or PNG by its extension). Of a sequence, every
/// finished frame's: `out` names them as `render --frames` does (`shots/f-####.exr`), or is a
/// folder, which gets `####.exr`. With `denoised`, each image's denoised preview too, beside it
/// (`x.exr` → `x.denoised.exr`).
pub async fn fetch(client: &ApiClient, id: u64, out: &std::path::Path, denoised: bool) -> anyhow::Result<()> {
    let status = client.status(id).await?;
    if status.frames.is_empty() {
        return fetch_images(client, id, out, denoised).await;
    }
    let pattern = if out.is_dir() {
        out.join("####.exr")
    } else {
        out.to_path_buf()
    };
    check_output(&pattern)?;
    let done: Vec<_> = status
        .frames
        .iter()
        .filter(|f| f.state == JobState::Done)
        .collect();
    if done.is_empty() {
        bail!("job {id}: no frame is finished yet");
    }
    for f in &done {
        let out = photonfarm::frames::frame_path(&pattern, f.frame);
        fetch_images(client, f.job, &out, denoised).await?;
    }
    eprintln!("{} of {} frames fetched", done.len(), status.frames.len());
    Ok(())
}

/// Downloads one image, and with `denoised` its denoised preview.
async fn fetch_images(
    client: &ApiClient,
    id: u64,
    out: &std::path::Path,
    denoised: bool,
) -> anyhow::Result<()> {
    check_output(out)?;
    let ext = out
        .extension()
        .and_then(|e| e.to_str())
        .unwrap_or("exr")
        .to_ascii_lowercase();
    let mut files = vec![(format!("image.{ext}"), out.to_path_buf())];
    if denoised {
        files.push((
            format!("image.denoised.{ext}"),
            crate::denoise::denoised_path(out),
        ));
    }
    for (name, path) in files {
        let bytes = client
            .image(id, &name)
            .await
            .with_context(|| format!("job {id}: {name}"))?;
        std::fs::write(&path, bytes).with_context(|| format!("cannot write {}", path.display()))?;
        eprintln!("wrote {}", path.display());
    }
    Ok(())
}

/// One line about a job: id, state, progress, rate, time left, workers.
pub fn describe(s: &JobStatus) -> String {
    let (done, total) = (s.iterations_done, s.iterations_total);
    let mut line = format!(
        "job {}: {}, {done}/{total} passes ({:.1}%), {}x{} {}",
        s.id,
        s.state.as_str(),
        100.0 * done as f64 / total.max(1) as f64,
        s.width,
        s.height,
        s.integrator
    );
    match s.state {
        JobState::Queued if s.workers_present == 0 => {
            line.push_str(": no worker has asked for work");
        }
        JobState::Running if s.rate > 0.0 => {
            line.push_str(&format!(
                ", {:.1} passes/s, {:.0} s left",
                s.rate,
                total.saturating_sub(done) as f64 / s.rate
            ));
        }
        JobState::Failed | JobState::Cancelled => {
            if let Some(m) = &s.message {
                line.push_str(&format!(": {m}"));
            }
        }
        _ => {}
    }
    if !s.workers.is_empty() {
        line.push_str(&format!(", workers: {}", s.workers.join(", ")));
    }
    if !s.frames.is_empty() {
        let done = s.frames.iter().filter(|f| f.state == JobState::Done).count();
        line.push_str(&format!(", {done} of {} frames done", s.frames.len()));
    }
    line
}

/// `coordinator jobs|status|wait|fetch|cancel`.
pub fn run_job_command(command: &crate::cli::JobCommand) -> anyhow::Result<()> {
    use crate::cli::JobCommand;
    let conn = command.connection();
    let client = ApiClient::for_connection(conn)?;
    let rt = tokio::runtime::Runtime::new()?;
    rt.block_on(async {
        match command {
            JobCommand::Jobs(_) => {
                let jobs = client.jobs().await?;
                if jobs.is_empty() {
                    eprintln!("no jobs");
                }
                for j in jobs {
                    println!("{}", describe(&j));
                }
            }
            JobCommand::Status(a) => println!("{}", describe(&client.status(a.id).await?)),
            JobCommand::Wait(a) => {
                wait_for(&client, a.id, a.timeout).await?;
                if let Some(out) = &a.out {
                    fetch(&client, a.id, out, a.denoised).await?;
                }
            }
            JobCommand::Fetch(a) => fetch(&client, a.id, &a.out, a.denoised).await?,
            JobCommand::Cancel(a) => println!("{}", describe(&client.cancel(a.id).await?)),
        }
        Ok(())
    })
}

#[cfg(test)]
mod tests {
    use super::check_address;

    #[test]
    fn the_address_needs_http_or_https() {
        for ok in [
            "http://localhost:8080",
            "https://farm.example.com",
            "http://10.0.0.2:8080/",
        ] {
            assert!(check_address(ok).is_ok(), "{ok}");
        }
        for (bad, example) in [
            ("localhost:8080", "http://localhost:8080"),
            ("render-host", "http://render-host"),
            ("10.0.0.2:8080", "http://10.0.0.2:8080"),
            ("ftp://render-host:8080", "http://render-host:8080"),
            ("", "http://render-host:8080"),
        ] {
            let msg = check_address(bad).unwrap_err().to_string();
            assert_eq!(
                msg,
                format!("--to {bad}: expected an http:// or https:// address, e.g. {example}")
            );
        }
    }
}
