//! Checking a submitted scene: load it and resolve the job's settings against it, in a child
//! process with a time limit.
//!
//! Why a child: loading is the one step whose cost the limits can only bound indirectly (a
//! scene's file sizes bound its memory, not its CPU: a thousand rough plastics each tabulate
//! their albedo), and it runs a large parser on untrusted input. In a child process, a scene
//! that takes too long is killed at the time limit, and a loader failure of any kind (a panic,
//! an allocation failure, a stack overflow, the kernel's OOM killer) ends the child, never the
//! coordinator. The child is this same program (`coordinator check-scene`, hidden).

use std::path::{Path, PathBuf};
use std::time::{Duration, Instant};

use photonfarm::job::JobSettings;
use photonfarm::render::RenderSettings;
use photonfarm::scene::Scene;
use serde::{Deserialize, Serialize};

/// What the coordinator needs to know about a checked scene.
#[derive(Clone, Debug, Serialize, Deserialize)]
pub struct Checked {
    /// Image width.
    pub width: u32,
    /// Image height.
    pub height: u32,
    /// Passes of the job.
    pub total: u64,
    /// What workers will run.
    pub render: RenderSettings,
    /// The loader's and the resolution's warnings.
    pub warnings: Vec<String>,
}

/// Why a scene was not accepted.
#[derive(Debug, thiserror::Error)]
pub enum CheckError {
    /// The scene or the settings are wrong (the loader's message).
    #[error("{0}")]
    Refused(String),
    /// The check took longer than the limit.
    #[error("checking the scene took longer than {0} s, the limit (--scene-check-timeout)")]
    TooLong(u64),
    /// The checker died (out of memory, a crash in the loader).
    #[error("the scene could not be loaded: the loader stopped ({0})")]
    Crashed(String),
    /// The checker could not be run.
    #[error("cannot run the scene checker: {0}")]
    Internal(String),
}

/// Loads the scene, whose every file must lie inside `root` (the job's bundle), and resolves
/// the settings, in this process.
pub fn check(scene: &Path, root: &Path, settings: &JobSettings) -> Result<Checked, String> {
    let loaded = Scene::load_inside(scene, &settings.defines, root).map_err(|e| e.to_string())?;
    let resolved = settings.resolve(&loaded, false).map_err(|e| e.to_string())?;
    Ok(Checked {
        width: loaded.width(),
        height: loaded.height(),
        total: resolved.passes.expect("closed-ended resolution has a count"),
        render: resolved.render,
        warnings: loaded.warnings,
    })
}

/// How the child reports: one JSON file.
#[derive(Serialize, Deserialize)]
enum Report {
    Ok(Checked),
    Refused(String),
}

/// `coordinator check-scene`: runs [`check`] and writes its report to `out`.
pub fn run_child(scene: &Path, root: &Path, settings: &str, out: &Path) -> anyhow::Result<()> {
    let settings: JobSettings = serde_json::from_str(settings)?;
    let report = match check(scene, root, &settings) {
        Ok(c) => Report::Ok(c),
        Err(e) => Report::Refused(e),
    };
    std::fs::write(out, serde_json::to_vec(&report)?)?;
    Ok(())
}

/// Runs the check in a child process of `program` (this coordinator's executable), killing it
/// after `timeout`. Blocks: call it from a blocking thread.
pub fn check_in_child(
    program: &Path,
    scene: &Path,
    root: &Path,
    settings: &JobSettings,
    scratch: &Path,
    timeout: Duration,
) -> Result<Checked, CheckError> {
    let out: PathBuf = scratch.join("check.json");
    let settings = serde_json::to_string(settings).expect("settings serialise");
    let mut child = std::process::Command::new(program)
        .arg("check-scene")
        .arg(scene)
        .arg("--root")
        .arg(root)
        .arg("--settings")
        .arg(&settings)
        .arg("--out")
        .arg(&out)
        .stdin(std::process::Stdio::null())
        .stdout(std::process::Stdio::null())
        .stderr(std::process::Stdio::null())
        .spawn()
        .map_err(|e| CheckError::Internal(e.to_string()))?;
    let start = Instant::now();
    let status = loop {
        match child.try_wait() {
            Ok(Some(status)) => break status,
            Ok(None) if start.elapsed() > timeout => {
                let _ = child.kill();
                let _ = child.wait();
                return Err(CheckError::TooLong(timeout.as_secs()));
            }
            Ok(None) => std::thread::sleep(Duration::from_millis(5)),
            Err(e) => return Err(CheckError::Internal(e.to_string())),
        }
    };
    if !status.success() {
        return Err(CheckError::Crashed(status.to_string()));
    }
    let bytes = std::fs::read(&out).map_err(|e| CheckError::Internal(e.to_string()))?;
    match serde_json::from_slice(&bytes).map_err(|e| CheckError::Internal(e.to_string()))? {
        Report::Ok(c) => Ok(c),
        Report::Refused(e) => Err(CheckError::Refused(e)),
    }
}
