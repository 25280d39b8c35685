//! Job bundles: a scene file and the files it references, as one tar archive.
//!
//! The archive is content-addressed (SHA-256), so the coordinator stores each bundle once and
//! workers fetch it once. Unpacking accepts only plain relative paths, regular files and
//! folders: no absolute paths, no `..`, no links, so a bundle can never write or point outside
//! its own folder.

use std::io::Read;
use std::path::{Component, Path, PathBuf};

use sha2::{Digest, Sha256};

/// Why a bundle was refused.
#[derive(Debug, thiserror::Error)]
pub enum BundleError {
    /// An entry would leave the bundle's folder or is not a plain file or folder.
    #[error("bundle entry \"{0}\" is not allowed: {1}")]
    Entry(String, &'static str),
    /// The archive could not be read.
    #[error("malformed bundle archive: {0}")]
    Archive(String),
    /// A file could not be read or written.
    #[error("{0}: {1}")]
    Io(String, std::io::Error),
    /// The archive holds more files or bytes than the limits allow.
    #[error("the bundle {0}")]
    TooLarge(String),
}

/// Bounds on what unpacking a bundle may write: a small archive must not fill a disk or
/// create millions of files.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct UnpackLimits {
    /// Most files (and folders).
    pub max_files: usize,
    /// Most bytes, over all files.
    pub max_bytes: u64,
}

impl Default for UnpackLimits {
    fn default() -> Self {
        UnpackLimits {
            max_files: 10_000,
            max_bytes: 4 << 30,
        }
    }
}

/// Hex SHA-256 of the archive: the bundle's name.
pub fn content_hash(bytes: &[u8]) -> String {
    hex::encode(Sha256::digest(bytes))
}

/// Whether a relative path stays inside its folder.
fn is_plain_relative(p: &Path) -> bool {
    !p.as_os_str().is_empty()
        && p.components()
            .all(|c| matches!(c, Component::Normal(_) | Component::CurDir))
}

/// Packs `scene` and the files it reads (`files`, absolute) into a tar archive, under their
/// deepest common folder, so that the names the scene uses (`..` included) resolve the same
/// inside the bundle. Returns the archive and the scene's path inside it.
pub fn pack(scene: &Path, files: &[PathBuf]) -> Result<(Vec<u8>, PathBuf), BundleError> {
    let (archive, mut scenes) = pack_scenes(&[scene], files)?;
    Ok((archive, scenes.remove(0)))
}

/// [`pack`] for several scenes sharing one bundle (the frames of a sequence given as files):
/// `files` are what all of them read. Returns the archive and each scene's path inside it.
pub fn pack_scenes(scenes: &[&Path], files: &[PathBuf]) -> Result<(Vec<u8>, Vec<PathBuf>), BundleError> {
    let canonical = |p: &Path| {
        p.canonicalize()
            .map_err(|e| BundleError::Io(p.display().to_string(), e))
    };
    let scenes: Vec<PathBuf> = scenes.iter().map(|s| canonical(s)).collect::<Result<_, _>>()?;
    let mut all = scenes.clone();
    for f in files {
        all.push(canonical(f)?);
    }
    let first = scenes.first().map(PathBuf::as_path).unwrap_or(Path::new("/"));
    let mut root = first.parent().unwrap_or(Path::new("/")).to_path_buf();
    for f in &all {
        while !f.starts_with(&root) {
            root = root.parent().unwrap_or(Path::new("/")).to_path_buf();
        }
    }
    let mut builder = tar::Builder::new(Vec::new());
    let mut seen = std::collections::BTreeSet::new();
    for full in &all {
        let rel = full.strip_prefix(&root).expect("under the common folder");
        if !seen.insert(rel.to_path_buf()) {
            continue;
        }
        let data = std::fs::read(full).map_err(|e| BundleError::Io(full.display().to_string(), e))?;
        let mut header = tar::Header::new_gnu();
        header.set_size(data.len() as u64);
        header.set_mode(0o644);
        header.set_mtime(0); // the same files always give the same archive, so the same hash
        header.set_cksum();
        builder
            .append_data(&mut header, rel, data.as_slice())
            .map_err(|e| BundleError::Io(rel.display().to_string(), e))?;
    }
    let archive = builder
        .into_inner()
        .map_err(|e| BundleError::Io("archive".into(), e))?;
    let inside = scenes
        .iter()
        .map(|s| {
            s.strip_prefix(&root)
                .expect("under the common folder")
                .to_path_buf()
        })
        .collect();
    Ok((archive, inside))
}

/// Unpacks `bytes` into `dest` (created if missing), refusing anything but plain files and
/// folders at plain relative paths. Returns the files written.
pub fn unpack(bytes: &[u8], dest: &Path, limits: &UnpackLimits) -> Result<Vec<PathBuf>, BundleError> {
    unpack_from(bytes, dest, limits)
}

