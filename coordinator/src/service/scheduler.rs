//! Who renders which passes: the iteration counter, batches, leases and their deadlines.
//!
//! Pure logic: no I/O and no clock (the caller passes the time in milliseconds), so every rule
//! is unit-tested here and the same scheduler drives both the farm and `coordinator render`.
//!
//! Rules:
//! - Passes are handed out in increasing order; a batch never crosses a multiple of the job's
//!   window (its checkpoint interval), so checkpoints fall on batch boundaries.
//! - A batch is a lease with a deadline; heartbeats extend it. An expired or released lease's
//!   range goes back to the job and is handed out again before new passes.
//! - A result counts only for a live lease, once: the lease is gone after it.
//! - A worker that failed a range twice never gets that range again; a range that failed on
//!   three workers fails the job. A lease that expires (its worker crashed or hung) counts as
//!   a failure of its worker, so a batch that kills every worker fails its job instead of
//!   being handed out forever; and a range that every worker seen lately is barred from fails
//!   the job with a message instead of waiting for a worker that may never come. A relay's
//!   lease that expires is not a failure: a relay renders nothing, so its death says nothing
//!   of the batch (the relay reports its workers' failures itself, with a release); nor is a
//!   lease restored after a restart, whose worker may never have heard of the coordinator again.
//! - Jobs take turns: each lease goes to the next job after the one that had the last lease
//!   (round robin over the jobs with work), so a long job submitted first does not starve
//!   the jobs after it. Each job still gets its passes in increasing order.
//! - Batch sizes aim at a target duration from each worker's measured rate on the job. The
//!   target grows with the number of workers present so that their results together stay
//!   within what the coordinator absorbs: target = max(`target_batch_ms`, workers × image
//!   pixels / `absorb_pixels_per_s`). Each worker then sends fewer results as workers are
//!   added, and the coordinator's load stays flat (docs/scaling.md).

use std::collections::{BTreeMap, BTreeSet, HashMap};

/// Milliseconds on the caller's monotonic clock.
pub type Millis = u64;

/// Scheduling parameters.
#[derive(Clone, Copy, Debug)]
pub struct SchedulerConfig {
    /// A lease without a heartbeat for this long expires.
    pub lease_timeout_ms: Millis,
    /// Batches aim to take about this long on the worker that renders them.
    pub target_batch_ms: Millis,
    /// Largest batch, whatever the rate.
    pub max_batch: u64,
    /// Result pixels per second the coordinator absorbs (results × image pixels); batches
    /// lengthen to keep all workers' results within it. 0: no such growth.
    pub absorb_pixels_per_s: f64,
}

impl Default for SchedulerConfig {
    fn default() -> Self {
        SchedulerConfig {
            lease_timeout_ms: 30_000,
            target_batch_ms: 5_000,
            max_batch: 4096,
            absorb_pixels_per_s: DEFAULT_ABSORB_PIXELS_PER_S,
        }
    }
}

/// Result pixels per second one coordinator core absorbs, from the load benchmark
/// (docs/scaling.md: 17.6 Mpx/s at 1920×1080 and 12.6 at 512² at full load), with a margin.
pub const DEFAULT_ABSORB_PIXELS_PER_S: f64 = 10e6;

pub use photonfarm::protocol::JobState;

/// A granted batch.
#[derive(Clone, Debug, PartialEq, Eq)]
pub struct Grant {
    /// Lease id.
    pub lease_id: u64,
    /// Job id.
    pub job_id: u64,
    /// First pass.
    pub start: u64,
    /// One past the last pass.
    pub end: u64,
}

/// Why a lease operation was refused.
#[derive(Clone, Debug, PartialEq, Eq, thiserror::Error)]
pub enum LeaseError {
    /// No such lease: never granted, already completed, expired or reassigned.
    #[error("lease {0} is not active (it expired, was completed or was reassigned)")]
    NotActive(u64),
    /// The job was cancelled or failed.
    #[error("job {0} is no longer running")]
    JobOver(u64),
}

#[derive(Clone, Debug)]
struct LeaseInfo {
    job: u64,
    start: u64,
    end: u64,
    worker: String,
    /// Its expiry says nothing of the batch, so it is not a failure: granted to a relay (which
    /// renders nothing itself), or restored after a restart (its worker may never have heard
    /// of the coordinator again).
    blameless: bool,
    issued: Millis,
    deadline: Millis,
    /// When its result started to arrive: the worker's speed is measured to then, not to
    /// the end of an upload that queued behind others (a busy coordinator would otherwise
    /// measure workers slower, shorten their batches and get busier).
    arrived: Option<Millis>,
}

