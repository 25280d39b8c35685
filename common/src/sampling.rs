//! Random streams keyed by (seed, iteration, index), and the warps that turn uniform numbers
//! into directions and points.
//!
//! Why keyed streams: an iteration must give the same numbers on any machine, with any thread
//! count and any batch split. Every generator is therefore created from its key alone, never
//! from entropy, thread ids or a shared generator.

use std::f32::consts::{FRAC_1_PI, FRAC_PI_2, FRAC_PI_4, PI};

use glam::{Vec2, Vec3A};
use rand_core::Rng;
use rand_pcg::Pcg32;

/// Which kind of path a stream drives. Keeps camera and photon streams of the same index apart.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Stream {
    /// Camera paths: the index is the pixel.
    Camera = 1,
    /// Light paths (photons): the index is the photon.
    Photon = 2,
    /// The denoiser's dense emission rays ([`crate::features::DENSE_SAMPLES`]): the index is
    /// the pixel.
    Emission = 3,
}

/// One path's random numbers.
pub struct Sampler {
    rng: Pcg32,
    /// For [`Sampler::sobol`]: the dimensions of one point of an Owen-scrambled Sobol sequence
    /// come first, then `rng`.
    sobol: Option<SobolPoint>,
}

/// One point of a scrambled Sobol sequence, read one dimension at a time.
struct SobolPoint {
    point: crate::sobol::Point,
    /// Next dimension to hand out.
    dim: u32,
    /// Dimensions `dim & !3` to `(dim & !3) + 3`, computed four at a time.
    four: [f32; 4],
}

/// Points of one scrambled Sobol sequence ([`crate::sobol`]). Longer runs continue in a sequence
/// of another scramble, block by block.
const SOBOL_POINTS: u64 = 1 << 32;

/// Dimensions taken from the Sobol point before the PCG stream takes over: the pixel, the lens
/// and the first bounce or two, where stratification pays. 16 gave the same RMSE as 256 at equal
/// samples, in less time (fog paths 23%, cbox paths about 7%; docs/sampling.md).
const SOBOL_DIMENSIONS: u32 = crate::sobol::DIMENSION_SETS * 4;

/// SplitMix64's finaliser: a bijective mix, so distinct keys never share a state.
pub fn mix64(mut z: u64) -> u64 {
    z = (z ^ (z >> 30)).wrapping_mul(0xbf58_476d_1ce4_e5b9);
    z = (z ^ (z >> 27)).wrapping_mul(0x94d0_49bb_1331_11eb);
    z ^ (z >> 31)
}

impl Sampler {
    /// The stream for one (seed, kind, iteration, index): the only way to make a sampler.
    pub fn new(seed: u64, stream: Stream, iteration: u64, index: u64) -> Self {
        let a = mix64(seed ^ mix64(stream as u64));
        let b = mix64(a ^ iteration);
        let state = mix64(b ^ index.rotate_left(17));
        let inc = mix64(state ^ 0x9e37_79b9_7f4a_7c15);
        Sampler {
            rng: Pcg32::new(state, inc),
            sobol: None,
        }
    }

    /// Sample `sample` of the low-discrepancy sequence `key` (of kind `stream`, under `seed`):
    /// its first [`SOBOL_DIMENSIONS`] numbers are the dimensions of point `sample` of an
    /// Owen-scrambled Sobol sequence (Burley's hash-based scrambling, [`crate::sobol`]), the
    /// rest come from [`Sampler::new`]'s stream for the same key.
    ///
    /// Why: the samples of one sequence fill the space of random numbers evenly, so pixels that
    /// take their passes as samples of one sequence, or light paths of every pass, converge
    /// faster than with independent numbers, and stay unbiased. A sample depends only on its key
    /// and index, so any machine renders any pass or photon to the same bits.
    pub fn sobol(seed: u64, stream: Stream, key: u64, sample: u64) -> Self {
        let mut s = Sampler::new(seed, stream, sample, key);
        let block = sample / SOBOL_POINTS;
        let scramble = mix64(mix64(seed ^ mix64(stream as u64 + 16)) ^ key.rotate_left(29) ^ block);
        s.sobol = Some(SobolPoint {
            // The scramble makes sequences of different keys independent.
            point: crate::sobol::Point::new(
                (sample % SOBOL_POINTS) as u32,
                (scramble >> 32) as u32 ^ scramble as u32,
            ),
            dim: 0,
            four: [0.0; 4],
        });
        s
    }