/// [`unpack`] from a reader (a file on disk), so an archive never needs to be in memory.
pub fn unpack_from(
    reader: impl Read,
    dest: &Path,
    limits: &UnpackLimits,
) -> Result<Vec<PathBuf>, BundleError> {
    std::fs::create_dir_all(dest).map_err(|e| BundleError::Io(dest.display().to_string(), e))?;
    let mut archive = tar::Archive::new(reader);
    let mut written = Vec::new();
    let (mut count, mut total) = (0usize, 0u64);
    let entries = archive
        .entries()
        .map_err(|e| BundleError::Archive(e.to_string()))?;
    for entry in entries {
        let mut entry = entry.map_err(|e| BundleError::Archive(e.to_string()))?;
        count += 1;
        if count > limits.max_files {
            return Err(BundleError::TooLarge(format!(
                "holds more than {} files (the limit)",
                limits.max_files
            )));
        }
        total = total.saturating_add(entry.size());
        if total > limits.max_bytes {
            return Err(BundleError::TooLarge(format!(
                "unpacks to more than {} bytes (the limit)",
                limits.max_bytes
            )));
        }
        let path = entry
            .path()
            .map_err(|e| BundleError::Archive(e.to_string()))?
            .into_owned();
        let shown = path.display().to_string();
        if !is_plain_relative(&path) {
            return Err(BundleError::Entry(shown, "absolute paths and '..' are refused"));
        }
        let target = dest.join(&path);
        match entry.header().entry_type() {
            tar::EntryType::Directory => {
                std::fs::create_dir_all(&target).map_err(|e| BundleError::Io(shown, e))?;
            }
            tar::EntryType::Regular | tar::EntryType::Continuous => {
                if let Some(parent) = target.parent() {
                    std::fs::create_dir_all(parent).map_err(|e| BundleError::Io(shown.clone(), e))?;
                }
                // Streamed to disk: never more in memory than a copy buffer.
                let mut file =
                    std::fs::File::create(&target).map_err(|e| BundleError::Io(shown.clone(), e))?;
                let size = entry.size();
                let copied = std::io::copy(&mut (&mut entry).take(size), &mut file)
                    .map_err(|e| BundleError::Archive(format!("{shown}: {e}")))?;
                if copied != size {
                    return Err(BundleError::Archive(format!("{shown}: truncated")));
                }
                written.push(path);
            }
            _ => {
                return Err(BundleError::Entry(
                    shown,
                    "only regular files and folders are allowed",
                ));
            }
        }
    }
    Ok(written)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn packs_unpacks_and_hashes_deterministically() {
        let src = tempfile::tempdir().unwrap();
        std::fs::create_dir_all(src.path().join("scenes/a")).unwrap();
        std::fs::create_dir(src.path().join("meshes")).unwrap();
        std::fs::write(src.path().join("scenes/a/scene.xml"), "<scene/>").unwrap();
        std::fs::write(src.path().join("meshes/a.obj"), "v 0 0 0").unwrap();
        // A mesh outside the scene's folder (as Mitsuba's scenes keep them, "../../meshes").
        let files = vec![src.path().join("scenes/a/../../meshes/a.obj")];
        let scene = src.path().join("scenes/a/scene.xml");
        let (a, rel) = pack(&scene, &files).unwrap();
        let (b, _) = pack(&scene, &files).unwrap();
        assert_eq!(content_hash(&a), content_hash(&b));
        assert_eq!(rel, PathBuf::from("scenes/a/scene.xml"));
        let dst = tempfile::tempdir().unwrap();
        let written = unpack(&a, dst.path(), &UnpackLimits::default()).unwrap();
        assert_eq!(written.len(), 2);
        assert_eq!(
            std::fs::read_to_string(dst.path().join("scenes/a/../../meshes/a.obj")).unwrap(),
            "v 0 0 0"
        );
        assert!(pack(&scene, &[src.path().join("missing.obj")]).is_err());
    }

    #[test]
    fn refuses_traversal_and_links() {
        // A hand-made archive with "../evil": the tar crate's builder refuses to write it, so
        // write the header bytes directly.
        let mut header = tar::Header::new_old();
        header.as_old_mut().name[..7].copy_from_slice(b"../evil");
        header.set_size(1);
        header.set_mode(0o644);
        header.set_entry_type(tar::EntryType::Regular);
        header.set_cksum();
        let mut bytes = header.as_bytes().to_vec();
        bytes.extend_from_slice(b"x");
        bytes.resize(bytes.len() + 511, 0);
        bytes.extend_from_slice(&[0; 1024]);
        let dst = tempfile::tempdir().unwrap();
        let e = unpack(&bytes, &dst.path().join("b"), &UnpackLimits::default())
            .unwrap_err()
            .to_string();
        assert!(e.contains("../evil"), "{e}");
        assert!(!dst.path().join("evil").exists());

        let mut b = tar::Builder::new(Vec::new());
        let mut h = tar::Header::new_gnu();
        h.set_entry_type(tar::EntryType::Symlink);
        h.set_size(0);
        b.append_link(&mut h, "link", "/etc/passwd").unwrap();
        let e = unpack(&b.into_inner().unwrap(), dst.path(), &UnpackLimits::default())
            .unwrap_err()
            .to_string();
        assert!(e.contains("only regular files"), "{e}");
        assert!(
            unpack(
                b"garbage that is not a tar archive at all",
                dst.path(),
                &UnpackLimits::default()
            )
            .is_err()
        );
    }

    #[test]
    fn refuses_more_files_or_bytes_than_the_limits() {
        let mut b = tar::Builder::new(Vec::new());
        for i in 0..5 {
            let mut h = tar::Header::new_gnu();
            h.set_size(1000);
            h.set_mode(0o644);
            h.set_cksum();
            b.append_data(&mut h, format!("f{i}"), &[0u8; 1000][..]).unwrap();
        }
        let tar = b.into_inner().unwrap();
        let dst = tempfile::tempdir().unwrap();
        let few = UnpackLimits {
            max_files: 4,
            max_bytes: 1 << 20,
        };
        assert!(matches!(
            unpack(&tar, dst.path(), &few),
            Err(BundleError::TooLarge(_))
        ));
        let small = UnpackLimits {
            max_files: 100,
            max_bytes: 4500,
        };
        assert!(matches!(
            unpack(&tar, dst.path(), &small),
            Err(BundleError::TooLarge(_))
        ));
        assert_eq!(
            unpack(&tar, dst.path(), &UnpackLimits::default()).unwrap().len(),
            5
        );
    }
}