#[derive(Clone, Debug)]
struct JobSched {
    total: u64,
    window: u64,
    next_start: u64,
    free: BTreeSet<(u64, u64)>,
    completed: u64,
    state: JobState,
    message: Option<String>,
    /// (range start, worker) → failures.
    failures: HashMap<(u64, String), u32>,
    /// The latest failure's message, for the job's message if it fails.
    last_error: Option<String>,
    /// Passes per millisecond, per worker, from its finished batches.
    rates: HashMap<String, f64>,
    /// Image pixels (the size of each result), for the batch length rule; 0 if unknown.
    pixels: u64,
    /// Of a frame of a sequence: the last job of its group (see [`Scheduler::set_group`]).
    group_end: Option<u64>,
}

/// The scheduler of all jobs.
#[derive(Debug)]
pub struct Scheduler {
    config: SchedulerConfig,
    jobs: BTreeMap<u64, JobSched>,
    leases: BTreeMap<u64, LeaseInfo>,
    next_lease: u64,
    /// Workers that asked for work, with the time they last asked: the farm's workers as far
    /// as the scheduler can know them.
    seen: HashMap<String, Millis>,
    /// The job whose turn is next (round robin): the first job from this id on is offered the
    /// next lease first.
    turn: u64,
}

/// Failures of one range on one worker before that worker is no longer given it.
const FAILURES_PER_WORKER: u32 = 2;
/// Distinct workers a range may fail on before the job fails.
const FAILING_WORKERS: usize = 3;

impl Scheduler {
    /// A scheduler whose lease ids start at `first_lease_id` (persisted across restarts, so
    /// that a lease from before a restart can never match a new one).
    pub fn new(config: SchedulerConfig, first_lease_id: u64) -> Scheduler {
        Scheduler {
            config,
            jobs: BTreeMap::new(),
            leases: BTreeMap::new(),
            next_lease: first_lease_id,
            seen: HashMap::new(),
            turn: 0,
        }
    }

    /// How many workers asked for work recently (within two lease timeouts of their last
    /// request, as of the latest request).
    pub fn workers_present(&self) -> usize {
        self.seen.len()
    }

    /// The next lease id that will be granted.
    pub fn next_lease_id(&self) -> u64 {
        self.next_lease
    }

    /// Adds a job of `total` passes, aligned to `window`. `done` are ranges already rendered
    /// (after a restart); everything else below `next_start` is handed out again.
    pub fn add_job(
        &mut self,
        id: u64,
        total: u64,
        window: u64,
        next_start: u64,
        done: &[(u64, u64)],
        state: JobState,
    ) {
        let window = window.max(1);
        let mut free = BTreeSet::new();
        let done: BTreeSet<(u64, u64)> = done.iter().copied().collect();
        // The ranges may overlap: a batch merged into the stored prefix whose record the
        // coordinator had not yet forgotten when it stopped. Each pass counts once, or the job
        // would count as done with passes never rendered, and wait for them forever.
        let (mut cursor, mut completed) = (0, 0);
        for &(s, e) in &done {
            if s > cursor {
                split_into(&mut free, cursor, s.min(next_start), window);
            }
            completed += e.saturating_sub(s.max(cursor));
            cursor = cursor.max(e);
        }
        if next_start > cursor {
            split_into(&mut free, cursor, next_start, window);
        }
        self.jobs.insert(
            id,
            JobSched {
                total,
                window,
                next_start,
                free,
                completed,
                state,
                message: None,
                failures: HashMap::new(),
                last_error: None,
                rates: HashMap::new(),
                pixels: 0,
                group_end: None,
            },
        );
    }

    /// Sets a job's image size in pixels (each result's size), which lengthens its batches
    /// as workers are added (see the module's rules).
    pub fn set_pixels(&mut self, job_id: u64, pixels: u64) {
        if let Some(job) = self.jobs.get_mut(&job_id) {
            job.pixels = pixels;
        }
    }

    /// Makes a job a frame of a sequence whose frames are the jobs up to `group_end` (ids in
    /// frame order): the frames take one turn together, each turn going to the first frame
    /// with passes left, so frames finish in order.
    pub fn set_group(&mut self, job_id: u64, group_end: u64) {
        if let Some(job) = self.jobs.get_mut(&job_id) {
            job.group_end = Some(group_end);
        }
    }

    /// Grants the next batch to `worker`, from the next job in turn with work it may take.
    pub fn lease(&mut self, worker: &str, now: Millis) -> Option<Grant> {
        self.lease_for(worker, None, now)
    }

