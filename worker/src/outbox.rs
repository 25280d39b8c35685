//! Finished batches waiting to be delivered, kept on disk until the coordinator has them.
//!
//! A coordinator that restarts (or a network that drops) while a worker finishes a batch must
//! not cost the batch: the coordinator keeps leases across restarts, and the worker keeps the
//! result in `CACHE/results/` and sends it again until the coordinator answers. A worker that
//! stops first leaves it there, and the next worker started with the same `--cache` sends it.

use std::path::{Path, PathBuf};

use anyhow::Context;
use serde::{Deserialize, Serialize};

/// What the coordinator needs to accept a result besides its bytes.
#[derive(Clone, Debug, Serialize, Deserialize, PartialEq, Eq)]
pub struct Parcel {
    /// The lease the result is for.
    pub lease_id: u64,
    /// The lease's secret.
    pub key: String,
    /// For the log.
    pub job_id: u64,
    /// First pass.
    pub start: u64,
    /// One past the last.
    pub end: u64,
}

/// The folder of waiting results.
pub struct Outbox {
    dir: PathBuf,
}

impl Outbox {
    /// Opens (creates) `CACHE/results`.
    pub fn open(cache: &Path) -> anyhow::Result<Outbox> {
        let dir = cache.join("results");
        std::fs::create_dir_all(&dir).with_context(|| format!("cannot create {}", dir.display()))?;
        Ok(Outbox { dir })
    }

    fn paths(&self, lease_id: u64) -> (PathBuf, PathBuf) {
        (
            self.dir.join(format!("{lease_id}.batch")),
            self.dir.join(format!("{lease_id}.json")),
        )
    }

    /// Keeps a result until [`Outbox::remove`]: the bytes first, then the parcel that makes
    /// them count, each written whole (a kill in between leaves no half entry behind).
    pub fn put(&self, parcel: &Parcel, bytes: &[u8]) -> anyhow::Result<()> {
        let (batch, meta) = self.paths(parcel.lease_id);
        write_whole(&batch, bytes)?;
        write_whole(&meta, &serde_json::to_vec(parcel)?)
    }

    /// The bytes of a kept result.
    pub fn bytes(&self, parcel: &Parcel) -> anyhow::Result<Vec<u8>> {
        let (batch, _) = self.paths(parcel.lease_id);
        std::fs::read(&batch).with_context(|| format!("cannot read {}", batch.display()))
    }

    /// Forgets a result (delivered, or refused for good).
    pub fn remove(&self, parcel: &Parcel) {
        let (batch, meta) = self.paths(parcel.lease_id);
        let _ = std::fs::remove_file(meta);
        let _ = std::fs::remove_file(batch);
    }

    /// Results left by an earlier run, oldest lease first. Unreadable entries, and entries
    /// whose key is not a header value, are dropped.
    pub fn waiting(&self) -> Vec<Parcel> {
        let Ok(entries) = std::fs::read_dir(&self.dir) else {
            return Vec::new();
        };
        let mut parcels: Vec<Parcel> = entries
            .flatten()
            .filter(|e| e.path().extension().is_some_and(|x| x == "json"))
            .filter_map(|e| {
                // A key that cannot be sent as a header (an edited entry) could never be
                // delivered: dropped with the rest of the unreadable.
                let parcel = std::fs::read(e.path())
                    .ok()
                    .and_then(|b| serde_json::from_slice::<Parcel>(&b).ok())
                    .filter(|p| reqwest::header::HeaderValue::from_str(&p.key).is_ok());
                if parcel.is_none() {
                    let _ = std::fs::remove_file(e.path());
                }
                parcel
            })
            .filter(|p| self.paths(p.lease_id).0.exists())
            .collect();
        parcels.sort_by_key(|p| p.lease_id);
        parcels
    }

    /// Where a result is kept (for the log).
    pub fn path_of(&self, parcel: &Parcel) -> PathBuf {
        self.paths(parcel.lease_id).0
    }
}

fn write_whole(path: &Path, bytes: &[u8]) -> anyhow::Result<()> {
    use std::io::Write;
    let tmp = path.with_extension("partial");
    let mut f = std::fs::File::create(&tmp).with_context(|| format!("cannot write {}", tmp.display()))?;
    f.write_all(bytes)
        .and_then(|_| f.sync_all())
        .with_context(|| format!("cannot write {}", tmp.display()))?;
    std::fs::rename(&tmp, path).with_context(|| format!("cannot write {}", path.display()))
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn keeps_results_until_removed_and_finds_them_again() {
        let dir = tempfile::tempdir().unwrap();
        let outbox = Outbox::open(dir.path()).unwrap();
        let parcel = |id| Parcel {
            lease_id: id,
            key: format!("k{id}"),
            job_id: 1,
            start: id,
            end: id + 1,
        };
        outbox.put(&parcel(9), b"nine").unwrap();
        outbox.put(&parcel(4), b"four").unwrap();
        // A parcel whose bytes are gone, and a damaged one, are not offered.
        std::fs::write(
            dir.path().join("results/5.json"),
            serde_json::to_vec(&parcel(5)).unwrap(),
        )
        .unwrap();
        std::fs::write(dir.path().join("results/6.json"), b"{").unwrap();
        // An edited key that no request can carry used to wedge the worker, retried forever.
        let mut bad = parcel(7);
        bad.key = "k\n7".into();
        outbox.put(&bad, b"seven").unwrap();
        let again = Outbox::open(dir.path()).unwrap();
        assert_eq!(again.waiting(), vec![parcel(4), parcel(9)]);
        assert_eq!(again.bytes(&parcel(9)).unwrap(), b"nine");
        again.remove(&parcel(4));
        assert_eq!(again.waiting(), vec![parcel(9)]);
    }
}
