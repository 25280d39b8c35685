//! The odd passes' sums on a sample of pixels, kept apart from a job's full sum so the
//! coordinator can estimate the image's remaining noise without a reference.
//!
//! Why: passes are independent samples, so the mean of the even passes and the mean of the odd
//! passes are two independent estimates of the same image. Their squared difference, scaled, is
//! an unbiased estimate of the variance of the full image (docs/api.md, "Noise without a
//! reference", derives the scaling).
//!
//! Why a sample of pixels: the estimate is a mean over pixels, and 16,384 pixels pin it down
//! to about 1%, so a result carries the odd passes of at most about that many pixels (a regular
//! grid) beside its exact full sum: under 1% more bytes at 1920×1080. The full sum is sent and
//! added exactly as before, so the image's bytes do not depend on any of this; the even
//! passes' sum is the full sum minus the odd one.

use serde::{Deserialize, Serialize};

use crate::film::{FIXED_SCALE, FilmSum, add_fixed};

/// The sample aims at this many pixels (fewer on a grid that does not divide the image).
pub const SAMPLE_PIXELS: u64 = 16_384;

/// Distance in pixels between two sampled pixels along each axis: pixels whose x and y are both
/// multiples of it are sampled. Every pixel of an image up to 16,384 pixels.
pub fn stride(width: u32, height: u32) -> u32 {
    let pixels = width as f64 * height as f64;
    ((pixels / SAMPLE_PIXELS as f64).sqrt().floor() as u32).max(1)
}

/// Indices (row by row) of the sampled pixels of a `width` × `height` image.
pub fn sample_indices(width: u32, height: u32) -> impl Iterator<Item = usize> {
    let s = stride(width, height) as usize;
    let (w, h) = (width as usize, height as usize);
    (0..h)
        .step_by(s)
        .flat_map(move |y| (0..w).step_by(s).map(move |x| y * w + x))
}

/// How many pixels are sampled.
pub fn sample_len(width: u32, height: u32) -> usize {
    let s = stride(width, height) as u64;
    (width as u64).div_ceil(s) as usize * (height as u64).div_ceil(s) as usize
}

/// Sums of the odd passes of a range, on the sampled pixels only.
#[derive(Clone, Debug, PartialEq, Eq, Serialize, Deserialize)]
pub struct OddSums {
    /// Per sampled pixel, per channel: as [`FilmSum::sums`].
    pub sums: Vec<[i64; 3]>,
    /// Per sampled pixel: as [`FilmSum::weights`] (empty for a box filter).
    pub weights: Vec<i64>,
    /// Odd passes summed.
    pub passes: u64,
}

impl OddSums {
    /// No odd pass yet.
    pub fn empty(width: u32, height: u32) -> OddSums {
        OddSums {
            sums: vec![[0; 3]; sample_len(width, height)],
            weights: Vec::new(),
            passes: 0,
        }
    }

    /// A result's odd passes' sample: as sent, or, for a one-pass result of pass `start` sent
    /// without it (an older worker), known from the pass's parity.
    pub fn sent_or_known(odd: Option<OddSums>, start: u64, sum: &FilmSum) -> Option<OddSums> {
        odd.or_else(|| match sum.passes {
            1 if start % 2 == 1 => Some(OddSums::of(sum)),
            1 => Some(OddSums::empty(sum.width, sum.height)),
            _ => None,
        })
    }

    /// The sampled pixels of `film`, every pass of which is odd.
    pub fn of(film: &FilmSum) -> OddSums {
        let idx = || sample_indices(film.width, film.height);
        OddSums {
            sums: idx().map(|i| film.sums[i]).collect(),
            weights: if film.weights.is_empty() {
                Vec::new()
            } else {
                idx().map(|i| film.weights[i]).collect()
            },
            passes: film.passes,
        }
    }

    /// Whether this fits a `width` × `height` image summed over `passes` passes.
    pub fn check(&self, width: u32, height: u32, passes: u64) -> Result<(), String> {
        let n = sample_len(width, height);
        if self.sums.len() != n || !(self.weights.is_empty() || self.weights.len() == n) {
            return Err(format!(
                "{} odd-pass sums and {} weights for the {n} sampled pixels of a {width}x{height} image",
                self.sums.len(),
                self.weights.len()
            ));
        }
        if self.passes > passes {
            return Err(format!("{} odd passes in {passes} passes", self.passes));
        }
        Ok(())
    }