    /// [`Scheduler::lease`] for a client that is a relay for `renderers` machines (None: a
    /// worker): its first batch on a job has a pass for each.
    pub fn lease_for(&mut self, worker: &str, renderers: Option<u32>, now: Millis) -> Option<Grant> {
        let config = self.config;
        self.seen.insert(worker.to_string(), now);
        // Workers that asked within two lease timeouts count as present.
        let recent = now.saturating_sub(config.lease_timeout_ms.saturating_mul(2));
        self.seen.retain(|_, &mut t| t >= recent);
        let clients = self.seen.len() as u64;
        let order: Vec<u64> = (self.jobs.range(self.turn..).map(|(&id, _)| id))
            .chain(self.jobs.range(..self.turn).map(|(&id, _)| id))
            .collect();
        let relayed = renderers.is_some();
        let renderers = renderers.unwrap_or(1).max(1);
        for job_id in order {
            let job = self.jobs.get_mut(&job_id).expect("listed above");
            if job.state.is_final() {
                continue;
            }
            let target = target_ms(&config, clients, job.pixels);
            let size = batch_size(&config, target, job.rates.get(worker).copied(), renderers)
                .min(fair_share(job, worker, self.seen.keys()));
            let Some(range) = take_free(job, worker, size).or_else(|| take_new(job, size)) else {
                fail_if_barred_everywhere(job, self.seen.keys());
                continue;
            };
            let lease_id = self.next_lease;
            self.next_lease += 1;
            job.state = JobState::Running;
            self.leases.insert(
                lease_id,
                LeaseInfo {
                    job: job_id,
                    start: range.0,
                    end: range.1,
                    worker: worker.to_string(),
                    blameless: relayed,
                    issued: now,
                    deadline: now + config.lease_timeout_ms,
                    arrived: None,
                },
            );
            // A group takes one turn: the next lease goes past its last job, and the group's
            // next turn starts again at its first frame with passes left.
            self.turn = job.group_end.unwrap_or(job_id).max(job_id) + 1;
            return Some(Grant {
                lease_id,
                job_id,
                start: range.0,
                end: range.1,
            });
        }
        None
    }

    /// Gives back a lease granted before a restart, with a fresh deadline: its worker may
    /// still be rendering it, or may hold its result and be waiting for the coordinator to
    /// answer. Refused (false) unless the job is still running and the range still waits to be
    /// rendered.
    pub fn restore_lease(&mut self, lease_id: u64, grant: &Grant, worker: &str, deadline: Millis) -> bool {
        let Some(job) = self.jobs.get_mut(&grant.job_id) else {
            return false;
        };
        if job.state.is_final() || self.leases.contains_key(&lease_id) {
            return false;
        }
        let Some(&(s, e)) = job
            .free
            .iter()
            .find(|&&(s, e)| s <= grant.start && grant.end <= e)
        else {
            return false;
        };
        job.free.remove(&(s, e));
        for part in [(s, grant.start), (grant.end, e)] {
            if part.0 < part.1 {
                job.free.insert(part);
            }
        }
        job.state = JobState::Running;
        self.leases.insert(
            lease_id,
            LeaseInfo {
                job: grant.job_id,
                start: grant.start,
                end: grant.end,
                worker: worker.to_string(),
                blameless: true,
                issued: deadline.saturating_sub(self.config.lease_timeout_ms),
                deadline,
                arrived: None,
            },
        );
        true
    }

    /// Extends a live lease; returns its new deadline.
    pub fn heartbeat(&mut self, lease_id: u64, now: Millis) -> Result<Millis, LeaseError> {
        let lease = self
            .leases
            .get_mut(&lease_id)
            .ok_or(LeaseError::NotActive(lease_id))?;
        if lease.deadline < now {
            return Err(LeaseError::NotActive(lease_id));
        }
        if self.jobs.get(&lease.job).is_none_or(|j| j.state.is_final()) {
            return Err(LeaseError::JobOver(lease.job));
        }
        lease.deadline = now + self.config.lease_timeout_ms;
        Ok(lease.deadline)
    }

    /// The range of a live lease, without changing anything (to check a result before storing it).
    pub fn lease_range(&self, lease_id: u64, now: Millis) -> Result<Grant, LeaseError> {
        let lease = self
            .leases
            .get(&lease_id)
            .ok_or(LeaseError::NotActive(lease_id))?;
        if lease.deadline < now {
            return Err(LeaseError::NotActive(lease_id));
        }
        if self.jobs.get(&lease.job).is_none_or(|j| j.state.is_final()) {
            return Err(LeaseError::JobOver(lease.job));
        }
        Ok(Grant {
            lease_id,
            job_id: lease.job,
            start: lease.start,
            end: lease.end,
        })
    }

    /// Notes that a lease's result started to arrive (its worker's speed is measured to then).
    pub fn arriving(&mut self, lease_id: u64, now: Millis) {
        if let Some(l) = self.leases.get_mut(&lease_id) {
            l.arrived.get_or_insert(now);
        }
    }

