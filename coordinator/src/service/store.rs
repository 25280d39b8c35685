//! The coordinator's durable state: jobs in SQLite, images and partial sums as files beside it.
//!
//! Every file is written to a temporary name, flushed to disk and renamed, so a crash leaves
//! either the old or the new file, never half of one. A batch result is on disk before its
//! upload is acknowledged, so nothing a worker reported is lost. Layout under the data folder:
//!
//! ```text
//! photonfarm.sqlite           jobs, completed batches not yet merged, the lease id base
//! bundles/HASH.tar, HASH/     job bundles, content-addressed, and their unpacked files
//! jobs/ID/prefix.bin          passes [0, N) summed (the accumulator's prefix), with its odd
//!                             passes on the sampled pixels (photonfarm::parity) and, for a
//!                             job with --aovs or --denoise, its features (photonfarm::features)
//! jobs/ID/batch-S-E-lL.bin    result of passes [S, E) delivered under lease L, not yet
//!                             merged into the prefix (batch-S-E.bin: stored before lease ids
//!                             were part of the name)
//! jobs/ID/image.exr, .png     the latest checkpoint (the EXR with the features' channels)
//! jobs/ID/image.denoised.*    its denoised preview, for a job with --denoise
//! ```
//!
//! Job ids are never reused, even if the database is lost or replaced by an older copy: a new
//! id is above every id in the database *and* every folder under `jobs/`, so a fresh job can
//! never be served an old job's files. Slow file work (fsync, image encoding) goes through
//! [`Layout`], which needs no database and so runs outside the farm's lock.

use std::path::{Path, PathBuf};
use std::sync::Arc;
use std::sync::atomic::{AtomicU64, Ordering};

use photonfarm::features::{Features, write_image_with_features};
use photonfarm::film::{FilmError, FilmSum};
use photonfarm::parity::OddSums;
use photonfarm::protocol::{BatchResult, decode_result, encode_batch, encode_result, max_encoded_batch};
use rusqlite::{Connection, OptionalExtension, params};

use crate::service::scheduler::JobState;

/// Storage failures: reported as 500s and logged, never a panic.
#[derive(Debug, thiserror::Error)]
pub enum StoreError {
    /// SQLite failed.
    #[error("database: {0}")]
    Db(#[from] rusqlite::Error),
    /// A file could not be read or written.
    #[error("{0}: {1}")]
    Io(String, std::io::Error),
    /// A stored file is damaged.
    #[error("{0}: {1}")]
    Corrupt(String, String),
}

/// A job as stored.
#[derive(Clone, Debug)]
pub struct JobRow {
    /// Id.
    pub id: u64,
    /// Creation time, Unix milliseconds.
    pub created_ms: u64,
    /// The settings as submitted (JSON of `JobSettings`).
    pub settings: String,
    /// The resolved render settings (JSON of `RenderSettings`).
    pub render: String,
    /// The scene's path inside the bundle.
    pub scene: String,
    /// The bundle's hash.
    pub bundle: String,
    /// Passes in total.
    pub total: u64,
    /// Checkpoint interval.
    pub window: u64,
    /// First pass never handed out.
    pub next_start: u64,
    /// State.
    pub state: JobState,
    /// Why it failed.
    pub message: Option<String>,
    /// Image size.
    pub width: u32,
    /// Image size.
    pub height: u32,
    /// Passes in the latest checkpoint image.
    pub image_passes: u64,
    /// What the job's status counts, kept across restarts.
    pub stats: JobStats,
    /// Of a frame of a sequence: the sequence's job and the frame number.
    pub frame_of: Option<(u64, u32)>,
    /// Of a sequence: its frames' (frame number, job), as JSON.
    pub frames: Option<String>,
}

/// A job's counters, stored so that its elapsed time, rate and batch count go on after a
/// restart instead of starting from zero.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub struct JobStats {
    /// Milliseconds during which a coordinator ran the job (time while it was down not counted).
    pub elapsed_ms: u64,
    /// Batch results received.
    pub batches_received: u64,
    /// Bytes of batch results received.
    pub bytes_received: u64,
}

/// A stored batch result: passes [start, end), delivered under `lease` (0 for a batch
/// stored before lease ids were recorded).
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct StoredBatch {
    /// First pass.
    pub start: u64,
    /// One past the last pass.
    pub end: u64,
    /// The lease whose result it is.
    pub lease: u64,
}

