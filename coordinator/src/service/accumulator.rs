//! Adds batch results up in pass order, so that the image at every checkpoint is exactly the
//! image of passes [0, N): byte-identical whichever workers rendered them and in whatever order
//! they arrived.
//!
//! Results that arrive ahead of a gap wait, summed per checkpoint window: exact integer
//! addition does not depend on order, and one sum per window (not one per result) bounds the
//! memory a job takes however many workers deliver out of order (a 1920×1080 sum is 50 MB, and
//! a thousand workers' results arrive in any order).
//!
//! Beside the prefix it sums the prefix's odd passes on the sampled pixels
//! ([`photonfarm::parity`]), and estimates the image's noise from them as the prefix grows;
//! for a job that asks for them, it sums the denoiser's features ([`photonfarm::features`])
//! the same way, so that a checkpoint's features are of exactly its passes.

use std::collections::BTreeMap;

use photonfarm::features::Features;
use photonfarm::film::{FilmError, FilmSum};
use photonfarm::parity::{self, OddSums};

/// The running sum of a job.
#[derive(Debug)]
pub struct Accumulator {
    /// Passes [0, prefix.passes), summed.
    prefix: FilmSum,
    /// The prefix's odd passes on the sampled pixels; None once a result without them (from
    /// an older worker) was merged: the job then has no noise estimate.
    odd: Option<OddSums>,
    /// The prefix's features, for a job that asks for them.
    features: Option<Features>,
    /// Results that arrived ahead of a gap, summed per checkpoint window (by window index).
    pending: BTreeMap<u64, Waiting>,
    /// Checkpoints fall on multiples of this.
    checkpoint_every: u64,
    /// Passes at the latest noise estimate reported.
    noise_passes: u64,
}

/// The results of one checkpoint window that wait for a gap before them to be filled.
#[derive(Debug)]
struct Waiting {
    /// Their sum.
    sum: FilmSum,
    /// Their odd passes' sample; None if one of them came without it.
    odd: Option<OddSums>,
    /// Their features; None if one of them came without them.
    features: Option<Features>,
    /// Their pass ranges, by first pass (never overlapping: each pass is leased once at a time
    /// and counted once).
    ranges: BTreeMap<u64, u64>,
}

impl Waiting {
    /// Whether the ranges are one run starting at `from`: then the sum is exactly the passes
    /// [from, end) and may join the prefix.
    fn run_from(&self, from: u64) -> Option<u64> {
        let mut at = from;
        for (&s, &e) in &self.ranges {
            if s != at {
                return None;
            }
            at = e;
        }
        Some(at)
    }
}

/// The prefix at a checkpoint.
#[derive(Debug)]
pub struct Checkpoint {
    /// Passes [0, N) summed.
    pub sum: FilmSum,
    /// Their features, for a job that asks for them.
    pub features: Option<Features>,
}

/// What merging a result did.
#[derive(Debug, Default)]
pub struct Merged {
    /// A copy of the prefix at each checkpoint (a multiple of the interval) it reached.
    pub checkpoints: Vec<Checkpoint>,
    /// Whether the prefix moved.
    pub moved: bool,
    /// (passes, estimated variance) as the prefix grew: at checkpoints, and otherwise at
    /// least 5% apart in passes, so a long job's chart stays a few hundred points.
    pub noise: Vec<(u64, f64)>,
}

impl Accumulator {
    /// Starts from `prefix` (passes [0, prefix.passes) already summed), its odd passes'
    /// sample, if known, and its features, for a job that asks for them.
    pub fn new(
        prefix: FilmSum,
        odd: Option<OddSums>,
        features: Option<Features>,
        checkpoint_every: u64,
    ) -> Accumulator {
        let noise_passes = prefix.passes;
        Accumulator {
            prefix,
            odd,
            features,
            pending: BTreeMap::new(),
            checkpoint_every: checkpoint_every.max(1),
            noise_passes,
        }
    }

    /// An empty sum of a `width` × `height` image.
    pub fn empty(width: u32, height: u32, checkpoint_every: u64) -> Accumulator {
        Accumulator::new(
            FilmSum::new(width, height),
            Some(OddSums::empty(width, height)),
            None,
            checkpoint_every,
        )
    }

    /// The same empty sum, summing the denoiser's features too.
    pub fn with_features(mut self) -> Accumulator {
        let (w, h) = self.size();
        self.features = Some(Features::new(w, h));
        self
    }

    /// The same sum with checkpoints every `window` passes.
    pub fn with_window(mut self, window: u64) -> Accumulator {
        self.checkpoint_every = window.max(1);
        self
    }

