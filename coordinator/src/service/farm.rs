//! The farm's state and rules: jobs, their schedulers and sums, kept durable in the store.
//! The HTTP layer ([`crate::service::api`]) only translates requests into these calls.
//!
//! The farm sits behind one mutex, so every method here is bookkeeping only: no fsync, no
//! image encoding, no per-pixel work and no allocation proportional to a job's size. Those
//! happen in the callers, outside the lock: a result is decoded and written to disk before
//! [`Farm::commit`] counts it, and it is added to its job's sum under that job's own mutex
//! ([`JobSum`]), which [`Farm::commit`] hands out.
//!
//! Nor does the farm write its database. Each event (a lease, a result, a release, an expiry,
//! a cancel, a checkpoint, a submission) leaves the list of its writes, and [`SharedFarm::run`]
//! commits them in one SQLite transaction after letting the farm's lock go, as mini-redis's
//! `Db` keeps its state behind one short lock. The store's own lock is taken before the
//! farm's is released, so events reach the database in the order they happened.

use std::collections::{BTreeMap, HashMap};
use std::hash::{BuildHasher, Hasher};
use std::sync::{Arc, Mutex, MutexGuard};
use std::time::{Duration, Instant, SystemTime, UNIX_EPOCH};

use photonfarm::features::Features;
use photonfarm::job::JobSettings;
use photonfarm::limits::Limits;
use photonfarm::protocol::{HeartbeatReply, Lease, LeaseRequest};
use photonfarm::render::{Method, RenderSettings};
use serde::Serialize;

use crate::service::accumulator::Accumulator;
use crate::service::scheduler::{Grant, JobState, LeaseError, Scheduler, SchedulerConfig};
use crate::service::store::{
    JobRow, JobStats, Layout, LeaseRow, NewJob, Store, StoreError, StoredBatch, Write,
};
use crate::service::workers::{Holding, Roster, WorkerStatus};

/// Farm settings.
#[derive(Clone, Copy, Debug)]
pub struct FarmConfig {
    /// Lease timeouts and batch sizing.
    pub scheduler: SchedulerConfig,
    /// Checkpoint interval of jobs that do not set one.
    pub default_checkpoint: u64,
    /// The largest job admitted (also applied to jobs found in the database at start).
    pub limits: Limits,
}

impl Default for FarmConfig {
    fn default() -> Self {
        FarmConfig {
            scheduler: SchedulerConfig::default(),
            default_checkpoint: 64,
            limits: Limits::for_this_machine(),
        }
    }
}

/// Why a farm operation failed.
#[derive(Debug, thiserror::Error)]
pub enum FarmError {
    /// No such job.
    #[error("no job {0}")]
    NoJob(u64),
    /// The lease cannot be used.
    #[error(transparent)]
    Lease(#[from] LeaseError),
    /// The lease was granted to another worker (its key does not match).
    #[error("lease {0} was granted to another worker")]
    NotYours(u64),
    /// The uploaded result does not fit its lease.
    #[error("result does not match the lease: {0}")]
    BadResult(String),
    /// Storage failed.
    #[error(transparent)]
    Store(#[from] StoreError),
    /// The job's image is not there yet.
    #[error("job {0} has no checkpoint yet")]
    NoImage(u64),
}

pub use photonfarm::protocol::{FrameStatus, JobStatus};

/// A job's running sum, with its own lock: merging a result and writing the prefix and the
/// checkpoint images happen under it, never under the farm's.
pub type JobSum = Arc<Mutex<Accumulator>>;

struct JobEntry {
    created_ms: u64,
    render: RenderSettings,
    scene: String,
    bundle: String,
    defines: Vec<(String, String)>,
    /// Whether workers sum the denoiser's features for it (`--aovs`, `--denoise`).
    features: bool,
    /// Whether its checkpoints get a denoised preview.
    denoise: bool,
    width: u32,
    height: u32,
    total: u64,
    /// The running sum while the job may still receive results. None once the job is over:
    /// its sums are on disk, and a finished job holds no pixels in memory.
    sum: Option<JobSum>,
    /// Passes in the latest image on disk (the job is reported done only once this reaches
    /// the total, so a client told "done" always finds the final image).
    image_passes: u64,
    started: Option<Instant>,
    finished: Option<Instant>,
    /// Counters as stored when this process started: elapsed time, batches and bytes go on
    /// from them.
    before: JobStats,
    batches_received: u64,
    bytes_received: u64,
    /// Noise estimates (passes, variance), by passes; those from `noise_saved` on are not in
    /// the database yet (they are saved at the next checkpoint).
    noise: Vec<(u64, f64)>,
    noise_saved: usize,
    /// Of a frame of a sequence: the sequence's job and the frame number.
    frame_of: Option<(u64, u32)>,
    /// Of a sequence: its frames' (frame number, job). A sequence is bookkeeping only: its
    /// frames are jobs, scheduled, summed and stored as any.
    frames: Vec<(u32, u64)>,
}

/// One frame of a sequence to create: its settings resolved against its scene, and its empty
/// sum (allocated by the caller, outside the lock).
pub struct FrameJob {
    /// The frame number.
    pub frame: u32,
    /// Its scene's path in the bundle.
    pub scene: String,
    /// The frame's settings ([`JobSettings::for_frame`]).
    pub settings: JobSettings,
    /// What workers run for it.
    pub render: RenderSettings,
    /// Its passes.
    pub total: u64,
    /// Its empty sum.
    pub sum: Accumulator,
}

/// What `GET /api/jobs/{id}/noise` answers.
#[derive(Clone, Debug, Serialize)]
pub struct NoiseReport {
    /// The job.
    pub id: u64,
    /// Whether the estimate is being followed: false once a result without its odd passes
    /// (from an older worker) was merged.
    pub tracking: bool,
    /// (passes, estimated variance of the image), by passes.
    pub points: Vec<NoisePoint>,
}

/// One noise estimate.
#[derive(Clone, Copy, Debug, Serialize)]
pub struct NoisePoint {
    /// Passes in the image.
    pub passes: u64,
    /// Estimated variance of the image: its expected mean squared error, over pixels and
    /// channels, against the converged image.
    pub variance: f64,
}

impl JobEntry {
    /// Time a coordinator spent on the job, this one and those before a restart.
    fn elapsed(&self) -> Duration {
        let now = match (self.started, self.finished) {
            (Some(s), Some(f)) => f - s,
            (Some(s), None) => s.elapsed(),
            _ => Duration::ZERO,
        };
        Duration::from_millis(self.before.elapsed_ms) + now
    }

    fn stats(&self) -> JobStats {
        JobStats {
            elapsed_ms: self.elapsed().as_millis() as u64,
            batches_received: self.batches_received,
            bytes_received: self.bytes_received,
        }
    }
}

/// A result the caller may add to the job's sum: counted and recorded by [`Farm::commit`].
pub struct Committed {
    /// The job.
    pub job: u64,
    /// The job's sum.
    pub sum: JobSum,
    /// The job's pass count.
    pub total: u64,
}

/// What a result for a lease must be (checked before the body is read and decoded).
#[derive(Clone, Copy, Debug)]
pub struct Expected {
    /// The job.
    pub job: u64,
    /// First pass.
    pub start: u64,
    /// One past the last.
    pub end: u64,
    /// Image width.
    pub width: u32,
    /// Image height.
    pub height: u32,
    /// Whether the result must carry the denoiser's features.
    pub features: bool,
    /// Whether checkpoints get a denoised preview.
    pub denoise: bool,
}

/// The farm and its store, each behind its own lock (see the module's note).
pub struct SharedFarm {
    farm: Mutex<Farm>,
    store: Mutex<Store>,
    /// Woken when an event makes passes available (a submission, a release, an expiry), for
    /// lease requests that wait for work instead of polling.
    work: tokio::sync::Notify,
}

fn locked<T>(m: &Mutex<T>) -> MutexGuard<'_, T> {
    m.lock().unwrap_or_else(|p| p.into_inner())
}

impl SharedFarm {
    /// Opens the farm on its store (see [`Farm::open`]).
    pub fn open(mut store: Store, config: FarmConfig) -> Result<SharedFarm, FarmError> {
        let farm = Farm::open(&mut store, config)?;
        Ok(SharedFarm {
            farm: Mutex::new(farm),
            store: Mutex::new(store),
            work: tokio::sync::Notify::new(),
        })
    }