/// A lease as stored: a batch a worker holds survives a coordinator restart, so that a worker
/// which finishes it while the coordinator is down can still deliver it.
#[derive(Clone, Debug, PartialEq, Eq)]
pub struct LeaseRow {
    /// Lease id.
    pub id: u64,
    /// Job.
    pub job: u64,
    /// First pass.
    pub start: u64,
    /// One past the last.
    pub end: u64,
    /// The worker's name.
    pub worker: String,
    /// The lease's secret.
    pub key: String,
}

/// A new job's row.
#[derive(Clone, Debug)]
pub struct NewJob {
    /// Id, from [`Store::next_job_id`] at start and counted on in memory.
    pub id: u64,
    /// Creation time, Unix milliseconds.
    pub created_ms: u64,
    /// The settings as submitted (JSON of `JobSettings`).
    pub settings: String,
    /// The resolved render settings (JSON of `RenderSettings`).
    pub render: String,
    /// The scene's path inside the bundle.
    pub scene: String,
    /// The bundle's hash.
    pub bundle: String,
    /// Passes in total.
    pub total: u64,
    /// Checkpoint interval.
    pub window: u64,
    /// Image size.
    pub width: u32,
    /// Image size.
    pub height: u32,
    /// Of a frame of a sequence: the sequence's job and the frame number.
    pub frame_of: Option<(u64, u32)>,
    /// Of a sequence: its frames' (frame number, job), as JSON.
    pub frames: Option<String>,
}

impl From<&NewJob> for JobRow {
    /// The row a new job has once inserted: queued, nothing rendered.
    fn from(job: &NewJob) -> JobRow {
        JobRow {
            id: job.id,
            created_ms: job.created_ms,
            settings: job.settings.clone(),
            render: job.render.clone(),
            scene: job.scene.clone(),
            bundle: job.bundle.clone(),
            total: job.total,
            window: job.window,
            next_start: 0,
            state: JobState::Queued,
            message: None,
            width: job.width,
            height: job.height,
            image_passes: 0,
            stats: JobStats::default(),
            frame_of: job.frame_of,
            frames: job.frames.clone(),
        }
    }
}

/// One change to the database. A farm event returns the list of its writes, and
/// [`Store::apply`] makes them durable together, outside the farm's lock.
#[derive(Clone, Debug)]
pub enum Write {
    /// A job was submitted.
    InsertJob(NewJob),
    /// A job's scheduling and counters.
    Progress {
        /// The job.
        id: u64,
        /// First pass never handed out.
        next_start: u64,
        /// State.
        state: JobState,
        /// Why it failed.
        message: Option<String>,
        /// Counters.
        stats: JobStats,
    },
    /// A job's scheduling only (when it is restored: its counters are as stored).
    State {
        /// The job.
        id: u64,
        /// First pass never handed out.
        next_start: u64,
        /// State.
        state: JobState,
        /// Why it failed.
        message: Option<String>,
    },
    /// The pass count of a job's latest image.
    ImagePasses {
        /// The job.
        id: u64,
        /// Passes in it.
        passes: u64,
    },
    /// A lease was granted.
    InsertLease(LeaseRow),
    /// A lease ended (completed, released, expired, or its job is over).
    DeleteLease(u64),
    /// A batch result whose file [`Layout::keep_received`] stored: from here on it counts.
    RecordBatch {
        /// The job.
        job: u64,
        /// The batch.
        batch: StoredBatch,
    },
    /// A batch found damaged: its row and file go.
    ForgetBatch {
        /// The job.
        job: u64,
        /// The batch.
        batch: StoredBatch,
    },
    /// The batches a stored prefix of `passes` passes contains: their rows and files go.
    ForgetMerged {
        /// The job.
        job: u64,
        /// Passes in the stored prefix.
        passes: u64,
    },
    /// Noise estimates (passes, variance) of a job.
    Noise {
        /// The job.
        job: u64,
        /// (passes, variance).
        points: Vec<(u64, f64)>,
    },
}

/// Where everything lives under the data folder: paths only, so it is cheap to clone and
/// usable without the farm's lock.
#[derive(Clone, Debug)]
pub struct Layout {
    dir: PathBuf,
}

/// The data folder.
pub struct Store {
    layout: Layout,
    db: Connection,
    /// Above every job folder found at start: new ids start past it.
    id_floor: u64,
    /// Transactions committed, counted by SQLite's commit hook.
    commits: Arc<AtomicU64>,
}

