//! The job commands against a real coordinator and worker: `jobs`, `status` (saying when no
//! worker has asked for work), `wait --out` and `--timeout`, `fetch` and `cancel`.

mod support;

use std::process::{Command, Output};

use support::{cbox_spheres, coordinator_bin, serve, worker};

fn coordinator(args: &[&str]) -> Output {
    let o = Command::new(coordinator_bin()).args(args).output().unwrap();
    eprintln!("{}", String::from_utf8_lossy(&o.stderr));
    o
}

fn submit(url: &str, spp: &str) -> String {
    let scene = cbox_spheres();
    let o = coordinator(&[
        "submit",
        "--to",
        url,
        scene.to_str().unwrap(),
        "--spp",
        spp,
        "-D",
        "res=16",
    ]);
    assert!(o.status.success());
    String::from_utf8_lossy(&o.stdout).trim().to_string()
}

#[test]
fn jobs_status_wait_fetch_and_cancel() {
    let dir = tempfile::tempdir().unwrap();
    let (_c, url) = serve(
        &dir.path().join("data"),
        "127.0.0.1:0",
        &["--batch-seconds", "0.2"],
        &[],
    );
    let id = submit(&url, "8");
    // No worker yet: the job is queued, and status says why.
    let o = coordinator(&["status", &id, "--to", &url]);
    let out = String::from_utf8_lossy(&o.stdout);
    assert!(
        o.status.success() && out.contains("queued") && out.contains("no worker has asked for work"),
        "{out}"
    );
    let o = coordinator(&["jobs", "--to", &url]);
    assert!(String::from_utf8_lossy(&o.stdout).contains(&format!("job {id}: queued")));
    // Waiting with a timeout on a job nobody renders gives up, says how far it got, and leaves
    // the job as it was.
    let o = coordinator(&["wait", &id, "--to", &url, "--timeout", "1.5"]);
    let err = String::from_utf8_lossy(&o.stderr);
    assert!(
        !o.status.success() && err.contains("still queued after 1.5 s (0 of 8 passes done"),
        "{err}"
    );
    let o = coordinator(&["wait", &id, "--to", &url, "--timeout", "0"]);
    assert!(String::from_utf8_lossy(&o.stderr).contains("expected a positive number of seconds"));

    let _w = worker(&url, "w1", dir.path());
    let image = dir.path().join("waited.exr");
    let o = coordinator(&[
        "wait",
        &id,
        "--to",
        &url,
        "--out",
        image.to_str().unwrap(),
        "--timeout",
        "300",
    ]);
    assert!(o.status.success());
    let png = dir.path().join("fetched.png");
    let o = coordinator(&["fetch", &id, "--to", &url, "--out", png.to_str().unwrap()]);
    assert!(o.status.success());
    assert!(std::fs::metadata(&image).unwrap().len() > 0 && std::fs::metadata(&png).unwrap().len() > 0);
    let o = coordinator(&["status", &id, "--to", &url]);
    assert!(String::from_utf8_lossy(&o.stdout).contains("done, 8/8 passes"));

    // A long job, cancelled; waiting on it then fails with its state.
    let long = submit(&url, "1000000");
    let o = coordinator(&["cancel", &long, "--to", &url]);
    assert!(o.status.success() && String::from_utf8_lossy(&o.stdout).contains("cancelled"));
    let o = coordinator(&["wait", &long, "--to", &url, "--timeout", "300"]);
    assert!(!o.status.success() && String::from_utf8_lossy(&o.stderr).contains("cancelled"));
    // An unknown job is a clear error.
    let o = coordinator(&["status", "999", "--to", &url]);
    assert!(!o.status.success() && String::from_utf8_lossy(&o.stderr).contains("404"));
}

/// An address without `http://` is refused at once with an example, by `submit` and by the job
/// commands alike (it used to say "relative URL without a base").
#[test]
fn an_address_without_a_scheme_says_what_is_expected() {
    let scene = cbox_spheres();
    for args in [
        &["submit", "--to", "localhost:8080", scene.to_str().unwrap()][..],
        &["jobs", "--to", "localhost:8080"],
        &["status", "1", "--to", "localhost:8080"],
    ] {
        let o = coordinator(args);
        assert_eq!(o.status.code(), Some(1), "{args:?}");
        let err = String::from_utf8_lossy(&o.stderr);
        assert!(
            err.contains(
                "--to localhost:8080: expected an http:// or https:// address, e.g. http://localhost:8080"
            ),
            "{args:?}: {err}"
        );
    }
}