    /// Accepts a lease's result: the lease ends, its passes count once. Returns the range.
    pub fn complete(&mut self, lease_id: u64, now: Millis) -> Result<Grant, LeaseError> {
        let grant = self.lease_range(lease_id, now)?;
        let lease = self.leases.remove(&lease_id).expect("checked above");
        let job = self.jobs.get_mut(&lease.job).expect("a lease's job exists");
        job.completed += lease.end - lease.start;
        let elapsed = (lease.arrived.unwrap_or(now).saturating_sub(lease.issued)).max(1) as f64;
        job.rates
            .insert(lease.worker, (lease.end - lease.start) as f64 / elapsed);
        if job.completed >= job.total {
            job.state = JobState::Done;
        }
        Ok(grant)
    }

    /// Gives a lease back: after a failure (`error`), or cleanly (shutdown). Its range is handed
    /// out again.
    pub fn release(&mut self, lease_id: u64, error: Option<&str>) -> Result<(), LeaseError> {
        let lease = self
            .leases
            .remove(&lease_id)
            .ok_or(LeaseError::NotActive(lease_id))?;
        let job = self.jobs.get_mut(&lease.job).expect("a lease's job exists");
        job.free.insert((lease.start, lease.end));
        if let Some(error) = error {
            job.last_error = Some(error.to_string());
            *job.failures
                .entry((lease.start, lease.worker.clone()))
                .or_default() += 1;
            let workers = job.failures.keys().filter(|(s, _)| *s == lease.start).count();
            if workers >= FAILING_WORKERS {
                job.state = JobState::Failed;
                job.message = Some(format!(
                    "passes {}..{} failed on {workers} workers; last error: {error}",
                    lease.start, lease.end
                ));
            }
        }
        Ok(())
    }

    /// Ends every lease whose deadline has passed; returns them (lease id, job id).
    /// A lease that expires counts as a failure of its worker (see the module's rules).
    pub fn expire(&mut self, now: Millis) -> Vec<(u64, u64)> {
        let expired: Vec<u64> = self
            .leases
            .iter()
            .filter(|(_, l)| l.deadline < now)
            .map(|(&id, _)| id)
            .collect();
        expired
            .into_iter()
            .map(|id| {
                let lease = &self.leases[&id];
                let job = lease.job;
                let error = (!lease.blameless).then_some(
                    "the lease expired without a heartbeat (the worker crashed, hung or lost the network)",
                );
                self.release(id, error).expect("listed above");
                (id, job)
            })
            .collect()
    }

    /// Stops a job (cancelled by a user); its leases become void.
    pub fn cancel(&mut self, job_id: u64) -> bool {
        let Some(job) = self.jobs.get_mut(&job_id) else {
            return false;
        };
        if !job.state.is_final() {
            job.state = JobState::Cancelled;
        }
        self.leases.retain(|_, l| l.job != job_id);
        true
    }

    /// Stops handing out new passes of a job beyond those already granted (a time limit):
    /// the job ends when the granted ones are in.
    pub fn close(&mut self, job_id: u64) {
        if let Some(job) = self.jobs.get_mut(&job_id) {
            let granted_end = job.next_start;
            job.total = granted_end.max(job.completed);
            job.free.retain(|&(s, _)| s < granted_end);
            if job.completed >= job.total {
                job.state = JobState::Done;
            }
        }
    }

    /// A job's state, passes completed and total, and its error message.
    pub fn status(&self, job_id: u64) -> Option<(JobState, u64, u64, Option<String>)> {
        self.jobs
            .get(&job_id)
            .map(|j| (j.state, j.completed, j.total, j.message.clone()))
    }

    /// Fails a job with a message (one that cannot be resumed).
    pub fn set_failed(&mut self, job_id: u64, message: String) {
        if let Some(job) = self.jobs.get_mut(&job_id) {
            job.state = JobState::Failed;
            job.message = Some(message);
        }
        self.leases.retain(|_, l| l.job != job_id);
    }

    /// Whether a lease is still held (granted, and neither completed, released nor expired).
    pub fn is_live(&self, lease_id: u64) -> bool {
        self.leases.contains_key(&lease_id)
    }

    /// The first pass never handed out (persisted, so a restart knows what to re-issue).
    pub fn next_start(&self, job_id: u64) -> Option<u64> {
        self.jobs.get(&job_id).map(|j| j.next_start)
    }

    /// The worker holding a live lease.
    pub fn lease_worker(&self, lease_id: u64) -> Option<&str> {
        self.leases.get(&lease_id).map(|l| l.worker.as_str())
    }

    /// Every live lease: its worker and its range.
    pub fn holdings(&self) -> Vec<(String, Grant)> {
        self.leases
            .iter()
            .map(|(&lease_id, l)| {
                (
                    l.worker.clone(),
                    Grant {
                        lease_id,
                        job_id: l.job,
                        start: l.start,
                        end: l.end,
                    },
                )
            })
            .collect()
    }

