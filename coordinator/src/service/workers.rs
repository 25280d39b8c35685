//! The workers as the coordinator has seen them, for `GET /api/workers` and the web page.
//!
//! Workers are plain pull clients with no registration: what is known of one is what it
//! said when it last asked for work (its name and threads), when it was last heard from
//! (lease requests and heartbeats), and the speed of its latest finished batch. Workers unheard
//! of for an hour are forgotten, and the roster holds at most [`MAX_WORKERS`], so no worker
//! token holder can grow it without bound.

use std::collections::HashMap;
use std::time::{Duration, Instant};

use serde::Serialize;

/// The most workers remembered; beyond it the one heard from longest ago is forgotten.
pub const MAX_WORKERS: usize = 10_000;
/// Workers unheard of for this long are forgotten.
const FORGET_AFTER: Duration = Duration::from_secs(3600);

#[derive(Clone, Debug)]
struct Seen {
    threads: u32,
    last_seen: Instant,
    batches: u64,
    passes: u64,
    rate: f64,
}

/// A batch a worker holds now.
#[derive(Clone, Debug, Serialize)]
pub struct Holding {
    /// The job.
    pub job: u64,
    /// First pass.
    pub start: u64,
    /// One past the last.
    pub end: u64,
}

/// One worker in `GET /api/workers`.
#[derive(Clone, Debug, Serialize)]
pub struct WorkerStatus {
    /// Its name (`--name`).
    pub name: String,
    /// Threads it said it renders with.
    pub threads: u32,
    /// Seconds since it last asked for work or sent a heartbeat.
    pub last_seen_seconds: f64,
    /// Batches it delivered since this coordinator started.
    pub batches: u64,
    /// Passes in them.
    pub passes: u64,
    /// Passes per second of its latest finished batch (0 before its first).
    pub rate: f64,
    /// Batches it holds now.
    pub leases: Vec<Holding>,
}

/// Every worker heard from lately.
#[derive(Debug, Default)]
pub struct Roster {
    seen: HashMap<String, Seen>,
}

impl Roster {
    /// A worker asked for work.
    pub fn asked(&mut self, name: &str, threads: u32) {
        let now = Instant::now();
        self.seen
            .retain(|_, s| now.duration_since(s.last_seen) < FORGET_AFTER);
        if !self.seen.contains_key(name) && self.seen.len() >= MAX_WORKERS {
            let oldest = self
                .seen
                .iter()
                .min_by_key(|(_, s)| s.last_seen)
                .map(|(n, _)| n.clone());
            if let Some(oldest) = oldest {
                self.seen.remove(&oldest);
            }
        }
        let entry = self.seen.entry(name.to_string()).or_insert(Seen {
            threads,
            last_seen: now,
            batches: 0,
            passes: 0,
            rate: 0.0,
        });
        entry.threads = threads;
        entry.last_seen = now;
    }

    /// A worker sent a heartbeat.
    pub fn heard(&mut self, name: &str) {
        if let Some(s) = self.seen.get_mut(name) {
            s.last_seen = Instant::now();
        }
    }

    /// A worker delivered `passes` passes at `rate` passes per second.
    pub fn delivered(&mut self, name: &str, passes: u64, rate: f64) {
        if let Some(s) = self.seen.get_mut(name) {
            s.last_seen = Instant::now();
            s.batches += 1;
            s.passes += passes;
            s.rate = rate;
        }
    }

    /// Every worker, by name, with the batches each holds (`holding`: worker name and batch).
    pub fn list(&self, holding: &[(String, Holding)]) -> Vec<WorkerStatus> {
        let now = Instant::now();
        let mut out: Vec<WorkerStatus> = self
            .seen
            .iter()
            .map(|(name, s)| WorkerStatus {
                name: name.clone(),
                threads: s.threads,
                last_seen_seconds: now.duration_since(s.last_seen).as_secs_f64(),
                batches: s.batches,
                passes: s.passes,
                rate: s.rate,
                leases: holding
                    .iter()
                    .filter(|(w, _)| w == name)
                    .map(|(_, h)| h.clone())
                    .collect(),
            })
            .collect();
        out.sort_by(|a, b| a.name.cmp(&b.name));
        out
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn follows_workers_and_stays_bounded() {
        let mut r = Roster::default();
        r.asked("b", 4);
        r.asked("a", 2);
        r.delivered("a", 6, 3.0);
        r.heard("nobody");
        let held = [(
            "a".to_string(),
            Holding {
                job: 1,
                start: 6,
                end: 12,
            },
        )];
        let list = r.list(&held);
        assert_eq!(list.len(), 2);
        assert_eq!((list[0].name.as_str(), list[0].threads), ("a", 2));
        assert_eq!((list[0].passes, list[0].rate), (6, 3.0));
        assert_eq!(list[0].leases.len(), 1);
        assert!(list[1].leases.is_empty());
        for i in 0..MAX_WORKERS + 5 {
            r.asked(&format!("w{i}"), 1);
        }
        assert_eq!(r.seen.len(), MAX_WORKERS);
    }
}
