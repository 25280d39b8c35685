//! The relay's bookkeeping: the batches it leased upstream, the parts of them its local
//! workers hold, and each batch's running sum.
//!
//! Pure logic (the caller passes the time), so every rule is unit-tested:
//! - An upstream batch [s, e) is cut into parts handed to local workers, each about the
//!   batch's length over the local workers present (so they finish together).
//! - A part whose worker stops heartbeating, or releases it, goes back to the batch for
//!   another local worker; a batch whose parts failed three times is given up upstream.
//! - Parts' sums are added exactly (integers): the batch's sum is the bits the coordinator
//!   would have summed from the parts, so images stay byte-identical. Their odd passes'
//!   samples are added too (the relay forwards the whole batch's odd passes); a part sent
//!   without one (an older worker) makes the batch go upstream without one.

use std::collections::{BTreeMap, BTreeSet, HashMap};
use std::sync::{Arc, Mutex};

use photonfarm::features::Features;
use photonfarm::film::FilmSum;
use photonfarm::parity::OddSums;
use photonfarm::protocol::Lease;

/// Milliseconds on the caller's clock.
pub type Millis = u64;

/// Why a local request about a part is refused.
#[derive(Debug, PartialEq, Eq, thiserror::Error)]
pub enum PartError {
    /// Unknown, delivered, released or expired.
    #[error("lease {0} is not active (it expired, was completed or was reassigned)")]
    NotActive(u64),
    /// The upstream batch was lost (expired, or its job ended).
    #[error("lease {0}'s batch is no longer held upstream")]
    Gone(u64),
    /// Another worker's part.
    #[error("lease {0} was granted to another worker")]
    NotYours(u64),
}

/// A batch's running sum, under its own lock (adding a 1920×1080 sum takes milliseconds).
#[derive(Debug)]
pub struct BatchSum {
    /// Passes in the batch.
    pub len: u64,
    /// Passes added so far.
    pub added: u64,
    /// The sum so far (None before the first part).
    pub sum: Option<FilmSum>,
    /// The odd passes' sample so far; None once a part came without one.
    pub odd: Option<OddSums>,
    odd_known: bool,
    /// The denoiser's features so far, for a job that asks for them; None once a part came
    /// without them.
    pub features: Option<Features>,
    features_known: bool,
}

impl BatchSum {
    fn new(len: u64) -> BatchSum {
        BatchSum {
            len,
            added: 0,
            sum: None,
            odd: None,
            odd_known: true,
            features: None,
            features_known: true,
        }
    }

    /// Adds a part's sum of passes [start, start + sum.passes) with its odd passes' sample
    /// (None: not sent; a one-pass part's is known from its parity) and its features (None:
    /// not sent). Returns whether the batch is complete.
    pub fn add(
        &mut self,
        start: u64,
        sum: FilmSum,
        odd: Option<OddSums>,
        features: Option<Features>,
    ) -> Result<bool, photonfarm::film::FilmError> {
        let odd = OddSums::sent_or_known(odd, start, &sum);
        let passes = sum.passes;
        match &mut self.sum {
            None => self.sum = Some(sum),
            Some(total) => total.add(&sum)?,
        }
        match (odd, self.odd.as_mut()) {
            (Some(o), Some(mine)) => mine.add(&o),
            (Some(o), None) if self.odd_known => self.odd = Some(o),
            _ => {
                self.odd = None;
                self.odd_known = false;
            }
        }
        match (features, self.features.as_mut()) {
            (Some(f), Some(mine)) => mine.add(&f)?,
            (Some(f), None) if self.features_known => self.features = Some(f),
            _ => {
                self.features = None;
                self.features_known = false;
            }
        }
        self.added += passes;
        Ok(self.added >= self.len)
    }
}

struct Batch {
    /// The upstream lease (its id, key, range, radii and settings).
    lease: Lease,
    /// Ranges no local worker holds or delivered.
    free: BTreeSet<(u64, u64)>,
    sum: Arc<Mutex<BatchSum>>,
    failures: u32,
    /// Complete: being forwarded upstream (still heartbeated until then).
    forwarding: bool,
    /// When its upstream lease is next heartbeated.
    beat_at: Millis,
}

struct Part {
    batch: u64,
    start: u64,
    end: u64,
    key: String,
    deadline: Millis,
}

/// What a local worker's result must be.
#[derive(Clone, Debug)]
pub struct PartInfo {
    /// The upstream lease.
    pub batch: u64,
    /// First pass.
    pub start: u64,
    /// One past the last.
    pub end: u64,
    /// Image size (0 if the upstream did not say).
    pub width: u32,
    /// See `width`.
    pub height: u32,
    /// Whether the result must carry the denoiser's features.
    pub features: bool,
}