    /// A worker's speed on a job, in passes per second, from its latest finished batch.
    pub fn worker_rate(&self, job_id: u64, worker: &str) -> Option<f64> {
        Some(self.jobs.get(&job_id)?.rates.get(worker)? * 1000.0)
    }

    /// Workers holding leases on a job.
    pub fn workers_on(&self, job_id: u64) -> Vec<String> {
        let mut w: Vec<String> = self
            .leases
            .values()
            .filter(|l| l.job == job_id)
            .map(|l| l.worker.clone())
            .collect();
        w.sort();
        w.dedup();
        w
    }
}

/// The batch duration aimed at with `clients` workers present on a job of `pixels` pixels:
/// `target_batch_ms`, or longer when that many workers' results would exceed what the
/// coordinator absorbs.
pub fn target_ms(config: &SchedulerConfig, clients: u64, pixels: u64) -> Millis {
    let spread = if config.absorb_pixels_per_s > 0.0 {
        (clients as f64 * pixels as f64 * 1000.0 / config.absorb_pixels_per_s) as Millis
    } else {
        0
    };
    config.target_batch_ms.max(spread)
}

fn batch_size(config: &SchedulerConfig, target_ms: Millis, rate: Option<f64>, renderers: u32) -> u64 {
    match rate {
        // A worker's first batch on a job is one pass (one per renderer of a relay): it
        // measures the worker's speed.
        None => (renderers as u64).clamp(1, config.max_batch),
        Some(r) => ((r * target_ms as f64) as u64).clamp(1, config.max_batch),
    }
}

/// Guided self-scheduling: a batch is at most the worker's share of the passes not yet handed
/// out, in proportion to its rate among the workers present (those without a rate on the job
/// count as fast as this one). Batches so shrink as a job nears its end, and the workers finish
/// together instead of one rendering the last long batch while the others wait.
fn fair_share<'a>(job: &JobSched, worker: &str, present: impl Iterator<Item = &'a String>) -> u64 {
    let Some(&mine) = job.rates.get(worker) else {
        return u64::MAX;
    };
    let left = (job.total - job.next_start) + job.free.iter().map(|(s, e)| e - s).sum::<u64>();
    let all: f64 = present.map(|w| job.rates.get(w).copied().unwrap_or(mine)).sum();
    if all <= 0.0 || mine <= 0.0 {
        return u64::MAX;
    }
    ((left as f64 * mine / all).ceil() as u64).max(1)
}

/// Splits [a, b) at window boundaries into the free set.
fn split_into(free: &mut BTreeSet<(u64, u64)>, a: u64, b: u64, window: u64) {
    let mut s = a;
    while s < b {
        let e = ((s / window + 1) * window).min(b);
        free.insert((s, e));
        s = e;
    }
}

/// The first free range this worker has not failed too often, cut to `size`.
fn take_free(job: &mut JobSched, worker: &str, size: u64) -> Option<(u64, u64)> {
    let &(s, e) = job.free.iter().find(|(s, _)| {
        job.failures.get(&(*s, worker.to_string())).copied().unwrap_or(0) < FAILURES_PER_WORKER
    })?;
    job.free.remove(&(s, e));
    let cut = (s + size).min(e);
    if cut < e {
        job.free.insert((cut, e));
    }
    Some((s, cut))
}

/// Fails the job when a free range is barred to every worker present (each failed it too
/// often): nobody will ever render it.
fn fail_if_barred_everywhere<'a>(job: &mut JobSched, workers: impl Iterator<Item = &'a String> + Clone) {
    let barred =
        |s: u64, w: &String| job.failures.get(&(s, w.clone())).copied().unwrap_or(0) >= FAILURES_PER_WORKER;
    let stuck = job
        .free
        .iter()
        .find(|&&(s, _)| workers.clone().all(|w| barred(s, w)))
        .copied();
    if let Some((s, e)) = stuck {
        let mut names: Vec<&String> = workers.collect();
        names.sort();
        job.state = JobState::Failed;
        job.message = Some(format!(
            "passes {s}..{e} failed on every available worker ({}); no worker may take them; last error: {}",
            names.iter().map(|n| n.as_str()).collect::<Vec<_>>().join(", "),
            job.last_error.as_deref().unwrap_or("none")
        ));
    }
}

/// New passes from the counter, up to `size`, never crossing a window boundary.
fn take_new(job: &mut JobSched, size: u64) -> Option<(u64, u64)> {
    if job.next_start >= job.total {
        return None;
    }
    let s = job.next_start;
    let window_end = (s / job.window + 1) * job.window;
    let e = (s + size).min(window_end).min(job.total);
    job.next_start = e;
    Some((s, e))
}

#[cfg(test)]
mod tests {
    use super::*;

    fn sched() -> Scheduler {
        Scheduler::new(
            SchedulerConfig {
                lease_timeout_ms: 1000,
                target_batch_ms: 100,
                max_batch: 1000,
                absorb_pixels_per_s: 0.0,
            },
            1,
        )
    }