    /// Light path `index` of the `count` of pass `pass` (particle tracer, hybrid): the light
    /// paths of all even passes are the points of one sequence, and those of all odd passes of
    /// another.
    ///
    /// Why across passes: each pass's own sequence covers the light's directions evenly, but
    /// leaves its gaps independent of the other passes'; as points of one sequence the passes fill
    /// each other's gaps, which halved the particle tracer's RMSE at equal passes on the caustic
    /// (docs/sampling.md). Why two: the coordinator's noise estimate compares even passes with
    /// odd ones, which must be independent, as for camera passes. SPPM's photons keep a sequence
    /// per iteration: across iterations they gained 6% on the caustic and skewed photon beams'
    /// means in fog low (the same docs).
    pub fn across_passes(seed: u64, stream: Stream, pass: u64, count: u64, index: u64) -> Self {
        debug_assert!(index < count, "light path {index} of {count}");
        Sampler::sobol(seed, stream, pass % 2, pass / 2 * count + index)
    }

    /// A uniform number in [0, 1).
    #[inline]
    pub fn next_1d(&mut self) -> f32 {
        if let Some(p) = &mut self.sobol
            && p.dim < SOBOL_DIMENSIONS
        {
            if p.dim % 4 == 0 {
                p.four = p.point.four(p.dim / 4);
            }
            let x = p.four[(p.dim % 4) as usize];
            p.dim += 1;
            return x;
        }
        // 24 bits: every value is exactly representable and strictly below 1.
        (self.rng.next_u32() >> 8) as f32 * (1.0 / 16_777_216.0)
    }

    /// Two uniform numbers in [0, 1).
    #[inline]
    pub fn next_2d(&mut self) -> Vec2 {
        let x = self.next_1d();
        Vec2::new(x, self.next_1d())
    }
}

/// Cosine-weighted direction on the +z hemisphere.
pub fn square_to_cosine_hemisphere(u: Vec2) -> Vec3A {
    let p = square_to_uniform_disk_concentric(u);
    let z = (1.0 - p.length_squared()).max(0.0).sqrt();
    Vec3A::new(p.x, p.y, z)
}

/// Density of [`square_to_cosine_hemisphere`] per unit solid angle.
pub fn square_to_cosine_hemisphere_pdf(v: Vec3A) -> f32 {
    FRAC_1_PI * v.z.max(0.0)
}

/// Shirley and Chiu's concentric map: low distortion, so stratified numbers stay stratified.
pub fn square_to_uniform_disk_concentric(u: Vec2) -> Vec2 {
    let o = 2.0 * u - Vec2::ONE;
    if o.x == 0.0 && o.y == 0.0 {
        return Vec2::ZERO;
    }
    let (r, theta) = if o.x.abs() > o.y.abs() {
        (o.x, FRAC_PI_4 * (o.y / o.x))
    } else {
        (o.y, FRAC_PI_2 - FRAC_PI_4 * (o.x / o.y))
    };
    let (sin_theta, cos_theta) = libm::sincosf(theta);
    Vec2::new(r * cos_theta, r * sin_theta)
}

/// Uniform direction on the unit sphere.
pub fn square_to_uniform_sphere(u: Vec2) -> Vec3A {
    let z = 1.0 - 2.0 * u.x;
    let r = (1.0 - z * z).max(0.0).sqrt();
    let phi = 2.0 * PI * u.y;
    let (sin_phi, cos_phi) = libm::sincosf(phi);
    Vec3A::new(r * cos_phi, r * sin_phi, z)
}