    /// The image size.
    pub fn size(&self) -> (u32, u32) {
        (self.prefix.width, self.prefix.height)
    }

    /// Passes in the prefix.
    pub fn prefix_passes(&self) -> u64 {
        self.prefix.passes
    }

    /// The prefix sum: the latest exact image.
    pub fn prefix(&self) -> &FilmSum {
        &self.prefix
    }

    /// The prefix's odd passes on the sampled pixels, if known.
    pub fn odd(&self) -> Option<&OddSums> {
        self.odd.as_ref()
    }

    /// The prefix's features, for a job that asks for them.
    pub fn features(&self) -> Option<&Features> {
        self.features.as_ref()
    }

    /// Adds the result of passes [start, start + sum.passes), with its odd passes' sample
    /// (None: not sent; a one-pass result's is known from its parity) and its features (None:
    /// not sent; the prefix then has none from there on).
    pub fn add(
        &mut self,
        start: u64,
        sum: FilmSum,
        odd: Option<OddSums>,
        features: Option<Features>,
    ) -> Result<Merged, FilmError> {
        if (sum.width, sum.height) != (self.prefix.width, self.prefix.height) {
            return Err(FilmError::SizeMismatch(
                sum.width,
                sum.height,
                self.prefix.width,
                self.prefix.height,
            ));
        }
        let mut merged = Merged::default();
        if start < self.prefix.passes {
            // Already merged. Cannot happen: a lease restored after a restart covers only
            // passes not yet stored, and a restart skips stored batches the prefix already
            // holds; this guards the invariant.
            return Ok(merged);
        }
        let odd = OddSums::sent_or_known(odd, start, &sum);
        let end = start + sum.passes;
        match self.pending.entry(start / self.checkpoint_every) {
            std::collections::btree_map::Entry::Vacant(v) => {
                v.insert(Waiting {
                    sum,
                    odd,
                    features,
                    ranges: BTreeMap::from([(start, end)]),
                });
            }
            std::collections::btree_map::Entry::Occupied(mut o) => {
                let w = o.get_mut();
                w.sum.add(&sum)?;
                w.odd = match (w.odd.take(), odd) {
                    (Some(mut mine), Some(theirs)) => {
                        mine.add(&theirs);
                        Some(mine)
                    }
                    _ => None,
                };
                w.features = both(w.features.take(), features)?;
                w.ranges.insert(start, end);
            }
        }
        loop {
            let window = self.prefix.passes / self.checkpoint_every;
            let ready = self
                .pending
                .get(&window)
                .is_some_and(|w| w.run_from(self.prefix.passes).is_some());
            if !ready {
                break;
            }
            let next = self.pending.remove(&window).expect("checked above");
            self.prefix.add(&next.sum)?;
            self.odd = match (self.odd.take(), next.odd) {
                (Some(mut mine), Some(theirs)) => {
                    mine.add(&theirs);
                    Some(mine)
                }
                _ => None,
            };
            self.features = both(self.features.take(), next.features)?;
            merged.moved = true;
            let passes = self.prefix.passes;
            let checkpoint = passes.is_multiple_of(self.checkpoint_every);
            if checkpoint {
                merged.checkpoints.push(Checkpoint {
                    sum: self.prefix.clone(),
                    features: self.features.clone(),
                });
            }
            if (checkpoint || passes * 20 >= self.noise_passes * 21)
                && let Some(v) = self.odd.as_ref().and_then(|o| parity::noise(&self.prefix, o))
            {
                merged.noise.push((passes, v));
                self.noise_passes = passes;
            }
        }
        Ok(merged)
    }

    /// Ranges of results held ahead of a gap.
    pub fn pending_ranges(&self) -> Vec<(u64, u64)> {
        self.pending
            .values()
            .flat_map(|w| w.ranges.iter().map(|(&s, &e)| (s, e)))
            .collect()
    }
}

