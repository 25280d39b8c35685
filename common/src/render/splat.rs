//! Splatting samples through a wide reconstruction filter, exactly and in parallel.
//!
//! A sample reaches the pixels up to [`Filter::reach`] rows and columns away, so rows are not
//! independent. Each task renders a band of rows and splats into its own buffer, which covers the
//! band and the rows the filter reaches beyond it; the buffers are then added into the film.
//! Every contribution is rounded to fixed point on its own, so the sums do not depend on how rows
//! were banded or in which order buffers were added.

use glam::Vec2;
use rayon::prelude::*;

use crate::color::Rgb;
use crate::film::{FIXED_SCALE, FilmSum, add_fixed, to_fixed};
use crate::scene::Scene;

/// Rows one task renders: enough to keep the filter's overlap between bands small.
const BAND_ROWS: u32 = 8;
/// Bands rendered before their buffers are added into the film: bounds the memory held in
/// buffers to a few times the film's rows of this many bands.
const BANDS_AT_ONCE: u32 = 64;

/// A band's splatted sums: rows `first_row ..` of the film (possibly starting above it).
struct BandBuffer {
    first_row: i64,
    sums: Vec<[i64; 3]>,
    weights: Vec<i64>,
    nonfinite: u64,
}

/// Adds one sample per pixel, each splatted over its neighbours with the scene's filter and
/// weighted as Mitsuba's film does; the film becomes weighted. `row(y)` gives row y's samples,
/// each with its offset within its pixel.
pub(super) fn add_filtered_rows(
    scene: &Scene,
    film: &mut FilmSum,
    row: impl Fn(u32) -> Vec<(Rgb, Vec2)> + Sync,
) {
    film.make_weighted();
    let (w, h) = (scene.width(), scene.height());
    let bands = h.div_ceil(BAND_ROWS);
    for group in (0..bands).step_by(BANDS_AT_ONCE as usize) {
        let buffers: Vec<BandBuffer> = (group..(group + BANDS_AT_ONCE).min(bands))
            .into_par_iter()
            .map(|band| splat_band(scene, band * BAND_ROWS, ((band + 1) * BAND_ROWS).min(h), &row))
            .collect();
        for b in buffers {
            film.nonfinite += b.nonfinite;
            for (i, (s, wt)) in b.sums.iter().zip(&b.weights).enumerate() {
                let y = b.first_row + (i / w as usize) as i64;
                if !(0..h as i64).contains(&y) {
                    continue;
                }
                let p = y as usize * w as usize + i % w as usize;
                add_fixed(&mut film.sums[p], s);
                film.weights[p] += wt;
            }
        }
    }
}

/// Renders rows `y0..y1` and splats them into a buffer of the rows they reach.
fn splat_band(scene: &Scene, y0: u32, y1: u32, row: &impl Fn(u32) -> Vec<(Rgb, Vec2)>) -> BandBuffer {
    let filter = scene.filter;
    let n = filter.reach() as i64;
    let w = scene.width() as i64;
    let first_row = y0 as i64 - n;
    let rows = (y1 - y0) as usize + 2 * n as usize;
    let mut buf = BandBuffer {
        first_row,
        sums: vec![[0; 3]; rows * w as usize],
        weights: vec![0; rows * w as usize],
        nonfinite: 0,
    };
    let (mut wx, mut wy) = (Vec::new(), Vec::new());
    for y in y0..y1 {
        for (x, (l, u)) in (0..).zip(row(y)) {
            if !l.is_finite() {
                buf.nonfinite += 1;
                continue;
            }
            filter.weights(u.x, &mut wx);
            filter.weights(u.y, &mut wy);
            for (dy, &fy) in wy.iter().enumerate() {
                if fy == 0.0 {
                    continue;
                }
                // Row y + dy - n of the film is row (y - y0) + dy of the buffer.
                let row = (y - y0) as usize + dy;
                for (dx, &fx) in wx.iter().enumerate() {
                    let px = x as i64 + dx as i64 - n;
                    let f = fx * fy;
                    // Pixels outside the image receive nothing, as in Mitsuba's film.
                    if f == 0.0 || !(0..w).contains(&px) {
                        continue;
                    }
                    let i = row * w as usize + px as usize;
                    let v = to_fixed(l * f).expect("finite sample, finite weight");
                    add_fixed(&mut buf.sums[i], &v);
                    buf.weights[i] += (f as f64 * FIXED_SCALE).round() as i64;
                }
            }
        }
    }
    buf
}

/// Contributions that land anywhere on the film (a particle tracer's), each spread over the
/// pixels the filter reaches with its weights normalised to one over those inside the image:
/// the film cannot weight pixels by the samples they received, as it does for one sample per
/// pixel, so each contribution keeps its own total. Kept as (pixel, fixed-point value) pairs,
/// added into the film in any order with the same result.
pub(super) struct Splats {
    pub(super) values: Vec<(u32, [i64; 3])>,
    pub(super) nonfinite: u64,
    wx: Vec<f32>,
    wy: Vec<f32>,
}

impl Splats {
    pub(super) fn new() -> Splats {
        Splats {
            values: Vec::new(),
            nonfinite: 0,
            wx: Vec::new(),
            wy: Vec::new(),
        }
    }

    /// Adds `l` at film position `at` (pixels from the top-left corner).
    pub(super) fn add(&mut self, scene: &Scene, at: Vec2, l: Rgb) {
        if !l.is_finite() {
            self.nonfinite += 1;
            return;
        }
        if l == Rgb::ZERO {
            return;
        }
        let (w, h) = (scene.width() as i64, scene.height() as i64);
        let n = scene.filter.reach() as i64;
        let (x, y) = (at.x.floor() as i64, at.y.floor() as i64);
        scene.filter.weights(at.x - x as f32, &mut self.wx);
        scene.filter.weights(at.y - y as f32, &mut self.wy);
        let inside = |d: usize, c: i64, len: i64| (0..len).contains(&(c + d as i64 - n));
        let sum_inside = |ws: &[f32], c: i64, len: i64| -> f32 {
            ws.iter()
                .enumerate()
                .filter(|(d, _)| inside(*d, c, len))
                .map(|(_, f)| f)
                .sum()
        };
        let total = sum_inside(&self.wx, x, w) * sum_inside(&self.wy, y, h);
        if total <= 0.0 {
            return;
        }
        for (dy, fy) in self.wy.iter().enumerate() {
            for (dx, fx) in self.wx.iter().enumerate() {
                let f = fx * fy;
                if f == 0.0 || !inside(dx, x, w) || !inside(dy, y, h) {
                    continue;
                }
                let p = (y + dy as i64 - n) * w + x + dx as i64 - n;
                let v = to_fixed(l * (f / total)).expect("finite sample, finite weight");
                self.values.push((p as u32, v));
            }
        }
    }
}