/// Uniform direction in the cone around +z with the given cosine of its half-angle.
pub fn square_to_uniform_cone(u: Vec2, cos_cutoff: f32) -> Vec3A {
    let cos_theta = 1.0 - u.x * (1.0 - cos_cutoff);
    let sin_theta = (1.0 - cos_theta * cos_theta).max(0.0).sqrt();
    let phi = 2.0 * PI * u.y;
    let (sin_phi, cos_phi) = libm::sincosf(phi);
    Vec3A::new(sin_theta * cos_phi, sin_theta * sin_phi, cos_theta)
}

/// Density of [`square_to_uniform_cone`] per unit solid angle.
pub fn square_to_uniform_cone_pdf(cos_cutoff: f32) -> f32 {
    1.0 / (2.0 * PI * (1.0 - cos_cutoff))
}

/// Uniform barycentric coordinates (b1, b2) on a triangle.
pub fn square_to_uniform_triangle(u: Vec2) -> Vec2 {
    let t = (1.0 - u.x).sqrt();
    Vec2::new(1.0 - t, u.y * t)
}

/// Kulla and Fajardo's equiangular sampling of a distance t in [0, t_max) (t_max may be
/// infinite) along a unit ray that passes at distance `h` from a point, nearest to it at
/// t = `delta`: the density follows 1 / (h² + (t − delta)²), the point's inverse-square
/// falloff, so that light from a point source in a medium has finite variance. Returns the
/// distance and its density; None when the ray passes through the point (h = 0).
pub fn sample_equiangular(delta: f32, h: f32, t_max: f32, u: f32) -> Option<(f32, f32)> {
    // Written to refuse NaN too.
    if h.is_nan() || h <= 1e-7 || t_max.is_nan() || t_max <= 0.0 {
        return None;
    }
    let theta_a = libm::atanf(-delta / h);
    let theta_b = if t_max.is_finite() {
        libm::atanf((t_max - delta) / h)
    } else {
        FRAC_PI_2
    };
    let span = theta_b - theta_a;
    if span.is_nan() || span <= 0.0 {
        return None;
    }
    let x = h * libm::tanf(theta_a + u * span);
    let t = (delta + x).clamp(0.0, t_max.next_down());
    Some((t, h / (span * (h * h + x * x))))
}

/// A discrete distribution, sampled by inverting its cumulative sum.
///
/// Why a guide table: an environment map keeps one distribution per row of 2048 columns, 16 MiB
/// in all, and a binary search over a row missed the cache at nearly every step; `perf` put 38%
/// of a living room's path tracing in the envmap's sample. The guide (Chen and Asau's
/// indexed search) narrows each search to the entries of one `1/guide.len()` of the unit
/// interval, a cache line or two, and always returns the entry the full search would. Each
/// entry's cumulative sum and probability lie side by side, so that a sample reads one or two
/// lines beyond the guide's.
#[derive(Clone, Debug, Default)]
pub struct Distribution1D {
    entries: Vec<Entry>,
    /// `guide[k]`: the first entry whose cumulative sum exceeds k / (guide.len() − 1).
    guide: Vec<u32>,
    total: f32,
}

/// One entry of a [`Distribution1D`].
#[derive(Clone, Copy, Debug, Default)]
struct Entry {
    /// The sum of the probabilities up to and including this entry's.
    cdf: f32,
    pmf: f32,
}

/// The full search: the first of `entries` whose cumulative sum exceeds `u`, or the last.
fn first_above(entries: &[Entry], u: f32) -> usize {
    entries.partition_point(|e| e.cdf <= u).min(entries.len() - 1)
}

/// Entries per guide bucket, on average: a 64-byte cache line of the cumulative sums.
const GUIDE_SPAN: usize = 16;