    /// Applies one event to the farm and makes its writes durable in one transaction, after
    /// the farm's lock is let go: reads of the farm never wait for an fsync. The writes are
    /// made even when the event fails (a lease request that fails a job still saves that).
    pub fn run<T>(&self, event: impl FnOnce(&mut Farm) -> Result<T, FarmError>) -> Result<T, FarmError> {
        let mut farm = locked(&self.farm);
        let out = event(&mut farm);
        let writes = std::mem::take(&mut farm.writes);
        let new_work = std::mem::take(&mut farm.new_work);
        if writes.is_empty() {
            return out;
        }
        let mut store = locked(&self.store);
        drop(farm);
        store.apply(&writes)?;
        drop(store);
        if new_work {
            self.work.notify_waiters();
        }
        out
    }

    /// Completes when an event after this call makes passes available. Create it before
    /// asking for a lease, so that work arriving in between is not missed.
    pub fn new_work(&self) -> tokio::sync::futures::Notified<'_> {
        self.work.notified()
    }

    /// Reads the farm (no event: nothing to write).
    pub fn read<T>(&self, f: impl FnOnce(&Farm) -> T) -> T {
        f(&locked(&self.farm))
    }

    /// The store, for reads outside any event.
    pub fn store(&self) -> MutexGuard<'_, Store> {
        locked(&self.store)
    }
}

/// The coordinator's state.
pub struct Farm {
    layout: Layout,
    /// Writes the current event made, for [`SharedFarm::run`] to commit.
    writes: Vec<Write>,
    /// Whether the current event made passes available (to wake waiting lease requests).
    new_work: bool,
    /// The next job's id.
    next_job: u64,
    scheduler: Scheduler,
    jobs: BTreeMap<u64, JobEntry>,
    epoch: Instant,
    /// A lease expires this long after its last heartbeat.
    lease_timeout_ms: u64,
    /// Workers heartbeat four times per timeout, so one lost heartbeat never costs a lease.
    heartbeat_ms: u64,
    default_checkpoint: u64,
    /// The secret of each live lease: only the worker it was granted to knows it, so no other
    /// token holder can heartbeat, complete or release it.
    lease_keys: HashMap<u64, String>,
    /// Seeds the lease secrets (randomly keyed by the standard library per process).
    key_source: std::collections::hash_map::RandomState,
    /// The workers seen lately.
    roster: Roster,
    /// Each job's state, first unissued pass and message as last written to the store, so
    /// that [`Farm::save_changes`] finds what the scheduler changed.
    saved: HashMap<u64, Saved>,
}

/// What of a job's scheduling the store keeps: (state, first unissued pass, message).
type Saved = (JobState, u64, Option<String>);

fn unix_ms() -> u64 {
    SystemTime::now()
        .duration_since(UNIX_EPOCH)
        .map_or(0, |d| d.as_millis() as u64)
}

/// A job as restored from the store, or why it cannot be.
struct Restored {
    entry: JobEntry,
    done: Vec<(u64, u64)>,
    next_start: u64,
    state: JobState,
}

impl Farm {
    /// Opens the store and resumes every unfinished job from its durable state. A job that
    /// cannot be restored (damaged files, sizes beyond the limits) is marked failed with a
    /// message; it never stops the others, or the coordinator, from starting.
    pub fn open(store: &mut Store, config: FarmConfig) -> Result<Farm, FarmError> {
        let first_lease = store.reserve_lease_ids()?;
        let mut scheduler = Scheduler::new(config.scheduler, first_lease);
        let mut jobs = BTreeMap::new();
        let mut saved = HashMap::new();
        for row in store.load_jobs()? {
            let id = row.id;
            if row.frames.is_some() {
                // A sequence: bookkeeping over its frames' jobs, restored below as any job.
                let settings: JobSettings = serde_json::from_str(&row.settings).unwrap_or_default();
                jobs.insert(id, entry_of(&row, placeholder_render(&row), &settings, None));
                continue;
            }
            match restore(store, &row, &config.limits) {
                Ok(r) => {
                    if r.state != row.state {
                        store.update_job(id, row.next_start, r.state, None)?;
                    }
                    scheduler.add_job(id, row.total, row.window, r.next_start, &r.done, r.state);
                    scheduler.set_pixels(id, row.width as u64 * row.height as u64);
                    // A failed job keeps its failure's message across restarts.
                    if r.state == JobState::Failed
                        && let Some(message) = row.message.clone()
                    {
                        scheduler.set_failed(id, message);
                    }
                    let message = (r.state == row.state).then(|| row.message.clone()).flatten();
                    saved.insert(id, (r.state, row.next_start, message));
                    jobs.insert(id, r.entry);
                }
                Err(message) => {
                    tracing::error!(job = id, "cannot resume: {message}");
                    let message = format!("the coordinator could not resume this job: {message}");
                    store.update_job(id, row.next_start, JobState::Failed, Some(&message))?;
                    scheduler.add_job(id, row.total, row.window, row.next_start, &[], JobState::Failed);
                    scheduler.set_failed(id, message.clone());
                    saved.insert(id, (JobState::Failed, row.next_start, Some(message)));
                    jobs.insert(
                        id,
                        entry_of(&row, placeholder_render(&row), &JobSettings::default(), None),
                    );
                }
            }
        }
        // Each sequence's frames are scheduled as a group again.
        for seq in jobs.values().filter(|j: &&JobEntry| !j.frames.is_empty()) {
            let last = seq.frames.iter().map(|f| f.1).max().unwrap_or(0);
            for &(_, frame) in &seq.frames {
                scheduler.set_group(frame, last);
            }
        }
        // Leases granted before the restart: their workers may be rendering them, or holding
        // a finished batch until the coordinator answers. Each gets one lease timeout from now
        // (the grace period) to heartbeat or deliver, like any live lease.
        let grace = config.scheduler.lease_timeout_ms;
        let mut lease_keys = HashMap::new();
        let mut stale = Vec::new();
        for row in store.load_leases()? {
            let grant = Grant {
                lease_id: row.id,
                job_id: row.job,
                start: row.start,
                end: row.end,
            };
            if scheduler.restore_lease(row.id, &grant, &row.worker, grace) {
                lease_keys.insert(row.id, row.key);
            } else {
                stale.push(row.id);
            }
        }
        store.delete_leases(&stale)?;
        if !lease_keys.is_empty() {
            tracing::info!(
                leases = lease_keys.len(),
                grace_ms = grace,
                "restored the leases held before the restart"
            );
        }
        Ok(Farm {
            layout: store.layout().clone(),
            writes: Vec::new(),
            new_work: false,
            next_job: store.next_job_id()?,
            scheduler,
            jobs,
            epoch: Instant::now(),
            lease_timeout_ms: config.scheduler.lease_timeout_ms,
            heartbeat_ms: (config.scheduler.lease_timeout_ms / 4).max(10),
            default_checkpoint: config.default_checkpoint,
            lease_keys,
            key_source: std::collections::hash_map::RandomState::new(),
            roster: Roster::default(),
            saved,
        })
    }