/// Failures of parts of one batch after which the batch is given up upstream.
const BATCH_FAILURES: u32 = 3;

/// The relay's state.
pub struct Book {
    batches: BTreeMap<u64, Batch>,
    parts: HashMap<u64, Part>,
    next_part: u64,
    timeout_ms: Millis,
    /// Local workers with the time they last asked for work.
    seen: HashMap<String, Millis>,
}

impl Book {
    /// A book whose parts expire `timeout_ms` after their last heartbeat.
    pub fn new(timeout_ms: Millis) -> Book {
        Book {
            batches: BTreeMap::new(),
            parts: HashMap::new(),
            next_part: 1,
            timeout_ms,
            seen: HashMap::new(),
        }
    }

    /// Notes a local worker asking for work; returns how many asked lately (the renderers
    /// this relay stands for upstream).
    pub fn asked(&mut self, worker: &str, now: Millis) -> u32 {
        self.seen.insert(worker.to_string(), now);
        let recent = now.saturating_sub(self.timeout_ms.saturating_mul(2));
        self.seen.retain(|_, &mut t| t >= recent);
        self.seen.len() as u32
    }

    /// Adds a batch leased upstream at `now`.
    pub fn add_batch(&mut self, lease: Lease, now: Millis) {
        let len = lease.end - lease.start;
        let beat_at = now + beat_every(&lease);
        self.batches.insert(
            lease.lease_id,
            Batch {
                free: BTreeSet::from([(lease.start, lease.end)]),
                sum: Arc::new(Mutex::new(BatchSum::new(len))),
                lease,
                failures: 0,
                forwarding: false,
                beat_at,
            },
        );
    }

    /// Hands a part of the oldest batch with passes free to a local worker: a lease of its
    /// own (`key` is its secret), or None if every batch is taken.
    pub fn take(&mut self, key: String, now: Millis) -> Option<Lease> {
        let workers = self.seen.len().max(1) as u64;
        let (&id, batch) = self
            .batches
            .iter_mut()
            .find(|(_, b)| !b.forwarding && !b.free.is_empty())?;
        let &(s, e) = batch.free.iter().next()?;
        batch.free.remove(&(s, e));
        let size = (batch.lease.end - batch.lease.start).div_ceil(workers).max(1);
        let cut = (s + size).min(e);
        if cut < e {
            batch.free.insert((cut, e));
        }
        let part_id = self.next_part;
        self.next_part += 1;
        self.parts.insert(
            part_id,
            Part {
                batch: id,
                start: s,
                end: cut,
                key: key.clone(),
                deadline: now + self.timeout_ms,
            },
        );
        let up = &batch.lease;
        let radii = if up.radii.is_empty() {
            Vec::new()
        } else {
            let from = (s - up.start) as usize;
            up.radii[from..from + (cut - s) as usize].to_vec()
        };
        Some(Lease {
            lease_id: part_id,
            start: s,
            end: cut,
            radii,
            deadline_ms: self.timeout_ms,
            heartbeat_ms: (self.timeout_ms / 4).max(10),
            key,
            accept_encoding: vec![photonfarm::compression::ZSTD.to_string()],
            ..up.clone()
        })
    }

    fn part(&self, id: u64, key: &str) -> Result<&Part, PartError> {
        let part = self.parts.get(&id).ok_or(PartError::NotActive(id))?;
        if part.key.as_bytes() != key.as_bytes() {
            return Err(PartError::NotYours(id));
        }
        if !self.batches.contains_key(&part.batch) {
            return Err(PartError::Gone(id));
        }
        Ok(part)
    }

    /// Extends a part's deadline.
    pub fn heartbeat(&mut self, id: u64, key: &str, now: Millis) -> Result<Millis, PartError> {
        self.part(id, key)?;
        let deadline = now + self.timeout_ms;
        if let Some(p) = self.parts.get_mut(&id) {
            p.deadline = deadline;
        }
        Ok(self.timeout_ms)
    }

    /// What a part's result must be.
    pub fn expected(&self, id: u64, key: &str) -> Result<PartInfo, PartError> {
        let part = self.part(id, key)?;
        let up = &self.batches[&part.batch].lease;
        Ok(PartInfo {
            batch: part.batch,
            start: part.start,
            end: part.end,
            width: up.width,
            height: up.height,
            features: up.features,
        })
    }