impl Distribution1D {
    /// From non-negative weights. All-zero weights give an empty distribution.
    pub fn new(weights: &[f32]) -> Self {
        let total: f64 = weights.iter().map(|&w| w.max(0.0) as f64).sum();
        if total <= 0.0 {
            return Distribution1D::default();
        }
        let mut acc = 0.0f64;
        let mut entries: Vec<Entry> = weights
            .iter()
            .map(|&w| {
                acc += w.max(0.0) as f64;
                Entry {
                    cdf: (acc / total) as f32,
                    pmf: (w.max(0.0) as f64 / total) as f32,
                }
            })
            .collect();
        if let Some(last) = entries.last_mut() {
            last.cdf = 1.0;
        }
        let buckets = entries.len().div_ceil(GUIDE_SPAN);
        let guide = (0..=buckets)
            .map(|k| first_above(&entries, k as f32 / buckets as f32) as u32)
            .collect();
        Distribution1D {
            entries,
            guide,
            total: total as f32,
        }
    }

    /// The guide's bounds for `u`'s bucket (the first of [`Distribution1D::find`]'s two
    /// dependent loads); none for a distribution short enough to scan whole.
    #[inline]
    fn bounds(&self, u: f32) -> Option<(usize, usize)> {
        if self.entries.len() <= GUIDE_SPAN {
            return None;
        }
        let buckets = self.guide.len() - 1;
        let k = ((u * buckets as f32) as usize).min(buckets - 1);
        Some((self.guide[k] as usize, self.guide[k + 1] as usize))
    }

    /// The first entry whose cumulative sum exceeds `u` (the last if none does), searched
    /// between the guide's bounds for `u`'s bucket, or over all entries where rounding put
    /// `u` outside them.
    #[inline]
    fn find(&self, u: f32) -> usize {
        self.find_within(u, self.bounds(u))
    }

    /// [`Distribution1D::find`] with the guide's bounds already read.
    #[inline]
    fn find_within(&self, u: f32, bounds: Option<(usize, usize)>) -> usize {
        let e = &self.entries;
        let Some((lo, hi)) = bounds else {
            // A line of sums (a light's few triangles, a scene's few lights): the count of
            // those at or below `u` is the full search's answer, as the sums never decrease,
            // without its branches, which `u` mispredicts half the time (the cbox's light pick
            // was 9% of the lane engine's time).
            return e
                .iter()
                .map(|x| usize::from(x.cdf <= u))
                .sum::<usize>()
                .min(e.len() - 1);
        };
        let last = e.len() - 1;
        let inside = (lo == 0 || e[lo - 1].cdf <= u) && (hi == last || e[hi].cdf > u);
        if inside {
            lo + e[lo..hi].partition_point(|x| x.cdf <= u)
        } else {
            first_above(e, u)
        }
    }

    /// Whether there is anything to sample.
    pub fn is_empty(&self) -> bool {
        self.entries.is_empty()
    }

    /// Sum of the weights.
    pub fn total(&self) -> f32 {
        self.total
    }

    /// Probability of entry `i`.
    pub fn pmf(&self, i: usize) -> f32 {
        self.entries.get(i).map_or(0.0, |e| e.pmf)
    }

    /// Picks an entry; returns it, its probability, and `u` rescaled to [0, 1) for reuse.
    #[inline]
    pub fn sample(&self, u: f32) -> (usize, f32, f32) {
        self.sample_found(u, self.find(u))
    }

    /// [`Distribution1D::sample`] of `dists[l]` at `u[l]`, lane after lane but step by step:
    /// every lane's guide bounds are read before any lane's entries, so that the loads of
    /// different lanes are in flight together. The environment's column tables (16 MB for a
    /// 2048×1024 map) miss the cache at both steps; one sample after the other, each waits for
    /// its two misses in turn. The same answers as [`Distribution1D::sample`].
    #[inline]
    pub fn sample_each<const N: usize>(dists: [&Distribution1D; N], u: [f32; N]) -> [(usize, f32, f32); N] {
        let bounds: [Option<(usize, usize)>; N] = std::array::from_fn(|l| dists[l].bounds(u[l]));
        let found: [usize; N] = std::array::from_fn(|l| dists[l].find_within(u[l], bounds[l]));
        std::array::from_fn(|l| dists[l].sample_found(u[l], found[l]))
    }

