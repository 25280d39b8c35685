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

/// The lane engine (cbox: diffuse triangles) pinned to each instruction set this machine has,
/// on 1 and 2 threads: the same EXR bytes; a backend the machine cannot run, or no backend,
/// is refused before rendering.
#[test]
fn every_simd_backend_gives_the_same_bytes() {
    let dir = tempfile::tempdir().unwrap();
    let scene = refs().join("cbox.xml");
    let render = |simd: &str, threads: &str| {
        let out = dir.path().join(format!("{simd}-{threads}.exr"));
        let o = coordinator()
            .env("PHOTONFARM_SIMD", simd)
            .args(["render", scene.to_str().unwrap(), "--out", out.to_str().unwrap()])
            .args(["--spp", "3", "--seed", "5", "--threads", threads, "-D", "res=40"])
            .output()
            .unwrap();
        (o, out)
    };
    // The scene must be one the lane engine models, or this would test the scalar tracer.
    let loaded = photonfarm::scene::Scene::load(&scene, &[]).unwrap();
    let path = photonfarm::integrator::path::PathSettings::from_scene(&loaded);
    assert!(photonfarm::engine::path::LaneScene::new(&loaded, &path).is_ok());
    let available = photonfarm::engine::Backend::available();
    let mut first: Option<Vec<u8>> = None;
    for b in &available {
        for threads in ["1", "2"] {
            let (o, out) = render(b.name(), threads);
            assert!(o.status.success(), "{b}: {}", String::from_utf8_lossy(&o.stderr));
            let bytes = std::fs::read(&out).unwrap();
            match &first {
                None => first = Some(bytes),
                Some(f) => assert!(*f == bytes, "{b} on {threads} threads gives other bytes"),
            }
        }
    }
    for bad in ["neon", "avx1024"] {
        let (o, out) = render(bad, "1");
        assert!(!o.status.success());
        let err = String::from_utf8_lossy(&o.stderr);
        assert!(
            err.contains(&format!("PHOTONFARM_SIMD={bad}")) && err.contains("this machine has: sse2"),
            "{err}"
        );
        assert!(!out.exists());
    }
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
    assert!(log.contains(" passes in "), "{log}");
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

#[test]
fn sppm_bytes_do_not_depend_on_threads_and_checkpoints_match_shorter_renders() {
    let dir = tempfile::tempdir().unwrap();
    let scene = refs().join("cbox-spheres.xml");
    let render = |threads: &str, iterations: &str, out: &Path, extra: &[&str]| {
        let mut args = vec![
            "render",
            scene.to_str().unwrap(),
            "--integrator",
            "sppm",
            "--out",
            out.to_str().unwrap(),
            "--iterations",
            iterations,
            "--photons",
            "4000",
            "--threads",
            threads,
            "-D",
            "res=40",
        ];
        args.extend_from_slice(extra);
        let o = run(&args);
        assert!(o.status.success());
    };
    let one = dir.path().join("one.exr");
    let two = dir.path().join("two.exr");
    render("1", "6", &one, &["--checkpoint-every", "2"]);
    render("2", "6", &two, &[]);
    assert!(
        std::fs::read(&one).unwrap() == std::fs::read(&two).unwrap(),
        "SPPM bytes depend on threads"
    );
    // Checkpoints at 2 and 4 equal renders of 2 and 4 iterations.
    for n in [2, 4] {
        let cp = dir.path().join(format!("one-{n:06}.exr"));
        let short = dir.path().join(format!("short{n}.exr"));
        render("2", &n.to_string(), &short, &[]);
        assert!(
            std::fs::read(&cp).unwrap() == std::fs::read(&short).unwrap(),
            "checkpoint {n}"
        );
    }
    // The last checkpoint coincides with the final image.
    assert!(std::fs::read(dir.path().join("one-000006.exr")).unwrap() == std::fs::read(&one).unwrap());
}

#[test]
fn bad_sppm_parameters_fail_clearly() {
    let scene = refs().join("cbox.xml");
    let s = scene.to_str().unwrap();
    for (flags, needle) in [
        (vec!["--alpha", "1.5"], "alpha must lie strictly between 0 and 1"),
        (vec!["--alpha", "0"], "alpha must lie strictly between 0 and 1"),
        (
            vec!["--photons", "0"],
            "photon count per iteration must be at least 1",
        ),
        (
            vec!["--radius", "-0.1"],
            "initial radius must be a positive number",
        ),
        (vec!["--k", "0.5"], "k must be at least 1"),
        (vec!["--spp", "4"], "use --iterations"),
    ] {
        let mut args = vec!["render", s, "--integrator", "sppm", "--out", "/tmp/never.exr"];
        args.extend(flags);
        let o = run(&args);
        assert!(!o.status.success());
        let err = String::from_utf8_lossy(&o.stderr);
        assert!(err.contains(needle), "expected \"{needle}\" in {err}");
    }
    let o = run(&[
        "render",
        s,
        "--out",
        "/tmp/never.exr",
        "--integrator",
        "path",
        "--photons",
        "5",
    ]);
    assert!(!o.status.success());
    assert!(String::from_utf8_lossy(&o.stderr).contains("--photons applies to --integrator sppm"));
    // Without --integrator the scene's <integrator> (path here) decides, and says so.
    let o = run(&["render", s, "--out", "/tmp/never.exr", "--photons", "5"]);
    assert!(!o.status.success());
    let err = String::from_utf8_lossy(&o.stderr);
    assert!(
        err.contains("photons applies to the sppm integrator only"),
        "{err}"
    );
}

/// Issue 11: sizes that used to abort `coordinator render` (a 103 GB film, a stack overflow on
/// deep XML, a radius schedule of 8 TB) are clear errors with exit status 1.
#[test]
fn oversized_jobs_are_clear_errors_not_aborts() {
    let dir = tempfile::tempdir().unwrap();
    let write = |name: &str, text: String| {
        let p = dir.path().join(name);
        std::fs::write(&p, text).unwrap();
        p
    };
    let film = |w: u32| {
        format!(
            r#"<scene version="3.0.0"><sensor type="perspective"><film type="hdrfilm">
            <integer name="width" value="{w}"/><integer name="height" value="{w}"/><rfilter type="box"/>
            </film></sensor><emitter type="point"><point name="position" x="0" y="0" z="0"/></emitter></scene>"#
        )
    };
    let huge = write("huge.xml", film(65536));
    let small = write("small.xml", film(8));
    let deep = write(
        "deep.xml",
        format!(
            "<scene version=\"3.0.0\">{}{}</scene>",
            "<shape>".repeat(5000),
            "</shape>".repeat(5000)
        ),
    );
    let out = dir.path().join("out.exr");
    let out = out.to_str().unwrap();
    for (scene, extra, needle) in [
        (&huge, &[][..], "--max-pixels"),
        (&deep, &[][..], "deeper than"),
        (
            &small,
            &["--integrator", "sppm", "--iterations", "1000000000000"][..],
            "--max-passes",
        ),
        (
            &small,
            &["--integrator", "sppm", "--photons", "1000000000000"][..],
            "--max-photons",
        ),
    ] {
        let mut args = vec!["render", scene.to_str().unwrap(), "--out", out];
        args.extend_from_slice(extra);
        let o = run(&args);
        let err = String::from_utf8_lossy(&o.stderr);
        assert_eq!(o.status.code(), Some(1), "{err}");
        assert!(err.contains(needle), "{err}");
    }
}

/// Ctrl-c (SIGINT) keeps the work done: the render stops after the batch under way, writes the
/// image of every finished pass, says how many, exits non-zero, and the image has the bytes of
/// a render of exactly that many passes.
#[test]
fn sigint_writes_the_finished_passes() {
    let dir = tempfile::tempdir().unwrap();
    let scene = refs().join("cbox.xml");
    let out = dir.path().join("interrupted.exr");
    let child = coordinator()
        .args([
            "render",
            scene.to_str().unwrap(),
            "-D",
            "res=24",
            "--spp",
            "1000000",
        ])
        .args(["--threads", "1", "--out", out.to_str().unwrap()])
        .stderr(std::process::Stdio::piped())
        .spawn()
        .unwrap();
    std::thread::sleep(std::time::Duration::from_millis(1500));
    let kill = Command::new("kill")
        .args(["-INT", &child.id().to_string()])
        .status()
        .unwrap();
    assert!(kill.success());
    let o = child.wait_with_output().unwrap();
    let err = String::from_utf8_lossy(&o.stderr);
    assert!(
        !o.status.success(),
        "an interrupted render is not a finished one: {err}"
    );
    let passes: u64 = err
        .split("holds the ")
        .nth(1)
        .and_then(|rest| rest.split(' ').next())
        .and_then(|n| n.parse().ok())
        .unwrap_or_else(|| panic!("no pass count in: {err}"));
    assert!(passes > 0, "{err}");
    let again = dir.path().join("again.exr");
    let o = run(&[
        "render",
        scene.to_str().unwrap(),
        "-D",
        "res=24",
        "--spp",
        &passes.to_string(),
        "--out",
        again.to_str().unwrap(),
    ]);
    assert!(o.status.success(), "{}", String::from_utf8_lossy(&o.stderr));
    assert!(
        std::fs::read(&out).unwrap() == std::fs::read(&again).unwrap(),
        "the interrupted image is not the image of its {passes} passes"
    );
}

/// A render killed outright (SIGKILL: no chance to write anything) continues with `--resume`
/// from the sums it saved while running, and ends with the bytes of one uninterrupted render;
/// a changed scene setting is refused instead of mixed in.
#[test]
fn resume_after_sigkill_gives_the_uninterrupted_bytes() {
    let dir = tempfile::tempdir().unwrap();
    let scene = refs().join("cbox.xml");
    let out = dir.path().join("resumed.exr");
    let sums = dir.path().join("resumed.exr.resume");
    let spp = "6000";
    let render = |extra: &[&str], out: &std::path::Path| {
        let mut c = coordinator();
        c.args(["render", scene.to_str().unwrap(), "-D", "res=24", "--spp", spp])
            .args(["--threads", "1", "--out", out.to_str().unwrap()])
            .args(extra);
        c
    };
    let mut child = render(&["--save-every", "0.2"], &out)
        .stderr(std::process::Stdio::null())
        .spawn()
        .unwrap();
    let start = std::time::Instant::now();
    while !sums.exists() {
        assert!(start.elapsed().as_secs() < 60, "no sums saved within 60 s");
        assert!(
            child.try_wait().unwrap().is_none(),
            "the render ended before it was killed"
        );
        std::thread::sleep(std::time::Duration::from_millis(50));
    }
    std::thread::sleep(std::time::Duration::from_millis(300));
    child.kill().unwrap();
    child.wait().unwrap();
    assert!(!out.exists(), "a killed render wrote no image");

    // Another scene setting is refused, and the sums stay.
    let o = render(&["--resume"], &out)
        .args(["--seed", "7"])
        .output()
        .unwrap();
    assert!(!o.status.success());
    let err = String::from_utf8_lossy(&o.stderr);
    assert!(err.contains("different scene or settings"), "{err}");
    assert!(sums.exists());

    // Fewer passes than the sums already hold cannot be given back.
    let o = coordinator()
        .args(["render", scene.to_str().unwrap(), "-D", "res=24", "--spp", "1"])
        .args(["--threads", "1", "--out", out.to_str().unwrap(), "--resume"])
        .output()
        .unwrap();
    assert!(!o.status.success());
    let err = String::from_utf8_lossy(&o.stderr);
    assert!(err.contains("more than the 1 asked for"), "{err}");

    let o = render(&["--resume"], &out).output().unwrap();
    let err = String::from_utf8_lossy(&o.stderr);
    assert!(o.status.success(), "{err}");
    let done: u64 = err
        .split("resuming from ")
        .nth(1)
        .and_then(|rest| rest.split(" (").nth(1))
        .and_then(|rest| rest.split(' ').next())
        .and_then(|n| n.parse().ok())
        .unwrap_or_else(|| panic!("no resumed pass count in: {err}"));
    assert!(done > 0 && done < 6000, "resumed at {done}: {err}");
    assert!(!sums.exists(), "a finished render leaves no sums behind");

    let whole = dir.path().join("whole.exr");
    let o = render(&[], &whole).output().unwrap();
    assert!(o.status.success(), "{}", String::from_utf8_lossy(&o.stderr));
    assert!(
        std::fs::read(&out).unwrap() == std::fs::read(&whole).unwrap(),
        "the resumed render (killed after {done} passes) is not the uninterrupted one"
    );
}

/// `--frames` renders a sequence: one file per frame under Blender's `#` padding, each frame
/// with its ramped parameters and its own seed. A frame rendered alone (a one-frame list, the
/// ramp's value at that frame) has the bytes of the same frame in the sequence; `--resume`
/// skips the frames that are done; a bad list fails before anything renders.
#[test]
fn a_frame_sequence_ramps_parameters_and_each_frame_renders_alone_to_the_same_bytes() {
    let dir = tempfile::tempdir().unwrap();
    let scene = Path::new(env!("CARGO_MANIFEST_DIR")).join("../scenes/turntable.xml");
    let scene = scene.to_str().unwrap();
    let render = |frames: &str, angle: &str, roll: &str, out: &str, extra: &[&str]| {
        let out = dir.path().join(out);
        let mut args = vec![
            "render",
            scene,
            "--frames",
            frames,
            "--out",
            out.to_str().unwrap(),
            "--spp",
            "2",
            "--seed",
            "9",
            "-D",
            "res=24",
            "-D",
            angle,
            "-D",
            roll,
        ];
        args.extend_from_slice(extra);
        run(&args)
    };
    let o = render("1-3", "angle=-20:20", "roll=-0.5:0.4", "seq-##.exr", &[]);
    assert!(o.status.success());
    let frame = |name: &str| std::fs::read(dir.path().join(name)).unwrap();
    let seq: Vec<Vec<u8>> = ["seq-01.exr", "seq-02.exr", "seq-03.exr"].map(frame).to_vec();
    assert!(
        seq[0] != seq[1] && seq[1] != seq[2],
        "the frames are not animated"
    );
    // Frame 2 alone: angle and roll at their midpoints (0 and -0.05), the sequence's seed.
    let alone = |angle: &str, roll: &str| {
        assert!(render("2", angle, roll, "alone.exr", &[]).status.success());
        frame("alone0002.exr")
    };
    assert!(
        alone("angle=0", "roll=-0.05") == seq[1],
        "frame 2 alone differs from the sequence's"
    );
    assert!(
        alone("angle=1", "roll=-0.05") != seq[1],
        "the angle changes nothing"
    );
    // --resume: every frame is done, so nothing renders again.
    let o = render(
        "1-3",
        "angle=-20:20",
        "roll=-0.5:0.4",
        "seq-##.exr",
        &["--resume"],
    );
    assert!(o.status.success());
    let log = String::from_utf8_lossy(&o.stderr);
    assert_eq!(log.matches("is done").count(), 3, "{log}");
    // Errors before any rendering.
    for (frames, angle, why) in [
        ("3-1", "angle=0", "runs backwards"),
        ("1-3", "angle=0:x", "two numbers"),
    ] {
        let o = render(frames, angle, "roll=0", "bad-#.exr", &[]);
        assert!(!o.status.success());
        let log = String::from_utf8_lossy(&o.stderr);
        assert!(log.contains(why), "{log}");
        assert!(!log.contains("rendering"), "{log}");
    }
}
