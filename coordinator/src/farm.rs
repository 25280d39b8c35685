//! The farm's state and rules: jobs, their schedulers and sums, kept durable in the store.
//! The HTTP layer ([`crate::api`]) only translates requests into these calls.

use std::collections::BTreeMap;
use std::time::{Instant, SystemTime, UNIX_EPOCH};

use photonfarm::film::FilmSum;
use photonfarm::job::JobSettings;
use photonfarm::protocol::{HeartbeatReply, Lease, LeaseRequest};
use photonfarm::render::{Method, RenderSettings};
use serde::Serialize;

use crate::accumulator::Accumulator;
use crate::scheduler::{JobState, LeaseError, Scheduler, SchedulerConfig};
use crate::store::{Store, StoreError};

/// Farm settings.
#[derive(Clone, Copy, Debug)]
pub struct FarmConfig {
    /// Lease timeouts and batch sizing.
    pub scheduler: SchedulerConfig,
    /// Checkpoint interval of jobs that do not set one.
    pub default_checkpoint: u64,
}

impl Default for FarmConfig {
    fn default() -> Self {
        FarmConfig {
            scheduler: SchedulerConfig::default(),
            default_checkpoint: 64,
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

/// What `GET /api/jobs/{id}` answers.
#[derive(Clone, Debug, Serialize)]
pub struct JobStatus {
    /// Job id.
    pub id: u64,
    /// queued, running, done, failed or cancelled.
    pub state: JobState,
    /// Passes (iterations or samples per pixel) rendered and received.
    pub iterations_done: u64,
    /// Passes asked for.
    pub iterations_total: u64,
    /// Passes in the latest checkpoint image.
    pub checkpoint_iterations: u64,
    /// Workers holding a batch of this job now.
    pub workers: Vec<String>,
    /// Seconds since the first batch was handed out.
    pub elapsed_seconds: f64,
    /// Passes per second since then.
    pub rate: f64,
    /// `path` or `sppm`.
    pub integrator: &'static str,
    /// Image width.
    pub width: u32,
    /// Image height.
    pub height: u32,
    /// Why the job failed, if it did.
    pub message: Option<String>,
    /// When the job was submitted, Unix milliseconds.
    pub created_unix_ms: u64,
    /// Batch results received since this coordinator started.
    pub batches_received: u64,
    /// Bytes of batch results received since this coordinator started.
    pub bytes_received: u64,
}

struct JobEntry {
    created_ms: u64,
    render: RenderSettings,
    scene: String,
    bundle: String,
    defines: Vec<(String, String)>,
    width: u32,
    height: u32,
    total: u64,
    /// SPPM (surface, volume) radii of every pass, computed once so every batch gets the
    /// same bits.
    radii: Vec<[f32; 2]>,
    acc: Accumulator,
    started: Option<Instant>,
    finished: Option<Instant>,
    /// Passes already done when this process started (for an honest rate after a restart).
    done_at_start: u64,
    batches_received: u64,
    bytes_received: u64,
}

/// The coordinator's state.
pub struct Farm {
    store: Store,
    scheduler: Scheduler,
    jobs: BTreeMap<u64, JobEntry>,
    epoch: Instant,
    /// A lease expires this long after its last heartbeat.
    lease_timeout_ms: u64,
    /// Workers heartbeat four times per timeout, so one lost heartbeat never costs a lease.
    heartbeat_ms: u64,
    default_checkpoint: u64,
}

fn unix_ms() -> u64 {
    SystemTime::now()
        .duration_since(UNIX_EPOCH)
        .map_or(0, |d| d.as_millis() as u64)
}

fn radii_for(render: &RenderSettings, total: u64) -> Vec<[f32; 2]> {
    match &render.method {
        Method::Sppm(s) => s.radii(0..total),
        Method::Path(_) | Method::Direct(_) => Vec::new(),
    }
}

impl Farm {
    /// Opens the store and resumes every unfinished job from its durable state.
    pub fn open(mut store: Store, config: FarmConfig) -> Result<Farm, FarmError> {
        let first_lease = store.reserve_lease_ids()?;
        let mut scheduler = Scheduler::new(config.scheduler, first_lease);
        let mut jobs = BTreeMap::new();
        for row in store.load_jobs()? {
            let render: RenderSettings = serde_json::from_str(&row.render)
                .map_err(|e| StoreError::Corrupt(format!("job {}", row.id), e.to_string()))?;
            let settings: JobSettings = serde_json::from_str(&row.settings)
                .map_err(|e| StoreError::Corrupt(format!("job {}", row.id), e.to_string()))?;
            let prefix = store.load_prefix(row.id, row.width, row.height)?;
            let mut acc = Accumulator::new(prefix, row.window);
            let mut done = vec![(0, acc.prefix_passes())];
            if !row.state.is_final() {
                for (start, sum) in store.load_batches(row.id)? {
                    done.push((start, start + sum.passes));
                    acc.add(start, sum)
                        .map_err(|e| StoreError::Corrupt(format!("job {}", row.id), e.to_string()))?;
                }
            }
            let mut state = row.state;
            if !state.is_final() && acc.prefix_passes() >= row.total {
                // Every pass was stored but the coordinator stopped before finishing the job.
                store.save_prefix(row.id, acc.prefix())?;
                store.write_images(row.id, acc.prefix())?;
                state = JobState::Done;
                store.update_job(row.id, row.next_start, state, None)?;
            }
            scheduler.add_job(row.id, row.total, row.window, row.next_start, &done, state);
            let done_at_start = scheduler.status(row.id).map_or(0, |s| s.1);
            jobs.insert(
                row.id,
                JobEntry {
                    created_ms: row.created_ms,
                    radii: radii_for(&render, row.total),
                    render,
                    scene: row.scene,
                    bundle: row.bundle,
                    defines: settings.defines,
                    width: row.width,
                    height: row.height,
                    total: row.total,
                    acc,
                    started: None,
                    finished: None,
                    done_at_start,
                    batches_received: 0,
                    bytes_received: 0,
                },
            );
        }
        Ok(Farm {
            store,
            scheduler,
            jobs,
            epoch: Instant::now(),
            lease_timeout_ms: config.scheduler.lease_timeout_ms,
            heartbeat_ms: (config.scheduler.lease_timeout_ms / 4).max(10),
            default_checkpoint: config.default_checkpoint,
        })
    }

    fn now(&self) -> u64 {
        self.epoch.elapsed().as_millis() as u64
    }

    /// The store (bundle paths, images).
    pub fn store(&self) -> &Store {
        &self.store
    }

    /// Mutable store access (saving bundles at submission).
    pub fn store_mut(&mut self) -> &mut Store {
        &mut self.store
    }

    /// Creates a job from settings already checked against the loaded scene.
    #[allow(clippy::too_many_arguments)]
    pub fn create_job(
        &mut self,
        settings: &JobSettings,
        render: RenderSettings,
        total: u64,
        scene: &str,
        bundle: &str,
        width: u32,
        height: u32,
    ) -> Result<u64, FarmError> {
        let window = settings
            .checkpoint_every
            .unwrap_or(self.default_checkpoint)
            .max(1);
        let id = self.store.insert_job(
            unix_ms(),
            &serde_json::to_string(settings).expect("settings serialise"),
            &serde_json::to_string(&render).expect("settings serialise"),
            scene,
            bundle,
            total,
            window,
            width,
            height,
        )?;
        self.scheduler
            .add_job(id, total, window, 0, &[], JobState::Queued);
        self.jobs.insert(
            id,
            JobEntry {
                created_ms: unix_ms(),
                radii: radii_for(&render, total),
                render,
                scene: scene.to_string(),
                bundle: bundle.to_string(),
                defines: settings.defines.clone(),
                width,
                height,
                total,
                acc: Accumulator::new(FilmSum::new(width, height), window),
                started: None,
                finished: None,
                done_at_start: 0,
                batches_received: 0,
                bytes_received: 0,
            },
        );
        Ok(id)
    }

    /// Grants a batch to a worker, if any job has work for it.
    pub fn lease(&mut self, req: &LeaseRequest) -> Result<Option<Lease>, FarmError> {
        let now = self.now();
        let Some(g) = self.scheduler.lease(&req.worker, now) else {
            return Ok(None);
        };
        let job = self.jobs.get_mut(&g.job_id).expect("scheduled jobs are known");
        job.started.get_or_insert_with(Instant::now);
        let radii = if job.radii.is_empty() {
            Vec::new()
        } else {
            job.radii[g.start as usize..g.end as usize].to_vec()
        };
        let lease = Lease {
            lease_id: g.lease_id,
            job_id: g.job_id,
            start: g.start,
            end: g.end,
            radii,
            settings: job.render,
            bundle: job.bundle.clone(),
            scene: job.scene.clone(),
            defines: job.defines.clone(),
            deadline_ms: self.lease_timeout_ms,
            heartbeat_ms: self.heartbeat_ms,
        };
        self.persist_progress(g.job_id)?;
        Ok(Some(lease))
    }

    /// Extends a lease.
    pub fn heartbeat(&mut self, lease_id: u64) -> Result<HeartbeatReply, FarmError> {
        let now = self.now();
        let deadline = self.scheduler.heartbeat(lease_id, now)?;
        Ok(HeartbeatReply {
            deadline_ms: deadline.saturating_sub(now),
        })
    }

    /// Image size and pass count a lease's result must have (checked before decoding).
    pub fn expected_result(&self, lease_id: u64) -> Result<(u32, u32, u64), FarmError> {
        let g = self.scheduler.lease_range(lease_id, self.now())?;
        let job = &self.jobs[&g.job_id];
        Ok((job.width, job.height, g.end - g.start))
    }

    /// Accepts a batch result (`bytes` long on the wire): stored durably, counted once, merged
    /// in pass order.
    pub fn complete(&mut self, lease_id: u64, sum: FilmSum, bytes: u64) -> Result<(), FarmError> {
        let now = self.now();
        let g = self.scheduler.lease_range(lease_id, now)?;
        let (w, h) = {
            let job = &self.jobs[&g.job_id];
            (job.width, job.height)
        };
        if (sum.width, sum.height) != (w, h) || sum.passes != g.end - g.start {
            let msg = format!(
                "expected {w}x{h} and {} passes, got {}x{} and {}",
                g.end - g.start,
                sum.width,
                sum.height,
                sum.passes
            );
            self.scheduler.release(lease_id, Some(&msg))?;
            return Err(FarmError::BadResult(msg));
        }
        self.store.save_batch(g.job_id, g.start, &sum)?;
        self.scheduler.complete(lease_id, now)?;
        let job = self.jobs.get_mut(&g.job_id).expect("known");
        job.batches_received += 1;
        job.bytes_received += bytes;
        let (checkpoints, _) = job
            .acc
            .add(g.start, sum)
            .map_err(|e| FarmError::BadResult(e.to_string()))?;
        let finished = job.acc.prefix_passes() >= job.total;
        if finished {
            job.finished = Some(Instant::now());
        }
        // The latest checkpoint: the whole prefix once the job is finished.
        let latest = if finished {
            Some(job.acc.prefix())
        } else {
            checkpoints.last()
        };
        if let Some(image) = latest {
            // The prefix file first: the checkpoint images must never be ahead of it.
            self.store.save_prefix(g.job_id, job.acc.prefix())?;
            self.store.write_images(g.job_id, image)?;
        }
        self.persist_progress(g.job_id)
    }

    /// Gives a lease back, after a failure or cleanly.
    pub fn release(&mut self, lease_id: u64, error: Option<&str>) -> Result<(), FarmError> {
        let job = self
            .scheduler
            .lease_range(lease_id, self.now())
            .map(|g| g.job_id)
            .ok();
        self.scheduler.release(lease_id, error)?;
        if let Some(job) = job {
            self.persist_progress(job)?;
        }
        Ok(())
    }

    /// Ends expired leases so their passes go to other workers.
    pub fn expire(&mut self) -> Result<usize, FarmError> {
        let expired = self.scheduler.expire(self.now());
        for (lease, job) in &expired {
            tracing::warn!(
                lease,
                job,
                "lease expired without a heartbeat; its passes will be re-issued"
            );
        }
        Ok(expired.len())
    }

    /// Cancels a job.
    pub fn cancel(&mut self, id: u64) -> Result<JobStatus, FarmError> {
        if !self.scheduler.cancel(id) {
            return Err(FarmError::NoJob(id));
        }
        self.persist_progress(id)?;
        self.status(id).ok_or(FarmError::NoJob(id))
    }

    fn persist_progress(&mut self, id: u64) -> Result<(), FarmError> {
        let (state, _, _, message) = self.scheduler.status(id).ok_or(FarmError::NoJob(id))?;
        let next = self.scheduler.next_start(id).unwrap_or(0);
        self.store.update_job(id, next, state, message.as_deref())?;
        Ok(())
    }

    /// A job's status.
    pub fn status(&self, id: u64) -> Option<JobStatus> {
        let job = self.jobs.get(&id)?;
        let (state, done, total, message) = self.scheduler.status(id)?;
        let elapsed = match (job.started, job.finished) {
            (Some(s), Some(f)) => (f - s).as_secs_f64(),
            (Some(s), None) => s.elapsed().as_secs_f64(),
            _ => 0.0,
        };
        let rate = if elapsed > 0.0 {
            (done - job.done_at_start.min(done)) as f64 / elapsed
        } else {
            0.0
        };
        Some(JobStatus {
            id,
            state,
            iterations_done: done,
            iterations_total: total,
            checkpoint_iterations: job.acc.prefix_passes(),
            workers: self.scheduler.workers_on(id),
            elapsed_seconds: elapsed,
            rate,
            integrator: match job.render.method {
                Method::Path(_) => "path",
                Method::Direct(_) => "direct",
                Method::Sppm(_) => "sppm",
            },
            width: job.width,
            height: job.height,
            message,
            created_unix_ms: job.created_ms,
            batches_received: job.batches_received,
            bytes_received: job.bytes_received,
        })
    }

    /// Every job, oldest first.
    pub fn list(&self) -> Vec<JobStatus> {
        self.jobs.keys().filter_map(|&id| self.status(id)).collect()
    }

    /// The path of a job's latest checkpoint image.
    pub fn image(&self, id: u64, ext: &str) -> Result<std::path::PathBuf, FarmError> {
        if !self.jobs.contains_key(&id) {
            return Err(FarmError::NoJob(id));
        }
        let path = self.store.image_path(id, ext);
        if path.exists() {
            Ok(path)
        } else {
            Err(FarmError::NoImage(id))
        }
    }

    /// Whether a bundle hash belongs to a job (workers may only fetch those).
    pub fn knows_bundle(&self, hash: &str) -> bool {
        self.jobs.values().any(|j| j.bundle == hash)
    }
}