/// An image that cannot be made or written, as a storage error naming its file.
fn film_error(path: &Path, e: FilmError) -> StoreError {
    StoreError::Io(path.display().to_string(), std::io::Error::other(e.to_string()))
}

fn io(path: &Path) -> impl FnOnce(std::io::Error) -> StoreError + '_ {
    move |e| StoreError::Io(path.display().to_string(), e)
}

/// Writes `bytes` to `path` atomically and durably.
pub fn write_durably(path: &Path, bytes: &[u8]) -> Result<(), StoreError> {
    write_durably_as(path, bytes, 0)
}

/// [`write_durably`] through a temporary file named with `tag`, so that concurrent writers
/// of one path never share a temporary file.
fn write_durably_as(path: &Path, bytes: &[u8], tag: u64) -> Result<(), StoreError> {
    use std::io::Write;
    let dir = path.parent().expect("stored files live in a folder");
    std::fs::create_dir_all(dir).map_err(io(dir))?;
    // Beside the file, its whole name kept (x.exr and x.png never share one), and created
    // anew: a stale file or a planted symlink there is removed, never followed, and one
    // planted again in between makes the open fail instead of writing through it.
    let mut name = path.file_name().unwrap_or_default().to_os_string();
    name.push(format!(".tmp{tag}"));
    let tmp = dir.join(name);
    match std::fs::remove_file(&tmp) {
        Err(e) if e.kind() != std::io::ErrorKind::NotFound => return Err(io(&tmp)(e)),
        _ => {}
    }
    let mut f = std::fs::OpenOptions::new()
        .write(true)
        .create_new(true)
        .open(&tmp)
        .map_err(io(&tmp))?;
    f.write_all(bytes).map_err(io(&tmp))?;
    f.sync_all().map_err(io(&tmp))?;
    rename_durably(&tmp, path)
}

/// Makes the entries of folder `dir` durable (a rename into it, a new file or folder in it).
/// Best effort: a file system that cannot sync a folder keeps its entries its own way.
pub fn sync_dir(dir: &Path) {
    if let Ok(d) = std::fs::File::open(dir) {
        let _ = d.sync_all();
    }
}

/// Renames `from` to `to` and makes the rename durable.
pub fn rename_durably(from: &Path, to: &Path) -> Result<(), StoreError> {
    std::fs::rename(from, to).map_err(io(to))?;
    if let Some(dir) = to.parent() {
        sync_dir(dir);
    }
    Ok(())
}

impl Layout {
    /// Where a bundle's archive is kept.
    pub fn bundle_archive(&self, hash: &str) -> PathBuf {
        self.dir.join("bundles").join(format!("{hash}.tar"))
    }

    /// Where a bundle is unpacked.
    pub fn bundle_dir(&self, hash: &str) -> PathBuf {
        self.dir.join("bundles").join(hash)
    }

    /// A scratch folder inside the data folder (same file system, so renames work).
    pub fn scratch_dir(&self, name: &str) -> PathBuf {
        self.dir.join("bundles").join(format!("incoming-{name}"))
    }

    /// A job's folder.
    pub fn job_dir(&self, id: u64) -> PathBuf {
        self.dir.join("jobs").join(id.to_string())
    }

    /// Where a job's latest checkpoint image is.
    pub fn image_path(&self, id: u64, ext: &str) -> PathBuf {
        self.image_path_named(id, "image", ext)
    }

    /// A job's image `name.ext`: `image` (the latest checkpoint) or `image.denoised` (its
    /// denoised preview).
    pub fn image_path_named(&self, id: u64, name: &str, ext: &str) -> PathBuf {
        self.job_dir(id).join(format!("{name}.{ext}"))
    }

    /// Where a batch's result is kept until merged. The name holds the lease that delivered
    /// it, so a result whose lease has moved on can never replace the one that counts: only
    /// the row [`Store::record_batch`] writes makes a file count.
    pub fn batch_path(&self, job: u64, b: StoredBatch) -> PathBuf {
        let StoredBatch { start, end, lease } = b;
        let name = match lease {
            0 => format!("batch-{start}-{end}.bin"),
            _ => format!("batch-{start}-{end}-l{lease}.bin"),
        };
        self.job_dir(job).join(name)
    }

    /// Where a batch's result is received, before it is decoded and checked: its lease's own
    /// name (one upload per lease at a time), which never counts.
    pub fn received_path(&self, job: u64, b: StoredBatch) -> PathBuf {
        let mut name = self.batch_path(job, b).into_os_string();
        name.push(".part");
        PathBuf::from(name)
    }