    fn now(&self) -> u64 {
        self.epoch.elapsed().as_millis() as u64
    }

    /// The data folder's paths, for file work outside the lock.
    pub fn layout(&self) -> Layout {
        self.layout.clone()
    }

    /// The checkpoint interval a job with these settings gets.
    pub fn window_of(&self, settings: &JobSettings) -> u64 {
        settings
            .checkpoint_every
            .unwrap_or(self.default_checkpoint)
            .max(1)
    }

    /// Creates a job from settings already checked against the loaded scene and the limits;
    /// `sum` is its empty sum, allocated by the caller outside the lock.
    pub fn create_job(
        &mut self,
        settings: &JobSettings,
        render: RenderSettings,
        total: u64,
        scene: &str,
        bundle: &str,
        sum: Accumulator,
    ) -> Result<u64, FarmError> {
        let job = FrameJob {
            frame: 0,
            scene: scene.to_string(),
            settings: settings.clone(),
            render,
            total,
            sum,
        };
        Ok(self.insert_job(job, bundle, None))
    }

    /// Creates a sequence: one job per frame, in the order given, and the sequence's own job
    /// that follows them. The frames' jobs are scheduled as a group: a lease goes to the first
    /// frame with passes left, so frames finish in order and early ones can be looked at first.
    pub fn create_sequence(
        &mut self,
        settings: &JobSettings,
        frames: Vec<FrameJob>,
        scene: &str,
        bundle: &str,
    ) -> Result<u64, FarmError> {
        let first = frames
            .first()
            .ok_or(FarmError::BadResult("a sequence without frames".into()))?;
        let id = self.next_job;
        self.next_job += 1;
        let ids: Vec<(u32, u64)> = frames
            .iter()
            .enumerate()
            .map(|(i, f)| (f.frame, id + 1 + i as u64))
            .collect();
        let (width, height) = first.sum.size();
        let total = frames.iter().map(|f| f.total).sum();
        let render = first.render;
        let new = NewJob {
            id,
            created_ms: unix_ms(),
            settings: serde_json::to_string(settings).expect("settings serialise"),
            render: serde_json::to_string(&render).expect("settings serialise"),
            scene: scene.to_string(),
            bundle: bundle.to_string(),
            total,
            window: 1,
            width,
            height,
            frame_of: None,
            frames: Some(serde_json::to_string(&ids).expect("frames serialise")),
        };
        let row = JobRow::from(&new);
        self.writes.push(Write::InsertJob(new));
        let mut entry = entry_of(&row, render, settings, None);
        entry.frames = ids.clone();
        self.jobs.insert(id, entry);
        let last = ids.last().map_or(id, |f| f.1);
        for job in frames {
            let frame = job.frame;
            let child = self.insert_job(job, bundle, Some((id, frame)));
            self.scheduler.set_group(child, last);
        }
        Ok(id)
    }

    /// Creates one job (an image, or a frame of sequence `frame_of.0`).
    fn insert_job(&mut self, job: FrameJob, bundle: &str, frame_of: Option<(u64, u32)>) -> u64 {
        let FrameJob {
            scene,
            settings,
            render,
            total,
            sum,
            ..
        } = job;
        let window = self.window_of(&settings);
        let (width, height) = sum.size();
        let id = self.next_job;
        self.next_job += 1;
        let new = NewJob {
            id,
            created_ms: unix_ms(),
            settings: serde_json::to_string(&settings).expect("settings serialise"),
            render: serde_json::to_string(&render).expect("settings serialise"),
            scene,
            bundle: bundle.to_string(),
            total,
            window,
            width,
            height,
            frame_of,
            frames: None,
        };
        let row = JobRow::from(&new);
        self.writes.push(Write::InsertJob(new));
        self.scheduler
            .add_job(id, total, window, 0, &[], JobState::Queued);
        self.new_work = true;
        self.scheduler.set_pixels(id, width as u64 * height as u64);
        self.saved.insert(id, (JobState::Queued, 0, None));
        self.jobs.insert(
            id,
            entry_of(&row, render, &settings, Some(Arc::new(Mutex::new(sum)))),
        );
        id
    }

    fn new_key(&self) -> String {
        let mut a = self.key_source.build_hasher();
        a.write_u64(self.scheduler.next_lease_id());
        let mut b = self.key_source.build_hasher();
        b.write_u64(!self.scheduler.next_lease_id());
        b.write_u128(Instant::now().duration_since(self.epoch).as_nanos());
        format!("{:016x}{:016x}", a.finish(), b.finish())
    }

    /// Grants a batch to a worker, if any job has work for it. SPPM radii are left empty:
    /// the caller fills them from the returned settings outside the lock (their cost grows
    /// with the pass index).
    pub fn lease(&mut self, req: &LeaseRequest) -> Result<Option<Lease>, FarmError> {
        let now = self.now();
        let key = self.new_key();
        self.roster.asked(&req.worker, req.threads);
        let granted = self.scheduler.lease_for(&req.worker, req.renderers, now);
        // Looking for work may fail a job that no worker may take any more.
        self.save_changes()?;
        let Some(g) = granted else {
            return Ok(None);
        };
        self.lease_keys.insert(g.lease_id, key.clone());
        self.writes.push(Write::InsertLease(LeaseRow {
            id: g.lease_id,
            job: g.job_id,
            start: g.start,
            end: g.end,
            worker: req.worker.clone(),
            key: key.clone(),
        }));
        let job = self.jobs.get_mut(&g.job_id).expect("scheduled jobs are known");
        job.started.get_or_insert_with(Instant::now);
        let sequence = job.frame_of.map(|f| f.0);
        if let Some(seq) = sequence.and_then(|s| self.jobs.get_mut(&s)) {
            seq.started.get_or_insert_with(Instant::now);
        }
        let job = &self.jobs[&g.job_id];
        let lease = Lease {
            lease_id: g.lease_id,
            job_id: g.job_id,
            start: g.start,
            end: g.end,
            radii: Vec::new(),
            settings: job.render,
            bundle: job.bundle.clone(),
            scene: job.scene.clone(),
            defines: job.defines.clone(),
            deadline_ms: self.lease_timeout_ms,
            heartbeat_ms: self.heartbeat_ms,
            key,
            accept_encoding: vec![photonfarm::compression::ZSTD.to_string()],
            width: job.width,
            height: job.height,
            features: job.features,
        };
        Ok(Some(lease))
    }

