//! Realistic batch results without rendering them, for the load generator.
//!
//! Why not zeros: how well a result compresses, and so how many bytes the coordinator takes
//! in, depends on its content. A batch of `n` passes of a real image sums to about `n` times
//! the image plus noise growing as √n; this module renders two real passes once, and makes the
//! sum of any `n` passes from their mean and spread: `n·m + √n·σ·z` per pixel and channel, with
//! `z` of unit variance, in the film's fixed point. The result is the real `PFBATCH2` encoding
//! the coordinator checks and decodes, with its odd passes' sample.

use photonfarm::film::{FIXED_SCALE, FilmSum};
use photonfarm::integrator::path::PathSettings;
use photonfarm::parity::{OddSums, sample_indices};
use photonfarm::protocol::encode_result;
use photonfarm::render::{Method, RenderSettings, Renderer};
use photonfarm::scene::Scene;

/// A rendered image's per-pass mean and spread, from which results of any pass count are made.
pub struct Synthetic {
    width: u32,
    height: u32,
    /// Per pixel and channel, in fixed-point units per pass.
    mean: Vec<[f32; 3]>,
    /// Per pixel and channel: the spread of one pass, same units.
    sigma: Vec<[f32; 3]>,
}

/// A small, fast generator (SplitMix64): the noise need not be good, only cheap and varied.
struct SplitMix(u64);

impl SplitMix {
    fn next(&mut self) -> u64 {
        self.0 = self.0.wrapping_add(0x9e37_79b9_7f4a_7c15);
        let mut z = self.0;
        z = (z ^ (z >> 30)).wrapping_mul(0xbf58_476d_1ce4_e5b9);
        z = (z ^ (z >> 27)).wrapping_mul(0x94d0_49bb_1331_11eb);
        z ^ (z >> 31)
    }

    /// About normal, unit variance: four uniforms summed (Irwin–Hall), centred and scaled.
    fn normal(&mut self) -> f32 {
        let r = self.next();
        let u = |k: u32| ((r >> (16 * k)) & 0xffff) as f32 / 65536.0;
        (u(0) + u(1) + u(2) + u(3) - 2.0) * 3f32.sqrt()
    }
}

impl Synthetic {
    /// Renders two passes of `scene` (path tracing) and keeps their mean and spread.
    pub fn render(scene: &Scene) -> Synthetic {
        let settings = RenderSettings {
            seed: 1,
            method: Method::Path(PathSettings {
                max_depth: None,
                rr_depth: 5,
            }),
        };
        let mut renderer = Renderer::new(scene, &settings);
        let (a, b) = (renderer.passes(0..1), renderer.passes(1..2));
        let (mean, sigma) = a
            .sums
            .iter()
            .zip(&b.sums)
            .map(|(x, y)| {
                let m = [0, 1, 2].map(|c| (x[c] + y[c]) as f32 / 2.0);
                // Two samples' spread: |x - y| / √2 estimates one sample's deviation.
                let s = [0, 1, 2].map(|c| (x[c] - y[c]).abs() as f32 / std::f32::consts::SQRT_2);
                (m, s)
            })
            .unzip();
        Synthetic {
            width: a.width,
            height: a.height,
            mean,
            sigma,
        }
    }

    /// A flat grey image with 50% noise, for tests (no scene needed).
    pub fn flat(width: u32, height: u32) -> Synthetic {
        let v = (0.5 * FIXED_SCALE) as f32;
        let n = width as usize * height as usize;
        Synthetic {
            width,
            height,
            mean: vec![[v; 3]; n],
            sigma: vec![[v / 2.0; 3]; n],
        }
    }

    /// The image size.
    pub fn size(&self) -> (u32, u32) {
        (self.width, self.height)
    }

    fn pixel(&self, i: usize, passes: u64, rng: &mut SplitMix) -> [i64; 3] {
        let n = passes as f32;
        let root = n.sqrt();
        [0, 1, 2].map(|c| (n * self.mean[i][c] + root * self.sigma[i][c] * rng.normal()).max(0.0) as i64)
    }

    /// The sum of `passes` passes (noise drawn from `seed`).
    pub fn sum(&self, passes: u64, seed: u64) -> FilmSum {
        let mut rng = SplitMix(seed);
        let mut film = FilmSum::new(self.width, self.height);
        for (i, s) in film.sums.iter_mut().enumerate() {
            *s = self.pixel(i, passes, &mut rng);
        }
        film.passes = passes;
        film
    }

    /// The sample of `odd` odd passes on the sampled pixels (see [`photonfarm::parity`]).
    pub fn odd(&self, odd: u64, seed: u64) -> OddSums {
        let mut rng = SplitMix(seed ^ 0x5555);
        OddSums {
            sums: sample_indices(self.width, self.height)
                .map(|i| self.pixel(i, odd, &mut rng))
                .collect(),
            weights: Vec::new(),
            passes: odd,
        }
    }

    /// The `PFBATCH2` encoding of a batch of `passes` passes of which `odd` are odd.
    pub fn encoded(&self, passes: u64, odd: u64, seed: u64) -> Vec<u8> {
        encode_result(&self.sum(passes, seed), &self.odd(odd, seed), None)
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn results_decode_and_scale_with_the_pass_count() {
        let s = Synthetic::flat(64, 32);
        let r = photonfarm::protocol::decode_result(&s.encoded(4, 2, 7), 64, 32).unwrap();
        assert_eq!((r.sum.width, r.sum.height, r.sum.passes), (64, 32, 4));
        assert_eq!(r.odd.unwrap().passes, 2);
        let mean = |f: &FilmSum| f.sums.iter().map(|p| p[0] as f64).sum::<f64>() / f.sums.len() as f64;
        let ratio = mean(&s.sum(8, 1)) / mean(&s.sum(2, 1));
        assert!((ratio - 4.0).abs() < 0.1, "{ratio}");
        assert_ne!(s.sum(2, 1), s.sum(2, 2), "noise differs by seed");
    }
}