    #[test]
    fn hands_out_every_pass_once_in_order_within_windows() {
        let mut s = sched();
        s.add_job(7, 50, 16, 0, &[], JobState::Queued);
        let mut t = 0;
        let mut covered = Vec::new();
        while let Some(g) = s.lease("w", t) {
            assert!(g.end <= 50 && g.start < g.end);
            assert_eq!(g.start / 16, (g.end - 1) / 16, "crosses a window: {g:?}");
            t += 10;
            covered.push((g.start, g.end));
            s.complete(g.lease_id, t).unwrap();
        }
        let mut next = 0;
        for (a, b) in covered {
            assert_eq!(a, next);
            next = b;
        }
        assert_eq!(next, 50);
        assert_eq!(s.status(7).unwrap().0, JobState::Done);
        // Batches grew from the measured rate (1 pass per 10 ms, target 100 ms).
        assert!(s.status(7).unwrap().1 == 50);
    }

    #[test]
    fn expired_leases_are_reissued_and_late_results_refused() {
        let mut s = sched();
        s.add_job(1, 4, 4, 0, &[], JobState::Queued);
        let a = s.lease("a", 0).unwrap();
        assert_eq!((a.start, a.end), (0, 1));
        // No heartbeat: expires after 1000 ms.
        assert_eq!(s.expire(1001), vec![(a.lease_id, 1)]);
        let b = s.lease("b", 1002).unwrap();
        assert_eq!((b.start, b.end), (0, 1), "the expired range comes first");
        assert_eq!(
            s.complete(a.lease_id, 1003),
            Err(LeaseError::NotActive(a.lease_id))
        );
        s.complete(b.lease_id, 1004).unwrap();
        assert_eq!(
            s.complete(b.lease_id, 1005),
            Err(LeaseError::NotActive(b.lease_id)),
            "counted once"
        );
        assert_eq!(s.status(1).unwrap().1, 1);
    }

    #[test]
    fn heartbeats_keep_a_lease() {
        let mut s = sched();
        s.add_job(1, 10, 10, 0, &[], JobState::Queued);
        let a = s.lease("a", 0).unwrap();
        assert_eq!(s.heartbeat(a.lease_id, 900), Ok(1900));
        assert!(s.expire(1500).is_empty());
        s.complete(a.lease_id, 1800).unwrap();
        assert!(s.heartbeat(a.lease_id, 1801).is_err());
    }

    #[test]
    fn failing_ranges_avoid_their_worker_then_fail_the_job() {
        let mut s = sched();
        s.add_job(1, 2, 2, 0, &[], JobState::Queued);
        for _ in 0..2 {
            let g = s.lease("bad", 0).unwrap();
            assert_eq!(g.start, 0);
            s.release(g.lease_id, Some("boom")).unwrap();
        }
        // "bad" no longer gets range 0; it gets the next one.
        let g = s.lease("bad", 0).unwrap();
        assert_eq!(g.start, 1);
        let g0 = s.lease("other", 0).unwrap();
        assert_eq!(g0.start, 0);
        s.release(g0.lease_id, Some("boom")).unwrap();
        let g0 = s.lease("third", 0).unwrap();
        s.release(g0.lease_id, Some("boom")).unwrap();
        let (state, _, _, msg) = s.status(1).unwrap();
        assert_eq!(state, JobState::Failed);
        assert!(msg.unwrap().contains("boom"));
        assert!(s.lease("fresh", 0).is_none());
        // A clean hand-back is not a failure.
        let mut s = sched();
        s.add_job(2, 1, 1, 0, &[], JobState::Queued);
        for _ in 0..5 {
            let g = s.lease("w", 0).unwrap();
            s.release(g.lease_id, None).unwrap();
        }
        assert_eq!(s.status(2).unwrap().0, JobState::Running);
    }

    #[test]
    fn crashing_workers_fail_the_job_and_a_barred_job_fails_with_a_message() {
        // Three workers each take the batch and die (no heartbeat): the job fails.
        let mut s = sched();
        s.add_job(1, 10, 10, 0, &[], JobState::Queued);
        let mut t = 0;
        for w in ["a", "b", "c"] {
            let g = s.lease(w, t).unwrap();
            assert_eq!(g.start, 0);
            t += 1001;
            assert_eq!(s.expire(t).len(), 1);
        }
        let (state, _, _, msg) = s.status(1).unwrap();
        assert_eq!(state, JobState::Failed);
        assert!(msg.unwrap().contains("expired"));

        // One worker, failing twice: nobody else will ever take the range.
        let mut s = sched();
        s.add_job(2, 1, 1, 0, &[], JobState::Queued);
        for _ in 0..2 {
            let g = s.lease("only", 0).unwrap();
            s.release(g.lease_id, Some("out of memory")).unwrap();
        }
        assert!(s.lease("only", 1).is_none());
        let (state, _, _, msg) = s.status(2).unwrap();
        assert_eq!(state, JobState::Failed);
        assert!(msg.unwrap().contains("every available worker (only)"));
    }