    /// Checks that `key` is the secret of live lease `lease_id`.
    fn check_key(&self, lease_id: u64, key: &str) -> Result<(), FarmError> {
        match self.lease_keys.get(&lease_id) {
            None => Err(LeaseError::NotActive(lease_id).into()),
            Some(k) if k.as_bytes() == key.as_bytes() => Ok(()),
            Some(_) => Err(FarmError::NotYours(lease_id)),
        }
    }

    /// Extends a lease.
    pub fn heartbeat(&mut self, lease_id: u64, key: &str) -> Result<HeartbeatReply, FarmError> {
        self.check_key(lease_id, key)?;
        let now = self.now();
        let deadline = self.scheduler.heartbeat(lease_id, now)?;
        if let Some(worker) = self.scheduler.lease_worker(lease_id) {
            self.roster.heard(worker);
        }
        Ok(HeartbeatReply {
            deadline_ms: deadline.saturating_sub(now),
        })
    }

    /// Image size and pass range a lease's result must have (checked before reading it).
    /// Also notes the result's arrival, to measure the worker's speed without the time its
    /// upload waits for the coordinator.
    pub fn expected_result(&mut self, lease_id: u64, key: &str) -> Result<Expected, FarmError> {
        self.check_key(lease_id, key)?;
        let now = self.now();
        let g = self.scheduler.lease_range(lease_id, now)?;
        self.scheduler.arriving(lease_id, now);
        let job = &self.jobs[&g.job_id];
        Ok(Expected {
            job: g.job_id,
            start: g.start,
            end: g.end,
            width: job.width,
            height: job.height,
            features: job.features,
            denoise: job.denoise,
        })
    }

    /// Refuses a lease's result that does not fit it: the lease ends as a failure of its
    /// worker.
    pub fn reject(&mut self, lease_id: u64, why: &str) -> Result<(), FarmError> {
        self.scheduler.release(lease_id, Some(why))?;
        self.new_work = true;
        self.forget_lease(lease_id)?;
        self.save_changes()
    }

    /// Counts a result already stored durably (by [`Layout::write_batch`]): the lease ends,
    /// its passes count once and the batch is recorded. The caller then adds the sum to the
    /// returned [`JobSum`] and calls [`Farm::checkpointed`] after writing any checkpoint.
    pub fn commit(&mut self, lease_id: u64, key: &str, bytes: u64) -> Result<Committed, FarmError> {
        self.check_key(lease_id, key)?;
        let now = self.now();
        let worker = self.scheduler.lease_worker(lease_id).map(str::to_string);
        let g: Grant = self.scheduler.complete(lease_id, now)?;
        if let Some(worker) = worker {
            let rate = self.scheduler.worker_rate(g.job_id, &worker).unwrap_or(0.0);
            self.roster.delivered(&worker, g.end - g.start, rate);
        }
        let batch = StoredBatch {
            start: g.start,
            end: g.end,
            lease: lease_id,
        };
        self.writes.push(Write::RecordBatch { job: g.job_id, batch });
        self.forget_lease(lease_id)?;
        let job = self.jobs.get_mut(&g.job_id).expect("known");
        job.batches_received += 1;
        job.bytes_received += bytes;
        // A job that takes results holds its sum; should that ever not hold, the result is
        // stored and recorded, and a restart merges it.
        let sum = job.sum.clone().ok_or(LeaseError::JobOver(g.job_id))?;
        let committed = Committed {
            job: g.job_id,
            sum,
            total: job.total,
        };
        self.persist_progress(g.job_id)?;
        Ok(committed)
    }

    /// Records that the prefix of `prefix_passes` passes is on disk, and the image of
    /// `image_passes` (if one was written); once the final image is there the job is done
    /// and its sum leaves memory.
    pub fn checkpointed(
        &mut self,
        job_id: u64,
        prefix_passes: u64,
        image_passes: Option<u64>,
    ) -> Result<(), FarmError> {
        let job = self.jobs.get_mut(&job_id).ok_or(FarmError::NoJob(job_id))?;
        self.writes.push(Write::ForgetMerged {
            job: job_id,
            passes: prefix_passes,
        });
        if job.noise_saved < job.noise.len() {
            self.writes.push(Write::Noise {
                job: job_id,
                points: job.noise[job.noise_saved..].to_vec(),
            });
            job.noise_saved = job.noise.len();
        }
        if let Some(p) = image_passes
            && p > job.image_passes
        {
            job.image_passes = p;
            self.writes.push(Write::ImagePasses {
                id: job_id,
                passes: p,
            });
        }
        if job.image_passes >= job.total {
            job.finished.get_or_insert_with(Instant::now);
            job.sum = None;
        }
        self.persist_progress(job_id)
    }

    /// Gives a lease back, after a failure or cleanly.
    pub fn release(&mut self, lease_id: u64, key: &str, error: Option<&str>) -> Result<(), FarmError> {
        self.check_key(lease_id, key)?;
        self.scheduler.release(lease_id, error)?;
        self.new_work = true;
        self.forget_lease(lease_id)?;
        // Also after the lease's deadline, before the expiry tick: the failure it may cause
        // is saved like any other (it once stayed in memory, and a restart revived the job).
        self.save_changes()
    }

    /// Ends expired leases so their passes go to other workers (each expiry counts as a
    /// failure of the worker that held it).
    pub fn expire(&mut self) -> Result<usize, FarmError> {
        let expired = self.scheduler.expire(self.now());
        self.new_work |= !expired.is_empty();
        for &(lease, job) in &expired {
            tracing::warn!(
                lease,
                job,
                "lease expired without a heartbeat; its passes will be re-issued"
            );
            self.forget_lease(lease)?;
        }
        self.save_changes()?;
        Ok(expired.len())
    }

    /// A lease ended: its secret and its stored row go.
    fn forget_lease(&mut self, lease_id: u64) -> Result<(), FarmError> {
        self.lease_keys.remove(&lease_id);
        self.writes.push(Write::DeleteLease(lease_id));
        Ok(())
    }

    /// Cancels a job.
    pub fn cancel(&mut self, id: u64) -> Result<JobStatus, FarmError> {
        let frames: Vec<u64> = match self.jobs.get(&id) {
            Some(j) if !j.frames.is_empty() => j.frames.iter().map(|f| f.1).collect(),
            Some(_) => vec![id],
            None => return Err(FarmError::NoJob(id)),
        };
        for &job in &frames {
            if !self.scheduler.cancel(job) {
                return Err(FarmError::NoJob(job));
            }
        }
        let void: Vec<u64> = self
            .lease_keys
            .keys()
            .copied()
            .filter(|&l| !self.scheduler.is_live(l))
            .collect();
        for lease in void {
            self.forget_lease(lease)?;
        }
        for job in frames {
            self.persist_progress(job)?;
        }
        self.status(id).ok_or(FarmError::NoJob(id))
    }