    /// Stores an encoded batch result durably, as a received one is kept (for tests that play
    /// a worker without HTTP).
    #[cfg(test)]
    pub fn write_batch_bytes(&self, job: u64, b: StoredBatch, encoded: &[u8]) -> Result<(), StoreError> {
        write_durably_as(&self.batch_path(job, b), encoded, b.lease)
    }

    /// Makes a received (and already durable) result the stored batch, before its row is
    /// recorded under the lock.
    pub fn keep_received(&self, job: u64, b: StoredBatch) -> Result<(), StoreError> {
        rename_durably(&self.received_path(job, b), &self.batch_path(job, b))
    }

    /// Stores a job's prefix (passes [0, N) summed) durably, with its odd passes' sample if
    /// known and its features if the job has them (one file, so they always agree).
    pub fn write_prefix(
        &self,
        job: u64,
        prefix: &FilmSum,
        odd: Option<&OddSums>,
        features: Option<&Features>,
    ) -> Result<(), StoreError> {
        // Features travel with the odd sample (PFBATCH4): a prefix without one (merged from a
        // worker too old for either) has no features either.
        let bytes = match odd {
            Some(odd) => encode_result(prefix, odd, features),
            None => encode_batch(prefix),
        };
        write_durably(&self.job_dir(job).join("prefix.bin"), &bytes)
    }

    /// Writes the checkpoint images (EXR and PNG) atomically; with features, the EXR carries
    /// them as channels.
    pub fn write_images(
        &self,
        job: u64,
        sum: &FilmSum,
        features: Option<&Features>,
    ) -> Result<(), StoreError> {
        let image = sum
            .image()
            .map_err(|e| film_error(&self.image_path(job, "exr"), e))?;
        self.write_image_files(job, "image", &image, sum.width, sum.height, features)
    }

    /// Writes the denoised preview of a checkpoint (`image.denoised.exr` and `.png`)
    /// atomically.
    pub fn write_denoised(&self, job: u64, sum: &FilmSum, features: &Features) -> Result<(), StoreError> {
        let path = self.image_path_named(job, "image.denoised", "exr");
        let image = sum.image().map_err(|e| film_error(&path, e))?;
        let denoised = crate::denoise::denoise(&image, features).map_err(|e| {
            StoreError::Io(
                path.display().to_string(),
                std::io::Error::other(format!("{e:#}")),
            )
        })?;
        self.write_image_files(job, "image.denoised", &denoised, sum.width, sum.height, None)
    }

    /// Writes `name.exr` and `name.png` of a job atomically.
    fn write_image_files(
        &self,
        job: u64,
        name: &str,
        pixels: &[photonfarm::color::Rgb],
        width: u32,
        height: u32,
        features: Option<&Features>,
    ) -> Result<(), StoreError> {
        for ext in ["exr", "png"] {
            let path = self.image_path_named(job, name, ext);
            let tmp = self.job_dir(job).join(format!("{name}-tmp.{ext}"));
            std::fs::create_dir_all(self.job_dir(job)).map_err(io(&tmp))?;
            write_image_with_features(pixels, width, height, features, &tmp)
                .map_err(|e| film_error(&tmp, e))?;
            std::fs::rename(&tmp, &path).map_err(io(&path))?;
        }
        Ok(())
    }

    /// The stored prefix and its odd passes' sample (None if it was stored without one), or
    /// an empty prefix.
    pub fn load_prefix(&self, job: u64, width: u32, height: u32) -> Result<BatchResult, StoreError> {
        let path = self.job_dir(job).join("prefix.bin");
        match std::fs::read(&path) {
            Ok(bytes) => decode_result(&bytes, width, height)
                .map_err(|e| StoreError::Corrupt(path.display().to_string(), e.to_string())),
            Err(e) if e.kind() == std::io::ErrorKind::NotFound => Ok(BatchResult {
                sum: FilmSum::new(width, height),
                odd: Some(OddSums::empty(width, height)),
                features: None,
            }),
            Err(e) => Err(StoreError::Io(path.display().to_string(), e)),
        }
    }

