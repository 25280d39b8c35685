//! Starting the real programs for the farm's tests and benchmark.
#![allow(dead_code)]

pub mod api;

use std::io::{BufRead, BufReader};
use std::path::{Path, PathBuf};
use std::process::{Child, Command, Stdio};

/// A child process killed when dropped, whatever happens to the test.
pub struct Proc(pub Child);

impl Drop for Proc {
    fn drop(&mut self) {
        let _ = self.0.kill();
        let _ = self.0.wait();
    }
}

impl Proc {
    /// Kills the process with SIGKILL and waits for it.
    pub fn sigkill(&mut self) {
        self.0.kill().unwrap();
        self.0.wait().unwrap();
    }
}

/// A loopback address with a free port, for a coordinator that must come back on the same
/// address after a restart (so its workers find it again).
pub fn fixed_loopback_address() -> String {
    let port = std::net::TcpListener::bind("127.0.0.1:0")
        .unwrap()
        .local_addr()
        .unwrap()
        .port();
    format!("127.0.0.1:{port}")
}

/// The coordinator binary.
pub fn coordinator_bin() -> PathBuf {
    PathBuf::from(env!("CARGO_BIN_EXE_coordinator"))
}

/// The worker binary, built beside the coordinator by `cargo test --workspace`.
pub fn worker_bin() -> PathBuf {
    let p = coordinator_bin().with_file_name("worker");
    assert!(
        p.exists(),
        "{} is missing: run `cargo test --workspace` (or build the worker)",
        p.display()
    );
    p
}

/// The shared Cornell box with spheres.
pub fn cbox_spheres() -> PathBuf {
    Path::new(env!("CARGO_MANIFEST_DIR")).join("../tests/refs/cbox-spheres.xml")
}

/// Starts `coordinator serve` with extra flags and environment; returns it and its URL.
pub fn serve(data: &Path, bind: &str, extra: &[&str], env: &[(&str, &str)]) -> (Proc, String) {
    serve_limited(data, bind, extra, env, None)
}

/// [`serve`] with the operating system capping the coordinator's address space at
/// `address_space_mb` (util-linux's `prlimit --as`): past it, allocations fail.
pub fn serve_limited(
    data: &Path,
    bind: &str,
    extra: &[&str],
    env: &[(&str, &str)],
    address_space_mb: Option<u64>,
) -> (Proc, String) {
    let mut command = match address_space_mb {
        Some(mb) => {
            let mut c = Command::new("prlimit");
            c.arg(format!("--as={}", mb << 20))
                .arg("--")
                .arg(coordinator_bin());
            c
        }
        None => Command::new(coordinator_bin()),
    };
    command
        .args(["serve", "--bind", bind, "--data", data.to_str().unwrap()])
        .args(extra)
        .envs(env.iter().copied())
        .stderr(log_file(&data.with_extension("log")));
    announced_logging(command)
}

/// A log file beside a test's files, appended to (a restarted program adds to its log).
fn log_file(path: &Path) -> std::fs::File {
    if let Some(parent) = path.parent() {
        std::fs::create_dir_all(parent).unwrap();
    }
    std::fs::OpenOptions::new()
        .create(true)
        .append(true)
        .open(path)
        .unwrap()
}

/// The last lines of every `*.log` in `dir` (the coordinators' and workers' logs that
/// [`serve`] and [`worker`] keep there), for a failing test to show what the programs said.
pub fn logs(dir: &Path) -> String {
    let mut names: Vec<PathBuf> = std::fs::read_dir(dir)
        .into_iter()
        .flatten()
        .flatten()
        .map(|e| e.path())
        .filter(|p| p.extension().is_some_and(|e| e == "log"))
        .collect();
    names.sort();
    let mut out = String::new();
    for p in names {
        let text = std::fs::read_to_string(&p).unwrap_or_default();
        let lines: Vec<&str> = text.lines().collect();
        out += &format!("--- {} (last 40 lines)\n", p.display());
        for l in &lines[lines.len().saturating_sub(40)..] {
            out += l;
            out += "\n";
        }
    }
    out
}

/// Starts a `coordinator serve` or `coordinator relay` command and returns it with the URL its
/// first line announces ("listening on URL").
pub fn announced(mut command: Command) -> (Proc, String) {
    command.stderr(Stdio::null());
    announced_logging(command)
}

/// [`announced`] with the command's stderr as it was set (a log file).
/// Waits at most two minutes for the line: a service that never comes up fails the test (and
/// is killed) instead of holding up the whole run.
fn announced_logging(mut command: Command) -> (Proc, String) {
    let mut child = command.stdout(Stdio::piped()).spawn().unwrap();
    let stdout = child.stdout.take().unwrap();
    let child = Proc(child);
    let (tx, rx) = std::sync::mpsc::channel();
    std::thread::spawn(move || {
        let mut line = String::new();
        let _ = BufReader::new(stdout).read_line(&mut line);
        let _ = tx.send(line);
    });
    let line = rx
        .recv_timeout(std::time::Duration::from_secs(120))
        .expect("the service did not announce its address within 120 s");
    let url = line
        .trim()
        .strip_prefix("listening on ")
        .expect("the service announces its address")
        .to_string();
    (child, url)
}

/// Starts a one-thread worker named `name`, caching bundles under `cache`.
pub fn worker(url: &str, name: &str, cache: &Path) -> Proc {
    worker_with_env(url, name, cache, &[])
}

/// [`worker`] with extra environment (a token).
pub fn worker_with_env(url: &str, name: &str, cache: &Path, env: &[(&str, &str)]) -> Proc {
    Proc(
        Command::new(worker_bin())
            .args(["--coordinator", url, "--threads", "1", "--name", name, "--cache"])
            .arg(cache.join(name))
            .envs(env.iter().copied())
            .stdout(Stdio::null())
            .stderr(log_file(&cache.join(format!("{name}.log"))))
            .spawn()
            .unwrap(),
    )
}

/// `GET url + path` with a bearer token, as JSON: the tests' read-only look at the API.
pub async fn get_json(url: &str, path: &str, token: &str) -> serde_json::Value {
    reqwest::Client::new()
        .get(format!("{url}{path}"))
        .bearer_auth(token)
        .send()
        .await
        .unwrap()
        .json()
        .await
        .unwrap()
}