    /// The state as reported and stored: a job whose every pass is in but whose final image
    /// is not yet written is still running.
    fn reported_state(&self, id: u64) -> Option<(JobState, u64, u64, Option<String>)> {
        let (mut state, done, total, message) = self.scheduler.status(id)?;
        let job = self.jobs.get(&id)?;
        if state == JobState::Done && job.image_passes < job.total {
            state = JobState::Running;
        }
        Some((state, done, total, message))
    }

    /// Writes every job whose state, first unissued pass or message differs from what the
    /// store holds: the scheduler decides these (a lease, a failure, an expiry), and each of
    /// its decisions is saved here, so none stays in memory only.
    fn save_changes(&mut self) -> Result<(), FarmError> {
        let changed: Vec<u64> = self
            .jobs
            .keys()
            .copied()
            .filter(|&id| self.saved.get(&id) != self.scheduling(id).as_ref())
            .collect();
        for id in changed {
            self.persist_progress(id)?;
        }
        Ok(())
    }

    /// A job's scheduling as the store keeps it.
    fn scheduling(&self, id: u64) -> Option<Saved> {
        let (state, _, _, message) = self.reported_state(id)?;
        Some((state, self.scheduler.next_start(id).unwrap_or(0), message))
    }

    fn persist_progress(&mut self, id: u64) -> Result<(), FarmError> {
        let (state, _, _, message) = self.reported_state(id).ok_or(FarmError::NoJob(id))?;
        if state.is_final()
            && let Some(job) = self.jobs.get_mut(&id)
        {
            // Failed or cancelled: nothing will be added to the sum again.
            job.sum = None;
            job.finished.get_or_insert_with(Instant::now);
        }
        let next_start = self.scheduler.next_start(id).unwrap_or(0);
        let stats = self.jobs.get(&id).map(JobEntry::stats).unwrap_or_default();
        self.writes.push(Write::Progress {
            id,
            next_start,
            state,
            message: message.clone(),
            stats,
        });
        self.saved.insert(id, (state, next_start, message));
        if let Some((sequence, _)) = self.jobs.get(&id).and_then(|j| j.frame_of) {
            self.persist_sequence(sequence);
        }
        Ok(())
    }

    /// Writes a sequence's state and counters, as its frames make them.
    fn persist_sequence(&mut self, id: u64) {
        let Some(status) = self.status(id) else {
            return;
        };
        let Some(seq) = self.jobs.get_mut(&id) else {
            return;
        };
        if status.state.is_final() {
            seq.finished.get_or_insert_with(Instant::now);
        }
        let stats = JobStats {
            elapsed_ms: seq.elapsed().as_millis() as u64,
            batches_received: status.batches_received,
            bytes_received: status.bytes_received,
        };
        self.writes.push(Write::Progress {
            id,
            next_start: 0,
            state: status.state,
            message: status.message,
            stats,
        });
    }

    /// A sequence's status: its frames' summed, its state from theirs.
    fn sequence_status(&self, id: u64, seq: &JobEntry) -> JobStatus {
        let frames: Vec<(u32, JobStatus)> = seq
            .frames
            .iter()
            .filter_map(|&(f, job)| Some((f, self.status(job)?)))
            .collect();
        let all = |s: JobState| frames.iter().all(|(_, f)| f.state == s);
        let failed = frames.iter().find(|(_, f)| f.state == JobState::Failed);
        let state = if let Some((_, _)) = failed {
            JobState::Failed
        } else if all(JobState::Done) {
            JobState::Done
        } else if frames.iter().all(|(_, f)| f.state.is_final()) {
            JobState::Cancelled
        } else if all(JobState::Queued) {
            JobState::Queued
        } else {
            JobState::Running
        };
        let message = failed.map(|(n, f)| format!("frame {n}: {}", f.message.as_deref().unwrap_or("failed")));
        let sum = |get: fn(&JobStatus) -> u64| frames.iter().map(|(_, f)| get(f)).sum::<u64>();
        let done = sum(|f| f.iterations_done);
        let mut workers: Vec<String> = frames.iter().flat_map(|(_, f)| f.workers.clone()).collect();
        workers.sort();
        workers.dedup();
        let elapsed = seq.elapsed().as_secs_f64();
        JobStatus {
            id,
            state,
            iterations_done: done,
            iterations_total: sum(|f| f.iterations_total),
            checkpoint_iterations: sum(|f| f.checkpoint_iterations),
            workers,
            workers_present: self.scheduler.workers_present(),
            elapsed_seconds: elapsed,
            rate: if elapsed > 0.0 { done as f64 / elapsed } else { 0.0 },
            integrator: seq.render.method.name().to_string(),
            width: seq.width,
            height: seq.height,
            message,
            created_unix_ms: seq.created_ms,
            batches_received: sum(|f| f.batches_received),
            bytes_received: sum(|f| f.bytes_received),
            sequence: None,
            frame: None,
            frames: frames
                .iter()
                .map(|(n, f)| FrameStatus {
                    frame: *n,
                    job: f.id,
                    state: f.state,
                    iterations_done: f.iterations_done,
                    iterations_total: f.iterations_total,
                    checkpoint_iterations: f.checkpoint_iterations,
                })
                .collect(),
            denoise: seq.denoise,
        }
    }

    /// A job's status.
    pub fn status(&self, id: u64) -> Option<JobStatus> {
        let job = self.jobs.get(&id)?;
        if !job.frames.is_empty() {
            return Some(self.sequence_status(id, job));
        }
        let (state, done, total, message) = self.reported_state(id)?;
        let elapsed = job.elapsed().as_secs_f64();
        let rate = if elapsed > 0.0 { done as f64 / elapsed } else { 0.0 };
        Some(JobStatus {
            id,
            state,
            iterations_done: done,
            iterations_total: total,
            checkpoint_iterations: job.image_passes,
            workers: self.scheduler.workers_on(id),
            workers_present: self.scheduler.workers_present(),
            elapsed_seconds: elapsed,
            rate,
            integrator: job.render.method.name().to_string(),
            width: job.width,
            height: job.height,
            message,
            created_unix_ms: job.created_ms,
            batches_received: job.batches_received,
            bytes_received: job.bytes_received,
            sequence: job.frame_of.map(|f| f.0),
            frame: job.frame_of.map(|f| f.1),
            frames: Vec::new(),
            denoise: job.denoise,
        })
    }

    /// Leases held now (batches being rendered).
    pub fn live_leases(&self) -> usize {
        self.lease_keys.len()
    }

    /// Workers that asked for work lately.
    pub fn workers_present(&self) -> usize {
        self.scheduler.workers_present()
    }

    /// Every job, oldest first; a sequence's frames are listed in its status, not here.
    pub fn list(&self) -> Vec<JobStatus> {
        self.jobs
            .iter()
            .filter(|(_, j)| j.frame_of.is_none())
            .filter_map(|(&id, _)| self.status(id))
            .collect()
    }

