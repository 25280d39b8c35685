//! `coordinator render --resume`: the exact sums of a render, saved beside its output so that an
//! interrupted or killed render continues where it stopped and ends with the bytes of an
//! uninterrupted one.
//!
//! The image alone cannot do that: it is rounded to float and divided by the pass count, while
//! the sums are exact fixed point. The file also carries a fingerprint of everything that decides
//! the pixels (scene files, defines, seed, method and its parameters), so a changed scene or
//! setting is refused instead of silently mixed in. What does not change the pixels (threads,
//! pass count, time limit, checkpoints) may change between runs: `--spp 2048 --resume` after a
//! finished 1024-pass render adds 1024 passes.
//!
//! The sums carry their SHA-256, so a file damaged or edited by hand is refused rather than
//! mixed in (a deliberate forger can recompute it: the file is the user's own, and the
//! checksum guards against accidents, not against its owner).

use std::path::{Path, PathBuf};

use anyhow::{Context, bail};
use photonfarm::features::Features;
use photonfarm::film::FilmSum;
use photonfarm::protocol::{decode_batch, encode_batch};
use photonfarm::render::RenderSettings;
use photonfarm::scene::Scene;
use sha2::Digest;

use crate::service::store::write_durably;

/// First line of a resume file, before the fingerprint and the sums' checksum.
const HEADER: &str = "photonfarm-resume 2 ";
/// The first line of files saved before the checksum: still read.
const HEADER_V1: &str = "photonfarm-resume 1 ";

/// The sums file of output `out`: `out.exr` → `out.exr.resume`.
pub fn path_for(out: &Path) -> PathBuf {
    let mut name = out.file_name().unwrap_or_default().to_os_string();
    name.push(".resume");
    let path = out.with_file_name(name);
    if path.parent().is_some_and(|p| p.as_os_str().is_empty()) {
        Path::new(".").join(path)
    } else {
        path
    }
}

/// What decides the pixels of a render: the scene's files, byte for byte, the defines and the
/// resolved render settings.
pub fn fingerprint(
    scene_path: &Path,
    scene: &Scene,
    defines: &[(String, String)],
    settings: &RenderSettings,
) -> anyhow::Result<String> {
    let mut hash = sha2::Sha256::new();
    for file in std::iter::once(scene_path).chain(scene.files.iter().map(PathBuf::as_path)) {
        let bytes = std::fs::read(file).with_context(|| format!("cannot read {}", file.display()))?;
        hash.update((bytes.len() as u64).to_le_bytes());
        hash.update(&bytes);
    }
    for (k, v) in defines {
        hash.update(format!("-D{k:?}={v:?}\n").as_bytes());
    }
    hash.update(serde_json::to_vec(settings)?);
    hash.update(format!("{}x{}", scene.width(), scene.height()).as_bytes());
    Ok(hex::encode(hash.finalize()))
}

/// Saves the sums atomically (a kill while saving leaves the previous file whole).
pub fn save(path: &Path, fingerprint: &str, sum: &FilmSum) -> anyhow::Result<()> {
    let sums = encode_batch(sum);
    let checksum = hex::encode(sha2::Sha256::digest(&sums));
    let mut bytes = format!("{HEADER}{fingerprint} {checksum}\n").into_bytes();
    bytes.extend(sums);
    write_durably(path, &bytes).with_context(|| format!("cannot save {}", path.display()))
}

/// The file of feature `name` beside sums file `sums`: `out.exr.resume.albedo`.
fn features_path(sums: &Path, name: &str) -> PathBuf {
    let mut p = sums.as_os_str().to_os_string();
    p.push(format!(".{name}"));
    PathBuf::from(p)
}

/// Saves a render's features beside its sums file `sums`, one file per sum.
pub fn save_features(sums: &Path, fingerprint: &str, features: &Features) -> anyhow::Result<()> {
    for (name, sum) in Features::NAMES.iter().zip(features.sums()) {
        save(&features_path(sums, name), fingerprint, sum)?;
    }
    Ok(())
}

