//! `coordinator render` as a user runs it: a real process, real files.

use std::path::{Path, PathBuf};
use std::process::{Command, Output};

fn coordinator() -> Command {
    Command::new(env!("CARGO_BIN_EXE_coordinator"))
}

fn refs() -> PathBuf {
    Path::new(env!("CARGO_MANIFEST_DIR")).join("../tests/refs")
}

fn run(args: &[&str]) -> Output {
    let out = coordinator().args(args).output().expect("the binary runs");
    eprintln!("{}", String::from_utf8_lossy(&out.stderr));
    out
}

#[test]
fn thread_count_does_not_change_the_bytes() {
    let dir = tempfile::tempdir().unwrap();
    let scene = refs().join("cbox-spheres.xml");
    let mut images = Vec::new();
    for threads in ["1", "2"] {
        for ext in ["exr", "png"] {
            let out = dir.path().join(format!("t{threads}.{ext}"));
            let o = run(&[
                "render",
                scene.to_str().unwrap(),
                "--out",
                out.to_str().unwrap(),
                "--spp",
                "3",
                "--seed",
                "5",
                "--threads",
                threads,
                "-D",
                "res=48",
            ]);
            assert!(o.status.success());
            images.push(std::fs::read(&out).unwrap());
        }
    }
    assert!(images[0] == images[2], "EXR bytes differ between 1 and 2 threads");
    assert!(images[1] == images[3], "PNG bytes differ between 1 and 2 threads");
    assert!(
        images[0].starts_with(&[0x76, 0x2f, 0x31, 0x01]),
        "not an OpenEXR file"
    );
    assert!(images[1].starts_with(b"\x89PNG"), "not a PNG file");
    // A different seed is a different image.
    let other = dir.path().join("seed.exr");
    let o = run(&[
        "render",
        scene.to_str().unwrap(),
        "--out",
        other.to_str().unwrap(),
        "--spp",
        "3",
        "--seed",
        "6",
        "-D",
        "res=48",
    ]);
    assert!(o.status.success());
    assert!(std::fs::read(&other).unwrap() != images[0]);
}

#[test]
fn time_limit_renders_whole_passes() {
    let dir = tempfile::tempdir().unwrap();
    let out = dir.path().join("t.exr");
    let scene = refs().join("cbox.xml");
    let o = run(&[
        "render",
        scene.to_str().unwrap(),
        "--out",
        out.to_str().unwrap(),
        "--time-limit",
        "0.5",
        "-D",
        "res=32",
    ]);
    assert!(o.status.success());
    let log = String::from_utf8_lossy(&o.stderr);
    assert!(log.contains("passes)"), "{log}");
    assert!(out.exists());
}

#[test]
fn bad_scene_fails_with_one_line_naming_file_and_line() {
    let dir = tempfile::tempdir().unwrap();
    let scene = dir.path().join("bad.xml");
    std::fs::write(&scene, "<scene version=\"3.0.0\">\n  <shape type=\"sphere\">\n    <float name=\"radius\" value=\"-2\"/>\n  </shape>\n</scene>\n").unwrap();
    let out = dir.path().join("x.exr");
    let o = run(&["render", scene.to_str().unwrap(), "--out", out.to_str().unwrap()]);
    assert!(!o.status.success());
    let err = String::from_utf8_lossy(&o.stderr);
    assert_eq!(err.trim().lines().count(), 1, "{err}");
    assert!(
        err.contains(&format!("{}:3: <float name=\"radius\">", scene.display())),
        "{err}"
    );
    assert!(!err.contains("panicked"), "{err}");
    assert!(!out.exists());
}

#[test]
fn bad_arguments_fail_before_rendering() {
    let scene = refs().join("cbox.xml");
    let s = scene.to_str().unwrap();
    for args in [
        vec!["render", s, "--out", "/tmp/x.jpg"],
        vec!["render", s, "--out", "/nonexistent-dir/x.exr"],
        vec!["render", s, "--out", "/tmp/x.exr", "--spp", "0"],
        vec!["render", s, "--out", "/tmp/x.exr", "--time-limit", "-1"],
        vec!["render", s, "--out", "/tmp/x.exr", "--threads", "0"],
        vec!["render", s, "--out", "/tmp/x.exr", "-D", "novalue"],
        vec!["render", "/nonexistent.xml", "--out", "/tmp/x.exr"],
    ] {
        let o = run(&args);
        assert!(!o.status.success(), "{args:?} should fail");
        let err = String::from_utf8_lossy(&o.stderr);
        assert!(!err.contains("panicked"), "{err}");
    }
}