    /// Jobs that hold their sum in memory (those that may still receive results).
    pub fn sums_in_memory(&self) -> usize {
        self.jobs.values().filter(|j| j.sum.is_some()).count()
    }

    /// The path of a job's latest checkpoint image.
    /// Of a sequence: its latest frame (in the order given) with an image.
    pub fn image(&self, id: u64, name: &str, ext: &str) -> Result<std::path::PathBuf, FarmError> {
        let job = self.jobs.get(&id).ok_or(FarmError::NoJob(id))?;
        if !job.frames.is_empty() {
            return job
                .frames
                .iter()
                .rev()
                .find_map(|&(_, frame)| self.image(frame, name, ext).ok())
                .ok_or(FarmError::NoImage(id));
        }
        let path = self.layout.image_path_named(id, name, ext);
        if job.image_passes > 0 && path.exists() {
            Ok(path)
        } else {
            Err(FarmError::NoImage(id))
        }
    }

    /// Records noise estimates of a job as its prefix grew (saved at its next checkpoint).
    pub fn record_noise(&mut self, job_id: u64, points: &[(u64, f64)]) {
        if let Some(job) = self.jobs.get_mut(&job_id) {
            for &p in points {
                if job.noise.last().is_none_or(|l| l.0 < p.0) {
                    job.noise.push(p);
                }
            }
        }
    }

    /// A job's noise estimates. `tracking` is read from its sum, which the caller locks
    /// (None for a job that is over: its estimates are all there).
    pub fn noise(&self, id: u64) -> Result<(Vec<NoisePoint>, Option<JobSum>), FarmError> {
        let job = self.jobs.get(&id).ok_or(FarmError::NoJob(id))?;
        let points = job
            .noise
            .iter()
            .map(|&(passes, variance)| NoisePoint { passes, variance })
            .collect();
        Ok((points, job.sum.clone()))
    }

    /// The workers seen lately, with the batches they hold.
    pub fn workers(&self) -> Vec<WorkerStatus> {
        let holding: Vec<(String, Holding)> = self
            .scheduler
            .holdings()
            .into_iter()
            .map(|(w, g)| {
                (
                    w,
                    Holding {
                        job: g.job_id,
                        start: g.start,
                        end: g.end,
                    },
                )
            })
            .collect();
        self.roster.list(&holding)
    }

    /// Whether a bundle hash belongs to a job (workers may only fetch those).
    pub fn knows_bundle(&self, hash: &str) -> bool {
        self.jobs.values().any(|j| j.bundle == hash)
    }
}

fn entry_of(row: &JobRow, render: RenderSettings, settings: &JobSettings, sum: Option<JobSum>) -> JobEntry {
    JobEntry {
        created_ms: row.created_ms,
        render,
        scene: row.scene.clone(),
        bundle: row.bundle.clone(),
        defines: settings.defines.clone(),
        features: settings.features(),
        denoise: settings.denoise,
        width: row.width,
        height: row.height,
        total: row.total,
        sum,
        image_passes: row.image_passes,
        started: None,
        finished: None,
        before: row.stats,
        batches_received: row.stats.batches_received,
        bytes_received: row.stats.bytes_received,
        noise: Vec::new(),
        noise_saved: 0,
        frame_of: row.frame_of,
        frames: row
            .frames
            .as_deref()
            .and_then(|f| serde_json::from_str(f).ok())
            .unwrap_or_default(),
    }
}

/// Render settings for the status of a job whose stored ones cannot be read.
fn placeholder_render(row: &JobRow) -> RenderSettings {
    serde_json::from_str(&row.render).unwrap_or(RenderSettings {
        seed: 0,
        method: Method::Path(photonfarm::integrator::path::PathSettings {
            max_depth: None,
            rr_depth: 5,
        }),
    })
}

/// Restores one job from its row and files, or says why it cannot be.
fn restore(store: &mut Store, row: &JobRow, limits: &Limits) -> Result<Restored, String> {
    let render: RenderSettings =
        serde_json::from_str(&row.render).map_err(|e| format!("its settings are damaged: {e}"))?;
    let settings: JobSettings =
        serde_json::from_str(&row.settings).map_err(|e| format!("its settings are damaged: {e}"))?;
    // Checked before anything is allocated: a job stored by an older version, or under
    // larger limits, must not take the coordinator down at every start.
    limits
        .check_job(row.width, row.height, Some(row.total), &render)
        .map_err(|e| e.to_string())?;
    if row.total == 0 || row.window == 0 {
        return Err("it has no passes".into());
    }
    let mut image_passes = row.image_passes;
    if row.state.is_final() {
        // Over: its sums stay on disk. Jobs stored before image_passes was recorded count
        // their final image as whole.
        if row.state == JobState::Done {
            image_passes = row.total;
        }
        let mut entry = entry_of(row, render, &settings, None);
        entry.image_passes = image_passes;
        entry.noise = store.load_noise(row.id).map_err(|e| e.to_string())?;
        entry.noise_saved = entry.noise.len();
        return Ok(Restored {
            entry,
            done: vec![(0, image_passes.min(row.total))],
            next_start: row.next_start,
            state: row.state,
        });
    }
    let layout = store.layout().clone();
    let stored = layout
        .load_prefix(row.id, row.width, row.height)
        .map_err(|e| format!("its summed passes are damaged: {e}"))?;
    let prefix = stored.sum;
    if (prefix.width, prefix.height) != (row.width, row.height) {
        return Err(format!(
            "its stored sum is {}x{}, not {}x{}",
            prefix.width, prefix.height, row.width, row.height
        ));
    }
    // A job with features that has stored no prefix yet starts from empty features.
    let features = match stored.features {
        Some(f) => Some(f),
        None if settings.features() && prefix.passes == 0 => Some(Features::new(row.width, row.height)),
        None => None,
    };
    let mut acc = Accumulator::new(prefix, stored.odd, features, row.window);
    let mut done = vec![(0, acc.prefix_passes())];
    let mut noise = store.load_noise(row.id).map_err(|e| e.to_string())?;
    let noise_saved = noise.len();
    let last_saved = noise.last().map_or(0, |l| l.0);
    let ranges = store.batch_ranges(row.id).map_err(|e| e.to_string())?;
    for batch in ranges {
        let StoredBatch { start, end, .. } = batch;
        if end <= acc.prefix_passes() {
            // Merged into the stored prefix by a checkpoint the coordinator stopped after, before
            // forgetting its batches: nothing to read or count again (the next checkpoint's
            // `ForgetMerged` removes it).
            continue;
        }
        // A damaged batch is dropped: its passes are simply rendered again.
        let added = layout
            .load_batch(row.id, batch, row.width, row.height)
            .and_then(|r| {
                acc.add(start, r.sum, r.odd, r.features)
                    .map_err(|e| StoreError::Corrupt(format!("batch {start}..{end}"), e.to_string()))
            })
            .map(|merged| noise.extend(merged.noise.into_iter().filter(|p| p.0 > last_saved)));
        match added {
            Ok(()) => done.push((start, end)),
            Err(e) => {
                tracing::warn!(
                    job = row.id,
                    "dropping a damaged batch ({e}); its passes will be rendered again"
                );
                store.forget_batch(row.id, batch).map_err(|e| e.to_string())?;
            }
        }
    }
    let mut state = row.state;
    if acc.prefix_passes() >= row.total {
        // Every pass was stored but the coordinator stopped before finishing the job.
        layout
            .write_prefix(row.id, acc.prefix(), acc.odd(), acc.features())
            .and_then(|_| layout.write_images(row.id, acc.prefix(), acc.features()))
            .map_err(|e| e.to_string())?;
        if settings.denoise
            && let Some(f) = acc.features()
            && let Err(e) = layout.write_denoised(row.id, acc.prefix(), f)
        {
            tracing::warn!(job = row.id, "no denoised preview: {e}");
        }
        store
            .apply(&[
                Write::ForgetMerged {
                    job: row.id,
                    passes: acc.prefix_passes(),
                },
                Write::ImagePasses {
                    id: row.id,
                    passes: row.total,
                },
            ])
            .map_err(|e| e.to_string())?;
        image_passes = row.total;
        state = JobState::Done;
    }
    let sum = (!state.is_final()).then(|| Arc::new(Mutex::new(acc)));
    let mut entry = entry_of(row, render, &settings, sum);
    entry.image_passes = image_passes;
    entry.noise = noise;
    entry.noise_saved = noise_saved;
    Ok(Restored {
        entry,
        done,
        next_start: row.next_start,
        state,
    })
}

