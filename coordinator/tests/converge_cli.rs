//! `coordinator converge` as a user runs it: CSV, PNG and SVG, per method and per swept value.

use std::path::Path;
use std::process::Command;

fn coordinator() -> Command {
    Command::new(env!("CARGO_BIN_EXE_coordinator"))
}

#[test]
fn writes_the_csv_and_both_charts_with_one_line_per_method_and_value() {
    let dir = tempfile::tempdir().unwrap();
    let scene = Path::new(env!("CARGO_MANIFEST_DIR")).join("../tests/refs/cbox.xml");
    let reference = dir.path().join("ref.exr");
    let o = coordinator()
        .args([
            "render",
            scene.to_str().unwrap(),
            "--spp",
            "2048",
            "-D",
            "res=24",
            "--out",
        ])
        .arg(&reference)
        .output()
        .unwrap();
    assert!(o.status.success());
    let out = dir.path().join("conv");
    let o = coordinator()
        .args(["converge", scene.to_str().unwrap(), "--reference"])
        .arg(&reference)
        .args([
            "--methods",
            "path,sppm",
            "--alpha",
            "0.5,0.8",
            "--photons",
            "5000",
            "--time-limit",
            "0.6",
        ])
        .args(["-D", "res=24", "--out-dir"])
        .arg(&out)
        .output()
        .unwrap();
    assert!(o.status.success(), "{}", String::from_utf8_lossy(&o.stderr));
    let csv = std::fs::read_to_string(out.join("convergence.csv")).unwrap();
    let mut lines = csv.lines();
    assert_eq!(
        lines.next(),
        Some("method,seconds,passes,rmse,worst_channel_mean_error")
    );
    let rows: Vec<Vec<&str>> = lines.map(|l| l.split(',').collect()).collect();
    for name in ["path", "sppm alpha=0.5", "sppm alpha=0.8"] {
        let line: Vec<&Vec<&str>> = rows.iter().filter(|r| r[0] == name).collect();
        assert!(line.len() >= 3, "{name}: {csv}");
        let secs: Vec<f64> = line.iter().map(|r| r[1].parse().unwrap()).collect();
        let passes: Vec<u64> = line.iter().map(|r| r[2].parse().unwrap()).collect();
        let rmse: Vec<f64> = line.iter().map(|r| r[3].parse().unwrap()).collect();
        assert!(secs.windows(2).all(|w| w[0] < w[1]) && passes.windows(2).all(|w| w[0] < w[1]));
        assert!(*secs.last().unwrap() >= 0.6);
        assert!(rmse.iter().all(|e| e.is_finite() && *e > 0.0));
        assert!(
            rmse.last().unwrap() < &rmse[0],
            "{name}: the error should fall over the run"
        );
    }
    assert!(
        std::fs::read(out.join("convergence.png"))
            .unwrap()
            .starts_with(b"\x89PNG")
    );
    let svg = std::fs::read_to_string(out.join("convergence.svg")).unwrap();
    assert!(svg.contains("<svg") && svg.contains("sppm alpha=0.8"));
}

#[test]
fn bad_requests_fail_clearly() {
    let dir = tempfile::tempdir().unwrap();
    let scene = Path::new(env!("CARGO_MANIFEST_DIR")).join("../tests/refs/cbox.xml");
    let reference = Path::new(env!("CARGO_MANIFEST_DIR")).join("../tests/refs/cbox.exr");
    for (extra, needle) in [
        (
            vec!["-D", "res=32"],
            "the reference is 256x256 but the scene renders 32x32",
        ),
        (
            vec!["--alpha", "0.5,0.6", "--radius", "0.1,0.2"],
            "sweep one setting at a time",
        ),
        (vec!["--methods", "bdpt"], "unknown method"),
    ] {
        let o = coordinator()
            .args([
                "converge",
                scene.to_str().unwrap(),
                "--reference",
                reference.to_str().unwrap(),
            ])
            .args(["--time-limit", "0.2", "--out-dir"])
            .arg(dir.path())
            .args(extra)
            .output()
            .unwrap();
        assert!(!o.status.success());
        let err = String::from_utf8_lossy(&o.stderr);
        assert!(err.contains(needle), "expected \"{needle}\" in {err}");
    }
}