    /// Reads one stored batch result of a `width` × `height` job, as the worker sent it
    /// (compressed or not: see [`photonfarm::compression`]).
    pub fn load_batch(
        &self,
        job: u64,
        b: StoredBatch,
        width: u32,
        height: u32,
    ) -> Result<BatchResult, StoreError> {
        let path = self.batch_path(job, b);
        let corrupt = |e: String| StoreError::Corrupt(path.display().to_string(), e);
        let bytes = std::fs::read(&path).map_err(io(&path))?;
        let bytes = photonfarm::compression::decode_stored(bytes, max_encoded_batch(width, height, true))
            .map_err(|e| corrupt(e.to_string()))?;
        decode_result(&bytes, width, height).map_err(|e| corrupt(e.to_string()))
    }
}

impl Store {
    /// Opens (or creates) the data folder.
    pub fn open(dir: &Path) -> Result<Store, StoreError> {
        std::fs::create_dir_all(dir.join("bundles")).map_err(io(dir))?;
        std::fs::create_dir_all(dir.join("jobs")).map_err(io(dir))?;
        let mut db = Connection::open(dir.join("photonfarm.sqlite"))?;
        db.execute_batch(
            "PRAGMA journal_mode = WAL;
             PRAGMA synchronous = FULL;
             CREATE TABLE IF NOT EXISTS meta (key TEXT PRIMARY KEY, value INTEGER NOT NULL);
             CREATE TABLE IF NOT EXISTS jobs (
                 id INTEGER PRIMARY KEY, created_ms INTEGER NOT NULL, settings TEXT NOT NULL,
                 render TEXT NOT NULL, scene TEXT NOT NULL, bundle TEXT NOT NULL,
                 total INTEGER NOT NULL, window INTEGER NOT NULL, next_start INTEGER NOT NULL,
                 state TEXT NOT NULL, message TEXT, width INTEGER NOT NULL, height INTEGER NOT NULL);
             CREATE TABLE IF NOT EXISTS batches (
                 job INTEGER NOT NULL, start INTEGER NOT NULL, end INTEGER NOT NULL,
                 PRIMARY KEY (job, start));
             CREATE TABLE IF NOT EXISTS leases (
                 id INTEGER PRIMARY KEY, job INTEGER NOT NULL, start INTEGER NOT NULL,
                 end INTEGER NOT NULL, worker TEXT NOT NULL, key TEXT NOT NULL);
             CREATE TABLE IF NOT EXISTS noise (
                 job INTEGER NOT NULL, passes INTEGER NOT NULL, variance REAL NOT NULL,
                 PRIMARY KEY (job, passes));",
        )?;
        // Columns added after the first release (an error means the column is there already):
        // passes in each job's latest image, and its counters.
        for column in [
            "image_passes",
            "elapsed_ms",
            "batches_received",
            "bytes_received",
            "sequence",
            "frame",
        ] {
            let _ = db.execute(
                &format!("ALTER TABLE jobs ADD COLUMN {column} INTEGER NOT NULL DEFAULT 0"),
                [],
            );
        }
        // Sequences' frame lists (NULL for every other job).
        let _ = db.execute("ALTER TABLE jobs ADD COLUMN frames TEXT", []);
        // The lease that delivered each stored batch (0: stored before, under the old name).
        // Added only where missing, and an error here is one: without the column no batch
        // could be read back, and every job with stored batches would fail at restore.
        let has_lease = db
            .prepare("SELECT 1 FROM pragma_table_info('batches') WHERE name = 'lease'")?
            .exists([])?;
        if !has_lease {
            db.execute(
                "ALTER TABLE batches ADD COLUMN lease INTEGER NOT NULL DEFAULT 0",
                [],
            )?;
        }
        // Scratch folders of submissions a crash interrupted: nothing refers to them.
        if let Ok(entries) = std::fs::read_dir(dir.join("bundles")) {
            for e in entries.flatten() {
                if e.file_name().to_string_lossy().starts_with("incoming-") {
                    let _ = std::fs::remove_dir_all(e.path());
                }
            }
        }
        let id_floor = std::fs::read_dir(dir.join("jobs"))
            .map_err(io(dir))?
            .filter_map(|e| e.ok()?.file_name().to_str()?.parse::<u64>().ok())
            .max()
            .unwrap_or(0);
        let commits = Arc::new(AtomicU64::new(0));
        let counter = commits.clone();
        db.commit_hook(Some(move || {
            counter.fetch_add(1, Ordering::Relaxed);
            false
        }))?;
        Ok(Store {
            layout: Layout {
                dir: dir.to_path_buf(),
            },
            db,
            id_floor,
            commits,
        })
    }

    /// The paths, for work outside the farm's lock.
    pub fn layout(&self) -> &Layout {
        &self.layout
    }