#[cfg(test)]
mod tests {
    use super::*;
    use photonfarm::film::FilmSum;
    use photonfarm::integrator::path::PathSettings;

    fn render() -> RenderSettings {
        RenderSettings {
            seed: 0,
            method: Method::Path(PathSettings {
                max_depth: None,
                rr_depth: 5,
            }),
        }
    }

    #[test]
    fn jobs_that_are_over_hold_no_sums_in_memory_even_after_a_restart() {
        let dir = tempfile::tempdir().unwrap();
        let config = FarmConfig {
            limits: Limits::for_memory(1 << 30),
            ..FarmConfig::default()
        };
        let farm = SharedFarm::open(Store::open(dir.path()).unwrap(), config).unwrap();
        let settings = JobSettings {
            passes: Some(1),
            ..JobSettings::default()
        };
        let empty = || Accumulator::empty(4, 4, 1);
        let done = farm
            .run(|f| f.create_job(&settings, render(), 1, "s.xml", "h", empty()))
            .unwrap();
        let cancelled = farm
            .run(|f| f.create_job(&settings, render(), 1, "s.xml", "h", empty()))
            .unwrap();
        let running = farm
            .run(|f| f.create_job(&settings, render(), 1, "s.xml", "h", empty()))
            .unwrap();
        assert_eq!(farm.read(|f| f.sums_in_memory()), 3);

        // Render the first job: one result, its final image, and its sum leaves memory.
        let req = LeaseRequest {
            worker: "w".into(),
            threads: 1,
            renderers: None,
        };
        let lease = farm.run(|f| f.lease(&req)).unwrap().unwrap();
        assert_eq!(lease.job_id, done);
        assert!(matches!(
            farm.run(|f| f.commit(lease.lease_id, "not the key", 1)),
            Err(FarmError::NotYours(_))
        ));
        let c = farm.run(|f| f.commit(lease.lease_id, &lease.key, 1)).unwrap();
        let mut part = FilmSum::new(4, 4);
        part.passes = 1;
        let mut acc = c.sum.lock().unwrap();
        acc.add(0, part, None, None).unwrap();
        let layout = farm.read(|f| f.layout());
        layout.write_prefix(done, acc.prefix(), acc.odd(), None).unwrap();
        layout.write_images(done, acc.prefix(), None).unwrap();
        drop(acc);
        assert_eq!(
            farm.read(|f| f.status(done)).unwrap().state,
            JobState::Running,
            "no image yet"
        );
        farm.run(|f| f.checkpointed(done, 1, Some(1))).unwrap();
        assert_eq!(farm.read(|f| f.status(done)).unwrap().state, JobState::Done);
        farm.run(|f| f.cancel(cancelled)).unwrap();
        assert_eq!(farm.read(|f| f.sums_in_memory()), 1);

        drop(farm);
        let farm = SharedFarm::open(Store::open(dir.path()).unwrap(), config).unwrap();
        assert_eq!(farm.read(|f| f.sums_in_memory()), 1, "only the running job's");
        assert_eq!(farm.read(|f| f.status(done)).unwrap().state, JobState::Done);
        assert_eq!(farm.read(|f| f.status(done)).unwrap().checkpoint_iterations, 1);
        assert_eq!(farm.read(|f| f.status(running)).unwrap().state, JobState::Queued);
    }

    /// A farm of one one-pass job, leases expiring after `timeout_ms`, in `dir`.
    fn one_job_farm(dir: &std::path::Path, timeout_ms: u64) -> (SharedFarm, u64) {
        let config = FarmConfig {
            limits: Limits::for_memory(1 << 30),
            scheduler: SchedulerConfig {
                lease_timeout_ms: timeout_ms,
                ..SchedulerConfig::default()
            },
            ..FarmConfig::default()
        };
        let farm = SharedFarm::open(Store::open(dir).unwrap(), config).unwrap();
        let settings = JobSettings {
            passes: Some(1),
            ..JobSettings::default()
        };
        let job = farm
            .run(|f| f.create_job(&settings, render(), 1, "s.xml", "h", Accumulator::empty(4, 4, 1)))
            .unwrap();
        (farm, job)
    }

    fn ask(farm: &SharedFarm, worker: &str) -> Option<Lease> {
        let req = LeaseRequest {
            worker: worker.into(),
            threads: 1,
            renderers: None,
        };
        farm.run(|f| f.lease(&req)).unwrap()
    }

    /// The coordinator restarted on the same folder.
    fn restarted(farm: SharedFarm, dir: &std::path::Path) -> SharedFarm {
        drop(farm);
        let config = FarmConfig {
            limits: Limits::for_memory(1 << 30),
            ..FarmConfig::default()
        };
        SharedFarm::open(Store::open(dir).unwrap(), config).unwrap()
    }

    /// The job's state and message after the coordinator restarts on the same folder.
    fn after_restart(farm: SharedFarm, dir: &std::path::Path, job: u64) -> (JobState, Option<String>) {
        let status = restarted(farm, dir).read(|f| f.status(job)).unwrap();
        (status.state, status.message)
    }