/// Loads the features saved beside sums file `sums`, which must cover the `passes` the sums do.
pub fn load_features(
    sums: &Path,
    fingerprint: &str,
    width: u32,
    height: u32,
    passes: u64,
) -> anyhow::Result<Features> {
    let mut loaded = Vec::new();
    for name in Features::NAMES {
        let path = features_path(sums, name);
        let sum = load(&path, fingerprint, width, height)
            .context("the render being resumed was not summing features (--aovs, --denoise)")?;
        if sum.passes != passes {
            bail!(
                "--resume: {} holds {} passes where the sums hold {passes}; delete it to start afresh",
                path.display(),
                sum.passes
            );
        }
        loaded.push(sum);
    }
    Ok(Features::from_sums(loaded.try_into().expect("one sum per name")))
}

/// Removes the features saved beside sums file `sums`, if any.
pub fn remove_features(sums: &Path) {
    for name in Features::NAMES {
        let _ = std::fs::remove_file(features_path(sums, name));
    }
}

/// Loads the sums saved for a render with this fingerprint.
pub fn load(path: &Path, fingerprint: &str, width: u32, height: u32) -> anyhow::Result<FilmSum> {
    let bytes = match std::fs::read(path) {
        Ok(b) => b,
        Err(e) if e.kind() == std::io::ErrorKind::NotFound => bail!(
            "--resume: {} does not exist, so there is nothing to resume (it is written while a \
             render runs; run without --resume to start afresh)",
            path.display()
        ),
        Err(e) => return Err(e).with_context(|| format!("cannot read {}", path.display())),
    };
    let newline = bytes.iter().position(|&b| b == b'\n').unwrap_or(bytes.len());
    let head = std::str::from_utf8(&bytes[..newline]).unwrap_or("");
    let body = &bytes[(newline + 1).min(bytes.len())..];
    let (saved, checksum) = match (head.strip_prefix(HEADER), head.strip_prefix(HEADER_V1)) {
        (Some(rest), _) => match rest.split_once(' ') {
            Some((f, c)) => (f, Some(c)),
            None => (rest, Some("")),
        },
        (None, Some(f)) => (f, None),
        (None, None) => bail!("--resume: {} is not a photonfarm resume file", path.display()),
    };
    if saved != fingerprint {
        bail!(
            "--resume: {} was saved by a render of a different scene or settings (scene files, \
             -D values, seed, integrator and its parameters must be the same); delete it or run \
             without --resume",
            path.display()
        );
    }
    if checksum.is_some_and(|c| c != hex::encode(sha2::Sha256::digest(body))) {
        bail!(
            "--resume: {} is damaged or was edited (its sums do not match their checksum); \
             delete it or run without --resume",
            path.display()
        );
    }
    // A file of another image size is refused as damaged, with both sizes named.
    let sum = decode_batch(body, width, height)
        .with_context(|| format!("--resume: {} is damaged", path.display()))?;
    Ok(sum)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn the_sums_file_sits_beside_the_output() {
        assert_eq!(path_for(Path::new("a/b.exr")), Path::new("a/b.exr.resume"));
        assert_eq!(path_for(Path::new("b.png")), Path::new("./b.png.resume"));
    }

    #[test]
    fn round_trips_and_refuses_another_fingerprint_or_garbage() {
        let dir = tempfile::tempdir().unwrap();
        let path = dir.path().join("x.exr.resume");
        let mut sum = FilmSum::new(2, 1);
        sum.sums[1] = [5, 6, 7];
        sum.passes = 3;
        save(&path, "abc", &sum).unwrap();
        let back = load(&path, "abc", 2, 1).unwrap();
        assert_eq!((back.sums.clone(), back.passes), (sum.sums.clone(), 3));
        let e = load(&path, "abd", 2, 1).unwrap_err().to_string();
        assert!(e.contains("different scene or settings"), "{e}");
        assert!(load(&path, "abc", 3, 1).is_err());
        // Sums edited in place (one byte of the last pixel's sums) are refused.
        let mut edited = std::fs::read(&path).unwrap();
        let at = edited.len() - 9;
        edited[at] ^= 1;
        std::fs::write(&path, &edited).unwrap();
        let e = load(&path, "abc", 2, 1).unwrap_err().to_string();
        assert!(e.contains("edited"), "{e}");
        std::fs::write(&path, b"hello\n").unwrap();
        assert!(
            load(&path, "abc", 2, 1)
                .unwrap_err()
                .to_string()
                .contains("not a photonfarm")
        );
        let e = load(&dir.path().join("none"), "abc", 2, 1)
            .unwrap_err()
            .to_string();
        assert!(e.contains("nothing to resume"), "{e}");
    }
}