    /// Adds the odd passes of another range (of the same image).
    pub fn add(&mut self, other: &OddSums) {
        for (a, b) in self.sums.iter_mut().zip(&other.sums) {
            add_fixed(a, b);
        }
        if !other.weights.is_empty() || !self.weights.is_empty() {
            let (mine, theirs) = (box_weight(self.passes), box_weight(other.passes));
            if self.weights.is_empty() {
                self.weights = vec![mine; self.sums.len()];
            }
            for (i, a) in self.weights.iter_mut().enumerate() {
                *a = a.saturating_add(other.weights.get(i).copied().unwrap_or(theirs));
            }
        }
        self.passes += other.passes;
    }
}

/// The weight of a box-filtered pixel summed over `passes` passes (as the film counts it).
fn box_weight(passes: u64) -> i64 {
    (passes as f64 * FIXED_SCALE) as i64
}

/// The estimated variance of the image `full` (mean over the sampled pixels and the three
/// channels), from its odd passes `odd`: an estimate of its expected squared error against the
/// converged image. None until both halves hold a pass.
///
/// Per pixel, with even and odd weights `We`, `Wo` (pass counts for a box filter) and total
/// `W = We + Wo`, the image is `(We·me + Wo·mo) / W`; with per-pass variance σ², `Var(me - mo)
/// = σ²·W / (We·Wo)` and `Var(image) = σ² / W`, so `Var(image) = E[(me - mo)²]·We·Wo / W²`:
/// a quarter of the squared difference when the halves are equal.
pub fn noise(full: &FilmSum, odd: &OddSums) -> Option<f64> {
    if odd.passes == 0 || odd.passes >= full.passes {
        return None;
    }
    let (mut total, mut count) = (0.0f64, 0u64);
    for (k, i) in sample_indices(full.width, full.height).enumerate() {
        let (Some(s), Some(o)) = (full.sums.get(i), odd.sums.get(k)) else {
            return None;
        };
        let w = full
            .weights
            .get(i)
            .copied()
            .unwrap_or_else(|| box_weight(full.passes)) as f64;
        let wo = odd
            .weights
            .get(k)
            .copied()
            .unwrap_or_else(|| box_weight(odd.passes)) as f64;
        let we = w - wo;
        if we <= 0.0 || wo <= 0.0 {
            // A pixel no sample of one half reached: nothing to compare.
            continue;
        }
        for c in 0..3 {
            let mo = o[c] as f64 / wo;
            let me = (s[c] - o[c]) as f64 / we;
            total += (me - mo) * (me - mo) * we * wo / (w * w);
        }
        count += 3;
    }
    (count > 0).then(|| total / count as f64)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn sample_covers_small_images_whole_and_large_ones_sparsely() {
        assert_eq!(stride(128, 128), 1);
        assert_eq!(sample_len(128, 128), 128 * 128);
        assert_eq!(stride(256, 256), 2);
        assert_eq!(sample_len(1920, 1080), 175 * 99);
        assert_eq!(sample_indices(1920, 1080).count(), sample_len(1920, 1080));
        assert_eq!(sample_indices(3, 2).collect::<Vec<_>>(), vec![0, 1, 2, 3, 4, 5]);
    }

    /// Passes of constant value per pass (even passes 1, odd passes 3): the halves differ by 2
    /// everywhere, so the estimate is 2² / 4 = 1.
    #[test]
    fn noise_of_two_different_halves() {
        let mut full = FilmSum::new(2, 2);
        let mut odd = OddSums::empty(2, 2);
        for pass in 0..4u64 {
            let mut part = FilmSum::new(2, 2);
            let v = if pass % 2 == 0 { 1 } else { 3 };
            part.sums.iter_mut().for_each(|s| *s = [v << 24; 3]);
            part.passes = 1;
            full.add(&part).unwrap();
            if pass % 2 == 1 {
                odd.add(&OddSums::of(&part));
            }
        }
        assert_eq!(odd.passes, 2);
        assert!((noise(&full, &odd).unwrap() - 1.0).abs() < 1e-12);
        assert!(noise(&full, &OddSums::empty(2, 2)).is_none());
        assert!(odd.check(2, 2, 4).is_ok());
        assert!(odd.check(3, 2, 4).is_err());
    }
}
