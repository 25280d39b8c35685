//! `GET /metrics`: the farm in Prometheus' text format, for dashboards and for autoscalers
//! (KEDA scales workers on `photonfarm_pending_passes`).
//!
//! Most figures are read from the farm when scraped, so the request path carries no counters;
//! only checkpoint latency, which nothing else records, is observed as it happens.

use std::time::Duration;

use prometheus_client::encoding::EncodeLabelSet;
use prometheus_client::metrics::family::Family;
use prometheus_client::metrics::gauge::Gauge;
use prometheus_client::metrics::histogram::{Histogram, exponential_buckets};
use prometheus_client::registry::Registry;

use crate::service::farm::JobStatus;

/// What the service observes between scrapes.
#[derive(Clone)]
pub struct Metrics {
    checkpoint_seconds: Histogram,
}

impl Default for Metrics {
    fn default() -> Self {
        Metrics {
            // 1 ms to about 16 s.
            checkpoint_seconds: Histogram::new(exponential_buckets(0.001, 2.0, 15)),
        }
    }
}

/// The farm at one moment, copied under its lock.
pub struct Snapshot {
    /// Every job.
    pub jobs: Vec<JobStatus>,
    /// Workers that asked for work lately.
    pub workers: usize,
    /// Leases held.
    pub leases: usize,
}

#[derive(Clone, Debug, Hash, PartialEq, Eq, EncodeLabelSet)]
struct JobLabels {
    job: String,
}

#[derive(Clone, Debug, Hash, PartialEq, Eq, EncodeLabelSet)]
struct StateLabels {
    state: String,
}

type IntGauge = Gauge<i64>;
type FloatGauge = Gauge<f64, std::sync::atomic::AtomicU64>;

impl Metrics {
    /// Records how long writing a checkpoint (prefix sums and images) took.
    pub fn observe_checkpoint(&self, took: Duration) {
        self.checkpoint_seconds.observe(took.as_secs_f64());
    }

    /// The text a scrape returns.
    pub fn encode(&self, farm: &Snapshot) -> String {
        let mut registry = Registry::with_prefix("photonfarm");
        let gauge = |registry: &mut Registry, name: &str, help: &str, v: i64| {
            let g = IntGauge::default();
            g.set(v);
            registry.register(name, help, g);
        };
        gauge(
            &mut registry,
            "workers",
            "Workers that asked for work lately",
            farm.workers as i64,
        );
        gauge(
            &mut registry,
            "leases",
            "Batches being rendered now",
            farm.leases as i64,
        );
        let open = farm.jobs.iter().filter(|j| !j.state.is_final());
        let pending: u64 = open
            .clone()
            .map(|j| j.iterations_total.saturating_sub(j.iterations_done))
            .sum();
        gauge(
            &mut registry,
            "pending_passes",
            "Passes of queued and running jobs not yet received (the queue depth)",
            pending as i64,
        );
        let by_state = Family::<StateLabels, IntGauge>::default();
        for state in ["queued", "running", "done", "failed", "cancelled"] {
            let n = farm.jobs.iter().filter(|j| j.state.as_str() == state).count();
            by_state
                .get_or_create(&StateLabels { state: state.into() })
                .set(n as i64);
        }
        registry.register("jobs", "Jobs by state", by_state);
        let frames = Family::<StateLabels, IntGauge>::default();
        for state in ["queued", "running", "done", "failed", "cancelled"] {
            let n = farm
                .jobs
                .iter()
                .flat_map(|j| &j.frames)
                .filter(|f| f.state.as_str() == state)
                .count();
            frames
                .get_or_create(&StateLabels { state: state.into() })
                .set(n as i64);
        }
        registry.register("frames", "Frames of sequences by state", frames);

        let done = Family::<JobLabels, IntGauge>::default();
        let total = Family::<JobLabels, IntGauge>::default();
        let rate = Family::<JobLabels, FloatGauge>::default();
        let bytes = Family::<JobLabels, IntGauge>::default();
        let batches = Family::<JobLabels, IntGauge>::default();
        let workers = Family::<JobLabels, IntGauge>::default();
        for j in open {
            let l = JobLabels {
                job: j.id.to_string(),
            };
            done.get_or_create(&l).set(j.iterations_done as i64);
            total.get_or_create(&l).set(j.iterations_total as i64);
            rate.get_or_create(&l).set(j.rate);
            bytes.get_or_create(&l).set(j.bytes_received as i64);
            batches.get_or_create(&l).set(j.batches_received as i64);
            workers.get_or_create(&l).set(j.workers.len() as i64);
        }
        registry.register("job_passes_done", "Passes received, per open job", done);
        registry.register("job_passes", "Passes asked for, per open job", total);
        registry.register("job_passes_per_second", "Passes per second, per open job", rate);
        registry.register(
            "job_received_bytes",
            "Bytes of results received, per open job",
            bytes,
        );
        registry.register("job_batches", "Batch results received, per open job", batches);
        registry.register("job_workers", "Workers holding a batch, per open job", workers);
        registry.register(
            "checkpoint_seconds",
            "Time to write a checkpoint (exact sums and images)",
            self.checkpoint_seconds.clone(),
        );
        let mut out = String::new();
        prometheus_client::encoding::text::encode(&mut out, &registry).expect("writing to a String");
        out
    }
}
