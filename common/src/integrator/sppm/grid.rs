//! The hashed uniform grid both photon maps bucket photons in: cells at least twice the
//! iteration's radius wide, so that a sphere of that radius overlaps at most 2 × 2 × 2 of them.

use glam::Vec3A;

use crate::geometry::Ray;

/// The bucket of cell `c` in a table of `mask + 1` buckets.
#[inline]
pub fn hash_cell(c: [i32; 3], mask: usize) -> usize {
    let h = (c[0] as u32).wrapping_mul(73_856_093)
        ^ (c[1] as u32).wrapping_mul(19_349_663)
        ^ (c[2] as u32).wrapping_mul(83_492_791);
    (h as usize) & mask
}

/// The cell holding `p`.
#[inline]
pub fn cell_of(p: Vec3A, inv_cell: f32) -> [i32; 3] {
    let c = (p * inv_cell).floor();
    [c.x as i32, c.y as i32, c.z as i32]
}

/// The distinct buckets of the cells that the sphere of radius `r` at `p` overlaps, into
/// `out`; returns how many. Distinct cells may share a bucket, and a bucket must be visited
/// (or filled) once.
#[inline]
pub fn buckets_of_sphere(p: Vec3A, r: f32, inv_cell: f32, mask: usize, out: &mut [usize; 8]) -> usize {
    buckets_of_box(p - Vec3A::splat(r), p + Vec3A::splat(r), inv_cell, mask, 2, out)
}

/// The distinct buckets of the cells that the box [lo, hi] overlaps, at most `per_axis` cells
/// per axis (the caller knows its box's width against the cells'), into `out`, which holds
/// `per_axis`³; returns how many.
#[inline]
pub fn buckets_of_box(
    lo: Vec3A,
    hi: Vec3A,
    inv_cell: f32,
    mask: usize,
    per_axis: i32,
    out: &mut [usize],
) -> usize {
    let per_axis = per_axis - 1;
    let lo = cell_of(lo, inv_cell);
    let hi = cell_of(hi, inv_cell);
    let mut n = 0;
    for x in lo[0]..=hi[0].min(lo[0] + per_axis) {
        for y in lo[1]..=hi[1].min(lo[1] + per_axis) {
            for z in lo[2]..=hi[2].min(lo[2] + per_axis) {
                let b = hash_cell([x, y, z], mask);
                if !out[..n].contains(&b) {
                    out[n] = b;
                    n += 1;
                }
            }
        }
    }
    n
}

/// Items grouped by bucket, by one counting sort: the build both photon maps share.
#[derive(Debug, Default)]
pub struct Buckets {
    /// Bucket b's items are `items[starts[b]..starts[b + 1]]`.
    starts: Vec<u32>,
    /// Scratch: each bucket's next write position (kept between builds, so memory stays flat).
    cursor: Vec<u32>,
}

impl Buckets {
    /// Sorts the (bucket, item) pairs that `pairs` yields into `items` by bucket, keeping their
    /// order within a bucket (so queries visit them in a deterministic order). `pairs` is called
    /// twice, to count and to fill, and must yield the same pairs both times.
    pub fn sort<T: Copy + Default>(
        &mut self,
        buckets: usize,
        pairs: impl Fn(&mut dyn FnMut(usize, T)),
        items: &mut Vec<T>,
    ) {
        self.starts.clear();
        self.starts.resize(buckets + 1, 0);
        pairs(&mut |b, _| self.starts[b + 1] += 1);
        for i in 0..buckets {
            self.starts[i + 1] += self.starts[i];
        }
        items.clear();
        items.resize(self.starts[buckets] as usize, T::default());
        self.cursor.clear();
        self.cursor.extend_from_slice(&self.starts[..buckets]);
        pairs(&mut |b, item| {
            items[self.cursor[b] as usize] = item;
            self.cursor[b] += 1;
        });
    }

    /// Where bucket `b`'s items are.
    #[inline]
    pub fn range(&self, b: usize) -> std::ops::Range<usize> {
        self.starts[b] as usize..self.starts[b + 1] as usize
    }
}

/// The part of the segment [0, t_max] inside the box, if any.
pub fn clip_to_box(ray: &Ray, lo: Vec3A, hi: Vec3A, t_max: f32) -> Option<(f32, f32)> {
    let inv = ray.d.recip();
    let (a, b) = ((lo - ray.o) * inv, (hi - ray.o) * inv);
    // NaN (a zero direction component on the box's plane) compares false and is ignored.
    let t0 = a.min(b).max_element().max(0.0);
    let t1 = a.max(b).min_element().min(t_max);
    (t0 < t1).then_some((t0, t1))
}

/// Visits the cells of width `cell` that `ray.at(t0..t1)` passes through, in order (Amanatides
/// and Woo), calling `f(cell, t_in, t_out, last)`: the cell owns [t_in, t_out), and the last one
/// also its end, so that a query counting an item in the cell owning one of its ray distances
/// counts it once.
pub fn march(ray: &Ray, t0: f32, t1: f32, cell: f32, mut f: impl FnMut([i32; 3], f32, f32, bool)) {
    let (o, d) = (ray.o, ray.d);
    let start = o + d * t0;
    let mut c = cell_of(start, 1.0 / cell);
    let mut step = [0i32; 3];
    let mut t_next = [f32::INFINITY; 3];
    let mut t_delta = [f32::INFINITY; 3];
    for a in 0..3 {
        if d[a] > 0.0 {
            step[a] = 1;
            t_next[a] = t0 + ((c[a] + 1) as f32 * cell - start[a]) / d[a];
            t_delta[a] = cell / d[a];
        } else if d[a] < 0.0 {
            step[a] = -1;
            t_next[a] = t0 + (c[a] as f32 * cell - start[a]) / d[a];
            t_delta[a] = -cell / d[a];
        }
    }
    let mut t_in = t0;
    while t_in < t1 {
        let axis = if t_next[0] < t_next[1] {
            if t_next[0] < t_next[2] { 0 } else { 2 }
        } else if t_next[1] < t_next[2] {
            1
        } else {
            2
        };
        let t_out = t_next[axis].min(t1);
        let last = t_next[axis] >= t1;
        f(c, t_in, t_out, last);
        t_in = t_out;
        c[axis] += step[axis];
        t_next[axis] += t_delta[axis];
    }
}