    /// A relay renders nothing itself, so its lease expiring (the relay died) is no failure of
    /// the batch: a relay with a fixed name that died three times on one range used to fail
    /// the job, barred from the range and the only client present.
    #[test]
    fn a_relay_that_dies_never_fails_the_job() {
        let mut s = sched();
        s.add_job(1, 10, 10, 0, &[], JobState::Queued);
        let mut t = 0;
        for _ in 0..4 {
            let g = s.lease_for("relay-a", Some(4), t).unwrap();
            assert_eq!(g.start, 0, "the same range again");
            t += 1001;
            assert_eq!(s.expire(t).len(), 1);
        }
        assert_eq!(s.status(1).unwrap().0, JobState::Running);
        // A worker's expiry still counts.
        for w in ["a", "b", "c"] {
            s.lease(w, t).unwrap();
            t += 1001;
            s.expire(t);
        }
        assert_eq!(s.status(1).unwrap().0, JobState::Failed);
    }

    /// Jobs take turns: a worker asking again and again gets batches of every job with work in
    /// turn, not the oldest job's until it is done.
    #[test]
    fn jobs_take_turns() {
        let mut s = sched();
        for id in [1, 2, 3] {
            s.add_job(id, 100, 100, 0, &[], JobState::Queued);
        }
        let jobs: Vec<u64> = (0..7)
            .map(|t| s.lease(&format!("w{t}"), t).unwrap().job_id)
            .collect();
        assert_eq!(jobs, [1, 2, 3, 1, 2, 3, 1]);
        // A finished job drops out of the turns.
        s.cancel(2);
        assert_eq!(s.lease("w10", 10).unwrap().job_id, 3);
        assert_eq!(s.lease("w11", 11).unwrap().job_id, 1);
    }

    #[test]
    fn restart_reissues_what_was_not_done() {
        let mut s = sched();
        s.add_job(3, 20, 8, 12, &[(0, 4), (6, 8)], JobState::Running);
        let mut got = Vec::new();
        while let Some(g) = s.lease("w", 0) {
            got.push((g.start, g.end));
            s.complete(g.lease_id, 0).unwrap();
        }
        got.sort();
        // The holes (4..6, 8..12), then the rest in window-aligned batches.
        assert_eq!(&got[..2], &[(4, 5), (5, 6)]);
        let total: u64 = got.iter().map(|(a, b)| b - a).sum();
        assert_eq!(total, 20 - 6);
        assert_eq!(s.status(3).unwrap().0, JobState::Done);
    }

    /// After a restart between a checkpoint and forgetting the batches it merged, the stored
    /// prefix [0, 16) and the batch [14, 16) overlap: the job is done once every other pass is
    /// in, not two passes early (it once waited forever for passes it no longer handed out).
    #[test]
    fn overlapping_done_ranges_count_each_pass_once() {
        let mut s = sched();
        s.add_job(1, 40, 16, 18, &[(0, 16), (14, 16), (16, 17)], JobState::Running);
        assert_eq!(s.status(1).unwrap().1, 17);
        let mut handed = Vec::new();
        while let Some(g) = s.lease("w", 0) {
            assert_eq!(s.status(1).unwrap().0, JobState::Running, "done before {g:?}");
            handed.extend(g.start..g.end);
            s.complete(g.lease_id, 0).unwrap();
        }
        handed.sort();
        assert_eq!(handed, (17..40).collect::<Vec<u64>>());
        assert_eq!(s.status(1).unwrap().0, JobState::Done);
        assert_eq!(s.status(1).unwrap().1, 40);
    }

    #[test]
    fn a_lease_from_before_a_restart_is_restored_once_and_only_on_waiting_passes() {
        let mut s = sched();
        // After a restart: passes [0, 8) were handed out, [0, 2) are done.
        s.add_job(1, 20, 10, 8, &[(0, 2)], JobState::Running);
        let g = |start, end| Grant {
            lease_id: 0,
            job_id: 1,
            start,
            end,
        };
        assert!(s.restore_lease(100, &g(4, 6), "w", 50));
        assert!(!s.restore_lease(100, &g(4, 6), "w", 50), "once");
        assert!(!s.restore_lease(101, &g(0, 2), "w", 50), "done already");
        assert!(
            !s.restore_lease(102, &g(5, 7), "w", 50),
            "overlaps the restored one"
        );
        assert!(!s.restore_lease(103, &g(1, 1 << 40), "w", 50));
        // The rest is handed out again, around the restored lease.
        let mut handed = Vec::new();
        while let Some(l) = s.lease("v", 0) {
            handed.extend(l.start..l.end);
            s.complete(l.lease_id, 1).unwrap();
        }
        handed.sort();
        let expected: Vec<u64> = (2..4).chain(6..20).collect();
        assert_eq!(handed, expected);
        assert_eq!(s.complete(100, 10).unwrap().start, 4);
        assert!(s.expire(51).is_empty());
    }