    /// A part's result arrived (checked by the caller): the part ends, and the caller adds
    /// the sum to the returned batch sum.
    pub fn deliver(&mut self, id: u64, key: &str) -> Result<Arc<Mutex<BatchSum>>, PartError> {
        let part = self.part(id, key)?;
        let batch = part.batch;
        self.parts.remove(&id);
        Ok(self.batches[&batch].sum.clone())
    }

    /// A batch is complete: it is forwarded upstream, and heartbeated until then. Returns its
    /// upstream lease.
    pub fn forwarding(&mut self, batch: u64) -> Option<Lease> {
        let b = self.batches.get_mut(&batch)?;
        b.forwarding = true;
        Some(b.lease.clone())
    }

    /// A local worker gives a part back: its passes go to another. With an error, the batch
    /// counts a failure; returns the batch's upstream lease if it is given up (the caller
    /// releases it upstream with the error).
    pub fn release(&mut self, id: u64, key: &str, error: bool) -> Result<Option<Lease>, PartError> {
        let part = self.part(id, key)?;
        let (batch, s, e) = (part.batch, part.start, part.end);
        self.parts.remove(&id);
        let b = self.batches.get_mut(&batch).expect("checked by part()");
        b.free.insert((s, e));
        if error {
            b.failures += 1;
            if b.failures >= BATCH_FAILURES {
                return Ok(self.finish(batch));
            }
        }
        Ok(None)
    }

    /// Parts whose deadline passed go back to their batches; returns how many.
    pub fn expire(&mut self, now: Millis) -> usize {
        let expired: Vec<u64> = self
            .parts
            .iter()
            .filter(|(_, p)| p.deadline < now)
            .map(|(&id, _)| id)
            .collect();
        for id in &expired {
            if let Some(p) = self.parts.remove(id)
                && let Some(b) = self.batches.get_mut(&p.batch)
            {
                b.free.insert((p.start, p.end));
            }
        }
        expired.len()
    }

    /// A batch's sum (to forward it once complete).
    pub fn sum_of(&self, batch: u64) -> Option<Arc<Mutex<BatchSum>>> {
        self.batches.get(&batch).map(|b| b.sum.clone())
    }

    /// Forgets a batch (forwarded, given up, or lost upstream): its parts become void.
    pub fn finish(&mut self, batch: u64) -> Option<Lease> {
        let b = self.batches.remove(&batch)?;
        self.parts.retain(|_, p| p.batch != batch);
        Some(b.lease)
    }

    /// The upstream leases (id, key) due for a heartbeat at `now`, each then due again after
    /// its interval.
    pub fn due(&mut self, now: Millis) -> Vec<(u64, String)> {
        self.batches
            .values_mut()
            .filter(|b| b.beat_at <= now)
            .map(|b| {
                b.beat_at = now + beat_every(&b.lease);
                (b.lease.lease_id, b.lease.key.clone())
            })
            .collect()
    }
}

/// How often an upstream lease is heartbeated: as often as the upstream asks, and at least
/// three times per deadline (an upstream that does not say is heartbeated every 5 s, within
/// the coordinator's default 30 s).
fn beat_every(lease: &Lease) -> Millis {
    let asked = match lease.heartbeat_ms {
        0 => 5000,
        ms => ms,
    };
    let within = match lease.deadline_ms {
        0 => asked,
        ms => ms / 3,
    };
    asked.min(within).max(10)
}

#[cfg(test)]
mod tests {
    use super::*;
    use photonfarm::integrator::path::PathSettings;
    use photonfarm::render::{Method, RenderSettings};

    fn upstream(id: u64, start: u64, end: u64) -> Lease {
        Lease {
            lease_id: id,
            job_id: 1,
            start,
            end,
            radii: (start..end).map(|p| [p as f32, 0.0]).collect(),
            settings: RenderSettings {
                seed: 0,
                method: Method::Path(PathSettings {
                    max_depth: None,
                    rr_depth: 5,
                }),
            },
            bundle: "b".into(),
            scene: "s.xml".into(),
            defines: Vec::new(),
            deadline_ms: 1000,
            heartbeat_ms: 250,
            key: "up".into(),
            accept_encoding: Vec::new(),
            width: 2,
            height: 1,
            features: false,
        }
    }

    fn film(start: u64, end: u64) -> FilmSum {
        let mut f = FilmSum::new(2, 1);
        for p in start..end {
            f.sums[0][0] += p as i64 + 1;
            f.sums[1][2] += 10 * p as i64;
        }
        f.passes = end - start;
        f
    }