    /// The sample of `u` once its entry `i` is found.
    #[inline]
    fn sample_found(&self, u: f32, i: usize) -> (usize, f32, f32) {
        let lo = if i == 0 { 0.0 } else { self.entries[i - 1].cdf };
        let p = self.entries[i].pmf;
        let rescaled = if p > 0.0 {
            ((u - lo) / p).clamp(0.0, 1.0 - f32::EPSILON)
        } else {
            0.0
        };
        (i, p, rescaled)
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// The light paths of four even passes together put one direction (the first two numbers)
    /// in every cell of each 2^-a × 2^-b grid of 4 × 256 cells: the passes fill each other's
    /// gaps. The odd passes' sequence is another: their first paths differ.
    #[test]
    fn light_paths_of_even_passes_are_one_net() {
        let (count, m) = (256u64, 10);
        let first_two = |pass, i| {
            let mut s = Sampler::across_passes(5, Stream::Photon, pass, count, i);
            (s.next_1d(), s.next_1d())
        };
        for a in 0..=m {
            let mut seen = vec![false; 1 << m];
            for pass in [0, 2, 4, 6] {
                for i in 0..count {
                    let (x, y) = first_two(pass, i);
                    let cell =
                        ((x * (1 << a) as f32) as usize) << (m - a) | (y * (1 << (m - a)) as f32) as usize;
                    assert!(!seen[cell], "{a}: two light paths in cell {cell}");
                    seen[cell] = true;
                }
            }
        }
        assert_ne!(first_two(0, 0), first_two(1, 0));
    }

    /// The guided search picks the entry the full binary search picks, for every number near
    /// each cumulative sum and bucket edge, on weights with runs of zeros, spikes and tiny
    /// entries (a sky with a sun).
    #[test]
    fn guided_sampling_picks_what_a_full_search_picks() {
        let mut r = Sampler::new(3, Stream::Camera, 0, 0);
        for n in [1usize, 2, 15, 16, 17, 100, 2048] {
            let weights: Vec<f32> = (0..n)
                .map(|i| match i % 7 {
                    0 | 1 => 0.0,
                    2 => 1e4 * r.next_1d(),
                    3 => 1e-6,
                    _ => r.next_1d(),
                })
                .collect();
            let d = Distribution1D::new(&weights);
            if d.is_empty() {
                continue;
            }
            let mut us: Vec<f32> = (0..4000).map(|_| r.next_1d()).collect();
            let cdf: Vec<f32> = d.entries.iter().map(|e| e.cdf).collect();
            for &c in cdf.iter().chain(&[0.0, 0.5, 1.0 - f32::EPSILON]) {
                us.extend(
                    [c, c.next_down(), c.next_up()]
                        .into_iter()
                        .filter(|u| (0.0..1.0).contains(u)),
                );
            }
            let buckets = d.guide.len() - 1;
            for k in 0..=buckets {
                let e = k as f32 / buckets as f32;
                us.extend(
                    [e, e.next_down(), e.next_up()]
                        .into_iter()
                        .filter(|u| (0.0..1.0).contains(u)),
                );
            }
            // Numbers no sampler draws, which must not panic or pick otherwise either.
            us.extend([f32::NAN, -1.0, -0.0, 1.0, 2.0, f32::INFINITY]);
            for u in &us {
                let full = cdf.partition_point(|&c| c <= *u).min(cdf.len() - 1);
                assert_eq!(d.find(*u), full, "{n} entries, u = {u:e}");
            }
            // Eight at a time in lock step: the same picks, probabilities and rescaled bits.
            let bits = |(i, p, v): (usize, f32, f32)| (i, p.to_bits(), v.to_bits());
            for chunk in us.chunks(8) {
                let u: [f32; 8] = std::array::from_fn(|l| chunk[l % chunk.len()]);
                let each = Distribution1D::sample_each([&d; 8], u);
                for l in 0..8 {
                    assert_eq!(bits(each[l]), bits(d.sample(u[l])), "{n} entries, u = {:e}", u[l]);
                }
            }
        }
    }

    #[test]
    fn equiangular_distances_are_sampled_by_their_density() {
        // E[g(t) / pdf(t)] = ∫₀^T g: with g = 1 the segment's length, and with g = e^{−t} its
        // integral, for a point beside, ahead of and behind the segment.
        let mut s = Sampler::new(9, Stream::Photon, 0, 0);
        for (delta, h, t_max) in [
            (1.0f32, 0.2f32, 3.0f32),
            (-0.5, 0.05, 2.0),
            (5.0, 1.0, 2.0),
            (0.5, 0.3, f32::INFINITY),
        ] {
            let n = 400_000;
            let (mut len, mut expo) = (0.0f64, 0.0f64);
            for _ in 0..n {
                let (t, pdf) = sample_equiangular(delta, h, t_max, s.next_1d()).unwrap();
                assert!((0.0..t_max).contains(&t));
                len += 1.0 / pdf as f64;
                expo += libm::exp(-t as f64) / pdf as f64;
            }
            let expect_expo = 1.0 - libm::exp(-t_max as f64);
            assert!(
                (expo / n as f64 / expect_expo - 1.0).abs() < 0.01,
                "{delta} {h} {t_max}: {}",
                expo / n as f64
            );
            if t_max.is_finite() {
                assert!(
                    (len / n as f64 / t_max as f64 - 1.0).abs() < 0.01,
                    "{delta} {h}: {}",
                    len / n as f64
                );
            }
        }
        assert!(sample_equiangular(1.0, 0.0, 2.0, 0.5).is_none());
    }

    #[test]
    fn streams_depend_on_every_key_part_only() {
        let draw = |s, st, i, j| Sampler::new(s, st, i, j).next_1d();
        assert_eq!(draw(1, Stream::Camera, 2, 3), draw(1, Stream::Camera, 2, 3));
        assert_ne!(draw(1, Stream::Camera, 2, 3), draw(1, Stream::Camera, 2, 4));
        assert_ne!(draw(1, Stream::Camera, 2, 3), draw(1, Stream::Camera, 3, 3));
        assert_ne!(draw(1, Stream::Camera, 2, 3), draw(2, Stream::Camera, 2, 3));
        assert_ne!(draw(1, Stream::Camera, 2, 3), draw(1, Stream::Photon, 2, 3));
    }

    #[test]
    fn uniform_numbers_have_the_right_mean_and_range() {
        let mut s = Sampler::new(7, Stream::Camera, 0, 0);
        let n = 100_000;
        let mut sum = 0.0f64;
        for _ in 0..n {
            let x = s.next_1d();
            assert!((0.0..1.0).contains(&x));
            sum += x as f64;
        }
        assert!((sum / n as f64 - 0.5).abs() < 0.005);
    }

    #[test]
    fn distribution_samples_in_proportion() {
        let d = Distribution1D::new(&[1.0, 0.0, 3.0]);
        let mut counts = [0usize; 3];
        let n = 40_000;
        for k in 0..n {
            let (i, p, r) = d.sample((k as f32 + 0.5) / n as f32);
            assert!((0.0..1.0).contains(&r));
            assert!(p > 0.0);
            counts[i] += 1;
        }
        assert_eq!(counts[1], 0);
        assert!((counts[0] as f32 / n as f32 - 0.25).abs() < 0.001);
    }
}
