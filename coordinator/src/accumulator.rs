//! Adds batch results up in pass order, so that the image at every checkpoint is exactly the
//! image of passes [0, N): byte-identical whichever workers rendered them and in whatever order
//! they arrived.

use std::collections::BTreeMap;

use photonfarm::film::{FilmError, FilmSum};

/// The running sum of a job.
#[derive(Debug)]
pub struct Accumulator {
    /// Passes [0, prefix.passes), summed.
    prefix: FilmSum,
    /// Results that arrived ahead of a gap, by first pass.
    pending: BTreeMap<u64, FilmSum>,
    /// Checkpoints fall on multiples of this.
    checkpoint_every: u64,
}

impl Accumulator {
    /// Starts from `prefix` (passes [0, prefix.passes) already summed).
    pub fn new(prefix: FilmSum, checkpoint_every: u64) -> Accumulator {
        Accumulator {
            prefix,
            pending: BTreeMap::new(),
            checkpoint_every: checkpoint_every.max(1),
        }
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

    /// Adds the result of passes [start, start + sum.passes). Returns the pass counts at which
    /// the prefix reached a checkpoint (a multiple of the interval) while merging, each with a
    /// copy of the prefix at that moment, and whether the prefix moved.
    pub fn add(&mut self, start: u64, sum: FilmSum) -> Result<(Vec<FilmSum>, bool), FilmError> {
        if (sum.width, sum.height) != (self.prefix.width, self.prefix.height) {
            return Err(FilmError::SizeMismatch(
                sum.width,
                sum.height,
                self.prefix.width,
                self.prefix.height,
            ));
        }
        if start < self.prefix.passes {
            // Already merged. Cannot happen: a lease restored after a restart covers only
            // passes not yet stored; this guards the invariant.
            return Ok((Vec::new(), false));
        }
        self.pending.insert(start, sum);
        let mut checkpoints = Vec::new();
        let mut moved = false;
        while let Some(next) = self.pending.remove(&self.prefix.passes) {
            self.prefix.add(&next)?;
            moved = true;
            if self.prefix.passes.is_multiple_of(self.checkpoint_every) {
                checkpoints.push(self.prefix.clone());
            }
        }
        Ok((checkpoints, moved))
    }

    /// Ranges of results held ahead of a gap.
    pub fn pending_ranges(&self) -> Vec<(u64, u64)> {
        self.pending.iter().map(|(&s, f)| (s, s + f.passes)).collect()
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
        let mut a = Accumulator::new(FilmSum::new(1, 1), 4);
        let (cp, moved) = a.add(2, part(3, 2)).unwrap();
        assert!(cp.is_empty() && !moved);
        let (cp, moved) = a.add(0, part(1, 2)).unwrap();
        assert!(moved);
        assert_eq!(cp.len(), 1);
        assert_eq!(cp[0].passes, 4);
        assert_eq!(cp[0].sums[0][0], 4);
        let (cp, _) = a.add(4, part(5, 3)).unwrap();
        assert!(cp.is_empty());
        assert_eq!(a.prefix_passes(), 7);
        assert!(a.add(0, FilmSum::new(2, 1)).is_err());
    }
}