    /// Each event's writes are one SQLite transaction: one fsync per event, and a crash keeps
    /// all of an event or none of it (a result used to take 4 to 9 commits).
    #[test]
    fn each_farm_event_commits_one_transaction() {
        let dir = tempfile::tempdir().unwrap();
        let (farm, _) = one_job_farm(dir.path(), 50);
        let commits_of = |event: &dyn Fn(&mut Farm)| {
            let before = farm.store().commits();
            farm.run(|f| {
                event(f);
                Ok(())
            })
            .unwrap();
            farm.store().commits() - before
        };
        let settings = JobSettings {
            passes: Some(4),
            checkpoint_every: Some(1),
            ..JobSettings::default()
        };
        let job = std::cell::Cell::new(0);
        let submitted = commits_of(&|f| {
            let empty = Accumulator::empty(4, 4, 1);
            job.set(f.create_job(&settings, render(), 4, "s.xml", "h", empty).unwrap());
        });
        assert_eq!(submitted, 1, "a submission");
        // The first job, of one pass, is cancelled: the leases below are the new job's.
        assert_eq!(commits_of(&|f| drop(f.cancel(1).unwrap())), 1, "a cancel");
        let lease = std::cell::RefCell::new(None);
        let req = LeaseRequest {
            worker: "a".into(),
            threads: 1,
            renderers: None,
        };
        let take = || commits_of(&|f| *lease.borrow_mut() = f.lease(&req).unwrap());
        let held = || lease.borrow().clone().unwrap();
        assert_eq!(take(), 1, "a lease");
        assert_eq!(held().job_id, job.get());
        let beat = commits_of(&|f| {
            f.heartbeat(held().lease_id, &held().key).unwrap();
        });
        assert_eq!(beat, 0, "a heartbeat writes nothing");
        let result = commits_of(&|f| drop(f.commit(held().lease_id, &held().key, 1).unwrap()));
        assert_eq!(result, 1, "a result");
        let checkpoint = commits_of(&|f| f.checkpointed(job.get(), 1, Some(1)).unwrap());
        assert_eq!(checkpoint, 1, "a checkpoint");
        assert_eq!(take(), 1);
        let release = commits_of(&|f| f.release(held().lease_id, &held().key, Some("no GPU")).unwrap());
        assert_eq!(release, 1, "a release");
        assert_eq!(take(), 1);
        std::thread::sleep(std::time::Duration::from_millis(100));
        assert_eq!(
            commits_of(&|f| assert_eq!(f.expire().unwrap(), 1)),
            1,
            "an expiry"
        );
        assert_eq!(
            commits_of(&|f| assert_eq!(f.expire().unwrap(), 0)),
            0,
            "nothing expired"
        );
    }

    #[test]
    fn a_failure_by_a_release_after_the_lease_deadline_survives_a_restart() {
        let dir = tempfile::tempdir().unwrap();
        let (farm, job) = one_job_farm(dir.path(), 30);
        for worker in ["a", "b", "c"] {
            let lease = ask(&farm, worker).unwrap();
            // Past the deadline, before any expiry tick: the release still counts.
            std::thread::sleep(std::time::Duration::from_millis(60));
            farm.run(|f| f.release(lease.lease_id, &lease.key, Some("out of memory")))
                .unwrap();
        }
        assert_eq!(farm.read(|f| f.status(job)).unwrap().state, JobState::Failed);
        let (state, message) = after_restart(farm, dir.path(), job);
        assert_eq!(state, JobState::Failed, "a failed job is not leased again");
        assert!(message.unwrap().contains("out of memory"));
    }

    #[test]
    fn a_failure_by_rejected_results_survives_a_restart() {
        let dir = tempfile::tempdir().unwrap();
        let (farm, job) = one_job_farm(dir.path(), 60_000);
        for worker in ["a", "b", "c"] {
            let lease = ask(&farm, worker).unwrap();
            farm.run(|f| f.reject(lease.lease_id, "expected 4x4, got 2x2"))
                .unwrap();
        }
        assert_eq!(farm.read(|f| f.status(job)).unwrap().state, JobState::Failed);
        let (state, message) = after_restart(farm, dir.path(), job);
        assert_eq!(state, JobState::Failed);
        assert!(message.unwrap().contains("expected 4x4, got 2x2"));
    }

    #[test]
    fn a_failure_because_no_worker_may_take_the_passes_survives_a_restart() {
        let dir = tempfile::tempdir().unwrap();
        let (farm, job) = one_job_farm(dir.path(), 60_000);
        // The only worker present fails the batch twice: it may not take it again, and
        // nobody else is there.
        for _ in 0..2 {
            let lease = ask(&farm, "only").unwrap();
            farm.run(|f| f.release(lease.lease_id, &lease.key, Some("GPU lost")))
                .unwrap();
        }
        assert!(ask(&farm, "only").is_none());
        assert_eq!(farm.read(|f| f.status(job)).unwrap().state, JobState::Failed);
        let (state, message) = after_restart(farm, dir.path(), job);
        assert_eq!(state, JobState::Failed);
        assert!(message.unwrap().contains("no worker may take them"));
    }

    #[test]
    fn a_result_whose_lease_moved_on_never_replaces_the_one_that_counts() {
        let dir = tempfile::tempdir().unwrap();
        let (farm, job) = one_job_farm(dir.path(), 400);
        let layout = farm.read(|f| f.layout());
        let result = |value: i64| {
            let mut sum = FilmSum::new(4, 4);
            sum.sums.iter_mut().for_each(|p| *p = [value; 3]);
            sum.passes = 1;
            photonfarm::protocol::encode_batch(&sum)
        };
        let stored = |lease: &Lease| StoredBatch {
            start: lease.start,
            end: lease.end,
            lease: lease.lease_id,
        };
        // Worker a's result is checked against its live lease (its head arrives)...
        let late = ask(&farm, "a").unwrap();
        farm.run(|f| f.expected_result(late.lease_id, &late.key)).unwrap();
        // ...but its body is slow: the lease expires and worker b renders the same passes. (b
        // then has the lease's 400 ms to commit: 30 ms failed once under the suite's load.)
        std::thread::sleep(std::time::Duration::from_millis(500));
        assert_eq!(farm.run(|f| f.expire()).unwrap(), 1);
        let honest = ask(&farm, "b").unwrap();
        assert_eq!((honest.start, honest.end), (late.start, late.end));
        layout
            .write_batch_bytes(job, stored(&honest), &result(7))
            .unwrap();
        farm.run(|f| f.commit(honest.lease_id, &honest.key, 1)).unwrap();
        // a's body lands at last, and its commit is refused.
        layout
            .write_batch_bytes(job, stored(&late), &result(666))
            .unwrap();
        assert!(farm.run(|f| f.commit(late.lease_id, &late.key, 1)).is_err());
        // Only the honest batch is named by a row: the late file is the one a refused upload
        // removes, and a retried upload of a counted result keeps its file.
        assert!(farm.store().has_batch(job, stored(&honest)).unwrap());
        assert!(!farm.store().has_batch(job, stored(&late)).unwrap());
        // After a restart the job is made of b's result, not a's.
        let farm = restarted(farm, dir.path());
        assert_eq!(farm.read(|f| f.status(job)).unwrap().state, JobState::Done);
        let prefix = farm.read(|f| f.layout()).load_prefix(job, 4, 4).unwrap();
        assert!(
            prefix.sum.sums.iter().all(|p| *p == [7; 3]),
            "{:?}",
            prefix.sum.sums[0]
        );
    }
}