    /// Reserves a fresh range of lease ids for this run: ids from an earlier run can never be
    /// granted again, so a result for a lease from before a restart is always refused.
    pub fn reserve_lease_ids(&mut self) -> Result<u64, StoreError> {
        let base: u64 = self
            .db
            .query_row("SELECT value FROM meta WHERE key = 'lease_base'", [], |r| {
                r.get::<_, i64>(0)
            })
            .optional()?
            .unwrap_or(1) as u64;
        self.db.execute(
            "INSERT INTO meta (key, value) VALUES ('lease_base', ?1)
             ON CONFLICT(key) DO UPDATE SET value = excluded.value",
            params![(base + (1 << 32)) as i64],
        )?;
        Ok(base)
    }

    /// The id the next job gets: above every id in the database and every job folder.
    pub fn next_job_id(&self) -> Result<u64, StoreError> {
        let in_db: i64 = self
            .db
            .query_row("SELECT COALESCE(MAX(id), 0) FROM jobs", [], |r| r.get(0))?;
        Ok((in_db as u64).max(self.id_floor) + 1)
    }

    /// Makes `writes` durable in one transaction (one fsync), in order: one farm event is
    /// one commit, so a crash keeps all of an event or none of it.
    pub fn apply(&mut self, writes: &[Write]) -> Result<(), StoreError> {
        if writes.is_empty() {
            return Ok(());
        }
        let tx = self.db.transaction()?;
        let mut merged_files = Vec::new();
        for w in writes {
            match w {
                Write::InsertJob(job) => {
                    tx.execute(
                        "INSERT INTO jobs (id, created_ms, settings, render, scene, bundle, total, window,
                                           next_start, state, width, height, sequence, frame, frames)
                         VALUES (?1, ?2, ?3, ?4, ?5, ?6, ?7, ?8, 0, 'queued', ?9, ?10, ?11, ?12, ?13)",
                        params![
                            job.id as i64,
                            job.created_ms as i64,
                            job.settings,
                            job.render,
                            job.scene,
                            job.bundle,
                            job.total as i64,
                            job.window as i64,
                            job.width,
                            job.height,
                            job.frame_of.map_or(0, |f| f.0) as i64,
                            job.frame_of.map_or(0, |f| f.1),
                            job.frames,
                        ],
                    )?;
                    // Its folder now, not at its first batch: folders are what keep ids from
                    // being reused when the database is lost (see `id_floor`), and a job lost
                    // with its database before any batch arrived had none.
                    let folder = self.layout.job_dir(job.id);
                    std::fs::create_dir_all(&folder).map_err(io(&folder))?;
                    sync_dir(&self.layout.dir.join("jobs"));
                }
                Write::Progress {
                    id,
                    next_start,
                    state,
                    message,
                    stats,
                } => {
                    tx.execute(
                        "UPDATE jobs SET next_start = ?2, state = ?3, message = ?4, elapsed_ms = ?5,
                                         batches_received = ?6, bytes_received = ?7
                         WHERE id = ?1",
                        params![
                            *id as i64,
                            *next_start as i64,
                            state.as_str(),
                            message,
                            stats.elapsed_ms as i64,
                            stats.batches_received as i64,
                            stats.bytes_received as i64
                        ],
                    )?;
                }
                Write::State {
                    id,
                    next_start,
                    state,
                    message,
                } => {
                    tx.execute(
                        "UPDATE jobs SET next_start = ?2, state = ?3, message = ?4 WHERE id = ?1",
                        params![*id as i64, *next_start as i64, state.as_str(), message],
                    )?;
                }
                Write::ImagePasses { id, passes } => {
                    tx.execute(
                        "UPDATE jobs SET image_passes = ?2 WHERE id = ?1",
                        params![*id as i64, *passes as i64],
                    )?;
                }
                Write::InsertLease(lease) => {
                    tx.execute(
                        "INSERT OR REPLACE INTO leases (id, job, start, end, worker, key)
                         VALUES (?1, ?2, ?3, ?4, ?5, ?6)",
                        params![
                            lease.id as i64,
                            lease.job as i64,
                            lease.start as i64,
                            lease.end as i64,
                            lease.worker,
                            lease.key
                        ],
                    )?;
                }
                Write::DeleteLease(id) => {
                    tx.execute("DELETE FROM leases WHERE id = ?1", params![*id as i64])?;
                }
                Write::RecordBatch { job, batch } => {
                    tx.execute(
                        "INSERT OR REPLACE INTO batches (job, start, end, lease) VALUES (?1, ?2, ?3, ?4)",
                        params![
                            *job as i64,
                            batch.start as i64,
                            batch.end as i64,
                            batch.lease as i64
                        ],
                    )?;
                }
                Write::ForgetBatch { job, batch } => {
                    tx.execute(
                        "DELETE FROM batches WHERE job = ?1 AND start = ?2 AND end = ?3",
                        params![*job as i64, batch.start as i64, batch.end as i64],
                    )?;
                    merged_files.push(self.layout.batch_path(*job, *batch));
                }
                Write::ForgetMerged { job, passes } => {
                    let merged: Vec<StoredBatch> = batch_ranges(&tx, *job)?
                        .into_iter()
                        .filter(|b| b.end <= *passes)
                        .collect();
                    tx.execute(
                        "DELETE FROM batches WHERE job = ?1 AND end <= ?2",
                        params![*job as i64, *passes as i64],
                    )?;
                    merged_files.extend(merged.into_iter().map(|b| self.layout.batch_path(*job, b)));
                }
                Write::Noise { job, points } => {
                    for &(passes, v) in points {
                        tx.execute(
                            "INSERT OR REPLACE INTO noise (job, passes, variance) VALUES (?1, ?2, ?3)",
                            params![*job as i64, passes as i64, v],
                        )?;
                    }
                }
            }
        }
        tx.commit()?;
        // Files of forgotten batches go once no row names them; a crash before this leaves
        // only unnamed files, which nothing reads.
        for f in merged_files {
            let _ = std::fs::remove_file(f);
        }
        Ok(())
    }

    /// Transactions committed since the store was opened (each farm event makes one).
    pub fn commits(&self) -> u64 {
        self.commits.load(Ordering::Relaxed)
    }

    /// Records how far the counter went and the state.
    pub fn update_job(
        &mut self,
        id: u64,
        next_start: u64,
        state: JobState,
        message: Option<&str>,
    ) -> Result<(), StoreError> {
        self.apply(&[Write::State {
            id,
            next_start,
            state,
            message: message.map(str::to_string),
        }])
    }

    /// Forgets leases that ended (completed, released, expired, or of a job that is over).
    pub fn delete_leases(&mut self, ids: &[u64]) -> Result<(), StoreError> {
        let writes: Vec<Write> = ids.iter().map(|&id| Write::DeleteLease(id)).collect();
        self.apply(&writes)
    }

    /// Every stored lease.
    pub fn load_leases(&self) -> Result<Vec<LeaseRow>, StoreError> {
        let mut stmt = self
            .db
            .prepare("SELECT id, job, start, end, worker, key FROM leases ORDER BY id")?;
        let rows = stmt.query_map([], |r| {
            Ok(LeaseRow {
                id: r.get::<_, i64>(0)? as u64,
                job: r.get::<_, i64>(1)? as u64,
                start: r.get::<_, i64>(2)? as u64,
                end: r.get::<_, i64>(3)? as u64,
                worker: r.get(4)?,
                key: r.get(5)?,
            })
        })?;
        Ok(rows.collect::<Result<_, _>>()?)
    }

    /// Every job, oldest first.
    pub fn load_jobs(&self) -> Result<Vec<JobRow>, StoreError> {
        let mut stmt = self.db.prepare(
            "SELECT id, created_ms, settings, render, scene, bundle, total, window, next_start, state, message,
                    width, height, image_passes, elapsed_ms, batches_received, bytes_received,
                    sequence, frame, frames
             FROM jobs ORDER BY id",
        )?;
        let rows = stmt.query_map([], |r| {
            Ok(JobRow {
                id: r.get::<_, i64>(0)? as u64,
                created_ms: r.get::<_, i64>(1)? as u64,
                settings: r.get(2)?,
                render: r.get(3)?,
                scene: r.get(4)?,
                bundle: r.get(5)?,
                total: r.get::<_, i64>(6)? as u64,
                window: r.get::<_, i64>(7)? as u64,
                next_start: r.get::<_, i64>(8)? as u64,
                state: JobState::parse(&r.get::<_, String>(9)?).unwrap_or(JobState::Failed),
                message: r.get(10)?,
                width: r.get(11)?,
                height: r.get(12)?,
                image_passes: r.get::<_, i64>(13)? as u64,
                stats: JobStats {
                    elapsed_ms: r.get::<_, i64>(14)? as u64,
                    batches_received: r.get::<_, i64>(15)? as u64,
                    bytes_received: r.get::<_, i64>(16)? as u64,
                },
                frame_of: match r.get::<_, i64>(17)? {
                    0 => None,
                    sequence => Some((sequence as u64, r.get::<_, u32>(18)?)),
                },
                frames: r.get(19)?,
            })
        })?;
        Ok(rows.collect::<Result<_, _>>()?)
    }

    /// Whether a row names this batch (its result counted).
    pub fn has_batch(&self, job: u64, b: StoredBatch) -> Result<bool, StoreError> {
        Ok(self
            .db
            .prepare("SELECT 1 FROM batches WHERE job = ?1 AND start = ?2 AND lease = ?3")?
            .exists(params![job as i64, b.start as i64, b.lease as i64])?)
    }

    /// The batch results stored for a job and not yet merged into its prefix.
    pub fn batch_ranges(&self, job: u64) -> Result<Vec<StoredBatch>, StoreError> {
        batch_ranges(&self.db, job)
    }

    /// Forgets a batch found damaged, and removes its file.
    pub fn forget_batch(&mut self, job: u64, batch: StoredBatch) -> Result<(), StoreError> {
        self.apply(&[Write::ForgetBatch { job, batch }])
    }

    /// A job's stored noise estimates, by passes.
    pub fn load_noise(&self, job: u64) -> Result<Vec<(u64, f64)>, StoreError> {
        let mut stmt = self
            .db
            .prepare("SELECT passes, variance FROM noise WHERE job = ?1 ORDER BY passes")?;
        let points = stmt
            .query_map(params![job as i64], |r| {
                Ok((r.get::<_, i64>(0)? as u64, r.get::<_, f64>(1)?))
            })?
            .collect::<Result<_, _>>()?;
        Ok(points)
    }
}