    #[test]
    fn batches_lengthen_with_the_workers_present() {
        let config = SchedulerConfig {
            lease_timeout_ms: 1_000_000,
            target_batch_ms: 5_000,
            max_batch: 1_000_000,
            absorb_pixels_per_s: 1e6,
        };
        // 1000 pixels, 1e6 pixels/s absorbed: up to 5000 workers keep the 5 s target.
        assert_eq!(target_ms(&config, 1, 1000), 5_000);
        assert_eq!(target_ms(&config, 5_000, 1000), 5_000);
        assert_eq!(target_ms(&config, 20_000, 1000), 20_000);
        let mut s = Scheduler::new(config, 1);
        s.add_job(1, 1 << 40, 1 << 40, 0, &[], JobState::Queued);
        s.set_pixels(1, 2_000_000);
        // A relay's first batch has a pass per renderer.
        let g = s.lease_for("relay", Some(8), 0).unwrap();
        assert_eq!(g.end - g.start, 8);
        // One pass per second measured: 5 passes with 2 workers (2 × 2 Mpx / 1 Mpx/s = 4 s
        // is under the 5 s target)...
        s.lease("other", 0).unwrap();
        s.complete(g.lease_id, 8_000).unwrap();
        let g = s.lease("relay", 8_000).unwrap();
        assert_eq!(g.end - g.start, 5);
        s.complete(g.lease_id, 13_000).unwrap();
        // ... and 20 passes (20 s) with 10 workers present (20 Mpx / 1 Mpx/s).
        for i in 0..8 {
            s.lease(&format!("w{i}"), 13_000).unwrap();
        }
        let g = s.lease("relay", 13_000).unwrap();
        assert_eq!(g.end - g.start, 20);
    }

    #[test]
    fn batches_shrink_near_the_end_so_workers_finish_together() {
        let mut s = sched();
        s.add_job(1, 100, 100, 0, &[], JobState::Queued);
        // Both workers measured at one pass per millisecond: 100 ms batches of 100 passes
        // would be the whole job, but each takes half of what is left.
        for w in ["a", "b"] {
            let g = s.lease(w, 0).unwrap();
            s.complete(g.lease_id, 1).unwrap();
        }
        let mut sizes = Vec::new();
        let mut now = 1;
        while let Some(g) = s.lease(if sizes.len() % 2 == 0 { "a" } else { "b" }, now) {
            // Each batch takes its size in milliseconds: the rates stay one pass per ms.
            sizes.push(g.end - g.start);
            now += g.end - g.start;
            s.complete(g.lease_id, now).unwrap();
        }
        assert_eq!(sizes.iter().sum::<u64>(), 98);
        assert_eq!(sizes, [49, 25, 12, 6, 3, 2, 1]);
        assert_eq!(s.status(1).unwrap().0, JobState::Done);
    }

    #[test]
    fn a_sequence_takes_one_turn_and_each_turn_goes_to_its_first_frame_with_passes() {
        let mut s = sched();
        // A job, then a sequence of three frames (jobs 2 to 4), then another job.
        for id in 1..=5 {
            s.add_job(id, 2, 100, 0, &[], JobState::Queued);
        }
        for id in 2..=4 {
            s.set_group(id, 4);
        }
        let jobs: Vec<u64> = (0..10).map(|_| s.lease("w", 0).unwrap().job_id).collect();
        // While jobs 1 and 5 have passes, each round gives them a lease each and the sequence
        // one, to its first frame with passes left; the frames finish in order.
        assert_eq!(jobs, [1, 2, 5, 1, 2, 5, 3, 3, 4, 4]);
    }

    #[test]
    fn cancel_and_close() {
        let mut s = sched();
        s.add_job(1, 100, 10, 0, &[], JobState::Queued);
        let g = s.lease("w", 0).unwrap();
        assert!(s.cancel(1));
        assert_eq!(s.complete(g.lease_id, 1), Err(LeaseError::NotActive(g.lease_id)));
        assert!(s.lease("w", 2).is_none());
        let mut s = sched();
        s.add_job(2, u64::MAX, 10, 0, &[], JobState::Queued);
        let g = s.lease("w", 0).unwrap();
        s.close(2);
        assert!(s.lease("w", 1).is_none());
        s.complete(g.lease_id, 2).unwrap();
        assert_eq!(s.status(2).unwrap().0, JobState::Done);
    }
}