/// Two sums of features added, or None if either is missing.
fn both(mine: Option<Features>, theirs: Option<Features>) -> Result<Option<Features>, FilmError> {
    match (mine, theirs) {
        (Some(mut mine), Some(theirs)) => {
            mine.add(&theirs)?;
            Ok(Some(mine))
        }
        _ => Ok(None),
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn part(v: i64, passes: u64) -> FilmSum {
        let mut f = FilmSum::new(1, 1);
        f.sums[0] = [v, 0, 0];
        f.passes = passes;
        f
    }

    #[test]
    fn merges_in_order_and_reports_checkpoints() {
        let mut a = Accumulator::empty(1, 1, 4);
        let m = a.add(2, part(3, 2), None, None).unwrap();
        assert!(m.checkpoints.is_empty() && !m.moved);
        let m = a.add(0, part(1, 2), None, None).unwrap();
        assert!(m.moved);
        assert_eq!(m.checkpoints.len(), 1);
        assert_eq!(m.checkpoints[0].sum.passes, 4);
        assert_eq!(m.checkpoints[0].sum.sums[0][0], 4);
        let m = a.add(4, part(5, 3), None, None).unwrap();
        assert!(m.checkpoints.is_empty());
        assert_eq!(a.prefix_passes(), 7);
        assert!(a.add(0, FilmSum::new(2, 1), None, None).is_err());
        assert!(
            a.odd().is_none(),
            "results without their odd passes end the estimate"
        );
    }

    /// Results ahead of a gap are summed per window: one sum in memory per window, and the
    /// prefix is the same integers as adding in pass order.
    #[test]
    fn waiting_results_are_summed_per_window_and_merge_exactly() {
        let mut a = Accumulator::empty(1, 1, 8);
        for (start, passes, v) in [
            (5u64, 2u64, 50i64),
            (2, 1, 20),
            (9, 1, 90),
            (7, 1, 70),
            (3, 2, 30),
        ] {
            let m = a.add(start, part(v, passes), None, None).unwrap();
            assert!(!m.moved);
        }
        // Window 0 holds 2..5, 5..7, 7..8 in one sum; window 1 holds 9..10.
        assert_eq!(a.pending.len(), 2);
        assert_eq!(a.pending_ranges(), vec![(2, 3), (3, 5), (5, 7), (7, 8), (9, 10)]);
        let m = a.add(0, part(1, 2), None, None).unwrap();
        assert!(m.moved);
        assert_eq!(a.prefix_passes(), 8);
        assert_eq!(a.prefix().sums[0][0], 1 + 20 + 30 + 50 + 70);
        assert_eq!(m.checkpoints.len(), 1);
        a.add(8, part(80, 1), None, None).unwrap();
        assert_eq!(a.prefix_passes(), 10);
        assert_eq!(a.prefix().sums[0][0], 1 + 20 + 30 + 50 + 70 + 80 + 90);
        assert!(a.pending_ranges().is_empty());
    }

    /// Features are summed with the sums, per window and in pass order: a checkpoint's
    /// features are those of exactly its passes, whatever order results came in. A result
    /// without them ends them.
    #[test]
    fn features_follow_the_prefix_into_checkpoints() {
        let features = |v: i64, passes: u64| {
            Features::from_sums(std::array::from_fn(|k| part((k as i64 + 1) * v, passes)))
        };
        let mut a = Accumulator::empty(1, 1, 4).with_features();
        for (start, passes, v) in [(2u64, 2u64, 20i64), (4, 1, 40), (0, 2, 1)] {
            let m = a
                .add(start, part(v, passes), None, Some(features(v, passes)))
                .unwrap();
            if start == 0 {
                assert_eq!(m.checkpoints.len(), 1);
                let f = m.checkpoints[0].features.as_ref().unwrap();
                assert_eq!(
                    (f.albedo.sums[0][0], f.normal.sums[0][0], f.emitted.sums[0][0]),
                    (21, 42, 63)
                );
                assert_eq!(f.albedo.passes, 4);
            }
        }
        assert_eq!(a.features().unwrap().emitted.sums[0][0], 3 * 61);
        assert_eq!(a.features().unwrap().albedo.passes, a.prefix_passes());
        a.add(5, part(50, 1), None, None).unwrap();
        assert!(a.features().is_none(), "a result without features ends them");
        assert!(Accumulator::empty(1, 1, 4).features().is_none());
    }

    /// One-pass results need no odd sample: their parity says which half they belong to.
    #[test]
    fn one_pass_results_estimate_noise_by_their_parity() {
        let mut a = Accumulator::empty(1, 1, 2);
        let mut points = Vec::new();
        // Even passes are 1, odd ones 3 (in one channel of three): the halves' means differ
        // by 2, so the estimate is 2² · We·Wo / W² / 3: 1/3 with equal halves, 8/27 with two
        // even passes and one odd.
        for pass in [1u64, 0, 2, 3] {
            let v = if pass % 2 == 0 { 1 } else { 3 };
            points.extend(a.add(pass, part(v << 24, 1), None, None).unwrap().noise);
        }
        assert_eq!(a.odd().unwrap().passes, 2);
        let want = [(2, 1.0 / 3.0), (3, 8.0 / 27.0), (4, 1.0 / 3.0)];
        assert_eq!(points.len(), want.len(), "{points:?}");
        for (got, want) in points.iter().zip(want) {
            assert_eq!(got.0, want.0);
            assert!((got.1 - want.1).abs() < 1e-12, "{points:?}");
        }
    }
}