fn batch_ranges(db: &Connection, job: u64) -> Result<Vec<StoredBatch>, StoreError> {
    let mut stmt = db.prepare("SELECT start, end, lease FROM batches WHERE job = ?1 ORDER BY start")?;
    let ranges = stmt
        .query_map(params![job as i64], |r| {
            Ok(StoredBatch {
                start: r.get::<_, i64>(0)? as u64,
                end: r.get::<_, i64>(1)? as u64,
                lease: r.get::<_, i64>(2)? as u64,
            })
        })?
        .collect::<Result<_, _>>()?;
    Ok(ranges)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[cfg(unix)]
    #[test]
    fn a_symlink_planted_at_the_temporary_name_is_not_followed() {
        let dir = tempfile::tempdir().unwrap();
        let victim = dir.path().join("victim.txt");
        std::fs::write(&victim, b"keep me").unwrap();
        let out = dir.path().join("out.exr");
        // Wherever the temporary file might be: with the extension replaced or appended to.
        for tmp in ["out.tmp0", "out.exr.tmp0"] {
            std::os::unix::fs::symlink(&victim, dir.path().join(tmp)).unwrap();
        }
        write_durably(&out, b"image").unwrap();
        assert_eq!(std::fs::read(&out).unwrap(), b"image");
        assert_eq!(std::fs::read(&victim).unwrap(), b"keep me");
    }

    /// docs/api.md promises job ids are never reused, even if the database is lost: a job
    /// lost with its database before its first batch had no folder, so its id came back.
    #[test]
    fn job_ids_are_not_reused_after_the_database_is_lost() {
        let dir = tempfile::tempdir().unwrap();
        let mut store = Store::open(dir.path()).unwrap();
        let insert = |s: &mut Store| {
            let id = s.next_job_id().unwrap();
            let job = NewJob {
                id,
                created_ms: 0,
                settings: "{}".into(),
                render: "{}".into(),
                scene: "s.xml".into(),
                bundle: "b".into(),
                total: 4,
                window: 4,
                width: 2,
                height: 2,
                frame_of: None,
                frames: None,
            };
            s.apply(&[Write::InsertJob(job)]).unwrap();
            id
        };
        assert_eq!(insert(&mut store), 1);
        drop(store);
        for f in [
            "photonfarm.sqlite",
            "photonfarm.sqlite-wal",
            "photonfarm.sqlite-shm",
        ] {
            let _ = std::fs::remove_file(dir.path().join(f));
        }
        let mut store = Store::open(dir.path()).unwrap();
        assert_eq!(insert(&mut store), 2);
    }
}