    #[test]
    fn parts_split_the_batch_and_sum_exactly_with_their_odd_passes() {
        let mut book = Book::new(1000);
        for w in ["a", "b", "c"] {
            book.asked(w, 0);
        }
        book.add_batch(upstream(7, 10, 17), 0);
        let mut parts = Vec::new();
        while let Some(l) = book.take(format!("k{}", parts.len()), 0) {
            assert_eq!(l.radii[0][0], l.start as f32, "radii follow the part");
            parts.push(l);
        }
        let ranges: Vec<(u64, u64)> = parts.iter().map(|l| (l.start, l.end)).collect();
        assert_eq!(ranges, vec![(10, 13), (13, 16), (16, 17)]);
        assert_eq!(
            book.deliver(parts[0].lease_id, "wrong").err(),
            Some(PartError::NotYours(parts[0].lease_id))
        );
        let mut complete = false;
        for l in parts.iter().rev() {
            let sum = book.deliver(l.lease_id, &l.key).unwrap();
            let mut odd = OddSums::empty(2, 1);
            odd.passes = l.end / 2 - l.start / 2;
            complete = sum
                .lock()
                .unwrap()
                .add(l.start, film(l.start, l.end), Some(odd), None)
                .unwrap();
        }
        assert!(complete);
        let sum = book.batches[&7].sum.lock().unwrap();
        assert_eq!(sum.sum.as_ref().unwrap(), &film(10, 17));
        assert_eq!(sum.odd.as_ref().unwrap().passes, 17 / 2 - 10 / 2);
    }

    #[test]
    fn expired_and_failed_parts_go_to_other_workers_and_three_failures_give_up() {
        let mut book = Book::new(1000);
        book.asked("a", 0);
        book.add_batch(upstream(1, 0, 4), 0);
        let a = book.take("ka".into(), 0).unwrap();
        assert_eq!((a.start, a.end), (0, 4));
        assert!(book.take("kb".into(), 0).is_none());
        assert_eq!(book.heartbeat(a.lease_id, "ka", 500), Ok(1000));
        assert_eq!(book.expire(1400), 0);
        assert_eq!(book.expire(1501), 1);
        assert_eq!(
            book.heartbeat(a.lease_id, "ka", 1502),
            Err(PartError::NotActive(a.lease_id))
        );
        for k in 0..3 {
            let p = book.take(format!("f{k}"), 2000).unwrap();
            assert_eq!((p.start, p.end), (0, 4), "the same passes again");
            let given_up = book.release(p.lease_id, &p.key, true).unwrap();
            assert_eq!(given_up.is_some(), k == 2);
        }
        assert!(book.due(u64::MAX).is_empty());
        // A batch lost upstream voids its parts.
        book.add_batch(upstream(2, 0, 2), 0);
        let p = book.take("k".into(), 0).unwrap();
        book.finish(2);
        assert_eq!(
            book.heartbeat(p.lease_id, "k", 1),
            Err(PartError::NotActive(p.lease_id))
        );
    }

    /// Upstream leases are heartbeated as often as their upstream asks, whatever the relay's
    /// own timeout: a coordinator with a 3 s lease timeout used to lose a relay's batches,
    /// heartbeated every 5 s.
    #[test]
    fn upstream_leases_are_heartbeated_as_often_as_the_upstream_asks() {
        let mut book = Book::new(30_000);
        book.add_batch(upstream(1, 0, 4), 0);
        assert!(book.due(249).is_empty());
        assert_eq!(book.due(250), vec![(1, "up".to_string())]);
        assert!(book.due(499).is_empty());
        assert_eq!(book.due(500).len(), 1);
        // An upstream that asks for rarer heartbeats than its deadline allows is heartbeated
        // three times per deadline.
        let mut lax = upstream(2, 0, 4);
        lax.heartbeat_ms = 10_000;
        lax.deadline_ms = 3000;
        book.add_batch(lax, 1000);
        assert!(book.due(1999).iter().all(|(id, _)| *id != 2));
        assert!(book.due(2000).iter().any(|(id, _)| *id == 2));
    }

    #[test]
    fn a_part_without_odd_passes_sends_the_batch_without_them() {
        let mut s = BatchSum::new(5);
        assert!(
            !s.add(0, film(0, 1), None, None).unwrap(),
            "one pass: parity known"
        );
        assert!(s.odd.is_some());
        assert!(s.add(1, film(1, 5), None, None).unwrap());
        assert!(s.odd.is_none());
        assert_eq!(s.sum.unwrap(), film(0, 5));
    }
}
